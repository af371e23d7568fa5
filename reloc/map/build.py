"""Map construction (paper Sec. III-B): class-labelled, gravity-aligned boxes from a mapping tour.

The paper builds its map from the mapping video with a class-agnostic 3D segmentation whose
segments get open-vocabulary labels, and stores one gravity-aligned box per segment for objects,
walls, floors and ceilings. Here detector masks stand in for that pipeline:

* every ``stride``-th frame of the mapping tour is run through a detector (by default the
  :class:`~reloc.frontend.detection.OracleDetector` of the tour's classes);
* the depth-consistent pixels of each mask (valid depth; not on the far side of a depth
  discontinuity; near the mask's edge, within the depth range of the mask's interior around them;
  for objects, within a band around the mask's median depth) are back-projected with the frame's
  camera-to-world pose into world points;
* the points are accumulated per *segment*: the oracle's ``track_id`` plays the class-agnostic 3D
  segment id; object detections without one join an untracked segment of the same class by voxel
  overlap, containment in its bounding box or proximity (and overlapping untracked segments are
  merged at the end); walls, floors and ceilings without track ids are pooled per class and split
  geometrically at the end: walls into straight vertical runs cut at T-junctions, floors and
  ceilings into rooms separated by the walls;
* each segment is voxel-downsampled as it grows (per ``voxel`` cell: the point count, centroid
  and second moments), so memory is bounded by the observed surface area, not by the number of
  frames;
* a voxel claimed by several segments stays with the ones holding at least half as many points
  there as the best (per-voxel majority labelling: mask bleed onto a neighbouring surface loses);
  segments with too few voxels or seen in a single frame (spurious detections) are dropped;
* the class of a segment is the pixel-weighted majority of its detections' labels;
* one box per segment (:func:`fit_box`): yaw from the rectangle whose edges the XY points hug
  (the closeness criterion of L-shape fitting; the minimum-area rectangle, ``cv2.minAreaRect``,
  refines it when the two agree within 2 degrees: the minimum area alone turns partial outlines,
  such as an object in a corner seen from one side, by 45 degrees), extents from the 1st/99th
  percentiles in the box frame extrapolated to the ends (ignoring flying pixels at mask edges
  without shrinking the box), each voxel counting with the spread of its points, z likewise. Surfaces thinner than the ground truth's structure (walls 0.1 m, floor
  and ceiling slabs ``synth.scene.STRUCT_SLAB``) are thickened *away from the cameras that saw
  them*, since only their visible face is observed.

Boxes are canonical: size x >= size y (x along the longest horizontal axis), yaw in [-90, 90)
degrees. Ids: the track ids when the detector gives them (so :func:`box_errors` can match boxes to
the ground truth by id), else objects 1.., walls 1000+k, floors 2000+k, ceilings 3000+k.

``reloc map from-scene NAME`` writes the ground-truth boxes of a layout instead (the same document
as ``synth scene export-boxes``).
"""

from __future__ import annotations

import json
import math
import sys
import time
from collections import Counter
from dataclasses import asdict, dataclass

import numpy as np

from synth.atomic import write_text_atomic
from synth.errors import UserError, check_output_file

from ..frontend.detection import STRUCTURE_CLASSES, FrameData, OracleDetector

MAP_FORMAT = "videoreloc-boxes/1"
FRAME_TEXT = "world: right-handed, Z up, metres; yaw about +Z in radians"
ID_BASE = {"object": 1, "wall": 1000, "floor": 2000, "ceiling": 3000}
DEFAULT_STRIDE = 5  # every 5th frame: a 6000-frame 320x240 tour maps in well under a minute


def _struct_slab() -> float:
    from synth.scene import STRUCT_SLAB

    return float(STRUCT_SLAB)


@dataclass(frozen=True)
class MappingSettings:
    """Knobs of :func:`build_map` (all "ours": the paper's pipeline has none of these)."""

    stride: int = DEFAULT_STRIDE
    voxel: float = 0.05  # m, one centroid per cell
    depth_max_m: float = 10.0
    # a pixel is on a depth discontinuity when a 4-neighbour differs by more than abs + rel * z
    edge_abs_m: float = 0.05
    edge_rel: float = 0.05
    # object masks: keep pixels within scale * median + offset of the mask's median depth
    band_scale: float = 0.25
    band_offset_m: float = 0.5
    min_mask_pixels: int = 10  # depth-consistent pixels a detection needs to count
    # a mask's outer rim_px pixels count only where their depth agrees with the mask's interior
    # nearby (a mask bleeding onto what lies behind or in front of it); 0: no rim test
    rim_px: int = 2
    min_voxels: int = 8  # segments with fewer occupied voxels are dropped
    min_frames: int = 2  # ... and segments seen in fewer frames (one-off spurious detections)
    # a voxel several segments claim stays only with those that put at least this fraction of the
    # best claimant's points in it (per-voxel majority labelling, as semantic mapping does)
    vote_ratio: float = 0.5
    quantile: float = 0.01  # robust extents: quantile .. 1 - quantile
    # minimum box thickness: walls as the thinnest ground-truth wall, objects 2 cm; floors and
    # ceilings as the ground truth's slab (synth.scene.STRUCT_SLAB)
    min_wall_thickness_m: float = 0.1
    min_object_size_m: float = 0.02
    # association of untracked object detections to untracked segments
    assoc_min_overlap: float = 0.2  # fraction of the detection's voxels already in the segment
    assoc_radius_m: float = 0.3  # or centroids this close with touching bounding boxes
    # geometric split of pooled (untracked) structure
    wall_line_tol_m: float = 0.06
    wall_gap_m: float = 0.5

    def __post_init__(self):
        if int(self.stride) != self.stride or self.stride < 1:
            raise UserError(f"stride must be a positive integer, got {self.stride!r}")
        if not (self.voxel > 0 and math.isfinite(self.voxel)):
            raise UserError(f"voxel must be a positive number of metres, got {self.voxel!r}")
        if not 0.0 <= self.quantile < 0.25:
            raise UserError(f"quantile must be in [0, 0.25), got {self.quantile!r}")


# ---------------------------------------------------------------------------------------------
# ground truth


def map_from_scene(name_or_layout_file) -> dict:
    """The ground-truth boxes document of a layout (built-in name or file), as
    ``synth scene export-boxes`` writes it."""
    from synth.scene import boxes_document, load_layout

    return boxes_document(load_layout(name_or_layout_file))


# ---------------------------------------------------------------------------------------------
# box fitting


def kind_of(cls: str) -> str:
    return cls if cls in STRUCTURE_CLASSES else "object"


def _quantiles(a: np.ndarray, q: float, axis=-1) -> tuple[np.ndarray, np.ndarray]:
    lo, hi = np.quantile(a, [q, 1.0 - q], axis=axis)
    return lo, hi


