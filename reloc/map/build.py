"""Map construction (paper Sec. III-B): class-labelled, gravity-aligned boxes from a mapping tour.

The paper builds its map from the mapping video with a class-agnostic 3D segmentation whose
segments get open-vocabulary labels, and stores one gravity-aligned box per segment for objects,
walls, floors and ceilings. Here detector masks stand in for that pipeline (:func:`build_map`,
with the knobs of :class:`~reloc.map.settings.MapBuildSettings`):

* every ``stride``-th frame of the mapping tour is run through a detector (by default the
  :class:`~reloc.detection.oracle.OracleDetector` of the tour's classes); a detector that sees
  images (the learned one) gets the frames among them that have RGB (every
  lcm(``stride``, the tour's ``rgb_every``)-th);
* the depth-consistent pixels of each mask (valid depth; not on the far side of a depth
  discontinuity; near the mask's edge, within the depth range of the mask's interior around them;
  for objects, within a band around the mask's median depth) are back-projected with the frame's
  camera-to-world pose into world points (:mod:`reloc.map.pixels`);
* the points are accumulated per *segment* (:mod:`reloc.map.segmentation`): the oracle's
  ``track_id`` plays the class-agnostic 3D segment id; object detections without one join an
  untracked segment of the same class by voxel overlap, containment in its bounding box or
  proximity (and overlapping untracked segments are merged at the end); an untracked segment
  sharing at least ``cross_class_shared`` of its voxels with a bigger one of another class is the
  same thing under another label and joins it (class-agnostic fusion: a learned detector calls
  one sofa an armchair in some views); walls, floors and ceilings
  without track ids are pooled per class and split geometrically at the end
  (:mod:`reloc.map.structure`): walls into straight vertical runs cut at T-junctions, floors and
  ceilings into rooms separated by the walls (an untracked wall piece lower than
  ``min_wall_height_m`` is a ceiling edge or skirting a detector called wall, and is dropped);
* each segment is voxel-downsampled as it grows (per ``voxel`` cell: the point count, centroid
  and second moments), so memory is bounded by the observed surface area, not by the number of
  frames;
* a voxel claimed by several segments stays with the ones holding at least half as many points
  there as the best (per-voxel majority labelling: mask bleed onto a neighbouring surface loses);
  segments with too few voxels or seen in a single frame (spurious detections) are dropped;
* the class of a segment is the pixel-weighted majority of its detections' labels;
* one box per segment (:func:`~reloc.map.fitting.fit_box`): yaw from the rectangle whose edges the
  XY points hug (the closeness criterion of L-shape fitting; the minimum-area rectangle,
  ``cv2.minAreaRect``, refines it when the two agree within 2 degrees: the minimum area alone turns
  partial outlines, such as an object in a corner seen from one side, by 45 degrees), extents from
  the 1st/99th percentiles in the box frame extrapolated to the ends (ignoring flying pixels at
  mask edges without shrinking the box), each voxel counting with the spread of its points, z
  likewise. Surfaces thinner than the ground truth's structure (walls 0.1 m, floor and ceiling
  slabs ``vrformats.boxes.STRUCT_SLAB``) are thickened *away from the cameras that saw them*, since
  only their visible face is observed.

Boxes are canonical: size x >= size y (x along the longest horizontal axis), yaw in [-90, 90)
degrees. Ids: the track ids when the detector gives them (so
:func:`~reloc.map.scoring.box_errors` can match boxes to the ground truth by id), else objects
1.., walls 1000+k, floors 2000+k, ceilings 3000+k.

The map's text form and the ground-truth map of a layout are in :mod:`reloc.map.document`; the
``reloc map`` commands in :mod:`reloc.map.cli`.
"""

from __future__ import annotations

import math
import sys
import time
from collections import Counter
from dataclasses import asdict

import numpy as np

from vrformats.boxes import BOXES_FORMAT, FRAME_TEXT, ID_BASE
from vrformats.errors import UserError

