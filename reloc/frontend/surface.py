"""Box-surface consistency (paper Sec. III-D, Eq. 2), batched over candidate transforms.

For fused instance k with surface samples P_k and map box m_j of the same class,
rho_kj(S) is the root-mean-square distance of S(P_k) to the solid box (interior points count 0).
kappa(S) is the fraction of instances whose best same-class rho is below tau; the minimising box
is the instance's assignment. :class:`SurfaceScorer` precomputes the class-compatible
(instance, box) pairs once so that many transforms can be scored in one vectorised pass.
"""

from __future__ import annotations

import numpy as np

from ..geometry import BoxSet
from ..map.boxmap import BoxMap


class SurfaceScorer:
    def __init__(self, bmap: BoxMap, classes: list[str], samples: list[np.ndarray]):
        self.map = bmap
        self.K = len(classes)
        self.classes = list(classes)
        pts, e_pt, e_box, g_start, g_n, g_k, g_slot = [], [], [], [], [], [], []
        offset = 0
        jmax = 1
        slot_box: list[list[int]] = []
        for k, (cls, P) in enumerate(zip(classes, samples)):
            P = np.asarray(P, float).reshape(-1, 3)
            pts.append(P)
            boxes = bmap.nodes_of(cls) if len(P) else np.empty(0, int)
            slot_box.append([int(b) for b in boxes])
            jmax = max(jmax, len(boxes))
            for s, j in enumerate(boxes):
                g_start.append(len(e_pt))
                g_n.append(len(P))
                g_k.append(k)
                g_slot.append(s)
                e_pt.extend(range(offset, offset + len(P)))
                e_box.extend([j] * len(P))
            offset += len(P)
        self.points = np.concatenate(pts) if pts else np.empty((0, 3))
        self.e_pt = np.asarray(e_pt, dtype=np.int64)
        self.e_box = np.asarray(e_box, dtype=np.int64)
        self.g_start = np.asarray(g_start, dtype=np.int64)
        self.g_n = np.asarray(g_n, dtype=float)
        self.g_k = np.asarray(g_k, dtype=np.int64)
        self.g_slot = np.asarray(g_slot, dtype=np.int64)
        self.jmax = jmax
        self.slot_box = np.full((max(self.K, 1), jmax), -1, dtype=np.int64)
        for k, boxes in enumerate(slot_box):
            self.slot_box[k, : len(boxes)] = boxes
        # the box of each (point, box) pair, paired element-wise with the mapped points in rho
        self._boxes = BoxSet(bmap.centers[self.e_box], bmap.sizes[self.e_box], bmap.yaws[self.e_box])

    def rho(self, Ts: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Best same-class rms distance (H, K) (inf without a same-class box) and its box (-1)."""
        Ts = np.asarray(Ts, float).reshape(-1, 4, 4)
        H = len(Ts)
        best = np.full((H, self.K), np.inf)
        assign = np.full((H, self.K), -1, dtype=np.int64)
        if not len(self.e_pt) or self.K == 0:
            return best, assign
        X = np.einsum("hij,pj->hpi", Ts[:, :3, :3], self.points[self.e_pt]) + Ts[:, None, :3, 3]
        d2 = self._boxes.sq_distance(X)  # (H, E)
        rms = np.sqrt(np.add.reduceat(d2, self.g_start, axis=1) / self.g_n)  # (H, G)
        grid = np.full((H, self.K, self.jmax), np.inf)
        grid[:, self.g_k, self.g_slot] = rms
        slot = np.argmin(grid, axis=2)
        best = np.take_along_axis(grid, slot[..., None], axis=2)[..., 0]
        assign = np.where(np.isfinite(best), self.slot_box[np.arange(self.K)[None, :], slot], -1)
        return best, assign


def kappa(rho: np.ndarray, tau: float) -> np.ndarray:
    """Eq. 2 over the last axis: fraction of instances with rho < tau (0 for no instances)."""
    rho = np.atleast_2d(rho)
    if rho.shape[1] == 0:
        return np.zeros(len(rho))
    return (rho < tau).mean(axis=1)


def median_rho(rho: np.ndarray) -> np.ndarray:
    """Tie-breaker of Eq. 2: median best rho over instances that have a same-class box."""
    rho = np.atleast_2d(rho)
    out = np.full(len(rho), np.inf)
    for h in range(len(rho)):
        r = rho[h][np.isfinite(rho[h])]
        if len(r):
            out[h] = float(np.median(r))
    return out
