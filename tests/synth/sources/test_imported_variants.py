"""Rearranged variants, light fixtures and camera paths of IMPORTED (ReplicaCAD) layouts.

Two kinds of input: a layout built here by hand (the shell of the built-in apt_0, mesh-asset
objects written as GLBs in habitat's Y-up frame, like ReplicaCAD's), and -- when the importer
derives rooms from the stage mesh -- the ReplicaCAD-shaped fixture (tests/replicacad_fixture.py).
Expected numbers are worked out by hand. Frames: habitat is Y up; ours is Z up;
C = [[1,0,0],[0,0,-1],[0,1,0]] maps (x, y, z)_habitat -> (x, -z, y)_ours.
"""

from __future__ import annotations

import json
import math
import sys
from dataclasses import asdict
from pathlib import Path

import numpy as np
import pytest
import trimesh

from vrformats.errors import SceneFormatError
from synth.scene import geometry as geo
from synth.scene.fixtures import layout_fixtures
from synth.layout.validity import check_layout
from synth.scene.lighting import kelvin_to_rgb
from synth.sources.replicacad.habitat_lighting import assign_lights, color_temperature, fixtures_for_imported, parse_lighting_config, read_lighting_config
from synth.layout.placement import Placer, placed_copy
from synth.mesh.surfaces import mesh_top_coverage
from synth.layout.rearrange import (
    RearrangePlan,
    VariantSpec,
    make_variant,
    free_holders,
    free_rests,
    new_problems,
    pinned_ids,
    rearrange,
    scaled_plan,
    template_pool,
)
from synth.scene.model import Layout, ObjectInstance, Room, Stage, layout_to_dict, load_layout, object_box
from synth.scene.stats import PAPER_RANGES, change_stats, flat_mean_distance, scaled_ranges
from meshes import box_mesh, write_glb

C = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, -1.0], [0.0, 1.0, 0.0]])  # by hand, not imported


# ---------------------------------------------------------------------------------------------
# meshes, HABITAT local frame (x, y up, z)


def _join(parts):
    return trimesh.util.concatenate(parts)


def _table():  # top board y[0.72, 0.75] over x[-0.6,0.6] z[-0.4,0.4], four legs: the whole top is covered
    parts = [box_mesh((-0.6, 0.72, -0.4), (0.6, 0.75, 0.4))]
    for x0 in (-0.6, 0.55):
        for z0 in (-0.4, 0.35):
            parts.append(box_mesh((x0, 0.0, z0), (x0 + 0.05, 0.72, z0 + 0.05)))
    return _join(parts)


def _chair():  # 0.44 x 0.9 x 0.44; the backrest top (0.44 x 0.04) is all that is at the top
    parts = [box_mesh((-0.22, 0.42, -0.22), (0.22, 0.46, 0.22)), box_mesh((-0.22, 0.46, -0.22), (0.22, 0.9, -0.18))]
    for x0 in (-0.22, 0.18):
        for z0 in (-0.22, 0.18):
            parts.append(box_mesh((x0, 0.0, z0), (x0 + 0.04, 0.42, z0 + 0.04)))
    return _join(parts)


def _shelf():  # a closed 0.8 x 1.2 x 0.3 box: top covered
    return box_mesh((-0.4, 0.0, -0.15), (0.4, 1.2, 0.15))


def _sofa():  # seat at y = 0.42, backrest at habitat -z (our +y) up to 0.85: top covers 0.2 / 0.9 of the box top
    return _join([box_mesh((-0.9, 0.0, -0.45), (0.9, 0.42, 0.45)), box_mesh((-0.9, 0.42, -0.45), (0.9, 0.85, -0.25))])


def _bowl():  # open: base and four 1.5 cm walls, 0.2 x 0.08 x 0.2
    t = 0.015
    return _join([box_mesh((-0.1, 0.0, -0.1), (0.1, t, 0.1)), box_mesh((-0.1, t, -0.1), (0.1, 0.08, -0.1 + t)),
                  box_mesh((-0.1, t, 0.1 - t), (0.1, 0.08, 0.1)), box_mesh((-0.1, t, -0.1 + t), (-0.1 + t, 0.08, 0.1 - t)),
                  box_mesh((0.1 - t, t, -0.1 + t), (0.1, 0.08, 0.1 - t))])


def _lamp():  # foot, pole, open shade (a ring): 0.4 x 1.6 x 0.4
    t = 0.01
    return _join([box_mesh((-0.15, 0.0, -0.15), (0.15, 0.03, 0.15)), box_mesh((-0.015, 0.03, -0.015), (0.015, 1.3, 0.015)),
                  box_mesh((-0.2, 1.3, -0.2), (0.2, 1.6, -0.2 + t)), box_mesh((-0.2, 1.3, 0.2 - t), (0.2, 1.6, 0.2)),
                  box_mesh((-0.2, 1.3, -0.2 + t), (-0.2 + t, 1.6, 0.2 - t)), box_mesh((0.2 - t, 1.3, -0.2 + t), (0.2, 1.6, 0.2 - t))])


