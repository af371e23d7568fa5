"""ONNX instance segmentation with YOLO-style outputs (Ultralytics YOLOv8 / YOLO11 ``-seg`` exports).

Accepted models: one image input ``1x3xHxW`` (float32 or float16, RGB in [0, 1]; a dynamic size
falls back to ``imgsz``, then to the model's ``imgsz`` metadata, then to 640) and two outputs,
predictions ``(1, 4 + nc + nm, N)`` or transposed ``(1, N, 4 + nc + nm)`` (box cx, cy, w, h in
input pixels, nc class scores, nm mask coefficients) and mask prototypes ``(1, nm, mh, mw)``.

Class names: a class map (a dict, or a YAML/JSON file such as ``{0: chair, 1: sofa, 2: null}``,
keyed by class index or by the model's own class name; an Ultralytics data YAML with ``names:``
also works) and/or the model's ``names`` metadata as Ultralytics writes it. With a class map,
classes it maps to null or leaves out are dropped.
"""

from __future__ import annotations

import ast
import math
import re
from pathlib import Path

import cv2
import numpy as np
import yaml

from vrformats.errors import UserError, one_line
from vrformats.fields import is_integer
from vrformats.yamlfile import read_yaml
from vrformats.color import srgb8

from .base import Detection, FrameData

PAD_VALUE = 114  # letterbox padding, out of 255 (as Ultralytics)
MAX_NMS = 30000  # candidates kept for NMS, by score


# ---------------------------------------------------------------- image preparation


def linear_to_srgb8(rgb: np.ndarray) -> np.ndarray:
    """Linear float RGB -> 8-bit sRGB (standard transfer curve, clipped to [0, 1])."""
    if rgb.dtype == np.uint8:
        return rgb
    return srgb8(np.nan_to_num(np.asarray(rgb, np.float32), nan=0.0))


def letterbox(img: np.ndarray, size: tuple[int, int]):
    """Resize ``img`` (HxWx3 uint8) to fit ``size`` = (h, w), keeping its aspect, and pad centred.

    Returns the padded image and ``(sx, sy, left, top)``: a frame point (x, y) (continuous pixel
    coordinates) lands at (x * sx + left, y * sy + top) in the model input.
    """
    H, W = img.shape[:2]
    Sh, Sw = size
    r = min(Sh / H, Sw / W)
    nw, nh = max(1, int(round(W * r))), max(1, int(round(H * r)))
    if (nw, nh) != (W, H):
        img = cv2.resize(img, (nw, nh), interpolation=cv2.INTER_LINEAR)
    dw, dh = (Sw - nw) / 2, (Sh - nh) / 2
    top, bottom = int(round(dh - 0.1)), int(round(dh + 0.1))
    left, right = int(round(dw - 0.1)), int(round(dw + 0.1))
    img = cv2.copyMakeBorder(img, top, bottom, left, right, cv2.BORDER_CONSTANT,
                             value=(PAD_VALUE, PAD_VALUE, PAD_VALUE))
    return img, (nw / W, nh / H, left, top)


# ---------------------------------------------------------------- class names


def _parse_names(text: str | None) -> dict[int, str] | None:
    """The ``names`` metadata Ultralytics writes (``"{0: 'person', 1: 'bicycle'}"``), or None."""
    if not text:
        return None
    try:
        v = ast.literal_eval(text)
    except Exception:
        try:
            v = yaml.safe_load(text)
        except yaml.YAMLError:
            return None
    if isinstance(v, (list, tuple)):
        v = dict(enumerate(v))
    if not isinstance(v, dict):
        return None
    try:
        return {int(k): str(x) for k, x in v.items()}
    except (TypeError, ValueError):
        return None


def load_class_map(source) -> tuple[dict[int | str, str | None], str]:
    """A class map from a dict/list or a YAML/JSON file; returns (map, where) for messages.

    Keys: a class index (int or digit string) or a model class name; values: a class name or null.
    """
    if isinstance(source, (dict, list)):
        return _normalize_class_map(source, "class map"), "class map"
    p = Path(source)
    if not p.is_file():
        raise UserError(f"{p}: class map not found")
    data = read_yaml(p)
    return _normalize_class_map(data, str(p)), str(p)


