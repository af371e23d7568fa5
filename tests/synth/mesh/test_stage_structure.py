"""synth.mesh.stage_structure: structure (floor, ceiling, walls, openings, rooms) from one stage mesh.

Every stage here is built by the test from boxes or quads in our frame (Z up), and every expected
number is written out by hand from that construction (the same two-room stage as the ReplicaCAD
fixture, but not imported from it):

    floor slab z [-0.1, 0], ceiling slab z [2.5, 2.6], both over x [-0.1, 7.2] y [-0.1, 3.1];
    walls 0.1 thick, z 0..2.5: south x[-0.1,7.2] y[-0.1,0]; north x[-0.1,7.2] y[3.0,3.1] with a window
    x[1.0,2.2] z[0.9,2.0]; west x[-0.1,0] y[0,3]; east x[7.1,7.2] y[0,3]; interior x[4.0,4.1] y[0,3]
    with a door y[1.0,1.9] z[0,2.1]. Rooms: A x[0,4] y[0,3], B x[4.1,7.1] y[0,3].
"""

from __future__ import annotations

import logging
import math

import numpy as np
import pytest
import trimesh

from vrformats.boxes import CEILING_ID_BASE, FLOOR_ID_BASE, WALL_ID_BASE
from vrformats.errors import SceneFormatError
from synth.scene.model import Stage, structure_boxes
from synth.mesh.stage_structure import DEFAULT_THICKNESS, derive_structure, face_ids
from meshes import box_mesh

TOL = 0.05  # m
YAW_TOL = math.radians(2.0)


FLOOR_SLAB = ((-0.1, -0.1, -0.1), (7.2, 3.1, 0.0))
CEILING_SLAB = ((-0.1, -0.1, 2.5), (7.2, 3.1, 2.6))
# wall name -> boxes it is built from (holes cut), and the whole wall's box (x0, y0, x1, y1)
WALL_PIECES = {
    "south": [((-0.1, -0.1, 0.0), (7.2, 0.0, 2.5))],
    "north": [((-0.1, 3.0, 0.0), (1.0, 3.1, 2.5)), ((2.2, 3.0, 0.0), (7.2, 3.1, 2.5)),
              ((1.0, 3.0, 0.0), (2.2, 3.1, 0.9)), ((1.0, 3.0, 2.0), (2.2, 3.1, 2.5))],
    "west": [((-0.1, 0.0, 0.0), (0.0, 3.0, 2.5))],
    "east": [((7.1, 0.0, 0.0), (7.2, 3.0, 2.5))],
    "interior": [((4.0, 0.0, 0.0), (4.1, 1.0, 2.5)), ((4.0, 1.9, 0.0), (4.1, 3.0, 2.5)),
                 ((4.0, 1.0, 2.1), (4.1, 1.9, 2.5))],
}
# expected wall boxes: centre (x, y, z), size (length, thickness, height), yaw (mod pi)
WALL_BOXES = {
    "south": ((3.55, -0.05, 1.25), (7.3, 0.1, 2.5), 0.0),
    "north": ((3.55, 3.05, 1.25), (7.3, 0.1, 2.5), 0.0),
    "west": ((-0.05, 1.5, 1.25), (3.0, 0.1, 2.5), math.pi / 2),
    "east": ((7.15, 1.5, 1.25), (3.0, 0.1, 2.5), math.pi / 2),
    "interior": ((4.05, 1.5, 1.25), (3.0, 0.1, 2.5), math.pi / 2),
}
ROOM_A, ROOM_B = (0.0, 0.0, 4.0, 3.0), (4.1, 0.0, 7.1, 3.0)


def two_room_stage(extra=()) -> trimesh.Trimesh:
    boxes = [FLOOR_SLAB, CEILING_SLAB] + [b for pcs in WALL_PIECES.values() for b in pcs] + list(extra)
    return trimesh.util.concatenate([box_mesh(*b) for b in boxes])


def _stage(s) -> Stage:
    return Stage(ceiling_height=s.ceiling_height, rooms=s.rooms, walls=s.walls, openings=s.openings, floor_z=s.floor_z)


def _yaw_diff(a, b) -> float:
    d = (a - b) % math.pi
    return min(d, math.pi - d)


def _match_walls(stage: Stage, expected: dict) -> dict[str, int]:
    """Expected wall name -> index of the derived wall whose box matches it (centre, size, yaw)."""
    boxes = [b for b in structure_boxes(stage) if b.kind == "wall"]
    assert len(boxes) == len(expected), [(b.center, b.size) for b in boxes]
    out = {}
    for name, (c, size, yaw) in expected.items():
        k = int(np.argmin([np.linalg.norm(np.subtract(b.center, c)) for b in boxes]))
        b = boxes[k]
        assert np.allclose(b.center, c, atol=TOL), (name, b.center, c)
        assert np.allclose(b.size, size, atol=TOL), (name, b.size, size)
        assert _yaw_diff(b.yaw, yaw) < YAW_TOL, (name, b.yaw, yaw)
        assert b.id == WALL_ID_BASE + k
        out[name] = k
    assert len(set(out.values())) == len(expected)
    return out


