"""Planning at scale: the cluster estimate of ``synth render SPEC --dry-run --nodes N --cpus-per-node C``
against schedules worked out by hand, the calibration file, and bad input (one line, exit 2)."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from jobspecs import write_spec

from synth.jobs import estimate as ce
from synth import jobs
from synth.cli import main as synth_main

NO_SETUP: dict = {}


def cal(spf, cpu_count=4, devices=None, bytes_per_frame=None, quality="preview", size=(64, 48)) -> dict:
    doc = {"format": "synth-calibration", "version": 1, "seconds_per_frame": dict(spf), "cpu_count": cpu_count,
           "device": next((d for d in (devices or {}).values() if d != "CPU"), "CPU"), "devices": dict(devices or {}),
           "spec": {"quality": quality, "width": size[0], "height": size[1]}, "date": "2026-01-01T00:00:00+00:00",
           "toolkit_version": "0.1.0"}
    if bytes_per_frame is not None:
        doc["bytes_per_frame"] = dict(bytes_per_frame)
    return ce.validate_calibration(doc, "<test>")


def fast_chunks(frames) -> list[ce.Work]:
    return [ce.Work(f"fast/t/{k:04d}", "fast", n) for k, n in enumerate(frames)]


# ---------------------------------------------------------------------------------------------
# the schedule against hand-computed makespans


FRAMES = [10, 8, 6, 5, 4, 3]  # 1 s/frame on a 4-core node from a 4-core calibration: a chunk takes its frame count


@pytest.mark.parametrize("nodes, makespan, lower", [
    (1, 36.0, 36.0),  # one node: the total work
    # longest first on 2: A 10, B 8; B@8 takes 6 (->14); A@10 takes 5 (->15); B@14 takes 4 (->18); A@15 takes 3 (->18)
    (2, 18.0, 18.0),
    # on 3: A 10, B 8, C 6; C@6 takes 5 (->11); B@8 takes 4 (->12); A@10 takes 3 (->13)
    (3, 13.0, 12.0),
    (6, 10.0, 10.0),  # as many nodes as chunks: the longest chunk
    (50, 10.0, 10.0),  # more nodes than chunks: still the longest chunk
])
def test_independent_chunks_longest_first(nodes, makespan, lower):
    r = ce.estimate_cluster(fast_chunks(FRAMES), cal({"fast": 1.0}), ce.Cluster(nodes, 4), setup=NO_SETUP)
    assert r["makespan_s"] == pytest.approx(makespan)
    assert r["lower_bound_s"] == pytest.approx(lower)
    assert r["work_s"] == pytest.approx(36.0)
    assert r["node_hours"] == pytest.approx(nodes * makespan / 3600)
    assert r["mean_utilisation"] == pytest.approx(36.0 / (nodes * makespan))


def test_busiest_node_utilisation_and_setup():
    r = ce.estimate_cluster(fast_chunks(FRAMES), cal({"fast": 1.0}), ce.Cluster(3, 4), setup=NO_SETUP)
    assert r["busiest_node_utilisation"] == pytest.approx(13.0 / 13.0)  # node A: 10 + 3
    # more nodes than chunks: the longest chunk plus its start-up
    r = ce.estimate_cluster(fast_chunks(FRAMES), cal({"fast": 1.0}), ce.Cluster(50, 4), setup={"fast": 1.5})
    assert r["makespan_s"] == pytest.approx(11.5) and r["lower_bound"]["longest_chunk_s"] == pytest.approx(11.5)
    assert r["busiest_node_utilisation"] == pytest.approx(1.0)
    assert r["mean_utilisation"] == pytest.approx((36 + 6 * 1.5) / (50 * 11.5))
    # the default start-up constants are those of the local estimate
    r = ce.estimate_cluster(fast_chunks([10]), cal({"fast": 1.0}), ce.Cluster(1, 4))
    assert r["makespan_s"] == pytest.approx(10.0 + ce.SETUP_S["fast"])


def test_measured_startup_replaces_the_constant():
    """A calibration's measured start-up (startup_s) is what each chunk pays; the assumptions say so."""
    c = cal({"fast": 1.0})
    c["startup_s"] = {"fast": 7.5}
    r = ce.estimate_cluster(fast_chunks([10]), c, ce.Cluster(1, 4))
    assert r["makespan_s"] == pytest.approx(10.0 + 7.5)
    assert ce.setup_seconds(c) == {**ce.SETUP_S, "fast": 7.5}
    text = ce.describe_estimate([r], c, "from <test>")
    assert "fast 7.5 s (measured by the calibration)" in text and "geometry 3 s," in text


