"""Box fitting: one gravity-aligned box (center, size, yaw) per point set (:func:`fit_box`).

Yaw from the rectangle whose edges the XY points hug (the closeness criterion of L-shape fitting;
the minimum-area rectangle, ``cv2.minAreaRect``, refines it when the two agree within 2 degrees),
extents from robust quantiles in the box frame extrapolated to the ends, thin boxes thickened away
from the side they were seen from. Canonical: size x >= size y, yaw in [-90, 90) degrees.
"""

from __future__ import annotations

import math

import numpy as np


def _quantiles(a: np.ndarray, q: float, axis=-1) -> tuple[np.ndarray, np.ndarray]:
    lo, hi = np.quantile(a, [q, 1.0 - q], axis=axis)
    return lo, hi


def _robust_extents(local: np.ndarray, q: float) -> tuple[np.ndarray, np.ndarray]:
    """Per-axis ends of a point distribution, ignoring the outer ``q`` on each side: the quantile
    function extrapolated linearly from q and 2q to 0 (and 1), clamped to the data. A uniform
    spread (a surface seen face-on) gets its true ends back instead of ends shrunk by q of the
    extent; mass piled up at an end (a face seen edge-on) stays where it is."""
    if q <= 0:
        return local.min(axis=0), local.max(axis=0)
    q1, q2, q3, q4 = np.quantile(local, [q, 2 * q, 1 - 2 * q, 1 - q], axis=0)
    lo = np.maximum(2 * q1 - q2, local.min(axis=0))
    hi = np.minimum(2 * q4 - q3, local.max(axis=0))
    return lo, hi


def _rotated(xy: np.ndarray, yaws: np.ndarray):
    c, s = np.cos(yaws)[:, None], np.sin(yaws)[:, None]
    return c * xy[:, 0] + s * xy[:, 1], -s * xy[:, 0] + c * xy[:, 1]


def _yaw_closeness(xy: np.ndarray, q: float, d0: float = 0.01) -> float:
    """Yaw of the rectangle whose edges the points hug (the closeness criterion of L-shape
    fitting, Zhang et al. 2017, made smooth): each point scores 1 / (d + d0), d its distance to the nearest
    edge of the rectangle bounding it at that yaw (robust ends, :func:`_robust_extents`). Unlike
    the minimum area it is not fooled by partial outlines (an object in a corner seen from one
    side is an L, whose smallest rectangle is turned by 45 degrees), and it has no tilt bias on
    large filled rectangles. 1 degree steps, then 0.05 degree steps around the best."""

    def score(yaws):
        u, v = _rotated(xy, yaws)
        qs = [q, 2 * q, 1 - 2 * q, 1 - q]
        u1, u2, u3, u4 = np.quantile(u, qs, axis=1)
        v1, v2, v3, v4 = np.quantile(v, qs, axis=1)
        ulo = np.maximum(2 * u1 - u2, u.min(axis=1))[:, None]
        uhi = np.minimum(2 * u4 - u3, u.max(axis=1))[:, None]
        vlo = np.maximum(2 * v1 - v2, v.min(axis=1))[:, None]
        vhi = np.minimum(2 * v4 - v3, v.max(axis=1))[:, None]
        d = np.minimum(np.minimum(np.abs(u - ulo), np.abs(uhi - u)), np.minimum(np.abs(v - vlo), np.abs(vhi - v)))
        return (1.0 / (d + d0)).sum(axis=1)

    coarse = np.radians(np.arange(0.0, 90.0, 1.0))
    best = float(coarse[int(np.argmax(score(coarse)))])
    fine = best + np.radians(np.arange(-1.0, 1.0001, 0.05))
    yaw = float(fine[int(np.argmax(score(fine)))])
    # a minimum-area rectangle that agrees within 2 degrees refines it (stray points can tilt
    # the closeness of large filled rectangles by a degree)
    ma = _yaw_min_area(xy, q, start=yaw)
    dev = (ma - yaw + math.pi / 4) % (math.pi / 2) - math.pi / 4
    return yaw + dev if abs(dev) <= math.radians(2.0) else yaw


def _yaw_min_area(xy: np.ndarray, q: float, start: float | None = None) -> float:
    """Yaw of the minimum-area rectangle: first (1 degree steps, unless ``start`` is given) of the
    rectangle holding the q..1-q extents, then ``cv2.minAreaRect`` of the points inside it grown
    by a margin (the trimmed search alone tilts large rectangles by about a degree: tilting trims
    their corners)."""
    import cv2

    def areas(yaws):
        u, v = _rotated(xy, yaws)
        ulo, uhi = _quantiles(u, q, axis=1)
        vlo, vhi = _quantiles(v, q, axis=1)
        eu, ev = uhi - ulo, vhi - vlo
        # a tiny perimeter term: collinear sets pick the yaw of their thinnest extent
        return eu * ev + 1e-6 * (eu + ev)

    if start is None:
        coarse = np.radians(np.arange(0.0, 90.0, 1.0))
        yaw = float(coarse[int(np.argmin(areas(coarse)))])
    else:
        yaw = float(start)
    u, v = _rotated(xy, np.array([yaw]))
    u, v = u[0], v[0]
    (ulo, vlo), (uhi, vhi) = _quantiles(np.stack([u, v], axis=1), q, axis=0)
    mu = max(0.1, 0.05 * (uhi - ulo + vhi - vlo))
    keep = (u >= ulo - mu) & (u <= uhi + mu) & (v >= vlo - mu) & (v <= vhi + mu)
    if keep.sum() >= 3:
        (_, _), (_, _), ang = cv2.minAreaRect(xy[keep].astype(np.float32))
        yaw = math.radians(float(ang))
    return yaw


