"""The full ReplicaCAD import on the ReplicaCAD-shaped fixture (tests/replicacad_fixture.py):
structure from the stage mesh, the URDF counter, supports, light fixtures, variants, the render
spec from a ReplicaCAD root, and bad input through the command line.

Expected values are the fixture's construction (written in habitat's Y-up frame, stated in ours),
never the importer's own output.
"""

from __future__ import annotations

import json
import math
import os
import shutil
from pathlib import Path
from dataclasses import replace

import numpy as np
import pytest
import trimesh
from replicacad_fixture import (
    CEILING_Z, COUNTER_BOX, DOOR, FLOOR_Z, LIGHTS, OBJECT_BOXES, ROOMS, SCENES, TEXTURE_SRGB, URDF_LINK_BOXES, WALL_BOXES,
    WINDOW,
    make_fixture,
)

from synth.layout.validity import check_layout
from synth.cli import main as synth_main
from synth.jobs import load_spec
from synth.sources.replicacad.importer import load_replicacad
from synth.sources.replicacad.job import prepare
from synth.scene.model import load_layout, object_box, structure_boxes
from vrformats.errors import SceneFormatError


@pytest.fixture(scope="module")
def root(tmp_path_factory) -> Path:
    return make_fixture(tmp_path_factory.mktemp("replica_cad"))


@pytest.fixture(scope="module")
def apt0(root):
    return load_replicacad(root, "apt_0")


def _copy(root: Path, tmp_path: Path) -> Path:
    dst = tmp_path / "rc"
    shutil.copytree(root, dst)
    return dst


def _aabb(box) -> tuple[np.ndarray, np.ndarray]:
    """World axis-aligned bounds of a gravity-aligned oriented box (from its corners)."""
    c = box.corners_2d()
    return (np.array([c[:, 0].min(), c[:, 1].min(), box.zmin]), np.array([c[:, 0].max(), c[:, 1].max(), box.zmax]))


# ---- structure -------------------------------------------------------------------------------


def test_structure_boxes_match_the_stage_construction(apt0):
    st = apt0.stage
    assert st.floor_z == pytest.approx(FLOOR_Z, abs=0.01) and st.floor_z + st.ceiling_height == pytest.approx(CEILING_Z, abs=0.01)
    boxes = structure_boxes(st)
    walls = [b for b in boxes if b.kind == "wall"]
    assert len(walls) == len(WALL_BOXES)
    for name, (lo, hi) in WALL_BOXES.items():
        lo, hi = np.array(lo), np.array(hi)
        match = [w for w in walls if np.abs((_aabb(w)[0] + _aabb(w)[1]) / 2 - (lo + hi) / 2).max() < 0.05]
        assert len(match) == 1, name
        w = match[0]
        assert math.degrees(abs(math.sin(2 * w.yaw))) / 2 < 2.0  # axis-aligned within 2 deg
        wlo, whi = _aabb(w)
        assert np.abs(wlo - lo).max() < 0.05 and np.abs(whi - hi).max() < 0.05, (name, wlo, whi)
    # floor and ceiling per room: the room interiors
    for kind, z in (("floor", FLOOR_Z), ("ceiling", CEILING_Z)):
        got = sorted((_aabb(b) for b in boxes if b.kind == kind), key=lambda a: a[0][0])
        want = sorted(ROOMS.values())
        assert len(got) == len(want)
        for (glo, ghi), (wlo, whi) in zip(got, want):
            assert np.abs(glo[:2] - wlo).max() < 0.05 and np.abs(ghi[:2] - whi).max() < 0.05
            assert (glo[2] + ghi[2]) / 2 == pytest.approx(z - 0.05 if kind == "floor" else z + 0.05, abs=0.05)


