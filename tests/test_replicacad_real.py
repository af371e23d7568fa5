"""The real-format ReplicaCAD fixture (tests/replicacad_real_fixture.py): vendored files are the real
ones, every box GLB has the real GLB's bounds, the stand-in stage stands on the navmesh footprint."""

from __future__ import annotations

import json

import numpy as np
import pytest

from replicacad_real_fixture import DATA, FILES, STAGE_GLB, bounds_table, manifest, sha256, write_real_fixture

C = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, -1.0], [0.0, 1.0, 0.0]])


@pytest.fixture(scope="module")
def root(tmp_path_factory):
    return write_real_fixture(tmp_path_factory.mktemp("rcad_real"))


def test_vendored_files_are_the_real_ones(root):
    m = manifest()
    assert len(m) == 134
    for rel, digest in m.items():
        assert sha256(FILES / rel) == digest, rel
        assert sha256(root / rel) == digest, rel
    assert sorted(p.relative_to(FILES).as_posix() for p in FILES.rglob("*") if p.is_file()) == sorted(m)
    total = sum(p.stat().st_size for p in DATA.rglob("*") if p.is_file())
    assert total < 1.5e6
    assert "CC BY-NC 4.0" in (DATA / "LICENSE.txt").read_text()


def test_structure_of_the_vendored_files():
    scenes = [json.loads((FILES / f"configs/scenes/apt_{k}.scene_instance.json").read_text()) for k in range(6)]
    for s in scenes:
        assert s["stage_instance"]["template_name"].endswith("frl_apartment_stage")
        assert s["navmesh_instance"] == "empty_stage_navmesh"
        assert s["object_instances"] and s["articulated_object_instances"]
    cfg = json.loads((FILES / "replicaCAD.scene_dataset_config.json").read_text())
    assert cfg["light_setups"]["default_attributes"] == {"positive_intensity_scale": 2.5, "negative_intensity_scale": 0.1}
    objs = sorted(FILES.glob("configs/objects/*.object_config.json"))
    assert len(objs) == 92
    assert all("semantic_id" in json.loads(p.read_text()) for p in objs)
    assert len(list(FILES.glob("urdf/*/*.urdf"))) == 12


def test_every_box_glb_has_the_table_bounds(root):
    from synth.gltf import glb_geometry, load_glb_parts

    table = bounds_table()
    assert len(table) == 116
    textured = 0
    for rel, b in table.items():
        m = glb_geometry(root / rel)
        h = m.vertices @ C  # our frame -> the GLB's own
        np.testing.assert_allclose(h.min(0), b["min"], atol=2e-5, err_msg=rel)
        np.testing.assert_allclose(h.max(0), b["max"], atol=2e-5, err_msg=rel)
        textured += load_glb_parts(root / rel)[0].visual.material.baseColorTexture is not None
    assert textured == 4
    missing = {r for r, b in table.items() if b["source"] != "measured"}
    assert missing == {"objects/frl_apartment_bike_01.glb", "objects/frl_apartment_bike_02.glb",
                       "objects/frl_apartment_clothes_hanger_01.glb"}
    # every render asset of every object config and every URDF mesh has an entry
    for p in FILES.glob("configs/objects/*.object_config.json"):
        rel = json.loads(p.read_text())["render_asset"].replace("../../", "")
        assert rel in table


def test_standin_stage_floor_is_the_navmesh_footprint(root):
    from synth.gltf import glb_geometry
    from synth.navmesh import read_navmesh

    nav = read_navmesh(root / "navmeshes/empty_stage.navmesh")
    fp = nav.footprint()
    m = glb_geometry(root / STAGE_GLB)
    up = (m.face_normals[:, 2] > 0.95) & (np.abs(m.triangles_center[:, 2]) < 1e-6)
    from synth.stage_structure import _rasterise

    # the floor's up-facing faces at z 0, on the footprint's grid: they cover the footprint except
    # where the stairs stand, and lie nowhere else
    tri = (m.triangles[up][:, :, :2] - fp.origin) / fp.cell
    floor = _rasterise(tri, fp.mask.shape)
    covered = (floor & fp.mask).sum() / fp.mask.sum()
    assert covered > 0.9
    assert not (floor & ~fp.mask).any()
    assert m.bounds[0][2] == pytest.approx(-0.1, abs=1e-4)


def test_apt_0_imports_on_the_fixture(root):
    from synth.replicacad import load_replicacad

    lay = load_replicacad(root, "apt_0", allow_unknown=True)
    doc = json.loads((FILES / "configs/scenes/apt_0.scene_instance.json").read_text())
    assert len(lay.objects) == len(doc["object_instances"]) + len(doc["articulated_object_instances"])
    st = lay.stage
    assert st.floor_z == pytest.approx(0.0, abs=1e-3)
    assert st.ceiling_height == pytest.approx(2.8, abs=1e-3)
    assert sum(o.kind == "window" for o in st.openings) >= 4  # the stand-in's windows are found as windows
    assert len(st.rooms) >= 1
