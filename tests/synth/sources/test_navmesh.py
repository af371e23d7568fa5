"""synth.sources.replicacad.navmesh on ReplicaCAD's own navmeshes (vendored in tests/data/replicacad/files/navmeshes).

Expected figures were read off the files' headers by hand (a hex dump of empty_stage.navmesh: one
tile, 62 vertices, 28 polygons, 116 links, 28 detail meshes, 1 detail vertex, 61 detail triangles, 56
BV nodes, tile data 4620 bytes; settings cell 0.05 x 0.2, agent 0.3 x 1.5 m) and from the
dataset's description (the FRL apartment: one open-plan main floor of roughly 45-65 m2, stairs).
"""

from __future__ import annotations

import struct

import numpy as np
import pytest

from vrformats.errors import SceneFormatError
from synth.sources.replicacad.navmesh import navmesh_for_scene, read_navmesh, standin_stage, StandinSpec, write_standin_glb

from replicacad_real_fixture import FILES

NAV = FILES / "navmeshes"
C = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, -1.0], [0.0, 1.0, 0.0]])


def test_header_of_the_empty_stage():
    n = read_navmesh(NAV / "empty_stage.navmesh")
    s = n.settings
    assert n.version == 2 and len(n.tiles) == 1
    assert s.cell_size == pytest.approx(0.05) and s.cell_height == pytest.approx(0.2)
    assert n.agent_radius == pytest.approx(0.3) and n.agent_height == pytest.approx(1.5)
    assert s.agent_max_climb == pytest.approx(0.2) and s.agent_max_slope == pytest.approx(45.0)
    assert s.verts_per_poly == pytest.approx(6.0) and s.edge_max_error == pytest.approx(1.3)
    t = n.tiles[0]
    assert (t["vertices"], t["polygons"], t["detail_meshes"], t["detail_triangles"], t["bv_nodes"]) == (62, 28, 28, 61, 56)
    assert t["walkable_radius"] == pytest.approx(0.3)
    assert len(n.polygons) == 28
    np.testing.assert_allclose(n.origin, [-2.6766, -0.0806, -4.8343], atol=1e-3)


@pytest.mark.parametrize("name", ["empty_stage", "apt_0", "apt_3", "apt_5"])
def test_polygons_lie_in_their_tile_and_in_our_frame(name):
    n = read_navmesh(NAV / f"{name}.navmesh")
    t = n.tiles[0]
    for p in n.polygons:
        assert 3 <= len(p.vertices) <= 6
        h = p.vertices @ C  # back to habitat (C^T v, rows)
        assert (h >= t["bmin"] - 1e-4).all() and (h <= t["bmax"] + 1e-4).all()
    # our z is habitat's y: polygon heights sit on Recast's 0.2 m voxel grid above bmin.y
    zs = np.concatenate([p.vertices[:, 2] for p in n.polygons])
    k = (zs - t["bmin"][1]) / n.settings.cell_height
    np.testing.assert_allclose(k, np.round(k), atol=1e-3)


def test_levels_of_the_empty_stage():
    n = read_navmesh(NAV / "empty_stage.navmesh")
    lv = n.levels()
    main = lv[0]
    assert main.z == pytest.approx(0.12, abs=0.01)
    assert 40.0 < main.area < 55.0  # the walkable main floor (eroded by the agent radius)
    zs = sorted(round(v.z, 2) for v in lv)
    assert zs == pytest.approx([0.12, 0.27, 0.87, 1.32, 2.12], abs=0.011)
    assert max(v.z_range[1] for v in lv) == pytest.approx(2.92, abs=0.01)  # top of the stairs
    g = n.walkable(main)
    assert g.area == pytest.approx(main.area, rel=0.03)
    f = n.footprint(main)
    assert f.mask[g.mask].all()  # the footprint contains the walkable area
    assert 1.2 * g.area < f.area < 1.5 * g.area
    x0, y0, x1, y1 = f.bounds()
    assert 6.5 < x1 - x0 < 7.5 and 12.0 < y1 - y0 < 13.5


