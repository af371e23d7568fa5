"""Speed of learned-detector models side by side (``reloc bench detector-speed TOUR -m A.onnx B.onnx``).

Each model runs on one onnxruntime thread (the experiments' setting) over the same RGB frames of a
tour, round robin (frame i through every model, then frame i + 1, ...), so the machine's drifts hit
every model alike. Per model it prints the median wall time of

* ``network``: ``LearnedDetector.predict`` (tonemap, 8-bit input, the network, softmax), and
* ``detect``: ``predict`` plus cutting instances (``LearnedDetector.detect``),

and their ratio against the first model. The machine is shared and noisy: quote medians and
ratios, never one run.
"""

from __future__ import annotations
from vrformats.cli import positive_int

import argparse
import statistics
import time


def bench(tour_dir, models, frames: int = 40, repeats: int = 3) -> list[dict]:
    from vrformats.tour import Tour

    from .base import FrameData
    from .learned import LearnedDetector

    tour = Tour(tour_dir)
    data = []
    for i in tour.frame_indices:
        f = tour.frame(int(i), rgb=True, depth=True, instance=False, semantic=False)
        if f.rgb is not None:
            data.append(FrameData(int(i), f.depth, tour.K, rgb=f.rgb))
        if len(data) >= frames:
            break
    if not data:
        raise SystemExit(f"{tour_dir}: no RGB frames")
    dets = [LearnedDetector(m) for m in models]
    for d in dets:  # warm-up
        d.detect(data[0])
    net = [[] for _ in dets]
    full = [[] for _ in dets]
    for _ in range(repeats):
        for fd in data:
            for k, d in enumerate(dets):
                t0 = time.perf_counter()
                d.predict(fd.rgb, fd.index)
                net[k].append(time.perf_counter() - t0)
                t0 = time.perf_counter()
                d.detect(fd)
                full[k].append(time.perf_counter() - t0)
    rows = []
    for k, m in enumerate(models):
        rows.append({"model": str(m), "network_ms": round(1000 * statistics.median(net[k]), 1),
                     "detect_ms": round(1000 * statistics.median(full[k]), 1), "frames": len(data) * repeats})
    for r in rows:
        r["network_ratio"] = round(r["network_ms"] / rows[0]["network_ms"], 2)
        r["detect_ratio"] = round(r["detect_ms"] / rows[0]["detect_ms"], 2)
    return rows


def add_arguments(ap: argparse.ArgumentParser) -> None:
    """The options of ``reloc bench detector-speed``."""
    ap.add_argument("tour", help="a rendered tour with RGB frames")
    ap.add_argument("-m", "--models", nargs="+", required=True, help="ONNX models (the first is the reference)")
    ap.add_argument("--frames", type=positive_int, default=40)
    ap.add_argument("--repeats", type=int, default=3)


def run(args) -> int:
    rows = bench(args.tour, args.models, args.frames, args.repeats)
    print("| model | network ms (median) | ratio | detect ms (median) | ratio | frames |")
    print("|---|---|---|---|---|---|")
    for r in rows:
        print(f"| {r['model']} | {r['network_ms']} | {r['network_ratio']} | {r['detect_ms']} | {r['detect_ratio']} | {r['frames']} |")
    return 0
