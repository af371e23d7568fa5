"""Camera paths in rooms that are polygons (an L-shaped room, an open plan split into rooms), and a
planned path that checks with the clearance the planner reported.

The geometry the assertions use (point-in-polygon, distances to the rooms' edges and to the object
footprints) is computed here, not with the planner's grid or ``synth.paths.clearance``.
"""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
from matplotlib.path import Path as MplPath

from synth.cli import main as synth_main
from synth.paths.clearance import clearance_report, path_clearance, wall_segments
from synth.paths.files import load_path
from synth.paths.mapping import plan_mapping_path
from synth.paths.query import plan_query_path
from synth.scene.model import Layout, ObjectInstance, Opening, Room, Stage, Wall, object_box, save_layout

L_SHAPE = ((0.0, 0.0), (6.0, 0.0), (6.0, 2.5), (2.5, 2.5), (2.5, 6.0), (0.0, 6.0))
TOL = 1e-3


def _obj(oid: int, cls: str, xy, size) -> ObjectInstance:
    return ObjectInstance(oid, cls, f"proc:{cls}", (xy[0], xy[1], 0.0), (1.0, 0.0, 0.0, 0.0), size, (0.0, 0.0, size[2] / 2))


def l_layout(name: str = "l_room") -> Layout:
    """One L-shaped room (6 x 6 m rect, its north-east 3.5 x 3.5 m quarter missing) and two objects."""
    room = Room("ell", "living", (0.0, 0.0, 6.0, 6.0), L_SHAPE)
    walls = [Wall(f"W{k}", a, b, 0.1, 2.6) for k, (a, b) in enumerate(zip(L_SHAPE, L_SHAPE[1:] + L_SHAPE[:1]))]
    objs = [_obj(1, "dining_table", (1.2, 1.2), (0.8, 0.8, 0.75)), _obj(2, "sofa", (4.8, 0.6), (1.6, 0.8, 0.8))]
    return Layout(name, Stage(2.6, [room], walls, []), objs)


def open_plan_layout() -> Layout:
    """An open plan: a rectangular kitchen polygon and an L-shaped living polygon sharing the edge
    x = 4, y 0..3 with no wall or door between them; a bedroom (rect) behind a door off the living room."""
    kitchen = ((0.0, 0.0), (4.0, 0.0), (4.0, 3.0), (0.0, 3.0))
    living = ((4.0, 0.0), (8.0, 0.0), (8.0, 5.0), (6.0, 5.0), (6.0, 3.0), (4.0, 3.0))
    rooms = [Room("kitchen", "kitchen", (0.0, 0.0, 4.0, 3.0), kitchen), Room("living", "living", (4.0, 0.0, 8.0, 5.0), living),
             Room("bed", "bedroom", (8.1, 0.0, 11.0, 3.0))]
    walls = [Wall("W_bed", (8.05, 0.0), (8.05, 3.0), 0.1, 2.6)]
    door = Opening("D0", "door", "W_bed", 1.5, 0.9, 0.0, 2.0, ("living", "bed"))
    objs = [_obj(1, "dining_table", (2.0, 1.5), (1.0, 0.7, 0.75)), _obj(2, "bed", (9.8, 1.5), (1.4, 2.0, 0.5))]
    return Layout("open_plan", Stage(2.6, rooms, walls, [door]), objs)


def seg_dist(p: np.ndarray, a, b) -> np.ndarray:
    a, b = np.asarray(a, float), np.asarray(b, float)
    ab = b - a
    t = np.clip(((p - a) @ ab) / (ab @ ab), 0.0, 1.0)
    return np.hypot(*(p - a - t[:, None] * ab).T)


def footprint_dist(p: np.ndarray, box) -> np.ndarray:
    c, s = math.cos(box.yaw), math.sin(box.yaw)
    d = p - np.asarray(box.center[:2])
    lx, ly = d[:, 0] * c + d[:, 1] * s, -d[:, 0] * s + d[:, 1] * c
    return np.hypot(np.maximum(np.abs(lx) - box.size[0] / 2, 0.0), np.maximum(np.abs(ly) - box.size[1] / 2, 0.0))


