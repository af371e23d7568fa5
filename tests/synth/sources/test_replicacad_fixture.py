"""The ReplicaCAD-shaped fixture (tests/replicacad_fixture.py): deterministic, textured, and imported
by synth.sources.replicacad.importer with the boxes worked out by hand in the fixture's constants."""

from __future__ import annotations

import inspect
import itertools
import json
import math
import sys
from pathlib import Path

import numpy as np
import pytest
import trimesh

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))
import replicacad_fixture as F  # noqa: E402

from synth.sources.replicacad.importer import load_replicacad  # noqa: E402
from synth.scene.model import object_box  # noqa: E402


@pytest.fixture(scope="module")
def root(tmp_path_factory) -> Path:
    return F.make_fixture(tmp_path_factory.mktemp("rcad"))


def _load(root, scene, **kw):
    if "structure" in inspect.signature(load_replicacad).parameters:
        kw.setdefault("structure", False)  # plain reading: boxes of the object instances only
    return load_replicacad(root, scene, allow_unknown=False, **kw)


def _aabb(obj):
    b = object_box(obj)
    c, s, y = np.array(b.center), np.array(b.size), b.yaw
    h = np.array([abs(math.cos(y)) * s[0] / 2 + abs(math.sin(y)) * s[1] / 2,
                  abs(math.sin(y)) * s[0] / 2 + abs(math.cos(y)) * s[1] / 2, s[2] / 2])
    return c - h, c + h


def _overlap(a, b, eps=1e-6) -> bool:
    return all(a[0][i] < b[1][i] - eps and b[0][i] < a[1][i] - eps for i in range(len(a[0])))


def test_deterministic_bytes(root, tmp_path):
    again = F.make_fixture(tmp_path / "again")
    files = sorted(p.relative_to(root) for p in root.rglob("*") if p.is_file())
    assert files == sorted(p.relative_to(again) for p in again.rglob("*") if p.is_file())
    assert len(files) >= 20
    for rel in files:
        assert (root / rel).read_bytes() == (again / rel).read_bytes(), rel


def test_textures_carry_the_mean_colour(root):
    for key, rel in F.GLB_PATHS.items():
        scene = trimesh.load(str(root / rel))
        geoms = list(scene.geometry.values())
        textured = [g for g in geoms if getattr(g.visual, "material", None) is not None
                    and getattr(g.visual.material, "baseColorTexture", None) is not None]
        assert len(textured) == 1, rel
        img = np.asarray(textured[0].visual.material.baseColorTexture.convert("RGB"), dtype=float)
        assert img.shape == (F.TEXTURE_SIZE, F.TEXTURE_SIZE, 3)
        np.testing.assert_allclose(img.reshape(-1, 3).mean(axis=0), F.TEXTURE_SRGB[key], atol=0.5, err_msg=key)
        assert len(np.unique(img.reshape(-1, 3), axis=0)) == 2  # the stripe pattern
    # walls and ceiling: plain colour factors
    stage = trimesh.load(str(root / "stages/frl_apartment_stage.glb"))
    assert tuple(stage.geometry["walls"].visual.material.baseColorFactor) == F.WALL_COLOR_FACTOR
    assert tuple(stage.geometry["ceiling"].visual.material.baseColorFactor) == F.CEILING_COLOR_FACTOR