from ..detection.base import FrameData, check_rgb_schedule, needs_labels, needs_rgb
from ..detection.oracle import OracleDetector
from .document import kind_of
from .fitting import fit_box
from .pixels import Backprojector, depth_edges, mask_pixels
from .segmentation import fuse_across_classes, associate_segment, merge_overlapping, point_moments, reduce_by_key, Segment, vote_voxels, voxel_keys
from .settings import MapBuildSettings
from .structure import structure_camera, split_rooms, split_walls


def _struct_slab() -> float:
    from vrformats.boxes import STRUCT_SLAB

    return float(STRUCT_SLAB)


def build_map(tour_dir, detector=None, stride: int | None = None, voxel: float | None = None, progress: bool = True,
              settings: MapBuildSettings | None = None, max_frames: int | None = None) -> tuple[dict, dict]:
    """Build a box map from a mapping tour: ``(videoreloc-boxes/1 document, report)``.

    ``tour_dir``: the tour's folder, or a ``vrformats.tour.Tour`` (one read through a sensor model:
    the map then sees what that camera measures). ``detector``: anything with ``detect(FrameData) -> list[Detection]`` (default: the oracle of
    the tour's classes). ``stride``/``voxel`` (default 5 frames / 0.05 m, see
    :class:`MapBuildSettings`) override ``settings``. ``max_frames``: stop after that many visited
    frames. ``progress``: a tqdm bar on stderr. Frames without depth or without detections are
    skipped and counted in the report; a tour from which nothing can be built gives an empty
    (valid) map and a ``warnings`` entry. A missing or unreadable frame file is an error naming
    the file (``FrameFileError``), as in ``reloc run``: a map must not quietly lack its views.
    """
    from tqdm import tqdm

    from vrformats.tour import Tour

    t_start = time.perf_counter()
    s = _settings(settings, stride, voxel)
    tour = tour_dir if isinstance(tour_dir, Tour) else Tour(tour_dir)  # UserError when missing or malformed
    classes = tour.class_names()
    if detector is None:
        if not classes:
            raise UserError(f"{tour.root}: no class table in objects.json; the oracle detector needs one")
        detector = OracleDetector(classes)
    labels = needs_labels(detector)
    want_rgb = not labels and tour.has_rgb()  # label images only for the oracle, RGB for the rest
    indices = [int(i) for i in tour.frame_indices[:: int(s.stride)]]
    if needs_rgb(detector):  # a detector that sees images: every stride-th frame that has RGB
        check_rgb_schedule(tour, None, detector, "mapping")
        step = math.lcm(int(s.stride), tour.rgb_every)
        indices = [int(i) for i in tour.frame_indices if int(i) % step == 0]
    if max_frames is not None:
        indices = indices[: int(max_frames)]
    acc = _Accumulator(tour.K, s)
    for fi in tqdm(indices, desc="mapping", unit="frame", disable=not progress, file=sys.stderr):
        f = tour.frame(fi, rgb=want_rgb, instance=labels, semantic=labels)  # FrameFileError names the file
        acc.add_frame(fi, f, detector)

    if s.cross_class_shared > 0:
        acc.absorb_across_classes(s.cross_class_shared)
    # voxel ownership: a voxel claimed by several segments stays with those holding at least
    # vote_ratio of the best one's points (mask bleed onto neighbouring surfaces loses)
    voxels_disowned = vote_voxels(acc.segments(), s.vote_ratio, 4 * s.min_voxels) if s.vote_ratio > 0 else 0
    movable = _movable_classes(tour)
    dropped = Counter()  # segments dropped, by kind
    pieces = _pieces(acc, s, dropped)
    boxes, assigned_ids, n_voxels = _boxes(pieces, s, movable, dropped)
    doc = _document(tour, detector, classes, boxes, assigned_ids, s)
    report = _report(tour, indices, acc.counts, pieces, dropped, boxes, n_voxels, voxels_disowned, s, t_start)
    return doc, report