def _robust_extents(local: np.ndarray, q: float) -> tuple[np.ndarray, np.ndarray]:
    """Per-axis ends of a point distribution, ignoring the outer ``q`` on each side: the quantile
    function extrapolated linearly from q and 2q to 0 (and 1), clamped to the data. A uniform
    spread (a surface seen face-on) gets its true ends back instead of ends shrunk by q of the
    extent; mass piled up at an end (a face seen edge-on) stays where it is."""
    if q <= 0:
        return local.min(axis=0), local.max(axis=0)
    q1, q2, q3, q4 = np.quantile(local, [q, 2 * q, 1 - 2 * q, 1 - q], axis=0)
    lo = np.maximum(2 * q1 - q2, local.min(axis=0))
    hi = np.minimum(2 * q4 - q3, local.max(axis=0))
    return lo, hi


def _rotated(xy: np.ndarray, yaws: np.ndarray):
    c, s = np.cos(yaws)[:, None], np.sin(yaws)[:, None]
    return c * xy[:, 0] + s * xy[:, 1], -s * xy[:, 0] + c * xy[:, 1]


def _yaw_closeness(xy: np.ndarray, q: float, d0: float = 0.01) -> float:
    """Yaw of the rectangle whose edges the points hug (the closeness criterion of L-shape
    fitting, Zhang et al. 2017, made smooth): each point scores 1 / (d + d0), d its distance to the nearest
    edge of the rectangle bounding it at that yaw (robust ends, :func:`_robust_extents`). Unlike
    the minimum area it is not fooled by partial outlines (an object in a corner seen from one
    side is an L, whose smallest rectangle is turned by 45 degrees), and it has no tilt bias on
    large filled rectangles. 1 degree steps, then 0.05 degree steps around the best."""

    def score(yaws):
        u, v = _rotated(xy, yaws)
        qs = [q, 2 * q, 1 - 2 * q, 1 - q]
        u1, u2, u3, u4 = np.quantile(u, qs, axis=1)
        v1, v2, v3, v4 = np.quantile(v, qs, axis=1)
        ulo = np.maximum(2 * u1 - u2, u.min(axis=1))[:, None]
        uhi = np.minimum(2 * u4 - u3, u.max(axis=1))[:, None]
        vlo = np.maximum(2 * v1 - v2, v.min(axis=1))[:, None]
        vhi = np.minimum(2 * v4 - v3, v.max(axis=1))[:, None]
        d = np.minimum(np.minimum(np.abs(u - ulo), np.abs(uhi - u)), np.minimum(np.abs(v - vlo), np.abs(vhi - v)))
        return (1.0 / (d + d0)).sum(axis=1)

    coarse = np.radians(np.arange(0.0, 90.0, 1.0))
    best = float(coarse[int(np.argmax(score(coarse)))])
    fine = best + np.radians(np.arange(-1.0, 1.0001, 0.05))
    yaw = float(fine[int(np.argmax(score(fine)))])
    # a minimum-area rectangle that agrees within 2 degrees refines it (stray points can tilt
    # the closeness of large filled rectangles by a degree)
    ma = _yaw_min_area(xy, q, start=yaw)
    dev = (ma - yaw + math.pi / 4) % (math.pi / 2) - math.pi / 4
    return yaw + dev if abs(dev) <= math.radians(2.0) else yaw


def _yaw_min_area(xy: np.ndarray, q: float, start: float | None = None) -> float:
    """Yaw of the minimum-area rectangle: first (1 degree steps, unless ``start`` is given) of the
    rectangle holding the q..1-q extents, then ``cv2.minAreaRect`` of the points inside it grown
    by a margin (the trimmed search alone tilts large rectangles by about a degree: tilting trims
    their corners)."""
    import cv2

    def areas(yaws):
        u, v = _rotated(xy, yaws)
        ulo, uhi = _quantiles(u, q, axis=1)
        vlo, vhi = _quantiles(v, q, axis=1)
        eu, ev = uhi - ulo, vhi - vlo
        # a tiny perimeter term: collinear sets pick the yaw of their thinnest extent
        return eu * ev + 1e-6 * (eu + ev)

    if start is None:
        coarse = np.radians(np.arange(0.0, 90.0, 1.0))
        yaw = float(coarse[int(np.argmin(areas(coarse)))])
    else:
        yaw = float(start)
    u, v = _rotated(xy, np.array([yaw]))
    u, v = u[0], v[0]
    (ulo, vlo), (uhi, vhi) = _quantiles(np.stack([u, v], axis=1), q, axis=0)
    mu = max(0.1, 0.05 * (uhi - ulo + vhi - vlo))
    keep = (u >= ulo - mu) & (u <= uhi + mu) & (v >= vlo - mu) & (v <= vhi + mu)
    if keep.sum() >= 3:
        (_, _), (_, _), ang = cv2.minAreaRect(xy[keep].astype(np.float32))
        yaw = math.radians(float(ang))
    return yaw


