"""One clip-to-map transform from per-frame map poses: the consensus fit that VideoReloc's frame
anchors (``reloc.frontend.registration.anchor_candidate``) and the per-frame baselines' clip-rigid controls
share.

A clip is a run of frames whose within-clip odometry V_i is known; its map poses are T_i = S_c V_i for
one unknown clip-to-map transform S_c. Given per-frame map estimates (frame anchors W_i, or any
per-frame relocalizer's poses), every estimated frame proposes a candidate S_i = T_i V_i^-1. The
candidate that predicts the most other estimated frames of the clip within tolerance wins
(consensus; ties: the smaller summed error); S is then refined over those inliers (rotation:
chordal mean of R_T R_V^T; translation: the mean residual for that rotation) and re-evaluated once.
For the clip-rigid controls, every frame of the clip gets S V_i, frames without an estimate
included; without a consensus the clip keeps its frame estimates (paper: "without a consensus, they
retain the frame estimates").
"""

from __future__ import annotations

import math
from typing import Callable

import numpy as np

from ..config import ClipRigidConfig
from ..geometry import make_T, rotation_mean

# accept(position errors m, rotation errors rad) -> (inlier mask, per-frame error for ties)
Tolerance = Callable[[np.ndarray, np.ndarray], tuple[np.ndarray, np.ndarray]]


def within(pos_tol: float, rot_tol_deg: float) -> Tolerance:
    """Support when the position is within pos_tol and the orientation within rot_tol_deg (ties:
    summed position error)."""
    rot_tol = math.radians(rot_tol_deg)
    return lambda pos, rot: ((pos <= pos_tol) & (rot <= rot_tol), pos)


def within_sum(tol: float) -> Tolerance:
    """Support when translation distance plus rotation angle (radians) is below tol (Sec. III-D's
    anchor consensus; ties: summed distance)."""
    return lambda pos, rot: (pos + rot < tol, pos + rot)


def _errors(S: np.ndarray, Ts: np.ndarray, Vs: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(position, rotation angle) errors of the predictions S V_j against the estimates T_j."""
    P = np.einsum("ij,njk->nik", S, Vs)
    pos = np.linalg.norm(P[:, :3, 3] - Ts[:, :3, 3], axis=1)
    # rotation angle of R_T^T R_P via its trace: cos = (tr - 1) / 2
    tr = np.einsum("nji,nji->n", Ts[:, :3, :3], P[:, :3, :3])
    return pos, np.arccos(np.clip((tr - 1.0) / 2.0, -1.0, 1.0))


def _refine(Ts: np.ndarray, Vs: np.ndarray) -> np.ndarray:
    R = rotation_mean(np.einsum("nij,nkj->nik", Ts[:, :3, :3], Vs[:, :3, :3]))
    t = np.mean(Ts[:, :3, 3] - Vs[:, :3, 3] @ R.T, axis=0)
    return make_T(R, t)


def consensus_fit(Ts: np.ndarray, Vs: np.ndarray, accept: Tolerance,
                  min_support: int) -> tuple[np.ndarray | None, np.ndarray]:
    """The consensus transform S of per-frame map poses ``Ts`` (n, 4, 4) and within-clip poses
    ``Vs`` (n, 4, 4). Returns (S, support mask over the n frames); S is None when fewer than
    ``min_support`` frames support the best candidate."""
    Ts, Vs = np.asarray(Ts, float).reshape(-1, 4, 4), np.asarray(Vs, float).reshape(-1, 4, 4)
    if not len(Ts):
        return None, np.zeros(0, bool)
    cands = np.einsum("nij,njk->nik", Ts, np.linalg.inv(Vs))  # S_i = T_i V_i^-1
    best, best_key = None, None
    for k in range(len(Ts)):
        ok, err = accept(*_errors(cands[k], Ts, Vs))
        key = (int(ok.sum()), -float(err[ok].sum()))  # most support, then the tightest
        if best_key is None or key > best_key:
            best, best_key = ok, key
    if best_key[0] < min_support:
        return None, best
    S = _refine(Ts[best], Vs[best])
    # one re-evaluation with the refined transform (it may gain or lose borderline frames)
    ok, _ = accept(*_errors(S, Ts, Vs))
    if ok.sum() >= best_key[0]:
        S = _refine(Ts[ok], Vs[ok])
        ok, _ = accept(*_errors(S, Ts, Vs))
    if ok.sum() < min_support:
        return None, ok
    return S, ok


def fit_clip_transform(frame_poses: dict[int, np.ndarray], V: dict[int, np.ndarray],
                       cfg: ClipRigidConfig | None = None) -> tuple[np.ndarray | None, int]:
    """One clip-to-map transform S robustly fitted from per-frame estimates T_i and odometry V_i.

    ``frame_poses``: frame -> estimated camera-to-world pose (frames without an estimate absent);
    ``V``: frame -> the clip's odometry pose. Returns (S, support) with support the number of
    estimated frames that S predicts within (pos_tol_m, rot_tol_deg); S is None when the best
    candidate has fewer than ``min_support`` supporters.
    """
    cfg = cfg or ClipRigidConfig()
    frames = sorted(i for i in V if i in frame_poses and frame_poses[i] is not None)
    if not frames:
        return None, 0
    Ts = np.stack([np.asarray(frame_poses[i], float) for i in frames])
    Vs = np.stack([np.asarray(V[i], float) for i in frames])
    S, ok = consensus_fit(Ts, Vs, within(cfg.pos_tol_m, cfg.rot_tol_deg), cfg.min_support)
    return S, int(ok.sum())


def clip_rigid_trajectory(frame_poses: dict[int, np.ndarray], clip_poses: dict[int, dict[int, np.ndarray]],
                          cfg: ClipRigidConfig | None = None) -> tuple[dict[int, np.ndarray], dict]:
    """Clip-rigid trajectory: frame -> pose, and statistics.

    Per clip (``clip_poses``: clip id -> {frame: V_i}, e.g. ``reloc.backend.run.load_clip_poses``): with a
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
        S, support = fit_clip_transform(est, V, cfg)
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