def test_truncated_and_foreign_files_fail_with_one_line(tmp_path):
    b = (NAV / "apt_0.navmesh").read_bytes()
    cases = {"short": b[:50], "cut": b[:-10], "magic": b"XXXX" + b[4:],
             "version": b[:4] + struct.pack("<i", 3) + b[8:], "lfs": b"version https://git-lfs.github.com/spec/v1\n"}
    for name, data in cases.items():
        p = tmp_path / f"{name}.navmesh"
        p.write_bytes(data)
        with pytest.raises(SceneFormatError) as e:
            read_navmesh(p)
        assert str(p) in str(e.value) and "\n" not in str(e.value)


def test_navmesh_for_scene_resolves_the_apartments_handle():
    import json

    doc = json.loads((FILES / "configs/scenes/apt_0.scene_instance.json").read_text())
    assert doc["navmesh_instance"] == "empty_stage_navmesh"
    assert navmesh_for_scene(FILES, doc) == FILES / "navmeshes/empty_stage.navmesh"
    assert navmesh_for_scene(FILES, {"navmesh_instance": "apt_2"}) == FILES / "navmeshes/apt_2.navmesh"
    assert navmesh_for_scene(FILES, {}) is None
    with pytest.raises(SceneFormatError, match="navmesh_instance"):
        navmesh_for_scene(FILES, {"navmesh_instance": "nowhere"})


def test_standin_stage_matches_the_navmesh(tmp_path):
    from synth.mesh.gltf import glb_geometry

    n = read_navmesh(NAV / "empty_stage.navmesh")
    s = standin_stage(n, StandinSpec(floor_z=0.0))
    assert s.floor_z == 0.0 and s.ceiling_z == pytest.approx(2.8)
    assert s.stair_ceiling_z is not None and s.stair_ceiling_z > 2.9 + n.agent_height
    assert len(s.windows) >= 4
    assert not (s.walls.mask & s.footprint.mask).any()
    m = glb_geometry(write_standin_glb(s, tmp_path / "stage.glb"))
    x0, y0, x1, y1 = s.footprint.bounds()
    t = 0.1 + 1e-4  # walls outside the footprint
    np.testing.assert_allclose(m.bounds[0][:2], [x0 - t, y0 - t], atol=2e-3)
    np.testing.assert_allclose(m.bounds[1][:2], [x1 + t, y1 + t], atol=2e-3)
    # the floor's up-facing faces at z 0 cover the main footprint (minus stair cells)
    up = (m.face_normals[:, 2] > 0.95) & (np.abs(m.triangles_center[:, 2]) < 1e-6)
    area = m.area_faces[up].sum()
    assert s.main_footprint.area - 10.0 < area <= s.footprint.area + 1e-6


# --------------------------------------------------------------------------------------------
# the stand-in holds the scenes' objects (StandinSpec.keep) and puts no window behind them
#
# The empty stage's footprint ends at x = 4.4 along y -4.25 .. 2 and at 4.35 along y -7.9 .. -4.3 (its
# east wall; windows without objects at y -6.75..-5.6, -3.65..-2.5, -1.1..0.05). Objects (XY boxes, tops):
EAST = 4.4
SHELF = (EAST - 0.6, -3.5, EAST + 0.2, -2.7)  # 0.2 m out of the footprint, 1.5 m tall, before a window
BENCH = (EAST - 0.5, -0.9, EAST + 0.1, -0.2)  # 0.1 m out, 0.5 m tall (under the sills): a window may stay
FAR = (EAST - 0.4, -6.0, EAST + 1.4, -5.0)  # 1.45 m out: not held
OUTSIDE = (EAST + 0.5, -1.0, EAST + 0.9, -0.5)  # does not overlap the footprint: not held
OFF_GRID = (EAST + 20.0, 0.0, EAST + 21.0, 1.0)  # far off: not held
KEEP = [SHELF, BENCH, FAR, OUTSIDE, OFF_GRID]
TOPS = [1.5, 0.5, 1.5, 1.5, 1.5]