def fit_box(points: np.ndarray, quantile: float = 0.01, min_size=(0.0, 0.0, 0.0),
            camera: np.ndarray | None = None, spread: np.ndarray | None = None,
            max_search_points: int = 2000, yaw_method: str = "closeness"):
    """Gravity-aligned box (center (3), size (3), yaw) of a point set.

    yaw: first the yaw (1 degree steps) of the smallest rectangle holding the quantile..1-quantile
    extents of the XY points, then the exact minimum-area rectangle (``cv2.minAreaRect``) of the
    points inside that rectangle grown by a margin (the trimmed search alone tilts large
    rectangles by about a degree); extents: :func:`_robust_extents` in that frame. Canonical: size x >= size y, yaw in [-pi/2, pi/2). ``min_size``
    (per box axis, after canonicalisation) thickens thin boxes; with ``camera`` (a point on the
    observed side, e.g. the mean camera position) they grow away from it, keeping the observed
    face, else symmetrically. ``spread`` (N, 4): when the points are voxel centroids, the
    variances of x, y, z and the xy covariance of the raw points in each voxel; each centroid
    then stands for a uniform spread over centroid +- sqrt(3) std along each box axis (exact for
    points spread uniformly), which removes the half-voxel shrink of surfaces running through a
    box end.
    """
    P = np.asarray(points, float).reshape(-1, 3)
    if len(P) == 0:
        raise ValueError("fit_box: no points")
    xy = P[:, :2]
    if len(xy) > max_search_points:
        idx = np.random.default_rng(0).choice(len(xy), max_search_points, replace=False)
        xy_s = xy[idx]
    else:
        xy_s = xy
    xy_s = xy_s - xy_s.mean(axis=0)

    if len(xy_s) >= 3 and yaw_method == "closeness":
        yaw = _yaw_closeness(xy_s, quantile)
    elif len(xy_s) >= 3:
        yaw = _yaw_min_area(xy_s, quantile)
    else:
        yaw = 0.0
    c, s = math.cos(yaw), math.sin(yaw)
    local = np.stack([c * P[:, 0] + s * P[:, 1], -s * P[:, 0] + c * P[:, 1], P[:, 2]], axis=1)
    if spread is not None:
        V = np.asarray(spread, float).reshape(-1, 4)
        var = np.stack([c * c * V[:, 0] + 2 * c * s * V[:, 3] + s * s * V[:, 1],
                        s * s * V[:, 0] - 2 * c * s * V[:, 3] + c * c * V[:, 1], V[:, 2]], axis=1)
        half = math.sqrt(3.0) * np.sqrt(np.maximum(var, 0.0))
        # each voxel as a uniform spread over its interval, drawn at 8 stratified offsets: the
        # quantiles are then those of a continuous distribution, not of voxel rows
        off = (2.0 * np.arange(8) + 1.0) / 8.0 - 1.0
        lo, hi = _robust_extents((local[:, None, :] + off[None, :, None] * half[:, None, :]).reshape(-1, 3), quantile)
    else:
        lo, hi = _robust_extents(local, quantile)
    if hi[0] - lo[0] < hi[1] - lo[1]:  # canonical: x along the longest horizontal axis
        yaw += math.pi / 2
        lo, hi = np.array([lo[1], -hi[0], lo[2]]), np.array([hi[1], -lo[0], hi[2]])
    # wrap to [-pi/2, pi/2) (a box is symmetric under a half turn)
    k = math.floor((yaw + math.pi / 2) / math.pi)
    if k:
        yaw -= k * math.pi
        if k % 2:
            lo, hi = np.array([-hi[0], -hi[1], lo[2]]), np.array([-lo[0], -lo[1], hi[2]])
    lo, hi = lo.astype(float).copy(), hi.astype(float).copy()
    cam_local = None
    if camera is not None:
        cx, cy = math.cos(yaw), math.sin(yaw)
        cam = np.asarray(camera, float)
        cam_local = np.array([cx * cam[0] + cy * cam[1], -cy * cam[0] + cx * cam[1], cam[2]])
    for ax in range(3):
        m = float(min_size[ax])
        if hi[ax] - lo[ax] >= m:
            continue
        if cam_local is None or abs(cam_local[ax] - (lo[ax] + hi[ax]) / 2) < 1e-9:
            mid = (lo[ax] + hi[ax]) / 2
            lo[ax], hi[ax] = mid - m / 2, mid + m / 2
        elif cam_local[ax] > (lo[ax] + hi[ax]) / 2:  # seen from +: keep the + face, grow to -
            lo[ax] = hi[ax] - m
        else:
            hi[ax] = lo[ax] + m
    mid = (lo + hi) / 2
    cx, cy = math.cos(yaw), math.sin(yaw)
    center = np.array([cx * mid[0] - cy * mid[1], cy * mid[0] + cx * mid[1], mid[2]])
    return center, hi - lo, float(yaw)


# ---------------------------------------------------------------------------------------------
# voxel accumulation

_OFF = 1 << 20  # voxel indices within +-2^20 (52 km at 5 cm) pack into 21 bits each


def voxel_keys(points: np.ndarray, voxel: float) -> np.ndarray:
    v = np.floor(points / voxel).astype(np.int64) + _OFF
    return (v[:, 0] << 42) | (v[:, 1] << 21) | v[:, 2]


def _moments(P: np.ndarray) -> np.ndarray:
    """Per-point moments summed per voxel: x, y, z, xx, yy, zz, xy."""
    return np.column_stack([P, P * P, P[:, 0] * P[:, 1]])


def _reduce(keys: np.ndarray, sums: np.ndarray, counts: np.ndarray):
    u, inv = np.unique(keys, return_inverse=True)
    inv = inv.ravel()
    s = np.stack([np.bincount(inv, sums[:, d], len(u)) for d in range(sums.shape[1])], axis=1)
    c = np.bincount(inv, counts, len(u))
    return u, s, c


class _Segment:
    __slots__ = ("track", "votes", "frames", "cam_sum", "cam_w", "keys", "sums", "counts", "pending",
                 "pending_n", "lo", "hi", "last_frame")

    def __init__(self, track):
        self.track = track
        self.votes: Counter = Counter()
        self.frames = 0
        self.last_frame = None
        self.cam_sum = np.zeros(3)
        self.cam_w = 0.0
        self.keys = np.empty(0, np.int64)
        self.sums = np.empty((0, 7))
        self.counts = np.empty(0)
        self.pending: list = []
        self.pending_n = 0
        self.lo = np.full(3, np.inf)
        self.hi = np.full(3, -np.inf)

    def add(self, frame_index, cls, keys, sums, counts, cam, npix):
        self.votes[cls] += npix
        if frame_index != self.last_frame:
            self.frames += 1
            self.last_frame = frame_index
        self.cam_sum += cam * npix
        self.cam_w += npix
        self.pending.append((keys, sums, counts))
        self.pending_n += len(keys)
        pts = sums[:, :3] / counts[:, None]
        self.lo = np.minimum(self.lo, pts.min(axis=0))
        self.hi = np.maximum(self.hi, pts.max(axis=0))
        if self.pending_n > max(2 * len(self.keys), 20000):
            self.merge()

    def absorb(self, other: "_Segment") -> None:
        """Take over another segment's points, votes and views."""
        other.merge()
        self.votes.update(other.votes)
        self.frames += other.frames
        self.cam_sum += other.cam_sum
        self.cam_w += other.cam_w
        self.pending.append((other.keys, other.sums, other.counts))
        self.pending_n += len(other.keys)
        self.lo = np.minimum(self.lo, other.lo)
        self.hi = np.maximum(self.hi, other.hi)
        self.merge()

    def merge(self):
        if not self.pending:
            return
        ks = [self.keys] + [p[0] for p in self.pending]
        ss = [self.sums] + [p[1] for p in self.pending]
        cs = [self.counts] + [p[2] for p in self.pending]
        self.keys, self.sums, self.counts = _reduce(np.concatenate(ks), np.concatenate(ss), np.concatenate(cs))
        self.pending, self.pending_n = [], 0

    @property
    def cls(self) -> str:
        return self.votes.most_common(1)[0][0]

    def points(self) -> tuple[np.ndarray, np.ndarray]:
        """Voxel centroids (N, 3) and the spread of the points in each voxel (N, 4): variances
        of x, y, z and the xy covariance."""
        self.merge()
        m = self.sums / self.counts[:, None]
        c = m[:, :3]
        spread = np.column_stack([m[:, 3:6] - c * c, m[:, 6] - c[:, 0] * c[:, 1]])
        return c, spread

    def camera(self) -> np.ndarray | None:
        return self.cam_sum / self.cam_w if self.cam_w > 0 else None


# ---------------------------------------------------------------------------------------------
# geometric split of pooled structure (detectors without track ids)


