"""The fault suite: signals, locks and corrupt input, each asserting the exit status, the one-line
message and what is left behind, so that they stay fixed (issue: hardening 2).

How the checks are made, so that others can extend them:

* **Signals** (``vrformats.lifetime``): the command runs as a child process (``python -m reloc.cli``
  or ``python -m synth.cli``) on a small geometry-only design; once it has its workers (pool
  workers, or chunk worker processes), the test sends one signal to the **driver only** (not its
  process group: that is what ``kill PID`` and a closed terminal do) and records every descendant
  from ``/proc``. SIGINT, SIGTERM and SIGHUP must end the driver with ``128 + signal`` and one line
  ``PROG: interrupted (SIGNAL)``; SIGKILL cannot be caught, so there only the workers' own watch
  (parent-death signal, parent-pid poll) is tested. In every case no descendant may be alive 5 s
  later, and a rerun (``--resume`` for a render) must finish with nothing failed.
* **Locks**: a second run into a folder that a run owns is refused (exit 2, one line naming the
  owner's pid), whether or not it passes ``--resume``; a lock file left by a dead run never blocks.
* **Corrupt input and full disks** live beside the code they guard (``test_bad_input_*.py``,
  ``test_faults`` adds the cases of this issue).
"""

from __future__ import annotations

import json
import os
import re
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
import yaml

from vrformats.lifetime import FolderLock, descendants

REPO = Path(__file__).resolve().parents[2]


def _children(pid: int) -> set[int]:
    """Every live descendant of ``pid`` (from /proc)."""
    return descendants(pid)


def _alive(pid: int) -> bool:
    try:
        state = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0]
    except OSError:
        return False
    return state != "Z"


def _cmdline(pid: int) -> str:
    try:
        return Path(f"/proc/{pid}/cmdline").read_bytes().replace(b"\0", b" ").decode()
    except OSError:
        return ""


def _start(argv: list[str], want_workers: int, marker: str, timeout: float = 120.0):
    """Start ``python -m ...`` and wait until it has ``want_workers`` children whose command line holds
    ``marker``; returns (process, descendants)."""
    # SIGINT as a terminal's Ctrl-C delivers it: a shell starts background commands with SIGINT ignored
    # (CI may run the suite so), and Python keeps an ignored SIGINT ignored
    proc = subprocess.Popen([sys.executable, "-m", *argv], cwd=REPO, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            text=True, preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))
    t0 = time.monotonic()
    while time.monotonic() - t0 < timeout:
        kids = _children(proc.pid)
        if sum(marker in _cmdline(k) for k in kids) >= want_workers:
            return proc, kids
        if proc.poll() is not None:
            break
        time.sleep(0.1)
    out, err = proc.communicate(timeout=30) if proc.poll() is None else proc.communicate()
    proc.kill()
    pytest.fail(f"{argv}: no {want_workers} workers ({marker}) appeared; rc {proc.returncode}; {err[-2000:]}")


def _signal_and_check(proc, kids: set[int], sig: int, prog: str) -> str:
    os.kill(proc.pid, sig)
    try:
        _, err = proc.communicate(timeout=20)
    except subprocess.TimeoutExpired:
        proc.kill()
        pytest.fail(f"the driver did not end within 20 s of {signal.Signals(sig).name}")
    deadline = time.monotonic() + 5.0
    while time.monotonic() < deadline and any(_alive(k) for k in kids):
        time.sleep(0.1)
    left = [f"{k}: {_cmdline(k)}" for k in kids if _alive(k)]
    for k in kids:  # never leave them to the next test, whatever the verdict
        try:
            os.kill(k, signal.SIGKILL)
        except OSError:
            pass
    assert not left, f"still running 5 s after {signal.Signals(sig).name} to the driver: {left}"
    if sig == signal.SIGKILL:
        assert proc.returncode == -signal.SIGKILL
    else:
        assert proc.returncode == 128 + sig, (proc.returncode, err[-2000:])
        last = err.strip().splitlines()[-1]
        assert last == f"{prog}: interrupted ({signal.Signals(sig).name})", err[-2000:]
    return err


