"""Camera conventions: intrinsics, poses, TUM trajectories. One place; never re-derive them.

- Camera axes are **OpenCV** in every file and API: x right, y down, z forward.
- A pose is camera-to-world ``T_world_cam`` (4x4): ``p_world = T[:3, :3] @ p_cam + T[:3, 3]``.
- Pixel (u, v) has its centre at integer coordinates (u = column, v = row); the principal point
  is the image centre, ``cx = (width - 1) / 2``, ``cy = (height - 1) / 2``; square pixels, fx = fy.
- Depth is planar: the camera-frame z of the surface point, in metres (0 = no surface).
- Text trajectories are TUM: ``t tx ty tz qx qy qz qw`` per line, ``t = frame / fps``.
- Quaternions in code are ``(w, x, y, z)`` (``quat_to_matrix``, ``matrix_to_quat``: w >= 0).

Blender's camera looks down its -Z with +Y up; ``blender_from_opencv`` converts a pose once, for
the bpy camera code.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from .atomic import write_text_atomic
from .errors import SceneFormatError

DEFAULT_WIDTH, DEFAULT_HEIGHT = 640, 480
DEFAULT_HFOV_DEG = 75.0  # horizontal field of view of the default camera
DEFAULT_FPS = 30.0

# OpenCV camera axes expressed in Blender camera axes: x same, y and z flipped
CV_TO_BLENDER_CAM = np.diag([1.0, -1.0, -1.0])


@dataclass(frozen=True)
class Intrinsics:
    width: int
    height: int
    fx: float
    fy: float
    cx: float
    cy: float

    @property
    def K(self) -> np.ndarray:
        return np.array([[self.fx, 0.0, self.cx], [0.0, self.fy, self.cy], [0.0, 0.0, 1.0]])

    @property
    def hfov(self) -> float:
        """Horizontal field of view (radians) spanned by the image's outer pixel edges."""
        return 2.0 * math.atan(self.width / (2.0 * self.fx))

    @staticmethod
    def from_fov(width: int, height: int, hfov_deg: float = DEFAULT_HFOV_DEG) -> "Intrinsics":
        f = width / (2.0 * math.tan(math.radians(hfov_deg) / 2.0))
        return Intrinsics(int(width), int(height), f, f, (width - 1) / 2.0, (height - 1) / 2.0)

    def scaled(self, width: int, height: int) -> "Intrinsics":
        """The same camera at another resolution (same field of view)."""
        s = width / self.width
        return Intrinsics(width, height, self.fx * s, self.fy * s, (width - 1) / 2.0, (height - 1) / 2.0)

    def to_dict(self) -> dict:
        return {
            "width": self.width,
            "height": self.height,
            "K": self.K.tolist(),
            "fx": self.fx,
            "fy": self.fy,
            "cx": self.cx,
            "cy": self.cy,
        }

    @staticmethod
    def from_dict(d: dict, source: str = "<camera>") -> "Intrinsics":
        try:
            return Intrinsics(int(d["width"]), int(d["height"]), float(d["fx"]), float(d["fy"]), float(d["cx"]), float(d["cy"]))
        except (KeyError, TypeError, ValueError) as e:
            raise SceneFormatError(source, None, f"camera intrinsics need width, height, fx, fy, cx, cy ({e})") from None

    def pixel_rays(self) -> np.ndarray:
        """(H, W, 3) camera-frame ray directions with z = 1 through every pixel centre.

        A surface at planar depth d along pixel (u, v) is at ``d * rays[v, u]``.
        """
        u = np.arange(self.width, dtype=np.float64)
        v = np.arange(self.height, dtype=np.float64)
        uu, vv = np.meshgrid(u, v)
        return np.stack([(uu - self.cx) / self.fx, (vv - self.cy) / self.fy, np.ones_like(uu)], axis=-1)


# quaternions are (w, x, y, z) everywhere in the toolkit's code; TUM files store x y z w


def quat_to_matrix(q) -> np.ndarray:
    """3x3 rotation matrix of a (w, x, y, z) quaternion (normalised first)."""
    w, x, y, z = np.asarray(q, dtype=float) / np.linalg.norm(q)
    return np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
            [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
            [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
        ]
    )


