"""The query path (``plan_query_path``): one smooth walk through every room, clear of the objects of
every layout given, so the same poses are valid in each of them.
"""

from __future__ import annotations

import math

import numpy as np

from vrformats.errors import UserError

from ..scene.model import Layout
from .curves import arc_length, final_yaw, polyline_resample, track_poses, resample_track, smooth_noise, smooth_valid, travel_yaw, turn_loops
from .model import BOB, DEFAULTS, DS, Q_HEIGHT, Q_HEIGHT_VAR, Q_LOOK, Q_PITCH, Q_PITCH_VAR, Q_ROLL, Q_SMOOTH, STEP_HZ, CameraPath
from .space import Space, check_args, path_meta, require_rooms, start_cell

__all__ = ["plan_query_path"]


def _pick_waypoints(space: Space, rng) -> list[tuple[int, int]]:
    """(room index, cell index) waypoints: a few local clearance maxima per room (seeded)."""
    from scipy import ndimage

    g = space.grid
    score = np.minimum(space.dist, 1.2) - 0.4 * space.occ
    score = np.where(space.comp, score, -np.inf)
    peak = ndimage.maximum_filter(np.where(np.isfinite(score), score, -9.0), size=int(0.8 / g) | 1)
    cand = space.comp & (score >= peak - 1e-9)
    out = []
    for k, r in enumerate(space.stage.rooms):
        m = space.comp & (space.room == k)
        if not m.any():
            continue
        area = m.sum() * g * g
        n = int(np.clip(round(area / 4.0), 1, 4))
        roomy = space.dist >= space.clearance + 0.35  # room to turn around without a tight curl
        ii, jj = np.nonzero(cand & m & roomy)
        if len(ii) == 0:
            ii, jj = np.nonzero(cand & m)
        if len(ii) == 0:
            ii, jj = np.nonzero(m)
        sc = score[ii, jj] + rng.uniform(0.0, 0.35, len(ii))
        order = np.argsort(-sc, kind="stable")
        chosen = []
        for o in order:
            p = space.xy(ii[o] * space.nx + jj[o])
            if all(np.linalg.norm(p - q) >= 1.4 for q in chosen):
                chosen.append(p)
                out.append((k, int(ii[o] * space.nx + jj[o])))
            if len(chosen) >= n:
                break
    return out


def _tour(D: np.ndarray, start: int) -> list[int]:
    """Open tour over all nodes from ``start``: nearest neighbour, then 2-opt."""
    n = len(D)
    order, left = [start], set(range(n)) - {start}
    while left:
        cur = order[-1]
        nxt = min(left, key=lambda j: (D[cur, j], j))
        order.append(nxt)
        left.remove(nxt)
    improved = True
    while improved:
        improved = False
        for i in range(1, n - 1):
            for j in range(i + 1, n):
                a, b = order[i - 1], order[i]
                c = order[j]
                d = order[j + 1] if j + 1 < n else None
                before = D[a, b] + (D[c, d] if d is not None else 0.0)
                after = D[a, c] + (D[b, d] if d is not None else 0.0)
                if after < before - 1e-9:
                    order[i : j + 1] = order[i : j + 1][::-1]
                    improved = True
    return order


def plan_query_path(layouts: list[Layout], frames: int = DEFAULTS.query_frames, seed: int = DEFAULTS.seed,
                    fps: float = DEFAULTS.fps, speed: float = DEFAULTS.speed, clearance: float = DEFAULTS.clearance,
                    obstacles: str = DEFAULTS.obstacles, name: str = "query") -> CameraPath:
    """The shared query walk: every room, ``clearance`` from the objects of every layout given."""
    from scipy import ndimage

    check_args(frames, fps, speed, clearance)
    if not layouts:
        raise UserError("plan_query_path needs at least one layout")
    rng = np.random.default_rng([seed, 1])
    zlo = Q_HEIGHT - Q_HEIGHT_VAR - BOB
    zhi = Q_HEIGHT + Q_HEIGHT_VAR + BOB
    space = Space(layouts, clearance, zlo, zhi, obstacles)
    require_rooms(space, "query path")
    step = speed / fps
    need = (frames - 1) * step
    cur = start_cell(space)
    pieces, marks, n_loops = [space.xy([cur])], [], 0
    raw_len = 0.0
    while True:
        wps = _pick_waypoints(space, np.random.default_rng([seed, 2, n_loops]))
        cells = [c for _, c in wps]
        D, Pred = space.shortest(cells)
        start = int(np.argmin(D[:, cur]))
        Dm = D[:, cells]
        order = _tour(Dm, start)
        seq = [cur] + [cells[o] for o in order]
        for a, b in zip(seq[:-1], seq[1:]):
            if a == b:
                continue
            if a in cells:
                poly = space.xy(space.trace(Pred[cells.index(a)], a, b))
            else:
                poly = space.xy(space.trace(Pred[cells.index(b)], b, a))[::-1]
            pieces.append(poly[1:])
            marks.append(sum(len(p) for p in pieces) - 1)
            raw_len += float(np.linalg.norm(np.diff(poly, axis=0), axis=1).sum())
        cur = seq[-1]
        n_loops += 1
        if raw_len >= 1.25 * need + 2.0 or n_loops >= 100:
            raw = np.concatenate(pieces)
            P = _dense_smooth(space, raw, marks[:-1], Q_SMOOTH, rng)
            if arc_length(P)[-1] >= need:
                break
            if n_loops >= 100:
                raise UserError(f"query path: the free space shared by {', '.join(l.name for l in layouts)} is too "
                                f"small to walk {need:.1f} m without standing still")
    xy, _ = resample_track(P, {}, frames, step)
    n = len(xy)
    t = np.arange(n) / fps
    nr = np.random.default_rng([seed, 3])
    z = Q_HEIGHT + Q_HEIGHT_VAR * smooth_noise(nr, t, 14.0, 40.0) + BOB * np.sin(2 * math.pi * STEP_HZ * speed * t)
    travel = ndimage.gaussian_filter1d(travel_yaw(xy), 0.6 * fps, mode="nearest") if n > 1 else np.zeros(n)
    target = travel + Q_LOOK * smooth_noise(nr, t, 9.0, 22.0)
    yaw = final_yaw(target, fps)
    pitch = Q_PITCH + Q_PITCH_VAR * smooth_noise(nr, t, 7.0, 19.0)
    roll = Q_ROLL * smooth_noise(nr, t, 5.0, 13.0) + math.radians(0.4) * np.sin(math.pi * STEP_HZ * speed * t)
    poses = track_poses(xy, z, yaw, pitch, roll)
    path = CameraPath(name, poses, float(fps), {})
    path.meta = path_meta("query", layouts, seed, frames, fps, speed, clearance, obstacles, space, path,
                      {"loops": n_loops, "smoothing_sigma_m": Q_SMOOTH, "height_m": Q_HEIGHT, "height_var_m": Q_HEIGHT_VAR,
                       "bob_m": BOB, "look_around_deg": round(math.degrees(Q_LOOK), 3)})
    return path


def _dense_smooth(space: Space, raw: np.ndarray, marks: list[int], sigma: float, rng) -> np.ndarray:
    looped, _ = turn_loops(space, raw, marks, rng)
    Q = polyline_resample(looped, DS)
    Q, _ = smooth_valid(space, Q, 0.1)  # takes the grid staircase off first (nearly always valid)
    P, _ = smooth_valid(space, Q, sigma)
    return P