def _counter():
    return box_mesh((-0.75, 0.0, -0.3), (0.75, 0.9, 0.3))


def _cushion():
    return box_mesh((-0.2, 0.0, -0.2), (0.2, 0.12, 0.2))


def _vase():
    return box_mesh((-0.05, 0.0, -0.05), (0.05, 0.25, 0.05))


MESHES = {"table": _table, "chair": _chair, "shelf": _shelf, "sofa": _sofa, "bowl": _bowl, "lamp": _lamp,
          "counter": _counter, "cushion": _cushion, "vase": _vase}
CLASSES = {"table": "dining_table", "chair": "chair", "shelf": "bookshelf", "sofa": "sofa", "bowl": "bowl",
           "lamp": "floor_lamp", "counter": "kitchen_counter", "cushion": "cushion", "vase": "vase"}


def _proto(name: str, movable: bool = True) -> ObjectInstance:
    """An instance of mesh ``name`` at the origin; its local box is C applied to the habitat bounds."""
    lo_h, hi_h = MESHES[name]().bounds
    corners = np.array([[x, y, z] for x in (lo_h[0], hi_h[0]) for y in (lo_h[1], hi_h[1]) for z in (lo_h[2], hi_h[2])]) @ C.T
    lo, hi = corners.min(axis=0), corners.max(axis=0)
    return ObjectInstance(0, CLASSES[name], f"replicacad:objects/{name}.glb", (0.0, 0.0, 0.0), (1.0, 0.0, 0.0, 0.0),
                          tuple(hi - lo), tuple((lo + hi) / 2), support="floor", movable=movable,
                          params={"template": f"objects/frl_apartment_{name}_01", "motion_type": "DYNAMIC" if movable else "STATIC"})


def _write_meshes(root: Path) -> None:
    for name, fn in MESHES.items():
        write_glb(root / f"objects/{name}.glb", fn())


def _imported_layout(root: Path, seed: int = 3) -> Layout:
    """The shell of apt_0 furnished with mesh objects (placed with a seeded Placer), as an import would be."""
    _write_meshes(root)
    apt0 = load_layout("apt_0")
    st = apt0.stage
    stage = Stage(st.ceiling_height, rooms=list(st.rooms), walls=list(st.walls), openings=list(st.openings),
                  floor_z=st.floor_z, asset="replicacad:stages/stage.glb")
    lay = Layout("rc_test", stage, meta={"source": "replicacad", "root": str(root), "scene": "rc_test"})
    p = Placer(lay, np.random.default_rng(seed))

    def put(name, room, wall=False, movable=True):
        t = _proto(name, movable)
        size = object_box(t).size
        fn = p.against_wall if wall else p.free_spot
        kw = {} if wall else {"margin": 0.3}
        o = fn(p.next_id(), t.cls, size, t.params, st.room(room), template=t, **kw)
        assert o is not None, (name, room)
        return p.add(o)

    def on(name, parents):
        t = _proto(name)
        o = p.on_surface(p.next_id(), t.cls, object_box(t).size, t.params, parents, yaw_mode="any90", template=t)
        assert o is not None, (name, [q.id for q in parents])
        return p.add(o)

    sofa = put("sofa", "living", wall=True)
    # a vase standing on the sofa's backrest (the top of its box: ours local y 0.25..0.45 at z 0.85),
    # recorded "free" as the importer does for what the boxes do not explain
    sb = object_box(sofa)
    c = np.asarray(sb.center) + geo.rot_z(sb.yaw) @ np.array([0.0, 0.35, 0.0])
    p.add(placed_copy(_proto("vase"), p.next_id(), c[:2], sb.zmax, sb.yaw, "free"))
    for room, n_chairs in (("living", 2), ("kitchen", 4), ("bedroom", 1)):
        table = put("table", room)
        on("bowl", [table])
        on("vase", [table])
        for _ in range(n_chairs):
            put("chair", room)
    put("counter", "kitchen", wall=True, movable=False)
    for room in ("living", "living", "bedroom", "hallway", "bathroom"):
        shelf = put("shelf", room, wall=True)
        on("vase", [shelf])
    put("lamp", "living")
    put("lamp", "bedroom")
    lay.objects.sort(key=lambda o: o.id)
    return lay


@pytest.fixture(scope="module")
def rc(tmp_path_factory) -> Layout:
    lay = _imported_layout(tmp_path_factory.mktemp("rc_hand"))
    rep = check_layout(lay)
    assert rep.ok, rep.to_dict()
    return lay


# ---------------------------------------------------------------------------------------------
# placement primitives on meshes


def _zup(m):
    return m.vertices @ C.T, m.faces