def _opening_centre(stage: Stage, op) -> np.ndarray:
    w = stage.wall(op.wall)
    d = np.subtract(w.end, w.start) / w.length
    xy = np.asarray(w.start) + d * op.offset
    return np.array([xy[0], xy[1], stage.floor_z + op.bottom + op.height / 2.0])


def _check_openings(stage: Stage, walls: dict[str, int], transform=lambda p: p, floor_z=0.0):
    doors = [o for o in stage.openings if o.kind == "door"]
    windows = [o for o in stage.openings if o.kind == "window"]
    assert len(doors) == 1 and len(windows) == 1
    door, win = doors[0], windows[0]
    assert door.id == "D0" and win.id == "N0"
    assert door.wall == stage.walls[walls["interior"]].id
    assert abs(door.width - 0.9) <= TOL and abs(door.height - 2.1) <= TOL and door.bottom == 0.0
    assert sorted(door.rooms) == sorted(r.name for r in stage.rooms)  # connects both rooms
    assert np.allclose(_opening_centre(stage, door), transform(np.array([4.05, 1.45, 1.05])) + [0, 0, floor_z], atol=TOL)
    assert win.wall == stage.walls[walls["north"]].id
    assert abs(win.width - 1.2) <= TOL and abs(win.bottom - 0.9) <= TOL and abs(win.height - 1.1) <= TOL
    assert np.allclose(_opening_centre(stage, win), transform(np.array([1.6, 3.05, 1.45])) + [0, 0, floor_z], atol=TOL)
    return door, win


# --------------------------------------------------------------------------------------------


def test_two_room_stage_from_boxes():
    s = derive_structure(two_room_stage(), "two_room.glb")
    assert abs(s.floor_z - 0.0) <= 1e-6 and abs(s.ceiling_height - 2.5) <= 1e-6
    stage = _stage(s)
    walls = _match_walls(stage, WALL_BOXES)
    assert [w.id for w in s.walls] == [f"W{k}" for k in range(5)]
    assert all(w.thickness == pytest.approx(0.1, abs=1e-3) for w in s.walls)
    assert set(s.report["wall_thickness_source"].values()) == {"paired faces"}

    # rooms: A then B (ordered by position); floor and ceiling boxes over each room rect
    assert [r.name for r in s.rooms] == ["room_0", "room_1"] and {r.type for r in s.rooms} == {"room"}
    assert np.allclose(s.rooms[0].rect, ROOM_A, atol=TOL) and np.allclose(s.rooms[1].rect, ROOM_B, atol=TOL)
    boxes = {b.id: b for b in structure_boxes(stage)}
    for k, (x0, y0, x1, y1) in enumerate((ROOM_A, ROOM_B)):
        f, c = boxes[FLOOR_ID_BASE + k], boxes[CEILING_ID_BASE + k]
        assert np.allclose(f.center, ((x0 + x1) / 2, (y0 + y1) / 2, -0.05), atol=TOL)
        assert np.allclose(f.size[:2], (x1 - x0, y1 - y0), atol=TOL)
        assert np.allclose(c.center, ((x0 + x1) / 2, (y0 + y1) / 2, 2.55), atol=TOL)
        assert np.allclose(c.size[:2], (x1 - x0, y1 - y0), atol=TOL)
    assert s.report["rooms"]["fill_ratio"] == {"room_0": pytest.approx(1.0, abs=0.02), "room_1": pytest.approx(1.0, abs=0.02)}

    door, win = _check_openings(stage, walls)
    assert door.rooms == ("room_0", "room_1")
    assert win.rooms == ("room_0",)  # the window's inner side is room A (x 1.0..2.2)


def test_yawed_and_translated_stage(caplog):
    yaw, shift = math.radians(30.0), np.array([1.5, -2.0, 0.25])
    c, s_ = math.cos(yaw), math.sin(yaw)
    R = np.array([[c, -s_, 0.0], [s_, c, 0.0], [0.0, 0.0, 1.0]])

    def move(p):
        return R @ np.asarray(p, float) + shift * [1, 1, 0]

    mesh = two_room_stage()
    T = np.eye(4)
    T[:3, :3], T[:3, 3] = R, shift
    mesh.apply_transform(T)
    with caplog.at_level(logging.WARNING, logger="synth.mesh.stage_structure"):
        s = derive_structure(mesh, "yawed.glb")
    assert abs(s.floor_z - 0.25) <= 1e-6 and abs(s.ceiling_height - 2.5) <= 1e-6
    expected = {n: (tuple(move(cen) + [0, 0, 0.25]), size, y + yaw) for n, (cen, size, y) in WALL_BOXES.items()}
    stage = _stage(s)
    walls = _match_walls(stage, expected)
    _check_openings(stage, walls, transform=move, floor_z=0.25)

    # rooms are axis-aligned rects: the bounding rectangles of the rotated rooms
    def bounds(rect):
        x0, y0, x1, y1 = rect
        pts = np.array([move((x, y, 0.0))[:2] for x in (x0, x1) for y in (y0, y1)])
        return (*pts.min(axis=0), *pts.max(axis=0))

    got = sorted(r.rect for r in s.rooms)
    want = sorted([bounds(ROOM_A), bounds(ROOM_B)])
    assert len(got) == 2
    for g, w in zip(got, want):
        assert np.allclose(g, w, atol=TOL), (g, w)
    # a rotated 4 x 3 room fills 12 / (4.96 x 4.6) of its bounding rectangle: reported, warned
    fills = s.report["rooms"]["fill_ratio"]
    assert all(0.45 < f < 0.65 for f in fills.values()), fills
    # ... so each room is its polygon (counter-clockwise, within its rect), which its floor fills: no warning
    for r in s.rooms:
        q = np.asarray(r.polygon)
        assert q[:, 0].min() >= r.rect[0] - 1e-6 and q[:, 0].max() <= r.rect[2] + 1e-6
        assert np.dot(q[:, 0], np.roll(q[:, 1], -1)) - np.dot(q[:, 1], np.roll(q[:, 0], -1)) > 0
        assert r.area == pytest.approx(s.report["rooms"]["area_m2"][r.name], rel=0.03)
    assert sorted(round(r.area) for r in s.rooms) == [9, 12]
    assert all(f > 0.95 for f in s.report["rooms"]["outline_fill_ratio"].values()), s.report["rooms"]
    assert "fills" not in caplog.text


