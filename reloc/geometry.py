"""Rigid-transform and box geometry for the relocalizer (numpy only).

Transforms are 4x4 homogeneous matrices; ``S`` maps clip coordinates to map coordinates.
Boxes are gravity-aligned: center (3), size (3), yaw about +Z (radians).
"""

from __future__ import annotations

import math

import numpy as np


def make_T(R: np.ndarray, t) -> np.ndarray:
    T = np.eye(4)
    T[:3, :3] = R
    T[:3, 3] = t
    return T


def inv_T(T: np.ndarray) -> np.ndarray:
    R, t = T[:3, :3], T[:3, 3]
    out = np.eye(4)
    out[:3, :3] = R.T
    out[:3, 3] = -R.T @ t
    return out


def apply(T: np.ndarray, p: np.ndarray) -> np.ndarray:
    """Transform points (..., 3)."""
    return p @ T[:3, :3].T + T[:3, 3]


def rot_angle(R: np.ndarray) -> float:
    """Angle of a rotation matrix, radians in [0, pi]."""
    c = (np.trace(R) - 1.0) / 2.0
    return float(math.acos(max(-1.0, min(1.0, c))))


def rot_z(yaw: float) -> np.ndarray:
    c, s = math.cos(yaw), math.sin(yaw)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def exp_so3(w) -> np.ndarray:
    w = np.asarray(w, dtype=float)
    th = float(np.linalg.norm(w))
    K = np.array([[0, -w[2], w[1]], [w[2], 0, -w[0]], [-w[1], w[0], 0]])
    if th < 1e-10:
        return np.eye(3) + K
    K /= th
    return np.eye(3) + math.sin(th) * K + (1 - math.cos(th)) * (K @ K)


def log_so3(R: np.ndarray) -> np.ndarray:
    th = rot_angle(R)
    if th < 1e-10:
        return np.array([R[2, 1] - R[1, 2], R[0, 2] - R[2, 0], R[1, 0] - R[0, 1]]) / 2.0
    if th > math.pi - 1e-6:
        # axis from the symmetric part
        A = (R + np.eye(3)) / 2.0
        k = int(np.argmax(np.diag(A)))
        axis = A[:, k] / math.sqrt(max(A[k, k], 1e-12))
        return axis / np.linalg.norm(axis) * th
    v = np.array([R[2, 1] - R[1, 2], R[0, 2] - R[2, 0], R[1, 0] - R[0, 1]])
    return v * (th / (2.0 * math.sin(th)))


def rotation_between(a, b) -> np.ndarray:
    """Smallest rotation taking unit direction a to unit direction b."""
    a = np.asarray(a, float) / np.linalg.norm(a)
    b = np.asarray(b, float) / np.linalg.norm(b)
    v = np.cross(a, b)
    c = float(np.dot(a, b))
    s = float(np.linalg.norm(v))
    if s < 1e-12:
        if c > 0:
            return np.eye(3)
        perp = np.cross(a, [1.0, 0.0, 0.0])
        if np.linalg.norm(perp) < 1e-6:
            perp = np.cross(a, [0.0, 1.0, 0.0])
        return exp_so3(perp / np.linalg.norm(perp) * math.pi)
    return exp_so3(v / s * math.atan2(s, c))


def rigid_fit(x: np.ndarray, y: np.ndarray, w: np.ndarray | None = None) -> np.ndarray:
    """Least-squares rigid transform (Kabsch, no scale) with R x + t ~ y; 4x4."""
    x = np.asarray(x, float)
    y = np.asarray(y, float)
    w = np.ones(len(x)) if w is None else np.asarray(w, float)
    ws = w / w.sum()
    mx, my = ws @ x, ws @ y
    H = (x - mx).T @ ((y - my) * ws[:, None])
    U, _, Vt = np.linalg.svd(H)
    d = np.sign(np.linalg.det(Vt.T @ U.T)) or 1.0
    D = np.diag([1.0, 1.0, d])
    R = Vt.T @ D @ U.T
    return make_T(R, my - R @ mx)