def _run_geometry(xy: np.ndarray):
    """Centroid, unit direction (PCA), unit normal and [t0, t1] extent of 2D points."""
    c = xy.mean(axis=0)
    if len(xy) > 1:
        _, _, Vt = np.linalg.svd(xy - c, full_matrices=False)
        d = Vt[0]
    else:
        d = np.array([1.0, 0.0])
    n = np.array([-d[1], d[0]])
    t = (xy - c) @ d
    return c, d, n, float(t.min()), float(t.max())


def split_walls(points: np.ndarray, voxel: float, tol: float, gap: float, min_points: int,
                seed: int = 0) -> list[np.ndarray]:
    """Index arrays of straight vertical wall segments, for wall points pooled without track ids.

    On the occupied XY cells: sequential RANSAC lines (inliers within ``tol``), each split where
    its cells leave a gap over ``gap``; parallel runs closer than 0.3 m (the two faces of a wall,
    or leftovers of a slightly tilted line) are merged; runs are cut where another run ends
    against them (T-junctions), as the ground truth splits wall segments there.
    """
    if len(points) < min_points:
        return []
    cell = np.floor(points[:, :2] / voxel).astype(np.int64)
    cells, inv = np.unique(cell, axis=0, return_inverse=True)
    inv = inv.ravel()
    xy = (cells + 0.5) * voxel
    rng = np.random.default_rng(seed)
    free = np.ones(len(xy), bool)
    min_cells = max(3, int(math.ceil(0.3 / voxel)))
    runs: list[np.ndarray] = []  # cell indices
    while free.sum() >= min_cells:
        idx = np.flatnonzero(free)
        Q = xy[idx]
        a = rng.integers(len(Q), size=300)
        b = rng.integers(len(Q), size=300)
        d = Q[b] - Q[a]
        nrm = np.linalg.norm(d, axis=1)
        ok = nrm > 2 * voxel
        if not ok.any():
            break
        a, d = a[ok], d[ok] / nrm[ok, None]
        n = np.stack([-d[:, 1], d[:, 0]], axis=1)
        dist = np.abs(n @ Q.T - np.sum(n * Q[a], axis=1)[:, None])  # (lines, cells)
        score = (dist < tol).sum(axis=1)
        k = int(np.argmax(score))
        if score[k] < min_cells:
            break
        inl = dist[k] < tol
        for _ in range(2):  # refine: PCA of the inliers, inliers again
            c0, dirn, nn, _, _ = _run_geometry(Q[inl])
            new = np.abs((Q - c0) @ nn) < tol
            if new.sum() < min_cells:
                break
            inl = new
        c0, dirn, nn, _, _ = _run_geometry(Q[inl])
        members = idx[inl]
        free[members] = False
        t = (xy[members] - c0) @ dirn
        order = np.argsort(t)
        cut = np.flatnonzero(np.diff(t[order]) > gap) + 1
        runs += [p for p in np.split(members[order], cut) if len(p) >= min_cells]

    def geom(r):
        return _run_geometry(xy[r])

    # merge parallel runs closer than 0.3 m that overlap along their length
    merged = True
    while merged:
        merged = False
        G = [geom(r) for r in runs]
        for i in range(len(runs)):
            ci, di, ni, ti0, ti1 = G[i]
            for j in range(len(runs)):
                if j == i or abs(float(di @ G[j][1])) < math.cos(math.radians(5)):
                    continue
                rel = xy[runs[j]] - ci
                if np.median(np.abs(rel @ ni)) > 0.3:
                    continue
                tj = rel @ di
                ov = min(ti1, tj.max()) - max(ti0, tj.min())
                if ov < 0.5 * min(ti1 - ti0, tj.max() - tj.min()):
                    continue
                runs[i] = np.concatenate([runs[i], runs[j]])
                del runs[j]
                merged = True
                break
            if merged:
                break
    # cut runs at T-junctions: where a run at least 45 degrees off ends within 0.35 m of the line
    G = [geom(r) for r in runs]
    out_runs = []
    for i, r in enumerate(runs):
        ci, di, ni, ti0, ti1 = G[i]
        cuts = []
        for j, (cj, dj, _, tj0, tj1) in enumerate(G):
            if j == i or abs(float(di @ dj)) > math.cos(math.radians(45)) or tj1 - tj0 < 0.5:
                continue
            for e in (cj + dj * tj0, cj + dj * tj1):
                rel = e - ci
                t = float(rel @ di)
                if abs(float(rel @ ni)) < 0.35 and ti0 + 0.3 < t < ti1 - 0.3:
                    cuts.append(t)
        t = (xy[r] - ci) @ di
        edges = [-np.inf] + sorted(cuts) + [np.inf]
        for lo, hi in zip(edges[:-1], edges[1:]):
            sel = (t >= lo) & (t < hi)
            # runs shorter than 0.4 m are reveals (a wall's thickness seen in a door or window)
            if sel.sum() >= min_cells and np.ptp(t[sel]) >= 0.4:
                out_runs.append(r[sel])
    label = np.full(len(xy), -1)
    for k, r in enumerate(out_runs):
        label[r] = k
    pl = label[inv]
    out = [np.flatnonzero(pl == k) for k in range(len(out_runs))]
    return [o for o in out if len(o) >= min_points]


def split_rooms(points: np.ndarray, min_points: int, cell: float = 0.05, barrier: np.ndarray | None = None,
                min_area_m2: float = 1.0) -> list[np.ndarray]:
    """Index arrays of floor (or ceiling) points per room, for points pooled without track ids.

    The occupied XY grid, less the cells of ``barrier`` points (the walls, whose lintels close
    the doorways) grown by one cell, falls into connected regions; regions of at least
    ``min_area_m2`` are rooms and every occupied cell joins the nearest room.
    """
    from scipy import ndimage

    if len(points) < min_points:
        return []
    g = np.floor(points[:, :2] / cell).astype(np.int64)
    g0 = g.min(axis=0) - 2
    g -= g0
    shape = tuple(g.max(axis=0) + 3)
    occ = np.zeros(shape, bool)
    occ[g[:, 0], g[:, 1]] = True
    free = occ.copy()
    if barrier is not None and len(barrier):
        b = np.floor(barrier[:, :2] / cell).astype(np.int64) - g0
        inside = np.all((b >= 0) & (b < np.array(shape)), axis=1)
        wall = np.zeros(shape, bool)
        wall[b[inside, 0], b[inside, 1]] = True
        free &= ~ndimage.binary_dilation(wall)
    lab, n = ndimage.label(free)
    if n == 0:
        return [np.arange(len(points))]
    area = ndimage.sum(free, lab, index=np.arange(1, n + 1)) * cell * cell
    keep = np.zeros(n + 1, bool)
    keep[1:] = area >= min_area_m2
    if not keep.any():
        keep[1 + int(np.argmax(area))] = True
    lab = np.where(keep[lab], lab, 0)
    _, (ix, iy) = ndimage.distance_transform_edt(lab == 0, return_indices=True)
    near = lab[ix, iy]
    pl = near[g[:, 0], g[:, 1]]
    out = [np.flatnonzero(pl == k) for k in np.unique(pl) if k > 0]
    return [o for o in out if len(o) >= min_points]