def _quad(corners, normal) -> trimesh.Trimesh:
    """One planar quad (two triangles) wound so that its normal is ``normal``."""
    v = np.asarray(corners, float)
    f = np.array([[0, 1, 2], [0, 2, 3]])
    if np.dot(np.cross(v[1] - v[0], v[2] - v[0]), normal) < 0:
        f = f[:, ::-1]
    return trimesh.Trimesh(v, f, process=False)


def _wall_face(axis: str, fixed: float, lo: float, hi: float, normal, holes=()) -> list[trimesh.Trimesh]:
    """A vertical face at x = fixed (axis 'x') or y = fixed (axis 'y') over [lo, hi] x z[0, 2.5],
    with rectangular holes (a, b, z0, z1) cut out, as quads."""
    rects = []
    x = lo
    for a, b, z0, z1 in sorted(holes):
        rects.append((x, a, 0.0, 2.5))
        if z0 > 0:
            rects.append((a, b, 0.0, z0))
        rects.append((a, b, z1, 2.5))
        x = b
    rects.append((x, hi, 0.0, 2.5))

    def pt(u, z):
        return (fixed, u, z) if axis == "x" else (u, fixed, z)

    return [_quad([pt(a, z0), pt(b, z0), pt(b, z1), pt(a, z1)], normal) for a, b, z0, z1 in rects]


def test_walls_modelled_as_single_faces_are_placed_behind_the_face():
    parts = [
        _quad([(0, 0, 0), (7.1, 0, 0), (7.1, 3, 0), (0, 3, 0)], (0, 0, 1)),  # floor, facing up
        _quad([(0, 0, 2.5), (7.1, 0, 2.5), (7.1, 3, 2.5), (0, 3, 2.5)], (0, 0, -1)),  # ceiling, facing down
        *_wall_face("y", 0.0, 0.0, 7.1, (0, 1, 0)),  # south, facing north into the rooms
        *_wall_face("y", 3.0, 0.0, 7.1, (0, -1, 0), holes=[(1.0, 2.2, 0.9, 2.0)]),  # north, window
        *_wall_face("x", 0.0, 0.0, 3.0, (1, 0, 0)),  # west
        *_wall_face("x", 7.1, 0.0, 3.0, (-1, 0, 0)),  # east
        *_wall_face("x", 4.0, 0.0, 3.0, (-1, 0, 0), holes=[(1.0, 1.9, 0.0, 2.1)]),  # interior, facing room A
    ]
    s = derive_structure(trimesh.util.concatenate(parts), "faces.glb")
    # each wall 0.1 thick, behind its face (away from where the face looks)
    expected = {
        "south": ((3.55, -0.05, 1.25), (7.1, 0.1, 2.5), 0.0),
        "north": ((3.55, 3.05, 1.25), (7.1, 0.1, 2.5), 0.0),
        "west": ((-0.05, 1.5, 1.25), (3.0, 0.1, 2.5), math.pi / 2),
        "east": ((7.15, 1.5, 1.25), (3.0, 0.1, 2.5), math.pi / 2),
        "interior": ((4.05, 1.5, 1.25), (3.0, 0.1, 2.5), math.pi / 2),
    }
    assert DEFAULT_THICKNESS == 0.1
    stage = _stage(s)
    walls = _match_walls(stage, expected)
    assert set(s.report["wall_thickness_source"].values()) == {"default"}
    assert s.report["walls"] == {"count": 5, "paired": 0, "default": 5}
    assert len(s.rooms) == 2
    assert np.allclose(s.rooms[0].rect, ROOM_A, atol=TOL) and np.allclose(s.rooms[1].rect, ROOM_B, atol=TOL)
    _check_openings(stage, walls)