def test_plan_order_is_what_the_driver_does():
    """In the plan's order (shortest first here) on 2 nodes: A 3, B 4; A@3 takes 5 (->8); B@4 takes 6
    (->10); A@8 takes 8 (->16); B@10 takes 10 (->20)."""
    work = fast_chunks([3, 4, 5, 6, 8, 10])
    c = cal({"fast": 1.0})
    assert ce.estimate_cluster(work, c, ce.Cluster(2, 4), order="plan", setup=NO_SETUP)["makespan_s"] == pytest.approx(20.0)
    assert ce.estimate_cluster(work, c, ce.Cluster(2, 4), order="longest", setup=NO_SETUP)["makespan_s"] == pytest.approx(18.0)


def test_rgb_chunks_wait_for_their_geometry_chunk():
    """g1 4 s; r1, r2 (2 s each) need g1. Two nodes: the second waits for g1, then both run r1, r2."""
    work = [ce.Work("geometry/a/0", "geometry", 4), ce.Work("rgb/a/0", "rgb", 1, "geometry/a/0"),
            ce.Work("rgb/b/0", "rgb", 1, "geometry/a/0")]
    c = cal({"geometry": 1.0, "rgb": 2.0})
    sched_r = ce.estimate_cluster(work, c, ce.Cluster(2, 4), setup=NO_SETUP)
    assert sched_r["makespan_s"] == pytest.approx(6.0)
    assert sched_r["lower_bound"] == pytest.approx({"work_per_slot_s": 4.0, "longest_chunk_s": 4.0, "longest_chain_s": 6.0})
    assert sched_r["busiest_node_utilisation"] == pytest.approx(1.0)
    assert sched_r["mean_utilisation"] == pytest.approx(8.0 / 12.0)
    # without the dependency the two rgb chunks would have started at once on the second node
    free = [ce.Work(w.id, w.kind, w.frames) for w in work]
    assert ce.estimate_cluster(free, c, ce.Cluster(2, 4), setup=NO_SETUP)["makespan_s"] == pytest.approx(4.0)
    # a geometry chunk that is already done (not in the work) holds nothing up
    assert ce.estimate_cluster(work[1:], c, ce.Cluster(2, 4), setup=NO_SETUP)["makespan_s"] == pytest.approx(2.0)


def test_longest_path_first_starts_the_geometry_that_unlocks_most_work():
    """g1 2 s -> r1a, r1b (6 s each); g2 1 s -> r2 (6 s); 2 nodes. By hand: g1 0-2, g2 0-1; r2 1-7 (the
    only chunk ready at 1); r1a 2-8; r1b 7-13. Three 6 s chunks on two nodes: 13 is the optimum."""
    work = [ce.Work("geometry/1", "geometry", 2), ce.Work("rgb/1a", "rgb", 3, "geometry/1"),
            ce.Work("rgb/1b", "rgb", 3, "geometry/1"), ce.Work("geometry/2", "geometry", 1),
            ce.Work("rgb/2", "rgb", 3, "geometry/2")]
    c = cal({"geometry": 1.0, "rgb": 2.0})
    durations = {w.id: ce.chunk_seconds(w, c, ce.Cluster(2, 4), NO_SETUP) for w in work}
    assert ce.priority_order(work, durations, "longest")[:2] == ["geometry/1", "geometry/2"]
    sched = ce.list_schedule(durations, {w.id: w.needs for w in work}, 2, ce.priority_order(work, durations, "longest"))
    assert {k: v[:2] for k, v in sched.items()} == {"geometry/1": (0, 2), "geometry/2": (0, 1), "rgb/2": (1, 7),
                                                    "rgb/1a": (2, 8), "rgb/1b": (7, 13)}
    for order in ("longest", "plan"):
        assert ce.estimate_cluster(work, c, ce.Cluster(2, 4), order=order, setup=NO_SETUP)["makespan_s"] == pytest.approx(13.0)


