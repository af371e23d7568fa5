"""The oracle detector (paper Sec. III-C): class-labelled instance masks from the rendered labels.

:class:`OracleDetector` reads the rendered instance and semantic images and can degrade them on
purpose with a seeded :class:`Corruption` model (misses, label confusion among map classes, mask
erosion/dilation, spurious detections), so experiments can ask how much detector quality matters.
It implements the :class:`~reloc.detection.base.Detector` interface, as do
:class:`reloc.detection.learned.LearnedDetector` (the toolkit's own model) and
:class:`reloc.detection.onnx_yolo.OnnxDetector` (a user's ONNX instance-segmentation model with
YOLO-style segmentation outputs); :mod:`reloc.detection.factory` builds whichever a spec names.

Detectors see only what a camera would give them plus, for the oracle, the rendered label
images. The relocalizer never reads ground-truth instance ids: ``Detection.track_id`` is filled
by the oracle only so that map building can stand in for a class-agnostic 3D segmentation.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np
from scipy.ndimage import find_objects

from vrformats.boxes import STRUCTURE_KINDS

from ..config import DetectionConfig
from .base import Detection, FrameData


MAX_MASK_PX = 64  # beyond this an eroded mask is gone and a dilated one covers the frame (and the kernel costs minutes)
MAX_SPURIOUS = 100.0  # invented detections per frame: far past any detector, and each one is a mask to make


@dataclass(frozen=True)
class Corruption:
    """Seeded degradation of oracle detections; all zero = perfect detections."""

    miss_rate: float = 0.0  # probability that a true instance is not detected
    confusion_rate: float = 0.0  # probability that a detected object gets another map class
    mask_px: int = 0  # masks eroded or dilated by a random radius in [-mask_px, mask_px]
    spurious_per_frame: float = 0.0  # Poisson mean of invented detections per frame
    seed: int = 0

    def __post_init__(self):
        for name in ("miss_rate", "confusion_rate"):
            v = getattr(self, name)
            if not 0.0 <= v <= 1.0:
                raise ValueError(f"corruption.{name}: expected a probability in [0, 1], got {v}")
        if not (isinstance(self.mask_px, int) and 0 <= self.mask_px <= MAX_MASK_PX):
            raise ValueError(f"corruption.mask_px: expected whole pixels from 0 to {MAX_MASK_PX}, got {self.mask_px!r}")
        if not 0.0 <= self.spurious_per_frame <= MAX_SPURIOUS:  # NaN fails too
            raise ValueError(f"corruption.spurious_per_frame: expected a mean from 0 to {MAX_SPURIOUS:g} detections "
                             f"per frame, got {self.spurious_per_frame!r}")

    @property
    def active(self) -> bool:
        return bool(self.miss_rate or self.confusion_rate or self.mask_px or self.spurious_per_frame)


class OracleDetector:
    """Detections from rendered instance/semantic images, optionally corrupted.

    ``classes``: semantic id -> class name (a tour's objects.json ``classes``). ``vocabulary``:
    the class names the detector is asked for (the map's classes, as SAM 3 is prompted with
    them); instances of other classes are not reported.
    """

    name = "oracle"
    needs_rgb = False
    needs_labels = True

    def __init__(self, classes: dict[int, str], vocabulary=None, corruption: Corruption | None = None,
                 min_pixels: int = DetectionConfig.min_mask_pixels):
        self.classes = {int(k): str(v) for k, v in classes.items()}
        self.vocabulary = set(vocabulary) if vocabulary is not None else set(self.classes.values())
        self.corruption = corruption or Corruption()
        self.min_pixels = int(min_pixels)
        objs = sorted(c for c in self.vocabulary if c not in STRUCTURE_KINDS)
        self._confusable = objs

    def detect(self, frame: FrameData) -> list[Detection]:
        if frame.instance is None or frame.semantic is None:
            raise ValueError(f"frame {frame.index}: the oracle detector needs the instance and semantic images")
        inst = frame.instance
        labels = inst.astype(np.int32, copy=False)
        counts = np.bincount(labels.ravel())
        ids = np.flatnonzero(counts)
        slices = find_objects(labels)  # bounding slices per id, one pass
        sem = frame.semantic
        c = self.corruption
        rng = np.random.default_rng([c.seed, int(frame.index)]) if c.active else None
        out: list[Detection] = []
        for iid in ids:
            if iid == 0 or counts[iid] < self.min_pixels:
                continue
            sl = slices[iid - 1]
            crop = labels[sl] == iid
            # the class of the instance: its most common semantic id
            s = np.bincount(sem[sl][crop].astype(np.int64)).argmax()
            cls = self.classes.get(int(s))
            if cls is None or cls not in self.vocabulary:
                continue
            mask = np.zeros(inst.shape, dtype=bool)
            mask[sl] = crop
            box = (sl[1].start, sl[0].start, sl[1].stop - 1, sl[0].stop - 1)
            if rng is not None:
                if rng.random() < c.miss_rate:
                    continue
                if cls not in STRUCTURE_KINDS and self._confusable and rng.random() < c.confusion_rate:
                    others = [x for x in self._confusable if x != cls]
                    if others:
                        cls = others[int(rng.integers(len(others)))]
                if c.mask_px:
                    mask = _morph(mask, int(rng.integers(-c.mask_px, c.mask_px + 1)))
                    if mask.sum() < self.min_pixels:
                        continue
                    box = None  # recomputed from the changed mask
            out.append(Detection(cls=cls, mask=mask, score=1.0, box2d=box, track_id=int(iid)))
        if rng is not None and c.spurious_per_frame and self._confusable:
            H, W = inst.shape
            for _ in range(int(rng.poisson(c.spurious_per_frame))):
                m = np.zeros((H, W), np.uint8)
                cx, cy = int(rng.integers(W)), int(rng.integers(H))
                ax, ay = int(rng.integers(W // 20 + 1, W // 6 + 2)), int(rng.integers(H // 20 + 1, H // 6 + 2))
                cv2.ellipse(m, (cx, cy), (ax, ay), float(rng.uniform(0, 180)), 0, 360, 1, -1)
                cls = self._confusable[int(rng.integers(len(self._confusable)))]
                if m.sum() >= self.min_pixels:
                    out.append(Detection(cls=cls, mask=m.astype(bool), score=0.5, spurious=True))
        return out


def _morph(mask: np.ndarray, r: int) -> np.ndarray:
    if r == 0:
        return mask
    k = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * abs(r) + 1, 2 * abs(r) + 1))
    m = mask.astype(np.uint8)
    m = cv2.dilate(m, k) if r > 0 else cv2.erode(m, k)
    return m.astype(bool)