def test_mesh_top_coverage_by_hand():
    def cov(m):
        return mesh_top_coverage(*_zup(m))

    assert cov(_table()) == pytest.approx(1.0)
    assert cov(_shelf()) == pytest.approx(1.0)
    assert cov(_chair()) == pytest.approx(0.44 * 0.04 / (0.44 * 0.44))  # backrest top only
    assert cov(_sofa()) == pytest.approx(1.8 * 0.2 / (1.8 * 0.9))
    assert cov(_bowl()) == pytest.approx((0.2 * 0.2 - 0.17 * 0.17) / (0.2 * 0.2))  # the rim
    # without C the "top" is a side: the table's end (x = 0.6) is 0.05 x 0.8 of a 1.2 x 0.75 side... not up-facing
    assert mesh_top_coverage(_table().vertices, _table().faces) < 0.5


def test_surfaces_of_mesh_objects(rc, tmp_path):
    p = Placer(rc.copy(), np.random.default_rng(0))
    by_cls = {}
    for o in rc.objects:
        by_cls.setdefault(o.cls, []).append(o)
    table = by_cls["dining_table"][0]
    (s,) = p.surfaces(table)
    # table local box (ours): x[-0.6,0.6] y[-0.4,0.4] z[0,0.75]; 2 cm margin
    assert (s.z, s.xmin, s.xmax, s.ymin, s.ymax) == pytest.approx((0.75, -0.58, 0.58, -0.38, 0.38))
    assert s.clearance == math.inf
    (s,) = p.surfaces(by_cls["bookshelf"][0])  # x[-0.4,0.4] y[-0.15,0.15] z[0,1.2]
    assert (s.z, s.xmin, s.xmax, s.ymin, s.ymax) == pytest.approx((1.2, -0.38, 0.38, -0.13, 0.13))
    # seats: the level below the top, without the strip under the backrest (a 9 x 9 grid: synth.layout.placement
    # LEVEL_GRID), 2 cm inside; clearance up to the box top, as a procedural chair's seat has one
    (s,) = p.surfaces(by_cls["chair"][0])  # seat top 0.46, x/y [-0.22, 0.22], backrest over y [0.18, 0.22]
    ymax = -0.22 + 8 * 0.44 / 9 - 0.02  # the last of 9 cells is under the backrest
    assert (s.z, s.xmin, s.xmax, s.ymin, s.ymax, s.clearance) == pytest.approx((0.46, -0.2, 0.2, -0.2, ymax, 0.44), abs=1e-6)
    (s,) = p.surfaces(by_cls["sofa"][0])  # seat top 0.42, x [-0.9, 0.9], y [-0.45, 0.45], backrest over y [0.25, 0.45]
    assert (s.z, s.xmin, s.xmax, s.ymin, s.ymax, s.clearance) == pytest.approx((0.42, -0.88, 0.88, -0.43, 0.23, 0.43), abs=1e-6)
    for cls in ("bowl", "floor_lamp", "vase"):
        assert p.surfaces(by_cls[cls][0]) == [], cls
    assert mesh_top_coverage(*_zup(_vase())) == pytest.approx(1.0)  # a closed top, but vases hold nothing
    # a tilted object holds nothing; a layout without meta.root has no mesh surfaces
    tilted = ObjectInstance(**{**table.__dict__, "id": 998, "rotation": (math.cos(0.1), math.sin(0.1), 0.0, 0.0)})
    assert p.surfaces(tilted) == []
    bare = rc.copy()
    bare.meta = {}
    assert Placer(bare, np.random.default_rng(0)).surfaces(table) == []


def test_placed_copy_by_hand():
    t = ObjectInstance(5, "chair", "replicacad:objects/chair.glb", (1.0, 1.0, 0.0), (1.0, 0.0, 0.0, 0.0), (0.4, 0.6, 1.0),
                       (0.1, 0.0, 0.5), support="floor", scale=(1.2, 1.2, 1.2), params={"template": "objects/c"})
    c = placed_copy(t, 9, (2.0, 3.0), 0.25, math.pi / 2, "object:4:0")
    # turned +90 deg: box offset (0.1, 0, 0.5) becomes (0, 0.1, 0.5); box centre (2, 3, 0.25 + 0.5)
    assert c.position == pytest.approx((2.0, 2.9, 0.25))
    assert c.rotation == pytest.approx((math.sqrt(0.5), 0.0, 0.0, math.sqrt(0.5)))
    assert (c.id, c.support, c.asset, c.size, c.box_offset, c.scale, c.params) == (
        9, "object:4:0", t.asset, t.size, t.box_offset, t.scale, t.params)
    b = object_box(c)
    assert b.center == pytest.approx((2.0, 3.0, 0.75)) and b.yaw == pytest.approx(math.pi / 2)


# ---------------------------------------------------------------------------------------------
# plan and ranges for a scene of another size


def test_scaled_ranges_and_plan_of_apt0_are_the_papers():
    apt0 = load_layout("apt_0")
    assert scaled_ranges(apt0) == PAPER_RANGES
    assert scaled_plan(apt0, RearrangePlan()) == RearrangePlan()
    assert scaled_plan(apt0, RearrangePlan(removed=8, added=10)) == RearrangePlan(removed=8, added=10)