# ---------------------------------------------------------------------------------------------
# scaling with cores, chunks per node and GPUs


def test_frame_time_scales_with_the_cores_a_chunk_gets():
    w = ce.Work("rgb/t/0", "rgb", 10)
    c = cal({"rgb": 10.0}, cpu_count=2)
    setup = {"rgb": 4.0}
    # 10 s/frame with 2 cores -> 1.25 s/frame with 16: 12.5 s + 4 s start-up
    assert ce.chunk_seconds(w, c, ce.Cluster(1, 16), setup) == pytest.approx(16.5)
    assert ce.chunk_seconds(w, c, ce.Cluster(1, 32), setup) == pytest.approx(10.25)
    assert ce.chunk_seconds(w, c, ce.Cluster(1, 2), setup) == pytest.approx(104.0)  # the calibration machine itself
    # two chunks at a time on 16 cores: 8 cores each, twice the frame time, but twice the slots
    assert ce.chunk_seconds(w, c, ce.Cluster(1, 16, chunks_per_node=2), setup) == pytest.approx(29.0)
    work = [ce.Work(f"rgb/t/{k}", "rgb", 10) for k in range(4)]
    one = ce.estimate_cluster(work, c, ce.Cluster(1, 16), setup=setup)
    two = ce.estimate_cluster(work, c, ce.Cluster(1, 16, chunks_per_node=2), setup=setup)
    assert one["makespan_s"] == pytest.approx(4 * 16.5) and two["makespan_s"] == pytest.approx(2 * 29.0)
    assert two["slots"] == 2 and two["busiest_node_utilisation"] == pytest.approx(1.0)
    doubled = ce.estimate_cluster(work, c, ce.Cluster(1, 32), setup=NO_SETUP)["makespan_s"]
    assert doubled == pytest.approx(ce.estimate_cluster(work, c, ce.Cluster(1, 16), setup=NO_SETUP)["makespan_s"] / 2)


def test_core_seconds_come_from_the_cpu_time_when_recorded():
    """A calibration on a busy machine: 10 s of wall time per frame on 2 CPUs, but the process got only
    6 CPU seconds (another job had the rest): 6 core-seconds, 0.375 s/frame on 16 cores (not 1.25)."""
    c = cal({"rgb": 10.0}, cpu_count=2)
    assert ce.core_seconds("rgb", c) == (20.0, "wall")
    c["cpu_seconds_per_frame"] = {"rgb": 6.0}
    c = ce.validate_calibration(c, "<test>")
    assert ce.core_seconds("rgb", c) == (6.0, "cpu")
    assert ce.chunk_seconds(ce.Work("rgb/0", "rgb", 10), c, ce.Cluster(1, 16), NO_SETUP) == pytest.approx(3.75)
    text = ce.describe_estimate([ce.estimate_cluster([ce.Work("rgb/0", "rgb", 10)], c, ce.Cluster(1, 16))], c, "here")
    assert "6.000 core-seconds/frame (the CPU time of the calibration process" in text and "is 30% of its cores" in text