def test_door_and_window(apt0):
    st = apt0.stage
    doors = [o for o in st.openings if o.kind == "door"]
    windows = [o for o in st.openings if o.kind == "window"]
    assert len(doors) == 1 and len(windows) == 1
    _, dlo, dhi = DOOR
    d = doors[0]
    assert d.width == pytest.approx(dhi[1] - dlo[1], abs=0.05) and d.height == pytest.approx(dhi[2], abs=0.05)
    centre = d.center_xy(st.wall(d.wall))
    assert np.allclose(centre, [(dlo[0] + dhi[0]) / 2, (dlo[1] + dhi[1]) / 2], atol=0.05)
    assert len(d.rooms) == 2  # it joins both rooms
    _, wlo, whi = WINDOW
    w = windows[0]
    assert (w.bottom, w.height, w.width) == pytest.approx((wlo[2], whi[2] - wlo[2], whi[0] - wlo[0]), abs=0.05)
    assert len(w.rooms) == 1 and st.room(w.rooms[0]).rect[0] < (wlo[0] + whi[0]) / 2 < st.room(w.rooms[0]).rect[2]


# ---- objects -----------------------------------------------------------------------------------


def test_articulated_counter_box_holds_its_links(apt0):
    (counter,) = [o for o in apt0.objects if o.asset.startswith("replicacad-urdf:")]
    assert counter.cls == "kitchen_counter" and not counter.movable and counter.id == len(OBJECT_BOXES) + 1
    lo, hi = _aabb(object_box(counter))
    assert np.allclose(lo, COUNTER_BOX[0], atol=1e-3) and np.allclose(hi, COUNTER_BOX[1], atol=1e-3)
    for link, (llo, lhi) in URDF_LINK_BOXES.items():
        assert np.all(lo <= np.array(llo) + 1e-3) and np.all(hi >= np.array(lhi) - 1e-3), link


def test_rigid_object_boxes_and_supports(apt0):
    by_index = {o.id - 1: o for o in apt0.objects}
    for k, (lo, hi) in OBJECT_BOXES.items():
        blo, bhi = _aabb(object_box(by_index[k]))
        assert np.allclose(blo, lo, atol=2e-3) and np.allclose(bhi, hi, atol=2e-3), (k, blo, bhi)
    cls = {o.cls: o for o in apt0.objects}
    assert cls["bowl"].support == f"object:{cls['dining_table'].id}:0"  # on the table top
    assert cls["cushion"].support.startswith(f"object:{cls['sofa'].id}:")  # on the seat, inside the sofa's box
    assert all(o.support == "floor" for o in apt0.objects if o.cls not in ("bowl", "cushion"))


def test_fixtures_come_from_the_lighting_config(apt0):
    fx = {f.kind: [] for f in apt0.fixtures}
    for f in apt0.fixtures:
        fx[f.kind].append(f)
    ceiling = sorted(tuple(f.position) for f in fx["ceiling"])
    assert ceiling == sorted([LIGHTS["0"], LIGHTS["1"]])  # one per room, where the config puts them
    (lamp,) = fx["lamp"]
    assert apt0.object(lamp.object).cls == "floor_lamp" and np.allclose(lamp.position, LIGHTS["2"], atol=1e-4)
    assert len(fx["window"]) == 1
    assert apt0.meta["lighting_config"].endswith(".lighting_config.json")


def test_every_authored_scene_checks_clean(root):
    for scene in SCENES:
        rep = check_layout(load_replicacad(root, scene))
        assert rep.ok, (scene, rep.to_dict())


# ---- command line: import, check, rearrange -----------------------------------------------------


def test_import_check_and_rearrange_on_the_command_line(root, tmp_path, capsys):
    lay = tmp_path / "apt_0.yaml"
    assert synth_main(["scene", "import-replicacad", str(root), "apt_0", "--out", str(lay)]) == 0
    assert "5 walls, 2 rooms, 2 openings" in capsys.readouterr().out
    assert synth_main(["scene", "check", str(lay)]) == 0
    var = tmp_path / "apt_0_var.yaml"
    assert synth_main(["scene", "rearrange", str(lay), "--seed", "3", "--out", str(var)]) == 0
    out = capsys.readouterr().out
    print(out)  # the change statistics against the scaled ranges
    assert "target" in out and "fx" not in out
    assert synth_main(["scene", "check", str(var)]) == 0
    ref, v = load_layout(lay), load_layout(var)
    assert v.stage == ref.stage and {o.id for o in v.objects} != {o.id for o in ref.objects} or any(
        object_box(a).center != object_box(v.object(a.id)).center for a in ref.objects if a.id in {o.id for o in v.objects})


# ---- bad input: one line naming the file and the field, exit 2, nothing written -----------------