@pytest.fixture(scope="module")
def fault_design(tmp_path_factory):
    """Two 600-frame geometry-only query tours and a 30-frame mapping tour at 64x48 (fast renderer),
    and an experiment on them with two workers and three methods (a few seconds a task). One chunk a
    tour: the frames are the same in any chunking, and each chunk is a process that loads the layout
    (the render tests below set their own chunk_size)."""
    from synth.jobs import load_spec, run_job

    root = tmp_path_factory.mktemp("faults")
    render = {"name": "faults", "out": str(root / "tours"), "renderer": "fast", "size": [64, 48], "chunk_size": 600,
              "designs": [{"layouts": ["apt_0", "apt_1"], "path": {"name": "query", "frames": 600}},
                          {"layouts": ["apt_0"], "path": {"name": "mapping", "frames": 30}}]}
    (root / "render.yaml").write_text(yaml.safe_dump(render))
    assert run_job(load_spec(root / "render.yaml"), workers=2, progress=False)["failed"] == {}
    exp = {"name": "faults", "render": "render.yaml", "out": str(root / "exp"), "query": "query", "unchanged": "apt_0",
           "mapping": {"layout": "apt_0", "lighting": "geometry", "path": "mapping"}, "map": "ground-truth",
           "methods": ["videoreloc", "fpfh_icp", "one_frame"], "one_frame_stride": 50, "workers": 2, "detector": "oracle"}
    (root / "exp.yaml").write_text(yaml.safe_dump(exp))
    return root


@pytest.mark.slow
@pytest.mark.parametrize("sig", [signal.SIGTERM, signal.SIGINT, signal.SIGHUP, signal.SIGKILL],
                         ids=lambda s: signal.Signals(s).name)
def test_a_signal_to_the_experiment_driver_stops_its_workers(fault_design, tmp_path, sig):
    spec = yaml.safe_load((fault_design / "exp.yaml").read_text())
    spec.update(render=str(fault_design / "render.yaml"), out=str(tmp_path / "exp"))
    (tmp_path / "exp.yaml").write_text(yaml.safe_dump(spec))
    argv = ["reloc.cli", "experiment", str(tmp_path / "exp.yaml"), "--quiet", "--no-plots"]
    proc, kids = _start(argv, 2, "multiprocessing.spawn")
    _signal_and_check(proc, kids, sig, "reloc")
    assert not list((tmp_path / "exp").rglob("*.tmp")) or sig == signal.SIGKILL  # nothing half-written
    finished = len(list((tmp_path / "exp" / "runs").rglob("done.json")))
    done = subprocess.run([sys.executable, "-m", *argv], cwd=REPO, capture_output=True, text=True, timeout=600)
    assert done.returncode == 0, done.stderr[-2000:]
    runs = int(re.search(r"(\d+) runs and \d+ maps computed now", done.stdout).group(1))
    assert runs == 6 - finished  # the rerun does only what the interrupted run left undone
    assert json.loads((tmp_path / "exp" / "results.json").read_text())["failed"] == {}


@pytest.mark.slow
@pytest.mark.parametrize("sig, backend", [(signal.SIGTERM, "local"), (signal.SIGKILL, "local"), (signal.SIGTERM, "ray"),
                                          (signal.SIGKILL, "ray")],
                         ids=lambda v: signal.Signals(v).name if isinstance(v, int) else v)