def test_gpu_kinds_take_the_calibrations_time_per_gpu():
    c = cal({"fast": 0.5, "rgb": 0.2}, cpu_count=8, devices={"fast": "CPU", "rgb": "OPTIX"})
    assert ce.has_gpu_kinds(c) and not ce.has_gpu_kinds(cal({"rgb": 1.0}))
    cl = ce.Cluster(2, 16, gpus_per_node=4)
    assert cl.slots == 8
    assert ce.chunk_seconds(ce.Work("rgb/0", "rgb", 100), c, cl, NO_SETUP) == pytest.approx(20.0)  # as measured
    # the fast renderer on the CPU: 16 cores / 4 chunks at a time = 4 cores each, from an 8-core calibration
    assert ce.chunk_seconds(ce.Work("fast/0", "fast", 100), c, cl, NO_SETUP) == pytest.approx(100.0)
    work = [ce.Work(f"rgb/{k}", "rgb", 100) for k in range(10)]
    r = ce.estimate_cluster(work, c, cl, setup=NO_SETUP)
    assert r["makespan_s"] == pytest.approx(40.0)  # 10 chunks of 20 s on 8 GPUs: two rounds


def test_the_driver_link():
    work = [ce.Work("geometry/0", "geometry", 10), ce.Work("rgb/0", "rgb", 10, "geometry/0")]
    c = cal({"geometry": 1.0, "rgb": 1.0}, bytes_per_frame={"geometry": 1e6, "rgb": 2e6})
    r = ce.estimate_cluster(work, c, ce.Cluster(1, 4), setup=NO_SETUP, link_gbps=1.0)
    assert r["bytes_home"] == pytest.approx(3e7) and r["bytes_out"] == pytest.approx(1e7)
    assert r["link_s"] == pytest.approx(0.32) and r["wall_s"] == pytest.approx(20.0)
    slow = ce.estimate_cluster(work, c, ce.Cluster(1, 4), setup=NO_SETUP, link_gbps=0.001)
    assert slow["wall_s"] == pytest.approx(320.0)  # the link, not the nodes, bounds the wall time


def test_plan_work_of_a_real_plan(tmp_path):
    spec = write_spec(tmp_path, geometry="fast", chunk_size=4, designs=[
        {"layouts": ["apt_0"], "lightings": ["day"], "path": {"name": "query", "frames": 10}, "rgb_every": 3}])
    plan = jobs.expand(jobs.load_spec(spec), out=tmp_path / "o")
    work = ce.plan_work(plan)
    assert [(w.kind, w.frames) for w in work if w.kind == "fast"] == [("fast", 4), ("fast", 4), ("fast", 2)]
    assert sum(w.frames for w in work if w.kind == "rgb") == 4  # frames 0, 3, 6, 9
    assert all(w.needs for w in work if w.kind in ("rgb", "copy"))
    r = ce.estimate_cluster(work, cal({"fast": 1.0, "rgb": 1.0}), ce.Cluster(1, 4), setup=NO_SETUP)
    assert r["copy_frames"] == 6 and r["frames"] == 14 and r["makespan_s"] == pytest.approx(14.0)  # copy: on the driver


def paper_design_work() -> list[ce.Work]:
    """The chunks of render_jobs/replicacad_6x3.yaml as ``expand`` makes them (test_jobs checks the plan
    itself; expanding it takes seconds): geometry once per layout + path, rgb per tour, 100 frames each."""
    work = []
    for layout, path, lightings, n in [(f"apt_{k}", "query", ("day", "evening", "night"), 40) for k in range(6)] + [
            ("apt_0", "mapping", ("day",), 60)]:
        geo = [ce.Work(f"geometry/{layout}__{path}/{k:04d}", "geometry", 100) for k in range(n)]
        work += geo
        for lighting in lightings:
            work += [ce.Work(f"rgb/{layout}__{lighting}__{path}/{k:04d}", "rgb", 100, g.id) for k, g in enumerate(geo)]
    return work


