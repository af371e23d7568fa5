"""Render jobs: spec validation, the plan, retries and state, kill + resume, and the Ray backend."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from cli_errors import exit_code
from jobspecs import write_spec

from vrformats.tour import Tour
from vrformats.errors import UserError
from synth import jobs
from synth.cli import main as synth_main
from synth.resources import REPO_ROOT



from jobspecs import SMOKE  # noqa: E402  (one home: tests/jobspecs.py)




@pytest.mark.slow
def test_shipped_specs_validate_and_expand():
    for name in ("smoke", "demo", "replicacad_6x3"):
        plan = jobs.expand(jobs.load_spec(REPO_ROOT / "render_jobs" / f"{name}.yaml"), out=Path("/nonexistent/x"))
        assert plan.tours and plan.chunks
    paper = jobs.expand(jobs.load_spec(REPO_ROOT / "render_jobs" / "replicacad_6x3.yaml"), out=Path("/nonexistent/x"))
    # the paper's design: 6 layouts x 3 lightings on the 4,000-frame query path + the 6,000-frame mapping tour
    assert len(paper.tours) == 19
    query = [p for n, p in paper.tours.items() if n.endswith("__query")]
    assert len(query) == 18 and all(len(p.frame_ids) == 4000 for p in query)
    assert len(paper.tours["apt_0__day__mapping"].frame_ids) == 6000
    rgb = sum(len(c.frames) for c in paper.chunks if c.kind == "rgb")
    geo = sum(len(c.frames) for c in paper.chunks if c.kind == "geometry")
    assert rgb == 18 * 4000 + 6000 and geo == 6 * 4000 + 6000  # geometry once per layout + path


def test_plan_shares_geometry_between_lightings(tmp_path):
    plan = jobs.expand(jobs.load_spec(SMOKE), out=tmp_path / "o")
    geo = [c for c in plan.chunks if c.kind == "geometry"]
    rgb = [c for c in plan.chunks if c.kind == "rgb"]
    assert len(geo) == 2 * 2 and len(rgb) == 2 * 2 * 2  # 2 layouts x 2 chunks; x 2 lightings for rgb
    assert {c.needs for c in rgb} == {c.id for c in geo}
    assert not (tmp_path / "o").exists()  # planning writes nothing


def test_fast_geometry_and_rgb_every_split_chunks(tmp_path):
    spec = write_spec(tmp_path, geometry="fast", chunk_size=4, designs=[
        {"layouts": ["apt_0"], "lightings": ["day", "night"], "path": {"name": "query", "frames": 10}, "rgb_every": 3},
        {"layouts": ["apt_0"], "lightings": ["day"], "path": {"name": "mapping", "frames": 8}}])
    plan = jobs.expand(jobs.load_spec(spec), out=tmp_path / "o")
    geo = [c for c in plan.chunks if c.kind == "fast"]
    assert not [c for c in plan.chunks if c.kind == "geometry"]
    assert all(Path(c.out_dir).name.endswith("__fast") for c in geo)  # never mixed with a Cycles cache
    for lighting in ("day", "night"):
        name = f"apt_0__{lighting}__query"
        rgb = sorted(i for c in plan.chunks if c.tour == name and c.kind == "rgb" for i in c.frames)
        copy = sorted(i for c in plan.chunks if c.tour == name and c.kind == "copy" for i in c.frames)
        assert rgb == [0, 3, 6, 9] and copy == [1, 2, 4, 5, 7, 8]
    mapping = [c for c in plan.chunks if c.tour == "apt_0__day__mapping"]
    assert {c.kind for c in mapping} == {"fast", "rgb"}  # rgb_every defaults to 1: RGB on every frame
    by_id = {c.id: c for c in plan.chunks}
    for c in plan.chunks:  # each copy/rgb chunk waits for the geometry chunk that holds its frames
        if c.needs:
            assert set(c.frames) <= set(by_id[c.needs].frames)


@pytest.mark.parametrize(
    "changes, message",
    [
        ({"colour": "red"}, "colour: unknown key"),
        ({"designs": [{"layouts": ["apt_0"], "lightings": ["day"], "path": "query", "extra": 1}]}, "designs[0].extra: unknown key"),
        ({"designs": [{"layouts": ["apt_9"], "lightings": ["day"], "path": "query"}]}, "unknown layout 'apt_9'"),
        ({"designs": [{"layouts": ["apt_0"], "lightings": ["dusk"], "path": "query"}]}, "unknown lighting preset 'dusk'"),
        ({"designs": [{"layouts": ["apt_0"], "lightings": ["day"], "path": "nowhere"}]}, "unknown camera path 'nowhere'"),
        ({"designs": [{"layouts": ["apt_0"], "lightings": ["day"], "path": {"name": "query", "frames": 0}}]}, "designs[0].path.frames: expected a positive integer"),
        ({"designs": [{"layouts": ["apt_0"], "lightings": ["day"], "path": {"name": "query", "frames": -5}}]}, "expected a positive integer"),
        ({"chunk_size": 0}, "chunk_size: expected a positive integer"),
        ({"size": [64, -48]}, "size: expected a positive integer"),
        ({"quality": "ultra"}, "unknown quality preset 'ultra'"),
        ({"designs": []}, "designs: expected a non-empty list"),
        ({"geometry": "cycles"}, "geometry: expected blender or fast"),
        ({"designs": [{"layouts": ["apt_0"], "lightings": ["day"], "path": "query", "rgb_every": 0}]}, "designs[0].rgb_every: expected a positive integer"),
        ({"designs": [{"layouts": ["apt_0"], "path": "query", "rgb_every": 2}]}, "designs[0].rgb_every: a geometry-only design renders no RGB"),
        ({"cycles": {"denoise_prefilter": "BEST"}}, "cycles.denoise_prefilter: expected one of NONE, FAST, ACCURATE"),
        ({"cycles": {"sample": 4}}, "cycles: unknown key(s) ['sample']"),
        ({"cycles": {"samples": 0}}, "cycles.samples: expected a positive integer"),
        ({"cycles": {"denoise": "yes"}}, "cycles.denoise: expected true or false"),
        ({"cycles": [4]}, "cycles: expected a mapping of Cycles settings"),
        ({"threads": -1}, "threads: expected a non-negative integer"),
        ({"renderer": "fast", "cycles": {"samples": 4}, "designs": [{"layouts": ["apt_0"], "path": "query"}]},
         "cycles: the fast renderer has no Cycles settings"),
    ],
)
def test_bad_specs_one_line_exit_2_nothing_written(tmp_path, capsys, changes, message):
    spec = write_spec(tmp_path, **changes)
    out = tmp_path / "out"
    assert synth_main(["render", str(spec), "--out", str(out), "--quiet"]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("synth: error:") and message in err and len(err.splitlines()) == 1, err
    assert not out.exists()


def test_malformed_yaml_and_unwritable_out(tmp_path, capsys):
    bad = tmp_path / "bad.yaml"
    bad.write_text("name: x\ndesigns: [\n")
    assert synth_main(["render", str(bad), "--quiet"]) == 2
    assert str(bad) in capsys.readouterr().err
    blocker = tmp_path / "file"
    blocker.write_text("x")
    assert synth_main(["render", str(SMOKE), "--out", str(blocker / "out"), "--quiet"]) == 2
    assert "is not a folder" in capsys.readouterr().err


@pytest.mark.slow
def test_failing_chunk_is_retried_then_reported_and_others_go_on(tmp_path, monkeypatch):
    """The scheduler with a worker that always fails on one chunk (a stand-in for a crashing Blender)."""
    spec = jobs.load_spec(write_spec(tmp_path, renderer="fast", designs=[{"layouts": ["apt_0", "apt_1"], "path": {"name": "query", "frames": 6}}]))
    calls = []
    real = jobs.chunk_queue.run_chunk_process

    def flaky(kind, job, job_file, log_file, on_frame=None):
        calls.append(job["frames"][0])
        if "apt_1" in job["layout"] and job["frames"][0] == 3:
            Path(log_file).write_text("boom")
            return 1, "RuntimeError: simulated crash", {}
        return real(kind, job, job_file, log_file, on_frame)

    monkeypatch.setattr(jobs.chunk_queue, "run_chunk_process", flaky)
    s = jobs.run_job(spec, tmp_path / "o", workers=1, progress=False)
    assert list(s["failed"]) == ["fast/apt_1__geometry__query/0001"]
    assert "simulated crash" in s["failed"]["fast/apt_1__geometry__query/0001"]
    state = json.loads((tmp_path / "o" / "job_state.json").read_text())
    bad = state["chunks"]["fast/apt_1__geometry__query/0001"]
    assert bad["state"] == "failed" and bad["attempts"] == spec.retries + 1
    assert sum(c["state"] == "done" for c in state["chunks"].values()) == 3
    assert len(list((tmp_path / "o" / "apt_0__geometry__query" / "frames").glob("*.exr"))) == 6
    # the same job again without --resume is refused; with --resume only the failed chunk runs
    with pytest.raises(UserError, match="--resume"):
        jobs.run_job(spec, tmp_path / "o", progress=False)
    monkeypatch.setattr(jobs.chunk_queue, "run_chunk_process", real)
    s2 = jobs.run_job(spec, tmp_path / "o", resume=True, progress=False)
    assert s2["failed"] == {} and s2["frames_rendered_now"] == 3


def _frames(root: Path) -> dict[str, list[Path]]:
    return {t.name: sorted((t / "frames").glob("*.exr")) for t in sorted(root.iterdir()) if (t / "frames").is_dir()}


def _assert_same_job(a: Path, b: Path) -> None:
    fa, fb = _frames(a), _frames(b)
    assert fa.keys() == fb.keys() and fa
    for name in fa:
        assert [p.name for p in fa[name]] == [p.name for p in fb[name]]
        for fname in ("camera.json", "poses.txt", "objects.json", "meta.json"):
            assert (a / name / fname).read_bytes() == (b / name / fname).read_bytes(), (name, fname)
        ta, tb = Tour(a / name), Tour(b / name)
        for x, y in zip(ta, tb):
            assert np.array_equal(x.depth, y.depth) and np.array_equal(x.instance, y.instance)
            assert np.array_equal(x.semantic, y.semantic)
            assert np.array_equal(x.rgb, y.rgb)  # same Cycles seed, same CPU: the same image


@pytest.mark.blender
@pytest.mark.slow
def test_killed_job_resumes_to_the_same_result(tmp_path, smoke_reference):
    ref = smoke_reference
    out = tmp_path / "killed"
    proc = subprocess.Popen([sys.executable, "-m", "synth.cli", "render", str(SMOKE), "--out", str(out), "--quiet"],
                            start_new_session=True, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    deadline = time.time() + 120
    while time.time() < deadline:  # kill once some, but not all, frames exist
        n = len(list(out.glob("*/frames/*.exr"))) if out.exists() else 0
        if n >= 8:
            break
        time.sleep(0.2)
    os.killpg(proc.pid, signal.SIGKILL)  # the runner and its Blender workers
    proc.wait()
    partial = len(list(out.glob("*/frames/*.exr")))
    assert 0 < partial < 24
    assert not [p for p in out.rglob("*.exr") if p.stat().st_size == 0]
    before = {p: p.stat().st_mtime_ns for p in out.rglob("frames/*.exr")} | {p: p.stat().st_mtime_ns for p in (out / "_geometry").rglob("*.exr")}
    s = jobs.run_job(jobs.load_spec(SMOKE), out, resume=True, progress=False)
    assert s["failed"] == {}
    # nothing that was done is rendered again
    assert all(p.stat().st_mtime_ns == t for p, t in before.items())
    assert not list(out.rglob(".*.tmp"))
    _assert_same_job(ref, out)


@pytest.mark.blender
@pytest.mark.slow
def test_ray_backend_on_loopback_renders_the_smoke_spec(tmp_path, smoke_reference):
    pytest.importorskip("ray")
    ref = smoke_reference
    out = tmp_path / "ray"
    s = jobs.run_job(jobs.load_spec(SMOKE), out, backend="ray", progress=False)
    assert s["failed"] == {} and s["frames_rendered_now"] == 36
    _assert_same_job(ref, out)


@pytest.mark.slow
@pytest.mark.blender
def test_fast_geometry_with_sparse_rgb_renders_a_checked_tour(tmp_path):
    """Depth and ids of every frame from the fast renderer, Cycles RGB on every 3rd frame only."""
    from synth.tour.check import check_tour
    from synth.render.fast_render import FastRenderer
    from synth.scene.model import load_layout
    from synth.tour.render import resolve_layout_path

    spec = write_spec(tmp_path, geometry="fast", chunk_size=4, designs=[
        {"layouts": ["apt_0"], "lightings": ["night"], "path": {"name": "query", "frames": 7}, "rgb_every": 3}])
    s = jobs.run_job(jobs.load_spec(spec), tmp_path / "o", progress=False)
    assert s["failed"] == {}
    tour = Tour(tmp_path / "o" / "apt_0__night__query")
    assert tour.rgb_every == 3
    renderer = FastRenderer(load_layout(resolve_layout_path("apt_0")))
    for i in tour.frame_indices:
        f = tour.frame(int(i))
        assert (f.rgb is not None) == (i % 3 == 0)
        depth, inst, _ = renderer.render(tour.pose(int(i)), tour.intrinsics)
        np.testing.assert_array_equal(f.depth, depth)  # the fast renderer's own output, every frame
        np.testing.assert_array_equal(f.instance, inst)
    rep = check_tour(tour.root, progress=False)
    assert not rep["missing_channels"], rep["missing_channels"]


def test_dry_run_prints_plan_and_estimate_writes_nothing(tmp_path, capsys):
    spec = write_spec(tmp_path, renderer="fast", designs=[{"layouts": ["apt_0"], "path": {"name": "query", "frames": 30}}])
    out = tmp_path / "o"
    assert synth_main(["render", str(spec), "--out", str(out), "--dry-run"]) == 0
    text = capsys.readouterr().out
    assert "1 tours, 30 chunk-frames" in text and "estimate with 1 worker(s)" in text and "calibration" in text
    assert not out.exists()


def test_spec_document_of_a_plain_spec_is_unchanged_by_the_replicacad_key():
    """A job started before specs could name a ReplicaCAD root resumes: the state document of a spec
    without replicacad: holds no such key (job_state.json compares documents)."""
    from synth.jobs import spec_document

    plain = spec_document(jobs.load_spec(REPO_ROOT / "render_jobs" / "demo.yaml"))
    assert "replicacad" not in plain
    rc = spec_document(jobs.load_spec(REPO_ROOT / "render_jobs" / "replicacad_apt_6x3.yaml"))
    assert rc["replicacad"] == {"root": None, "allow_unknown": False, "obstacles": "band"}


def test_spec_document_leaves_out_unset_cycles_and_threads_and_records_set_ones(tmp_path):
    """A job started before specs had cycles: and threads: resumes (its state document has neither); a job
    that sets them records them, so a resume with other settings is refused."""
    from synth.jobs import spec_document

    plain = spec_document(jobs.load_spec(REPO_ROOT / "render_jobs" / "demo.yaml"))
    assert "cycles" not in plain and "threads" not in plain
    spec = jobs.load_spec(write_spec(tmp_path, cycles={"denoise_prefilter": "ACCURATE"}, threads=1))
    doc = spec_document(spec)
    assert doc["cycles"] == {"denoise_prefilter": "ACCURATE"} and doc["threads"] == 1


@pytest.mark.parametrize("args, says", [
    (["--seed", "-1"], "--seed: expected an integer from 0 to"),
    (["--threads", "999"], "--threads: expected an integer from 0 to 256"),
    (["--cycles", "samples"], "--cycles samples: expected KEY=VALUE"),
    (["--cycles", "sample=3"], "--cycles: unknown key(s) ['sample']"),
    (["--cycles", "denoise_prefilter=BEST"], "--cycles: denoise_prefilter: expected one of NONE, FAST, ACCURATE"),
    (["--geometry-from", "."], "--geometry-from .: not a job folder (no job_state.json)"),
])
def test_render_setting_options_are_checked_before_anything_is_written(tmp_path, capsys, args, says):
    out = tmp_path / "out"
    assert exit_code(synth_main, ["render", str(SMOKE), "--out", str(out), "--quiet", *args]) == 2
    err = capsys.readouterr().err.strip()
    assert says in err and len(err.splitlines()) == 1, err
    assert not out.exists()


@pytest.mark.slow
@pytest.mark.blender
def test_render_settings_from_the_command_line_rerender_only_rgb(tmp_path):
    """synth render --seed/--cycles/--threads --geometry-from: the same design re-rendered with another Cycles
    seed and prefilter on one thread; geometry is the first job's (the same files, hard-linked: nothing of it
    renders), the RGB differs, meta.json and the job state record the settings, and a resume with other
    settings is refused."""
    spec = write_spec(tmp_path, geometry="fast", chunk_size=4, designs=[
        {"layouts": ["apt_0"], "lightings": ["night"], "path": {"name": "query", "frames": 6}, "rgb_every": 3}])
    a, b = tmp_path / "a", tmp_path / "b"
    assert synth_main(["render", str(spec), "--out", str(a), "--quiet"]) == 0
    argv = ["render", str(spec), "--out", str(b), "--quiet", "--seed", "7", "--cycles", "denoise_prefilter=ACCURATE",
            "--threads", "1", "--geometry-from", str(a)]
    assert synth_main(argv) == 0
    geo_a = sorted((a / "_geometry").rglob("*.exr"))
    geo_b = sorted((b / "_geometry").rglob("*.exr"))
    assert [f.relative_to(a) for f in geo_a] == [f.relative_to(b) for f in geo_b] and len(geo_a) == 6
    assert all(os.stat(x).st_ino == os.stat(y).st_ino for x, y in zip(geo_a, geo_b))  # linked, not rendered again
    meta = json.loads((b / "apt_0__night__query" / "meta.json").read_text())
    assert meta["seed"] == 7 and meta["settings"]["cycles"] == {"denoise_prefilter": "ACCURATE"}
    assert meta["settings"]["threads"] == 1 and meta["settings"]["quality_settings"]["denoise_prefilter"] == "ACCURATE"
    assert "cycles" not in json.loads((a / "apt_0__night__query" / "meta.json").read_text())["settings"]
    ta, tb = Tour(a / "apt_0__night__query"), Tour(b / "apt_0__night__query")
    for i in (0, 3):
        fa, fb = ta.frame(i), tb.frame(i)
        np.testing.assert_array_equal(fa.depth, fb.depth)
        assert not np.array_equal(fa.rgb, fb.rgb)  # another seed and prefilter: another image
    state = json.loads((b / "job_state.json").read_text())
    assert state["spec"]["seed"] == 7 and state["spec"]["threads"] == 1
    with pytest.raises(UserError, match="seed: 7 there, 0 in this spec"):
        jobs.run_job(jobs.load_spec(spec), b, resume=True, progress=False)

    # a job folder whose caches are links (to frames elsewhere, or a folder outside it) gives nothing of them
    c, evil = tmp_path / "c", tmp_path / "evil"
    (evil / "_geometry").mkdir(parents=True)
    (evil / "job_state.json").write_text("{}")
    for cache in (a / "_geometry").iterdir():
        (evil / "_geometry" / cache.name).symlink_to(cache, target_is_directory=True)
    with pytest.raises(UserError, match="it has none of this design's geometry caches"):
        jobs.run_job(jobs.load_spec(spec), c, progress=False, geometry_from=evil)
    assert not c.exists()


def test_job_summary_keeps_every_runs_times(tmp_path):
    """A resumed job keeps what its earlier runs cost: job_summary.json's runs, oldest first, and their sum;
    a summary written before runs were kept counts as one run."""
    spec = write_spec(tmp_path, renderer="fast", chunk_size=5,
                      designs=[{"layouts": ["apt_0"], "path": {"name": "query", "frames": 10}}])
    out = tmp_path / "o"
    first = jobs.run_job(jobs.load_spec(spec), out, progress=False)
    assert first["frames_rendered_now"] == 10 and len(first["runs"]) == 1
    (out / "apt_0__geometry__query" / "frames" / "000007.exr").unlink()
    second = jobs.run_job(jobs.load_spec(spec), out, resume=True, progress=False)
    doc = json.loads((out / "job_summary.json").read_text())
    assert doc == second
    assert [r["frames_rendered_now"] for r in doc["runs"]] == [10, 1]
    assert doc["runs"][0] == first["runs"][0] and doc["runs"][1]["wall_time_s"] == doc["wall_time_s"]
    assert doc["wall_time_s_all_runs"] == pytest.approx(sum(r["wall_time_s"] for r in doc["runs"]), abs=0.02)
    assert all(r["cpus"] == os.cpu_count() and r["started"][:2] == "20" for r in doc["runs"])
    legacy = {k: v for k, v in doc.items() if k not in ("runs", "wall_time_s_all_runs")}
    (out / "job_summary.json").write_text(json.dumps(legacy))
    third = jobs.run_job(jobs.load_spec(spec), out, resume=True, progress=False)
    assert [r["frames_rendered_now"] for r in third["runs"]] == [1, 0]


def test_live_eta_prices_each_pass_kind_by_its_own_frames():
    """The time left is frames left x seconds per frame of their own kind, plus the start-up of chunks
    not started, over the slots; a kind not timed yet is named, not guessed."""
    from synth.jobs.estimate import SETUP_S, LiveEta

    eta = LiveEta({"geometry": 100, "rgb": 20}, {"geometry": 2, "rgb": 2}, slots=2)
    assert eta.seconds() is None and eta.untimed == ["geometry", "rgb"]
    eta.chunk_started("geometry")
    for _ in range(10):
        eta.frame("geometry", 0.5)
    # 90 geometry frames at 0.5 s; one geometry and two rgb chunks still to start
    assert eta.seconds() == pytest.approx((90 * 0.5 + SETUP_S["geometry"] + 2 * SETUP_S["rgb"]) / 2)
    assert eta.untimed == ["rgb"]
    eta.chunk_finished("geometry", wall_s=9.0, frame_s=5.0)  # 4 s of start-up, measured
    eta.chunk_started("rgb")
    eta.frame("rgb", 30.0)  # an RGB frame costs 60 geometry frames here: priced as measured
    assert eta.untimed == []
    assert eta.seconds() == pytest.approx((90 * 0.5 + 19 * 30.0 + 4.0 + SETUP_S["rgb"]) / 2)


def test_progress_bar_shows_the_time_left(tmp_path, capsys):
    spec = write_spec(tmp_path, renderer="fast", chunk_size=5,
                      designs=[{"layouts": ["apt_0"], "path": {"name": "query", "frames": 20}}])
    jobs.run_job(jobs.load_spec(spec), tmp_path / "o", progress=True)
    err = capsys.readouterr().err
    assert "ETA " in err and "20/20" in err, err[-500:]