def test_flat_mean_distance_of_a_square():
    # mean distance between two uniform points of a unit square: (2 + sqrt2 + 5 ln(1 + sqrt2)) / 15
    unit = (2 + math.sqrt(2) + 5 * math.log(1 + math.sqrt(2))) / 15
    lay = Layout("sq", Stage(2.5, rooms=[Room("r", "living", (0.0, 0.0, 6.0, 6.0))]))
    assert flat_mean_distance(lay) == pytest.approx(6 * unit, rel=0.01)


def test_scaled_ranges_by_hand():
    apt0 = load_layout("apt_0")  # 82 movable objects: 36 on the floor, 38 on surfaces, 8 on walls
    half = apt0.copy()
    keep = [o for o in half.objects if o.movable][:41]
    half.objects = keep + [o for o in half.objects if not o.movable]
    half.objects = [o for o in half.objects if not (o.support_parent() and o.support_parent()[0] not in {k.id for k in half.objects})]
    half.fixtures = []
    n = sum(o.movable and o.support != "free" for o in half.objects)
    f = n / 82
    r = scaled_ranges(half)
    assert r["moved_over_0.1m"] == (math.floor(68 * f), math.ceil(76 * f))
    assert r["added"] == (max(1, math.floor(8 * f)), math.ceil(10 * f))
    assert r["moved_median_m"] == (1.9, 3.5)  # same flat
    # the same flat at half the size: moves of half the length
    small = half.copy()
    small.stage.rooms = [Room(x.name, x.type, tuple(v / 2 for v in x.rect)) for x in half.stage.rooms]
    assert scaled_ranges(small)["moved_median_m"] == pytest.approx((0.95, 1.75), abs=0.011)
    # free objects do not count
    freed = half.copy()
    for o in freed.objects:
        if o.movable and o.support == "floor":
            o.support = "free"
            break
    assert scaled_ranges(freed)["moved_over_0.1m"] == (math.floor(68 * (n - 1) / 82), math.ceil(76 * (n - 1) / 82))


def test_scaled_plan_by_hand(rc):
    mv = [o for o in rc.objects if o.movable and o.support != "free"]
    fl = sum(o.support == "floor" for o in mv)
    sf = sum(o.support.startswith("object:") for o in mv)
    plan = scaled_plan(rc, RearrangePlan())
    half_up = lambda x: math.floor(x + 0.5)  # noqa: E731
    assert plan.floor_moves == min(fl, half_up(33 * fl / 36))
    assert plan.nudges == min(fl, half_up(6 * fl / 36))
    assert plan.surface_moves == min(sf, half_up(24 * sf / 38))
    assert plan.wall_moves == 0
    assert plan.added == max(1, half_up(9 * len(mv) / 82)) and plan.removed == max(1, half_up(5 * len(mv) / 82))


# ---------------------------------------------------------------------------------------------
# the operator on an imported layout


def _relative(parent: ObjectInstance, child: ObjectInstance) -> np.ndarray:
    return np.linalg.inv(parent.matrix()) @ child.matrix()


def test_free_rests_pinned_and_pool(rc):
    sofa = next(o for o in rc.objects if o.cls == "sofa")
    vase = next(o for o in rc.objects if o.support == "free")
    # the free vase stands on the sofa's backrest, and only there: it goes where the sofa goes
    assert free_holders(rc) == {vase.id: [sofa.id]}
    assert free_rests(rc) == ({sofa.id: [vase.id]}, set()) and pinned_ids(rc) == set()
    # a free object that may not move (STATIC in the dataset) keeps what it rests on in place
    fixed = rc.copy()
    shelf = next(o for o in fixed.objects if o.cls == "bookshelf")
    sb = object_box(shelf)
    static = placed_copy(_proto("vase", movable=False), 900, sb.center[:2], sb.zmax, sb.yaw, "free")
    fixed.objects.append(static)
    assert free_rests(fixed) == ({sofa.id: [vase.id]}, {shelf.id})
    # so does one with two possible holders (a vase where a table's box and the shelf's meet)
    two = rc.copy()
    table = next(o for o in two.objects if o.cls == "dining_table")
    tb = object_box(table)
    two.objects.append(placed_copy(_proto("vase"), 901, tb.center[:2], tb.zmax, tb.yaw, "free"))
    two.objects.append(placed_copy(_proto("counter", movable=False), 902, tb.center[:2], tb.zmin, tb.yaw, "floor"))
    rests, pinned = free_rests(two)
    assert free_holders(two)[901] == [table.id, 902] and pinned == {table.id, 902} and 901 not in sum(rests.values(), [])
    pool = template_pool(rc)
    assert sorted({(o.cls, o.asset) for o in pool}) == sorted({(o.cls, o.asset) for o in rc.objects
                                                              if o.movable and o.support != "free"})
    assert len(pool) == len({(o.asset, o.size) for o in pool})


@pytest.fixture(scope="module")
def rc_variant(rc):
    var = make_variant(rc, VariantSpec("rc_v1", 21, RearrangePlan()))
    return var


