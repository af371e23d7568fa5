"""Odometry speed/drift trade-off (``reloc bench odometry TOUR``).

For each setting (odometry width, frame stride, method) the frames of a rendered tour are fed
through :class:`reloc.frontend.odometry.OdometryChain` in windows of a clip-like length (300 frames by
default) starting at several offsets, each window a fresh chain (as a clip starts without a
motion prior). Depths are read before the clock starts; the wall time covers everything the
front-end pays per frame (subsampling, pyramids, solves, gates, interpolation).

Reported per setting:

* ``ms_per_frame``: median over windows of (window wall time / frames);
* ``drift_pct``: median over windows of endpoint translation error / ground-truth path length,
  in percent, each clip of the window aligned to ground truth at its first frame (a window that
  breaks counts the errors and path lengths of all its clips);
* ``drift_deg_per_m``: the same for the endpoint rotation error;
* ``worst_drift_pct``: the largest window drift;
* ``failed_steps``: fraction of odometry solves that failed a gate; ``breaks``: clip breaks in
  all windows together.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import math
import sys
import time
from pathlib import Path

import numpy as np

from vrformats.atomic import write_json_atomic
from vrformats.cli import add_json, add_out, positive_int
from vrformats.errors import check_output_file

from ..config import OdometryConfig
from ..frontend.odometry import OdometryChain, rotation_deg

DEFAULT_SETTINGS = [(w, s, "point_to_plane") for w in (640, 320, 160, 80) for s in (1, 2, 3)]


def load_depths(tour_dir, frames: int | None = None, start: int = 0):
    """(frame indices, depths (N, H, W) float32, poses (N, 4, 4), K, width, height, has_rgb).

    Only frames whose files exist are read (a tour may still be rendering); ``frames`` caps
    the count after ``start`` (a position in poses.txt order).
    """
    from vrformats import frames as fr
    from vrformats.camera import read_tum

    root = Path(tour_dir)
    from vrformats.tour import Tour
    from vrformats.errors import UserError

    try:
        tour = Tour(root)
        idx_all, poses_all, K = tour.frame_indices, tour.poses, tour.K
        W, H, fps = tour.intrinsics.width, tour.intrinsics.height, tour.fps
    except UserError:  # e.g. meta.json not written yet while rendering
        from vrformats.tour import CAMERA_FILE, read_camera

        intr, fps, _ = read_camera(root / CAMERA_FILE)
        K, W, H = intr.K, intr.width, intr.height
        idx_all, poses_all = read_tum(root / "poses.txt", fps=fps)
    idx, depths, poses = [], [], []
    has_rgb = False
    for k in range(start, len(idx_all)):
        if frames is not None and len(idx) >= frames:
            break
        i = int(idx_all[k])
        path = root / "frames" / fr.frame_name(i)
        if not path.is_file():
            break  # stop at the first missing frame: windows need consecutive frames
        img = fr.read_frame(path, rgb=False, instance=False, semantic=False)
        if img.depth is None:
            break
        if not idx:
            has_rgb = _has_rgb(path)
        idx.append(i)
        depths.append(img.depth.astype(np.float32, copy=False))
        poses.append(poses_all[k])
    if not idx:
        raise SystemExit(f"{root}: no readable frames")
    return np.array(idx), np.stack(depths), np.stack(poses), K, W, H, has_rgb


def _has_rgb(path) -> bool:
    from vrformats import frames as fr

    try:
        return all(c in fr.read_channels(path) for c in fr.RGB_CHANNELS)
    except fr.FrameFileError:
        return False


def window_errors(outs, poses: dict[int, np.ndarray]) -> dict:
    """Endpoint errors of each clip in a window's chain output, aligned at the clip's first frame."""
    clips: dict[int, list] = {}
    for o in outs:
        if o.V is not None:
            clips.setdefault(o.clip, []).append(o)
    terr = rerr = path = 0.0
    for seq in clips.values():
        if len(seq) < 2:
            continue
        a, b = seq[0], seq[-1]
        est = poses[a.frame_index] @ b.V
        gt = poses[b.frame_index]
        terr += float(np.linalg.norm(est[:3, 3] - gt[:3, 3]))
        rerr += rotation_deg(gt[:3, :3].T @ est[:3, :3])
        pos = np.array([poses[o.frame_index][:3, 3] for o in seq])
        path += float(np.linalg.norm(np.diff(pos, axis=0), axis=1).sum())
    return {"translation_error_m": terr, "rotation_error_deg": rerr, "path_m": path, "clips": len(clips)}


def run_window(idx, depths, K, W, H, cfg: OdometryConfig):
    """Chain one window; returns (chain outputs, seconds, chain)."""
    chain = OdometryChain(K, W, H, cfg)
    outs = []
    t0 = time.perf_counter()
    for i, d in zip(idx, depths):
        outs += chain.add(int(i), d)
    outs += chain.flush()
    return outs, time.perf_counter() - t0, chain


def odometry_tradeoff(tour_dir, frames: int = 900, settings=None, window: int = 300, windows: int | None = None,
                      start: int = 0, config: OdometryConfig | None = None, data=None, progress: bool = False) -> list[dict]:
    """Speed and drift of each (width, stride, method) setting; see the module docstring.

    ``windows`` window starts are spread evenly over the loaded frames (default: every half
    window). ``config`` supplies the other odometry settings. ``data`` reuses a
    :func:`load_depths` result.
    """
    settings = list(settings or DEFAULT_SETTINGS)
    base = config or OdometryConfig()
    idx, depths, poses, K, W, H, has_rgb = data or load_depths(tour_dir, frames, start)
    n = len(idx)
    window = min(window, n)
    if windows is None:
        starts = list(range(0, n - window + 1, max(1, window // 2)))
    else:
        starts = sorted(set(np.linspace(0, n - window, max(1, windows)).round().astype(int).tolist()))
    pose_of = {int(i): P for i, P in zip(idx, poses)}
    rows = []
    for width, stride, method in settings:
        if method == "hybrid" and not has_rgb:
            continue
        cfg = dataclasses.replace(base, width=int(width), stride=int(stride), method=method)
        ms, drift, rot, solves, failed, breaks = [], [], [], 0, 0, 0
        for s0 in starts:
            sl = slice(s0, s0 + window)
            outs, secs, chain = run_window(idx[sl], depths[sl], K, W, H, cfg)
            assert [o.frame_index for o in outs] == [int(i) for i in idx[sl]]
            e = window_errors(outs, pose_of)
            ms.append(1000.0 * secs / window)
            if e["path_m"] > 0:
                drift.append(100.0 * e["translation_error_m"] / e["path_m"])
                rot.append(e["rotation_error_deg"] / e["path_m"])
            solves += len(chain.steps)
            failed += sum(not st.ok for st in chain.steps)
            breaks += sum(o.status == "break" for o in outs)
        row = {
            "width": int(width), "stride": int(stride), "method": method,
            "ms_per_frame": float(np.median(ms)),
            "drift_pct": float(np.median(drift)) if drift else math.nan,
            "drift_deg_per_m": float(np.median(rot)) if rot else math.nan,
            "worst_drift_pct": float(np.max(drift)) if drift else math.nan,
            "failed_steps": failed / solves if solves else 0.0,
            "breaks": breaks,
            "windows": len(starts), "window_frames": window,
        }
        rows.append(row)
        if progress:
            print(format_row(row), file=sys.stderr, flush=True)
    return rows


HEADER = (f"{'width':>5} {'stride':>6} {'method':<14} {'ms/frame':>8} {'drift %':>8} {'deg/m':>6} "
          f"{'worst %':>8} {'failed':>7} {'breaks':>6}")


def format_row(r: dict) -> str:
    return (f"{r['width']:>5} {r['stride']:>6} {r['method']:<14} {r['ms_per_frame']:>8.2f} {r['drift_pct']:>8.2f} "
            f"{r['drift_deg_per_m']:>6.2f} {r['worst_drift_pct']:>8.2f} {r['failed_steps']:>7.1%} {r['breaks']:>6}")


def format_table(rows: list[dict]) -> str:
    return "\n".join([HEADER] + [format_row(r) for r in rows])


def add_arguments(p: argparse.ArgumentParser) -> None:
    """The options of ``reloc bench odometry``."""
    p.add_argument("tour", help="tour directory")
    p.add_argument("--frames", type=positive_int, default=900, help="frames to load (default 900)")
    p.add_argument("--start", type=int, default=0, help="first frame position (default 0)")
    p.add_argument("--window", type=int, default=300, help="frames per window (a clip-like length; default 300)")
    p.add_argument("--windows", type=int, help="number of windows (default: one every half window)")
    p.add_argument("--widths", default="640,320,160,80", help="odometry image widths to compare (default 640,320,160,80)")
    p.add_argument("--strides", default="1,2,3", help="frame strides to compare (default 1,2,3)")
    p.add_argument("--methods", default="point_to_plane", help="point_to_plane,hybrid (hybrid needs RGB)")
    add_json(p, "the rows")
    add_out(p, "also write the rows to this JSON file", required=False)


def run(a) -> int:
    if a.out:
        check_output_file(a.out)
    settings = [(int(w), int(s), m) for w in a.widths.split(",") for s in a.strides.split(",")
                for m in a.methods.split(",")]
    data = load_depths(a.tour, a.frames, a.start)
    print(f"{a.tour}: {len(data[0])} frames {data[4]}x{data[5]}, windows of {min(a.window, len(data[0]))}"
          + ("" if data[6] else ", no RGB (hybrid skipped)"), file=sys.stderr if a.json else sys.stdout, flush=True)
    rows = odometry_tradeoff(a.tour, settings=settings, window=a.window, windows=a.windows, data=data)
    print(json.dumps(rows, indent=1) if a.json else format_table(rows))
    if a.out:
        write_json_atomic(a.out, rows, indent=1)
    return 0