def test_a_signal_to_the_render_driver_stops_its_chunk_workers(fault_design, tmp_path, sig, backend):
    """The local backend's chunk processes, and the Ray backend's whole local instance (GCS, raylet, its
    workers and their chunk processes: all descendants of the driver), end with the driver; Ray's own
    SIGTERM handler does not replace the orderly stop (vrformats.lifetime.reclaim_signals)."""
    if backend == "ray":
        pytest.importorskip("ray")
    spec = yaml.safe_load((fault_design / "render.yaml").read_text())
    spec.update(out=str(tmp_path / "tours"), chunk_size=100,
                designs=[{"layouts": ["apt_0"], "path": {"name": "query", "frames": 600}}])
    (tmp_path / "render.yaml").write_text(yaml.safe_dump(spec))
    argv = ["synth.cli", "render", str(tmp_path / "render.yaml"), "--workers", "2", "--quiet", "--backend", backend]
    proc, kids = _start(argv, 1 if backend == "ray" else 2, "synth.render.chunk_worker")
    _signal_and_check(proc, kids, sig, "synth")
    assert not [p for p in (tmp_path / "tours").rglob("*.exr") if p.stat().st_size == 0]  # no empty frame visible
    done = subprocess.run([sys.executable, "-m", *argv, "--resume"], cwd=REPO, capture_output=True, text=True, timeout=600)
    assert done.returncode == 0, done.stderr[-2000:]
    assert len(list((tmp_path / "tours" / "apt_0__geometry__query" / "frames").glob("*.exr"))) == 600


def test_a_worker_dies_with_its_parent(tmp_path):
    """kill -9 of a parent: its child that called die_with_parent ends within 2 s."""
    code = ("import subprocess, sys, time\n"
            "c = subprocess.Popen([sys.executable, '-c', 'from vrformats.lifetime import die_with_parent; "
            "die_with_parent(); import time; time.sleep(60)'])\n"
            "print(c.pid, flush=True)\n"
            "time.sleep(60)\n")
    parent = subprocess.Popen([sys.executable, "-c", code], cwd=REPO, stdout=subprocess.PIPE, text=True)
    child = int(parent.stdout.readline())
    time.sleep(0.5)  # the child has set its watch
    assert _alive(child)
    parent.kill()
    parent.wait()
    deadline = time.monotonic() + 2.0
    while time.monotonic() < deadline and _alive(child):
        time.sleep(0.05)
    alive = _alive(child)
    if alive:
        os.kill(child, signal.SIGKILL)
    assert not alive, "the child outlived its parent"


# ---------------------------------------------------------------------------------------------
# one run per folder


@pytest.mark.slow
def test_a_locked_experiment_folder_is_refused(fault_design, tmp_path, capsys):
    from reloc.cli import main as reloc_main

    out = tmp_path / "exp"
    spec = yaml.safe_load((fault_design / "exp.yaml").read_text())
    spec.update(render=str(fault_design / "render.yaml"), out=str(out))
    (tmp_path / "exp.yaml").write_text(yaml.safe_dump(spec))
    with FolderLock(out, "reloc experiment"):
        assert reloc_main(["experiment", str(tmp_path / "exp.yaml"), "--quiet"]) == 2
    err = capsys.readouterr().err.strip()
    assert err == (f"reloc: error: {out}: another reloc experiment is running in this folder (pid {os.getpid()}); "
                   "wait for it to finish or stop it, or use another output folder")
    assert list(out.iterdir()) == []  # nothing written (the test's own lock file went with its lock)


@pytest.mark.slow
def test_a_locked_job_folder_is_refused_with_or_without_resume(tmp_path, capsys):
    from synth.cli import main as synth_main

    spec = {"name": "lk", "out": str(tmp_path / "job"), "renderer": "fast", "size": [32, 24],
            "designs": [{"layouts": ["apt_0"], "path": {"name": "query", "frames": 5}}]}
    (tmp_path / "job.yaml").write_text(yaml.safe_dump(spec))
    lock = FolderLock(tmp_path / "job", "synth render").acquire()
    try:
        for extra in ([], ["--resume"]):
            assert synth_main(["render", str(tmp_path / "job.yaml"), "--quiet", *extra]) == 2
            err = capsys.readouterr().err.strip()
            assert len(err.splitlines()) == 1 and f"(pid {os.getpid()})" in err and "another synth render" in err
        assert sorted(p.name for p in (tmp_path / "job").iterdir()) == [".lock"]  # nothing else written
    finally:
        lock.release()
    (tmp_path / "job" / ".lock").write_text("999999999\n")  # a lock file left by a killed run never blocks
    assert synth_main(["render", str(tmp_path / "job.yaml"), "--quiet"]) == 0
    assert not (tmp_path / "job" / ".lock").exists()  # and a run that ends removes its own
    assert synth_main(["render", str(tmp_path / "job.yaml"), "--quiet", "--resume"]) == 0


