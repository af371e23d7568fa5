"""The real-format ReplicaCAD fixture (tests/replicacad_real_fixture.py): vendored files are the real
ones, every box GLB has the real GLB's bounds, the stand-in stage stands on the navmesh footprint and
holds the scenes' objects."""

from __future__ import annotations

import json

import numpy as np
import pytest
from scipy import ndimage

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
    from synth.mesh.gltf import glb_geometry, load_glb_parts

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


@pytest.fixture(scope="module")
def plain_footprint(root):
    """The navmesh footprint as the stand-in takes it (every level's), without objects to hold."""
    from synth.sources.replicacad.navmesh import StandinSpec, read_navmesh, standin_stage

    return standin_stage(read_navmesh(root / "navmeshes/empty_stage.navmesh"), StandinSpec(floor_z=0.0)).footprint


def _in_rect(pts, quad, grow):
    """Which points lie in the rectangle ``quad`` (4 x 2 corners, in order) grown by ``grow``."""
    q = np.asarray(quad, float)
    c = q.mean(axis=0)
    out = np.ones(len(pts), bool)
    for e in (q[1] - q[0], q[3] - q[0]):
        L = float(np.linalg.norm(e))
        out &= np.abs((pts - c) @ (e / L)) <= L / 2 + grow
    return out


def test_standin_stage_floor_is_the_navmesh_footprint_and_the_objects(root, plain_footprint):
    """The floor is the navmesh footprint plus every object's box (+2 cm) that sticks out of it
    (as tools/replicacad_standin.py builds the real data's): the up-facing floor faces at z 0 cover
    the footprint except where the stairs stand, and each held box; they lie nowhere else."""
    from synth.mesh.gltf import glb_geometry
    from synth.sources.replicacad.navmesh import STANDIN_KEEP_MARGIN, StandinSpec
    from synth.mesh.stage_structure import rasterise

    fp = plain_footprint
    cell, pad = fp.cell, int(round(2.0 / fp.cell))  # a grid 2 m wider than the footprint's on every side
    origin = fp.origin - pad * cell
    fpm = np.pad(fp.mask, pad)
    m = glb_geometry(root / STAGE_GLB)
    up = (m.face_normals[:, 2] > 0.95) & (np.abs(m.triangles_center[:, 2]) < 1e-6)
    floor = rasterise((m.triangles[up][:, :, :2] - origin) / cell, fpm.shape)
    steps = (m.face_normals[:, 2] > 0.95) & (m.triangles_center[:, 2] > 1e-6) & (m.triangles_center[:, 2] < 2.85)  # not the slabs' tops (2.9, 5.4)
    stood = floor | rasterise((m.triangles[steps][:, :, :2] - origin) / cell, fpm.shape)  # floor or a step
    assert (floor & fpm).sum() / fp.mask.sum() > 0.8  # the stairs and landings (10 m2) stand on the rest
    assert (stood & fpm).sum() / fp.mask.sum() > 0.98
    assert m.bounds[0][2] == pytest.approx(-0.1, abs=1e-4)

    from synth.sources.replicacad import stages as tool
    keep, _, _, who = tool.object_footprints(root, tool.stage_scenes(root)["frl_apartment_stage"], 0.0, StandinSpec.ceiling)
    assert len(keep) > 600  # the objects of apt_0..apt_5 (walls' and floor's, not those above the ceiling)
    ii, jj = np.nonzero(np.ones(fpm.shape, bool))
    centres = origin + (np.stack([ii, jj], axis=1) + 0.5) * cell
    held = np.zeros(fpm.shape, bool)  # cells whose square meets a held box + margin
    near = ndimage.binary_dilation(fpm, structure=np.ones((3, 3), bool))  # within a cell of the footprint
    sticking = not_held = 0
    for q, w in zip(keep, who):
        box = _in_rect(centres, q, STANDIN_KEEP_MARGIN).reshape(fpm.shape)  # centres in the box + margin
        grown = _in_rect(centres, q, STANDIN_KEEP_MARGIN + cell / 2 + 1e-6).reshape(fpm.shape)  # as the stand-in rasterises it
        if not (grown & near).any():  # wholly outside the building: not held
            not_held += 1
            assert w[:2] == ("apt_2", 37), w  # a shoe outside the east facade
            continue
        out = box & ~fpm
        sticking += bool(out.any())
        assert stood[out].all(), w  # the floor (or a step: see the next test) holds what sticks out
        held |= grown
    assert not_held == 1 and sticking > 20
    added = floor & ~fpm
    stray = added & ~held
    # no floor outside the footprint but under the boxes (+ margin + half a cell; once 15-20 cells more,
    # at long boxes' ends, when the margin was added along the diagonals)
    assert added.any() and not stray.any(), (int(stray.sum()), centres[stray.ravel()][:5])
    assert 2.0 < added.sum() * cell * cell < 6.0  # m2 (3.86 m2 when written)


def test_floor_standing_objects_are_held_at_the_floor(root, plain_footprint):
    """Every object standing on the floor (bottom within 0.1 m of z 0) whose box (+2 cm) sticks out of
    the footprint has floor at z 0 under the part that sticks out: a cell added to hold it goes to
    the level its bottom is nearest, not to the nearest level (beside the stairs: steps under a bike)."""
    from synth.mesh.gltf import glb_geometry
    from synth.sources.replicacad.navmesh import STANDIN_KEEP_MARGIN
    from synth.scene.model import object_box
    from synth.mesh.stage_structure import rasterise

    fp = plain_footprint
    cell, pad = fp.cell, int(round(2.0 / fp.cell))
    origin = fp.origin - pad * cell
    fpm = np.pad(fp.mask, pad)
    m = glb_geometry(root / STAGE_GLB)
    up = (m.face_normals[:, 2] > 0.95) & (np.abs(m.triangles_center[:, 2]) < 1e-6)
    floor = rasterise((m.triangles[up][:, :, :2] - origin) / cell, fpm.shape)
    ii, jj = np.nonzero(np.ones(fpm.shape, bool))
    centres = origin + (np.stack([ii, jj], axis=1) + 0.5) * cell
    from synth.sources.replicacad import stages as tool
    bad = []
    for p, doc in tool.stage_scenes(root)["frl_apartment_stage"]:
        for o in tool.scene_objects(root, p, doc):
            b = object_box(o)
            if abs(b.zmin) > 0.1:  # not on the floor
                continue
            box = _in_rect(centres, b.corners_2d(), STANDIN_KEEP_MARGIN).reshape(fpm.shape)
            out = box & ~fpm
            if (box & fpm).any() and not floor[out].all():
                bad.append((p.name, o.id, o.cls, int((out & ~floor).sum())))
    assert not bad, bad




def test_apt_0_imports_on_the_fixture(root):
    from synth.sources.replicacad.importer import load_replicacad

    lay = load_replicacad(root, "apt_0", allow_unknown=True)
    doc = json.loads((FILES / "configs/scenes/apt_0.scene_instance.json").read_text())
    assert len(lay.objects) == len(doc["object_instances"]) + len(doc["articulated_object_instances"])
    st = lay.stage
    assert st.floor_z == pytest.approx(0.0, abs=1e-3)
    assert st.ceiling_height == pytest.approx(2.8, abs=1e-3)
    assert sum(o.kind == "window" for o in st.openings) >= 4  # the stand-in's windows are found as windows
    assert len(st.rooms) >= 1