def test_stage_mesh_is_the_construction_in_habitat_frame(root):
    # habitat (x, y, z) = ours (x, z, -y): floor slab ours z[-0.1, 0] -> habitat y[-0.1, 0], etc.
    stage = trimesh.load(str(root / "stages/frl_apartment_stage.glb"))
    np.testing.assert_allclose(stage.geometry["floor"].bounds, [[-0.1, -0.1, -3.1], [7.2, 0.0, 0.1]], atol=1e-6)
    np.testing.assert_allclose(stage.geometry["ceiling"].bounds, [[-0.1, 2.5, -3.1], [7.2, 2.6, 0.1]], atol=1e-6)
    walls = stage.geometry["walls"]
    np.testing.assert_allclose(walls.bounds, [[-0.1, 0.0, -3.1], [7.2, 2.5, 0.1]], atol=1e-6)
    # the door and the window are holes: no wall triangle reaches into them (checked in our frame)
    C = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, -1.0], [0.0, 1.0, 0.0]])
    tri = walls.vertices[walls.faces] @ C.T
    tri_lo, tri_hi = tri.min(axis=1), tri.max(axis=1)
    for _, lo, hi in (F.DOOR, F.WINDOW):
        inside = np.all((tri_lo < np.array(hi) - 1e-6) & (np.array(lo) + 1e-6 < tri_hi), axis=1)
        assert not inside.any(), (lo, hi)
    # volume, by hand: walls 1.825 (S) + 1.825 - 1.2*0.1*1.1 (N, window) + 0.75 (W) + 0.75 (E)
    # + 0.75 - 0.9*0.1*2.1 (interior, door) = 5.579 m^3
    assert walls.volume == pytest.approx(5.579, abs=1e-5)  # float32 vertices
    # the pieces do not overlap each other
    for a, b in itertools.combinations(F.WALL_PIECES, 2):
        assert not _overlap(a, b)


def test_apt0_imports_with_the_hand_derived_boxes(root):
    layout = _load(root, "apt_0")
    objs = [o for o in layout.objects if o.params.get("template", "").startswith("objects/")]
    assert len(objs) == len(F.OBJECT_BOXES)
    for k, obj in enumerate(objs):
        lo, hi = _aabb(obj)
        elo, ehi = F.OBJECT_BOXES[k]
        np.testing.assert_allclose(lo, elo, atol=1e-3, err_msg=f"instance {k} {obj.cls}")
        np.testing.assert_allclose(hi, ehi, atol=1e-3, err_msg=f"instance {k} {obj.cls}")
        assert obj.cls == F.OBJECT_CLASSES[k]


def test_apt0_construction_is_consistent():
    """The hand-written boxes keep the promises the fixture makes (rooms, walkway, door, window)."""
    boxes = dict(F.OBJECT_BOXES)
    boxes["counter"] = F.COUNTER_BOX
    # the bowl stands on the table top (z 0.75); the cushion lies on the sofa seat (z 0.4), inside
    # the sofa's box (its backrest and armrests are higher), between the armrests and off the backrest
    assert boxes[6][0][2] == boxes[0][1][2] == 0.75
    assert boxes[4][0][2] == 0.4 and boxes[3][0][2] == 0.0
    assert 5.0 + 0.15 <= boxes[4][0][0] and boxes[4][1][0] <= 6.8 - 0.15 and boxes[4][1][1] <= 2.95 - 0.2
    resting = {(3, 4)}
    for (i, a), (j, b) in itertools.combinations(boxes.items(), 2):
        if (i, j) not in resting:
            assert not _overlap(a, b), (i, j)
    rooms = list(F.ROOMS.values())
    for k, (lo, hi) in boxes.items():
        assert any(r[0][0] <= lo[0] and hi[0] <= r[1][0] and r[0][1] <= lo[1] and hi[1] <= r[1][1] for r in rooms), k
        assert lo[2] >= F.FLOOR_Z - 1e-9 and hi[2] <= F.CEILING_Z
        for zone in (F.WALKWAY, F.DOOR_ZONE, F.WINDOW_FRONT):
            assert not _overlap((lo[:2], hi[:2]), zone), (k, zone)
    floor_standing = [k for k in boxes if k not in (4, 6)]
    assert all(boxes[k][0][2] == F.FLOOR_Z for k in floor_standing)
    # the drawer (closed) and the body make up the counter box
    lo = np.minimum(*[np.array(b[0]) for b in F.URDF_LINK_BOXES.values()])
    hi = np.maximum(*[np.array(b[1]) for b in F.URDF_LINK_BOXES.values()])
    np.testing.assert_allclose([lo, hi], F.COUNTER_BOX)