def matrix_to_quat(R) -> tuple[float, float, float, float]:
    """(w, x, y, z) quaternion of a 3x3 rotation matrix, with w >= 0."""
    R = np.asarray(R, dtype=float)
    tr = R[0, 0] + R[1, 1] + R[2, 2]
    if tr > 0:
        s = math.sqrt(tr + 1.0) * 2
        w, x, y, z = 0.25 * s, (R[2, 1] - R[1, 2]) / s, (R[0, 2] - R[2, 0]) / s, (R[1, 0] - R[0, 1]) / s
    elif R[0, 0] > R[1, 1] and R[0, 0] > R[2, 2]:
        s = math.sqrt(1.0 + R[0, 0] - R[1, 1] - R[2, 2]) * 2
        w, x, y, z = (R[2, 1] - R[1, 2]) / s, 0.25 * s, (R[0, 1] + R[1, 0]) / s, (R[0, 2] + R[2, 0]) / s
    elif R[1, 1] > R[2, 2]:
        s = math.sqrt(1.0 + R[1, 1] - R[0, 0] - R[2, 2]) * 2
        w, x, y, z = (R[0, 2] - R[2, 0]) / s, (R[0, 1] + R[1, 0]) / s, 0.25 * s, (R[1, 2] + R[2, 1]) / s
    else:
        s = math.sqrt(1.0 + R[2, 2] - R[0, 0] - R[1, 1]) * 2
        w, x, y, z = (R[1, 0] - R[0, 1]) / s, (R[0, 2] + R[2, 0]) / s, (R[1, 2] + R[2, 1]) / s, 0.25 * s
    q = np.array([w, x, y, z])
    q /= np.linalg.norm(q)
    if q[0] < 0:
        q = -q
    return tuple(float(v) for v in q)


CAMERA_DOC = {
    "camera_axes": "OpenCV: x right, y down, z forward",
    "pose": "camera-to-world (T_world_cam) in poses.txt (TUM: t tx ty tz qx qy qz qw, t = frame / fps)",
    "pixel_centers": "integer coordinates: pixel (u, v) = (column, row) is centred at (u, v); cx = (width - 1) / 2",
    "depth": "planar z in metres along the camera's +z axis (not ray length), float32, 0 where no surface was hit",
    "world": "right-handed, Z up, metres",
}


def camera_document(intr: "Intrinsics", fps: float, hfov_deg: float | None = None) -> dict:
    """A tour's ``camera.json``: the intrinsics, the frame rate (and the field of view it was made
    with), and the conventions above."""
    doc = {**intr.to_dict(), "fps": fps}
    if hfov_deg is not None:
        doc["hfov_deg"] = hfov_deg
    return {**doc, **CAMERA_DOC}


def look_at(eye, target, up=(0.0, 0.0, 1.0)) -> np.ndarray:
    """Camera-to-world pose (OpenCV axes) of a camera at ``eye`` looking at ``target``."""
    eye, target, up = (np.asarray(v, dtype=float) for v in (eye, target, up))
    z = target - eye
    z /= np.linalg.norm(z)
    x = np.cross(z, up)
    if np.linalg.norm(x) < 1e-9:
        x = np.cross(z, [0.0, 1.0, 0.0])
    x /= np.linalg.norm(x)
    y = np.cross(z, x)
    T = np.eye(4)
    T[:3, :3] = np.stack([x, y, z], axis=1)
    T[:3, 3] = eye
    return T


def wrap_angle(a):
    """An angle (radians; a number or an array) wrapped to (-pi, pi]: pi stays pi, -pi becomes pi.

    The one wrap of the toolkit (yaw of objects and cameras). The half-open end is +pi because the
    layout code wraps yaws with it and saved layouts keep what it gave (an object turned by exactly
    half a turn has yaw pi, not -pi). A number gives a float, an array an array."""
    r = np.fmod(np.asarray(a, dtype=float) + np.pi, 2 * np.pi)
    r = np.where(r <= 0, r + 2 * np.pi, r) - np.pi
    return float(r) if r.ndim == 0 else r


