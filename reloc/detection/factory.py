"""Naming, building and recording a detector (paper Sec. III-C), for reloc's commands and the experiments.

A :class:`DetectorSpec` names one of the detectors: ``oracle`` (:mod:`reloc.detection.oracle`, the
tour's rendered labels, with its corruption), ``onnx`` (:mod:`reloc.detection.onnx_yolo`, a user's
YOLO-style model) or ``learned`` (:mod:`reloc.detection.learned`, the toolkit's own model);
:func:`build_detector` builds it, :func:`detector_record` says what a run used, and
:func:`add_detector_arguments` / :func:`detector_spec_from_args` are the shared command-line options.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, field

from vrformats.errors import UserError

from ..config import DetectionConfig
from .base import Detector
from .learned import SHIPPED_MODEL, LearnedDetector, Perturbation
from .onnx_yolo import OnnxDetector
from .oracle import Corruption, OracleDetector


@dataclass
class DetectorSpec:
    """How experiments name a detector: ``oracle`` (with corruption) or ``onnx`` (model file)."""

    kind: str = "oracle"
    corruption: Corruption = field(default_factory=Corruption)
    model: str | None = None
    class_map: str | None = None
    perturbation: Perturbation = field(default_factory=Perturbation)  # the learned detector's (replicates, stability)


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
        return LearnedDetector(spec.model or SHIPPED_MODEL, vocabulary=vocabulary, min_pixels=cfg.min_mask_pixels,
                               perturbation=spec.perturbation)
    raise UserError(f"unknown detector {spec.kind!r} (expected oracle, onnx or learned)")


def detector_record(detector: Detector) -> dict:
    """What a run records of its detector (run.json), so that a degraded run can be told from a
    clean one by its files: the oracle's corruption settings and seed, the ONNX model and thresholds."""
    rec: dict = {"name": getattr(detector, "name", type(detector).__name__)}
    if isinstance(detector, OracleDetector):
        rec["corruption"] = {**asdict(detector.corruption), "active": detector.corruption.active}
        rec["min_pixels"] = detector.min_pixels
    if isinstance(detector, LearnedDetector) and detector.perturbation.active:
        rec["perturbation"] = asdict(detector.perturbation)
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
                                   "reloc/models/detector_v2_160x120.onnx)")
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
    except ValueError as e:  # named as the options the user typed
        msg = str(e)
        for name, option in (("corruption.miss_rate", "--miss-rate"), ("corruption.confusion_rate", "--confusion-rate"),
                              ("corruption.mask_px", "--mask-px"), ("corruption.spurious_per_frame", "--spurious")):
            msg = msg.replace(name, option)
        raise UserError(msg) from None
    return DetectorSpec(kind=args.detector, corruption=c, model=args.model, class_map=args.class_map)
