"""Clip-rigid protocol shared by the per-frame baselines' clip-rigid controls.

A clip is a run of frames whose within-clip odometry V_i is known; its map poses are T_i = S_c V_i for
one unknown clip-to-map transform S_c. Given per-frame map estimates (from any per-frame relocalizer),
every estimated frame proposes a candidate S_i = T_i V_i^-1. The candidate that predicts the most
other estimated frames of the clip within tolerance wins (consensus); S is then refined over those
inliers (rotation: chordal mean of R_T R_V^T; translation: the mean residual for that rotation). With
S, every frame of the clip gets S V_i, frames without an estimate included. Without a consensus the
clip keeps its frame estimates (paper: "without a consensus, they retain the frame estimates").
"""

from __future__ import annotations

import math

import numpy as np

from .geometry import make_T, rotation_mean

POS_TOL_M = 0.25  # a candidate supports a frame when it predicts its position within this ...
ROT_TOL_DEG = 5.0  # ... and its orientation within this
MIN_SUPPORT = 2  # frames (the candidate's own included) needed for a consensus


def _support(S: np.ndarray, Ts: np.ndarray, Vs: np.ndarray, pos_tol: float, cos_tol: float):
    """(inlier mask, position errors) of the predictions S V_j against the estimates T_j."""
    P = np.einsum("ij,njk->nik", S, Vs)
    pos = np.linalg.norm(P[:, :3, 3] - Ts[:, :3, 3], axis=1)
    # rotation angle of R_T^T R_P via its trace: cos = (tr - 1) / 2
    tr = np.einsum("nji,nji->n", Ts[:, :3, :3], P[:, :3, :3])
    cos = (tr - 1.0) / 2.0
    return (pos <= pos_tol) & (cos >= cos_tol), pos


def _refine(Ts: np.ndarray, Vs: np.ndarray) -> np.ndarray:
    R = rotation_mean(np.einsum("nij,nkj->nik", Ts[:, :3, :3], Vs[:, :3, :3]))
    t = np.mean(Ts[:, :3, 3] - Vs[:, :3, 3] @ R.T, axis=0)
    return make_T(R, t)


def fit_clip_transform(frame_poses: dict[int, np.ndarray], V: dict[int, np.ndarray], pos_tol: float = POS_TOL_M,
                       rot_tol_deg: float = ROT_TOL_DEG, min_support: int = MIN_SUPPORT) -> tuple[np.ndarray | None, int]:
    """One clip-to-map transform S robustly fitted from per-frame estimates T_i and odometry V_i.

    ``frame_poses``: frame -> estimated camera-to-world pose (frames without an estimate absent);
    ``V``: frame -> the clip's odometry pose. Returns (S, support) with support the number of
    estimated frames that S predicts within (pos_tol, rot_tol_deg); S is None when the best
    candidate has fewer than ``min_support`` supporters.
    """
    frames = sorted(i for i in V if i in frame_poses and frame_poses[i] is not None)
    if not frames:
        return None, 0
    Ts = np.stack([np.asarray(frame_poses[i], float) for i in frames])
    Vs = np.stack([np.asarray(V[i], float) for i in frames])
    Vinv = np.linalg.inv(Vs)
    cands = np.einsum("nij,njk->nik", Ts, Vinv)  # S_i = T_i V_i^-1
    cos_tol = math.cos(math.radians(rot_tol_deg))
    best, best_key = None, None
    for k in range(len(frames)):
        ok, pos = _support(cands[k], Ts, Vs, pos_tol, cos_tol)
        key = (int(ok.sum()), -float(pos[ok].sum()))  # most support, then the tightest
        if best_key is None or key > best_key:
            best, best_key = ok, key
    if best_key[0] < min_support:
        return None, best_key[0]
    S = _refine(Ts[best], Vs[best])
    # one re-evaluation with the refined transform (it may gain or lose borderline frames)
    ok, _ = _support(S, Ts, Vs, pos_tol, cos_tol)
    if ok.sum() >= best_key[0]:
        S = _refine(Ts[ok], Vs[ok])
        ok, _ = _support(S, Ts, Vs, pos_tol, cos_tol)
    n = int(ok.sum())
    if n < min_support:
        return None, n
    return S, n


def clip_rigid_trajectory(frame_poses: dict[int, np.ndarray], clip_poses: dict[int, dict[int, np.ndarray]],
                          pos_tol: float = POS_TOL_M, rot_tol_deg: float = ROT_TOL_DEG,
                          min_support: int = MIN_SUPPORT) -> tuple[dict[int, np.ndarray], dict]:
    """Clip-rigid trajectory: frame -> pose, and statistics.

    Per clip (``clip_poses``: clip id -> {frame: V_i}, e.g. ``reloc.run.load_clip_poses``): with a
    consensus S every frame of the clip gets S V_i; without one the clip's frames keep their
    per-frame estimates (frames without an estimate stay without a pose). Estimated frames that
    belong to no clip keep their estimates too.
    """
    out: dict[int, np.ndarray] = {}
    per_clip = []
    in_clip: set[int] = set()
    for cid in sorted(clip_poses):
        V = clip_poses[cid]
        in_clip.update(int(i) for i in V)
        est = {int(i): frame_poses[i] for i in V if i in frame_poses and frame_poses[i] is not None}
        S, support = fit_clip_transform(est, V, pos_tol, rot_tol_deg, min_support)
        if S is not None:
            for i, Vi in V.items():
                out[int(i)] = S @ np.asarray(Vi, float)
        else:
            for i, T in est.items():
                out[i] = np.asarray(T, float)
        per_clip.append({"clip": int(cid), "frames": len(V), "estimates": len(est), "support": int(support),
                         "fitted": S is not None})
    for i, T in frame_poses.items():
        if int(i) not in in_clip and T is not None:
            out[int(i)] = np.asarray(T, float)
    stats = {
        "clips": len(per_clip),
        "clips_fitted": sum(c["fitted"] for c in per_clip),
        "clips_fallback": sum(not c["fitted"] for c in per_clip),
        "frames_out": len(out),
        "per_clip": per_clip,
    }
    return out, stats
