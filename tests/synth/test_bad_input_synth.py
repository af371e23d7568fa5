"""Bad input found in a user trial (issue 12): each test failed before its fix.

1. a poses.txt shorter than the frame files was read as a shorter tour (exit 0);
2. `synth tour check` counted displayed lines as problems;
3. a layout without rooms and walls checked OK;
4. render specs named neither the spec file nor the field of an unknown name or unwritable `out`;
5. no command made a new rearranged variant;
6. the query path passes closer than its clearance in new variants, and nothing said so.

Tours here are tiny fast-renderer tours (Open3D, geometry only, a few frames at 32x24).
"""

from __future__ import annotations

import json
import math
import shutil
import time

import numpy as np
import pytest
import yaml

from reloc.cli import main as reloc_main

from vrformats.errors import SceneFormatError
from vrformats.frames import FrameFileError, write_frame
from vrformats.tour import Tour
from synth.layout.validity import check_layout
from synth.cli import main as synth_main
from synth.tour.check import check_tour
from synth.paths.clearance import path_clearance
from synth.paths.files import load_path, save_path
from synth.paths.model import CameraPath
from synth.scene.model import load_layout, object_box, save_layout
from synth.scene.stats import PAPER_RANGES, change_stats
from synth.tour.render import TourSpec, render_tour
from cli_errors import one_line_error

W, H = 32, 24
VARIANT_SEED = 12345  # the trial's variant: the query path passes 0.225 m from an object near frame 2817


@pytest.fixture(scope="module")
def small_tour(tmp_path_factory):
    """A complete 24-frame geometry tour of apt_0 along the query path (fast renderer)."""
    out = tmp_path_factory.mktemp("tours") / "apt_0__geometry__query"
    render_tour(TourSpec(layout="apt_0", path="query", out=str(out), renderer="fast", width=W, height=H, frames=24),
                progress=False)
    return out


@pytest.fixture
def tour(small_tour, tmp_path):
    dst = tmp_path / small_tour.name
    shutil.copytree(small_tour, dst)
    return dst


def _cut_poses(root, keep: int) -> None:
    lines = (root / "poses.txt").read_text().splitlines()
    head = [ln for ln in lines if ln.startswith("#")]
    body = [ln for ln in lines if ln.strip() and not ln.startswith("#")]
    (root / "poses.txt").write_text("\n".join(head + body[:keep]) + "\n")


# ---------------------------------------------------------------------------------------------
# 1. poses.txt and frame files disagree


def test_poses_cut_short_is_refused_by_every_reader(tour, tmp_path, capsys):
    _cut_poses(tour, 10)  # 10 poses, 24 frame files
    with pytest.raises(SceneFormatError, match=r"poses\.txt: 10 poses for 24 frame files"):
        Tour(tour)
    assert synth_main(["tour", "show", str(tour), "--out", str(tmp_path / "s.png")]) == 2
    err = one_line_error(capsys)
    assert "poses.txt" in err and "10 poses for 24 frame files" in err
    # reloc reads tours through vrformats.tour.Tour: no silently shortened map
    assert reloc_main(["map", "build", str(tour), "--out", str(tmp_path / "m.json"), "--quiet"]) == 2
    err = one_line_error(capsys)
    assert "poses.txt" in err and "10 poses for 24 frame files" in err
    assert not (tmp_path / "m.json").exists()
    # the check reports it, and its first line counts the frame files on disk
    assert synth_main(["tour", "check", str(tour)]) == 1
    out = capsys.readouterr().out
    assert out.splitlines()[0].startswith(f"{tour}: 10 poses for 24 frame files")
    assert "frames not in poses.txt (14): 10-23" in out


def test_meta_frame_count_disagreeing_with_poses_is_refused(tour, capsys):
    meta = json.loads((tour / "meta.json").read_text())
    assert meta["n_frames"] == 24
    for f in range(12, 24):  # poses and frames cut alike: only meta.json still knows
        (tour / "frames" / f"{f:06d}.exr").unlink()
    _cut_poses(tour, 12)
    with pytest.raises(SceneFormatError, match=r"poses\.txt: 12 poses, but meta\.json says the tour has 24 frames"):
        Tour(tour)
    rep = check_tour(tour)
    assert not rep["ok"] and any("meta.json says the tour has 24 frames" in p for p in rep["problems"])