def test_variant_checks_and_ranges(rc, rc_variant):
    var = rc_variant
    rep = check_layout(var)
    assert rep.ok, rep.to_dict()
    st = change_stats(rc, var)
    ranges = scaled_ranges(rc)
    print("\nhand-built imported layout:", {k: st[k] for k in ranges}, "ranges:", ranges)
    for k, (lo, hi) in ranges.items():
        assert lo <= st[k] <= hi, (k, st[k], (lo, hi))
    assert var.meta["ranges"] == {k: [lo, hi] for k, (lo, hi) in ranges.items()}
    assert var.meta["plan"] == asdict(scaled_plan(rc, RearrangePlan()))
    for key in ("source", "root", "scene"):  # the import record stays: meshes are found again
        assert var.meta[key] == rc.meta[key]


def test_same_seed_same_variant(rc, rc_variant):
    again = make_variant(rc, VariantSpec("rc_v1", 21, RearrangePlan()))
    assert layout_to_dict(again) == layout_to_dict(rc_variant)
    other = make_variant(rc, VariantSpec("rc_v1", 22, RearrangePlan()))
    assert layout_to_dict(other) != layout_to_dict(rc_variant)


def test_added_objects_are_copies_of_the_scenes_templates(rc, rc_variant):
    ref_ids = {o.id for o in rc.objects}
    added = [o for o in rc_variant.objects if o.id not in ref_ids]
    assert added and min(o.id for o in added) > max(ref_ids)  # no removed object's id is reused
    templates = {(o.asset, o.cls, o.size, o.box_offset, o.scale, o.params["template"]) for o in rc.objects}
    for o in added:
        assert not o.asset.startswith("proc:")
        assert (o.asset, o.cls, o.size, o.box_offset, o.scale, o.params["template"]) in templates


def test_supports_stay_valid(rc, rc_variant):
    ref, var = rc.by_id(), rc_variant.by_id()
    carried = moved_away = 0
    for o in rc_variant.objects:
        b = object_box(o)
        if o.support == "floor":
            assert abs(b.zmin - rc_variant.stage.floor_z) < 0.003, o.id
        par = o.support_parent()
        if par is None:
            continue
        parent = var[par[0]]
        pb = object_box(parent)
        if par[1] == 0 and abs(b.zmin - pb.zmax) < 0.003:  # on the top of its parent's box
            local = (b.corners_2d() - np.asarray(pb.center[:2])) @ geo.rot_z(pb.yaw)[:2, :2]
            assert (np.abs(local) <= np.asarray(pb.size[:2]) / 2 + 0.002).all(), o.id  # footprint on the top
        else:  # on a level inside the parent's box (a seat): below the top, footprint inside the box
            assert pb.zmin + 0.05 <= b.zmin < pb.zmax - 0.01, o.id
            local = (b.corners_2d() - np.asarray(pb.center[:2])) @ geo.rot_z(pb.yaw)[:2, :2]
            assert (np.abs(local) <= np.asarray(pb.size[:2]) / 2 + 0.002).all(), o.id
        if o.id in ref and ref[o.id].support == o.support:
            # still on the same object: where the parent went, it went along (same pose relative to it)
            rel0, rel1 = _relative(ref[par[0]], ref[o.id]), _relative(parent, o)
            if np.allclose(rel0, rel1, atol=2e-3):
                carried += parent.position != ref[par[0]].position
            else:
                moved_away += 1  # put elsewhere on the same top
        elif o.id in ref:
            moved_away += 1  # onto another surface
    print(f"\ncarried along: {carried}, put elsewhere: {moved_away}")
    assert carried > 0 and moved_away > 0
    # the free vase keeps its pose on the sofa it stands on, wherever the sofa went
    vase = next(o for o in rc.objects if o.support == "free")
    sofa = next(o for o in rc.objects if o.cls == "sofa")
    if vase.id in var and sofa.id in var:
        assert np.allclose(_relative(ref[sofa.id], ref[vase.id]), _relative(var[sofa.id], var[vase.id]), atol=1e-6)


def test_reference_with_problems_variant_adds_none(rc):
    """Real scans do not check clean (a cushion sunk into a sofa's seat box): a variant may keep the
    reference's problems but must not add any."""
    ref = rc.copy()
    sofa = next(o for o in ref.objects if o.cls == "sofa")
    sb = object_box(sofa)
    c = np.asarray(sb.center) + geo.rot_z(sb.yaw) @ np.array([0.0, -0.2, 0.0])
    ref.objects.append(placed_copy(_proto("cushion"), 900, c[:2], sb.zmin + 0.42, sb.yaw, "free"))
    ref_rep = check_layout(ref)
    assert not ref_rep.ok  # the cushion's box is inside the sofa's, and rests on no top
    var = make_variant(ref, VariantSpec("rc_bad", 31, RearrangePlan()))
    rep = check_layout(var)
    assert new_problems(ref_rep, rep) == []
    assert {(c["a"], c["b"]) for c in rep.collisions} == {(c["a"], c["b"]) for c in ref_rep.collisions}
    # the cushion rests on the sofa alone (free_rests): it keeps its place on it, wherever the sofa went
    assert np.allclose(_relative(sofa, ref.object(900)), _relative(var.object(sofa.id), var.object(900)), atol=1e-6)


