"""What every detector takes and gives (paper Sec. III-C): a frame in, class-labelled masks out.

Shared by :mod:`reloc.frontend.detection` (the oracle, the factory) and :mod:`reloc.frontend.detection_onnx` (a
user's ONNX model), so that neither imports the other's module for these types.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Protocol

import numpy as np

STRUCTURE_CLASSES = ("wall", "floor", "ceiling")


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

    def detect(self, frame: FrameData) -> list[Detection]:
        ...