def test_partly_rendered_tour_is_readable_and_resumes(tmp_path, capsys):
    """Fewer frame files than poses is a tour being rendered: readable, reported, and resumable."""
    spec = TourSpec(layout="apt_0", path="query", out=str(tmp_path / "t"), renderer="fast", width=W, height=H, frames=8)
    render_tour(spec, progress=False)
    root = tmp_path / "t"
    for f in (5, 6, 7):  # as if killed after frame 4
        (root / "frames" / f"{f:06d}.exr").unlink()
    meta = json.loads((root / "meta.json").read_text())
    (root / "meta.json").write_text(json.dumps({**meta, "complete": False}))
    t = Tour(root)
    assert len(t) == 8 and t.frame_files() == [0, 1, 2, 3, 4]
    with pytest.raises(FrameFileError, match="000006.exr"):
        t.frame(6)
    assert synth_main(["tour", "check", str(root)]) == 1
    out = capsys.readouterr().out
    assert out.splitlines()[0].startswith(f"{root}: 8 poses for 5 frame files")
    assert "missing frames (3 of 8, no EXR in frames/): 5-7" in out
    meta = render_tour(spec, progress=False)  # resume
    assert meta["complete"] and meta["geometry_frames_rendered_now"] == 3
    assert synth_main(["tour", "check", str(root)]) == 0
    assert "8/8 frames" in capsys.readouterr().out
    assert len(Tour(root)) == 8


# ---------------------------------------------------------------------------------------------
# 2. the problem count


def test_problem_count_is_problems_not_displayed_lines(tour, capsys):
    t = Tour(tour)
    for i in t.frame_indices:  # every frame loses its depth (all zero): 24 problems, 20 shown
        f = t.frame(int(i))
        write_frame(t.frame_path(int(i)), depth=np.zeros_like(f.depth), instance=f.instance, semantic=f.semantic)
    rep = check_tour(tour)
    assert rep["problem_total"] == 24
    assert rep["problem_counts"] == {"frames with all-zero depth": 24}
    assert len(rep["problems"]) == 21  # 20 lines + "... and 4 more like the above"
    assert synth_main(["tour", "check", str(tour)]) == 1
    last = capsys.readouterr().out.strip().splitlines()[-1]
    assert last.strip() == "PROBLEMS FOUND (24): 24 frames with all-zero depth"


# ---------------------------------------------------------------------------------------------
# 3. a layout without rooms and walls


def _shell_less(tmp_path):
    lay = load_layout("apt_0").copy()
    lay.name = "no_shell"
    lay.stage.rooms, lay.stage.walls, lay.stage.openings = [], [], []
    lay.objects = [o for o in lay.objects if o.support == "floor"][:3]
    lay.fixtures = []
    return lay


def test_layout_without_rooms_or_walls_is_a_problem(tmp_path, capsys):
    lay = _shell_less(tmp_path)
    rep = check_layout(lay)
    assert not rep.ok and {s["what"] for s in rep.structure} == {"rooms", "walls"}
    p = save_layout(lay, tmp_path / "no_shell.yaml")
    assert synth_main(["scene", "check", str(p)]) == 1
    out = capsys.readouterr().out
    assert "no rooms" in out and "no walls" in out and "PROBLEMS FOUND" in out and "OK" not in out
    assert synth_main(["scene", "check", str(p), "--json"]) == 1
    assert json.loads(capsys.readouterr().out)["ok"] is False
    # a stage mesh (ReplicaCAD) is its own shell: no rooms or walls expected
    lay.stage.asset = "replicacad:stages/frl_apartment_stage.glb"
    assert check_layout(lay).structure == []


# ---------------------------------------------------------------------------------------------
# 4. render specs: file and field


