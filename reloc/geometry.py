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


def level(R: np.ndarray, u_clip: np.ndarray) -> np.ndarray:
    """Rotate R about the smallest axis so that R u_clip points along +Z (tilt removed)."""
    up = R @ (u_clip / np.linalg.norm(u_clip))
    return rotation_between(up, [0.0, 0.0, 1.0]) @ R


def non_degenerate_triangles(P: np.ndarray, min_angle_deg: float) -> np.ndarray:
    """Triangles (M, 3, 3) whose smallest interior angle is at least min_angle_deg."""
    a = P[:, 1] - P[:, 0]
    b = P[:, 2] - P[:, 0]
    c = P[:, 2] - P[:, 1]
    la, lb, lc = (np.linalg.norm(v, axis=1) for v in (a, b, c))
    area2 = np.linalg.norm(np.cross(a, b), axis=1)
    # sin of each angle = 2 * area / (product of adjacent sides); smallest angle is opposite the
    # shortest side, so checking the largest product suffices
    prod = np.maximum.reduce([la * lb, la * lc, lb * lc])
    return area2 / np.maximum(prod, 1e-12) >= math.sin(math.radians(min_angle_deg))


# --------------------------------------------------------------------------------------------
# gravity-aligned boxes


def from_box_frame(local: np.ndarray, center: np.ndarray, yaw: float) -> np.ndarray:
    """Box-frame coordinates (..., 3) of a box with ``center`` and ``yaw`` -> map coordinates."""
    c, s = math.cos(yaw), math.sin(yaw)
    return np.stack([c * local[..., 0] - s * local[..., 1], s * local[..., 0] + c * local[..., 1], local[..., 2]], axis=-1) + center


class BoxSet:
    """Solid gravity-aligned boxes with half sizes and yaw cosines/sines precomputed: the one
    point-to-box implementation (surface consistency, refinement residuals, tests).

    The boxes have a batch shape N: ``(B,)`` when built, ``()`` for one box ``boxes[j]``, any
    shape for ``boxes[idx]``. Query points ``(..., *N, 3)`` are paired with the boxes element-wise
    by broadcasting; for every point against every box pass ``points[:, None, :]`` (-> ``(P, B)``).
    Distances count 0 inside a box.
    """

    __slots__ = ("centers", "half", "cos", "sin", "_nsin", "_hx", "_hy", "_hz")

    def __init__(self, centers, sizes, yaws):
        centers = np.asarray(centers, float)
        yaws = np.asarray(yaws, float)
        self._set(centers, np.asarray(sizes, float) / 2.0, np.cos(yaws), np.sin(yaws))

    def _set(self, centers, half, cos, sin) -> None:
        self.centers, self.half, self.cos, self.sin = centers, half, cos, sin
        self._nsin = -sin
        # contiguous per-axis half sizes for the hot path
        self._hx, self._hy, self._hz = (half[..., i].copy() for i in range(3))

    def __len__(self) -> int:
        return len(self.cos)

    def __getitem__(self, idx) -> "BoxSet":
        out = BoxSet.__new__(BoxSet)
        out._set(self.centers[idx], self.half[idx], self.cos[idx], self.sin[idx])
        return out

    def local(self, points: np.ndarray) -> np.ndarray:
        """Box-frame coordinates of the points (..., *N, 3)."""
        d = np.asarray(points, float) - self.centers
        return np.stack([self.cos * d[..., 0] + self.sin * d[..., 1],
                         self._nsin * d[..., 0] + self.cos * d[..., 1], d[..., 2]], axis=-1)

    def excess(self, points: np.ndarray) -> np.ndarray:
        """Signed per-axis excess over the box in its frame (..., *N, 3): the box-frame displacement
        from the closest point of the box, 0 on the axes whose slab holds the point."""
        local = self.local(points)
        return local - np.clip(local, -self.half, self.half)

    def rotation(self) -> np.ndarray:
        """Box-to-map rotations (*N, 3, 3) (box frame = map frame rotated by the yaw about +Z)."""
        R = np.zeros(np.shape(self.cos) + (3, 3))
        R[..., 0, 0] = self.cos
        R[..., 0, 1] = self._nsin
        R[..., 1, 0] = self.sin
        R[..., 1, 1] = self.cos
        R[..., 2, 2] = 1.0
        return R

    def sq_distance(self, points: np.ndarray) -> np.ndarray:
        """Squared distances of the points to their solid boxes (..., *N); the hot path of the
        surface score, so it works in place on one buffer per axis."""
        d = np.asarray(points, float) - self.centers
        dx, dy = d[..., 0], d[..., 1]
        acc = np.multiply(self.cos, dx, out=np.empty(d.shape[:-1]))  # box-frame x, then its squared excess
        acc += self.sin * dy
        np.abs(acc, out=acc)
        acc -= self._hx
        np.maximum(acc, 0.0, out=acc)
        acc *= acc
        t = np.multiply(self._nsin, dx, out=np.empty(d.shape[:-1]))  # box-frame y
        t += self.cos * dy
        np.abs(t, out=t)
        t -= self._hy
        np.maximum(t, 0.0, out=t)
        t *= t
        acc += t
        np.abs(d[..., 2], out=t)  # z
        t -= self._hz
        np.maximum(t, 0.0, out=t)
        t *= t
        acc += t
        return acc

    def distance(self, points: np.ndarray) -> np.ndarray:
        """Distances of the points to their solid boxes (..., *N)."""
        return np.sqrt(self.sq_distance(points))


def point_boxes_distance(points: np.ndarray, centers: np.ndarray, sizes: np.ndarray, yaws: np.ndarray) -> np.ndarray:
    """Distances of P points to B solid boxes: (P, B)."""
    return BoxSet(centers, sizes, yaws).distance(np.asarray(points, float)[:, None, :])


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