def _settings(settings: MapBuildSettings | None, stride: int | None, voxel: float | None) -> MapBuildSettings:
    """``settings`` (default: :class:`MapBuildSettings`), with ``stride`` and ``voxel`` where given."""
    s = settings or MapBuildSettings()
    over = {}
    if stride is not None:
        over["stride"] = stride
    if voxel is not None:
        over["voxel"] = voxel
    if over:
        s = MapBuildSettings(**{**asdict(s), **over})
    return s


class _Accumulator:
    """The segments a build grows frame by frame: tracked ones by track id, untracked objects per
    class, pooled structure (walls, floors, ceilings without track ids) per kind; and the counts of
    frames and detections for the report."""

    def __init__(self, K: np.ndarray, s: MapBuildSettings):
        self.K = K
        self.s = s
        self.bp: Backprojector | None = None
        self.tracked: dict[int, Segment] = {}
        self.untracked: dict[str, list[Segment]] = {}
        self.pooled: dict[str, Segment] = {}
        self.counts = Counter()

    def add_frame(self, fi: int, f, detector) -> None:
        """Run the detector on frame ``fi`` (``f``: its data) and add each usable detection's
        depth-consistent pixels, back-projected and voxelised, to its segment."""
        s, counts = self.s, self.counts
        depth = f.depth
        if depth is None:
            counts["no_depth"] += 1
            return
        valid = np.isfinite(depth) & (depth > 0) & (depth <= s.depth_max_m)
        if not valid.any():
            counts["no_depth"] += 1
            return
        if self.bp is None or self.bp.shape != depth.shape:
            self.bp = Backprojector(self.K, depth.shape)
        dets = detector.detect(FrameData(fi, depth, self.K, f.rgb, f.instance, f.semantic))
        counts["frames_used"] += 1
        if not dets:
            counts["no_detections"] += 1
            return
        zc = np.where(valid, depth, 0.0).astype(float)
        good = (valid & ~depth_edges(zc, valid, s.edge_abs_m, s.edge_rel)).ravel()
        zf = zc.ravel()
        world = self.bp(zc, f.pose)
        cam = f.pose[:3, 3]
        any_used = False
        for d in dets:
            kind = kind_of(d.cls)
            idx = mask_pixels(d.mask, kind, zc, zf, valid, good, s)
            if idx is None:
                counts["detections_too_small"] += 1
                continue
            P = world[idx]
            keys = voxel_keys(P, s.voxel)
            k, sm, ct = reduce_by_key(keys, point_moments(P), np.ones(len(P)))
            counts["detections"] += 1
            any_used = True
            self.segment_of(d, kind, k, sm, ct).add(fi, d.cls, k, sm, ct, cam, len(idx))
        if not any_used:
            counts["no_detections"] += 1

    def segment_of(self, d, kind: str, keys: np.ndarray, sums: np.ndarray, counts: np.ndarray) -> Segment:
        """The segment a detection's voxels (``keys``, moment ``sums``, point ``counts``) join: its
        track's, its kind's pool (structure without a track id), or the untracked segment of its
        class it belongs to (:func:`~reloc.map.segmentation.associate_segment`, which may start one)."""
        if d.track_id is not None:
            seg = self.tracked.get(int(d.track_id))
            if seg is None:
                seg = self.tracked[int(d.track_id)] = Segment(int(d.track_id))
            return seg
        if kind != "object":
            seg = self.pooled.get(kind)
            if seg is None:
                seg = self.pooled[kind] = Segment(None)
            return seg
        return associate_segment(self.untracked.setdefault(d.cls, []), keys, sums[:, :3] / counts[:, None], self.s)

    def absorb_across_classes(self, min_shared: float) -> None:
        """Untracked object segments of different classes that hold one thing become one
        (:func:`~reloc.map.segmentation.fuse_across_classes`), filed under its majority class."""
        segs = fuse_across_classes([g for v in self.untracked.values() for g in v], min_shared)
        self.untracked = {}
        for g in segs:
            self.untracked.setdefault(g.cls, []).append(g)

    def segments(self) -> list[Segment]:
        """Every segment: tracked, untracked, pooled."""
        return (list(self.tracked.values()) + [g for segs in self.untracked.values() for g in segs]
                + list(self.pooled.values()))


