"""ReplicaCAD as distributed, on the real-format fixture (the dataset's own configs, lexicon and URDFs):
classes from the lexicon, receptacles as supports, collisions from collision shapes, doors open."""

from __future__ import annotations

import collections
import json
import subprocess
import sys

import numpy as np
import pytest

from replicacad_real_fixture import FILES, write_real_fixture

from vrformats.errors import SceneFormatError
from synth.layout.validity import check_layout
from synth.scene.classes import class_table, lexicon_table
from synth.mesh.collision import overlap_depth, penetration, touching
from synth.sources.replicacad.importer import load_replicacad
from synth.scene.model import ObjectInstance, Room, load_layout, object_box, save_layout

APTS = [f"apt_{k}" for k in range(6)]


@pytest.fixture(scope="module")
def root(tmp_path_factory):
    return write_real_fixture(tmp_path_factory.mktemp("rcad_ds"))


@pytest.fixture(scope="module")
def apt0(root):
    return load_replicacad(root, "apt_0")


def test_lexicon_table_names_every_class_of_the_real_lexicon():
    lex = json.loads((FILES / "configs/ssd/replicaCAD_semantic_lexicon.json").read_text())["classes"]
    names = {c["name"] for c in lex}
    table = lexicon_table()
    assert len(names) == 101
    assert set(table.lexicon) == names
    classes = class_table()
    for cls in list(table.lexicon.values()) + list(table.templates.values()):
        assert cls in classes and not classes.get(cls).structure


def test_lexicon_errors_are_overridden_by_template():
    table = lexicon_table()
    # the real configs carry the ids of "chopping_board" and "tablet" for these
    for tmpl, wrong in (("frl_apartment_clothes_hanger_01", "chopping_board"), ("frl_apartment_setupbox", "tablet"),
                        ("frl_apartment_tv_object", "tablet")):
        cfg = json.loads((FILES / f"configs/objects/{tmpl}.object_config.json").read_text())
        lex = {c["id"]: c["name"] for c in json.loads((FILES / "configs/ssd/replicaCAD_semantic_lexicon.json").read_text())["classes"]}
        assert lex[cfg["semantic_id"]] == wrong
        cls, rule = table.class_of(f"objects/{tmpl}", wrong)
        assert rule == "template" and cls != table.lexicon[wrong]


@pytest.mark.parametrize("scene", APTS)
def test_apartments_import_with_classes_from_the_lexicon(root, scene):
    layout = load_replicacad(root, scene)  # no allow_unknown: every object has a class
    counts = collections.Counter(o.cls for o in layout.objects)
    assert counts["other"] < 0.05 * len(layout.objects)
    assert len(layout.objects) >= 119 and len(counts) >= 35
    by_template = {o.params["template"]: o.cls for o in layout.objects}
    assert by_template["objects/frl_apartment_chair_01"] == "chair"
    assert by_template["objects/frl_apartment_kitchen_utensil_03"] == "kitchen_utensil"
    assert by_template["objects/frl_apartment_sofa"] == "sofa"
    assert by_template["fridge"] == "fridge" and by_template["door2"] == "door"


def test_semantic_id_missing_from_the_lexicon_is_one_line_naming_the_config(root, tmp_path):
    import shutil

    bad = tmp_path / "bad"
    shutil.copytree(root, bad)
    cfg = bad / "configs/objects/frl_apartment_sofa.object_config.json"
    doc = json.loads(cfg.read_text())
    doc["semantic_id"] = 999
    cfg.write_text(json.dumps(doc))
    with pytest.raises(SceneFormatError) as e:
        load_replicacad(bad, "apt_0")
    assert "frl_apartment_sofa.object_config.json" in str(e.value) and "semantic_id" in str(e.value) and "999" in str(e.value)
    r = subprocess.run([sys.executable, "-m", "synth.cli", "scene", "import-replicacad", str(bad), "apt_0", "--out",
                        str(tmp_path / "x.yaml")], capture_output=True, text=True)
    assert r.returncode == 2 and len(r.stderr.strip().splitlines()) == 1 and "semantic_id" in r.stderr
    assert not (tmp_path / "x.yaml").exists()


