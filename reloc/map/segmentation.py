"""Voxel segments: the points of one thing, accumulated over the frames of a mapping tour.

A segment (:class:`Segment`) keeps per ``voxel`` cell the point count, centroid and second moments
(memory bounded by the observed surface, not by the number of frames), the pixel-weighted votes
for its class and the mean camera that saw it. Object detections without a track id join an
untracked segment of their class by voxel overlap, containment or proximity (:func:`associate_segment`);
overlapping untracked segments are merged (:func:`merge_overlapping`); a voxel several segments
claim stays with those holding at least a fraction of the best one's points there
(:func:`vote_voxels`).
"""

from __future__ import annotations

from collections import Counter

import numpy as np

from .settings import MapBuildSettings

_OFF = 1 << 20  # voxel indices within +-2^20 (52 km at 5 cm) pack into 21 bits each


def voxel_keys(points: np.ndarray, voxel: float) -> np.ndarray:
    v = np.floor(points / voxel).astype(np.int64) + _OFF
    return (v[:, 0] << 42) | (v[:, 1] << 21) | v[:, 2]


def point_moments(P: np.ndarray) -> np.ndarray:
    """Per-point moments summed per voxel: x, y, z, xx, yy, zz, xy."""
    return np.column_stack([P, P * P, P[:, 0] * P[:, 1]])


def reduce_by_key(keys: np.ndarray, sums: np.ndarray, counts: np.ndarray):
    u, inv = np.unique(keys, return_inverse=True)
    inv = inv.ravel()
    s = np.stack([np.bincount(inv, sums[:, d], len(u)) for d in range(sums.shape[1])], axis=1)
    c = np.bincount(inv, counts, len(u))
    return u, s, c


class Segment:
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

    def absorb(self, other: "Segment") -> None:
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
        self.keys, self.sums, self.counts = reduce_by_key(np.concatenate(ks), np.concatenate(ss), np.concatenate(cs))
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


def vote_voxels(segs: list[Segment], ratio: float, keep_small: int = 0) -> int:
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


def associate_segment(segs: list[Segment], keys, pts, s: MapBuildSettings) -> Segment:
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
        best = Segment(None)
        segs.append(best)
    return best


def fuse_across_classes(segs: list[Segment], min_shared: float) -> list[Segment]:
    """Class-agnostic fusion of untracked segments: a segment sharing at least ``min_shared`` of
    its voxels with a bigger segment of any class is the same thing seen under another label (a
    sofa some views call an armchair) and joins it; the class is the pixel-weighted majority of
    the merged votes. Returns the surviving segments (biggest first)."""
    for g in segs:
        g.merge()
    order = sorted((g for g in segs if len(g.keys)), key=lambda g: -len(g.keys))
    kept: list[Segment] = []
    for g in order:
        host = None
        for h in kept:
            if np.any(g.lo > h.hi) or np.any(g.hi < h.lo):
                continue
            if np.isin(g.keys, h.keys, assume_unique=True).mean() >= min_shared:
                host = h
                break
        if host is None:
            kept.append(g)
        else:
            host.absorb(g)
    return kept


def merge_overlapping(segs: list[Segment], min_shared: float = 0.5) -> list[Segment]:
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
