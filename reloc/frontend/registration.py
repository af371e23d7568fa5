"""Clip candidates generation and verification (paper Sec. III-D).

* Hypothesis-first registration: minimal three-pair assignments from the indexed triangle route
  (local object triangles looked up in the map's triangle index) and the random route; each gives
  a rigid transform S_h. The selected h* has the most greedy one-to-one same-class center pairs
  within 0.5 m, then the lowest RMSE, over all hypotheses (:func:`select_hypothesis`); the winner
  refitted on all its pairs is S_g.
* Frame-pose anchors: per-frame RANSAC fits W_i with at least six object inliers, their clip
  proposals W_i V_i^-1 and a consensus S_a (``reloc.frontend.clip_rigid.consensus_fit``); the anchors veto
  S_g when they disagree with it.
* Verification: box-surface consistency kappa (Eq. 2) ranks the candidates.
* Orientation fallback: gravity plus Manhattan yaw, four yaw candidates, each with the translation
  proposal that has the most one-to-one same-class center inliers.

Walls, floors and ceilings never propose centers; they take part in the surface score.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from itertools import combinations

import numpy as np

from vrformats.camera import wrap_angle

from .clip_rigid import consensus_fit, within_sum
from .clips import Node
from ..config import RegistrationConfig
from ..geometry import make_T, non_degenerate_triangles, pose_distance, rigid_fit, rigid_fit_batch, rot_z, yaw_of
from ..map.boxmap import BoxMap, circular_median_mod
from .observations import Observation
from .surface import SurfaceScorer, kappa, median_rho


@dataclass(eq=False)  # compared by identity: fields hold arrays
class Candidate:
    S: np.ndarray
    source: str  # graph | anchors | fallback | tracking | ...
    matches: int = 0
    rmse: float = math.inf
    kappa: float = 0.0
    median_rho: float = math.inf
    info: dict = field(default_factory=dict)

    def rank_key(self):
        return (self.kappa, -self.median_rho)


@dataclass(eq=False)
class Anchor:
    frame: int
    W: np.ndarray  # camera -> map
    inliers: int
    rmse: float


# --------------------------------------------------------------------------------------------
# center matching


class CenterMatcher:
    """Class-compatible (local node, map object) pairs; counts greedy matches for many S."""

    def __init__(self, bmap: BoxMap, classes: list[str], centers: np.ndarray):
        self.map = bmap
        self.X = np.asarray(centers, float).reshape(-1, 3)
        pl, pm = [], []
        for i, c in enumerate(classes):
            for j in bmap.nodes_of(c):
                if bmap.is_object[j]:
                    pl.append(i)
                    pm.append(j)
        order = np.lexsort((pm, pl))
        self.pl = np.asarray(pl, dtype=np.int64)[order]
        self.pm = np.asarray(pm, dtype=np.int64)[order]
        self.Y = bmap.centers[self.pm]
        if len(self.pl):
            self.l_start = np.flatnonzero(np.r_[True, self.pl[1:] != self.pl[:-1]])

    def distances(self, Ts: np.ndarray) -> np.ndarray:
        X = self.X[self.pl]
        Z = np.einsum("hij,pj->hpi", Ts[:, :3, :3], X) + Ts[:, None, :3, 3]
        return np.linalg.norm(Z - self.Y, axis=2)  # (H, P)

    def upper_bound(self, d: np.ndarray, radius: float) -> tuple[np.ndarray, np.ndarray]:
        """(number of local nodes with a pair within radius, sum of their best distances).

        The count lets several local nodes share one map node, so it bounds the number of
        one-to-one pairs from above."""
        near = d < radius
        hit = np.maximum.reduceat(near, self.l_start, axis=1)
        best = np.minimum.reduceat(np.where(near, d, radius), self.l_start, axis=1)
        return hit.sum(axis=1), best.sum(axis=1)

    def greedy(self, d_row: np.ndarray, radius: float) -> list[tuple[int, int, float]]:
        """Non-repeating pairs, closest first: (local, map node, distance)."""
        cand = np.flatnonzero(d_row < radius)
        cand = cand[np.argsort(d_row[cand], kind="stable")]
        used_l, used_m, out = set(), set(), []
        for p in cand:
            li, mj = int(self.pl[p]), int(self.pm[p])
            if li in used_l or mj in used_m:
                continue
            used_l.add(li)
            used_m.add(mj)
            out.append((li, mj, float(d_row[p])))
        return out


def _rmse(pairs) -> float:
    return math.sqrt(sum(p[2] ** 2 for p in pairs) / len(pairs)) if pairs else math.inf


def select_hypothesis(matcher: CenterMatcher, d: np.ndarray, radius: float) -> tuple[int, list]:
    """h* = argmax_h (|A_h|, -e_h) over all hypotheses (rows of ``d``): the most greedy
    one-to-one pairs within radius, then the lowest RMSE; exact ties keep the first in the
    evaluation order. Returns (h*, A_h*), or (-1, []) without hypotheses.

    Hypotheses are evaluated in decreasing order of the many-to-one count (an upper bound on
    |A_h|), and evaluation stops once that bound falls below the best |A_h| found: no hypothesis
    left could win, or tie and then win on RMSE."""
    if not len(d):
        return -1, []
    ub, dsum = matcher.upper_bound(d, radius)
    best_key, best_h, best_pairs = None, -1, []
    for h in np.lexsort((dsum, -ub)):
        if best_key is not None and ub[h] < max(best_key[0], 1):
            break
        pairs = matcher.greedy(d[h], radius)
        key = (len(pairs), -_rmse(pairs))
        if best_key is None or key > best_key:
            best_key, best_h, best_pairs = key, int(h), pairs
    return best_h, best_pairs


# --------------------------------------------------------------------------------------------
# hypothesis-first registration: S_g


def _class_movable(bmap: BoxMap) -> dict[str, bool]:
    out = {}
    for c, idx in bmap.by_class.items():
        out[c] = bool(bmap.movable[idx].any())
    return out


def indexed_assignments(U_cls: list[str], U_c: np.ndarray, U_n: np.ndarray, bmap: BoxMap,
                        cfg: RegistrationConfig) -> list[tuple[np.ndarray, np.ndarray]]:
    """Up to max_indexed_matches (local triple, map triple) assignments from the triangle index."""
    mov = _class_movable(bmap)
    order = sorted(range(len(U_cls)), key=lambda i: (mov.get(U_cls[i], True), -U_n[i], i))
    sel = order[: cfg.max_local_instances]
    if len(sel) < 3:
        return []
    mc = bmap.config
    trip = np.array(list(combinations(sel, 3)), dtype=np.int64)
    # canonical order: by class name (ties keep any order; the index holds every tied order)
    names = sorted(set(U_cls))
    code = np.array([names.index(c) for c in U_cls])
    trip = np.take_along_axis(trip, np.argsort(code[trip], axis=1, kind="stable"), axis=1)
    P = U_c[trip]
    e = np.stack([np.linalg.norm(P[:, 0] - P[:, 1], axis=1), np.linalg.norm(P[:, 0] - P[:, 2], axis=1),
                  np.linalg.norm(P[:, 1] - P[:, 2], axis=1)], axis=1)
    ok = (e >= mc.triangle_edge_min_m).all(axis=1) & (e <= mc.triangle_edge_max_m).all(axis=1)
    ok &= non_degenerate_triangles(P, mc.triangle_min_angle_deg)
    trip, e = trip[ok], e[ok]
    groups: dict[tuple, np.ndarray] = {}
    K = len(names)
    kc = code[trip]
    kk = (kc[:, 0] * K + kc[:, 1]) * K + kc[:, 2]
    for key in np.unique(kk):
        groups[(names[key // (K * K)], names[(key // K) % K], names[key % K])] = np.flatnonzero(kk == key)
    found_l, found_m, found_mov, found_err = [], [], [], []
    tol = cfg.triangle_edge_tol_m
    for key, rows in groups.items():
        ts = bmap.triangles.get(key)
        if ts is None:
            continue
        le = e[rows]
        chunk = max(1, 2_000_000 // max(1, len(ts.edges)))
        for a in range(0, len(rows), chunk):
            diff = np.abs(le[a:a + chunk, None, :] - ts.edges[None, :, :])
            hit = (diff <= tol).all(axis=2)
            li, mi = np.nonzero(hit)
            if len(li):
                found_l.append(trip[rows[a + li]])
                found_m.append(ts.verts[mi])
                found_mov.append(ts.movable[mi])
                found_err.append(diff[li, mi].sum(axis=1))
    if not found_l:
        return []
    L, M = np.concatenate(found_l), np.concatenate(found_m)
    mv, err = np.concatenate(found_mov), np.concatenate(found_err)
    best = np.lexsort((err, mv))[: cfg.max_indexed_matches]
    return [(L[i], M[i]) for i in best]


def random_assignments(U_cls: list[str], U_c: np.ndarray, bmap: BoxMap, cfg: RegistrationConfig,
                       rng: np.random.Generator) -> list[tuple[np.ndarray, np.ndarray]]:
    """Random route: three distinct local instances to distinct same-class map nodes, favouring
    map nodes whose distances to the ones already chosen agree with the local distances."""
    n = len(U_cls)
    if n < 3:
        return []
    cands = [np.array([j for j in bmap.nodes_of(c) if bmap.is_object[j]], dtype=np.int64) for c in U_cls]
    cmax = max(len(c) for c in cands)
    if cmax == 0:
        return []
    pad = np.full((n, cmax), -1, dtype=np.int64)
    for i, c in enumerate(cands):
        pad[i, : len(c)] = c
    D = cfg.random_draws
    loc = rng.random((D, n)).argsort(axis=1)[:, :3]
    chosen = np.full((D, 3), -1, dtype=np.int64)
    tol = cfg.triangle_edge_tol_m
    rows = np.arange(D)
    for k in range(3):
        pool = pad[loc[:, k]]  # (D, cmax)
        valid = pool >= 0
        for prev in range(k):
            valid &= pool != chosen[:, prev:prev + 1]
        pref = valid.copy()
        for prev in range(k):
            dl = np.linalg.norm(U_c[loc[:, k]] - U_c[loc[:, prev]], axis=1)
            pm = np.where(pool >= 0, pool, 0)
            dm = np.linalg.norm(bmap.centers[pm] - bmap.centers[np.maximum(chosen[:, prev], 0)][:, None, :], axis=2)
            pref &= np.abs(dm - dl[:, None]) <= tol
        use = np.where(pref.any(axis=1, keepdims=True), pref, valid)
        key = np.where(use, rng.random(use.shape), -1.0)
        pick = np.argmax(key, axis=1)
        ok = use[rows, pick]
        chosen[:, k] = np.where(ok, pool[rows, pick], -1)
    good = (chosen >= 0).all(axis=1)
    return [(loc[d], chosen[d]) for d in np.flatnonzero(good)]


def graph_candidate(nodes: list[Node], bmap: BoxMap, cfg: RegistrationConfig, rng: np.random.Generator,
                    indexed: bool = True, random_route: bool = True) -> Candidate | None:
    """S_g of Sec. III-D, or None when no hypothesis explains three centers."""
    U = [k for k, nd in enumerate(nodes) if not nd.structure and nd.cls in bmap.object_classes]
    if len(U) < 3:
        return None
    U_cls = [nodes[k].cls for k in U]
    U_c = np.array([nodes[k].center for k in U])
    U_n = np.array([len(nodes[k].samples) for k in U])
    assign = []
    if indexed:
        assign += indexed_assignments(U_cls, U_c, U_n, bmap, cfg)
    n_indexed = len(assign)
    if random_route:
        assign += random_assignments(U_cls, U_c, bmap, cfg, rng)
    if not assign:
        return None
    Xs = np.stack([U_c[a] for a, _ in assign])
    Ys = np.stack([bmap.centers[m] for _, m in assign])
    Ts = rigid_fit_batch(Xs, Ys)
    matcher = CenterMatcher(bmap, U_cls, U_c)
    h, pairs = select_hypothesis(matcher, matcher.distances(Ts), cfg.center_match_m)
    if len(pairs) < 3:
        return None
    S = rigid_fit(U_c[[p[0] for p in pairs]], bmap.centers[[p[1] for p in pairs]])
    # the refit can change which centers agree: report the refitted pairs
    pairs2 = matcher.greedy(matcher.distances(S[None])[0], cfg.center_match_m)
    src = "indexed" if h < n_indexed else "random"
    return Candidate(S=S, source="graph", matches=len(pairs2), rmse=_rmse(pairs2),
                     info={"route": src, "hypotheses": len(assign), "indexed": n_indexed,
                           "local_instances": len(U)})


# --------------------------------------------------------------------------------------------
# frame-pose anchors: S_a


def frame_anchor(frame: int, obs: list[Observation], bmap: BoxMap, cfg: RegistrationConfig,
                 rng: np.random.Generator) -> tuple[np.ndarray, int, float] | None:
    """Per-frame RANSAC: (W camera->map, inliers, center RMSE) or None.

    Inliers are object instances within ``anchor_inlier_m`` of a same-class box (box-surface
    test); walls, floors and ceilings are not counted, so "at least six inliers" means six objects.
    """
    objs = [o for o in obs if not o.structure and o.cls in bmap.object_classes]
    if len(objs) < 3:
        return None
    scorer = SurfaceScorer(bmap, [o.cls for o in objs], [o.samples for o in objs])
    cands = [np.array([j for j in bmap.nodes_of(o.cls) if bmap.is_object[j]]) for o in objs]
    C = np.array([o.center for o in objs])
    n_it = cfg.anchor_ransac_iterations
    picks = rng.random((n_it, len(objs))).argsort(axis=1)[:, :3]
    X, Y = [], []
    for a in picks:
        m = []
        for li in a:
            pool = cands[li][~np.isin(cands[li], m)]
            if not len(pool):
                break
            m.append(int(pool[rng.integers(len(pool))]))
        if len(m) == 3:
            X.append(C[a])
            Y.append(bmap.centers[m])
    if not X:
        return None
    Ts = rigid_fit_batch(np.array(X), np.array(Y))
    rho, _ = scorer.rho(Ts)
    score = (rho < cfg.anchor_inlier_m).sum(axis=1)
    h = int(np.argmax(score))
    T = Ts[h]
    for _ in range(cfg.anchor_refits):  # refit the winner on its inliers' assigned box centers
        rho1, asg1 = scorer.rho(T[None])
        inl = np.flatnonzero(rho1[0] < cfg.anchor_inlier_m)
        if len(inl) < 3:
            break
        T = rigid_fit(C[inl], bmap.centers[asg1[0, inl]])
    rho1, asg1 = scorer.rho(T[None])
    inl = np.flatnonzero(rho1[0] < cfg.anchor_inlier_m)
    if len(inl) < 3:
        return None
    res = (C[inl] @ T[:3, :3].T + T[:3, 3]) - bmap.centers[asg1[0, inl]]
    rmse = float(np.sqrt((res ** 2).sum(axis=1).mean()))
    return T, len(inl), rmse


def anchors_for_clip(frame_obs: dict[int, list[Observation]], V: dict[int, np.ndarray], bmap: BoxMap,
                     cfg: RegistrationConfig, rng: np.random.Generator) -> list[Anchor]:
    out = []
    for f in sorted(frame_obs):
        if f not in V:
            continue
        r = frame_anchor(f, frame_obs[f], bmap, cfg, rng)
        if r is None:
            continue
        W, inliers, rmse = r
        if inliers >= cfg.anchor_min_inliers and rmse <= cfg.anchor_max_rmse_m:
            out.append(Anchor(frame=f, W=W, inliers=inliers, rmse=rmse))
    out.sort(key=lambda a: (-a.inliers, a.rmse))
    return out[: cfg.max_anchors]


def anchor_candidate(anchors: list[Anchor], V: dict[int, np.ndarray], cfg: RegistrationConfig) -> Candidate | None:
    """S_a: the proposal W_i V_i^-1 supported by the most anchors (translation distance plus
    rotation angle below ``anchor_consensus``), refined over its supporters: a rotation average and
    the corresponding mean translation. None with fewer than ``anchor_min_support`` supporters."""
    if len(anchors) < cfg.anchor_min_support:
        return None
    S, ok = consensus_fit(np.stack([a.W for a in anchors]), np.stack([V[a.frame] for a in anchors]),
                          within_sum(cfg.anchor_consensus), cfg.anchor_min_support)
    if S is None:
        return None
    return Candidate(S=S, source="anchors", matches=int(ok.sum()),
                     info={"anchors": len(anchors), "support": int(ok.sum())})


def anchors_veto(S: np.ndarray, anchors: list[Anchor], V: dict[int, np.ndarray], cfg: RegistrationConfig) -> bool:
    """True when the anchors' median disagreement with S exceeds 1.5 m or 40 degrees."""
    if len(anchors) < cfg.anchor_min_support:
        return False
    dts, drs = zip(*(pose_distance(S @ V[a.frame], a.W) for a in anchors))
    return bool(np.median(dts) > cfg.veto_translation_m or math.degrees(np.median(drs)) > cfg.veto_rotation_deg)