def test_result_does_not_depend_on_triangle_order():
    mesh = two_room_stage()
    ref = derive_structure(mesh, "a.glb")
    rng = np.random.default_rng(3)
    faces = np.asarray(mesh.faces)[rng.permutation(len(mesh.faces))]
    faces = np.array([np.roll(f, int(r)) for f, r in zip(faces, rng.integers(0, 3, len(faces)))])  # same winding
    shuffled = trimesh.Trimesh(np.asarray(mesh.vertices), faces, process=False)
    got = derive_structure(shuffled, "b.glb")
    assert (got.floor_z, got.ceiling_height) == (ref.floor_z, ref.ceiling_height)
    assert got.walls == ref.walls and got.openings == ref.openings and got.rooms == ref.rooms


def test_finely_triangulated_stage_gives_the_same_structure():
    mesh = two_room_stage()
    fine = mesh
    for _ in range(3):  # 144 -> 9216 small triangles
        fine = fine.subdivide()
    a, b = derive_structure(mesh, "coarse.glb"), derive_structure(fine, "fine.glb")
    assert len(fine.faces) == 64 * len(mesh.faces)
    assert b.walls == a.walls and b.openings == a.openings and b.rooms == a.rooms


def test_trim_skirting_and_panels_merge_into_their_walls():
    trim = [
        # architraves around the door, 2 cm proud, 8 cm wide, both sides of the interior wall
        ((3.98, 0.92, 0.0), (4.0, 1.0, 2.18)), ((3.98, 1.9, 0.0), (4.0, 1.98, 2.18)), ((3.98, 0.92, 2.1), (4.0, 1.98, 2.18)),
        ((4.1, 0.92, 0.0), (4.12, 1.0, 2.18)), ((4.1, 1.9, 0.0), (4.12, 1.98, 2.18)), ((4.1, 0.92, 2.1), (4.12, 1.98, 2.18)),
        # skirting boards in room A, 1.5 cm proud, 8 cm high
        ((0.0, 0.0, 0.0), (4.0, 0.015, 0.08)), ((0.015, 0.015, 0.0), (0.0, 2.985, 0.08)),
        # a panel on the east wall in room B, 2 cm proud, 0.6 x 1.3 m: its hidden back face lies in the wall
        ((7.08, 1.0, 0.3), (7.1, 1.6, 1.6)),
    ]
    trim = [(tuple(np.minimum(a, b)), tuple(np.maximum(a, b))) for a, b in trim]
    s = derive_structure(two_room_stage(trim), "trim.glb")
    stage = _stage(s)
    walls = _match_walls(stage, WALL_BOXES)
    _check_openings(stage, walls)
    assert s.report["pieces"]["merged_trim"] >= 3
    assert s.report["faces_inside_walls"] >= 1
    assert np.allclose(s.rooms[0].rect, ROOM_A, atol=TOL) and np.allclose(s.rooms[1].rect, ROOM_B, atol=TOL)


def test_face_ids_of_the_box_triangles():
    s = derive_structure(two_room_stage(), "two_room.glb")
    stage = _stage(s)
    walls = _match_walls(stage, WALL_BOXES)
    for name, pieces in WALL_PIECES.items():
        for lo, hi in pieces:
            b = box_mesh(lo, hi)
            ids = face_ids(stage, b.triangles_center, b.face_normals)
            assert (ids == WALL_ID_BASE + walls[name]).all(), (name, lo, hi, ids)

    def slab_ids(lo, hi):
        b = box_mesh(lo, hi)
        return b.triangles_center, b.face_normals, face_ids(stage, b.triangles_center, b.face_normals)

    # floor slab: its top is floor, of the room holding each triangle's centroid (A: x < 4.05);
    # its bottom (facing down at z -0.1) is nothing
    cen, nrm, ids = slab_ids(*FLOOR_SLAB)
    top = nrm[:, 2] > 0.99
    assert top.sum() == 2
    assert list(ids[top]) == [FLOOR_ID_BASE + (0 if x < 4.05 else 1) for x in cen[top, 0]]
    assert (ids[nrm[:, 2] < -0.99] == 0).all()
    # ceiling slab: its underside is ceiling, its top (facing up at 2.6) nothing
    cen, nrm, ids = slab_ids(*CEILING_SLAB)
    under = nrm[:, 2] < -0.99
    assert list(ids[under]) == [CEILING_ID_BASE + (0 if x < 4.05 else 1) for x in cen[under, 0]]
    assert (ids[nrm[:, 2] > 0.99] == 0).all()

    # single probes: a floor triangle in room B, a threshold in the door (floor: nearest room),
    # a face 10 cm in front of a wall (nothing), an architrave standing 2 cm proud of a wall beside
    # the door (wall), a door stop inside the door opening and glass in the window (nothing)
    probes = np.array([[6.0, 1.0, 0.0], [4.05, 1.45, 0.0], [2.0, 1.5, 1.2], [3.99, 0.96, 1.0],
                       [4.05, 1.45, 1.0], [1.6, 3.05, 1.45]])
    normals = np.array([[0, 0, 1.0], [0, 0, 1.0], [1.0, 0, 0], [-1.0, 0, 0], [1.0, 0, 0], [0, -1.0, 0]])
    ids = face_ids(stage, probes, normals)
    assert ids[0] == FLOOR_ID_BASE + 1
    assert ids[1] in (FLOOR_ID_BASE, FLOOR_ID_BASE + 1)
    assert ids[2] == 0
    assert ids[3] == WALL_ID_BASE + walls["interior"]
    assert ids[4] == 0 and ids[5] == 0
    # deterministic: the same inputs give the same ids, in any order
    perm = np.array([3, 5, 1, 0, 4, 2])
    assert (face_ids(stage, probes[perm], normals[perm]) == ids[perm]).all()


