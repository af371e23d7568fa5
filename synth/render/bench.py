"""``synth bench render``: seconds per frame of every renderer on this machine, on apt_0.

Rows: geometry passes with Blender (Cycles, one sample per pixel) and with the fast Open3D
renderer, and RGB per quality preset (Cycles, day lighting), at 320x240 and 640x480. Each figure
is the median over several frames spread along the query path; scene set-up (building the
Blender scene or the ray-casting scene) is reported separately and not counted per frame.
Blender runs in a fresh worker process, as in real renders.
"""

from __future__ import annotations

import json
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from vrformats.atomic import write_nofollow
from vrformats.camera import Intrinsics, write_tum
from vrformats.cli import add_json, positive_int

from .settings import QUALITY

SIZES = ((320, 240), (640, 480))


def _frames_along(poses: np.ndarray, n: int) -> np.ndarray:
    idx = np.linspace(0, len(poses) - 1, n + 2).round().astype(int)[1:-1]
    return poses[idx]


def bench_fast(layout, poses, intr: Intrinsics) -> dict:
    from .fast_render import FastRenderer

    t0 = time.perf_counter()
    r = FastRenderer(layout)
    setup = time.perf_counter() - t0
    r.render(poses[0], intr)  # warm-up (ray table)
    ts = []
    for T in poses:
        t = time.perf_counter()
        r.render(T, intr)
        ts.append(time.perf_counter() - t)
    return {"setup_s": setup, "per_frame_s": ts}


def bench_blender(layout_file: Path, pass_: str, poses, intr: Intrinsics, quality: str, work: Path, lighting="day",
                  threads: int = 0, device: str = "cpu") -> dict:
    """Run one worker process over the frames; per-frame seconds come from the worker's own events."""
    poses_file = work / f"poses_{intr.width}.txt"
    write_tum(poses_file, poses)
    gdir = work / f"geom_{intr.width}"
    out = work / f"{pass_}_{quality}_{intr.width}"
    job = {"pass": pass_, "layout": str(layout_file), "lighting": lighting, "poses": str(poses_file), "fps": 30.0,
           "frames": list(range(len(poses))), "intrinsics": intr.to_dict(), "quality": quality, "seed": 0,
           "device": device, "out_dir": str(gdir if pass_ == "geometry" else out), "geometry_dir": str(gdir),
           "previews_dir": None, "threads": threads}
    jf = work / f"job_{pass_}_{quality}_{intr.width}.json"
    write_nofollow(jf, json.dumps(job))
    t0 = time.perf_counter()
    proc = subprocess.run([sys.executable, "-m", "synth.blender.worker", str(jf)], capture_output=True, text=True)
    total = time.perf_counter() - t0
    if proc.returncode != 0:
        raise RuntimeError(f"benchmark worker failed: {proc.stdout[-2000:]} {proc.stderr[-2000:]}")
    evs = [json.loads(x) for x in proc.stdout.splitlines() if x.startswith("{")]
    ts = [e["seconds"] for e in evs if e.get("event") == "frame"]
    return {"setup_s": total - sum(ts), "per_frame_s": ts}


def run_bench(frames: int = 5, qualities=tuple(QUALITY), sizes=SIZES, layout_name: str = "apt_0", path: str = "query",
              progress: bool = True) -> list[dict]:
    from ..paths.files import load_path
    from ..scene.model import load_layout, resolve_layout_path

    layout_file = resolve_layout_path(layout_name).resolve()
    layout = load_layout(layout_file)
    poses = _frames_along(load_path(path).poses, frames)
    rows = []
    with tempfile.TemporaryDirectory(prefix="synth_bench_") as tmp:
        work = Path(tmp)
        plan = [(w, h, kind, q) for (w, h) in sizes for kind, q in [("fast", None), ("blender", None)] + [("rgb", q) for q in qualities]]
        for w, h, kind, q in plan:
            intr = Intrinsics.from_fov(w, h)
            if progress:
                print(f"  {kind:<8} {q or '':<9} {w}x{h} ...", file=sys.stderr, flush=True)
            if kind == "fast":
                r = bench_fast(layout, poses, intr)
                pass_, renderer = "geometry", "fast (Open3D)"
            elif kind == "blender":
                r = bench_blender(layout_file, "geometry", poses, intr, "preview", work)
                pass_, renderer = "geometry", "blender (Cycles)"
            else:
                r = bench_blender(layout_file, "rgb", poses, intr, q, work)
                pass_, renderer = f"rgb {q}", "blender (Cycles)"
            med = statistics.median(r["per_frame_s"])
            rows.append({"pass": pass_, "renderer": renderer, "width": w, "height": h, "frames": len(r["per_frame_s"]),
                         "median_s_per_frame": round(med, 4), "frames_per_s": round(1.0 / med, 2) if med > 0 else None,
                         "min_s": round(min(r["per_frame_s"]), 4), "max_s": round(max(r["per_frame_s"]), 4),
                         "setup_s": round(r["setup_s"], 3)})
    return rows


def ratios(rows: list[dict]) -> dict:
    out = {}
    for w, h in {(r["width"], r["height"]) for r in rows}:
        g = {r["renderer"]: r["median_s_per_frame"] for r in rows if r["pass"] == "geometry" and (r["width"], r["height"]) == (w, h)}
        if "fast (Open3D)" in g and "blender (Cycles)" in g:
            out[f"{w}x{h}"] = round(g["blender (Cycles)"] / g["fast (Open3D)"], 1)
    return out


def cmd_bench(args) -> int:
    import os

    qualities = tuple(args.quality) if args.quality else tuple(QUALITY)
    rows = run_bench(frames=args.frames, qualities=qualities, progress=not args.json)
    rat = ratios(rows)
    env = {"cpus": os.cpu_count(), "frames_per_row": args.frames}
    if args.json:
        print(json.dumps({"rows": rows, "blender_over_fast_geometry": rat, "machine": env}, indent=1))
        return 0
    print(f"apt_0, query path, {args.frames} frames per row, {env['cpus']} CPUs; medians (set-up not included)")
    print(f"{'pass':<14} {'renderer':<17} {'size':>8} {'s/frame':>9} {'frames/s':>9} {'setup s':>8}")
    for r in rows:
        print(f"{r['pass']:<14} {r['renderer']:<17} {r['width']}x{r['height']:<4} {r['median_s_per_frame']:>9.3f} "
              f"{r['frames_per_s'] or 0:>9.2f} {r['setup_s']:>8.2f}")
    for size, x in sorted(rat.items()):
        print(f"geometry, Blender / fast at {size}: {x}x slower")
    return 0


def register_cli(subparsers):
    """Add the ``bench`` group to ``synth`` with the renderers' benchmark; returns its subcommands, to
    which ``synth.jobs.quality_bench`` adds ``quality``."""
    p = subparsers.add_parser("bench", help="benchmarks that print figures (renderers' seconds per frame; "
                                            "each quality setting's PSNR against a reference)")
    sub = p.add_subparsers(dest="cmd", required=True)
    a = sub.add_parser("render", help="seconds per frame of each renderer and quality on this machine")
    a.add_argument("--frames", type=positive_int, default=5, help="frames per measurement (median reported)")
    a.add_argument("--quality", action="append", choices=list(QUALITY), help="RGB presets to time (default: all)")
    add_json(a)
    a.set_defaults(fn=cmd_bench)
    return sub