def test_a_stale_lock_file_never_blocks(tmp_path):
    (tmp_path / ".lock").write_text("999999999\n")  # left by a run killed long ago
    with FolderLock(tmp_path, "x") as lk:
        assert (tmp_path / ".lock").read_text().strip() == str(os.getpid()) and lk.folder == tmp_path
    assert not (tmp_path / ".lock").exists()  # a run that ends leaves no lock file


def test_a_lock_file_removed_by_its_owner_is_not_shared(tmp_path):
    """After its owner removed the lock file (while another process still had the old one open), the
    next run locks a new file there and a third is refused: two runs never both hold the folder."""
    first = FolderLock(tmp_path, "x").acquire()
    stale_fd = os.open(tmp_path / ".lock", os.O_RDWR)  # a second run has opened it ...
    first.release()  # ... when the owner removes it and drops the lock
    try:
        second = FolderLock(tmp_path, "x").acquire()
        third = FolderLock(tmp_path, "x")
        with pytest.raises(Exception, match="another x is running"):
            third.acquire()
        second.release()
    finally:
        os.close(stale_fd)


# ---------------------------------------------------------------------------------------------
# specs and outputs that cannot hurt


def _render_spec(tmp_path, **changes) -> Path:
    doc = {"name": "x", "out": "o", "renderer": "fast", "size": [32, 24],
           "designs": [{"layouts": ["apt_0"], "path": {"name": "query", "frames": 3}}]}
    doc.update(changes)
    p = tmp_path / "spec.yaml"
    p.write_text(yaml.safe_dump(doc))
    return p


@pytest.mark.parametrize("changes, says", [
    ({"out": "../../etc/x"}, "out: '../../etc/x' leaves the working folder; give an absolute path in the spec, or --out"),
    ({"size": [100000, 100000]}, "size: 100000x100000 is too large: at most 8192 px a side"),
    ({"size": [8192, 4096]}, "is too large"),
    ({"previews": "no"}, "previews: expected true or false, got 'no'"),
    ({"name": ["a", "b"]}, "name: expected a non-empty string, got ['a', 'b']"),
    ({"description": 3}, "description: expected text, got 3"),
])
def test_render_specs_that_could_hurt_are_refused(tmp_path, monkeypatch, capsys, changes, says):
    from synth.cli import main as synth_main

    sub = tmp_path / "a" / "b"
    sub.mkdir(parents=True)
    monkeypatch.chdir(sub)
    spec = _render_spec(sub, **changes)
    assert synth_main(["render", str(spec), "--quiet"]) == 2
    err = capsys.readouterr().err.strip()
    assert says in err and len(err.splitlines()) == 1, err
    assert sorted(p.name for p in tmp_path.rglob("*")) == ["a", "b", "spec.yaml"]  # nothing written


def test_a_relative_out_inside_the_working_folder_and_an_absolute_one_are_fine(tmp_path, monkeypatch):
    from vrformats import fields

    monkeypatch.chdir(tmp_path)
    assert fields.out_folder("s.yaml", "out/demo/../x") == "out/demo/../x"
    assert fields.out_folder("s.yaml", "/abs/elsewhere") == "/abs/elsewhere"
    with pytest.raises(Exception, match="leaves the working folder"):
        fields.out_folder("s.yaml", "out/../../x")