def rigid_fit_batch(x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """Kabsch for a batch of minimal sets: x, y (B, n, 3) -> (B, 4, 4)."""
    mx, my = x.mean(axis=1, keepdims=True), y.mean(axis=1, keepdims=True)
    H = np.einsum("bni,bnj->bij", x - mx, y - my)
    U, _, Vt = np.linalg.svd(H)
    V = np.transpose(Vt, (0, 2, 1))
    d = np.sign(np.linalg.det(V @ np.transpose(U, (0, 2, 1))))
    d[d == 0] = 1.0
    D = np.zeros((len(x), 3, 3))
    D[:, 0, 0] = 1.0
    D[:, 1, 1] = 1.0
    D[:, 2, 2] = d
    R = V @ D @ np.transpose(U, (0, 2, 1))
    t = my[:, 0] - np.einsum("bij,bj->bi", R, mx[:, 0])
    T = np.tile(np.eye(4), (len(x), 1, 1))
    T[:, :3, :3] = R
    T[:, :3, 3] = t
    return T


def pose_distance(A: np.ndarray, B: np.ndarray) -> tuple[float, float]:
    """(translation distance m, rotation angle rad) between two 4x4 poses."""
    return float(np.linalg.norm(A[:3, 3] - B[:3, 3])), rot_angle(A[:3, :3].T @ B[:3, :3])


def rotation_mean(Rs) -> np.ndarray:
    """Chordal L2 mean of rotations (projection of the arithmetic mean onto SO(3))."""
    M = np.sum(np.asarray(Rs), axis=0)
    U, _, Vt = np.linalg.svd(M)
    R = U @ Vt
    if np.linalg.det(R) < 0:
        U[:, -1] *= -1
        R = U @ Vt
    return R


def yaw_of(R: np.ndarray) -> float:
    """Heading of a rotation: the direction of its rotated x axis in the ground plane."""
    return math.atan2(R[1, 0], R[0, 0])


def wrap_angle(a):
    return (np.asarray(a) + np.pi) % (2 * np.pi) - np.pi


def level(R: np.ndarray, u_clip: np.ndarray) -> np.ndarray:
    """Rotate R about the smallest axis so that R u_clip points along +Z (tilt removed)."""
    up = R @ (u_clip / np.linalg.norm(u_clip))
    return rotation_between(up, [0.0, 0.0, 1.0]) @ R


# --------------------------------------------------------------------------------------------
# gravity-aligned boxes


def to_box_frame(points: np.ndarray, center: np.ndarray, yaw: float) -> np.ndarray:
    c, s = math.cos(yaw), math.sin(yaw)
    d = points - center
    return np.stack([c * d[..., 0] + s * d[..., 1], -s * d[..., 0] + c * d[..., 1], d[..., 2]], axis=-1)


def from_box_frame(local: np.ndarray, center: np.ndarray, yaw: float) -> np.ndarray:
    c, s = math.cos(yaw), math.sin(yaw)
    return np.stack([c * local[..., 0] - s * local[..., 1], s * local[..., 0] + c * local[..., 1], local[..., 2]], axis=-1) + center


def point_box_distance(points: np.ndarray, center, size, yaw: float) -> np.ndarray:
    """Distance of each point to a solid box (0 inside)."""
    local = to_box_frame(points, np.asarray(center, float), yaw)
    d = np.maximum(np.abs(local) - np.asarray(size, float) / 2.0, 0.0)
    return np.linalg.norm(d, axis=-1)


def closest_point_on_box(points: np.ndarray, center, size, yaw: float) -> np.ndarray:
    """Closest point of the solid box to each point (the point itself when inside)."""
    center = np.asarray(center, float)
    local = to_box_frame(points, center, yaw)
    h = np.asarray(size, float) / 2.0
    return from_box_frame(np.clip(local, -h, h), center, yaw)


def point_boxes_distance(points: np.ndarray, centers: np.ndarray, sizes: np.ndarray, yaws: np.ndarray) -> np.ndarray:
    """Distances of P points to B solid boxes: (P, B)."""
    c, s = np.cos(yaws), np.sin(yaws)
    d = points[:, None, :] - centers[None, :, :]
    lx = c * d[..., 0] + s * d[..., 1]
    ly = -s * d[..., 0] + c * d[..., 1]
    h = sizes / 2.0
    ex = np.maximum(np.abs(lx) - h[:, 0], 0.0)
    ey = np.maximum(np.abs(ly) - h[:, 1], 0.0)
    ez = np.maximum(np.abs(d[..., 2]) - h[:, 2], 0.0)
    return np.sqrt(ex * ex + ey * ey + ez * ez)


def farthest_point_sample(points: np.ndarray, k: int, start: int | None = None) -> np.ndarray:
    """Indices of up to k farthest-point samples (deterministic: starts nearest the centroid)."""
    n = len(points)
    if n <= k:
        return np.arange(n)
    if start is None:
        start = int(np.argmin(np.linalg.norm(points - points.mean(axis=0), axis=1)))
    idx = [start]
    diff = points - points[start]
    d = np.einsum("ij,ij->i", diff, diff)
    for _ in range(k - 1):
        j = int(np.argmax(d))
        idx.append(j)
        diff = points - points[j]
        d = np.minimum(d, np.einsum("ij,ij->i", diff, diff))
    return np.asarray(idx)
