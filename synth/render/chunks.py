"""The chunk protocol: how a render pass is cut into chunks and run, one worker process each.

Both sides live here. The parent (``synth tour render`` and the job runner, local or Ray) writes a
chunk's job as JSON and starts a worker: ``python -m synth.blender.worker JOB.json`` for the Blender
passes (``geometry``, ``rgb``), ``python -m synth.render.chunk_worker JOB.json`` for the rest (``fast``,
``copy``). The worker skips frames already on disk and reports on stdout, one JSON object a line:
``start``, ``ready`` (device), ``frame`` (index, seconds, cpu: the worker's CPU seconds over all its
threads), ``error``; everything else it prints
goes to the chunk's log.
"""

from __future__ import annotations

import json
import subprocess
import sys
import threading
from contextlib import contextmanager
from pathlib import Path

from vrformats import frames as fr
from vrformats.atomic import nofollow_opener, write_nofollow
from vrformats.lifetime import die_with_parent, stop_processes, worker_env



BLENDER_PASSES = ("geometry", "rgb")
PLAIN_PASSES = ("fast", "copy")


def missing_frames(frames_dir: Path, frame_ids) -> list[int]:
    return [i for i in frame_ids if not (Path(frames_dir) / fr.frame_name(i)).exists()]


def split(ids: list[int], size: int) -> list[list[int]]:
    return [ids[k : k + size] for k in range(0, len(ids), size)]


def chunk_job(p, kind: str, frames: list[int], out_dir: Path | None = None) -> dict:
    """The job of one chunk of pass ``kind`` of the prepared tour ``p`` (``synth.tour.render.Prepared``).

    ``out_dir`` defaults to the tour's frames (the geometry cache for ``geometry``). Paths are
    absolute, so a worker can run anywhere the files are."""
    if kind not in BLENDER_PASSES + PLAIN_PASSES:
        raise ValueError(f"unknown pass {kind!r}")
    if out_dir is None:
        out_dir = p.geometry_dir if kind == "geometry" else p.out / "frames"
    job = {"pass": kind, "layout": str(p.layout_file.resolve()), "poses": str((p.out / "poses.txt").resolve()),
           "fps": p.path_fps, "frames": list(frames), "intrinsics": p.intr.to_dict(), "out_dir": str(Path(out_dir).resolve()),
           "geometry_dir": str(p.geometry_dir.resolve()) if p.geometry_dir else None}
    if kind in BLENDER_PASSES:
        s = p.spec
        job.update({"lighting": s.lighting, "quality": s.quality, "cycles": s.cycles, "seed": s.seed, "device": s.device,
                    "threads": s.threads,
                    "previews_dir": str((p.out / "previews").resolve()) if s.previews else None})
    return job


def run_chunk_process(chunk_kind: str, job: dict, job_file: str, log_file: str, on_frame=None,
                      env: dict | None = None, worker: str | None = None) -> tuple[int, str | None, dict]:
    """Run one chunk in a fresh process; returns (exit status, error, info). Used by every runner.

    ``env``: the worker's environment (default: this process's); the Ray backend points
    ``SYNTH_SCENES_DIR`` at the scene files it shipped with the chunk. ``worker``: the worker module
    in place of the chunk kind's (the quality benchmark's, ``synth.blender.quality_worker``)."""
    write_nofollow(job_file, json.dumps(job))
    worker = worker or ("synth.blender.worker" if chunk_kind in BLENDER_PASSES else "synth.render.chunk_worker")
    info: dict = {}
    err = None
    with open(log_file, "w", opener=nofollow_opener) as log:
        with _LIVE_LOCK:  # no new worker once the driver is stopping (stopping_workers)
            if _STOPPING.is_set():
                return 130, "stopped: the run was interrupted", info
            proc = subprocess.Popen([sys.executable, "-m", worker, job_file], stdout=subprocess.PIPE, stderr=log, text=True,
                                    bufsize=1, env=worker_env(env))
            _LIVE.add(proc)
        try:
            rc, err = _follow(proc, log, on_frame, info)
        finally:
            with _LIVE_LOCK:
                _LIVE.discard(proc)
    if rc != 0 and err is None:
        err = f"exit status {rc}" + (" (killed)" if rc < 0 else "")
    return rc, err, info


# the chunk workers this process has running, so that a stopping driver can end them (stopping_workers)
_LIVE: set = set()
_LIVE_LOCK = threading.Lock()
_STOPPING = threading.Event()


@contextmanager
def stopping_workers(pool=None):
    """``with ThreadPoolExecutor(...) as pool, stopping_workers(pool):`` around a driver's chunk loop:
    if it ends by an exception (Ctrl-C, SIGTERM, SIGHUP: ``vrformats.lifetime``), the chunks not yet
    started are cancelled, no new worker starts, and every running chunk worker is stopped (SIGTERM,
    SIGKILL after 3 s) before the exception goes on. Frames are written atomically, so a chunk cut
    short leaves only whole frames, and ``--resume`` renders the rest."""
    try:
        yield
    except BaseException:
        with _LIVE_LOCK:
            _STOPPING.set()
            procs = list(_LIVE)
        try:
            if pool is not None:
                pool.shutdown(wait=False, cancel_futures=True)
            stop_processes(procs)
            if pool is not None:
                pool.shutdown(wait=True)  # the threads return once their workers are gone
        finally:
            _STOPPING.clear()
        raise


def _follow(proc, log, on_frame, info: dict) -> tuple[int, str | None]:
    """Read a chunk worker's events until it exits: (exit status, its error event or None)."""
    err = None
    try:
        for line in proc.stdout:
            if not line.startswith("{"):
                log.write(line)
                continue
            try:
                ev = json.loads(line)
            except json.JSONDecodeError:
                continue
            e = ev.get("event")
            if e == "frame" and on_frame:
                on_frame(ev)
            elif e == "start":
                info["blender"] = ev.get("blender")
            elif e == "ready":
                info["device"] = ev.get("device")
                info["setup"] = ev.get("setup")  # the worker's start-up by stage
            elif e == "error":
                err = ev.get("error")
    finally:
        rc = proc.wait()
    return rc, err


# -- the worker's side ----------------------------------------------------------------------------


def emit(**event) -> None:
    """One progress event to the parent."""
    print(json.dumps(event), flush=True)


def worker_main(module: str, run, argv=None) -> int:
    """``python -m MODULE JOB.json``: run the chunk; an exception is reported as an ``error`` event, then raised."""
    argv = sys.argv[1:] if argv is None else argv
    die_with_parent()  # a chunk worker never outlives the driver that reads its events
    if len(argv) != 1:
        print(f"usage: python -m {module} JOB.json", file=sys.stderr)
        return 2
    try:
        return run(json.loads(Path(argv[0]).read_text()))
    except Exception as e:  # the parent records it in the job state
        emit(event="error", error=f"{type(e).__name__}: {e}")
        raise