# --------------------------------------------------------------------------------------------
# verification


def score_candidates(cands: list[Candidate], nodes: list[Node], bmap: BoxMap, cfg: RegistrationConfig,
                     scorer: SurfaceScorer | None = None) -> list[Candidate]:
    """Fill kappa and the median-rho tie-breaker; return the candidates best first."""
    if not cands:
        return []
    scorer = scorer or SurfaceScorer(bmap, [n.cls for n in nodes], [n.samples for n in nodes])
    rho, _ = scorer.rho(np.stack([c.S for c in cands]))
    kap = kappa(rho, cfg.kappa_tau_m)
    med = median_rho(rho)
    for c, k, m in zip(cands, kap, med):
        c.kappa, c.median_rho = float(k), float(m)
    return sorted(cands, key=lambda c: c.rank_key(), reverse=True)


# --------------------------------------------------------------------------------------------
# orientation fallback


def fallback_candidates(nodes: list[Node], bmap: BoxMap, cfg: RegistrationConfig, R_level: np.ndarray,
                        wall_yaws: np.ndarray, yaw_prior: float | None = None) -> list[Candidate]:
    """Four yaw candidates about +Z after levelling; for each, every same-class local/map center
    pair proposes a translation, and the proposal with the most one-to-one inliers (then the
    lowest RMSE) is replaced by the mean offset over those inliers.

    R_level takes the clip's gravity direction to +Z; wall_yaws are the horizontal directions of
    the levelled wall normals (radians). Returns scored candidates (object instances only), best first.
    """
    if not len(wall_yaws):
        return []
    psi0 = bmap.manhattan_yaw - circular_median_mod(np.asarray(wall_yaws), period=math.pi / 2)
    objs = [n for n in nodes if not n.structure and n.cls in bmap.object_classes]
    if not objs:
        return []
    cls = [n.cls for n in objs]
    X = np.array([n.center for n in objs])
    matcher = CenterMatcher(bmap, cls, X)
    if not len(matcher.pl):
        return []
    out = []
    for k in range(4):
        R = rot_z(psi0 + k * math.pi / 2) @ R_level
        if yaw_prior is not None:
            dy = abs(wrap_angle(yaw_of(R) - yaw_prior))
            if dy > math.radians(cfg.fallback_yaw_window_deg):
                continue
        # every class-compatible pair proposes t = y - R x
        t_all = matcher.Y - X[matcher.pl] @ R.T
        Ts = np.tile(np.eye(4), (len(t_all), 1, 1))
        Ts[:, :3, :3] = R
        Ts[:, :3, 3] = t_all
        _, pairs = select_hypothesis(matcher, matcher.distances(Ts), cfg.fallback_inlier_m)
        if not pairs:
            continue
        t = np.mean([bmap.centers[m] - R @ X[li] for li, m, _ in pairs], axis=0)
        out.append(Candidate(S=make_T(R, t), source="fallback", matches=len(pairs), rmse=_rmse(pairs),
                             info={"yaw_k": k}))
    obj_nodes = [n for n in nodes if not n.structure]
    return score_candidates(out, obj_nodes, bmap, cfg)