def pose_from_ypr(position, yaw: float, pitch: float = 0.0, roll: float = 0.0) -> np.ndarray:
    """Camera-to-world pose (OpenCV axes) from a position and heading angles.

    ``yaw`` is the heading of the optical axis in the world XY plane (0 = looking along +X,
    counter-clockwise), ``pitch`` tilts it up (positive = looking up), ``roll`` turns the image
    clockwise about the optical axis. Zero pitch and roll give a level camera whose image
    y axis points down the world Z axis.
    """
    cy_, sy_ = math.cos(yaw), math.sin(yaw)
    cp, sp = math.cos(pitch), math.sin(pitch)
    fwd = np.array([cy_ * cp, sy_ * cp, sp])
    left = np.array([-sy_, cy_, 0.0])
    up = np.cross(fwd, left)
    x, y, z = -left, -up, fwd  # OpenCV: x right, y down, z forward
    R = np.stack([x, y, z], axis=1)
    if roll:
        cr, sr = math.cos(roll), math.sin(roll)
        R = R @ np.array([[cr, -sr, 0.0], [sr, cr, 0.0], [0.0, 0.0, 1.0]])
    T = np.eye(4)
    T[:3, :3] = R
    T[:3, 3] = position
    return T


def blender_from_opencv(T_world_cam: np.ndarray) -> np.ndarray:
    """Blender camera object's world matrix for an OpenCV camera-to-world pose."""
    T = np.array(T_world_cam, dtype=float, copy=True)
    T[:3, :3] = T[:3, :3] @ CV_TO_BLENDER_CAM
    return T


def write_tum(path, poses, fps: float = DEFAULT_FPS, frames=None, header: str | None = None) -> Path:
    """Write camera-to-world poses as TUM lines (atomically). ``frames`` gives each pose's frame index."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    frames = range(len(poses)) if frames is None else frames
    lines = [] if header is None else [f"# {h}" for h in header.splitlines()]
    for i, T in zip(frames, poses):
        q = matrix_to_quat(np.asarray(T)[:3, :3])  # (w, x, y, z)
        t = np.asarray(T)[:3, 3]
        lines.append(f"{i / fps:.6f} {t[0]:.6f} {t[1]:.6f} {t[2]:.6f} {q[1]:.9f} {q[2]:.9f} {q[3]:.9f} {q[0]:.9f}")
    return write_text_atomic(path, "\n".join(lines) + "\n")


# frames: how far t * fps may lie from a whole frame in a strict read (float printing of
# t = frame / fps: 6 decimals are off by < 1e-4 frames at 120 fps, 4 decimals by < 0.006)
FRAME_GRID_TOL = 0.01


def read_tum(path, fps: float = DEFAULT_FPS, strict: bool = False, lines: bool = False):
    """(frame indices, (N, 4, 4) camera-to-world poses) from a TUM file; errors name file and line.

    ``strict``: every time must lie on the frame grid (``t * fps`` within ``FRAME_GRID_TOL`` of a
    whole frame) and name its frame once. ``lines``: also return each pose's line number."""
    path = Path(path)
    if not path.exists():
        raise SceneFormatError(path, None, "trajectory file not found")
    frames, poses, line_nos = [], [], []
    first: dict[int, int] = {}
    for ln, line in enumerate(path.read_text().splitlines(), start=1):
        s = line.strip()
        if not s or s.startswith("#"):
            continue
        parts = s.split()
        if len(parts) != 8:
            raise SceneFormatError(path, f"line {ln}", f"expected 8 numbers 't tx ty tz qx qy qz qw', got {len(parts)}")
        try:
            v = [float(x) for x in parts]
        except ValueError:
            raise SceneFormatError(path, f"line {ln}", f"not a number in {s!r}") from None
        if not all(math.isfinite(x) for x in v):
            raise SceneFormatError(path, f"line {ln}", "non-finite value")
        q = np.array([v[7], v[4], v[5], v[6]])
        n = np.linalg.norm(q)
        if abs(n - 1.0) > 1e-3:
            raise SceneFormatError(path, f"line {ln}", f"quaternion is not unit length (norm {n:.4f})")
        T = np.eye(4)
        T[:3, :3] = quat_to_matrix(q)
        T[:3, 3] = v[1:4]
        k = int(round(v[0] * fps))
        if strict:
            if abs(v[0] * fps - k) > FRAME_GRID_TOL:
                raise SceneFormatError(path, f"line {ln}", f"t = {parts[0]} is not a frame time: t * fps = "
                                       f"{v[0] * fps:.4f} at {fps:g} fps (t = frame / fps)")
            if k in first:
                raise SceneFormatError(path, f"line {ln}", f"frame {k} (t = {parts[0]}) already given on line {first[k]}")
            first[k] = ln
        frames.append(k)
        poses.append(T)
        line_nos.append(ln)
    out = np.asarray(frames, dtype=int), np.asarray(poses).reshape(-1, 4, 4)
    return (*out, line_nos) if lines else out
