"""Frame observations (paper Sec. III-C): depth-backed, class-labelled instance points.

A detection's depth-consistent mask pixels are back-projected into the camera frame (OpenCV
axes); their centroid is the observation center and farthest-point sampling keeps up to twelve
visible-surface samples for box matching. Structure (walls, floors, ceilings) additionally gets a
plane fit: its normal feeds the gravity and Manhattan-yaw cues of Sec. III-E.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from vrformats.boxes import STRUCTURE_KINDS

from ..config import DetectionConfig, ObservationConfig
from ..detection.base import Detection
from ..geometry import farthest_point_sample


@dataclass
class Observation:
    frame: int
    cls: str
    center: np.ndarray  # (3,) camera frame
    samples: np.ndarray  # (k, 3) camera frame, k <= surface_samples
    n_points: int
    score: float = 1.0
    normal: np.ndarray | None = None  # unit plane normal (camera frame) for structure, facing the camera
    plane_rms: float | None = None

    @property
    def structure(self) -> bool:
        return self.cls in STRUCTURE_KINDS

    def transformed(self, T: np.ndarray) -> "Observation":
        """The observation in another frame (T maps camera coordinates there)."""
        R, t = T[:3, :3], T[:3, 3]
        return Observation(
            frame=self.frame, cls=self.cls, center=R @ self.center + t, samples=self.samples @ R.T + t,
            n_points=self.n_points, score=self.score,
            normal=None if self.normal is None else R @ self.normal, plane_rms=self.plane_rms,
        )


def clean_depth(depth: np.ndarray) -> np.ndarray:
    """Depth with NaN, inf and negative values replaced by 0 (= no surface)."""
    d = np.asarray(depth, dtype=np.float32)
    bad = ~np.isfinite(d) | (d < 0)
    if bad.any():
        d = d.copy()
        d[bad] = 0.0
    return d


@dataclass
class Box3D:
    """A 3D box detection (camera frame), as a Map-Det3D-style detector gives them."""

    center: np.ndarray  # (3,) camera frame
    box2d: tuple[float, float, float, float]  # its projection's bounding rectangle x0, y0, x1, y1


def box_iou(a, b) -> float:
    ix = max(0.0, min(a[2], b[2]) - max(a[0], b[0]) + 1)
    iy = max(0.0, min(a[3], b[3]) - max(a[1], b[1]) + 1)
    inter = ix * iy
    area = lambda r: max(0.0, r[2] - r[0] + 1) * max(0.0, r[3] - r[1] + 1)  # noqa: E731
    union = area(a) + area(b) - inter
    return inter / union if union > 0 else 0.0


def observe(frame_index: int, depth: np.ndarray, K: np.ndarray, detections: list[Detection],
            cfg: ObservationConfig | None = None, plane_min_points: int = 30,
            plane_max_rms_m: float = 0.03, boxes3d: list[Box3D] | None = None,
            det_cfg: DetectionConfig | None = None) -> list[Observation]:
    """Observations of one frame's detections (camera frame). Masks smaller than
    ``det_cfg.min_mask_pixels`` or without valid depth are skipped.

    With ``boxes3d`` (a 3D box detector's output for the frame), an unused box replaces the mask
    center when its projection has the highest 2D IoU (> 0.4) with the detection's box and its
    center depth is within 0.4 z + 0.5 m of the mask-center depth z (Secs. III-C, IV-A).
    """
    cfg = cfg or ObservationConfig()
    det_cfg = det_cfg or DetectionConfig()
    unused = list(range(len(boxes3d or [])))
    depth = clean_depth(depth)
    fx, fy, cx, cy = K[0, 0], K[1, 1], K[0, 2], K[1, 2]
    out: list[Observation] = []
    for det in detections:
        if np.count_nonzero(det.mask) < det_cfg.min_mask_pixels:
            continue
        if det.box2d is not None:  # search the mask's bounding box only
            x0, y0, x1, y1 = det.box2d
            ys, xs = np.nonzero(det.mask[y0:y1 + 1, x0:x1 + 1] & (depth[y0:y1 + 1, x0:x1 + 1] > 0))
            ys, xs = ys + y0, xs + x0
        else:
            ys, xs = np.nonzero(det.mask & (depth > 0))
        if len(ys) < 3:
            continue
        if len(ys) > cfg.max_points_per_mask:
            step = int(np.ceil(len(ys) / cfg.max_points_per_mask))
            ys, xs = ys[::step], xs[::step]
        z = depth[ys, xs].astype(np.float64)
        structure = det.cls in STRUCTURE_KINDS
        if not structure:
            # depth-consistent pixels: drop background seen through or beside the object
            zm = float(np.median(z))
            keep = np.abs(z - zm) <= cfg.depth_band_scale * zm + cfg.depth_band_offset_m
            ys, xs, z = ys[keep], xs[keep], z[keep]
            if len(z) < 3:
                continue
        P = np.column_stack([(xs - cx) * z / fx, (ys - cy) * z / fy, z])
        center = P.mean(axis=0)
        sub = P[:: max(1, len(P) // cfg.fps_pool)]  # farthest-point sampling over a grid subsample
        samples = sub[farthest_point_sample(sub, cfg.surface_samples)]
        normal = rms = None
        if structure and len(P) >= plane_min_points:
            normal, rms = _plane_normal(P)
            if rms > plane_max_rms_m:
                normal = None
            elif normal @ center > 0:  # face the camera (the camera is at the origin)
                normal = -normal
        if unused and not structure and det.box2d is not None:
            ious = [box_iou(det.box2d, boxes3d[b].box2d) for b in unused]
            k = int(np.argmax(ious))
            b = boxes3d[unused[k]]
            if (ious[k] > det_cfg.mask_box_iou
                    and abs(b.center[2] - center[2]) <= det_cfg.depth_check_scale * center[2] + det_cfg.depth_check_offset_m):
                center = np.asarray(b.center, float)
                unused.pop(k)
        out.append(Observation(frame=int(frame_index), cls=det.cls, center=center, samples=samples,
                               n_points=int(len(P)), score=float(det.score), normal=normal, plane_rms=rms))
    return out


def _plane_normal(P: np.ndarray) -> tuple[np.ndarray, float]:
    c = P.mean(axis=0)
    _, s, Vt = np.linalg.svd(P - c, full_matrices=False)
    n = Vt[2]
    return n / np.linalg.norm(n), float(s[2] / np.sqrt(len(P)))