def _scene_json(root: Path, scene: str = "apt_0") -> Path:
    return root / "configs" / "scenes" / f"{scene}.scene_instance.json"


def _edit(path: Path, fn) -> None:
    doc = json.loads(path.read_text())
    fn(doc)
    path.write_text(json.dumps(doc))


def _no_floor_stage(root: Path) -> None:
    """Rewrite the stage GLB without its floor slab (walls and ceiling only)."""
    glb = next((root / "stages").glob("*.glb"))
    scene = trimesh.load(str(glb), file_type="glb", force="scene")
    keep = trimesh.util.concatenate([g for g in scene.dump() if g.bounds[1][1] > 0.01])  # habitat y up: drop the slab below 0
    glb.write_bytes(trimesh.exchange.gltf.export_glb(trimesh.Scene(keep)))


def _first_object_glb(root: Path) -> Path:
    cfg = next((root / "configs" / "objects").glob("*.object_config.json"))
    return (cfg.parent / json.loads(cfg.read_text())["render_asset"]).resolve()


BAD = {
    "missing GLB": (lambda r: _first_object_glb(r).unlink(), ("render_asset", "GLB not found")),
    "missing URDF": (lambda r: next((r / "urdf").rglob("*.urdf")).unlink(), ("ao_config.json: urdf_filepath: URDF not found",)),
    "no URDF for a template": (lambda r: [p.unlink() for p in list((r / "urdf").rglob("*.urdf")) + list((r / "urdf").rglob("*.ao_config.json"))],
                               ("articulated_object_instances[0].template_name", "no URDF")),
    "missing URDF mesh": (lambda r: next((r / "urdf").rglob("drawer*.glb")).unlink(), (".urdf", "drawer")),
    "stage without floor": (_no_floor_stage, ("stage", "no floor found")),
    "unknown template": (lambda r: _edit(_scene_json(r), lambda d: d["object_instances"][0].update(template_name="objects/no_such_thing")),
                         ("object_instances[0].template_name", "no object config")),
    "malformed lighting config": (lambda r: next((r / "configs" / "lighting").glob("*.json")).write_text('{"lights": {"0": {"position": [1, 2]}}}'),
                                  (".lighting_config.json", "lights.0.position")),
    "lighting config not JSON": (lambda r: [p.write_text("{not json") for p in (r / "configs" / "lighting").glob("*.json")],
                                 (".lighting_config.json",)),
    "unknown lighting config": (lambda r: _edit(_scene_json(r), lambda d: d.update(default_lighting="lighting/nowhere")),
                                ("default_lighting", "no lighting config")),
}