def test_no_floor_is_a_scene_format_error():
    walls = [box_mesh(*b) for pcs in WALL_PIECES.values() for b in pcs] + [box_mesh(*CEILING_SLAB)]
    with pytest.raises(SceneFormatError) as e:
        derive_structure(trimesh.util.concatenate(walls), "stages/no_floor.glb")
    msg = str(e.value)
    assert msg.startswith("stages/no_floor.glb: stage: no floor found:") and "\n" not in msg
    assert "up-facing" in msg and "m2" in msg


def test_no_walls_is_a_scene_format_error():
    with pytest.raises(SceneFormatError) as e:
        derive_structure(trimesh.util.concatenate([box_mesh(*FLOOR_SLAB), box_mesh(*CEILING_SLAB)]), "stages/slabs.glb")
    msg = str(e.value)
    assert msg.startswith("stages/slabs.glb: stage: no walls found:") and "\n" not in msg
    assert "vertical" in msg


def test_entrance_door_and_a_terrace_without_a_ceiling():
    """An entrance door in the south wall of room B opens onto a terrace (floor, no ceiling): the
    door has one room, the terrace is no room."""
    pieces = dict(WALL_PIECES)
    pieces["south"] = [((-0.1, -0.1, 0.0), (5.0, 0.0, 2.5)), ((5.9, -0.1, 0.0), (7.2, 0.0, 2.5)),
                       ((5.0, -0.1, 2.1), (5.9, 0.0, 2.5))]
    terrace = ((-0.1, -2.0, -0.1), (7.2, -0.1, 0.0))
    boxes = [FLOOR_SLAB, CEILING_SLAB, terrace] + [b for pcs in pieces.values() for b in pcs]
    s = derive_structure(trimesh.util.concatenate([box_mesh(*b) for b in boxes]), "entrance.glb")
    stage = _stage(s)
    walls = _match_walls(stage, WALL_BOXES)
    assert len(s.rooms) == 2 and s.report["rooms"]["rejected_components"] == {"no ceiling above": 1}
    assert np.allclose(s.rooms[1].rect, ROOM_B, atol=TOL)
    doors = {o.wall: o for o in s.openings if o.kind == "door"}
    assert len(doors) == 2
    entrance = doors[stage.walls[walls["south"]].id]
    assert entrance.rooms == ("room_1",)
    assert abs(entrance.width - 0.9) <= TOL and abs(entrance.height - 2.1) <= TOL
    assert np.allclose(_opening_centre(stage, entrance), (5.45, -0.05, 1.05), atol=TOL)
    assert doors[stage.walls[walls["interior"]].id].rooms == ("room_0", "room_1")
    assert [o.id for o in s.openings] == ["D0", "D1", "N0"]


def test_stage_without_a_ceiling_takes_the_top_of_the_mesh():
    boxes = [FLOOR_SLAB] + [b for pcs in WALL_PIECES.values() for b in pcs]
    s = derive_structure(trimesh.util.concatenate([box_mesh(*b) for b in boxes]), "open.glb")
    assert abs(s.ceiling_height - 2.5) <= 1e-6 and s.report["ceiling"]["source"].startswith("top of the mesh")
    assert len(s.rooms) == 2
    assert np.allclose(s.rooms[0].rect, ROOM_A, atol=TOL) and np.allclose(s.rooms[1].rect, ROOM_B, atol=TOL)
    _match_walls(_stage(s), WALL_BOXES)


def test_derived_stage_serves_layout_checks_and_path_walls():
    from synth.layout.validity import check_layout
    from synth.paths.clearance import wall_segments
    from synth.scene.model import Layout

    stage = _stage(derive_structure(two_room_stage(), "two_room.glb"))
    rep = check_layout(Layout("derived", stage))
    assert rep.ok, rep.to_dict()  # rooms and walls present, the door passable between both rooms
    # path planning's walls: room A's east edge (x = 4.0) and room B's west edge (x = 4.1) are
    # walls except in the door gap y 1.0..1.9
    segs = wall_segments(stage)
    for x in (4.0, 4.1):
        edge = sorted(tuple(sorted(s_[:, 1])) for s_ in segs if np.allclose(s_[:, 0], x, atol=1e-6))
        assert np.allclose(edge, [(0.0, 1.0), (1.9, 3.0)], atol=TOL), (x, edge)