def _spec(tmp_path, **changes):
    doc = {"name": "t", "out": str(tmp_path / "out"), "renderer": "fast", "size": [W, H],
           "designs": [{"layouts": ["apt_0", "apt_1"], "path": {"name": "query", "frames": 3}}]}
    doc.update(changes)
    p = tmp_path / "spec.yaml"
    p.write_text(yaml.safe_dump(doc))
    return p


@pytest.mark.parametrize(
    "design, field, message",
    [
        ({"layouts": ["apt_0", "apt_9"], "path": "query"}, "designs[0].layouts[1]", "unknown layout 'apt_9'"),
        ({"layouts": ["apt_0"], "lightings": ["day", "dusk"], "path": "query"}, "designs[0].lightings[1]",
         "unknown lighting preset 'dusk'"),
        ({"layouts": ["apt_0"], "path": {"name": "nowhere"}}, "designs[0].path", "unknown camera path 'nowhere'"),
        ({"layouts": ["apt_0"], "path": {"name": "query", "frames": 99999}}, "designs[0].path.frames", "exceeds"),
    ],
)
def test_spec_unknown_names_name_spec_file_and_field(tmp_path, capsys, design, field, message):
    renderer = "blender" if "lightings" in design else "fast"
    spec = _spec(tmp_path, renderer=renderer, designs=[{"layouts": ["apt_0"], "path": "query"}, design])
    field = field.replace("designs[0]", "designs[1]")
    assert synth_main(["render", str(spec), "--quiet"]) == 2
    err = one_line_error(capsys)
    assert err.startswith(f"synth: error: {spec}: {field}: ") and message in err, err
    assert not (tmp_path / "out").exists()


def test_spec_unwritable_out_names_spec_file_and_field(tmp_path, capsys):
    spec = _spec(tmp_path, out="/proc/forbidden")
    assert synth_main(["render", str(spec), "--quiet"]) == 2
    err = one_line_error(capsys)
    assert err.startswith(f"synth: error: {spec}: out: ") and "/proc/forbidden" in err
    # the command line's --out overrides the spec's: named as such
    assert synth_main(["render", str(_spec(tmp_path)), "--out", "/proc/forbidden", "--quiet"]) == 2
    err = one_line_error(capsys)
    assert err.startswith("synth: error: --out: ") and "/proc/forbidden" in err


# ---------------------------------------------------------------------------------------------
# 5. synth scene rearrange


@pytest.fixture(scope="module")
def variant(tmp_path_factory):
    """The trial's variant of apt_0 (seed 12345), made from Python as the trial had to."""
    from synth.layout.rearrange import RearrangePlan, VariantSpec, make_variant, reference_walkway

    ref = load_layout("apt_0")
    var = make_variant(ref, VariantSpec("apt_x", VARIANT_SEED, RearrangePlan()), walkway=reference_walkway(ref))
    return save_layout(var, tmp_path_factory.mktemp("variant") / "apt_x.yaml")


@pytest.mark.slow
def test_rearrange_makes_a_checked_variant_in_the_paper_ranges(variant, tmp_path, capsys):
    made = tmp_path / "apt_x.yaml"
    assert synth_main(["scene", "rearrange", "apt_0", "--seed", str(VARIANT_SEED), "--out", str(made)]) == 0
    assert made.read_bytes() == variant.read_bytes()  # the operator, plan and walkway of the Python route
    lay, ref = load_layout(made), load_layout("apt_0")
    assert lay.name == "apt_x" and lay.reference == "apt_0"
    assert lay.meta["variant_seed"] == VARIANT_SEED and lay.meta["walkway"]["planned_on"] == "apt_0"
    st = change_stats(ref, lay)
    assert all(lo <= st[k] <= hi for k, (lo, hi) in PAPER_RANGES.items()), st
    assert check_layout(lay).ok
    # --name, and the statistics printed like `synth scene build`
    out = tmp_path / "v.yaml"
    assert synth_main(["scene", "rearrange", "apt_0", "--seed", str(VARIANT_SEED), "--out", str(out),
                       "--name", "apt_6"]) == 0
    text = capsys.readouterr().out
    assert "paper" in text and "moved_over_0.1m" in text and f"wrote {out}" in text
    row = next(ln for ln in text.splitlines() if ln.startswith("apt_6 "))
    assert row.split()[2] == "ok" and row.split()[3:] == [str(st[k]) for k in PAPER_RANGES]
    assert load_layout(out).name == "apt_6"


