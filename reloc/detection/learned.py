"""The learned detector (``detector: learned``): instances from pixels, by the toolkit's own model.

The model (``reloc.detector``: trained on renders of apartments the experiments never use,
exported to ONNX) sees only the RGB frame, exposed as a camera would (``vrformats.tour.tonemap``:
per-frame auto exposure, 8-bit sRGB), and gives per-pixel class scores and instance-boundary
scores. Instances are then cut here, without any ground truth:

1. each pixel takes its best class (background included) and that class's probability;
2. pixels on a predicted boundary (``boundary_threshold``) or on a depth discontinuity (a
   4-neighbour whose depth differs by more than ``depth_edge_rel`` of the nearer depth plus
   ``depth_edge_abs_m``, or has none) are cut;
3. the remaining pixels of each class fall into 4-connected components; a component of at least
   ``min_pixels`` pixels is an instance, and the cut pixels of its class within ``REGROW_PX`` go
   to the nearest such component (so masks reach their borders again);
4. an instance's score is its mean class probability; ``score_threshold`` drops weak ones.

Frames without RGB give no detections: detections are computed where the camera image exists.
Errors (a missing or corrupt model, a model of another format, a model whose classes do not cover
the map's) are one-line ``UserError`` naming the file.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from vrformats.cli import MAX_WORKERS as MAX_THREADS
from vrformats.errors import UserError, one_line
from vrformats.fields import is_integer, shown
from vrformats.tour import tonemap

from .. import resources
from .base import Detection, FrameData
from .onnx_yolo import open_session

MODEL_FORMAT = "videoreloc-segnet/1"
# the model the toolkit ships (reloc/models/detector_v2_160x120.md: its data, training and metrics); the
# experiments' default detector
SHIPPED_MODEL = resources.SHIPPED_MODEL
REGROW_PX = 3.0  # cut pixels this close to an instance rejoin it (predicted boundaries are 2-4 px wide)


@dataclass(frozen=True)
class Perturbation:
    """Last-bit changes of what the learned detector computes, of the size another processor makes:
    a replicate's or a stability benchmark's way to see which results stand on a knife edge.

    ``input_jitter``: each 8-bit level of the image the model sees moves by a uniform integer in
    [-input_jitter, input_jitter] (clipped to 0..255), drawn per pixel and channel from
    ``(seed, frame index)``, so a frame gets the same jitter in every run; ``threads``:
    onnxruntime's intra-op threads (another summation order); ``graph_optimization``: false runs the
    model without onnxruntime's graph rewrites (other fused kernels). All defaults: no change."""

    input_jitter: int = 0
    seed: int = 0
    threads: int = 1
    graph_optimization: bool = True

    def __post_init__(self):
        for k in ("input_jitter", "seed"):
            v = getattr(self, k)
            if not is_integer(v) or v < 0:
                raise ValueError(f"perturbation.{k}: expected a non-negative integer, got {v!r}")
        if not is_integer(self.threads) or not 1 <= self.threads <= MAX_THREADS:
            raise ValueError(f"perturbation.threads: expected an integer from 1 to {MAX_THREADS}, got {shown(self.threads)}")
        if self.input_jitter > 255 or self.seed >= 2**32:
            raise ValueError(f"perturbation: input_jitter is at most 255 levels and seed below 2^32, got "
                             f"{shown(self.input_jitter)} and {shown(self.seed)}")
        if not isinstance(self.graph_optimization, bool):
            raise ValueError(f"perturbation.graph_optimization: expected true or false, got {self.graph_optimization!r}")

    @property
    def active(self) -> bool:
        return self != Perturbation()

    def label(self) -> str:
        """``jitter 1 (seed 2), 2 threads, no graph optimisation``; ``none``."""
        parts = []
        if self.input_jitter:
            parts.append(f"jitter {self.input_jitter} (seed {self.seed})")
        if self.threads != 1:
            parts.append(f"{self.threads} threads")
        if not self.graph_optimization:
            parts.append("no graph optimisation")
        return ", ".join(parts) or "none"

    def jitter(self, img8: np.ndarray, frame_index: int | None) -> np.ndarray:
        """``img8`` (8-bit levels as floats) with this perturbation's jitter for one frame."""
        if not self.input_jitter:
            return img8
        rng = np.random.default_rng([self.seed, 0 if frame_index is None else int(frame_index)])
        j = rng.integers(-self.input_jitter, self.input_jitter + 1, size=img8.shape)
        return np.clip(img8 + j, 0.0, 255.0)


def depth_edges(depth: np.ndarray, rel: float, abs_m: float) -> np.ndarray:
    """(H, W) bool: pixels without depth, or next to a 4-neighbour across a depth jump."""
    d = np.asarray(depth, np.float32)
    bad = ~(d > 0) | ~np.isfinite(d)
    e = bad.copy()
    for a, b, sl_a, sl_b in ((d[1:, :], d[:-1, :], (slice(1, None), slice(None)), (slice(None, -1), slice(None))),
                             (d[:, 1:], d[:, :-1], (slice(None), slice(1, None)), (slice(None), slice(None, -1)))):
        with np.errstate(invalid="ignore"):
            jump = np.abs(a - b) > rel * np.minimum(a, b) + abs_m
        e[sl_a] |= jump
        e[sl_b] |= jump
    return e