def _pieces(acc: _Accumulator, s: MapBuildSettings, dropped: Counter) -> list[tuple]:
    """The point sets to fit boxes to, ``(class, voxel centroids, voxel spreads, camera, track id,
    frames)``: each tracked segment; the untracked object segments, overlapping ones merged; the
    pooled structure split into walls and rooms (a pool that gives no piece counts in ``dropped``)."""
    pieces = []
    for tid, seg in sorted(acc.tracked.items()):
        pieces.append((seg.cls, *seg.points(), seg.camera(), tid, seg.frames))
    for cls, segs in sorted(acc.untracked.items()):
        for seg in merge_overlapping(segs):
            pieces.append((seg.cls, *seg.points(), seg.camera(), None, seg.frames))
    wall_points = acc.pooled["wall"].points()[0] if "wall" in acc.pooled else None
    for kind, seg in sorted(acc.pooled.items()):
        P, V = seg.points()
        if kind == "wall":
            parts = split_walls(P, s.voxel, s.wall_line_tol_m, s.wall_gap_m, s.min_voxels)
        else:
            parts = split_rooms(P, s.min_voxels, cell=s.voxel, barrier=wall_points)
        for idx in parts:
            pieces.append((seg.cls, P[idx], V[idx], seg.camera(), None, seg.frames))
        if len(P) and not parts:
            dropped[kind] += 1
    return pieces


def _min_sizes(s: MapBuildSettings) -> dict[str, tuple]:
    """The minimum box size per kind: walls as the thinnest ground-truth wall, floor and ceiling
    slabs as the ground truth's (``vrformats.boxes.STRUCT_SLAB``)."""
    slab = _struct_slab()
    return {
        "object": (s.min_object_size_m,) * 3,
        "wall": (s.min_wall_thickness_m,) * 3,
        "floor": (s.min_object_size_m, s.min_object_size_m, slab),
        "ceiling": (s.min_object_size_m, s.min_object_size_m, slab),
    }


def _movable_classes(tour) -> dict[str, bool]:
    """Whether each class of the tour's ground truth is movable (objects.json: one value per class
    in every shipped layout, as in the class table)."""
    return {b["class"]: bool(b.get("movable", False)) for b in tour.objects().get("boxes", [])}


def _boxes(pieces: list[tuple], s: MapBuildSettings, movable_of: dict[str, bool], dropped: Counter) -> tuple[list[dict], list[int], int]:
    """One box per piece of at least ``min_voxels`` voxels seen in at least ``min_frames`` frames
    (the others count in ``dropped``), sorted by id: ``(boxes, the ids assigned to pieces without
    a track id, the voxels of the boxed pieces)``."""
    min_sizes = _min_sizes(s)
    boxes = []
    used_ids = {p[4] for p in pieces if p[4] is not None}
    next_id = dict(ID_BASE)
    assigned_ids = []
    n_voxels = 0
    for cls, P, V, camera, tid, frames in pieces:
        kind = kind_of(cls)
        if len(P) < s.min_voxels or frames < s.min_frames:
            dropped[kind] += 1
            continue
        n_voxels += len(P)
        if kind != "object" and tid is None:
            camera = structure_camera(kind, P, camera)
        center, size, yaw = fit_box(P, s.quantile, min_sizes[kind], camera, spread=V)
        if kind == "wall" and tid is None and size[2] < s.min_wall_height_m:
            dropped[kind] += 1  # a wall-labelled strip (a ceiling edge, a skirting) is no wall
            continue
        if tid is None:
            tid = next_id[kind]
            while tid in used_ids:
                tid += 1
            next_id[kind] = tid + 1
            used_ids.add(tid)
            assigned_ids.append(int(tid))
        movable = movable_of.get(cls, kind == "object")  # a class the ground truth lacks: objects move
        boxes.append({
            "id": int(tid), "class": cls, "kind": kind,
            "center": [round(float(v), 4) for v in center],
            "size": [round(max(float(v), 1e-3), 4) for v in size],
            # 5 decimals, kept inside [-pi/2, pi/2) (rounding would push +-pi/2 just outside)
            "yaw": min(max(round(float(yaw), 5), -1.57079), 1.57079),
            "movable": bool(movable),
        })
    boxes.sort(key=lambda b: b["id"])
    return boxes, assigned_ids, n_voxels