def test_rearrange_refuses_unwritable_out_before_work(tmp_path, capsys, monkeypatch):
    from synth.layout import rearrange

    def boom(*a, **k):
        raise AssertionError("work started")

    monkeypatch.setattr(rearrange, "reference_walkway", boom)
    monkeypatch.setattr(rearrange, "make_variant", boom)
    blocker = tmp_path / "a_file"
    blocker.write_text("x")
    for out, why in [(blocker / "v.yaml", "is not a folder"), ("/proc/forbidden/v.yaml", "cannot create"),
                     (tmp_path, "ends in .yaml"), (tmp_path / "v.json", "ends in .yaml")]:
        assert synth_main(["scene", "rearrange", "apt_0", "--seed", "1", "--out", str(out)]) == 2
        err = one_line_error(capsys)
        assert err.startswith("synth: error: --out: ") and why in err, err
    assert synth_main(["scene", "rearrange", "apt_0", "--seed", "1", "--out", str(tmp_path / "apt_0.yaml")]) == 2
    assert "--name" in one_line_error(capsys)  # a variant named like its base


def test_rearrange_without_a_variant_in_range_exits_2(tmp_path, capsys):
    out = tmp_path / "v.yaml"
    # seed 2's first draw moves 65 objects by more than 0.1 m (paper: 68-76)
    assert synth_main(["scene", "rearrange", "apt_0", "--seed", "2", "--attempts", "1", "--out", str(out)]) == 2
    err = one_line_error(capsys)
    assert "no variant of apt_0 from seed 2" in err and "moved_over_0.1m 65 (paper 68-76)" in err
    assert "another --seed" in err
    assert not out.exists()


# ---------------------------------------------------------------------------------------------
# 6. clearance of a path in layouts it was not planned on


def _footprint_dist(xy, box) -> float:
    c, s = math.cos(box.yaw), math.sin(box.yaw)
    dx, dy = xy[0] - box.center[0], xy[1] - box.center[1]
    lx, ly = abs(dx * c + dy * s) - box.size[0] / 2, abs(-dx * s + dy * c) - box.size[1] / 2
    return math.hypot(max(lx, 0.0), max(ly, 0.0))


def _breach_ranges(d, clearance):
    idx = np.flatnonzero(d < clearance - 1e-6)
    runs = np.split(idx, np.flatnonzero(np.diff(idx) > 1) + 1) if len(idx) else []
    return [(int(r[0]), int(r[-1])) for r in runs]


def test_path_check_names_frames_and_object(variant, capsys):
    query, lay = load_path("query"), load_layout(variant)
    d = path_clearance(query, lay)
    assert round(float(d.min()), 3) == 0.225 and int((d < 0.3).sum()) == 28
    ranges = _breach_ranges(d, 0.3)
    k = int(np.argmin(d))
    xy = query.poses[k, :2, 3]
    near = min((o for o in lay.objects if o.support != "ceiling"), key=lambda o: _footprint_dist(xy, object_box(o)))
    assert synth_main(["path", "check", "query", "--layout", "apt_1", "--layout", str(variant)]) == 1
    out = capsys.readouterr().out
    assert "apt_1: ok" in out
    for a, b in ranges:
        assert f"frames {a}-{b}" in out
    assert f"object {near.id} ({near.cls})" in out and "0.225 m" in out
    assert "synth path plan query --layouts apt_0 apt_1 apt_2 apt_3 apt_4 apt_5" in out
    assert synth_main(["path", "check", "query", "--layout", str(variant), "--json"]) == 1
    rep = json.loads(capsys.readouterr().out)
    assert [tuple(r["frames"]) for r in rep["layouts"][0]["ranges"]] == ranges
    # the layouts it was planned on: one OK line, exit 0
    assert synth_main(["path", "check", "query"]) == 0
    out = capsys.readouterr().out.strip()
    assert len(out.splitlines()) == 1 and out.startswith("OK: camera path 'query' keeps 0.3 m clearance in apt_0")
    assert synth_main(["path", "check", "query", "--layout", "apt_9"]) == 2
    assert "unknown layout 'apt_9'" in one_line_error(capsys)