def test_the_typed_field_checks_are_one_line_naming_file_and_field():
    """vrformats.fields is the one home of typed checks: a bool is never a number, a list names the
    bad element by index, a mapping names its unknown and missing keys."""
    from vrformats import fields
    from vrformats.errors import SceneFormatError

    def says(fn, *args, **kw):
        with pytest.raises(SceneFormatError) as e:
            fn("f.yaml", *args, **kw)
        assert "\n" not in str(e.value)
        return str(e.value)

    assert not fields.is_number(True) and not fields.is_number(float("nan")) and fields.is_number(2)
    assert not fields.is_integer(True) and not fields.is_integer(2.0) and fields.is_integer(-3)
    assert says(fields.number, True, "x") == "f.yaml: x: expected a finite number, got True"
    assert says(fields.number, 5, "x", hi=4) == "f.yaml: x: must be <= 4, got 5"
    assert says(fields.integer, 5, "n", hi=4) == "f.yaml: n: expected an integer <= 4, got 5"
    assert says(fields.nonneg_int, -1, "seed") == "f.yaml: seed: expected a non-negative integer, got -1"
    assert fields.whole_number("f.yaml", 640.0, "width") == 640
    assert says(fields.whole_number, 640.5, "width") == "f.yaml: width: expected an integer, got 640.5"
    assert says(fields.required, {}, "fx") == "f.yaml: fx: missing"
    assert fields.vector("f.yaml", [1, 2.5, 0], "p", 3) == (1.0, 2.5, 0.0)
    assert says(fields.vector, [1, "a", 0], "p", 3) == "f.yaml: p[1]: expected a finite number, got 'a'"
    assert says(fields.vector, [1, 2], "p", 3) == "f.yaml: p: expected a list of 3 numbers, got [1, 2]"
    assert fields.listing("f.yaml", None, "rooms", none_is_empty=True) == []
    assert says(fields.mapping, {"a": 1, "z": 2}, "m", allowed={"a", "b"}) == "f.yaml: m: unknown key(s) ['z']; allowed: ['a', 'b']"
    assert says(fields.mapping, {"a": 1}, "m", allowed={"a", "b"}, required={"b"}) == "f.yaml: m: missing key(s) ['b']"
    assert says(fields.mapping, [], "m", what="a mapping") == "f.yaml: m: expected a mapping, got list"


@pytest.mark.slow
def test_an_experiment_spec_out_that_climbs_out_is_refused(tmp_path, capsys):
    from reloc.cli import main as reloc_main
    from tests.jobspecs import write_experiment_spec

    spec = write_experiment_spec(tmp_path, out="../../../etc/exp")
    assert reloc_main(["experiment", str(spec), "--quiet"]) == 2
    err = capsys.readouterr().err.strip()
    assert "out: '../../../etc/exp' leaves the working folder" in err and len(err.splitlines()) == 1


@pytest.mark.slow
def test_an_experiment_into_a_render_folder_is_refused(fault_design, capsys):
    from reloc.cli import main as reloc_main

    tours = fault_design / "tours"
    before = sorted(p.name for p in tours.iterdir())
    assert reloc_main(["experiment", str(fault_design / "exp.yaml"), "--out", str(tours), "--quiet"]) == 2
    err = capsys.readouterr().err.strip()
    assert err.endswith("holds a rendered design (design.json); write the experiment into another folder")
    assert sorted(p.name for p in tours.iterdir()) == before


def test_results_beside_the_tours_are_allowed_and_inside_a_tour_refused(tmp_path):
    """make demo writes its experiment to out/demo/experiment, beside the tours of out/demo: allowed.
    The design's folder itself, a tour folder and anything below a tour are refused."""
    from vrformats.errors import UserError
    from reloc.experiments.runner import check_not_a_render_folder

    demo = tmp_path / "demo"
    tour = demo / "apt_0_day"
    (tour / "frames").mkdir(parents=True)
    (demo / "design.json").write_text("{}")
    (tour / "meta.json").write_text("{}")
    (tour / "poses.txt").write_text("")
    check_not_a_render_folder(demo / "experiment")  # the Makefile's demo recipe
    check_not_a_render_folder(tmp_path / "elsewhere")
    with pytest.raises(UserError, match="holds a rendered design"):
        check_not_a_render_folder(demo)
    for bad in (tour, tour / "frames", tour / "frames" / "exp"):
        with pytest.raises(UserError, match=r"lies inside a rendered tour \(.*apt_0_day\)"):
            check_not_a_render_folder(bad)
    make = (Path(__file__).resolve().parents[2] / "Makefile").read_text()
    assert "--tours $(OUT)/demo --out $(OUT)/demo/experiment" in make  # the layout this test allows