class LearnedDetector:
    """A :class:`reloc.detection.base.Detector` running the toolkit's segmentation model."""

    name = "learned"
    needs_rgb = True

    def __init__(self, model, vocabulary=None, *, min_pixels: int = 20, boundary_threshold: float = 0.5,
                 score_threshold: float = 0.3, depth_edge_rel: float = 0.04, depth_edge_abs_m: float = 0.03,
                 perturbation: Perturbation | None = None):
        self.model_path = where = Path(model)
        self.perturbation = perturbation or Perturbation()
        self.session = open_session(where, "detector model", self.perturbation.threads,
                                    graph_optimization=self.perturbation.graph_optimization)
        meta = self.session.get_modelmeta().custom_metadata_map or {}
        if meta.get("format") != MODEL_FORMAT:
            raise UserError(f"{where}: format: expected a {MODEL_FORMAT} model (reloc detector export), "
                            f"got {meta.get('format')!r}")
        try:
            self.classes = list(json.loads(meta["classes"]))
        except (KeyError, ValueError, TypeError) as e:
            raise UserError(f"{where}: classes: missing or malformed in the model's metadata ({one_line(e)})") from None
        if vocabulary is not None:
            missing = sorted(set(vocabulary) - set(self.classes))
            if missing:
                raise UserError(f"{where}: classes: the model does not know the map's classes {', '.join(missing)}")
        self.vocabulary = set(vocabulary) if vocabulary is not None else set(self.classes[1:])
        self.min_pixels = int(min_pixels)
        self.boundary_threshold = float(boundary_threshold)
        self.score_threshold = float(score_threshold)
        self.depth_edge_rel = float(depth_edge_rel)
        self.depth_edge_abs_m = float(depth_edge_abs_m)
        self._input = self.session.get_inputs()[0].name
        try:  # models before issue 28 carry neither (stride 8, any resolution)
            self.stride = int(meta.get("stride", 8))
            res = json.loads(meta["resolution"]) if "resolution" in meta else None
            self.resolution = None if res is None else (int(res[0]), int(res[1]))
        except (ValueError, TypeError, IndexError) as e:
            raise UserError(f"{where}: stride or resolution: malformed in the model's metadata ({one_line(e)})") from None

    # -- the network -------------------------------------------------------------------------------

    def predict(self, rgb_linear: np.ndarray, index: int | None = None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(class index, its probability, boundary probability), each (H, W), for a linear RGB frame
        (``index``: the frame's, which seeds a perturbation's jitter)."""
        h, w = np.asarray(rgb_linear).shape[:2]
        if self.resolution is not None and (w, h) != self.resolution:
            raise UserError(f"{self.model_path}: the model was trained on {self.resolution[0]}x{self.resolution[1]} "
                            f"frames, but this tour is {w}x{h}: render the tour at the model's size, or train a model at {w}x{h}")
        srgb, _ = tonemap(rgb_linear)
        x = self.perturbation.jitter(np.round(srgb * 255.0), index) / 255.0  # the 8-bit frame the model was trained on
        ph, pw = (-h) % self.stride, (-w) % self.stride
        x = np.pad(x, ((0, ph), (0, pw), (0, 0)), mode="edge").transpose(2, 0, 1)[None].astype(np.float32)
        sem, bnd = self.session.run(None, {self._input: x})
        logits = np.ascontiguousarray(sem[0, :, :h, :w])
        cls = logits.argmax(axis=0)
        # the winning class's softmax probability, exp(0) / sum(exp(l - max)), without the others'
        conf = 1.0 / np.exp(logits - logits.max(axis=0, keepdims=True)).sum(axis=0)
        return cls, conf, 1.0 / (1.0 + np.exp(-bnd[0, 0, :h, :w]))

    # -- instances ---------------------------------------------------------------------------------

    def detect(self, frame: FrameData) -> list[Detection]:
        if frame.rgb is None:
            return []
        return self.instances(*self.predict(frame.rgb, frame.index), frame.depth)

    def instances(self, cls: np.ndarray, conf: np.ndarray, bnd: np.ndarray, depth: np.ndarray | None) -> list[Detection]:
        """Instances from a prediction (``predict``'s three maps) and the frame's depth (steps 2-4)."""
        from scipy import ndimage

        cut = bnd > self.boundary_threshold
        if depth is not None:
            cut |= depth_edges(depth, self.depth_edge_rel, self.depth_edge_abs_m)
        out = []
        four = np.array([[0, 1, 0], [1, 1, 1], [0, 1, 0]], bool)
        for k in np.unique(cls):
            name = self.classes[int(k)]
            if k == 0 or name not in self.vocabulary:
                continue
            of_class = cls == k
            lab, n = ndimage.label(of_class & ~cut, structure=four)
            if n == 0:
                continue
            sizes = np.bincount(lab.ravel(), minlength=n + 1)
            keep = np.flatnonzero(sizes >= self.min_pixels)
            keep = keep[keep > 0]
            if not len(keep):
                continue
            kept = np.isin(lab, keep)
            lab = np.where(kept, lab, 0)
            # the class's cut pixels near an instance (a boundary's width) go back to the nearest one;
            # pieces too small to keep stay out
            dist, (iy, ix) = ndimage.distance_transform_edt(lab == 0, return_indices=True)
            full = np.where(of_class & ((lab > 0) | (cut & (dist <= REGROW_PX))), lab[iy, ix], 0)
            for j in keep:
                m = full == j
                score = float(conf[m].mean())
                if score >= self.score_threshold and m.sum() >= self.min_pixels:
                    out.append(Detection(cls=name, mask=m, score=score))
        out.sort(key=lambda d: -d.score)
        return out