# ---------------------------------------------------------------------------------------------
# building


class _Backprojector:
    def __init__(self, K: np.ndarray, shape: tuple[int, int]):
        H, W = shape
        u, v = np.meshgrid(np.arange(W, dtype=float), np.arange(H, dtype=float))
        pix = np.stack([u, v, np.ones_like(u)], axis=-1).reshape(-1, 3)
        self.rays = pix @ np.linalg.inv(K).T  # camera-frame rays with z = 1, (H*W, 3)
        self.shape = shape

    def __call__(self, depth: np.ndarray, pose: np.ndarray) -> np.ndarray:
        """World points of every pixel, (H*W, 3) (meaningless where depth is 0)."""
        pc = self.rays * depth.reshape(-1, 1)
        return pc @ pose[:3, :3].T + pose[:3, 3]


def _depth_edges(z: np.ndarray, valid: np.ndarray, abs_m: float, rel: float) -> np.ndarray:
    """Pixels on the far side of a depth discontinuity: a valid 4-neighbour is nearer by more
    than abs_m + rel * z. These are the flying pixels and the background a mask bleeds onto; the
    near side (an object's own silhouette) is kept."""
    edge = np.zeros(z.shape, bool)
    thr = abs_m + rel * z
    for dy, dx in ((0, 1), (1, 0)):
        a = (slice(None, z.shape[0] - dy), slice(None, z.shape[1] - dx))
        b = (slice(dy, None), slice(dx, None))
        both = valid[a] & valid[b]
        diff = z[b] - z[a]  # > 0: b is farther than a
        edge[b] |= both & (diff > thr[b])
        edge[a] |= both & (-diff > thr[a])
    return edge


def _consistent_rim(mask: np.ndarray, z: np.ndarray, valid: np.ndarray, r: int, abs_m: float,
                    rel: float) -> np.ndarray:
    """The mask less the rim pixels (within ``r`` pixels of its edge) whose depth leaves the range
    of the mask's interior depths within 2r of them by more than abs_m + rel * z plus that range's
    own width (a slanted surface continues its depth ramp): where a mask bleeds
    onto a surface behind or in front of its object. Rim pixels with no interior pixel nearby
    (thin parts: legs, frames) are kept, the depth-edge test being all that checks them."""
    import cv2

    ys, xs = np.nonzero(mask)
    if len(ys) == 0:
        return mask
    H, W = mask.shape
    y0, y1 = max(int(ys.min()) - 2 * r, 0), min(int(ys.max()) + 2 * r + 1, H)
    x0, x1 = max(int(xs.min()) - 2 * r, 0), min(int(xs.max()) + 2 * r + 1, W)
    m = mask[y0:y1, x0:x1]
    zz = z[y0:y1, x0:x1].astype(np.float32)
    k = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * r + 1, 2 * r + 1))
    inner = cv2.erode(m.astype(np.uint8), k, borderType=cv2.BORDER_CONSTANT, borderValue=0).astype(bool)
    inner &= valid[y0:y1, x0:x1]
    rim = m & ~inner
    if not rim.any():
        return mask
    # the interior's depth range within 2r of each rim pixel (twice the rim's width, so that a
    # slanted surface's ramp shows in the range)
    k2 = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (4 * r + 1, 4 * r + 1))
    zmax = cv2.dilate(np.where(inner, zz, 0.0).astype(np.float32), k2)
    zmin = cv2.erode(np.where(inner, zz, np.float32(1e9)).astype(np.float32), k2)
    near = zmax > 0
    # slanted surfaces (seen at grazing angles) continue their interior's depth ramp: allow one
    # more window's worth of it beyond the interior's range
    tol = abs_m + rel * zz + np.where(near, zmax - zmin, 0.0)
    bad = rim & near & ((zz > zmax + tol) | (zz < zmin - tol))
    if not bad.any():
        return mask
    out = mask.copy()
    out[y0:y1, x0:x1] &= ~bad
    return out


def _needs_labels(detector) -> bool:
    return isinstance(detector, OracleDetector) or bool(getattr(detector, "needs_labels", False))