def in_poly(p: np.ndarray, poly) -> np.ndarray:
    return MplPath(np.asarray(poly)).contains_points(p, radius=1e-6) | MplPath(np.asarray(poly)).contains_points(p, radius=-1e-6)


# ---------------------------------------------------------------------------------------------
# an L-shaped room


@pytest.fixture(scope="module")
def l_query():
    return plan_query_path([l_layout()], frames=500, seed=0)


def test_query_path_stays_in_the_l_and_clear_of_its_edges(l_query):
    lay = l_layout()
    xy = l_query.positions[:, :2]
    assert in_poly(xy, L_SHAPE).all()
    # the missing quarter of the rect (x > 2.5 and y > 2.5) is outside the room: never entered,
    # not even within the clearance
    assert not ((xy[:, 0] > 2.5 - 0.3 + TOL) & (xy[:, 1] > 2.5 - 0.3 + TOL)).any()
    edges = np.min([seg_dist(xy, a, b) for a, b in zip(L_SHAPE, L_SHAPE[1:] + L_SHAPE[:1])], axis=0)
    objs = np.min([footprint_dist(xy, object_box(o)) for o in lay.objects], axis=0)
    clear = np.minimum(edges, objs)
    assert clear.min() >= 0.3 - TOL
    # both arms of the L are walked
    assert (xy[:, 0] > 3.5).sum() >= 20 and (xy[:, 1] > 3.5).sum() >= 20
    # planner's report = checker = the geometry here
    chk = path_clearance(l_query, lay)
    assert chk.min() == pytest.approx(l_query.meta["stats"]["min_clearance_m"], abs=1e-4)
    assert np.allclose(chk, clear, atol=1e-6)


def test_l_room_walls_are_its_polygon_edges():
    segs = wall_segments(l_layout().stage)
    got = sorted(tuple(np.round(s.ravel(), 6)) for s in segs)
    want = sorted(tuple(np.round(np.ravel([a, b]), 6)) for a, b in zip(L_SHAPE, L_SHAPE[1:] + L_SHAPE[:1]))
    assert got == want


def test_mapping_sweeps_are_clipped_to_the_l():
    lay = l_layout()
    p = plan_mapping_path(lay, frames=1500, seed=0)
    xy = p.positions[:, :2]
    assert in_poly(xy, L_SHAPE).all()
    assert not ((xy[:, 0] > 2.5 - 0.3 + TOL) & (xy[:, 1] > 2.5 - 0.3 + TOL)).any()
    # sweeps reach the far end of both arms (along x in the south arm, along y in the west arm)
    assert xy[:, 0].max() > 5.4 and xy[:, 1].max() > 5.4
    assert path_clearance(p, lay).min() == pytest.approx(p.meta["stats"]["min_clearance_m"], abs=1e-4)
    assert p.meta["stats"]["min_clearance_m"] >= 0.3 - 1e-4
    assert p.meta["stats"]["rooms"] == ["ell"]


# ---------------------------------------------------------------------------------------------
# an open plan: polygon rooms that share an edge have no wall between them


def test_open_plan_shared_edge_is_open_and_the_door_is_cut():
    segs = wall_segments(open_plan_layout().stage)
    on_shared = [s for s in segs if np.allclose(s[:, 0], 4.0, atol=1e-9) and s[:, 1].max() <= 3.0 + 1e-9]
    assert on_shared == []  # x = 4, y 0..3: the kitchen/living boundary
    # the living room's east edge x = 8 is wall except the door gap y 1.05..1.95
    east = sorted(tuple(sorted(s[:, 1])) for s in segs if np.allclose(s[:, 0], 8.0, atol=1e-9))
    assert np.allclose(east, [(0.0, 1.05), (1.95, 5.0)], atol=1e-6)