def _normalize_class_map(data, where: str) -> dict[int | str, str | None]:
    if isinstance(data, dict) and isinstance(data.get("names"), (dict, list)):
        data = data["names"]  # an Ultralytics data YAML
    if isinstance(data, list):
        data = dict(enumerate(data))
    if not isinstance(data, dict):
        raise UserError(f"{where}: expected a mapping of class index (or model class name) to class name, "
                        f"got {type(data).__name__}")
    if not data:
        raise UserError(f"{where}: the class map is empty")
    out: dict[int | str, str | None] = {}
    for k, v in data.items():
        if not (is_integer(k) or isinstance(k, str)):
            raise UserError(f"{where}: key {k!r}: expected a class index or a model class name")
        if isinstance(k, str):
            k = k.strip()
            if re.fullmatch(r"\d+", k):
                k = int(k)
            elif not k:
                raise UserError(f"{where}: empty key: expected a class index or a model class name")
        elif k < 0:
            raise UserError(f"{where}: key {k}: class indices start at 0")
        if v is not None and (not isinstance(v, str) or not v.strip()):
            raise UserError(f"{where}: {k}: expected a class name or null, got {v!r}")
        if k in out:
            raise UserError(f"{where}: class {k!r} is given twice")
        out[k] = v.strip() if v is not None else None
    return out


# ---------------------------------------------------------------- decoding helpers


def nms(boxes: np.ndarray, scores: np.ndarray, iou_threshold: float) -> np.ndarray:
    """Greedy NMS on xyxy boxes; indices kept, by decreasing score (suppresses IoU > threshold)."""
    boxes = boxes.astype(np.float64, copy=False)
    x1, y1, x2, y2 = boxes.T
    areas = np.clip(x2 - x1, 0, None) * np.clip(y2 - y1, 0, None)
    order = np.argsort(-scores, kind="stable")
    keep = []
    while order.size:
        i, rest = order[0], order[1:]
        keep.append(i)
        iw = np.clip(np.minimum(x2[i], x2[rest]) - np.maximum(x1[i], x1[rest]), 0, None)
        ih = np.clip(np.minimum(y2[i], y2[rest]) - np.maximum(y1[i], y1[rest]), 0, None)
        inter = iw * ih
        iou = inter / np.maximum(areas[i] + areas[rest] - inter, 1e-12)
        order = rest[iou <= iou_threshold]
    return np.asarray(keep, np.int64)


def _bilinear(m: np.ndarray, ys: np.ndarray, xs: np.ndarray) -> np.ndarray:
    """Sample ``m`` at the grid ys x xs (pixel-index coordinates), edges replicated."""
    h, w = m.shape

    def taps(c, n):
        c = np.clip(c, 0.0, n - 1.0)
        i0 = np.floor(c).astype(np.int64)
        return i0, np.minimum(i0 + 1, n - 1), (c - i0).astype(np.float32)

    y0, y1, wy = taps(ys, h)
    x0, x1, wx = taps(xs, w)
    rows = m[y0] * (1 - wy)[:, None] + m[y1] * wy[:, None]
    return rows[:, x0] * (1 - wx) + rows[:, x1] * wx


# ---------------------------------------------------------------- the detector


def open_session(path, what: str, intra_op_num_threads: int = 1, providers: list | None = None,
                 graph_optimization: bool = True):
    """A quiet onnxruntime session (CPU unless ``providers`` say otherwise; ``graph_optimization``
    false: no graph rewrites); a missing file or one onnxruntime cannot read is a one-line UserError
    naming it (``what``: how to call the file)."""
    import onnxruntime as ort

    path = Path(path)
    if not path.is_file():
        raise UserError(f"{path}: {what} not found")
    opts = ort.SessionOptions()
    opts.intra_op_num_threads = int(intra_op_num_threads)
    opts.inter_op_num_threads = 1
    opts.log_severity_level = 3
    if not graph_optimization:
        opts.graph_optimization_level = ort.GraphOptimizationLevel.ORT_DISABLE_ALL
    try:
        return ort.InferenceSession(str(path), sess_options=opts, providers=providers or ["CPUExecutionProvider"])
    except Exception as e:
        raise UserError(f"{path}: not a readable ONNX model: {one_line(e)}") from None