def test_the_paper_design_is_scheduled():
    """300 geometry + 780 rgb chunks of 100 frames: on one node the makespan is the total work; on 32
    within Graham's bound for list schedules (work / slots + the longest chain)."""
    work = paper_design_work()
    assert len(work) == 1080 and sum(w.frames for w in work if w.kind == "rgb") == 78000
    c = cal({"geometry": 2.0, "rgb": 60.0}, cpu_count=2, quality="paper", size=(640, 480))
    one = ce.estimate_cluster(work, c, ce.Cluster(1, 16))
    assert one["makespan_s"] == pytest.approx(one["work_s"])
    assert one["work_s"] == pytest.approx(300 * 3 + 780 * 4 + 30000 * 0.25 + 78000 * 7.5)
    many = ce.estimate_cluster(work, c, ce.Cluster(32, 16))
    lb = many["lower_bound"]
    assert many["lower_bound_s"] <= many["makespan_s"] <= lb["work_per_slot_s"] + lb["longest_chain_s"]
    assert many["makespan_s"] <= 1.05 * many["lower_bound_s"]


# ---------------------------------------------------------------------------------------------
# the command line




def fast_spec(tmp_path, frames=30) -> Path:
    return write_spec(tmp_path, renderer="fast", chunk_size=10, designs=[{"layouts": ["apt_0"], "path": {"name": "query", "frames": frames}}])


def cal_file(tmp_path, doc=None, name="cal.json") -> Path:
    p = tmp_path / name
    p.write_text(json.dumps(doc if doc is not None else cal({"fast": 0.5}, cpu_count=2)))
    return p


def run_cli(argv, capsys):
    rc = synth_main(argv)
    out, err = capsys.readouterr()
    return rc, out, err.strip()


def test_cli_prints_the_estimate_and_every_assumption(tmp_path, capsys):
    out_dir = tmp_path / "o"
    rc, out, err = run_cli(["render", str(fast_spec(tmp_path)), "--out", str(out_dir), "--dry-run",
                            "--calibration", str(cal_file(tmp_path)), "--nodes", "1,2,8", "--cpus-per-node", "4"], capsys)
    assert rc == 0, err
    assert "CPU nodes of 4 cores, 1 chunk(s) at a time per node (ray start --num-cpus=1)" in out
    for what in ("assumptions:", "calibration (from", "2 CPUs",
                 "fast: 0.500 s/frame x 2 CPUs = 1.000 core-seconds/frame (no CPU time recorded) / 4 cores = 0.250 s/frame",
                 "scales linearly with cores", "start-up per chunk", "list scheduling, longest path first",
                 "driver order", "frames still missing", "not modelled", "lower bound"):
        assert what in out, what
    rows = [line.split() for line in out.splitlines() if line.strip()[:2] in ("1 ", "2 ", "8 ")]
    assert [r[0] for r in rows] == ["1", "2", "8"]
    # 3 chunks of 10 frames: 10 x 0.25 s + 1 s start-up = 3.5 s each; 1 node: 10.5 s; 2: 7 s; 8: 3.5 s
    assert [r[2] for r in rows] == ["10", "7", "4"]  # printed to the second (3.5 -> "4")
    assert "estimate with 1 worker(s)" in out  # this machine's estimate from the file's figures (issue 42)
    assert not out_dir.exists()


def test_cli_save_then_use_a_calibration(tmp_path, capsys):
    spec = fast_spec(tmp_path, frames=12)
    saved = tmp_path / "cal" / "here.json"
    rc, out, err = run_cli(["render", str(spec), "--out", str(tmp_path / "o"), "--dry-run", "--save-calibration", str(saved)],
                           capsys)
    assert rc == 0, err
    assert "estimate with 1 worker(s)" in out and f"calibration saved to {saved}" in out
    doc = ce.load_calibration(saved)
    import os

    assert doc["cpu_count"] == os.cpu_count() and doc["device"] == "CPU" and doc["devices"] == {"fast": "CPU"}
    assert doc["spec"]["quality"] == "preview" and (doc["spec"]["width"], doc["spec"]["height"]) == (64, 48)
    assert doc["seconds_per_frame"]["fast"] > 0 and doc["bytes_per_frame"]["fast"] > 0
    assert doc["cpu_seconds_per_frame"]["fast"] > 0  # the worker's CPU time over its threads
    assert doc["startup_s"]["fast"] >= 0  # its chunk's wall time less its frames at the steady rate
    assert doc["date"] and doc["toolkit_version"].startswith("0.")
    rc, out2, err = run_cli(["render", str(spec), "--out", str(tmp_path / "o"), "--dry-run", "--calibration", str(saved),
                             "--nodes", "2", "--cpus-per-node", "16"], capsys)
    assert rc == 0, err
    assert f"{doc['seconds_per_frame']['fast']:.3f}" in out2 and "cluster estimate" in out2
    assert not (tmp_path / "o").exists()