def _quad_xy(r):
    x0, y0, x1, y1 = r
    return np.array([(x0, y0), (x1, y0), (x1, y1), (x0, y1)])


def _grow(r, d):
    return (r[0] - d, r[1] - d, r[2] + d, r[3] + d)


def _cells_in(grid, r):
    """World XY centres of ``grid``'s cells (set or not) whose centre lies in the rect ``r``."""
    c = grid.cell
    i = np.arange(int(np.ceil((r[0] - grid.origin[0]) / c - 0.5)), int(np.floor((r[2] - grid.origin[0]) / c - 0.5)) + 1)
    j = np.arange(int(np.ceil((r[1] - grid.origin[1]) / c - 0.5)), int(np.floor((r[3] - grid.origin[1]) / c - 0.5)) + 1)
    I, J = np.meshgrid(i, j, indexing="ij")
    return grid.origin + (np.stack([I.ravel(), J.ravel()], axis=1) + 0.5) * c


def _window_rect(w):
    a, b = w["wall_line"]
    return (w["from"], a, w["to"], b) if w["axis"] == "x" else (a, w["from"], b, w["to"])


def _rect_gap(r, s):
    dx = max(r[0] - s[2], s[0] - r[2], 0.0)
    dy = max(r[1] - s[3], s[1] - r[3], 0.0)
    return float(np.hypot(dx, dy))


def _east_windows(s, y0, y1):
    return [w for w in s.windows if w["axis"] == "y" and w["wall_line"][0] > EAST - 0.1 and w["from"] < y1 and w["to"] > y0]


@pytest.fixture(scope="module")
def plain():
    return standin_stage(read_navmesh(NAV / "empty_stage.navmesh"), StandinSpec(floor_z=0.0))


@pytest.fixture(scope="module")
def held():
    spec = StandinSpec(floor_z=0.0, keep=[_quad_xy(r) for r in KEEP], keep_tops=TOPS)
    return standin_stage(read_navmesh(NAV / "empty_stage.navmesh"), spec)


def test_the_objects_stick_out_of_the_plain_stand_in(plain):
    fp = plain.footprint
    assert fp.contains([(EAST - 0.025, -3.1), (EAST - 0.025, -0.5), (EAST - 0.075, -5.5)]).all()
    assert not fp.contains([(EAST + 0.025, -3.1), (EAST + 0.025, -0.5), (EAST - 0.025, -5.5)]).any()
    assert _east_windows(plain, SHELF[1], SHELF[3]) and _east_windows(plain, BENCH[1], BENCH[3])
    assert plain.report["keep"] == {"objects": 0, "held": 0, "hung": 0, "not_held": [], "added_m2": 0.0}


def test_standin_floor_holds_an_object_sticking_out(plain, held):
    m = 0.02  # StandinSpec.keep_margin
    assert held.report["keep"]["objects"] == 5 and held.report["keep"]["held"] == 2
    for r in (SHELF, BENCH):
        assert held.footprint.contains(_cells_in(held.footprint, _grow(r, m))).all(), r
        assert not held.walls.contains(_cells_in(held.walls, _grow(r, m))).any(), r
    # what was added is the two boxes (+ margin, to the cell), nothing else
    c = held.footprint.cell
    add = held.footprint.centres()[~plain.footprint.contains(held.footprint.centres())]
    near = np.zeros(len(add), bool)
    for r in (SHELF, BENCH):
        g = _grow(r, m + c / 2 + 1e-6)
        near |= (add[:, 0] >= g[0]) & (add[:, 0] <= g[2]) & (add[:, 1] >= g[1]) & (add[:, 1] <= g[3])
    assert near.all() and len(add) > 0
    want = (0.2 + m) * (SHELF[3] - SHELF[1] + 2 * m) + (0.1 + m) * (BENCH[3] - BENCH[1] + 2 * m)
    assert want <= held.report["keep"]["added_m2"] <= want + 2 * c * (SHELF[3] - SHELF[1] + BENCH[3] - BENCH[1] + 8 * m)
    # the mesh: floor faces (up, z 0) cover the shelf's box + margin, no wall face stands in it
    floor, walls = held.parts["floor"], held.parts["walls"]
    up = (floor.face_normals[:, 2] > 0.95) & (np.abs(floor.triangles_center[:, 2]) < 1e-6)
    from synth.mesh.stage_structure import rasterise

    r = _grow(SHELF, m)
    fine = 0.005
    shape = (int(round((r[2] - r[0]) / fine)), int(round((r[3] - r[1]) / fine)))
    cover = rasterise((floor.triangles[up][:, :, :2] - r[:2]) / fine, shape)
    assert cover.all()
    wc = walls.triangles_center
    inside = (wc[:, 0] > r[0] + 1e-3) & (wc[:, 0] < r[2] - 1e-3) & (wc[:, 1] > r[1] + 1e-3) & (wc[:, 1] < r[3] - 1e-3)
    assert not inside.any()