def test_rearrange_needs_rooms(rc):
    bare = rc.copy()
    bare.stage.rooms, bare.stage.openings, bare.stage.walls = [], [], []
    with pytest.raises(Exception, match="rooms"):
        rearrange(bare, "x", 1, RearrangePlan(floor_moves=1, surface_moves=0, wall_moves=0, nudges=0, added=0, removed=0))


# ---------------------------------------------------------------------------------------------
# lighting configs


def _config(tmp_path, doc, name="t.lighting_config.json") -> Path:
    p = tmp_path / name
    p.write_text(json.dumps(doc) if not isinstance(doc, str) else doc)
    return p


def test_lighting_config_by_hand(tmp_path):
    p = _config(tmp_path, {"lights": {
        "0": {"type": "point", "position": [1.0, 2.3, -0.5], "intensity": 1.2, "color": [1, 1, 0.95]},
        "1": {"position": [-2.0, 0.9, 3.0], "intensity": -0.4},  # no type: point; negative: habitat's fake shadow
        "2": {"type": "directional", "direction": [0.0, -1.0, 1.0], "color": [0.5, 0.5, 0.5]},
        "3": {"type": "point", "position": [0.0, 1.0, 0.0], "position_model": "camera"},
    }, "positive_intensity_scale": 2.0})
    lights = read_lighting_config(p)
    assert [lt.id for lt in lights] == ["0", "1", "2", "3"]
    # (x, y, z)_habitat -> (x, -z, y)_ours, by hand
    assert lights[0].position == pytest.approx((1.0, 0.5, 2.3))
    assert lights[1].position == pytest.approx((-2.0, -3.0, 0.9))
    assert lights[2].direction == pytest.approx((0.0, -1.0, -1.0)) and lights[2].position is None
    assert lights[3].position == pytest.approx((0.0, 0.0, 1.0)) and lights[3].position_model == "camera"
    assert [lt.type for lt in lights] == ["point", "point", "directional", "point"]
    assert lights[0].intensity == pytest.approx(2.4)  # times the file's positive scale
    assert lights[1].intensity == pytest.approx(-0.4)  # the negative scale defaults to 1
    assert lights[0].color == (1.0, 1.0, 0.95) and lights[1].color == (1.0, 1.0, 1.0)


@pytest.mark.parametrize("doc, field", [
    ([1, 2], "(top level)"),
    ({"lights": [1]}, "lights"),
    ({"lights": {"7": "lamp"}}, "lights.7"),
    ({"lights": {"7": {"type": "point", "intensity": 1.0}}}, "lights.7.position"),
    ({"lights": {"7": {"intensity": 1.0}}}, "lights.7.position"),
    ({"lights": {"7": {"type": "point", "position": [1, "a", 2]}}}, "lights.7.position[1]"),
    ({"lights": {"7": {"type": "point", "position": [1, 2]}}}, "lights.7.position"),
    ({"lights": {"7": {"type": "point", "position": [1, 2, 3], "intensity": "bright"}}}, "lights.7.intensity"),
    ({"lights": {"7": {"type": "point", "position": [1, 2, 3], "intensity": float("nan")}}}, "lights.7.intensity"),
    ({"lights": {"7": {"type": "area", "position": [1, 2, 3]}}}, "lights.7.type"),
    ({"lights": {"7": {"type": "point", "position": [1, 2, 3], "color": [1, -1, 1]}}}, "lights.7.color[1]"),
    ({"lights": {"7": {"type": "point", "position": [1, 2, 3], "position_model": "moon"}}}, "lights.7.position_model"),
    ({"lights": {}, "positive_intensity_scale": -1}, "positive_intensity_scale"),
])
def test_bad_lighting_config_names_file_and_field(tmp_path, doc, field):
    p = _config(tmp_path, doc)
    with pytest.raises(SceneFormatError) as e:
        read_lighting_config(p)
    assert e.value.field == field and e.value.file == str(p)
    assert str(e.value).startswith(f"{p}: {field}: ") and "\n" not in str(e.value)


def test_malformed_lighting_json(tmp_path):
    p = _config(tmp_path, "{not json")
    with pytest.raises(SceneFormatError, match="not valid JSON") as e:
        read_lighting_config(p)
    assert e.value.file == str(p)


def test_color_temperature_of_black_bodies():
    # McCamy's fit against Helland's black-body colours (synth.scene.lighting): within 5 %; white is D65
    for kelvin in (2000.0, 2700.0, 4000.0, 6500.0, 9000.0):
        assert color_temperature(kelvin_to_rgb(kelvin)) == pytest.approx(kelvin, rel=0.05)
    assert color_temperature((1.0, 1.0, 1.0)) == pytest.approx(6504.0, abs=10)


def _h(v):  # ours -> habitat: C^T, by hand: (x, y, z) -> (x, z, -y)
    return [v[0], v[2], -v[1]]


