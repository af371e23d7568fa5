"""synth.navmesh on ReplicaCAD's own navmeshes (vendored in tests/data/replicacad/files/navmeshes).

Expected figures were read off the files' headers by hand (a hex dump of empty_stage.navmesh: one
tile, 62 vertices, 28 polygons, 116 links, 28 detail meshes, 1 detail vertex, 61 detail triangles, 56
BV nodes, tile data 4620 bytes; settings cell 0.05 x 0.2, agent 0.3 x 1.5 m) and from the
dataset's description (the FRL apartment: one open-plan main floor of roughly 45-65 m2, stairs).
"""

from __future__ import annotations

import struct

import numpy as np
import pytest

from formats.errors import SceneFormatError
from synth.navmesh import navmesh_for_scene, read_navmesh, standin_stage, StandinSpec, write_standin_glb

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
    from synth.gltf import glb_geometry

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