# --------------------------------------------------------------------------------------------
# stairs and raised levels are not walls
#
# One room x[0, 6] y[0, 4], floor slab z[-0.1, 0], ceiling slab z[2.5, 2.6], walls 0.1 thick outside
# it: south with a door x[1.0, 1.9] z[0, 2.1], west with a window y[1.0, 2.2] z[0.9, 2.0], north,
# east. Along the north wall a straight flight (y[3, 4]) of five 0.3 m treads from x 3.5, rising
# 0.17 m each, and the sixth rise to a landing z 1.02 over x[5, 6] y[2.5, 4] in the north-east
# corner, modelled as their visible faces (treads, risers, the flight's south side, the landing's
# top and its west and south fronts). A half-height wall x[1.5, 3.0] y[2.0, 2.1] z[0, 1.1] (a box).

RISE, TREAD, LANDING_Z = 0.17, 0.3, 6 * 0.17
STAIR_WALLS = {
    "south": ((3.0, -0.05, 1.25), (6.2, 0.1, 2.5), 0.0),
    "north": ((3.0, 4.05, 1.25), (6.2, 0.1, 2.5), 0.0),
    "west": ((-0.05, 2.0, 1.25), (4.0, 0.1, 2.5), math.pi / 2),
    "east": ((6.05, 2.0, 1.25), (4.0, 0.1, 2.5), math.pi / 2),
    "low": ((2.25, 2.05, 0.55), (1.5, 0.1, 1.1), 0.0),
}


def stairs_room(stairs=True) -> trimesh.Trimesh:
    H = 2.5
    boxes = [((-0.1, -0.1, -0.1), (6.1, 4.1, 0.0)), ((-0.1, -0.1, H), (6.1, 4.1, H + 0.1)),
             ((-0.1, -0.1, 0.0), (1.0, 0.0, H)), ((1.9, -0.1, 0.0), (6.1, 0.0, H)), ((1.0, -0.1, 2.1), (1.9, 0.0, H)),
             ((-0.1, 0.0, 0.0), (0.0, 1.0, H)), ((-0.1, 2.2, 0.0), (0.0, 4.0, H)),
             ((-0.1, 1.0, 0.0), (0.0, 2.2, 0.9)), ((-0.1, 1.0, 2.0), (0.0, 2.2, H)),
             ((-0.1, 4.0, 0.0), (6.1, 4.1, H)), ((6.0, 0.0, 0.0), (6.1, 4.0, H)),
             ((1.5, 2.0, 0.0), (3.0, 2.1, 1.1))]
    parts = [box_mesh(*b) for b in boxes]
    if stairs:
        for k in range(1, 6):
            x0, z0, z1 = 3.5 + TREAD * (k - 1), RISE * (k - 1), RISE * k
            parts.append(_quad([(x0, 3, z1), (x0 + TREAD, 3, z1), (x0 + TREAD, 4, z1), (x0, 4, z1)], (0, 0, 1)))  # tread
            parts.append(_quad([(x0, 3, z0), (x0, 4, z0), (x0, 4, z1), (x0, 3, z1)], (-1, 0, 0)))  # riser
            parts.append(_quad([(x0, 3, 0), (x0 + TREAD, 3, 0), (x0 + TREAD, 3, z1), (x0, 3, z1)], (0, -1, 0)))  # side
        zl = LANDING_Z
        parts.append(_quad([(5, 2.5, zl), (6, 2.5, zl), (6, 4, zl), (5, 4, zl)], (0, 0, 1)))  # landing
        parts.append(_quad([(5, 3, 5 * RISE), (5, 4, 5 * RISE), (5, 4, zl), (5, 3, zl)], (-1, 0, 0)))  # sixth riser
        parts.append(_quad([(5, 2.5, 0), (5, 3, 0), (5, 3, zl), (5, 2.5, zl)], (-1, 0, 0)))  # landing, west front
        parts.append(_quad([(5, 2.5, 0), (6, 2.5, 0), (6, 2.5, zl), (5, 2.5, zl)], (0, -1, 0)))  # landing, south front
    return trimesh.util.concatenate(parts)


def test_stairs_and_a_landing_are_not_walls_a_half_height_wall_is():
    s = derive_structure(stairs_room(), "stairs.glb")
    assert abs(s.floor_z - 0.0) <= 1e-6 and abs(s.ceiling_height - 2.5) <= 1e-6
    stage = _stage(s)
    walls = _match_walls(stage, STAIR_WALLS)  # the four room walls and the low wall, nothing else
    assert s.walls[walls["low"]].height == pytest.approx(1.1, abs=TOL)
    assert s.report["pieces"]["platform_columns"] > 0
    # no wall box reaches into the stairs or the landing (the room walls only touch them)
    for b in structure_boxes(stage):
        if b.kind == "wall":
            c = np.asarray(b.corners_2d())
            assert not ((c[:, 0] > 3.5 + TOL) & (c[:, 0] < 6.0 - TOL) & (c[:, 1] > 2.5 + TOL) & (c[:, 1] < 4.0 - TOL)).any()
    doors = [o for o in s.openings if o.kind == "door"]
    windows = [o for o in s.openings if o.kind == "window"]
    assert len(doors) == 1 and len(windows) == 1
    door, win = doors[0], windows[0]
    assert door.wall == stage.walls[walls["south"]].id and door.rooms == ("room_0",)
    assert abs(door.width - 0.9) <= TOL and abs(door.height - 2.1) <= TOL and door.bottom == 0.0
    assert np.allclose(_opening_centre(stage, door), (1.45, -0.05, 1.05), atol=TOL)
    assert win.wall == stage.walls[walls["west"]].id
    assert abs(win.width - 1.2) <= TOL and abs(win.bottom - 0.9) <= TOL and abs(win.height - 1.1) <= TOL
    assert np.allclose(_opening_centre(stage, win), (-0.05, 1.6, 1.45), atol=TOL)
    assert len(s.rooms) == 1 and np.allclose(s.rooms[0].rect, (0.0, 0.0, 6.0, 4.0), atol=TOL)


