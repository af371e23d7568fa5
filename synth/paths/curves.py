"""Curves: resampling, smoothing that keeps the clearance, turn loops at dead ends, and the
slow noise, rate limits and pose assembly that turn a planar curve into camera poses.
"""

from __future__ import annotations

import math

import numpy as np

from vrformats import camera

from .model import CURVE_MARGIN, DS, MARGIN, MAX_YAW_RATE
from .space import Space


def polyline_resample(P: np.ndarray, step: float) -> np.ndarray:
    P = np.asarray(P, float)
    seg = np.linalg.norm(np.diff(P, axis=0), axis=1)
    keep = np.concatenate([[True], seg > 1e-9])
    P = P[keep]
    if len(P) < 2:
        return P.copy()
    s = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(P, axis=0), axis=1))])
    n = int(math.floor(s[-1] / step)) + 1
    t = np.arange(n) * step
    return np.stack([np.interp(t, s, P[:, 0]), np.interp(t, s, P[:, 1])], axis=1)


def arc_length(P: np.ndarray) -> np.ndarray:
    return np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(P, axis=0), axis=1))])


def smooth_valid(space: Space, Q: np.ndarray, sigma_m: float) -> tuple[np.ndarray, np.ndarray]:
    """Gaussian-smooth a dense valid polyline, less where the smooth curve would come too close."""
    from scipy import ndimage

    need = space.clearance + CURVE_MARGIN
    if len(Q) < 3 or sigma_m <= 0:
        return Q.copy(), np.zeros(len(Q))
    S = ndimage.gaussian_filter1d(Q, sigma_m / DS, axis=0, mode="nearest")
    w = np.ones(len(Q))
    grow = int(0.5 * sigma_m / DS) + 1
    for _ in range(24):
        P = Q + w[:, None] * (S - Q)
        bad = space.exact(P) < need
        if not bad.any():
            return P, w
        region = ndimage.binary_dilation(bad, iterations=grow)
        w[region] *= 0.7
        w = np.minimum(w, ndimage.gaussian_filter1d(w, 0.3 * sigma_m / DS, mode="nearest"))
    P = Q + w[:, None] * (S - Q)
    bad = space.exact(P) < need
    w[bad] = 0.0
    return Q + w[:, None] * (S - Q), w


def turn_loops(space: Space, raw: np.ndarray, marks: list[int], rng, attrs: np.ndarray | None = None):
    """Replace sharp reversals at junctions (indices ``marks`` into ``raw``) by a loop.

    The loop is a circle around a point of the incoming path (the junction itself when there is
    room, else up to 1.5 m back), with a radius below that point's clearance minus what the path
    must keep, so it is valid by construction (clearance is 1-Lipschitz). The stretch of path
    inside the circle (the spike into the corner and back) is cut out. ``attrs`` (N, k) per-point
    values are carried along (loop points get NaN in column 0 and the entry values elsewhere).
    Returns (points, attrs).
    """
    need = space.clearance + MARGIN
    A = np.zeros((len(raw), 0)) if attrs is None else np.asarray(attrs, float).reshape(len(raw), -1)
    out, out_a, last = [], [], 0
    for m in sorted(set(marks)):
        if m <= last or m >= len(raw) - 1:
            continue
        W = raw[m]
        dW = np.linalg.norm(raw - W, axis=1)

        def away(idx, dist=0.5):
            k = np.nonzero(dW[idx] >= dist)[0]
            return raw[idx[k[0]]] if len(k) else raw[idx[-1]]
        u = W - away(np.arange(m - 1, last - 1, -1))
        v = away(np.arange(m + 1, len(raw))) - W
        if np.linalg.norm(u) < 1e-6 or np.linalg.norm(v) < 1e-6:
            continue
        u, v = u / np.linalg.norm(u), v / np.linalg.norm(v)
        if float(u @ v) > -0.5:  # turn below 120 degrees: smoothing handles it
            continue
        back = np.arange(m, last, -1)
        arcb = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(raw[back], axis=0), axis=1))])
        back = back[arcb <= 1.5]
        r_all = np.minimum(0.55, space.exact(raw[back]) - need - 0.01)
        good = np.nonzero(r_all >= 0.3)[0]
        if len(good):
            i = int(back[good[0]])
            r = float(r_all[good[0]])
        else:
            k = int(np.argmax(r_all))
            i, r = int(back[k]), float(r_all[k])
            if r < 0.15:
                continue
        C = raw[i]
        dC = np.linalg.norm(raw - C, axis=1)
        a = i
        while a > last and dC[a] < r:
            a -= 1
        # where the path leaves the circle again: only just after the junction (never a later visit)
        ahead = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(raw[m:], axis=0), axis=1))])
        win = m + int(np.searchsorted(ahead, 3.5))
        inside = np.nonzero(dC[m:win] < r)[0]
        if dC[a] < 0.8 * r or not len(inside):
            continue
        j = m + int(inside[0])
        exits = np.nonzero(dC[j:win] >= r)[0]
        if not len(exits):
            continue
        b = j + int(exits[0])
        sgn = 1.0 if rng.random() < 0.5 else -1.0
        t_in = math.atan2(raw[a][1] - C[1], raw[a][0] - C[0])
        t_out = math.atan2(raw[b][1] - C[1], raw[b][0] - C[0])
        delta = (sgn * (t_out - t_in)) % (2 * math.pi)
        if delta < math.pi:
            delta += 2 * math.pi
        th = t_in + sgn * np.linspace(0.0, delta, int(delta * r / DS) + 2)
        circ = C + r * np.stack([np.cos(th), np.sin(th)], axis=1)
        out.append(raw[last : a + 1])
        out_a.append(A[last : a + 1])
        out.append(circ[1:-1])
        ca = np.repeat(A[a : a + 1], len(circ) - 2, axis=0)
        if ca.shape[1]:
            ca[:, 0] = np.nan
        out_a.append(ca)
        last = b
    out.append(raw[last:])
    out_a.append(A[last:])
    return np.concatenate(out, axis=0), np.concatenate(out_a, axis=0)


