"""The stored global map (paper Sec. III-B): class-labelled, gravity-aligned boxes.

On disk a map is the ``videoreloc-boxes/1`` JSON that ``synth scene export-boxes`` and
``reloc map build`` write: a list of boxes (id, class, kind, center, size, yaw, movable) plus a
class table. Nothing derived is stored. At load time :class:`BoxMap` derives

* center-distance edges between nearby object boxes,
* the triangle index: non-degenerate object triples keyed by their vertex classes, with edge
  lengths, for the indexed route of hypothesis-first registration,
* the Manhattan axes: the extent-weighted circular median of the wall boxes' longest horizontal
  axes, modulo 90 degrees.

Walls, floors and ceilings never enter the center edges or the triangle index (their mapped
centers are not where a camera sees them), but they take part in surface verification and in the
orientation cues.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from itertools import permutations
from pathlib import Path

import numpy as np

from vrformats.boxes import BOXES_FORMAT, STRUCTURE_KINDS
from vrformats import fields
from vrformats.errors import SceneFormatError
from vrformats.yamlfile import read_json

from ..config import MapConfig
from ..geometry import non_degenerate_triangles

KINDS = ("object",) + STRUCTURE_KINDS


@dataclass
class TriangleSet:
    """Map triangles of one class key, every vertex order that keeps the classes sorted."""

    verts: np.ndarray  # (M, 3) map box indices, in key order
    edges: np.ndarray  # (M, 3) lengths |v0v1|, |v0v2|, |v1v2|
    movable: np.ndarray  # (M,) number of movable vertices


class BoxMap:
    """A loaded map. Arrays are indexed by map node (box) number 0..N-1."""

    def __init__(self, doc: dict, source: str = "<map>", config: MapConfig | None = None):
        self.source = str(source)
        self.config = config or MapConfig()
        boxes = _validate(doc, self.source)
        self.doc = doc
        self.layout = doc.get("layout")
        self.ids = np.array([b["id"] for b in boxes], dtype=np.int64)
        self.classes = [str(b["class"]) for b in boxes]
        self.kinds = [str(b.get("kind", "object")) for b in boxes]
        self.centers = np.array([b["center"] for b in boxes], dtype=float).reshape(-1, 3)
        self.sizes = np.array([b["size"] for b in boxes], dtype=float).reshape(-1, 3)
        self.yaws = np.array([b["yaw"] for b in boxes], dtype=float)
        self.movable = np.array([bool(b.get("movable", True)) for b in boxes])
        self.is_object = np.array([k == "object" for k in self.kinds], dtype=bool)
        self.class_set = set(self.classes)
        self.by_class: dict[str, np.ndarray] = {
            c: np.flatnonzero(np.array([x == c for x in self.classes])) for c in sorted(self.class_set)
        }
        self.object_nodes = np.flatnonzero(self.is_object)
        self._triangles: dict[tuple[str, str, str], TriangleSet] | None = None
        self._edges: np.ndarray | None = None
        self.manhattan_yaw = manhattan_yaw(self)

    # -- loading ---------------------------------------------------------------------------------

    @staticmethod
    def load(path, config: MapConfig | None = None) -> "BoxMap":
        path = Path(path)
        doc = read_json(path, missing="map file not found")
        m = BoxMap(doc, source=str(path), config=config)
        m.size_bytes = path.stat().st_size
        return m

    size_bytes: int | None = None

    def __len__(self) -> int:
        return len(self.ids)

    def __repr__(self) -> str:
        return f"BoxMap({self.source!r}, {len(self)} boxes, {int(self.is_object.sum())} objects)"

    @property
    def object_classes(self) -> set[str]:
        return {self.classes[i] for i in self.object_nodes}

    def nodes_of(self, cls: str) -> np.ndarray:
        return self.by_class.get(cls, np.empty(0, dtype=int))

    # -- derived relations -----------------------------------------------------------------------

    @property
    def edges(self) -> np.ndarray:
        """Center-distance edges (i, j) with i < j between object boxes within the triangle edge range."""
        if self._edges is None:
            self._build_relations()
        return self._edges

    @property
    def triangles(self) -> dict[tuple[str, str, str], TriangleSet]:
        if self._triangles is None:
            self._build_relations()
        return self._triangles

    def _build_relations(self) -> None:
        cfg = self.config
        obj = self.object_nodes
        C = self.centers[obj]
        D = np.linalg.norm(C[:, None] - C[None], axis=-1)
        A = (D >= cfg.triangle_edge_min_m) & (D <= cfg.triangle_edge_max_m)
        iu, ju = np.nonzero(np.triu(A, 1))
        self._edges = np.stack([obj[iu], obj[ju]], axis=1) if len(iu) else np.empty((0, 2), int)
        # triples i < j < k, all three edges in range
        tris = []
        for i, j in zip(iu, ju):
            ks = np.flatnonzero(A[i] & A[j])
            ks = ks[ks > j]
            if len(ks):
                tris.append(np.column_stack([np.full(len(ks), i), np.full(len(ks), j), ks]))
        out: dict[tuple[str, str, str], TriangleSet] = {}
        if tris:
            T = np.concatenate(tris)
            T = T[non_degenerate_triangles(C[T], cfg.triangle_min_angle_deg)]
            names = sorted({self.classes[n] for n in obj})
            code = np.array([names.index(self.classes[n]) for n in obj])
            K = len(names)
            rows, keys = [], []
            for perm in permutations(range(3)):
                Tp = T[:, perm]
                c = code[Tp]
                # classes in sorted order: distinct classes keep one vertex order, tied ones all
                keep = (c[:, 0] <= c[:, 1]) & (c[:, 1] <= c[:, 2])
                rows.append(Tp[keep])
                keys.append((c[keep, 0] * K + c[keep, 1]) * K + c[keep, 2])
            rows = np.concatenate(rows)
            keys = np.concatenate(keys)
            order = np.argsort(keys, kind="stable")
            rows, keys = rows[order], keys[order]
            uk, start = np.unique(keys, return_index=True)
            stop = np.append(start[1:], len(keys))
            mov = self.movable[obj]
            for key, a, b in zip(uk, start, stop):
                Tk = rows[a:b]
                P = C[Tk]
                e = np.stack([
                    np.linalg.norm(P[:, 0] - P[:, 1], axis=1),
                    np.linalg.norm(P[:, 0] - P[:, 2], axis=1),
                    np.linalg.norm(P[:, 1] - P[:, 2], axis=1),
                ], axis=1)
                name = (names[key // (K * K)], names[(key // K) % K], names[key % K])
                out[name] = TriangleSet(verts=obj[Tk], edges=e, movable=mov[Tk].sum(axis=1))
        self._triangles = out

    def triangle_count(self) -> int:
        """Number of distinct map triangles (each counted once, whatever its vertex orders)."""
        n = 0
        for (a, b, c), ts in self.triangles.items():
            mult = 6 if a == b == c else (2 if (a == b or b == c) else 1)
            n += len(ts.verts) // mult
        return n

    # -- box queries -----------------------------------------------------------------------------

    def box(self, j: int) -> tuple[np.ndarray, np.ndarray, float]:
        return self.centers[j], self.sizes[j], float(self.yaws[j])

    def summary(self) -> dict:
        kinds = {k: int(sum(1 for x in self.kinds if x == k)) for k in KINDS}
        return {
            "source": self.source,
            "layout": self.layout,
            "boxes": len(self),
            "kinds": kinds,
            "classes": len(self.class_set),
            "object_edges": int(len(self.edges)),
            "triangles": self.triangle_count(),
            "manhattan_yaw_deg": round(math.degrees(self.manhattan_yaw), 3),
            "size_bytes": self.size_bytes,
        }


def manhattan_yaw(m: BoxMap) -> float:
    """Extent-weighted circular median of the walls' longest horizontal axes, modulo 90 degrees.

    Returns an angle in [-45, 45) degrees, in radians; 0.0 for a map without walls.
    """
    idx = [i for i, k in enumerate(m.kinds) if k == "wall"]
    if not idx:
        return 0.0
    ang, w = [], []
    for i in idx:
        sx, sy = m.sizes[i, 0], m.sizes[i, 1]
        a = m.yaws[i] + (0.0 if sx >= sy else math.pi / 2)
        ang.append(a)
        w.append(max(sx, sy))
    return circular_median_mod(np.array(ang), np.array(w), period=math.pi / 2)


def circular_median_mod(angles: np.ndarray, weights: np.ndarray | None = None, period: float = 2 * math.pi) -> float:
    """Weighted circular median of angles modulo ``period``: the data angle minimising the
    weighted sum of wrapped absolute deviations. Returned in [-period/2, period/2)."""
    a = np.asarray(angles, float)
    w = np.ones(len(a)) if weights is None else np.asarray(weights, float)
    a = (a + period / 2) % period - period / 2
    dev = np.abs((a[:, None] - a[None, :] + period / 2) % period - period / 2)  # (cand, data)
    cost = dev @ w
    return float(a[int(np.argmin(cost))])


def circular_mad_mod(angles: np.ndarray, center: float, period: float) -> float:
    dev = np.abs((np.asarray(angles, float) - center + period / 2) % period - period / 2)
    return float(np.median(dev)) if len(dev) else math.inf


def _validate(doc, source: str) -> list[dict]:
    if not isinstance(doc, dict):
        raise SceneFormatError(source, None, "expected a JSON object")
    fmt = doc.get("format")
    if fmt != BOXES_FORMAT:
        raise SceneFormatError(source, "format", f"expected {BOXES_FORMAT!r}, got {fmt!r}")
    boxes = doc.get("boxes")
    if not isinstance(boxes, list):
        raise SceneFormatError(source, "boxes", "expected a list of boxes")
    seen = set()
    for k, b in enumerate(boxes):
        where = f"boxes[{k}]"
        if not isinstance(b, dict):
            raise SceneFormatError(source, where, "expected a mapping")
        bid = fields.integer(source, b.get("id"), f"{where}.id")
        if bid in seen:
            raise SceneFormatError(source, f"{where}.id", f"duplicate id {bid}")
        seen.add(bid)
        if not isinstance(b.get("class"), str) or not b["class"]:
            raise SceneFormatError(source, f"{where}.class", f"expected a class name, got {b.get('class')!r}")
        kind = b.get("kind", "object")
        if kind not in KINDS:
            raise SceneFormatError(source, f"{where}.kind", f"expected one of {', '.join(KINDS)}, got {kind!r}")
        for key in ("center", "size"):
            v = b.get(key)
            if (not isinstance(v, list) or len(v) != 3
                    or not all(fields.is_number(x) for x in v)):
                raise SceneFormatError(source, f"{where}.{key}", f"expected a list of 3 finite numbers, got {v!r}")
        if any(x <= 0 for x in b["size"]):
            raise SceneFormatError(source, f"{where}.size", f"sizes must be positive, got {b['size']}")
        yaw = b.get("yaw")
        if not fields.is_number(yaw):
            raise SceneFormatError(source, f"{where}.yaw", f"expected a number (radians), got {yaw!r}")
        if "movable" in b:
            fields.boolean(source, b["movable"], f"{where}.movable")
    return boxes