def test_without_the_stairs_rule_the_landing_fronts_would_be_walls(monkeypatch):
    """The stage above exercises the rule: the landing's fronts are 1.02 m high (taller than
    MIN_WALL_HEIGHT) and long enough, so without it they come out as two more walls."""
    from synth.mesh import stage_structure as ss

    monkeypatch.setattr(ss, "_drop_platform_sides", lambda pieces, *a, **k: pieces)
    s = derive_structure(stairs_room(), "stairs.glb")
    boxes = [b for b in structure_boxes(_stage(s)) if b.kind == "wall"]
    assert len(boxes) == len(STAIR_WALLS) + 2
    extra = sorted((round(b.center[0], 2), round(b.center[1], 2)) for b in boxes
                   if min(np.linalg.norm(np.subtract(b.center, c)) for c, _, _ in STAIR_WALLS.values()) > TOL)
    assert np.allclose(extra, [(5.05, 3.25), (5.5, 2.55)], atol=TOL), extra


# --------------------------------------------------------------------------------------------
# rooms as polygons
#
# An L: floor and ceiling over x[0, 6] y[0, 3] and x[0, 3] y[3, 5] (area 24 m2), walls 0.1 thick
# around it. With the notch x[3.1, 6] y[3.1, 5] a second (rectangular) room: floor and ceiling over
# the whole x[0, 6] y[0, 5], walls x[3.0, 3.1] y[3.1, 5] and x[3.0, 6] y[3.0, 3.1] between them.

L_AREA = 24.0


def l_room(notch=False) -> trimesh.Trimesh:
    H = 2.5
    if notch:
        boxes = [((-0.1, -0.1, -0.1), (6.1, 5.1, 0.0)), ((-0.1, -0.1, H), (6.1, 5.1, H + 0.1)),
                 ((6.0, 0.0, 0.0), (6.1, 5.1, H)), ((3.0, 3.0, 0.0), (6.0, 3.1, H)), ((-0.1, 5.0, 0.0), (6.1, 5.1, H))]
    else:
        boxes = [((-0.1, -0.1, -0.1), (6.1, 3.0, 0.0)), ((-0.1, 3.0, -0.1), (3.1, 5.1, 0.0)),
                 ((-0.1, -0.1, H), (6.1, 3.0, H + 0.1)), ((-0.1, 3.0, H), (3.1, 5.1, H + 0.1)),
                 ((6.0, 0.0, 0.0), (6.1, 3.1, H)), ((3.0, 3.0, 0.0), (6.1, 3.1, H)), ((-0.1, 5.0, 0.0), (3.0, 5.1, H))]
    boxes += [((-0.1, -0.1, 0.0), (6.1, 0.0, H)), ((3.0, 3.1, 0.0), (3.1, 5.0, H)), ((-0.1, 0.0, 0.0), (0.0, 5.0, H))]
    return trimesh.util.concatenate([box_mesh(*b) for b in boxes])


def _ccw(q) -> bool:
    q = np.asarray(q, float)
    return np.dot(q[:, 0], np.roll(q[:, 1], -1)) - np.dot(q[:, 1], np.roll(q[:, 0], -1)) > 0


def test_l_shaped_room_is_a_polygon_its_floor_fills(caplog):
    with caplog.at_level(logging.WARNING, logger="synth.mesh.stage_structure"):
        s = derive_structure(l_room(), "l.glb")
    assert len(s.walls) == 6 and len(s.rooms) == 1
    r = s.rooms[0]
    assert np.allclose(r.rect, (0.0, 0.0, 6.0, 5.0), atol=TOL)
    assert r.polygon is not None and _ccw(r.polygon)
    q = np.asarray(r.polygon)
    assert (q[:, 0] >= r.rect[0] - 1e-6).all() and (q[:, 0] <= r.rect[2] + 1e-6).all()
    assert (q[:, 1] >= r.rect[1] - 1e-6).all() and (q[:, 1] <= r.rect[3] + 1e-6).all()
    assert r.area == pytest.approx(L_AREA, rel=0.03)
    assert s.report["rooms"]["area_m2"]["room_0"] == pytest.approx(L_AREA, rel=0.03)
    assert s.report["rooms"]["fill_ratio"]["room_0"] == pytest.approx(L_AREA / 30.0, abs=0.02)  # of its rect
    assert s.report["rooms"]["outline_fill_ratio"]["room_0"] > 0.97
    assert 6 <= len(r.polygon) <= 8
    # the L holds its arms, not the missing corner
    assert list(r.contains([(1.5, 4.0), (5.0, 1.5), (4.5, 4.0)])) == [True, True, False]
    assert "fills" not in caplog.text