def test_query_path_crosses_the_open_plan_and_the_door():
    lay = open_plan_layout()
    p = plan_query_path([lay], frames=1200, seed=0)
    xy = p.positions[:, :2]
    assert p.meta["stats"]["rooms"] and set(p.meta["stats"]["rooms"]) == {"kitchen", "living", "bed"}
    kitchen, living = lay.stage.rooms[0].polygon, lay.stage.rooms[1].polygon
    bed = MplPath(np.array([(8.1, 0.0), (11.0, 0.0), (11.0, 3.0), (8.1, 3.0)]))
    door_gap = (np.abs(xy[:, 0] - 8.05) <= 0.06) & (np.abs(xy[:, 1] - 1.5) <= 0.45)
    inside = in_poly(xy, kitchen) | in_poly(xy, living) | bed.contains_points(xy, radius=1e-6) | bed.contains_points(xy, radius=-1e-6) | door_gap
    assert inside.all()
    # it walks from the kitchen to the living room across x = 4 (no door there)
    assert ((xy[:-1, 0] < 4.0) != (xy[1:, 0] < 4.0)).any()
    chk = path_clearance(p, lay)
    assert chk.min() >= 0.3 - 1e-4
    assert chk.min() == pytest.approx(p.meta["stats"]["min_clearance_m"], abs=1e-4)
    # the polygons' outer edges (not the shared one) are kept 0.3 m away
    outer = [((0, 0), (4, 0)), ((0, 3), (0, 0)), ((4, 3), (0, 3)), ((4, 0), (8, 0)), ((8, 5), (6, 5)), ((6, 5), (6, 3)),
             ((6, 3), (4, 3))]
    m = in_poly(xy, kitchen) | in_poly(xy, living)
    d = np.min([seg_dist(xy[m], a, b) for a, b in outer], axis=0)
    assert d.min() >= 0.3 - TOL


def test_outside_the_polygon_scores_zero_with_a_reason():
    lay = l_layout()
    from synth.paths.model import CameraPath

    P = np.tile(np.eye(4), (2, 1, 1))
    P[0, :3, 3] = (4.5, 4.5, 1.5)  # in the rect, outside the L
    P[1, :3, 3] = (1.5, 4.5, 1.5)  # in the west arm
    rep = clearance_report(CameraPath("two", P, 30.0, {"planner": {"clearance_m": 0.3}}), lay)
    assert rep["frames_outside"] == 1 and rep["min_clearance_m"] == 0.0 and rep["min_frame"] == 0
    assert rep["nearest"]["class"] == "outside every room"
    assert rep["frames_below"] == 1


# ---------------------------------------------------------------------------------------------
# plan then check: the same clearance (a layout file named like a built-in one)


@pytest.mark.slow
def test_cli_plan_then_check_agree_on_a_layout_file_named_like_a_builtin(tmp_path, capsys):
    lay = l_layout(name="apt_0")  # an imported ReplicaCAD apartment is named apt_0 too
    f = save_layout(lay, tmp_path / "apt_0.yaml")
    out = tmp_path / "q.txt"
    assert synth_main(["path", "plan", "query", "--layouts", str(f), "--frames", "300", "--out", str(out)]) == 0
    planned = load_path(out)
    reported = planned.meta["stats"]["min_clearance_m"]
    assert reported >= 0.3 - 1e-4
    capsys.readouterr()
    rc = synth_main(["path", "check", str(out), "--json"])
    rep = json.loads(capsys.readouterr().out)
    assert rc == 0 and rep["ok"], rep
    assert rep["layouts"][0]["min_clearance_m"] == pytest.approx(reported, abs=0.01)
    assert rep["layouts"][0]["frames_outside"] == 0
    # the recorded layout is the file, not the built-in apt_0
    assert planned.meta["layouts"] == [str(f.resolve())]
    # and a built-in name stays a name
    assert synth_main(["path", "plan", "mapping", "--layout", "apt_0", "--frames", "3000", "--out", str(tmp_path / "m.txt")]) == 0
    assert load_path(tmp_path / "m.txt").meta["layouts"] == ["apt_0"]
