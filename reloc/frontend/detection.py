"""Detection (paper Sec. III-C): class-labelled instance masks for a frame.

One interface, :class:`Detector` (with :class:`FrameData` and :class:`Detection`, in
:mod:`reloc.frontend.detector_base`), with two implementations:

* :class:`OracleDetector` reads the rendered instance and semantic images and can degrade them
  on purpose with a seeded :class:`Corruption` model (misses, label confusion among map classes,
  mask erosion/dilation, spurious detections), so experiments can ask how much detector quality
  matters;
* :class:`reloc.frontend.detection_onnx.OnnxDetector` runs a user's ONNX instance-segmentation model with
  YOLO-style segmentation outputs.

Detectors see only what a camera would give them plus, for the oracle, the rendered label
images. The relocalizer never reads ground-truth instance ids: ``Detection.track_id`` is filled
by the oracle only so that map building can stand in for a class-agnostic 3D segmentation.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, field

import cv2
import numpy as np
from scipy.ndimage import find_objects

from formats.errors import UserError

from ..config import DetectionConfig
from .detection_learned import SHIPPED_MODEL, LearnedDetector
from .detection_onnx import OnnxDetector
from .detector_base import STRUCTURE_CLASSES, Detection, Detector, FrameData

__all__ = ["STRUCTURE_CLASSES", "Corruption", "Detection", "Detector", "DetectorSpec", "FrameData", "OnnxDetector",
           "OracleDetector", "add_detector_arguments", "build_detector", "detector_record", "detector_spec_from_args"]


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
        if self.mask_px < 0 or self.spurious_per_frame < 0:
            raise ValueError("corruption.mask_px and corruption.spurious_per_frame must be >= 0")

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
        objs = sorted(c for c in self.vocabulary if c not in STRUCTURE_CLASSES)
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
                if cls not in STRUCTURE_CLASSES and self._confusable and rng.random() < c.confusion_rate:
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


@dataclass
class DetectorSpec:
    """How experiments name a detector: ``oracle`` (with corruption) or ``onnx`` (model file)."""

    kind: str = "oracle"
    corruption: Corruption = field(default_factory=Corruption)
    model: str | None = None
    class_map: str | None = None


def build_detector(spec: DetectorSpec, classes: dict[int, str], vocabulary=None,
                   config: DetectionConfig | None = None) -> Detector:
    """The detector a spec names: ``oracle`` (tour label images, with its corruption) or ``onnx``."""
    if spec.kind == "oracle":
        cfg = config or DetectionConfig()
        return OracleDetector(classes, vocabulary=vocabulary, corruption=spec.corruption,
                              min_pixels=cfg.min_mask_pixels)
    if spec.kind == "onnx":
        if not spec.model:
            raise UserError("--detector onnx needs --model FILE.onnx")
        return OnnxDetector(spec.model, class_map=spec.class_map, vocabulary=vocabulary)
    if spec.kind == "learned":
        cfg = config or DetectionConfig()
        return LearnedDetector(spec.model or SHIPPED_MODEL, vocabulary=vocabulary, min_pixels=cfg.min_mask_pixels)
    raise UserError(f"unknown detector {spec.kind!r} (expected oracle, onnx or learned)")


def detector_record(detector: Detector) -> dict:
    """What a run records of its detector (run.json), so that a degraded run can be told from a
    clean one by its files: the oracle's corruption settings and seed, the ONNX model and thresholds."""
    rec: dict = {"name": getattr(detector, "name", type(detector).__name__)}
    if isinstance(detector, OracleDetector):
        rec["corruption"] = {**asdict(detector.corruption), "active": detector.corruption.active}
        rec["min_pixels"] = detector.min_pixels
    for k in ("model_path", "score_threshold", "iou_threshold", "max_detections", "mask_threshold",
              "boundary_threshold", "min_pixels"):
        v = getattr(detector, k, None)
        if v is not None:
            rec["model" if k == "model_path" else k] = str(v) if k == "model_path" else v
    return rec


def add_detector_arguments(p) -> None:
    """The detector options shared by reloc's commands."""
    g = p.add_argument_group("detector")
    g.add_argument("--detector", choices=("oracle", "onnx", "learned"), default="oracle",
                   help="oracle: the tour's rendered labels (default); onnx: a YOLO-style segmentation model; "
                        "learned: the toolkit's own model (reloc detector train)")
    g.add_argument("--model", help="ONNX model file (with --detector onnx; with learned, default: the shipped "
                                   "models/detector_160x120.onnx)")
    g.add_argument("--class-map", help="YAML/JSON mapping model class -> toolkit class (with --detector onnx)")
    g.add_argument("--miss-rate", type=float, default=0.0, help="oracle corruption: probability of missing an instance")
    g.add_argument("--confusion-rate", type=float, default=0.0, help="oracle corruption: probability of a wrong map class")
    g.add_argument("--mask-px", type=int, default=0, help="oracle corruption: erode/dilate masks by up to N pixels")
    g.add_argument("--spurious", type=float, default=0.0, help="oracle corruption: mean invented detections per frame")
    g.add_argument("--detector-seed", type=int, default=0, help="oracle corruption seed")


def detector_spec_from_args(args) -> DetectorSpec:
    try:
        c = Corruption(miss_rate=args.miss_rate, confusion_rate=args.confusion_rate, mask_px=args.mask_px,
                       spurious_per_frame=args.spurious, seed=args.detector_seed)
    except ValueError as e:
        raise UserError(str(e)) from None
    return DetectorSpec(kind=args.detector, corruption=c, model=args.model, class_map=args.class_map)