def _document(tour, detector, classes: dict, boxes: list[dict], assigned_ids: list[int],
              s: MapBuildSettings) -> dict:
    """The ``videoreloc-boxes/1`` document of the boxes, with the class ids of the classes they use
    (the tour's; 0 for a class it lacks) and a ``mapping`` note of how they were built."""
    sem = {v: k for k, v in classes.items()}
    used = sorted({b["class"] for b in boxes})
    doc = {
        "format": BOXES_FORMAT,
        "layout": tour.meta.get("layout"),
        "frame": FRAME_TEXT,
        "classes": {c: int(sem[c]) if c in sem else 0 for c in used},
        "boxes": boxes,
        "mapping": {
            "tour": str(tour.root),
            "detector": getattr(detector, "name", type(detector).__name__),
            "ids": "track" if not assigned_ids else ("mixed" if len(assigned_ids) < len(boxes) else "assigned"),
            "stride": int(s.stride),
            "voxel_m": float(s.voxel),
        },
    }
    if doc["mapping"]["ids"] == "mixed":  # which boxes are numbered here, not track ids
        doc["mapping"]["assigned_ids"] = sorted(assigned_ids)
    return doc


def _warnings(tour, indices: list[int], counts: Counter, boxes: list[dict]) -> list[str]:
    """A warning when no box was built, with what the frames lacked."""
    warnings = []
    if not boxes:
        why = []
        if counts["no_depth"]:
            why.append(f"{counts['no_depth']} frames without valid depth")
        if counts["no_detections"]:
            why.append(f"{counts['no_detections']} frames without usable detections")
        warnings.append(f"{tour.root}: no boxes built from {len(indices)} frames"
                        + (f" ({', '.join(why)})" if why else ""))
    return warnings


def _report(tour, indices: list[int], counts: Counter, pieces: list[tuple], dropped: Counter, boxes: list[dict],
            n_voxels: int, voxels_disowned: int, s: MapBuildSettings, t_start: float) -> dict:
    """The build report: frames and detections used and skipped, segments, boxes, settings, time."""
    kinds = Counter(b["kind"] for b in boxes)
    warnings = _warnings(tour, indices, counts, boxes)
    return {
        "tour": str(tour.root),
        "frames_in_tour": len(tour),
        "frames_visited": len(indices),
        "frames_used": counts["frames_used"],
        "frames_no_depth": counts["no_depth"],
        "frames_no_detections": counts["no_detections"],
        "detections": counts["detections"],
        "detections_too_small": counts["detections_too_small"],
        "segments": len(pieces),
        "segments_dropped": dict(dropped),
        "boxes": len(boxes),
        "boxes_by_kind": {k: kinds.get(k, 0) for k in ("object", "wall", "floor", "ceiling")},
        "voxels": int(n_voxels),
        "voxels_disowned": int(voxels_disowned),
        "settings": asdict(s),
        "wall_time_s": round(time.perf_counter() - t_start, 3),
        "warnings": warnings,
    }
