"""What every detector takes and gives (paper Sec. III-C): a frame in, class-labelled masks out.

Shared by every detector (:mod:`reloc.detection.oracle`, :mod:`reloc.detection.learned`,
:mod:`reloc.detection.onnx_yolo`), by :mod:`reloc.detection.factory` and by the detectors' users
(map building, the front-end), so that none imports another's module for these types.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Protocol

import numpy as np


@dataclass
class FrameData:
    """What a detector and the front-end get for one frame."""

    index: int
    depth: np.ndarray  # (H, W) float32 planar metres, 0 = no surface
    K: np.ndarray  # 3x3
    rgb: np.ndarray | None = None  # (H, W, 3) float32 linear, or None for geometry-only tours
    instance: np.ndarray | None = None  # (H, W) uint32, rendered ground truth (oracle only)
    semantic: np.ndarray | None = None  # (H, W) uint32, rendered ground truth (oracle only)


@dataclass
class Detection:
    cls: str
    mask: np.ndarray  # (H, W) bool
    score: float = 1.0
    box2d: tuple[int, int, int, int] | None = None  # x0, y0, x1, y1 (inclusive), from the mask
    track_id: int | None = None  # oracle only; never used by the relocalizer
    spurious: bool = False  # oracle bookkeeping: a detection the corruption model invented

    def __post_init__(self):
        if self.box2d is None and self.mask is not None and self.mask.any():
            ys, xs = np.nonzero(self.mask)
            self.box2d = (int(xs.min()), int(ys.min()), int(xs.max()), int(ys.max()))


class Detector(Protocol):
    name: str
    needs_rgb: bool  # True: detects from the camera image, so only frames with RGB give detections
    needs_labels: bool  # True: reads the rendered instance/semantic images (the oracle)

    def detect(self, frame: FrameData) -> list[Detection]:
        ...


def needs_labels(detector) -> bool:
    """Whether a detector reads the rendered label images (the oracle, and wrappers of it that say
    so); a detector without the attribute does not."""
    return bool(getattr(detector, "needs_labels", False))


def needs_rgb(detector) -> bool:
    """Whether a detector looks at the RGB image (the learned and ONNX ones); a detector without
    the attribute does unless it reads labels."""
    return bool(getattr(detector, "needs_rgb", not needs_labels(detector)))


def check_rgb_schedule(tour, every: int | None, detector, what: str) -> None:
    """A detector that needs RGB looks at every ``every``-th frame (``what`` names that setting,
    e.g. ``observation.stride``; None: at whichever frames have RGB): the tour must have RGB there.
    One-line ``UserError`` naming the tour's meta.json and its ``rgb_every`` otherwise (a
    geometry-only tour has no RGB at all)."""
    if not needs_rgb(detector):
        return
    from vrformats.errors import UserError

    where = f"{tour.root}/meta.json"
    if not tour.has_rgb():
        raise UserError(f"{where}: lighting: a geometry-only tour has no RGB, and the {detector.name} detector "
                        f"sees only RGB frames; render the tour with a lighting")
    k = tour.rgb_every
    if every is not None and int(every) % k:
        raise UserError(f"{where}: rgb_every: RGB on every {k}th frame, but the {detector.name} detector looks at "
                        f"every {every}th ({what}); render with an rgb_every that divides {every}")
