"""Pose errors and recall (paper Sec. IV-A, evaluation protocol).

Position error is the camera-center distance; rotation error is the angle of R_gt^T R_est.
Recall counts a frame as a success only when both errors are within the threshold, over ALL
ground-truth frames: a frame without an estimate is a failure. Median errors use returned poses.
"""

from __future__ import annotations

import math

import numpy as np

THRESHOLDS = {"recall_1m_10deg": (1.0, 10.0), "recall_25cm_5deg": (0.25, 5.0)}


def pose_errors(est: dict[int, np.ndarray], gt: dict[int, np.ndarray]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(frames, position errors m, rotation errors deg) for the frames that have both."""
    frames = np.array(sorted(set(est) & set(gt)), dtype=np.int64)
    if not len(frames):
        return frames, np.empty(0), np.empty(0)
    E = np.stack([est[int(i)] for i in frames])
    G = np.stack([gt[int(i)] for i in frames])
    pos = np.linalg.norm(E[:, :3, 3] - G[:, :3, 3], axis=1)
    Rrel = np.einsum("nji,njk->nik", G[:, :3, :3], E[:, :3, :3])
    c = np.clip((np.trace(Rrel, axis1=1, axis2=2) - 1.0) / 2.0, -1.0, 1.0)
    return frames, pos, np.degrees(np.arccos(c))


def summarize(est: dict[int, np.ndarray], gt: dict[int, np.ndarray]) -> dict:
    """Recall at both thresholds over all gt frames, median errors over returned poses, coverage."""
    n = len(gt)
    frames, pos, rot = pose_errors(est, gt)
    out = {}
    for key, (tp, tr) in THRESHOLDS.items():
        ok = (pos <= tp) & (rot <= tr)
        out[key] = float(ok.sum() / n) if n else 0.0
    out["median_pos_m"] = float(np.median(pos)) if len(pos) else math.nan
    out["median_rot_deg"] = float(np.median(rot)) if len(rot) else math.nan
    out["coverage"] = float(len(frames) / n) if n else 0.0
    out["frames"] = int(n)
    return out


def odometry_drift(clips: dict[int, dict[int, np.ndarray]], gt: dict[int, np.ndarray], min_path_m: float = 0.5) -> dict:
    """Within-clip odometry drift against ground truth.

    ``clips``: clip id -> {frame: V_i} (frame i's pose in its clip's frame, ``V_first = I``: the
    ``clip_poses.npz`` of a VideoReloc run); ``gt``: frame -> camera-to-world. Per clip, the
    endpoint error of ``V_last`` against ``G_first^-1 G_last`` (position m, rotation deg) and the
    ground-truth path length (sum of the steps between the clip's frames). Returns pooled
    ``drift_pct`` (100 * sum of endpoint errors / sum of path lengths), ``drift_deg_per_m``, the
    median per-clip ``median_drift_pct`` over clips of at least ``min_path_m``, ``path_m`` and
    ``clips`` (those with at least two frames with ground truth)."""
    err_t, err_r, paths = [], [], []
    for V in clips.values():
        fr = [i for i in sorted(V) if i in gt]
        if len(fr) < 2:
            continue
        G0inv = np.linalg.inv(gt[fr[0]])
        rel = G0inv @ gt[fr[-1]]
        E = np.linalg.inv(V[fr[0]]) @ V[fr[-1]]
        err_t.append(float(np.linalg.norm(E[:3, 3] - rel[:3, 3])))
        c = (np.trace(rel[:3, :3].T @ E[:3, :3]) - 1.0) / 2.0
        err_r.append(float(np.degrees(np.arccos(np.clip(c, -1.0, 1.0)))))
        P = np.stack([gt[i][:3, 3] for i in fr])
        paths.append(float(np.linalg.norm(np.diff(P, axis=0), axis=1).sum()))
    total = float(sum(paths))
    long_ = [100.0 * e / p for e, p in zip(err_t, paths) if p >= min_path_m]
    return {
        "clips": len(paths), "path_m": total,
        "drift_pct": 100.0 * sum(err_t) / total if total > 0 else None,
        "drift_deg_per_m": sum(err_r) / total if total > 0 else None,
        "median_drift_pct": float(np.median(long_)) if long_ else None,
    }


END_REASONS = ("closed", "max length", "end of tour", "odometry failure", "no usable depth")


def end_reason_kind(reason: str) -> str:
    """A clip's ``end_reason`` (``clips.json``) as one of ``END_REASONS``: a gap on a failed odometry
    gate (fitness, inlier rmse, step, rotation) is an odometry failure; a gap on a frame without
    enough valid depth is no usable depth."""
    r = str(reason or "")
    if not r.startswith("gap"):
        return r if r in END_REASONS else "closed"
    return "no usable depth" if "depth" in r else "odometry failure"