def test_rectangular_rooms_have_no_polygon():
    s = derive_structure(two_room_stage(), "two_room.glb")
    assert [r.polygon for r in s.rooms] == [None, None]
    assert s.report["rooms"]["polygon_vertices"] == {"room_0": 0, "room_1": 0}
    st = derive_structure(l_room(notch=True), "l_notch.glb")
    assert [r.polygon is None for r in st.rooms] == [False, True]  # the L and the notch
    assert np.allclose(st.rooms[1].rect, (3.1, 3.1, 6.0, 5.0), atol=TOL)
    # face_ids: a floor (ceiling) face in the notch goes to the notch room, though it lies in the L's rect
    stage = _stage(st)
    p = np.array([[4.5, 4.0, 0.0], [1.5, 4.0, 0.0], [4.5, 1.5, 0.0], [4.5, 4.0, 2.5]])
    nrm = np.array([[0, 0, 1.0], [0, 0, 1.0], [0, 0, 1.0], [0, 0, -1.0]])
    assert list(face_ids(stage, p, nrm)) == [FLOOR_ID_BASE + 1, FLOOR_ID_BASE, FLOOR_ID_BASE, CEILING_ID_BASE + 1]


# --------------------------------------------------------------------------------------------
# rooms meet in a doorway that is only a gap
#
# The two-room stage with the interior door's lintel left out: the wall x[4.0, 4.1] is two pieces,
# y[0, 1] and y[1.9, 3], and the 0.9 m gap between them reaches the ceiling, so no wall holds a
# door there and the free floor is one piece. Rooms A x[0, 4] and B x[4.1, 7.1] still meet only
# in that gap: two rooms, their shared edge open to the path planner, the walls closed elsewhere.
# A 1.5 m gap (wider than DOORWAY_MAX, an open plan) keeps them one room.


def gap_stage(gap=(1.0, 1.9)) -> trimesh.Trimesh:
    pieces = {k: v for k, v in WALL_PIECES.items() if k != "interior"}
    pieces["interior"] = [((4.0, 0.0, 0.0), (4.1, gap[0], 2.5)), ((4.0, gap[1], 0.0), (4.1, 3.0, 2.5))]
    boxes = [FLOOR_SLAB, CEILING_SLAB] + [b for pcs in pieces.values() for b in pcs]
    return trimesh.util.concatenate([box_mesh(*b) for b in boxes])


def test_rooms_meet_in_a_doorway_without_a_lintel():
    from synth.paths.clearance import wall_segments

    s = derive_structure(gap_stage(), "gap.glb")
    assert not [o for o in s.openings if o.kind == "door"]  # the gap is not a door in a wall
    assert len(s.rooms) == 2 and s.report["rooms"]["split_at_doorways"] == 2
    a, b = s.rooms
    assert np.allclose(a.rect[:2], ROOM_A[:2], atol=TOL) and np.allclose(b.rect[2:], ROOM_B[2:], atol=TOL)
    assert a.area == pytest.approx(12.0, abs=0.3) and b.area == pytest.approx(9.0, abs=0.3)
    assert a.polygon is not None and b.polygon is not None and _ccw(a.polygon) and _ccw(b.polygon)
    # every point is in one room: the rooms' floors do not overlap
    pts = np.array([(1.0, 1.5), (6.0, 1.5), (4.05, 0.5), (4.05, 2.5)])
    assert list(a.contains(pts[:2])) == [True, False] and list(b.contains(pts[:2])) == [False, True]
    # path walls: along x 4.0 .. 4.1 only the wall pieces y[0, 1] and y[1.9, 3]; nothing crosses the gap
    stage = _stage(s)
    segs = wall_segments(stage)
    for y in (1.2, 1.45, 1.7):
        crossing = [s_ for s_ in segs if _crosses(s_, (3.8, y), (4.3, y))]
        assert not crossing, (y, crossing)
    for y in (0.5, 2.5):
        assert [s_ for s_ in segs if _crosses(s_, (3.8, y), (4.3, y))], y

    wide = derive_structure(gap_stage((0.7, 2.2)), "wide_gap.glb")
    assert len(wide.rooms) == 1 and wide.report["rooms"]["split_at_doorways"] == 0


def _crosses(seg, p, q) -> bool:
    a, b = np.asarray(seg[0], float), np.asarray(seg[1], float)
    p, q = np.asarray(p, float), np.asarray(q, float)

    def orient(u, v, w):
        return (v[0] - u[0]) * (w[1] - u[1]) - (v[1] - u[1]) * (w[0] - u[0])

    return orient(a, b, p) * orient(a, b, q) < 0 and orient(p, q, a) * orient(p, q, b) < 0
