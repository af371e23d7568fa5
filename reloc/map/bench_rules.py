"""What each map-building rule costs (``reloc bench map-rules TOUR --model M``).

A map built with a learned detector misses ground-truth boxes and adds extra ones. This builds the
map of one mapping tour once with the defaults (``MapBuildSettings``, the detector's own minimum
mask size) and once per relaxed rule, and prints per variant the boxes built, matched, missing and
extra against the tour's ground truth, and which classes the variant recovers. The detections
are computed once per detector setting and cached in memory, so the variants differ only in the
rule. Variants:

* ``detector min_pixels 20 -> 8``: smaller predicted instances are kept by the detector;
* ``min_mask_pixels 10 -> 3``: detections with fewer depth-consistent pixels count;
* ``min_voxels 8 -> 2``, ``min_frames 2 -> 1``: segments seen small or once are kept;
* ``cross_class_shared 0.5 -> 0``: no class-agnostic fusion of overlapping segments;
* ``vote_ratio 0.5 -> 0``: voxels claimed by several segments stay with all of them;
* ``assoc_min_overlap 0.2 -> 0.05`` and ``assoc_radius_m 0.3 -> 0.15``: looser / tighter
  association of detections to segments;
* ``all of the size rules``: min_pixels, min_mask_pixels, min_voxels and min_frames relaxed together.
"""

from __future__ import annotations

import argparse
import sys
from collections import Counter
from dataclasses import replace

VARIANTS = (
    ("defaults", {}, {}),
    ("detector min_pixels 20 -> 8", {"min_pixels": 8}, {}),
    ("min_mask_pixels 10 -> 3", {}, {"min_mask_pixels": 3}),
    ("min_voxels 8 -> 2", {}, {"min_voxels": 2}),
    ("min_frames 2 -> 1", {}, {"min_frames": 1}),
    ("cross_class_shared 0.5 -> 0 (off)", {}, {"cross_class_shared": 0.0}),
    ("vote_ratio 0.5 -> 0", {}, {"vote_ratio": 0.0}),
    ("assoc_min_overlap 0.2 -> 0.05", {}, {"assoc_min_overlap": 0.05}),
    ("assoc_radius_m 0.3 -> 0.15", {}, {"assoc_radius_m": 0.15}),
    ("all of the size rules", {"min_pixels": 8}, {"min_mask_pixels": 3, "min_voxels": 2, "min_frames": 1}),
)


class _Cached:
    """A detector whose detections per frame are computed once."""

    def __init__(self, det):
        self.det, self.cache = det, {}
        self.needs_rgb = getattr(det, "needs_rgb", False)

    def __getattr__(self, name):
        return getattr(self.det, name)

    def detect(self, frame):
        if frame.index not in self.cache:
            self.cache[frame.index] = self.det.detect(frame)
        return self.cache[frame.index]


def _missing_classes(errors: dict) -> Counter:
    return Counter(m["class"] for m in errors["unobserved"] if m["kind"] == "object")


def bench(tour_dir, model, stride: int | None = None, progress: bool = False) -> list[dict]:
    from vrformats.tour import Tour

    from ..config import DetectionConfig
    from ..detection.learned import LearnedDetector
    from .build import build_map
    from .scoring import errors_against_ground_truth
    from .settings import MapBuildSettings

    tour = Tour(tour_dir)
    dets: dict = {}
    rows = []
    base = MapBuildSettings()
    if stride:
        base = replace(base, stride=int(stride))
    for label, det_kw, map_kw in VARIANTS:
        key = tuple(sorted(det_kw.items()))
        if key not in dets:
            kw = {"min_pixels": DetectionConfig().min_mask_pixels, **det_kw}  # the experiments' detector
            dets[key] = _Cached(LearnedDetector(model, **kw))
        doc, _ = build_map(tour.root, detector=dets[key], settings=replace(base, **map_kw), progress=progress)
        e = errors_against_ground_truth(tour, doc)
        bk = e["by_kind"]
        rows.append({"variant": label, "built": len(doc["boxes"]), "gt": sum(k["gt"] for k in bk.values()),
                     "matched": sum(k["matched"] for k in bk.values()), "missing": e["gt_unobserved"],
                     "extra": e["built_unmatched"], "missing_classes": dict(_missing_classes(e))})
        if progress:
            print(f"{label}: {rows[-1]['matched']} matched, {rows[-1]['extra']} extra", file=sys.stderr)
    return rows


def format_rows(rows: list[dict]) -> str:
    base = rows[0]
    out = ["Missing object classes with the defaults: "
           + ", ".join(f"{c} {n}" for c, n in sorted(base["missing_classes"].items(), key=lambda x: (-x[1], x[0]))), "",
           "| variant | built | matched | missing | extra | matched vs defaults | extra vs defaults |",
           "|---|---|---|---|---|---|---|"]
    for r in rows:
        out.append(f"| {r['variant']} | {r['built']} | {r['matched']} / {r['gt']} | {r['missing']} | {r['extra']} | "
                   f"{r['matched'] - base['matched']:+d} | {r['extra'] - base['extra']:+d} |")
    return "\n".join(out)


def add_arguments(ap: argparse.ArgumentParser) -> None:
    """The options of ``reloc bench map-rules``."""
    ap.add_argument("tour", help="a rendered mapping tour with RGB and ground truth")
    ap.add_argument("--model", required=True, help="the learned detector's ONNX model")
    ap.add_argument("--stride", type=int, help="every N-th frame (default: MapBuildSettings')")


def run(args) -> int:
    rows = bench(args.tour, args.model, args.stride, progress=True)
    print(format_rows(rows))
    return 0
