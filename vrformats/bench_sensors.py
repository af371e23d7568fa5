"""Read speed of a tour through each sensor model (``reloc bench sensors TOUR``).

Every sensor model runs when a frame is read (``Tour(root, sensor=...)``), so its cost is paid by
every method on every frame. For each sensor (default: every preset) this reads the same frames of
a rendered tour, round robin (frame i through every sensor, then frame i + step, ...), so the
machine's drifts hit every sensor alike, and prints per sensor:

* ``ms/frame``: the median wall time of ``Tour.frame(i)`` (EXR read + the sensor's depth and colour
  models, motion blur included) over the frames with RGB, and ``ratio`` against ``ideal``;
* ``depth only``: the median for a depth-only read (``rgb=False``: the colour model is skipped);
* ``valid depth``: the mean fraction of pixels with depth after the sensor (what the odometry and the
  detector's observations get), against the render's;
* ``exposure``: the median exposure time (ms) and analog gain the colour model's auto exposure chose.

The machine is shared and noisy: quote the medians and the ratios, never one run.
"""

from __future__ import annotations
from vrformats.cli import positive_int

import argparse
import statistics
import sys
import time

import numpy as np


def bench(tour_dir, sensors=None, frames: int = 60, seed: int = 0, progress: bool = False) -> dict:
    from .sensors import exposure, list_sensors, load_sensor
    from .tour import Tour

    names = list(sensors or list_sensors())
    if "ideal" not in names:
        names.insert(0, "ideal")
    models = {n: load_sensor(n) for n in names}
    tours = {n: Tour(tour_dir, sensor=models[n], sensor_seed=seed) for n in names}
    ideal = tours["ideal"]
    with_rgb = [int(i) for i in ideal.frame_indices if ideal.frame(int(i), depth=False, instance=False,
                                                                  semantic=False).rgb is not None]
    if not with_rgb:
        raise SystemExit(f"{tour_dir}: no frame with RGB (a geometry-only tour); the colour model needs RGB")
    step = max(1, len(with_rgb) // frames)
    idx = with_rgb[::step][:frames]
    t_full = {n: [] for n in names}
    t_depth = {n: [] for n in names}
    valid = {n: [] for n in names}
    expo = {n: [] for n in names}
    from tqdm import tqdm

    for i in tqdm(idx, desc="bench sensors", unit="frame", disable=not progress, file=sys.stderr):
        for n in names:
            t0 = time.perf_counter()
            f = tours[n].frame(i, instance=False, semantic=False)
            t_full[n].append(time.perf_counter() - t0)
            t0 = time.perf_counter()
            tours[n].frame(i, rgb=False, instance=False, semantic=False)
            t_depth[n].append(time.perf_counter() - t0)
            valid[n].append(float(np.mean(f.depth > 0)))
            if n != "ideal":
                raw = ideal.frame(i, depth=False, instance=False, semantic=False).rgb
                expo[n].append(exposure(models[n].color, raw))
    base = statistics.median(t_full["ideal"])
    rows = []
    for n in names:
        med = statistics.median(t_full[n])
        e = expo[n]
        rows.append({"sensor": n, "ms_per_frame": 1000 * med, "ratio": med / base,
                     "depth_only_ms": 1000 * statistics.median(t_depth[n]),
                     "valid_depth": float(np.mean(valid[n])),
                     "exposure_ms": statistics.median([x[0] for x in e]) if e else None,
                     "gain": statistics.median([x[1] for x in e]) if e else None})
    w, h = ideal.intrinsics.width, ideal.intrinsics.height
    return {"tour": str(tour_dir), "frames": len(idx), "size": [w, h], "rows": rows}


def format_table(r: dict) -> str:
    lines = [f"{r['tour']}: {r['frames']} frames with RGB at {r['size'][0]}x{r['size'][1]}, medians",
             f"{'sensor':<18} {'ms/frame':>9} {'ratio':>6} {'depth only':>11} {'valid depth':>12} {'exposure':>9} {'gain':>6}"]
    for x in r["rows"]:
        ex = "-" if x["exposure_ms"] is None else f"{x['exposure_ms']:.1f} ms"
        g = "-" if x["gain"] is None else f"{x['gain']:.1f}"
        lines.append(f"{x['sensor']:<18} {x['ms_per_frame']:>9.2f} {x['ratio']:>6.2f} {x['depth_only_ms']:>8.2f} ms "
                     f"{100 * x['valid_depth']:>11.1f}% {ex:>9} {g:>6}")
    return "\n".join(lines)


def add_arguments(p: argparse.ArgumentParser) -> None:
    """The options of ``reloc bench sensors``."""
    p.add_argument("tour", help="a rendered tour with RGB")
    p.add_argument("--sensors", nargs="*", help="presets or sensor YAML files (default: every preset)")
    p.add_argument("--frames", type=positive_int, default=60, help="frames with RGB to read (spread over the tour)")
    p.add_argument("--seed", type=int, default=0)


def run(a) -> int:
    print(format_table(bench(a.tour, a.sensors, a.frames, a.seed, progress=sys.stderr.isatty())))
    return 0