def test_fixtures_for_imported_by_hand(rc):
    st = rc.stage
    top = st.floor_z + st.ceiling_height
    lamps = [o for o in rc.objects if o.cls == "floor_lamp"]
    lb = object_box(lamps[0])
    living, kitchen = st.room("living"), st.room("kitchen")
    lc = ((living.rect[0] + living.rect[2]) / 2, (living.rect[1] + living.rect[3]) / 2)
    kc = ((kitchen.rect[0] + kitchen.rect[2]) / 2, (kitchen.rect[1] + kitchen.rect[3]) / 2)
    near_lamp = (lb.center[0] + lb.size[0] / 2 + 0.1, lb.center[1], lb.zmax - 0.2)  # 0.1 m beside its box (axis-aligned: yaw k*90)
    doc = {"lights": {
        "a": {"position": _h(near_lamp), "intensity": 0.8, "color": list(kelvin_to_rgb(2700.0))},
        "b": {"position": _h((lc[0], lc[1], top - 0.2)), "intensity": 1.0},  # in the upper 30 %: ceiling
        "c": {"position": _h((kc[0], kc[1], top + 0.4)), "intensity": 1.0},  # above the ceiling mesh: put 10 cm below it
        "d": {"position": _h((lc[0] + 0.5, lc[1], 1.2)), "intensity": 1.0},  # a fill light: no fixture
        "e": {"position": _h((kc[0], kc[1], top - 0.2)), "intensity": -0.5},  # negative: no fixture
        "f": {"type": "directional", "direction": [0, -1, 0]},
    }}
    lights = parse_lighting_config(doc)
    roles = assign_lights(rc, lights)
    assert roles["a"] == f"lamp:{lamps[0].id}" and roles["b"] == "ceiling" and roles["c"] == "ceiling"
    assert all(roles[k].startswith("ignored") for k in "def")
    fx = fixtures_for_imported(rc, lights)
    by_id = {f.id: f for f in fx}
    la = by_id[f"L{lamps[0].id}"]
    assert la.kind == "lamp" and la.object == lamps[0].id and la.position == pytest.approx(near_lamp, abs=1e-4)
    assert la.power == pytest.approx(80.0)  # 100 W per unit of intensity (nominal)
    assert la.color_temperature == pytest.approx(2700.0, rel=0.05)  # the colour of a 2700 K black body
    # the other lamp has no light: one at 85 % of its height over its box centre
    ob = object_box(lamps[1])
    assert by_id[f"L{lamps[1].id}"].position == pytest.approx((ob.center[0], ob.center[1], ob.zmin + 0.85 * ob.size[2]), abs=1e-4)
    assert by_id["Hb"].position == pytest.approx((lc[0], lc[1], top - 0.2)) and by_id["Hb"].room == "living"
    assert by_id["Hb"].object is None and 6000 < by_id["Hb"].color_temperature < 7000  # white ~ D65
    assert by_id["Hc"].position == pytest.approx((kc[0], kc[1], top - 0.1)) and by_id["Hc"].room == "kitchen"
    # rooms without a ceiling light get a placed one at the centre, 10 cm below the ceiling
    placed = {f.room: f for f in fx if f.id.startswith("P_")}
    assert set(placed) == {"bedroom", "hallway", "bathroom"}
    for name, f in placed.items():
        r = st.room(name)
        assert f.position == pytest.approx(((r.rect[0] + r.rect[2]) / 2, (r.rect[1] + r.rect[3]) / 2, top - 0.1))
    windows = [f for f in fx if f.kind == "window"]
    assert len(windows) == sum(op.kind == "window" for op in st.openings)
    assert len(fx) == 2 + 2 + 3 + len(windows)


def test_lamp_fixtures_follow_their_lamps(rc):
    lamp = next(o for o in rc.objects if o.cls == "floor_lamp")
    lb = object_box(lamp)
    light = (lb.center[0] + 0.05, lb.center[1] - 0.03, lb.zmax + 0.1)
    top = rc.stage.floor_z + rc.stage.ceiling_height
    lv = rc.stage.room("living")
    doc = {"lights": {"a": {"position": _h(light)},
                      "b": {"position": _h(((lv.rect[0] + lv.rect[2]) / 2, (lv.rect[1] + lv.rect[3]) / 2, top - 0.2))}}}
    ref = rc.copy()
    ref.fixtures = fixtures_for_imported(ref, parse_lighting_config(doc))
    assert layout_fixtures(ref) == ref.fixtures  # a layout's own fixtures come back unchanged
    var = rearrange(ref, "lit", 5, RearrangePlan(floor_moves=40, surface_moves=0, wall_moves=0, nudges=0, added=0, removed=0))
    moved = var.object(lamp.id)
    assert moved.position != lamp.position  # the plan moves every floor object it can
    fx = {f.id: f for f in var.fixtures}
    # the lamp's light keeps its place relative to the lamp
    rel = np.linalg.inv(lamp.matrix()) @ np.array([*light, 1.0])
    want = moved.matrix() @ rel
    assert fx[f"L{lamp.id}"].position == pytest.approx(tuple(want[:3]), abs=2e-4) and fx[f"L{lamp.id}"].object == lamp.id
    # the stage's ceiling lights stay
    for f in ref.fixtures:
        if f.kind == "ceiling" and f.object is None:
            assert fx[f.id] == f