def test_path_check_is_cheap(variant):
    from synth.paths.clearance import clearance_report

    query, lay = load_path("query"), load_layout(variant)
    clearance_report(query, lay)  # warm-up (imports)
    t0 = time.perf_counter()
    rep = clearance_report(query, lay)
    dt = time.perf_counter() - t0
    assert rep["frames"] == 4000 and not rep["ok"]
    assert dt < 1.0, f"clearance check of 4000 frames took {dt:.3f} s"  # measured: about 0.03 s


@pytest.fixture(scope="module")
def short_query(tmp_path_factory):
    """16 frames of the query path around its closest pass in the variant, with the query path's
    sidecar (planned on apt_0..apt_5 with 0.3 m clearance)."""
    q = load_path("query")
    p = CameraPath("query16", q.poses[2810:2826].copy(), q.fps, dict(q.meta))
    return save_path(p, tmp_path_factory.mktemp("paths") / "query16.txt")


def test_tour_render_refuses_a_clearance_breach(variant, short_query, tmp_path, capsys):
    out = tmp_path / "tour"
    args = ["tour", "render", str(variant), str(short_query), "--renderer", "fast", "--size", f"{W}x{H}",
            "--out", str(out), "--quiet"]
    assert synth_main(args) == 2
    err = one_line_error(capsys)
    assert "layout 'apt_x'" in err and "0.225 m" in err and "at frame 7" in err and "(14 frames" in err
    assert "object " in err and "synth path plan query --layouts" in err and "--allow-clearance-breach" in err
    assert not out.exists()
    # a layout the path was planned on is not checked; the breach can be allowed
    assert synth_main(["tour", "render", "apt_1", str(short_query), "--renderer", "fast", "--size", f"{W}x{H}",
                       "--out", str(tmp_path / "ok"), "--quiet", "--frames", "2"]) == 0
    assert synth_main(args + ["--allow-clearance-breach"]) == 0
    assert len(Tour(out)) == 16


@pytest.mark.slow
def test_render_spec_refuses_a_clearance_breach_before_rendering(variant, short_query, tmp_path, capsys):
    spec = _spec(tmp_path, designs=[{"layouts": ["apt_0", str(variant)], "path": {"name": str(short_query)}}])
    assert synth_main(["render", str(spec), "--quiet"]) == 2
    err = one_line_error(capsys)
    assert err.startswith(f"synth: error: {spec}: designs[0].layouts[1]: ") and "0.225 m" in err
    assert "--allow-clearance-breach" in err
    assert not (tmp_path / "out").exists()
    assert synth_main(["render", str(spec), "--quiet", "--allow-clearance-breach"]) == 0
    assert len(Tour(tmp_path / "out" / "apt_x__geometry__query16")) == 16


@pytest.mark.parametrize("state", ["{not json", "[1, 2]", b"\xff\xfe"])
def test_an_unreadable_job_state_is_one_line_and_kept(tmp_path, capsys, state):
    """A job_state.json that is not a JSON object: --resume says which file and what to do, exit 2,
    and leaves the file as it was."""
    spec = _spec(tmp_path)
    out = tmp_path / "out"
    out.mkdir()
    f = out / "job_state.json"
    f.write_bytes(state if isinstance(state, bytes) else state.encode())
    before = f.read_bytes()
    assert synth_main(["render", str(spec), "--out", str(out), "--resume", "--quiet"]) == 2
    line = one_line_error(capsys, str(f), "unreadable job state", "delete it to start the job afresh")
    assert "\n" not in line and f.read_bytes() == before
