#!/usr/bin/env python3
"""Clips whose output with clip closure is worse than the causal output, in an experiment's VideoReloc runs.

    python tools/closure_audit.py RESULTS_DIR [--method videoreloc] [--threshold 1.0]

The paper's protocol freezes a frame's causal pose from evidence up to that frame and its closure
pose when its clip closes; closure sees more evidence, so a clip whose closure frames fail (median
position error over the threshold) while its causal frames succeed is a back-end defect worth a
look (issue 55). Prints one line per such clip (tour, clip, frames, its placement's source before
and after the back-end, kappa, the two median errors) and a count per tour; exit 0 either way.
Ground truth from each run's tour (``run.json``'s ``tour``; ``poses.txt``, camera-to-world).
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from vrformats.camera import read_tum  # noqa: E402
from vrformats.errors import UserError  # noqa: E402
from vrformats.tour import Tour  # noqa: E402


def positions(path: Path, fps: float) -> dict[int, np.ndarray]:
    frames, T = read_tum(path, fps=fps)[:2]
    return {int(i): np.asarray(P)[:3, 3] for i, P in zip(frames, T)}


def audit_run(run: Path, threshold: float) -> list[dict]:
    meta = json.loads((run / "run.json").read_text())
    tour = Tour(meta["tour"])
    gt = {int(i): np.asarray(T)[:3, 3] for i, T in zip(tour.frame_indices, tour.poses)}
    fps = float(tour.fps)
    causal, closure = positions(run / "causal.txt", fps), positions(run / "closure.txt", fps)
    out = []
    for c in json.loads((run / "clips.json").read_text()):
        fr = [i for i in range(c["start"], c["end"] + 1) if i in gt]

        def med(d):
            e = [np.linalg.norm(d[i] - gt[i]) if i in d else np.inf for i in fr]
            return float(np.median(e)) if e else float("inf")

        m_closure, m_causal = med(closure), med(causal)
        if m_closure > threshold >= m_causal:
            out.append({"tour": run.name, "clip": c["clip"], "frames": [c["start"], c["end"]], "front_source": c["front_source"],
                        "source": c["source"], "kappa": c["kappa"], "closure_m": round(m_closure, 3), "causal_m": round(m_causal, 3)})
    return out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("results", type=Path, help="a reloc experiment results folder (with runs/)")
    ap.add_argument("--method", default="videoreloc", help="the method's runs folder (default videoreloc)")
    ap.add_argument("--threshold", type=float, default=1.0, help="position error, m (default 1.0, the paper's 1 m)")
    a = ap.parse_args(argv)
    try:
        runs_dir = a.results / "runs" / a.method
        if not runs_dir.is_dir():
            raise UserError(f"{runs_dir}: no runs of method {a.method!r}")
        rows, n_runs = [], 0
        for run in sorted(p for p in runs_dir.iterdir() if (p / "clips.json").is_file()):
            n_runs += 1
            rows += audit_run(run, a.threshold)
    except UserError as e:
        print(f"error: {e}", file=sys.stderr)
        return 2
    for r in rows:
        print(f"{r['tour']}: clip {r['clip']} ({r['frames'][0]}-{r['frames'][1]}) {r['front_source']} -> {r['source']}, "
              f"kappa {r['kappa']:.2f}: closure {r['closure_m']:.2f} m, causal {r['causal_m']:.2f} m")
    print(f"{len(rows)} clip(s) where closure lost to causal in {n_runs} run(s) of {a.method} ({a.results})")
    return 0


if __name__ == "__main__":
    sys.exit(main())