def test_builtin_fixtures_unchanged():
    apt0 = load_layout("apt_0")
    assert layout_fixtures(apt0) == apt0.fixtures
    assert layout_fixtures(apt0, previous=apt0) == apt0.fixtures


# ---------------------------------------------------------------------------------------------
# camera paths on an imported layout


@pytest.mark.slow
def test_camera_paths_plan_on_an_imported_layout(rc, rc_variant):
    from synth.paths.mapping import plan_mapping_path
    from synth.paths.query import plan_query_path

    q = plan_query_path([rc, rc_variant], frames=300, seed=1)
    assert len(q) == 300
    m = plan_mapping_path(rc, frames=2400, seed=1)
    assert len(m) == 2400


# ---------------------------------------------------------------------------------------------
# the ReplicaCAD-shaped fixture, imported with derived rooms


def _fixture_module():
    here = str(Path(__file__).resolve().parents[2])
    if here not in sys.path:
        sys.path.insert(0, here)
    import replicacad_fixture  # noqa: PLC0415

    return replicacad_fixture


@pytest.fixture(scope="module")
def fx_layout(tmp_path_factory):
    F = _fixture_module()
    from synth.sources.replicacad.importer import load_replicacad

    root = F.make_fixture(tmp_path_factory.mktemp("rcad_fixture"))
    lay = load_replicacad(root, "apt_0")
    assert lay.stage.rooms  # the import derives the stage's rooms
    return F, root, lay


def test_fixture_lighting_config_positions(fx_layout):
    F, root, _ = fx_layout
    lights = read_lighting_config(root / "configs/lighting/frl_apartment_stage.lighting_config.json")
    assert {lt.id: lt.position for lt in lights} == {k: pytest.approx(v) for k, v in F.LIGHTS.items()}
    assert {lt.id: lt.intensity for lt in lights} == pytest.approx(F.LIGHT_INTENSITY)
    neg = read_lighting_config(root / "configs/lighting/frl_apartment_1.lighting_config.json")
    assert [lt.intensity for lt in neg] == pytest.approx([v[1] for v in F.LIGHTS_1.values()])


def test_fixture_fixtures(fx_layout):
    F, _, lay = fx_layout
    lamp = next(o for o in lay.objects if o.cls == "floor_lamp")
    fx = {f.id: f for f in lay.fixtures}
    # light "2" sits 0.12 m above the lamp's shade (box top 1.98): the lamp's light
    assert fx[f"L{lamp.id}"].position == pytest.approx(F.LIGHTS["2"], abs=1e-4)
    # lights "0" and "1" at z 2.3 of a 2.5 m room: ceiling lights of rooms A and B; no room is left unlit
    assert fx["H0"].position == pytest.approx(F.LIGHTS["0"], abs=1e-4)
    assert fx["H1"].position == pytest.approx(F.LIGHTS["1"], abs=1e-4)
    assert fx["H0"].room != fx["H1"].room and not any(k.startswith("P_") for k in fx)
    assert sum(f.kind == "window" for f in fx.values()) == 1


def test_fixture_variant(fx_layout):
    _, _, lay = fx_layout
    var = make_variant(lay, VariantSpec("apt_v", 7, RearrangePlan()))
    rep, ref_rep = check_layout(var), check_layout(lay)
    # the fixture's cushion lies on the sofa's seat, inside the sofa's box (support "free"), as in
    # real scans: the reference does not check clean, and the variant may add no problem to it
    assert new_problems(ref_rep, rep) == [], rep.to_dict()
    assert ref_rep.ok or {u["id"] for u in rep.unsupported} <= {u["id"] for u in ref_rep.unsupported}
    st = change_stats(lay, var)
    ranges = scaled_ranges(lay)
    print(f"\nfixture apt_0 -> {var.name} (attempt {var.meta['attempt']}):", {k: st[k] for k in ranges}, "ranges:", ranges)
    for k, (lo, hi) in ranges.items():
        assert lo <= st[k] <= hi, (k, st[k], (lo, hi))
    again = make_variant(lay, VariantSpec("apt_v", 7, RearrangePlan()))
    assert layout_to_dict(again) == layout_to_dict(var)
    ref_ids = {o.id for o in lay.objects}
    templates = {(o.asset, o.cls, o.size, o.box_offset, o.scale, o.params.get("template")) for o in lay.objects}
    for o in var.objects:
        if o.id not in ref_ids:
            assert (o.asset, o.cls, o.size, o.box_offset, o.scale, o.params.get("template")) in templates
    # camera paths plan on the imported layout and its variant
    from synth.paths.mapping import plan_mapping_path
    from synth.paths.query import plan_query_path

    assert len(plan_query_path([lay, var], frames=200, seed=1)) == 200
    assert len(plan_mapping_path(lay, frames=900, seed=1)) == 900