def test_no_window_behind_a_tall_object(plain, held):
    clear = 0.2  # StandinSpec.window_clear
    assert not _east_windows(held, SHELF[1] - clear, SHELF[3] + clear)
    for w in held.windows:
        for r, top in zip(KEEP, TOPS):
            if top > 0.9:  # above the sills
                assert _rect_gap(_window_rect(w), r) >= clear - 1e-6, (w, r)
    assert _east_windows(held, BENCH[1], BENCH[3])  # the bench is under the sills
    assert len(held.windows) >= 4


def test_objects_far_out_are_not_held(plain, held):
    rep = held.report["keep"]
    out = {x["index"]: x["outside_m"] for x in rep["not_held"]}
    assert sorted(out) == [2, 3, 4]
    assert out[2] > 1.2 and out[2] == pytest.approx(1.45, abs=0.1)
    assert 0.3 < out[3] < 1.2 and out[4] > 20.0
    for r in (FAR, OUTSIDE):
        pts = _cells_in(held.footprint, r)
        assert (held.footprint.contains(pts) == plain.footprint.contains(pts)).all(), r
    # the wall east of FAR stays where the plain stand-in has it
    assert held.walls.contains([(EAST + 0.025, -5.5)]).all() and plain.walls.contains([(EAST + 0.025, -5.5)]).all()


# beside the stairs (their east flight ends at x 3.6, y 1.1..2.45, steps 0.34..0.69 m there): apt_0's
# bike, bottom z -0.03, sticking out of the east wall; a plant on the landing (z 1.2), sticking out east
BIKE = [(4.04, 1.84), (3.529, 0.236), (4.184, 0.028), (4.695, 1.632)]
LANDING_PLANT = (3.3, 3.4, 3.95, 4.0)


def _top_z(s, pts):
    """Height of the highest up-facing floor or step face over each point (None: none)."""
    faces = []
    for part in ("floor", "steps"):
        m = s.parts[part]
        up = m.face_normals[:, 2] > 0.95
        faces.append((m.triangles[up][:, :, :2], m.triangles_center[up][:, 2]))
    T = np.concatenate([f[0] for f in faces])
    z = np.concatenate([f[1] for f in faces])
    out = []
    for p in np.asarray(pts, float):
        a, b, c = T[:, 0], T[:, 1], T[:, 2]
        d = [(v[:, 0] - u[:, 0]) * (p[1] - u[:, 1]) - (v[:, 1] - u[:, 1]) * (p[0] - u[:, 0]) for u, v in ((a, b), (b, c), (c, a))]
        ins = ((d[0] >= -1e-9) & (d[1] >= -1e-9) & (d[2] >= -1e-9)) | ((d[0] <= 1e-9) & (d[1] <= 1e-9) & (d[2] <= 1e-9))
        out.append(float(z[ins].max()) if ins.any() else None)
    return out