def test_receptacles_in_the_object_frame_and_as_supports(apt0):
    # frl_apartment_table_02: three receptacle_aabb_* boxes; Top1's bottom is the GLB's top (y 0.334 in its frame)
    table = next(o for o in apt0.objects if o.params["template"] == "objects/frl_apartment_table_02")
    recs = table.params["receptacles"]
    assert [r["name"] for r in recs] == [f"receptacle_aabb_Tbl2_Top{k}_frl_apartment_table_02" for k in (1, 2, 3)]
    top1 = recs[0]
    # habitat (x, y, z) = (0.0088, 0.4683, 0.0441) +- (0.6336, 0.1366, 0.3973) -> ours (x, -z, y)
    assert np.allclose(top1["center"], [0.0088, -0.0441, 0.4683], atol=1e-4)
    assert np.allclose(top1["half"], [0.6336, 0.3973, 0.1366], atol=1e-4)
    from synth.mesh.surfaces import mesh_surfaces

    surfs = mesh_surfaces(table, apt0.meta["root"])
    assert len(surfs) == 3 and surfs[0].band == pytest.approx(2 * 0.1366, abs=1e-3)
    assert surfs[0].z == pytest.approx(0.4683 - 0.1366, abs=1e-3)
    # the kitchen counter's receptacles sit on its links (drawers) and its body
    counter = next(o for o in apt0.objects if o.params["template"] == "kitchen_counter")
    assert len(counter.params["receptacles"]) == 10
    # whatever the importer says stands on a receptacle, the check agrees with
    rep = check_layout(apt0)
    on_recs = [o for o in apt0.objects if o.support.startswith("object:")
               and apt0.object(o.support_parent()[0]).params.get("receptacles")]
    assert on_recs
    bad = {u["id"] for u in rep.unsupported}
    assert not [o.id for o in on_recs if o.id in bad]


def test_door_leaves_stand_open(apt0):
    door = next(o for o in apt0.objects if o.cls == "door")
    assert door.params["joint_state"] == {"root_rotation": -2.0}  # door2.urdf: limit lower -2.0, upper 0
    assert door.params["door_opening"] == "limit"


def test_an_inserted_collision_is_caught(apt0):
    rep = check_layout(apt0)
    sofa = next(o for o in apt0.objects if o.cls == "sofa")
    chair = next(o for o in apt0.objects if o.cls == "chair")
    assert not any({c["a"], c["b"]} == {sofa.id, chair.id} for c in rep.collisions)
    # put the chair into the middle of the sofa
    sb, cb = object_box(sofa), object_box(chair)
    moved = ObjectInstance(chair.id, chair.cls, chair.asset,
                           tuple(np.asarray(chair.position) + np.r_[np.asarray(sb.center[:2]) - cb.center[:2], 0.0]),
                           chair.rotation, chair.size, chair.box_offset, chair.support, chair.movable, chair.scale, chair.params)
    bad = apt0.copy()
    bad.objects = [moved if o.id == chair.id else o for o in bad.objects]
    rep2 = check_layout(bad)
    assert any({c["a"], c["b"]} == {sofa.id, chair.id} for c in rep2.collisions)


def _cube(c, h):
    s = np.array([[x, y, z] for x in (-1, 1) for y in (-1, 1) for z in (-1, 1)], float)
    return np.asarray(c, float) + s * np.asarray(h, float)


def test_overlap_depth_is_the_largest_inscribed_ball():
    a = _cube((0, 0, 0), (0.5, 0.5, 0.5))
    assert overlap_depth(a, _cube((0.9, 0, 0), (0.5, 0.5, 0.5))) == pytest.approx(0.05, abs=1e-6)  # 0.1 m slab
    assert overlap_depth(a, _cube((1.2, 0, 0), (0.5, 0.5, 0.5))) == 0.0
    assert overlap_depth(a, _cube((0, 0, 0), (0.1, 0.1, 0.1))) == pytest.approx(0.1, abs=1e-6)
    # an L: the boxes of the two overlap, the pieces do not (a chair's seat under a table top)
    table = [_cube((0, 0, 0.75), (0.6, 0.4, 0.02)), _cube((0.55, 0, 0.37), (0.03, 0.03, 0.37))]
    chair = [_cube((0, 0, 0.45), (0.2, 0.2, 0.02))]
    assert penetration(table, chair) == 0.0
    assert touching([_cube((0, 0, 0), (0.5, 0.5, 0.5))], [_cube((1.01, 0, 0), (0.5, 0.5, 0.5))], gap=0.02)
    assert not touching([_cube((0, 0, 0), (0.5, 0.5, 0.5))], [_cube((1.05, 0, 0), (0.5, 0.5, 0.5))], gap=0.02)