class OnnxDetector:
    """A :class:`reloc.detection.base.Detector` running a YOLO-style ONNX segmentation model.

    ``model``: the .onnx file. ``class_map``: see :func:`load_class_map`; without one the model's
    ``names`` metadata is used. ``vocabulary``: class names to report (others are dropped), None =
    all. Scores are class confidences; ``track_id`` stays None.
    """

    name = "onnx"
    needs_rgb = True

    def __init__(self, model, class_map=None, vocabulary=None, *, score_threshold: float = 0.25,
                 iou_threshold: float = 0.7, max_detections: int = 100, mask_threshold: float = 0.5,
                 imgsz: int | tuple[int, int] | None = None, intra_op_num_threads: int = 1,
                 providers: list | None = None):
        self.model_path = Path(model)
        self.score_threshold = float(score_threshold)
        self.iou_threshold = float(iou_threshold)
        self.max_detections = int(max_detections)
        self.mask_threshold = float(mask_threshold)
        self.vocabulary = set(vocabulary) if vocabulary is not None else None
        where = self.model_path
        self.session = open_session(where, "ONNX model", intra_op_num_threads, providers)

        # the image input
        inputs = self.session.get_inputs()
        if len(inputs) != 1:
            raise UserError(f"{where}: expected one image input, the model has {len(inputs)}")
        inp = inputs[0]
        shape = list(inp.shape or [])
        if len(shape) != 4 or (isinstance(shape[1], int) and shape[1] != 3):
            raise UserError(f"{where}: input '{inp.name}' has shape {shape}, expected 1x3xHxW")
        if inp.type not in ("tensor(float)", "tensor(float16)"):
            raise UserError(f"{where}: input '{inp.name}' is {inp.type}, expected float32 or float16")
        self._input_name = inp.name
        self._input_dtype = np.float16 if inp.type == "tensor(float16)" else np.float32
        meta = self.session.get_modelmeta().custom_metadata_map or {}
        fallback = _size_pair(imgsz) or _size_pair(_literal(meta.get("imgsz"))) or (640, 640)
        self.input_size = tuple(d if isinstance(d, int) and d > 0 else f
                                for d, f in zip(shape[2:], fallback))

        # the outputs: predictions (rank 3) and prototypes (rank 4)
        outs = self.session.get_outputs()
        ranks = [len(o.shape) if o.shape is not None else -1 for o in outs[:2]]
        if len(outs) < 2 or sorted(ranks) != [3, 4]:
            desc = ", ".join(f"{o.name} {list(o.shape) if o.shape is not None else '?'}" for o in outs)
            raise UserError(f"{where}: expected two outputs, predictions (1, 4+nc+nm, N) and mask "
                            f"prototypes (1, nm, mh, mw); the model has {desc or 'none'}")
        self._pred_name = outs[ranks.index(3)].name
        self._proto_name = outs[ranks.index(4)].name

        # class names
        self.model_names = _parse_names(meta.get("names"))
        if class_map is None:
            self.class_map, self._map_where = None, None
            if self.model_names is None:
                raise UserError(f"{where}: the model has no 'names' metadata; give a class map "
                                "(class index -> class name)")
        else:
            self.class_map, self._map_where = load_class_map(class_map)
            named = [k for k in self.class_map if isinstance(k, str)]
            if named and self.model_names is None:
                raise UserError(f"{self._map_where}: keys such as '{named[0]}' are model class names, but "
                                f"{where} has no 'names' metadata; key the map by class index")
            unknown = [k for k in named if k not in self.model_names.values()]
            if unknown:
                raise UserError(f"{self._map_where}: '{unknown[0]}' is not a class of {where.name} "
                                f"(its classes: {', '.join(list(self.model_names.values())[:20])}"
                                f"{', ...' if len(self.model_names) > 20 else ''})")
        self._tables: dict[int, list[str | None]] = {}

    # -------------------------------------------------------------- classes

    def class_names(self, nc: int) -> list[str | None]:
        """Toolkit class name per model class index (None = dropped), for a model with nc classes."""
        table = self._tables.get(nc)
        if table is None:
            table = []
            for i in range(nc):
                mname = self.model_names.get(i) if self.model_names else None
                if self.class_map is None:
                    name = mname
                elif i in self.class_map:
                    name = self.class_map[i]
                elif mname is not None and mname in self.class_map:
                    name = self.class_map[mname]
                else:
                    name = None
                if name is not None and self.vocabulary is not None and name not in self.vocabulary:
                    name = None
                table.append(name)
            self._tables[nc] = table
        return table

    # -------------------------------------------------------------- inference

    def detect(self, frame: FrameData) -> list[Detection]:
        if frame.rgb is None:
            raise UserError(f"{self.model_path}: the ONNX detector needs RGB frames; frame {frame.index} "
                            "has none (a geometry-only tour?)")
        rgb = np.asarray(frame.rgb)
        if rgb.ndim != 3 or rgb.shape[2] != 3:
            raise ValueError(f"frame {frame.index}: rgb has shape {rgb.shape}, expected (H, W, 3)")
        H, W = rgb.shape[:2]
        img, (sx, sy, left, top) = letterbox(linear_to_srgb8(rgb), self.input_size)
        x = (img.transpose(2, 0, 1)[None].astype(np.float32) / 255.0).astype(self._input_dtype)
        try:
            preds, protos = self.session.run([self._pred_name, self._proto_name], {self._input_name: x})
        except Exception as e:
            raise UserError(f"{self.model_path}: inference failed: {one_line(e)}") from None
        preds = np.asarray(preds, np.float32)
        protos = np.asarray(protos, np.float32)
        P = self._predictions(preds, protos)  # (4 + nc + nm, N)
        nm = protos.shape[1]
        nc = P.shape[0] - 4 - nm

        cls_scores = P[4:4 + nc]
        cls = cls_scores.argmax(0)
        score = cls_scores[cls, np.arange(cls.size)]
        names = self.class_names(nc)
        wanted = np.array([n is not None for n in names], bool)
        cand = np.nonzero((score > self.score_threshold) & wanted[cls])[0]
        if cand.size == 0:
            return []
        if cand.size > MAX_NMS:
            cand = cand[np.argsort(-score[cand], kind="stable")[:MAX_NMS]]
        cx, cy, w, h = P[0, cand], P[1, cand], P[2, cand], P[3, cand]
        boxes = np.stack([cx - w / 2, cy - h / 2, cx + w / 2, cy + h / 2], 1).astype(np.float64)
        # per-class NMS: shift each class's boxes apart
        offset = (np.abs(boxes).max() + 1.0) * 2.0 * cls[cand].astype(np.float64)
        keep = nms(boxes + offset[:, None], score[cand], self.iou_threshold)[: self.max_detections]

        sel = cand[keep]
        coeffs = P[4 + nc:, sel].T  # (k, nm)
        mh, mw = protos.shape[2:]
        logits = coeffs @ protos[0].reshape(nm, -1)
        masks = (1.0 / (1.0 + np.exp(-np.clip(logits, -50, 50)))).reshape(-1, mh, mw).astype(np.float32)

        Sh, Sw = self.input_size
        # frame pixel centre x + 0.5 -> input (x + 0.5) * sx + left -> prototype pixel index
        ax, bx = sx * mw / Sw, (0.5 * sx + left) * mw / Sw - 0.5
        ay, by = sy * mh / Sh, (0.5 * sy + top) * mh / Sh - 0.5
        out = []
        for j, b in enumerate(boxes[keep]):
            # frame pixels whose centres fall inside the box [x1, x2) x [y1, y2) (input pixels)
            x_lo = max(0, math.ceil((b[0] - left) / sx - 0.5))
            x_hi = min(W, math.ceil((b[2] - left) / sx - 0.5))
            y_lo = max(0, math.ceil((b[1] - top) / sy - 0.5))
            y_hi = min(H, math.ceil((b[3] - top) / sy - 0.5))
            if x_lo >= x_hi or y_lo >= y_hi:
                continue
            xs = np.arange(x_lo, x_hi) * ax + bx
            ys = np.arange(y_lo, y_hi) * ay + by
            roi = _bilinear(masks[j], ys, xs) > self.mask_threshold
            if not roi.any():
                continue
            mask = np.zeros((H, W), bool)
            mask[y_lo:y_hi, x_lo:x_hi] = roi
            i = sel[j]
            out.append(Detection(cls=names[cls[i]], mask=mask, score=float(score[i])))
        return out

    def _predictions(self, preds: np.ndarray, protos: np.ndarray) -> np.ndarray:
        """Predictions as (4 + nc + nm, N), whichever of the two layouts the model uses."""
        where = self.model_path
        if protos.ndim != 4 or protos.shape[0] != 1 or protos.shape[1] < 1:
            raise UserError(f"{where}: mask prototypes have shape {protos.shape}, expected (1, nm, mh, mw)")
        if preds.ndim != 3 or preds.shape[0] != 1:
            raise UserError(f"{where}: predictions have shape {preds.shape}, expected (1, 4+nc+nm, N)")
        nm = protos.shape[1]
        need = 5 + nm  # at least one class
        a, b = preds.shape[1:]
        axes = [ax for ax, n in ((1, a), (2, b)) if n >= need]
        if not axes:
            raise UserError(f"{where}: predictions have shape {preds.shape}; with {nm} mask coefficients "
                            f"(prototypes {protos.shape}) one axis must be 4 + nc + {nm} >= {need}")
        if len(axes) == 2 and self.model_names:
            match = [ax for ax in axes if preds.shape[ax] == 4 + len(self.model_names) + nm]
            if len(match) == 1:
                axes = match
        # both could be it: the anchor axis is normally the longer one (8400 at 640x640)
        ax = axes[0] if len(axes) == 1 else (1 if a <= b else 2)
        return preds[0] if ax == 1 else preds[0].T


def _literal(text):
    if not text:
        return None
    try:
        return ast.literal_eval(text)
    except Exception:
        return None


def _size_pair(v) -> tuple[int, int] | None:
    """imgsz as (h, w): an int, or a pair; None if not usable."""
    if is_integer(v) and v > 0:
        return (v, v)
    if isinstance(v, (list, tuple)) and len(v) == 2 and all(is_integer(x) and x > 0 for x in v):
        return (int(v[0]), int(v[1]))
    return None