def test_an_unknown_key_in_a_check_spec_is_refused(tmp_path, capsys):
    from reloc.cli import main as reloc_main

    (tmp_path / "results.json").write_text("{}")
    p = tmp_path / "c.yaml"
    p.write_text(yaml.safe_dump({"checks": ["videoreloc.kept >= 0.5"], "chekcs": ["x > 1"]}))
    assert reloc_main(["check", str(p), str(tmp_path)]) == 2
    err = capsys.readouterr().err.strip()
    assert err == f"reloc: error: {p}: chekcs: unknown key; allowed: checks, description"


@pytest.mark.parametrize("kind", ["device", "symlink"])
def test_an_out_file_that_is_not_a_file_is_refused(tmp_path, capsys, kind):
    """--out /dev/null (a device) or a symbolic link: refused before anything is written, and left as it was."""
    from synth.cli import main as synth_main

    if kind == "device":
        out = Path("/dev/null")
    else:
        out = tmp_path / "link.json"
        out.symlink_to(tmp_path / "elsewhere.json")
    assert synth_main(["scene", "export-boxes", "apt_0", "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and ("not a regular file" in err if kind == "device" else "symbolic link" in err)
    if kind == "device":
        assert out.is_char_device()
    else:
        assert out.is_symlink() and not (tmp_path / "elsewhere.json").exists()


def _with_file_size_limit(kb: int):
    def limit():
        import resource

        resource.setrlimit(resource.RLIMIT_FSIZE, (kb * 1024, kb * 1024))
    return limit


def test_a_full_disk_is_one_line(tmp_path):
    """A write past the file size limit (``ulimit -f``: EFBIG, as a full disk gives ENOSPC): one line
    naming the file, exit 2, and no file left behind, half-written or temporary."""
    out = tmp_path / "boxes.json"
    r = subprocess.run([sys.executable, "-m", "synth.cli", "scene", "export-boxes", "apt_0", "--out", str(out)], cwd=REPO,
                       capture_output=True, text=True, preexec_fn=_with_file_size_limit(8), timeout=120)
    assert r.returncode == 2, r.stderr
    assert r.stderr.strip() == (f"synth: error: cannot write {out}: File too large (EFBIG); rerun once it can be written "
                                "(finished work is kept)")
    assert list(tmp_path.iterdir()) == []


@pytest.mark.slow
def test_a_full_disk_during_an_experiment_is_one_line(fault_design, tmp_path):
    spec = yaml.safe_load((fault_design / "exp.yaml").read_text())
    spec.update(render=str(fault_design / "render.yaml"), out=str(tmp_path / "exp"))
    (tmp_path / "exp.yaml").write_text(yaml.safe_dump(spec))
    r = subprocess.run([sys.executable, "-m", "reloc.cli", "experiment", str(tmp_path / "exp.yaml"), "--quiet", "--no-plots"],
                       cwd=REPO, capture_output=True, text=True, preexec_fn=_with_file_size_limit(30), timeout=600)
    assert r.returncode == 2, r.stderr
    assert len(r.stderr.strip().splitlines()) == 1 and "File too large" in r.stderr, r.stderr
    assert not list((tmp_path / "exp").rglob("*.tmp"))


# ---------------------------------------------------------------------------------------------
# degenerate frames and errors on their own line


def _zero_depth(tour: Path, frames) -> None:
    from vrformats import frames as fr

    for i in frames:
        p = tour / "frames" / fr.frame_name(i)
        f = fr.read_frame(p)
        fr.write_frame(p, rgb=f.rgb, depth=np.zeros_like(f.depth), instance=f.instance, semantic=f.semantic)


@pytest.mark.slow
def test_degenerate_frames_are_counted_and_too_many_fail(fault_design, tmp_path, capsys):
    """A frame with all-zero depth inside a tour: reloc run counts it (run.json, a note); more than
    odometry.max_degenerate_fraction of them: one line, exit 2, on its own line after the progress bar."""
    import shutil

    from reloc.cli import main as reloc_main

    tour = tmp_path / "tour"
    shutil.copytree(fault_design / "tours" / "apt_0__geometry__query", tour)
    assert reloc_main(["map", "ground-truth", str(tour), "--out", str(tmp_path / "map.json")]) == 0
    _zero_depth(tour, [120])
    argv = ["run", "--map", str(tmp_path / "map.json"), "--tour", str(tour), "--detector", "oracle", "--frames", "300"]
    capsys.readouterr()
    assert reloc_main([*argv, "--out", str(tmp_path / "one"), "--quiet"]) == 0
    out = capsys.readouterr().out
    assert "note: 1 degenerate frame(s) (1 without usable depth, 0 without RGB): 120" in out
    dg = json.loads((tmp_path / "one" / "run.json").read_text())["degenerate_frames"]
    assert dg == {"no_usable_depth": 1, "no_rgb": 0, "frames": 1, "fraction": round(1 / 300, 4), "first": [120]}
    _zero_depth(tour, range(0, 300, 3))  # a third of the frames (120 among them)
    assert reloc_main([*argv, "--out", str(tmp_path / "many")]) == 2
    err = capsys.readouterr().err
    line = err.splitlines()[-1]
    assert line.startswith(f"reloc: error: {tour}: 100 of 300 frames are degenerate (100 without usable depth, 0 without")
    assert "odometry.max_degenerate_fraction = 0.25" in line
    assert err.endswith(line + "\n") and ("\r" not in line)  # its own line, after the closed progress bar
    assert not (tmp_path / "many" / "run.json").exists()


@pytest.mark.slow
def test_a_truncated_frame_is_one_line_after_the_progress_bar(fault_design, tmp_path, capsys):
    """A frame file cut short in the middle of a tour: reloc run stops with one line naming it, exit 2,
    starting on its own line (the progress bar is closed first), and writes no outputs."""
    import shutil

    from vrformats import frames as fr
    from reloc.cli import main as reloc_main

    tour = tmp_path / "tour"
    shutil.copytree(fault_design / "tours" / "apt_0__geometry__query", tour)
    assert reloc_main(["map", "ground-truth", str(tour), "--out", str(tmp_path / "map.json")]) == 0
    bad = tour / "frames" / fr.frame_name(150)
    bad.write_bytes(bad.read_bytes()[:200])
    capsys.readouterr()
    assert reloc_main(["run", "--map", str(tmp_path / "map.json"), "--tour", str(tour), "--detector", "oracle",
                       "--frames", "300", "--out", str(tmp_path / "run")]) == 2
    err = capsys.readouterr().err
    last = err.rstrip("\n").split("\n")[-1]
    assert last.startswith("reloc: error: ") and str(bad) in last and "\r" not in last, err[-500:]
    assert not (tmp_path / "run" / "run.json").exists()


@pytest.mark.parametrize("changes, field", [({"window_portals": "no"}, "window_portals"), ({"name": ["a"]}, "name"),
                                            ({"description": 5}, "description")])
def test_lighting_presets_are_type_checked(changes, field):
    from vrformats.errors import SceneFormatError
    from synth.scene.lighting import parse_preset, preset_document, load_lighting

    doc = {**preset_document(load_lighting("day")), **changes}
    with pytest.raises(SceneFormatError, match=f"day.yaml: {field}: expected"):
        parse_preset(doc, "day.yaml")


@pytest.mark.parametrize("changes, says", [({"size": [20000, 20000]}, "size: 20000x20000 is too large"),
                                           ({"name": ["a"]}, "name: expected a non-empty string"),
                                           ({"out": "../../x"}, "out: '../../x' leaves the working folder"),
                                           ({"quality": 3}, "quality: expected text")])
def test_trainset_specs_are_type_checked(changes, says):
    from vrformats.errors import SceneFormatError
    from synth.trainset.trainset import parse_trainset

    doc = {"name": "t", "out": "o", "seeds": [103], **changes}
    with pytest.raises(SceneFormatError, match=re.escape(says)):
        parse_trainset(doc, "t.yaml")