def test_room_polygon_round_trips_and_tests_points(tmp_path, apt0):
    L = Room("room_0", "hallway", (0.0, 0.0, 4.0, 3.0), ((0.0, 0.0), (4.0, 0.0), (4.0, 1.0), (1.0, 1.0), (1.0, 3.0), (0.0, 3.0)))
    assert L.area == pytest.approx(4.0 + 2.0)
    assert list(L.contains([(0.5, 2.5), (3.0, 0.5), (3.0, 2.5), (4.0, 0.5)])) == [True, True, False, True]
    lay = apt0.copy()
    lay.stage.rooms = [L]
    save_layout(lay, tmp_path / "l.yaml")
    back = load_layout(tmp_path / "l.yaml")
    assert back.stage.rooms[0].polygon == L.polygon and back.stage.room_at((3.0, 2.5)) is None


def test_a_settled_object_rests_within_the_collision_margins(root):
    # apt_3's mat lies 3.6 cm above the floor (habitat-sim: object margin 0.04 + stage margin 0.01)
    layout = load_replicacad(root, "apt_3")
    mat = next(o for o in layout.objects if o.params["template"] == "objects/frl_apartment_mat")
    assert mat.support == "free" and 0.03 < object_box(mat).zmin - layout.stage.floor_z < 0.05
    assert layout.meta["structure"]["margin"] == 0.01  # frl_apartment_stage.stage_config.json
    assert mat.id not in {u["id"] for u in check_layout(layout).unsupported}
    # the same mat 0.8 m above the dining table touches nothing
    table = object_box(next(o for o in layout.objects if o.params["template"] == "objects/frl_apartment_table_01"))
    mb = object_box(mat)
    d = np.r_[np.asarray(table.center[:2]) - mb.center[:2], table.zmax + 0.8 - mb.zmin]
    moved = ObjectInstance(mat.id, mat.cls, mat.asset, tuple(np.asarray(mat.position) + d), mat.rotation, mat.size,
                           mat.box_offset, mat.support, mat.movable, mat.scale, mat.params)
    floating = layout.copy()
    floating.objects = [moved if o.id == mat.id else o for o in floating.objects]
    why = {u["id"]: u["why"] for u in check_layout(floating).unsupported}
    assert "touches no object" in why[mat.id]


def test_soft_furnishings_may_press_into_each_other(root):
    layout = load_replicacad(root, "apt_0")
    soft = {o.params["template"] for o in layout.objects if o.params.get("soft")}
    assert "objects/frl_apartment_beanbag" in soft and "objects/frl_apartment_cushion_01" in soft
    assert "objects/frl_apartment_chair_01" not in soft


def test_a_door_opens_until_it_meets_an_object(root):
    # apt_4: door2 at its far limit (-2.0 rad) would swing into frl_apartment_bin_03
    layout = load_replicacad(root, "apt_4")
    door = next(o for o in layout.objects if o.cls == "door")
    assert door.params["door_opening"] == "stopped"
    angle = door.params["joint_state"]["root_rotation"]
    assert -2.0 < angle < -0.5
    assert not [c for c in check_layout(layout).collisions if door.id in (c["a"], c["b"])]
    assert next(o for o in load_replicacad(root, "apt_0").objects if o.cls == "door").params["door_opening"] == "limit"


def test_a_picture_on_its_wall_passes_one_pushed_through_it_does_not(root):
    layout = load_replicacad(root, "apt_0")
    pic = next(o for o in layout.objects if o.params["template"] == "objects/frl_apartment_picture_01")
    rep = check_layout(layout)
    assert pic.id not in {c["a"] for c in rep.collisions} | {u["id"] for u in rep.unsupported}
    from synth.layout.validity import _outside_rooms_by

    c = np.asarray(object_box(pic).center[:2], float)
    # the way out of the rooms: the horizontal direction in which the centre leaves them soonest
    dirs = [np.array([np.cos(a), np.sin(a)]) for a in np.linspace(0, 2 * np.pi, 16, endpoint=False)]
    out = max(dirs, key=lambda d: _outside_rooms_by(layout.stage, c + 0.3 * d))
    moved = ObjectInstance(pic.id, pic.cls, pic.asset, tuple(np.asarray(pic.position) + np.r_[0.5 * out, 0.0]), pic.rotation,
                           pic.size, pic.box_offset, pic.support, pic.movable, pic.scale, pic.params)
    bad = layout.copy()
    bad.objects = [moved if o.id == pic.id else o for o in bad.objects]
    rep2 = check_layout(bad)
    assert any(c["a"] == pic.id and c["b"] == "wall" for c in rep2.collisions) or pic.id in {u["id"] for u in rep2.unsupported}