def _bad(doc_edit):
    doc = cal({"fast": 0.5}, cpu_count=2)
    doc_edit(doc)
    return doc


@pytest.mark.parametrize("argv, message", [
    (["--nodes", "0", "--cpus-per-node", "16"], "--nodes: expected positive integers"),
    (["--nodes", "1,0", "--cpus-per-node", "16"], "--nodes: expected positive integers"),
    (["--nodes", "eight", "--cpus-per-node", "16"], "--nodes: expected positive integers"),
    (["--nodes", "8", "--cpus-per-node", "-4"], "--cpus-per-node: expected a positive integer, got '-4'"),
    (["--nodes", "8", "--cpus-per-node", "0"], "--cpus-per-node: expected a positive integer"),
    (["--nodes", "8"], "--nodes: needs --cpus-per-node"),
    (["--cpus-per-node", "16"], "--cpus-per-node: needs --nodes"),
    (["--nodes", "8", "--cpus-per-node", "16", "--gpus-per-node", "-1"], "--gpus-per-node: expected a non-negative integer"),
    (["--nodes", "8", "--cpus-per-node", "16", "--gpus-per-node", "1"], "--gpus-per-node: no GPU calibration exists"),
    (["--nodes", "8", "--cpus-per-node", "4", "--chunks-per-node", "8"], "--chunks-per-node: 8 chunks at a time on 4 cores"),
    (["--nodes", "8", "--cpus-per-node", "4", "--link-gbps", "-1"], "--link-gbps: expected a positive number"),
])
def test_bad_cluster_options_one_line_exit_2(tmp_path, capsys, argv, message):
    out_dir = tmp_path / "o"
    rc, out, err = run_cli(["render", str(fast_spec(tmp_path)), "--out", str(out_dir), "--dry-run", *argv], capsys)
    assert rc == 2 and err.startswith("synth: error:") and message in err and len(err.splitlines()) == 1, err
    assert out == "" and not out_dir.exists()  # refused before planning or rendering anything


def test_cluster_options_need_a_dry_run(tmp_path, capsys):
    out_dir = tmp_path / "o"
    rc, _, err = run_cli(["render", str(fast_spec(tmp_path)), "--out", str(out_dir), "--nodes", "8", "--cpus-per-node", "16"], capsys)
    assert rc == 2 and "--nodes: only with --dry-run" in err and len(err.splitlines()) == 1
    assert not out_dir.exists()


@pytest.mark.parametrize("edit, field", [
    (lambda d: d.pop("seconds_per_frame"), "seconds_per_frame"),
    (lambda d: d["seconds_per_frame"].update(fast=-1), "seconds_per_frame.fast"),
    (lambda d: d["seconds_per_frame"].update(fast="quick"), "seconds_per_frame.fast"),
    (lambda d: d["seconds_per_frame"].update(warp=1.0), "seconds_per_frame.warp"),
    (lambda d: d.update(cpu_count=0), "cpu_count"),
    (lambda d: d.update(cpu_seconds_per_frame={"fast": 0}), "cpu_seconds_per_frame.fast"),
    (lambda d: d.update(cpu_seconds_per_frame={"rgb": 1.0}), "cpu_seconds_per_frame.rgb"),
    (lambda d: d.pop("device"), "device"),
    (lambda d: d.update(format="other"), "format"),
    (lambda d: d.pop("date"), "date"),
    (lambda d: d["spec"].pop("width"), "spec.width"),
    (lambda d: d["spec"].update(quality="paper"), "spec.quality"),  # valid, but not the spec's quality
    (lambda d: d.update(seconds_per_frame={"rgb": 1.0}), "seconds_per_frame.fast"),  # the plan's kind is missing
    (lambda d: d.update(startup_s={"fast": -1}), "startup_s.fast"),
    (lambda d: d.update(startup_s={"rgb": 1.0}), "startup_s.rgb"),
    (lambda d: d.update(startup_s=[1.0]), "startup_s"),
])
def test_malformed_calibration_names_file_and_field(tmp_path, capsys, edit, field):
    f = cal_file(tmp_path, _bad(edit))
    rc, out, err = run_cli(["render", str(fast_spec(tmp_path)), "--out", str(tmp_path / "o"), "--dry-run",
                            "--calibration", str(f), "--nodes", "2", "--cpus-per-node", "16"], capsys)
    assert rc == 2 and f"{f}: {field}:" in err and len(err.splitlines()) == 1, err
    assert "cluster estimate" not in out and not (tmp_path / "o").exists()