def fit_box(points: np.ndarray, quantile: float = 0.01, min_size=(0.0, 0.0, 0.0),
            camera: np.ndarray | None = None, spread: np.ndarray | None = None,
            max_search_points: int = 2000, yaw_method: str = "closeness"):
    """Gravity-aligned box (center (3), size (3), yaw) of a point set.

    yaw: first the yaw (1 degree steps) of the smallest rectangle holding the quantile..1-quantile
    extents of the XY points, then the exact minimum-area rectangle (``cv2.minAreaRect``) of the
    points inside that rectangle grown by a margin (the trimmed search alone tilts large
    rectangles by about a degree); extents: :func:`_robust_extents` in that frame. Canonical: size x >= size y, yaw in [-pi/2, pi/2). ``min_size``
    (per box axis, after canonicalisation) thickens thin boxes; with ``camera`` (a point on the
    observed side, e.g. the mean camera position) they grow away from it, keeping the observed
    face, else symmetrically. ``spread`` (N, 4): when the points are voxel centroids, the
    variances of x, y, z and the xy covariance of the raw points in each voxel; each centroid
    then stands for a uniform spread over centroid +- sqrt(3) std along each box axis (exact for
    points spread uniformly), which removes the half-voxel shrink of surfaces running through a
    box end.
    """
    P = np.asarray(points, float).reshape(-1, 3)
    if len(P) == 0:
        raise ValueError("fit_box: no points")
    xy = P[:, :2]
    if len(xy) > max_search_points:
        idx = np.random.default_rng(0).choice(len(xy), max_search_points, replace=False)
        xy_s = xy[idx]
    else:
        xy_s = xy
    xy_s = xy_s - xy_s.mean(axis=0)

    if len(xy_s) >= 3 and yaw_method == "closeness":
        yaw = _yaw_closeness(xy_s, quantile)
    elif len(xy_s) >= 3:
        yaw = _yaw_min_area(xy_s, quantile)
    else:
        yaw = 0.0
    c, s = math.cos(yaw), math.sin(yaw)
    local = np.stack([c * P[:, 0] + s * P[:, 1], -s * P[:, 0] + c * P[:, 1], P[:, 2]], axis=1)
    if spread is not None:
        V = np.asarray(spread, float).reshape(-1, 4)
        var = np.stack([c * c * V[:, 0] + 2 * c * s * V[:, 3] + s * s * V[:, 1],
                        s * s * V[:, 0] - 2 * c * s * V[:, 3] + c * c * V[:, 1], V[:, 2]], axis=1)
        half = math.sqrt(3.0) * np.sqrt(np.maximum(var, 0.0))
        # each voxel as a uniform spread over its interval, drawn at 8 stratified offsets: the
        # quantiles are then those of a continuous distribution, not of voxel rows
        off = (2.0 * np.arange(8) + 1.0) / 8.0 - 1.0
        lo, hi = _robust_extents((local[:, None, :] + off[None, :, None] * half[:, None, :]).reshape(-1, 3), quantile)
    else:
        lo, hi = _robust_extents(local, quantile)
    if hi[0] - lo[0] < hi[1] - lo[1]:  # canonical: x along the longest horizontal axis
        yaw += math.pi / 2
        lo, hi = np.array([lo[1], -hi[0], lo[2]]), np.array([hi[1], -lo[0], hi[2]])
    # wrap to [-pi/2, pi/2) (a box is symmetric under a half turn)
    k = math.floor((yaw + math.pi / 2) / math.pi)
    if k:
        yaw -= k * math.pi
        if k % 2:
            lo, hi = np.array([-hi[0], -hi[1], lo[2]]), np.array([-lo[0], -lo[1], hi[2]])
    lo, hi = lo.astype(float).copy(), hi.astype(float).copy()
    cam_local = None
    if camera is not None:
        cx, cy = math.cos(yaw), math.sin(yaw)
        cam = np.asarray(camera, float)
        cam_local = np.array([cx * cam[0] + cy * cam[1], -cy * cam[0] + cx * cam[1], cam[2]])
    for ax in range(3):
        m = float(min_size[ax])
        if hi[ax] - lo[ax] >= m:
            continue
        if cam_local is None or abs(cam_local[ax] - (lo[ax] + hi[ax]) / 2) < 1e-9:
            mid = (lo[ax] + hi[ax]) / 2
            lo[ax], hi[ax] = mid - m / 2, mid + m / 2
        elif cam_local[ax] > (lo[ax] + hi[ax]) / 2:  # seen from +: keep the + face, grow to -
            lo[ax] = hi[ax] - m
        else:
            hi[ax] = lo[ax] + m
    mid = (lo + hi) / 2
    cx, cy = math.cos(yaw), math.sin(yaw)
    center = np.array([cx * mid[0] - cy * mid[1], cy * mid[0] + cx * mid[1], mid[2]])
    return center, hi - lo, float(yaw)
