"""The mapping path (``plan_mapping_path``): a cross-hatch tour of one layout, lawnmower sweeps along
x then y in every room with the camera looking across the sweep, rooms chained through doors.
"""

from __future__ import annotations

import math

import numpy as np

from vrformats.errors import UserError

from ..scene.model import Layout
from .curves import arc_length, continuous_angles, final_yaw, track_poses, rate_limit, resample_track, smooth_noise, smooth_valid, travel_yaw, turn_loops
from .model import BOB, DEFAULTS, DS, M_HEIGHT_VAR, M_HEIGHTS, M_LOOK, M_MIN_RUN, M_PITCH, M_PITCH_VAR, M_ROLL, M_SMOOTH, M_SPACING, MARGIN, STEP_HZ, CameraPath
from .space import Space, check_args, grid_line, path_meta, require_rooms, start_cell

__all__ = ["plan_mapping_path"]


def _line_runs(space: Space, k: int, axis: int) -> dict[int, list[tuple[int, int]]]:
    """Free runs (>= M_MIN_RUN) of every grid row (axis 0) or column (axis 1) crossing room ``k`` (cached)."""
    cache = space.__dict__.setdefault("_runs_cache", {})
    key = (k, axis)
    if key not in cache:
        m = space.comp & (space.room == k)
        lines = np.nonzero(m.any(axis=1 - axis))[0]
        cache[key] = {int(i): _runs(m[i, :] if axis == 0 else m[:, i], int(M_MIN_RUN / space.grid)) for i in lines}
    return cache[key]