def smooth_noise(rng, t: np.ndarray, pmin: float, pmax: float, n: int = 3) -> np.ndarray:
    """Slow, smooth noise in [-1, 1]: a sum of sinusoids with seeded periods and phases."""
    P = rng.uniform(pmin, pmax, n)
    ph = rng.uniform(0.0, 2 * math.pi, n)
    a = rng.uniform(0.5, 1.0, n)
    a /= a.sum()
    return np.sum(a[:, None] * np.sin(2 * math.pi * t[None, :] / P[:, None] + ph[:, None]), axis=0)


def continuous_angles(raw: np.ndarray) -> np.ndarray:
    """Angles made continuous (each within pi of the previous)."""
    out = np.empty_like(raw)
    out[0] = raw[0]
    for i in range(1, len(raw)):
        out[i] = out[i - 1] + (raw[i] - out[i - 1] + math.pi) % (2 * math.pi) - math.pi
    return out


def rate_limit(x: np.ndarray, max_step: float) -> np.ndarray:
    y = np.empty_like(x)
    y[0] = x[0]
    for i in range(1, len(x)):
        y[i] = y[i - 1] + np.clip(x[i] - y[i - 1], -max_step, max_step)
    return y


def travel_yaw(xy: np.ndarray) -> np.ndarray:
    if len(xy) < 2:
        return np.zeros(len(xy))
    d = np.diff(xy, axis=0)
    d = np.vstack([d, d[-1:]])
    return np.unwrap(np.arctan2(d[:, 1], d[:, 0]))


def resample_track(P: np.ndarray, attrs: dict[str, np.ndarray], frames: int, step: float):
    """Constant arc-length samples of a dense curve (and of per-point attributes, nearest)."""
    s = arc_length(P)
    n = min(frames, int(math.floor(s[-1] / step)) + 1)
    t = np.arange(n) * step
    xy = np.stack([np.interp(t, s, P[:, 0]), np.interp(t, s, P[:, 1])], axis=1)
    k = np.clip(np.searchsorted(s, t), 0, len(s) - 1)
    return xy, {key: v[k] for key, v in attrs.items()}


def track_poses(xy, z, yaw, pitch, roll) -> np.ndarray:
    return np.stack([camera.pose_from_ypr((float(p[0]), float(p[1]), float(h)), float(a), float(b), float(c))
                     for p, h, a, b, c in zip(xy, z, yaw, pitch, roll)]) if len(xy) else np.zeros((0, 4, 4))


def final_yaw(target: np.ndarray, fps: float) -> np.ndarray:
    """Rate-limit a continuous yaw target, then smooth it (smoothing cannot raise the rate)."""
    from scipy import ndimage

    if len(target) < 2:
        return target.copy()
    y = rate_limit(ndimage.gaussian_filter1d(target, 0.25 * fps, mode="nearest"), MAX_YAW_RATE / fps)
    return ndimage.gaussian_filter1d(y, 0.2 * fps, mode="nearest")