def build_map(tour_dir, detector=None, stride: int | None = None, voxel: float | None = None, progress: bool = True,
              settings: MappingSettings | None = None, max_frames: int | None = None) -> tuple[dict, dict]:
    """Build a box map from a mapping tour: ``(videoreloc-boxes/1 document, report)``.

    ``detector``: anything with ``detect(FrameData) -> list[Detection]`` (default: the oracle of
    the tour's classes). ``stride``/``voxel`` (default 5 frames / 0.05 m, see
    :class:`MappingSettings`) override ``settings``. ``max_frames``: stop after that many visited
    frames. ``progress``: a tqdm bar on stderr. Frames without depth or without detections are
    skipped and counted in the report; a tour from which nothing can be built gives an empty
    (valid) map and a ``warnings`` entry. A missing or unreadable frame file is an error naming
    the file (``FrameFileError``), as in ``reloc run``: a map must not quietly lack its views.
    """
    from tqdm import tqdm

    from synth.classes import class_table
    from synth.dataset import Tour

    t_start = time.perf_counter()
    s = settings or MappingSettings()
    over = {}
    if stride is not None:
        over["stride"] = stride
    if voxel is not None:
        over["voxel"] = voxel
    if over:
        s = MappingSettings(**{**asdict(s), **over})
    tour = Tour(tour_dir)  # UserError when missing or malformed
    classes = tour.class_names()
    if detector is None:
        if not classes:
            raise UserError(f"{tour.root}: no class table in objects.json; the oracle detector needs one")
        detector = OracleDetector(classes)
    labels = _needs_labels(detector)
    want_rgb = not labels and tour.has_rgb()  # label images only for the oracle, RGB for the rest
    indices = [int(i) for i in tour.frame_indices[:: int(s.stride)]]
    if max_frames is not None:
        indices = indices[: int(max_frames)]
    K = tour.K
    bp = None
    tracked: dict[int, _Segment] = {}
    untracked: dict[str, list[_Segment]] = {}
    pooled: dict[str, _Segment] = {}
    counts = Counter()
    for fi in tqdm(indices, desc="mapping", unit="frame", disable=not progress, file=sys.stderr):
        f = tour.frame(fi, rgb=want_rgb, instance=labels, semantic=labels)  # FrameFileError names the file
        depth = f.depth
        if depth is None:
            counts["no_depth"] += 1
            continue
        valid = np.isfinite(depth) & (depth > 0) & (depth <= s.depth_max_m)
        if not valid.any():
            counts["no_depth"] += 1
            continue
        if bp is None or bp.shape != depth.shape:
            bp = _Backprojector(K, depth.shape)
        dets = detector.detect(FrameData(fi, depth, K, f.rgb, f.instance, f.semantic))
        counts["frames_used"] += 1
        if not dets:
            counts["no_detections"] += 1
            continue
        zc = np.where(valid, depth, 0.0).astype(float)
        good = (valid & ~_depth_edges(zc, valid, s.edge_abs_m, s.edge_rel)).ravel()
        zf = zc.ravel()
        world = bp(zc, f.pose)
        cam = f.pose[:3, 3]
        any_used = False
        for d in dets:
            mask = np.asarray(d.mask, bool)
            if s.rim_px > 0:
                mask = _consistent_rim(mask, zc, valid, s.rim_px, s.edge_abs_m, s.edge_rel)
            idx = np.flatnonzero(mask.ravel() & good)
            n = len(idx)
            if n < s.min_mask_pixels:
                counts["detections_too_small"] += 1
                continue
            kind = kind_of(d.cls)
            if kind == "object":
                zm = zf[idx]
                med = float(np.median(zm))
                idx = idx[np.abs(zm - med) <= s.band_scale * med + s.band_offset_m]
                n = len(idx)
                if n < s.min_mask_pixels:
                    counts["detections_too_small"] += 1
                    continue
            P = world[idx]
            keys = voxel_keys(P, s.voxel)
            k, sm, ct = _reduce(keys, _moments(P), np.ones(len(P)))
            counts["detections"] += 1
            any_used = True
            if d.track_id is not None:
                seg = tracked.get(int(d.track_id))
                if seg is None:
                    seg = tracked[int(d.track_id)] = _Segment(int(d.track_id))
            elif kind != "object":
                seg = pooled.get(kind)
                if seg is None:
                    seg = pooled[kind] = _Segment(None)
            else:
                seg = _associate(untracked.setdefault(d.cls, []), k, sm[:, :3] / ct[:, None], s)
            seg.add(fi, d.cls, k, sm, ct, cam, n)
        if not any_used:
            counts["no_detections"] += 1

    # ---- voxel ownership: a voxel claimed by several segments stays with those holding at least
    # vote_ratio of the best one's points (mask bleed onto neighbouring surfaces loses)
    all_segs = list(tracked.values()) + [g for segs in untracked.values() for g in segs] + list(pooled.values())
    voxels_disowned = _vote_voxels(all_segs, s.vote_ratio, 4 * s.min_voxels) if s.vote_ratio > 0 else 0

    # ---- boxes
    table = class_table()
    slab = _struct_slab()
    min_sizes = {
        "object": (s.min_object_size_m,) * 3,
        "wall": (s.min_wall_thickness_m,) * 3,
        "floor": (s.min_object_size_m, s.min_object_size_m, slab),
        "ceiling": (s.min_object_size_m, s.min_object_size_m, slab),
    }
    boxes = []
    dropped = Counter()
    pieces = []  # (class, voxel centroids, voxel spreads, camera, track id)
    for tid, seg in sorted(tracked.items()):
        pieces.append((seg.cls, *seg.points(), seg.camera(), tid, seg.frames))
    for cls, segs in sorted(untracked.items()):
        for seg in _merge_overlapping(segs):
            pieces.append((seg.cls, *seg.points(), seg.camera(), None, seg.frames))
    wall_points = pooled["wall"].points()[0] if "wall" in pooled else None
    for kind, seg in sorted(pooled.items()):
        P, V = seg.points()
        if kind == "wall":
            parts = split_walls(P, s.voxel, s.wall_line_tol_m, s.wall_gap_m, s.min_voxels)
        else:
            parts = split_rooms(P, s.min_voxels, cell=s.voxel, barrier=wall_points)
        for idx in parts:
            pieces.append((seg.cls, P[idx], V[idx], seg.camera(), None, seg.frames))
        if len(P) and not parts:
            dropped[kind] += 1
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
            camera = _structure_camera(kind, P, camera)
        center, size, yaw = fit_box(P, s.quantile, min_sizes[kind], camera, spread=V)
        if tid is None:
            tid = next_id[kind]
            while tid in used_ids:
                tid += 1
            next_id[kind] = tid + 1
            used_ids.add(tid)
            assigned_ids.append(int(tid))
        movable = table.classes[cls].movable if cls in table else kind == "object"
        boxes.append({
            "id": int(tid), "class": cls, "kind": kind,
            "center": [round(float(v), 4) for v in center],
            "size": [round(max(float(v), 1e-3), 4) for v in size],
            # 5 decimals, kept inside [-pi/2, pi/2) (rounding would push +-pi/2 just outside)
            "yaw": min(max(round(float(yaw), 5), -1.57079), 1.57079),
            "movable": bool(movable),
        })
    boxes.sort(key=lambda b: b["id"])
    sem = {v: k for k, v in classes.items()}
    used = sorted({b["class"] for b in boxes})
    doc = {
        "format": MAP_FORMAT,
        "layout": tour.meta.get("layout"),
        "frame": FRAME_TEXT,
        "classes": {c: int(sem[c]) if c in sem else (table.id_of(c) if c in table else 0) for c in used},
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
    kinds = Counter(b["kind"] for b in boxes)
    warnings = []
    if not boxes:
        why = []
        if counts["no_depth"]:
            why.append(f"{counts['no_depth']} frames without valid depth")
        if counts["no_detections"]:
            why.append(f"{counts['no_detections']} frames without usable detections")
        warnings.append(f"{tour.root}: no boxes built from {len(indices)} frames"
                        + (f" ({', '.join(why)})" if why else ""))
    report = {
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
    return doc, report


def _vote_voxels(segs: list[_Segment], ratio: float, keep_small: int = 0) -> int:
    """Per-voxel majority: drop a segment's voxel where another segment has more than
    1 / ratio times its points. Segments of fewer than ``keep_small`` voxels lose none (a small
    thing lying on a bigger one shares most of its few voxels with it). Returns the number of
    voxel entries dropped."""
    segs = [g for g in segs if (g.merge() or len(g.keys))]
    if len(segs) < 2:
        return 0
    keys = np.concatenate([g.keys for g in segs])
    cnt = np.concatenate([g.counts for g in segs])
    _, inv = np.unique(keys, return_inverse=True)
    inv = inv.ravel()
    best = np.zeros(inv.max() + 1)
    np.maximum.at(best, inv, cnt)
    keep = cnt >= ratio * best[inv]
    small = np.concatenate([np.full(len(g.keys), len(g.keys) < keep_small) for g in segs])
    keep |= small
    dropped, start = 0, 0
    for g in segs:
        n = len(g.keys)
        k = keep[start:start + n]
        start += n
        if not k.all():
            dropped += int((~k).sum())
            g.keys, g.sums, g.counts = g.keys[k], g.sums[k], g.counts[k]
            if len(g.keys):
                c = g.sums[:, :3] / g.counts[:, None]
                g.lo, g.hi = c.min(axis=0), c.max(axis=0)
    return dropped


def _structure_camera(kind, P, camera):
    """The side a pooled structure piece was seen from: its own mean camera is not known after
    the split, so floors are seen from above, ceilings from below, walls from the pooled mean."""
    if kind == "floor":
        return np.array([*P[:, :2].mean(axis=0), P[:, 2].max() + 1.0])
    if kind == "ceiling":
        return np.array([*P[:, :2].mean(axis=0), P[:, 2].min() - 1.0])
    return camera


def _associate(segs: list[_Segment], keys, pts, s: MappingSettings) -> _Segment:
    """The untracked same-class segment a detection belongs to (or a new one).

    A candidate qualifies by voxel overlap (at least ``assoc_min_overlap`` of the detection's
    voxels already in the segment), by containment (at least 60 % of the detection's voxels
    inside the segment's bounding box: another side of the same thing), or by proximity
    (centroids within ``assoc_radius_m``); the best overlap, then containment, wins."""
    lo, hi = pts.min(axis=0), pts.max(axis=0)
    c = pts.mean(axis=0)
    best, best_score = None, 0.0
    pad = 2 * s.voxel
    for seg in segs:
        if np.any(lo > seg.hi + pad) or np.any(hi < seg.lo - pad):
            continue
        seg.merge()
        ov = float(np.isin(keys, seg.keys, assume_unique=True).mean())
        inside = float(np.all((pts >= seg.lo - s.voxel) & (pts <= seg.hi + s.voxel), axis=1).mean())
        sc = seg.sums[:, :3].sum(axis=0) / seg.counts.sum()
        near = np.linalg.norm(sc - c) <= s.assoc_radius_m
        if ov < s.assoc_min_overlap and inside < 0.6 and not near:
            continue
        score = 2.0 + ov if ov >= s.assoc_min_overlap else (1.0 + inside if inside >= 0.6 else 0.5)
        if score > best_score:
            best, best_score = seg, score
    if best is None:
        best = _Segment(None)
        segs.append(best)
    return best


def _merge_overlapping(segs: list[_Segment], min_shared: float = 0.5) -> list[_Segment]:
    """Merge untracked same-class segments whose bounding boxes share at least ``min_shared`` of
    the smaller box's volume (pieces of one thing that no single view tied together)."""
    segs = list(segs)
    changed = True
    while changed:
        changed = False
        for i in range(len(segs)):
            for j in range(i + 1, len(segs)):
                a, b = segs[i], segs[j]
                inter = np.clip(np.minimum(a.hi, b.hi) - np.maximum(a.lo, b.lo), 0, None)
                va = np.prod(np.maximum(a.hi - a.lo, 1e-3))
                vb = np.prod(np.maximum(b.hi - b.lo, 1e-3))
                if np.prod(inter) >= min_shared * min(va, vb):
                    a.absorb(b)
                    del segs[j]
                    changed = True
                    break
            if changed:
                break
    return segs


# ---------------------------------------------------------------------------------------------
# evaluation against ground truth


def _yaw_size_align(yaw_b, size_b, yaw_g):
    """The built box's size in the ground-truth box's axes and the yaw error modulo 90 degrees
    (a box is the same box under (sx, sy, yaw) -> (sy, sx, yaw + 90))."""
    d = (yaw_b - yaw_g) % math.pi  # in [0, pi)
    sb = list(size_b)
    if math.pi / 4 <= d < 3 * math.pi / 4:
        sb = [sb[1], sb[0], sb[2]]
    err = abs((d + math.pi / 4) % (math.pi / 2) - math.pi / 4)
    return np.asarray(sb, float), err


def box_errors(doc: dict, gt_doc: dict, match: str = "auto", max_match_m: float = 1.0,
               max_match_structure_m: float = 2.5) -> dict:
    """Per-box errors of a built map against ground truth, and medians by kind.

    ``match``: ``id`` (same id and class: the map kept the track ids), ``nearest`` (same class,
    minimum-cost assignment of center distances within ``max_match_m``, or
    ``max_match_structure_m`` for walls/floors/ceilings), ``mixed`` (``id`` for the track ids,
    ``nearest`` for the boxes the map numbered itself, ``mapping.assigned_ids``) or ``auto``
    (what the map's ``mapping.ids`` says; ``nearest`` for maps without it). Id matches ignore the
    class (a track whose majority label is wrong is counted in ``class_errors``); nearest matches
    need it. Sizes are compared axis by axis after turning the built box by the multiple of 90
    degrees closest to the ground truth's yaw; ``yaw_err_deg`` is modulo 90 degrees (the same box).
    Partially observed objects legitimately get smaller boxes; their errors are reported as they
    are (``size_ratio``: built volume / ground-truth volume).
    """
    from scipy.optimize import linear_sum_assignment

    built = list(doc.get("boxes", []))
    gt = list(gt_doc.get("boxes", []))
    info = doc.get("mapping") or {}
    if match == "auto":
        match = {"track": "id", "mixed": "mixed"}.get(info.get("ids"), "nearest")
    if match not in ("id", "nearest", "mixed"):
        raise ValueError(f"match must be auto, id, nearest or mixed, got {match!r}")
    pairs: list[tuple[int, int]] = []
    if match in ("id", "mixed"):
        assigned = set(info.get("assigned_ids", [])) if match == "mixed" else set()
        gi = {g["id"]: j for j, g in enumerate(gt)}
        for k, b in enumerate(built):
            j = gi.get(b["id"])
            if b["id"] not in assigned and j is not None:
                pairs.append((k, j))
    if match in ("nearest", "mixed"):
        done_b, done_g = {k for k, _ in pairs}, {j for _, j in pairs}
        for cls in sorted({b["class"] for b in built}):
            bk = [k for k, b in enumerate(built) if b["class"] == cls and k not in done_b]
            gk = [j for j, g in enumerate(gt) if g["class"] == cls and j not in done_g]
            if not bk or not gk:
                continue
            lim = max_match_m if kind_of(cls) == "object" else max_match_structure_m
            C = np.linalg.norm(np.array([built[k]["center"] for k in bk], float)[:, None]
                               - np.array([gt[j]["center"] for j in gk], float)[None], axis=-1)
            r, c = linear_sum_assignment(np.where(C <= lim, C, 1e6))
            pairs += [(bk[a], gk[b]) for a, b in zip(r, c) if C[a, b] <= lim]
    rows = []
    for k, j in sorted(pairs):
        b, g = built[k], gt[j]
        sb, yerr = _yaw_size_align(float(b["yaw"]), b["size"], float(g["yaw"]))
        se = np.abs(sb - np.asarray(g["size"], float))
        rows.append({
            "id": b["id"], "gt_id": g["id"], "class": b["class"], "kind": b.get("kind", "object"),
            "class_ok": b["class"] == g["class"],
            "center_err_m": round(float(np.linalg.norm(np.subtract(b["center"], g["center"]))), 4),
            "size_err_m": [round(float(v), 4) for v in se],
            "size_err_max_m": round(float(se.max()), 4),
            "size_ratio": round(float(np.prod(sb) / max(np.prod(g["size"]), 1e-12)), 3),
            "yaw_err_deg": round(math.degrees(yerr), 3),
            "size": [round(float(v), 4) for v in sb], "gt_size": [round(float(v), 4) for v in g["size"]],
        })
    matched_b = {k for k, _ in pairs}
    matched_g = {j for _, j in pairs}
    by_kind = {}
    for kind in ("object", "wall", "floor", "ceiling"):
        rk = [r for r in rows if r["kind"] == kind]
        gt_n = sum(1 for g in gt if g.get("kind", "object") == kind)
        unobs = [gt[j] for j in range(len(gt)) if j not in matched_g and gt[j].get("kind", "object") == kind]
        by_kind[kind] = {
            "gt": gt_n,
            "built": sum(1 for b in built if b.get("kind", "object") == kind),
            "matched": len(rk),
            "median_center_err_m": _med([r["center_err_m"] for r in rk]),
            "median_size_err_max_m": _med([r["size_err_max_m"] for r in rk]),
            "median_size_err_m": [_med([r["size_err_m"][a] for r in rk]) for a in range(3)] if rk else None,
            "median_yaw_err_deg": _med([r["yaw_err_deg"] for r in rk]),
            "unobserved": len(unobs),
        }
    unobserved = [{"id": g["id"], "class": g["class"], "kind": g.get("kind", "object")}
                  for j, g in enumerate(gt) if j not in matched_g]
    unmatched = [{"id": b["id"], "class": b["class"], "kind": b.get("kind", "object")}
                 for k, b in enumerate(built) if k not in matched_b]
    return {
        "match": match,
        "boxes": rows,
        "by_kind": by_kind,
        "class_errors": sum(1 for r in rows if not r["class_ok"]),
        "gt_unobserved": len(unobserved),
        "unobserved": unobserved,
        "built_unmatched": len(unmatched),
        "unmatched": unmatched,
    }


def _med(v):
    return round(float(np.median(v)), 4) if len(v) else None


# ---------------------------------------------------------------------------------------------
# files and CLI


def dumps_map(doc: dict) -> str:
    """Compact, diff-friendly JSON: header fields indented, one box per line."""
    head = {k: v for k, v in doc.items() if k != "boxes"}
    lines = ["{"]
    for k, v in head.items():
        lines.append(f" {json.dumps(k)}: {json.dumps(v)},")
    boxes = doc.get("boxes", [])
    lines.append(' "boxes": [' + ("" if boxes else "]"))
    for i, b in enumerate(boxes):
        lines.append("  " + json.dumps(b, separators=(", ", ": ")) + ("," if i + 1 < len(boxes) else ""))
    if boxes:
        lines.append(" ]")
    lines.append("}")
    return "\n".join(lines) + "\n"




def summary_line(doc: dict, size_bytes: int, errors: dict | None, report: dict | None = None) -> str:
    kinds = Counter(b.get("kind", "object") for b in doc["boxes"])
    parts = [f"{len(doc['boxes'])} boxes ("
             + ", ".join(f"{kinds.get(k, 0)} {k}s" for k in ("object", "wall", "floor", "ceiling")) + ")",
             f"{size_bytes / 1024:.1f} kB"]
    if report is not None:
        parts.append(f"{report['frames_used']}/{report['frames_in_tour']} frames in {report['wall_time_s']:.1f} s")
    if errors is not None:
        errs = []
        for k, e in errors["by_kind"].items():
            if e["matched"]:
                errs.append(f"{k} {e['median_center_err_m']:.3f}/{e['median_size_err_max_m']:.3f}")
        parts.append("median center/size err m: " + (", ".join(errs) or "-"))
        parts.append(f"{errors['gt_unobserved']} GT unobserved, {errors['built_unmatched']} unmatched")
    return "; ".join(parts)


def cmd_from_scene(args) -> int:
    check_output_file(args.out)
    doc = map_from_scene(args.name)
    out = write_text_atomic(args.out, dumps_map(doc))
    print(f"wrote {len(doc['boxes'])} boxes of {doc['layout']} to {out} ({out.stat().st_size / 1024:.1f} kB)")
    return 0


def cmd_build(args) -> int:
    check_output_file(args.out)
    if args.report:
        check_output_file(args.report)
    doc, report = build_map(args.tour, stride=args.stride, voxel=args.voxel, progress=not args.quiet)
    for w in report["warnings"]:
        print(f"warning: {w}", file=sys.stderr)
    if not doc["boxes"]:
        raise UserError(report["warnings"][0] if report["warnings"] else f"{args.tour}: no boxes built")
    from .boxmap import BoxMap

    BoxMap(doc, source=str(args.out))  # validates what is about to be written
    out = write_text_atomic(args.out, dumps_map(doc))
    errors = None
    try:
        from synth.dataset import Tour

        gt = Tour(args.tour).objects()
        errors = box_errors(doc, gt)
    except UserError:
        pass  # no ground truth: no errors to report
    if args.report:
        write_text_atomic(args.report, json.dumps({"build": report, "errors": errors}, indent=1) + "\n")
    print(f"{out}: " + summary_line(doc, out.stat().st_size, errors, report))
    return 0


def cmd_show(args) -> int:
    from .boxmap import BoxMap

    s = BoxMap.load(args.file).summary()
    for k, v in s.items():
        if isinstance(v, dict):
            v = ", ".join(f"{a} {b}" for a, b in v.items())
        print(f"{k:<18} {v}")
    return 0


def register_cli(subparsers) -> None:
    """Add the ``map`` command group: from-scene, build, show."""
    g = subparsers.add_parser("map", help="box maps: from a layout's ground truth, built from a mapping tour, summary")
    ms = g.add_subparsers(dest="cmd", required=True)
    a = ms.add_parser("from-scene", help="the ground-truth boxes of a layout as a map")
    a.add_argument("name", help="layout name (apt_0) or layout file")
    a.add_argument("--out", required=True, help="map file (.json)")
    a.set_defaults(fn=cmd_from_scene)
    a = ms.add_parser("build", help="build a map from a rendered mapping tour (oracle detector)")
    a.add_argument("tour", metavar="TOUR_DIR", help="tour directory")
    a.add_argument("--out", required=True, help="map file (.json)")
    a.add_argument("--stride", type=int, default=DEFAULT_STRIDE, help=f"use every N-th frame (default {DEFAULT_STRIDE})")
    a.add_argument("--voxel", type=float, default=0.05, help="voxel size in metres (default 0.05)")
    a.add_argument("--report", metavar="FILE.json", help="write the build report and per-box errors against the tour's ground truth")
    a.add_argument("--quiet", action="store_true", help="no progress bar")
    a.set_defaults(fn=cmd_build)
    a = ms.add_parser("show", help="summary of a map file")
    a.add_argument("file")
    a.set_defaults(fn=cmd_show)