def _sweep_runs(space: Space, k: int, axis: int, spacing: float, offset: float) -> list[list[tuple[np.ndarray, np.ndarray]]]:
    """Free runs on lawnmower lines in room ``k``: lines along x (axis 0) or y (axis 1), ~``spacing`` apart.

    Each line takes the grid row near its nominal position (within 0.45 spacing) with the most
    free length; a room where no nominal line finds any gets its single best row.
    """
    g = space.grid
    q = space.stage.rooms[k].outline()  # the rect's corners, or the polygon: lines span its extent, runs stay inside it
    r = (q[:, 0].min(), q[:, 1].min(), q[:, 0].max(), q[:, 1].max())
    table = _line_runs(space, k, axis)
    if not table:
        return []
    perp_lo, perp_hi = (r[1], r[3]) if axis == 0 else (r[0], r[2])
    c = space.clearance + MARGIN
    lo, hi = perp_lo + c, perp_hi - c
    if hi < lo:
        lo = hi = (perp_lo + perp_hi) / 2
    n = max(1, int(math.floor((hi - lo) / spacing + 1e-9)) + 1)
    span = (n - 1) * spacing
    pos = np.clip((lo + hi) / 2 - span / 2 + np.arange(n) * spacing + offset * spacing, lo, hi)
    origin = space.y0 if axis == 0 else space.x0
    used, lines = set(), []
    tot = {i: sum(b - a for a, b in runs) * g for i, runs in table.items()}
    for p in pos:
        base = int((p - origin) // g)
        reach = max(1, int(0.45 * spacing / g))
        cand = [i for i in range(base - reach, base + reach + 1) if tot.get(i, 0.0) > 0 and i not in used]
        if not cand:
            continue
        best = max(cand, key=lambda i: (tot[i] - 0.5 * abs(i - base) * g, -abs(i - base), -i))
        used.update(range(best - 2, best + 3))
        lines.append(best)
    if not lines:
        lines = [max(tot, key=lambda i: (tot[i], -i))]
    out = []
    for idx in sorted(lines):
        segs = []
        for a, b in table[idx]:
            ia, ib = (idx * space.nx + a, idx * space.nx + b - 1) if axis == 0 else (a * space.nx + idx, (b - 1) * space.nx + idx)
            segs.append((space.xy(ia), space.xy(ib)))
        out.append(segs)
    return out


def _runs(row: np.ndarray, min_len: int) -> list[tuple[int, int]]:
    d = np.diff(np.concatenate([[0], row.astype(int), [0]]))
    starts, ends = np.nonzero(d == 1)[0], np.nonzero(d == -1)[0]
    return [(int(a), int(b)) for a, b in zip(starts, ends) if b - a >= min_len]


def _room_pattern(space: Space, k: int, spacing: float, offset: float, flip: int) -> list[tuple[np.ndarray, np.ndarray, float, float]]:
    """Sweep segments of one room: (start, end, look yaw, height); x sweeps then y sweeps."""
    out = []
    for s_i, axis in enumerate((0, 1) if flip % 2 == 0 else (1, 0)):
        lines = _sweep_runs(space, k, axis, spacing, offset)
        if (flip // 2) % 2:
            lines = lines[::-1]
        z = M_HEIGHTS[axis]
        reverse_first = (flip // 4) % 2 == 1
        for j, segs in enumerate(lines):
            forward = (j % 2 == 0) != reverse_first
            segs = segs if forward else [(b, a) for a, b in segs[::-1]]
            # look across the sweep, alternating sides line by line; the first line looks into the room
            first_look = +1 if ((flip // 2) % 2 == 0) else -1
            side = first_look if j % 2 == 0 else -first_look
            look = (math.pi / 2 if side > 0 else -math.pi / 2) if axis == 0 else (0.0 if side > 0 else math.pi)
            for a, b in segs:
                out.append((a, b, look, z))
    return out


def plan_mapping_path(layout: Layout, frames: int = DEFAULTS.mapping_frames, seed: int = DEFAULTS.seed,
                      fps: float = DEFAULTS.fps, speed: float = DEFAULTS.speed, clearance: float = DEFAULTS.clearance,
                      obstacles: str = DEFAULTS.obstacles, name: str = "mapping") -> CameraPath:
    """Cross-hatch tour of one layout: lawnmower sweeps along x and y in every room, rooms chained through doors."""
    from scipy import ndimage

    check_args(frames, fps, speed, clearance)
    zlo = min(M_HEIGHTS) - M_HEIGHT_VAR
    zhi = max(M_HEIGHTS) + M_HEIGHT_VAR
    space = Space([layout], clearance, zlo, zhi, obstacles)
    require_rooms(space, "mapping path")
    step = speed / fps
    need = (frames - 1) * step
    max_dim = max(float((r.outline().max(axis=0) - r.outline().min(axis=0)).max()) for r in space.stage.rooms)

    def one_pass(sp, offset=0.0, k=0, start=None):
        return _mapping_pass(space, sp, offset, np.random.default_rng([seed, 11, k]), start=start)
    spacing = M_SPACING
    P, attrs = one_pass(spacing)
    if arc_length(P)[-1] > need:  # too long: sparser sweeps (never fewer rooms)
        lo, hi = spacing, 2.0 * max_dim
        P_hi, a_hi = one_pass(hi)
        L = arc_length(P_hi)[-1]
        if L > need:
            raise UserError(f"mapping path: {frames} frames at {speed:g} m/s ({need:.1f} m) cannot cover every room of "
                            f"'{layout.name}' even with one sweep line per direction ({L:.1f} m); use at least "
                            f"{int(math.ceil(L / step)) + 1} frames or a higher speed")
        for _ in range(7):
            mid = math.sqrt(lo * hi)
            P_mid, a_mid = one_pass(mid)
            if arc_length(P_mid)[-1] <= need:
                hi, P_hi, a_hi = mid, P_mid, a_mid
            else:
                lo = mid
        spacing, P, attrs = hi, P_hi, a_hi
    passes = 1
    while arc_length(P)[-1] < need and passes < 8:  # fill with offset passes, cut to length
        P2, a2 = one_pass(spacing, 0.5 if passes % 2 else 0.25, passes, start=P[-1])
        P = np.concatenate([P, P2[1:]])
        attrs = {k: np.concatenate([attrs[k], a2[k][1:]]) for k in attrs}
        passes += 1
    xy, at = resample_track(P, attrs, frames, step)
    n = len(xy)
    t = np.arange(n) / fps
    nr = np.random.default_rng([seed, 13])
    travel = ndimage.gaussian_filter1d(travel_yaw(xy), 0.4 * fps, mode="nearest") if n > 1 else np.zeros(n)
    look = at["look"]
    sweeping = np.isfinite(look)
    raw = np.where(sweeping, look, travel) + np.where(sweeping, M_LOOK * smooth_noise(nr, t, 5.0, 11.0), 0.0)
    yaw = final_yaw(continuous_angles(raw), fps)
    zt = at["z"]
    z = ndimage.gaussian_filter1d(rate_limit(zt, 0.15 / fps), 0.5 * fps, mode="nearest") if n > 1 else zt
    z = z + M_HEIGHT_VAR * smooth_noise(nr, t, 8.0, 20.0) * 0.6 + 0.4 * BOB * np.sin(2 * math.pi * STEP_HZ * speed * t)
    pitch = M_PITCH + M_PITCH_VAR * smooth_noise(nr, t, 6.0, 15.0)
    roll = M_ROLL * smooth_noise(nr, t, 5.0, 13.0)
    poses = track_poses(xy, z, yaw, pitch, roll)
    path = CameraPath(name, poses, float(fps), {})
    path.meta = path_meta("mapping", [layout], seed, frames, fps, speed, clearance, obstacles, space, path,
                      {"sweep_spacing_m": round(spacing, 4), "passes": passes, "smoothing_sigma_m": M_SMOOTH,
                       "heights_m": list(M_HEIGHTS), "look_sweep_deg": round(math.degrees(M_LOOK), 3)})
    return path


def _mapping_pass(space: Space, spacing: float, offset: float, rng, start=None):
    """One cross-hatch tour over all rooms: dense smoothed curve + per-point look yaw / height."""
    st = space.stage
    cur = start_cell(space) if start is None else space.snap(start)
    todo = [k for k in range(len(st.rooms)) if (space.comp & (space.room == k)).any()]
    pts, looks, zs = [space.xy([cur])], [np.array([np.nan])], [np.array([M_HEIGHTS[0]])]
    marks = []
    z_now = M_HEIGHTS[0]
    while todo:
        # the room (and sweep variant) whose first segment is nearest along the floor
        D, _ = space.shortest([cur])
        best = None
        for k in todo:
            for flip in range(8):
                pat = _room_pattern(space, k, spacing, offset, flip)
                if not pat:  # nothing to sweep: walk to the room's roomiest spot
                    m = space.comp & (space.room == k)
                    i, j = np.unravel_index(int(np.argmax(np.where(m, space.dist, -1.0))), m.shape)
                    p = space.xy(i * space.nx + j)
                    pat = [(p, p, np.nan, z_now)]
                c0 = space.snap(pat[0][0])
                key = (float(D[0, c0]), k, flip)
                if best is None or key < best[0]:
                    best = (key, k, pat)
        _, k, pat = best
        todo.remove(k)
        for a, b, look, z in pat:
            ca, cb = space.snap(a), space.snap(b)
            conn = space.straight(cur, ca)
            if conn is None:
                conn = space.route(cur, ca)
            if len(conn) > 1:
                pts.append(conn[1:])
                looks.append(np.full(len(conn) - 1, np.nan))
                zs.append(np.full(len(conn) - 1, z_now))
                marks.append(sum(len(p) for p in pts) - 1)
            seg = grid_line(space.xy(ca), space.xy(cb))  # a run of walkable cells on one grid line
            if len(seg) > 1:
                pts.append(seg[1:])
                looks.append(np.full(len(seg) - 1, look))
                zs.append(np.full(len(seg) - 1, z))
                marks.append(sum(len(p) for p in pts) - 1)
            z_now = z
            cur = cb
    raw = np.concatenate(pts)
    raw, A = turn_loops(space, raw, marks[:-1], rng,
                         np.stack([np.concatenate(looks), np.concatenate(zs)], axis=1))
    look, zz = A[:, 0], A[:, 1]
    # dense resampling carrying attributes
    s = arc_length(raw)
    keep = np.concatenate([[True], np.diff(s) > 1e-9])
    raw, look, zz, s = raw[keep], look[keep], zz[keep], s[keep]
    t = np.arange(int(math.floor(s[-1] / DS)) + 1) * DS
    Q = np.stack([np.interp(t, s, raw[:, 0]), np.interp(t, s, raw[:, 1])], axis=1)
    k = np.clip(np.searchsorted(s, t), 0, len(s) - 1)
    P, _ = smooth_valid(space, Q, M_SMOOTH)
    return P, {"look": look[k], "z": zz[k]}
