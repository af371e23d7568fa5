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
