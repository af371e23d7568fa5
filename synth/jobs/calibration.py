"""A render job's cost on this machine, from a short calibration render (``synth render SPEC
--dry-run``); the estimate on a Ray cluster is ``synth.jobs.estimate``'s."""

from __future__ import annotations

import os
import time
from pathlib import Path

from vrformats import frames as fr
from vrformats.errors import UserError

from ..render.chunks import run_chunk_process
from .plan import Plan


def measure_calibration(plan: Plan, frames: int = 1) -> dict:
    """A calibration document (``synth.jobs.estimate``): seconds per frame of each chunk kind of the
    plan, measured here on ``frames`` frames (after one left out: it pays for loading the kernels) of
    the first tour by one chunk process using every core, with the CPU seconds that process spent on
    them (over all its threads: core-seconds, which another job on the machine does not inflate
    the way it does wall time), the device each kind rendered on, the size
    of a frame file, and this machine (CPU count and model, load average, date, toolkit version)."""
    import tempfile

    from vrformats.camera import write_tum

    from .estimate import CALIBRATION_FORMAT, CALIBRATION_VERSION, is_gpu, measure_environment

    spec = plan.spec
    name, p = next(iter(plan.tours.items()))
    per, cpu, size, devices, startup = {}, {}, {}, {}, {}
    load = [round(x, 2) for x in os.getloadavg()] if hasattr(os, "getloadavg") else None
    with tempfile.TemporaryDirectory(prefix="synth_calib_") as tmp:
        tmp = Path(tmp)
        idx = list(range(min(frames + 1, len(p.frame_ids))))
        write_tum(tmp / "poses.txt", p.poses[idx], fps=p.path_fps)
        base = {"layout": str(p.layout_file.resolve()), "poses": str(tmp / "poses.txt"), "fps": p.path_fps, "frames": idx,
                "intrinsics": p.intr.to_dict(), "quality": spec.quality, "cycles": spec.cycles, "seed": spec.seed, "device": spec.device,
                "geometry_dir": str(tmp / "geom"), "previews_dir": None, "threads": 0}
        geo = "fast" if spec.geometry == "fast" else "geometry"
        kinds = [geo] + (["rgb"] if spec.renderer == "blender" and any(t.lighting_name for t in plan.tours.values()) else [])
        for kind in kinds:
            out_dir = tmp / ("geom" if kind == geo else kind)
            job = {**base, "pass": kind, "out_dir": str(out_dir),
                   "lighting": next((t.spec.lighting for t in plan.tours.values() if t.lighting_name), None)}
            events = []
            t0 = time.monotonic()
            rc, err, inf = run_chunk_process(kind, job, str(tmp / f"{kind}.json"), str(tmp / f"{kind}.log"),
                                             on_frame=events.append)
            wall = time.monotonic() - t0
            if rc != 0:
                raise UserError(f"calibration render ({kind}) failed: {err}")
            steady = events[1:] or events  # the first frame pays for kernel loading
            per[kind] = sum(ev["seconds"] for ev in steady) / len(steady)
            # the chunk's start-up: its wall time less its frames at the steady rate (process, scene, kernels)
            startup[kind] = round(max(0.0, wall - per[kind] * len(events)), 3)
            if all("cpu" in ev for ev in steady):
                cpu[kind] = sum(ev["cpu"] for ev in steady) / len(steady)
            files = [out_dir / fr.frame_name(i) for i in idx if (out_dir / fr.frame_name(i)).exists()]
            if files:
                size[kind] = round(sum(f.stat().st_size for f in files) / len(files))
            devices[kind] = inf.get("device") or "CPU"
    if hasattr(os, "getloadavg"):
        load = [round(max(a, b), 2) for a, b in zip(load, os.getloadavg())]
    env = measure_environment()
    return {"format": CALIBRATION_FORMAT, "version": CALIBRATION_VERSION, "seconds_per_frame": per,
            "cpu_seconds_per_frame": cpu, "startup_s": startup, "bytes_per_frame": size, "devices": devices,
            "device": next((d for d in devices.values() if is_gpu(d)), "CPU"),
            "frames_measured": len(idx) - 1 if len(idx) > 1 else len(idx), "tour": name,
            "spec": {"name": spec.name, "source": spec.source, "renderer": spec.renderer, "geometry": spec.geometry,
                     "quality": spec.quality, "width": spec.width, "height": spec.height, "device": spec.device},
            "load_avg": load, **env}


def calibrate(plan: Plan, frames: int = 1) -> dict:
    """Seconds per frame of each chunk kind, measured on ``frames`` frames of the first tour."""
    return measure_calibration(plan, frames)["seconds_per_frame"]


def estimate(plan: Plan, per_frame: dict, workers: int, setup: dict | None = None) -> float:
    """Seconds on this machine. The calibration ran one process using every core, so running more
    local workers hides per-chunk start-up (about 3-4 s each) rather than dividing the frame time.
    (A Ray cluster: ``synth.jobs.estimate``.)"""
    from .estimate import SETUP_S

    setup = SETUP_S if setup is None else setup
    work = 0.0
    for c in plan.chunks:
        if c.kind in per_frame:
            work += per_frame[c.kind] * len(c.missing())
    work += sum(setup.get(c.kind, 0.0) for c in plan.chunks if c.missing()) / max(1, min(workers, os.cpu_count() or 1))
    return work
