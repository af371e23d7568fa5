"""Small geometry helpers shared by the scene model, checks and plots.

Conventions (docs/conventions.md): world frame right-handed, Z up, metres. Rotations are
quaternions in (w, x, y, z) order. Yaw is the rotation about +Z in radians, counter-clockwise seen
from above; yaw 0 means the object's local axes coincide with the world axes.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from vrformats.camera import matrix_to_quat, quat_to_matrix  # noqa: F401


# the quaternion convention, (w, x, y, z), is the cameras' and TUM files': defined in vrformats.camera

Quat = tuple[float, float, float, float]

Y_UP_TO_Z_UP = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, -1.0], [0.0, 1.0, 0.0]])
"""Y-up files (glTF, habitat-sim / ReplicaCAD: +Y up, -Z forward) to our Z-up world: (x, y, z) -> (x, -z, y),
a proper rotation (+90 deg about X). The one copy of this matrix: every reader converts with it, once."""
Y_UP_TO_Z_UP.setflags(write=False)


def yaw_to_quat(yaw: float) -> Quat:
    """Quaternion (w, x, y, z) of a rotation by ``yaw`` radians about +Z."""
    return (math.cos(yaw / 2.0), 0.0, 0.0, math.sin(yaw / 2.0))


def quat_yaw(q) -> float:
    """Heading of a rotation: the yaw of its local +X axis projected on the ground plane."""
    R = quat_to_matrix(q)
    return math.atan2(R[1, 0], R[0, 0])


def is_yaw_only(q, tol: float = 1e-9) -> bool:
    """True when the rotation keeps +Z fixed (a pure yaw)."""
    R = quat_to_matrix(q)
    return abs(R[2, 2] - 1.0) < tol


def rot_z(yaw: float) -> np.ndarray:
    c, s = math.cos(yaw), math.sin(yaw)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


@dataclass(frozen=True)
class OrientedBox:
    """Gravity-aligned oriented box: the unit of the relocalizer's map.

    ``center`` is the box centre in world coordinates, ``size`` its extent along its own x, y, z
    axes, ``yaw`` the rotation of its x axis about +Z. ``id`` is the instance id (objects) or the
    structure id (walls, floors, ceilings), ``cls`` the class name.
    """

    id: int
    cls: str
    center: tuple[float, float, float]
    size: tuple[float, float, float]
    yaw: float
    kind: str = "object"  # object | wall | floor | ceiling

    def corners_2d(self) -> np.ndarray:
        """4x2 footprint corners, counter-clockwise."""
        hx, hy = self.size[0] / 2.0, self.size[1] / 2.0
        local = np.array([[-hx, -hy], [hx, -hy], [hx, hy], [-hx, hy]])
        c, s = math.cos(self.yaw), math.sin(self.yaw)
        R = np.array([[c, -s], [s, c]])
        return local @ R.T + np.asarray(self.center[:2])

    @property
    def zmin(self) -> float:
        return self.center[2] - self.size[2] / 2.0

    @property
    def zmax(self) -> float:
        return self.center[2] + self.size[2] / 2.0

    def contains(self, p, margin: float = 0.0) -> bool:
        """True when the point ``p`` lies inside the box (grown by ``margin`` on every side)."""
        c, sn = math.cos(self.yaw), math.sin(self.yaw)
        dx, dy = p[0] - self.center[0], p[1] - self.center[1]
        lx, ly = c * dx + sn * dy, -sn * dx + c * dy
        return (abs(lx) <= self.size[0] / 2 + margin and abs(ly) <= self.size[1] / 2 + margin
                and abs(p[2] - self.center[2]) <= self.size[2] / 2 + margin)

    def to_dict(self) -> dict:
        return {
            "id": self.id,
            "class": self.cls,
            "kind": self.kind,
            "center": [float(v) for v in self.center],
            "size": [float(v) for v in self.size],
            "yaw": float(self.yaw),
        }

    @staticmethod
    def from_dict(d: dict) -> "OrientedBox":
        return OrientedBox(
            id=int(d["id"]),
            cls=str(d["class"]),
            center=tuple(float(v) for v in d["center"]),
            size=tuple(float(v) for v in d["size"]),
            yaw=float(d["yaw"]),
            kind=str(d.get("kind", "object")),
        )


def polygons_overlap_2d(a: np.ndarray, b: np.ndarray, tol: float = 0.0) -> bool:
    """Separating-axis test for two convex polygons (Nx2, Mx2).

    Overlaps that are shallower than ``tol`` along some axis count as touching, not overlapping.
    """
    for poly in (a, b):
        n = len(poly)
        for i in range(n):
            e = poly[(i + 1) % n] - poly[i]
            axis = np.array([-e[1], e[0]])
            norm = np.linalg.norm(axis)
            if norm == 0:
                continue
            axis /= norm
            pa, pb = a @ axis, b @ axis
            if pa.max() <= pb.min() + tol or pb.max() <= pa.min() + tol:
                return False
    return True


def boxes_overlap(a: OrientedBox, b: OrientedBox, tol: float = 0.005) -> bool:
    """True when two gravity-aligned boxes interpenetrate by more than ``tol`` metres."""
    if a.zmax <= b.zmin + tol or b.zmax <= a.zmin + tol:
        return False
    return polygons_overlap_2d(a.corners_2d(), b.corners_2d(), tol)


def polygon_inside_rect(poly: np.ndarray, rect, tol: float = 1e-3) -> bool:
    """True when every vertex of ``poly`` lies inside the axis-aligned ``rect`` (xmin, ymin, xmax, ymax)."""
    xmin, ymin, xmax, ymax = rect
    return bool(
        (poly[:, 0] >= xmin - tol).all()
        and (poly[:, 0] <= xmax + tol).all()
        and (poly[:, 1] >= ymin - tol).all()
        and (poly[:, 1] <= ymax + tol).all()
    )