@pytest.mark.parametrize("text, message", [("{not json", "not a JSON calibration file"), ("[1, 2]", "expected a JSON object")])
def test_calibration_that_is_not_a_calibration(tmp_path, capsys, text, message):
    f = tmp_path / "cal.json"
    f.write_text(text)
    rc, _, err = run_cli(["render", str(fast_spec(tmp_path)), "--dry-run", "--calibration", str(f)], capsys)
    assert rc == 2 and err.startswith(f"synth: error: {f}: {message}") and len(err.splitlines()) == 1, err
    rc, _, err = run_cli(["render", str(fast_spec(tmp_path)), "--dry-run", "--calibration", str(tmp_path / "none.json")], capsys)
    assert rc == 2 and "--calibration" in err and "no such file" in err


def test_gpu_estimate_needs_a_gpu_calibration(tmp_path, capsys):
    cpu = cal_file(tmp_path, cal({"fast": 0.5}, cpu_count=2), "cpu.json")
    rc, out, err = run_cli(["render", str(fast_spec(tmp_path)), "--dry-run", "--calibration", str(cpu),
                            "--nodes", "4", "--cpus-per-node", "16", "--gpus-per-node", "2"], capsys)
    assert rc == 2 and f"{cpu}: device:" in err and "no GPU calibration" in err and len(err.splitlines()) == 1, err
    assert out == ""
    spec = write_spec(tmp_path, chunk_size=3)  # the smoke spec: geometry + rgb, 64x48 preview
    gpu = cal_file(tmp_path, cal({"geometry": 0.01, "rgb": 0.02}, cpu_count=8, devices={"geometry": "OPTIX", "rgb": "OPTIX"}),
                   "gpu.json")
    rc, out, err = run_cli(["render", str(spec), "--out", str(tmp_path / "o"), "--dry-run", "--calibration", str(gpu),
                            "--nodes", "1,2", "--cpus-per-node", "16", "--gpus-per-node", "2"], capsys)
    assert rc == 0, err
    assert "GPU nodes of 2 GPU(s)" in out and "on each GPU, as on the calibration's GPU (no CPU-to-GPU factor)" in out
    assert "the spec says device: cpu" in out  # the smoke spec: its chunks would not ask for GPUs


def test_save_calibration_where_it_cannot_be_written(tmp_path, capsys):
    blocker = tmp_path / "file"
    blocker.write_text("x")
    rc, out, err = run_cli(["render", str(fast_spec(tmp_path)), "--dry-run", "--save-calibration", str(blocker / "cal.json")],
                           capsys)
    assert rc == 2 and "cannot write to output file" in err and len(err.splitlines()) == 1
    assert "calibration" not in out  # refused before rendering
    rc, _, err = run_cli(["render", str(fast_spec(tmp_path)), "--dry-run", "--calibration", str(cal_file(tmp_path)),
                          "--save-calibration", str(tmp_path / "x.json")], capsys)
    assert rc == 2 and "--save-calibration: nothing is measured" in err