@pytest.mark.parametrize("case", sorted(BAD))
def test_bad_dataset_is_one_line_and_writes_nothing(root, tmp_path, capsys, case):
    r = _copy(root, tmp_path)
    damage, expect = BAD[case]
    damage(r)
    out = tmp_path / "layout.yaml"
    assert synth_main(["scene", "import-replicacad", str(r), "apt_0", "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "Traceback" not in err, err
    for piece in expect:
        assert piece in err, (case, err)
    assert not out.exists()


# ---- the render spec from a ReplicaCAD root -------------------------------------------------------

SPEC = """name: fx_design
replicacad: {root: %s}
out: %s
renderer: blender
geometry: fast
size: [48, 36]
chunk_size: 20
designs:
  - layouts: [apt_0, apt_1]
    lightings: [day, night]
    path: {name: query, frames: 60}
  - layouts: [apt_0]
    lightings: [day]
    path: {name: mapping, frames: 600}
"""


def test_spec_from_a_replicacad_root_prepares_layouts_and_paths_once(root, tmp_path, capsys):
    spec_file = tmp_path / "spec.yaml"
    spec_file.write_text(SPEC % ("null", tmp_path / "job"))
    spec = load_spec(spec_file)
    msgs = []
    ready = prepare(spec, tmp_path / "job", cli_root=str(root), progress=msgs.append)
    prep = tmp_path / "job" / "replicacad"
    assert sorted(p.name for p in (prep / "layouts").glob("*.yaml")) == ["apt_0.yaml", "apt_1.yaml"]
    assert (prep / "paths" / "query.txt").exists() and (prep / "paths" / "mapping.txt").exists()
    assert [Path(x).name for x in ready.designs[0].layouts] == ["apt_0.yaml", "apt_1.yaml"]
    q = load_layout(ready.designs[0].layouts[1])
    assert q.meta["source"] == "replicacad" and q.stage.walls
    # the planned path names the imported layout files, not the built-in layouts of the same names
    from synth.paths.files import load_path

    planned = load_path(prep / "paths" / "query.txt")
    assert planned.meta["layouts"] == [str((prep / "layouts" / f"{n}.yaml").resolve()) for n in ("apt_0", "apt_1")]
    # again: nothing is imported or planned a second time
    stamps = {p: p.stat().st_mtime_ns for p in prep.rglob("*") if p.is_file()}
    again = []
    prepare(spec, tmp_path / "job", cli_root=str(root), progress=again.append)
    assert again == [] and stamps == {p: p.stat().st_mtime_ns for p in prep.rglob("*") if p.is_file()}
    # the root from the environment
    os.environ["REPLICACAD_ROOT"] = str(root)
    try:
        assert prepare(spec, tmp_path / "job", progress=lambda m: None).replicacad["root"] == str(root.resolve())
    finally:
        del os.environ["REPLICACAD_ROOT"]


@pytest.mark.slow
def test_dry_run_shows_the_plan_and_writes_nothing(root, tmp_path, capsys):
    spec_file = tmp_path / "spec.yaml"
    spec_file.write_text(SPEC % (root, tmp_path / "job"))
    assert synth_main(["render", str(spec_file), "--dry-run"]) == 0
    out = capsys.readouterr().out
    assert "apt_1__night__query: 60 frames" in out and "apt_0__day__mapping: 600 frames" in out
    assert not (tmp_path / "job").exists()


@pytest.mark.parametrize("edit, field", [
    (lambda s, root: s % ("null", "{out}"), "replicacad.root"),  # no root anywhere
    (lambda s, root: s % ("/no/such/folder", "{out}"), "replicacad.root"),
    (lambda s, root: (s % (root, "{out}")).replace("[apt_0, apt_1]", "[apt_0, apt_9]"), "designs[0].layouts[1]"),
    (lambda s, root: (s % (root, "{out}")).replace("name: query", "name: walkway"), "designs[0].path.name"),
    (lambda s, root: (s % (root, "{out}")).replace("replicacad: {root: %s}" % root, "replicacad: {root: %s, extra: 1}" % root),
     "replicacad.extra"),
    (lambda s, root: (s % (root, "{out}")).replace("replicacad: {root: %s}" % root, "replicacad: {root: %s, obstacles: most}" % root),
     "replicacad.obstacles"),
])
def test_bad_replicacad_spec_is_one_line(root, tmp_path, capsys, monkeypatch, edit, field):
    monkeypatch.delenv("REPLICACAD_ROOT", raising=False)
    spec_file = tmp_path / "spec.yaml"
    spec_file.write_text(edit(SPEC, root).replace("{out}", str(tmp_path / "job")))
    assert synth_main(["render", str(spec_file), "--dry-run"]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and f"{spec_file}: {field}" in err, err
    assert not (tmp_path / "job").exists()


def test_replicacad_root_option_needs_a_replicacad_spec(root, capsys):
    smoke = Path(__file__).resolve().parents[3] / "render_jobs" / "smoke.yaml"
    assert synth_main(["render", str(smoke), "--dry-run", "--replicacad-root", str(root)]) == 2
    assert "has no replicacad: section" in capsys.readouterr().err


@pytest.mark.slow
def test_shipped_replicacad_spec_plans_the_paper_design(root, tmp_path):
    """render_jobs/replicacad_apt_6x3.yaml on the fixture: 18 query tours of 4,000 frames + the 6,000-frame mapping tour."""
    from synth.jobs import expand

    spec = load_spec(Path(__file__).resolve().parents[3] / "render_jobs" / "replicacad_apt_6x3.yaml")
    ready = prepare(spec, tmp_path / "job", cli_root=str(root), progress=lambda m: None)
    plan = expand(ready, tmp_path / "job")
    frames = {name: len(p.frame_ids) for name, p in plan.tours.items()}
    assert len(frames) == 19 and frames["apt_5__night__query"] == 4000 and frames["apt_0__day__mapping"] == 6000
    from synth.paths.files import load_path

    # the authored apartments share little floor: the shipped spec keeps its clearance at the camera's height
    q = load_path(tmp_path / "job" / "replicacad" / "paths" / "query.txt")
    assert q.meta["planner"]["obstacles"] == "band"


# ---- the whole pipeline on the fixture -------------------------------------------------------------

def _linear(srgb) -> np.ndarray:
    c = np.asarray(srgb[:3], float) / 255.0
    return np.where(c <= 0.04045, c / 12.92, ((c + 0.055) / 1.055) ** 2.4)


def _check_texture_colours(tour_dir: Path, layout_file: Path) -> None:
    from scipy import ndimage

    from vrformats.tour import Tour

    want = {k: _linear(v) / _linear(v).sum() for k, v in TEXTURE_SRGB.items()}
    tour, lay = Tour(tour_dir), load_layout(layout_file)
    seen = set()
    for i in range(len(tour)):
        f = tour.frame(i)
        if f.rgb is None:
            continue
        for o in lay.objects:
            mask = ndimage.binary_erosion(f.instance == o.id, iterations=1)
            if mask.sum() < 100:
                continue
            key = o.params["template"].rsplit("/", 1)[-1]
            key = key if key in want else f"{key}:body"  # the counter: its body's texture
            rgb = f.rgb[mask].mean(axis=0)
            chroma = rgb / rgb.sum()
            assert np.abs(chroma - want[key]).max() < 0.1, (i, o.cls, chroma, want[key])
            assert min(want, key=lambda k: np.abs(chroma - want[k]).max()) == key, (i, o.cls)
            seen.add(o.cls)
    assert {"dining_table", "chair", "sofa", "floor_lamp", "kitchen_counter"} <= seen, seen


PIPELINE = """name: fx_pipeline
replicacad: {root: %s}
out: %s
renderer: blender
geometry: fast
quality: preview
size: [160, 120]
chunk_size: 100
designs:
  - layouts: [apt_0, apt_1]
    lightings: [day]
    path: {name: query, frames: 300}
    rgb_every: 10
  - layouts: [apt_0]
    path: {name: mapping, frames: 600}
"""


@pytest.mark.blender
@pytest.mark.slow
def test_pipeline_render_map_run_eval_on_the_fixture(root, tmp_path, capsys):
    """Blender RGB + fast geometry from a ReplicaCAD root, a map built from the mapping tour, VideoReloc
    on the query tours of the reference and of the authored variant apt_1, recall from reloc eval."""
    from reloc.cli import main as reloc_main
    from synth.tour.check import check_tour

    job = tmp_path / "job"
    spec = tmp_path / "spec.yaml"
    spec.write_text(PIPELINE % (root, job))
    assert synth_main(["render", str(spec), "--workers", "2", "--quiet"]) == 0
    for tour in ("apt_0__day__query", "apt_1__day__query", "apt_0__geometry__mapping"):
        check_tour(job / tour)  # raises on a missing or malformed frame
    # textures: where a textured object projects (its instance mask, one pixel in), the day render
    # carries its texture's colour: chromaticity within 0.1 of the texture's, and nearer to it than
    # to any other texture of the fixture
    _check_texture_colours(job / "apt_0__day__query", job / "replicacad" / "layouts" / "apt_0.yaml")
    # the map built from the mapping tour holds every object and wall of the ground truth
    report = tmp_path / "map_report.json"
    assert reloc_main(["map", "build", str(job / "apt_0__geometry__mapping"), "--out", str(tmp_path / "map.json"),
                       "--report", str(report), "--quiet"]) == 0
    by_kind = json.loads(report.read_text())["errors"]["by_kind"]
    assert by_kind["object"]["matched"] == by_kind["object"]["gt"] == len(OBJECT_BOXES) + 1  # + the counter
    assert by_kind["wall"]["matched"] == by_kind["wall"]["gt"] == len(WALL_BOXES)
    assert by_kind["object"]["median_center_err_m"] < 0.05
    recall = {}
    for layout in ("apt_0", "apt_1"):
        tour = job / f"{layout}__day__query"
        out = tmp_path / f"run_{layout}"
        assert reloc_main(["run", "--map", str(tmp_path / "map.json"), "--tour", str(tour), "--out", str(out), "--quiet"]) == 0
        assert reloc_main(["eval", str(out), "--gt", str(tour), "--save", str(tmp_path / f"eval_{layout}.json")]) == 0
        ev = json.loads((tmp_path / f"eval_{layout}.json").read_text())
        recall[layout] = ev
    print(capsys.readouterr().out)  # the recall tables
    for layout, ev in recall.items():
        assert ev["frames"] == 300 and ev["closure"]["coverage"] == 1.0, layout
    # oracle detections on the layout the map was built from: VideoReloc places the whole tour
    assert recall["apt_0"]["closure"]["recall_1m_10deg"] >= 0.8


def test_paths_from_another_job_reuse_its_paths_and_are_checked_in_these_layouts(root, tmp_path, capsys):
    """Issue 55: the same camera path on another stage variant (here: the same dataset prepared twice,
    then a copy whose stage has a wall where the path runs). The reused path is not replanned, it keeps
    naming the layouts it was planned on, and the render's clearance check tests it in these layouts."""
    from synth.paths.files import load_path

    spec_file = tmp_path / "spec.yaml"
    spec_file.write_text(SPEC % ("null", tmp_path / "a"))
    spec = load_spec(spec_file)
    prepare(spec, tmp_path / "a", cli_root=str(root), progress=lambda m: None)
    first = load_path(tmp_path / "a" / "replicacad" / "paths" / "query.txt")
    spec_b = replace(spec, replicacad={**spec.replicacad, "paths_from": str(tmp_path / "a")})
    msgs = []
    ready = prepare(spec_b, tmp_path / "b", cli_root=str(root), progress=msgs.append)
    assert any(m.startswith("reusing the query path of") for m in msgs) and not any("planning" in m for m in msgs)
    reused = load_path(ready.designs[0].path)
    assert np.array_equal(reused.poses, first.poses)
    assert reused.meta["layouts"] == first.meta["layouts"]  # planned on job a's layouts, not on b's
    # the same stage: the clearance check passes; from the command line too
    assert synth_main(["render", str(spec_file), "--out", str(tmp_path / "c"), "--dry-run", "--replicacad-root", str(root),
                       "--paths-from", str(tmp_path / "a")]) == 0
    capsys.readouterr()
    # a folder without the path: one line naming the field
    bad = replace(spec, replicacad={**spec.replicacad, "paths_from": str(tmp_path / "nothing")})
    with pytest.raises(SceneFormatError) as e:
        prepare(bad, tmp_path / "d", cli_root=str(root), progress=lambda m: None)
    assert "replicacad.paths_from" in str(e.value) and "no planned 'query' path" in str(e.value)
    assert synth_main(["render", str(Path(__file__).resolve().parents[3] / "render_jobs" / "smoke.yaml"), "--dry-run",
                       "--paths-from", str(tmp_path / "a")]) == 2
    assert "--paths-from" in capsys.readouterr().err


def test_a_stage_that_cannot_hold_a_reused_path_is_refused_in_one_line(root, tmp_path, capsys):
    """A path reused from another stage variant that runs through this stage's wall: the render's
    clearance check names the path, the layout, the frame and the remedy; nothing is rendered."""
    from synth.paths.files import load_path, save_path

    spec_file = tmp_path / "spec.yaml"
    spec_file.write_text(SPEC % ("null", tmp_path / "a"))
    prepare(load_spec(spec_file), tmp_path / "a", cli_root=str(root), progress=lambda m: None)
    q = tmp_path / "a" / "replicacad" / "paths" / "query.txt"
    p = load_path(q)
    p.poses[:, 0, 3] += 50.0  # 50 m east: outside every room of the flat
    save_path(p, q)
    assert synth_main(["render", str(spec_file), "--out", str(tmp_path / "b"), "--dry-run", "--replicacad-root", str(root),
                       "--paths-from", str(tmp_path / "a")]) == 2
    lines = capsys.readouterr().err.strip().splitlines()  # progress lines (import, reuse), then the error
    errors = [x for x in lines if x.startswith("synth: error:")]
    assert len(errors) == 1 and errors[0] == lines[-1], lines
    assert "camera path 'query' was planned on" in errors[0] and "--allow-clearance-breach" in errors[0]
    assert not (tmp_path / "b").exists()