@pytest.mark.slow
def test_cells_added_for_an_object_go_to_the_level_of_its_bottom(plain):
    nav = read_navmesh(NAV / "empty_stage.navmesh")
    keep = [np.array(BIKE), _quad_xy(LANDING_PLANT)]
    by_bottom = standin_stage(nav, StandinSpec(floor_z=0.0, keep=keep, keep_bottoms=[-0.03, 1.18]))
    nearest = standin_stage(nav, StandinSpec(floor_z=0.0, keep=keep))  # no bottoms: the nearest level's
    for s in (by_bottom, nearest):
        assert s.report["keep"]["held"] == 2
    c = by_bottom.footprint.centres()
    add = c[~plain.footprint.contains(c)]
    bike = add[:, 1] < 2.5
    assert bike.sum() > 200 and (~bike).sum() > 50
    z = np.array(_top_z(by_bottom, add), float)
    assert np.abs(z[bike]).max() < 1e-6  # the bike's cells: floor at z 0
    assert np.allclose(z[~bike], 1.2, atol=0.01)  # the plant's: the landing (navmesh 1.32 - 0.12)
    z0 = np.array(_top_z(nearest, add), float)
    assert (z0[bike] > 0.3).sum() > 50  # the old rule: steps under the bike
    assert by_bottom.report["raised_m2"] < nearest.report["raised_m2"]
    with pytest.raises(ValueError, match="keep_bottoms"):
        standin_stage(nav, StandinSpec(floor_z=0.0, keep=keep, keep_bottoms=[0.0]))


def test_a_long_thin_object_is_held_with_the_margin_on_every_side(plain):
    """The margin is added along the box's own sides: a 0.25 x 0.81 m box gets 2 cm (+ half a cell)
    on its long sides too, and no more at its ends (moving the corners out along the diagonals
    would give its ends 1.4 times as much and its sides a third)."""
    rail = (EAST - 0.2, -2.02, EAST + 0.05, -1.21)
    m = 0.02  # StandinSpec.keep_margin
    s = standin_stage(read_navmesh(NAV / "empty_stage.navmesh"), StandinSpec(floor_z=0.0, keep=[_quad_xy(rail)], keep_tops=[0.5]))
    fp, cell = s.footprint, s.footprint.cell
    assert fp.contains(_cells_in(fp, _grow(rail, m + cell / 2 - 1e-6))).all()
    add = fp.centres()[~plain.footprint.contains(fp.centres())]
    g = _grow(rail, m + cell / 2 + 1e-6)
    assert ((add[:, 0] >= g[0]) & (add[:, 0] <= g[2]) & (add[:, 1] >= g[1]) & (add[:, 1] <= g[3])).all()
    assert fp.contains([(EAST + 0.075, -1.6)]).all() and not fp.contains([(EAST + 0.125, -1.6), (EAST + 0.025, -2.075)]).any()
    assert len(add) == 2 * 18  # x 4.425, 4.475; y -2.025 .. -1.175


def test_an_object_hanging_on_a_wall_keeps_the_wall_right_behind_it(plain):
    """A TV 0.9 m up on the east wall, 4 cm out of the footprint: held to the cell without margin, so
    the wall starts within a cell of its back (the checks find it hung on the wall); the same box
    standing on the floor gets the margin, the wall a cell farther out."""
    tv = (EAST - 0.03, -1.9, EAST + 0.04, -1.3)
    nav = read_navmesh(NAV / "empty_stage.navmesh")
    hung = standin_stage(nav, StandinSpec(floor_z=0.0, keep=[_quad_xy(tv)], keep_tops=[1.5], keep_bottoms=[0.9]))
    stands = standin_stage(nav, StandinSpec(floor_z=0.0, keep=[_quad_xy(tv)], keep_tops=[1.5], keep_bottoms=[0.0]))
    assert hung.report["keep"]["held"] == stands.report["keep"]["held"] == 1
    assert hung.report["keep"]["hung"] == 1 and stands.report["keep"]["hung"] == 0
    behind, out = (EAST + 0.025, -1.6), (EAST + 0.075, -1.6)
    assert not plain.footprint.contains([behind]).any()
    assert hung.footprint.contains([behind]).all() and not hung.footprint.contains([out]).any()
    assert hung.walls.contains([out]).all()  # the wall's face at x EAST + 0.05: 1 cm behind the TV
    assert stands.footprint.contains([behind, out]).all() and not stands.walls.contains([out]).any()