def test_variants_import_and_keep_objects_apart(root):
    for scene in F.SCENES:
        layout = _load(root, scene)
        objs = [o for o in layout.objects if o.params.get("template", "").startswith("objects/")]
        boxes = {o.id: (_aabb(o), o.cls) for o in objs}
        for (i, (a, ca)), (j, (b, cb)) in itertools.combinations(boxes.items(), 2):
            if {ca, cb} != {"sofa", "cushion"}:  # cushions lie on the seat, inside the sofa's box
                assert not _overlap(a, b, eps=1e-4), (scene, i, ca, j, cb)
        sofas = [b for b, c in boxes.values() if c == "sofa"]
        for (lo, hi), cls in boxes.values():
            assert lo[2] >= -1e-6 and hi[2] <= F.CEILING_Z
            assert any(r[0][0] <= lo[0] and hi[0] <= r[1][0] and r[0][1] <= lo[1] and hi[1] <= r[1][1]
                       for r in F.ROOMS.values()), (scene, cls)
            for zone in (F.WALKWAY, F.DOOR_ZONE, F.WINDOW_FRONT):
                assert not _overlap((lo[:2], hi[:2]), zone, eps=1e-4), (scene, cls, zone)
            if cls == "cushion":  # on the seat (z 0.4), clear of the backrest (sofa's back 0.2 m)
                (slo, shi), = sofas
                assert lo[2] == pytest.approx(0.4, abs=1e-6) and hi[1] <= shi[1] - 0.2 + 1e-6, scene


def test_json_files_in_the_real_format(root):
    lights = json.loads((root / "configs/lighting/frl_apartment_stage.lighting_config.json").read_text())["lights"]
    assert sorted(lights) == sorted(F.LIGHTS)
    for k, light in lights.items():
        x, y, z = F.LIGHTS[k]
        assert light["type"] == "point"
        assert light["position"] == pytest.approx([x, z, -y])  # ours -> habitat by hand
        assert light["intensity"] == F.LIGHT_INTENSITY[k]
    scene = json.loads((root / "configs/scenes/apt_0.scene_instance.json").read_text())
    assert scene["default_lighting"] == "lighting/frl_apartment_stage"
    assert (root / "configs" / (scene["default_lighting"] + ".lighting_config.json")).is_file()
    (ao,) = scene["articulated_object_instances"]
    assert ao["template_name"] == "kitchen_counter" and ao["fixed_base"] is True
    assert ao["translation"] == pytest.approx([5.95, 0.0, -0.31])
    assert ao["rotation"] == pytest.approx([0.0, 0.0, 1.0, 0.0])  # 180 deg about habitat +Y
    urdf = root / "urdf/kitchen_counter/kitchen_counter.urdf"
    text = urdf.read_text()
    for mesh in ("kitchen_counter.glb", "drawer1.glb"):
        assert f'filename="{mesh}"' in text and (urdf.parent / mesh).is_file()


def test_urdf_links_land_on_the_hand_derived_boxes(root):
    """URDF meshes (habitat frame) posed by the scene's base pose: C (R_h (origin + v) + t_h)."""
    C = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, -1.0], [0.0, 1.0, 0.0]])
    R_h = np.diag([-1.0, 1.0, -1.0])  # 180 deg about +Y
    t_h = np.array([5.95, 0.0, -0.31])
    origins = {"body": np.zeros(3), "drawer": np.array([0.0, 0.725, 0.045])}
    files = {"body": "kitchen_counter.glb", "drawer": "drawer1.glb"}
    for link, rel in files.items():
        v = trimesh.load(str(root / "urdf/kitchen_counter" / rel), force="mesh").vertices
        w = (C @ (R_h @ (v + origins[link]).T + t_h[:, None])).T
        np.testing.assert_allclose([w.min(axis=0), w.max(axis=0)], F.URDF_LINK_BOXES[link], atol=1e-6)


def test_structure_import_matches_the_construction(root):
    """The full import: the articulated counter is one object on COUNTER_BOX."""
    layout = load_replicacad(root, "apt_0", allow_unknown=False)
    counters = [o for o in layout.objects if o.cls == "kitchen_counter"]
    assert len(counters) == 1
    lo, hi = _aabb(counters[0])
    np.testing.assert_allclose([lo, hi], F.COUNTER_BOX, atol=1e-3)
    assert counters[0].id == len(F.OBJECT_BOXES) + 1  # after the rigid objects
