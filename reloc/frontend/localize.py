"""Localizing one clip: candidates, verification, fallback and refinement (Secs. III-D, III-E).

:func:`localize_clip` is what the front-end calls when a clip closes, and what the unit
experiment (Table I) calls for each independent unit. It never raises on poor input: a clip that
cannot be placed gets ``Placement.S = None`` and a one-line ``reason``.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np

from .clips import Node
from ..config import Config
from ..geometry import rotation_between, yaw_of
from ..map.boxmap import BoxMap
from .observations import Observation
from .refinement import Z, estimate_gravity, orientation_aware, tilt_deg, wall_normals, wall_yaws
from .registration import (Candidate, anchor_candidate, anchors_for_clip, anchors_veto, fallback_candidates,
                           graph_candidate, score_candidates)
from .surface import SurfaceScorer, kappa


@dataclass
class Placement:
    S: np.ndarray | None  # clip -> map, None when the clip could not be placed
    source: str | None = None  # graph | anchors | fallback
    reason: str = ""
    kappa: float = 0.0
    matches: int = 0
    nodes: int = 0
    gravity: str = ""
    info: dict = field(default_factory=dict)
    timings: dict = field(default_factory=dict)

    @property
    def ok(self) -> bool:
        return self.S is not None


def clip_rng(seed: int, first_frame: int) -> np.random.Generator:
    """The random draws of one clip's localization, keyed by the run's seed and the clip's first
    frame. A run-wide generator would hand every later clip other draws as soon as one clip consumed
    a different number of them (one detection more or less changes how many the random route
    draws), so a last-bit change in one clip would reach every clip after it; keyed, it stays in the
    clip where it happened."""
    return np.random.default_rng([int(seed), int(first_frame)])


def localize_clip(nodes: list[Node], frame_obs: dict[int, list[Observation]], V: dict[int, np.ndarray],
                  bmap: BoxMap, cfg: Config, rng: np.random.Generator, yaw_prior: float | None = None,
                  anchors: bool = True, prediction: np.ndarray | None = None) -> Placement:
    """Place one clip. ``prediction`` (tracking, Sec. III-F): the previous clip's placement carried
    over by boundary odometry; accepted and refined when the clip's box-surface support reaches
    ``backend.track_min_kappa``, otherwise the clip is localized afresh with the prediction's yaw
    restricting the orientation fallback."""
    reg, ref = cfg.registration, cfg.refinement
    tm: dict[str, float] = {}
    t0 = time.perf_counter()
    n_nodes = len(nodes)
    if len(bmap) == 0:
        return Placement(None, reason="the map has no boxes", nodes=n_nodes)
    if not nodes:
        return Placement(None, reason="no observations: no detections with valid depth in this clip", nodes=0)
    known = [n for n in nodes if n.cls in bmap.class_set]
    if not known:
        seen = sorted({n.cls for n in nodes})
        return Placement(None, reason=f"none of the observed classes ({', '.join(seen[:5])}) occur in the map",
                         nodes=n_nodes)
    gravity = estimate_gravity(nodes, V, ref)
    scorer = SurfaceScorer(bmap, [n.cls for n in nodes], [n.samples for n in nodes])
    gate = gravity.gate_deg(ref)
    info: dict = {"gravity_planes": gravity.n_planes}
    if prediction is not None:
        rho, _ = scorer.rho(prediction[None])
        k_pred = float(kappa(rho, reg.kappa_tau_m)[0])
        info["tracking_kappa"] = round(k_pred, 3)
        if k_pred >= cfg.backend.track_min_kappa:
            t1 = time.perf_counter()
            S, rinfo = orientation_aware(prediction, nodes, bmap, ref, reg, gravity)
            tm["refinement"] = time.perf_counter() - t1
            rho, _ = scorer.rho(S[None])
            info["refinement"] = rinfo
            return Placement(S=S, source="tracking", kappa=float(kappa(rho, reg.kappa_tau_m)[0]), nodes=n_nodes,
                             gravity=gravity.source, info=info, timings=tm)
        if yaw_prior is None:
            yaw_prior = yaw_of(prediction[:3, :3])

    anchor_rng = rng.spawn(1)[0]  # the anchors' draws do not depend on how many the graph route made
    S_g = graph_candidate(nodes, bmap, reg, rng)
    tm["graph"] = time.perf_counter() - t0
    cands: list[Candidate] = []
    if S_g is not None:
        score_candidates([S_g], nodes, bmap, reg, scorer)
        info["graph"] = {"matches": S_g.matches, "kappa": round(S_g.kappa, 3), **S_g.info}
        cands.append(S_g)
    weak = S_g is None or S_g.matches < reg.min_graph_matches or S_g.kappa < reg.min_graph_surface_fraction
    if anchors and weak:
        t1 = time.perf_counter()
        anc = anchors_for_clip(frame_obs, V, bmap, reg, anchor_rng)
        S_a = anchor_candidate(anc, V, reg)
        info["anchors"] = {"anchors": len(anc), "consensus": S_a.matches if S_a else 0}
        if S_g is not None and anchors_veto(S_g.S, anc, V, reg):
            cands.remove(S_g)
            info["anchors"]["veto"] = True
        if S_a is not None:
            cands.append(S_a)
        tm["anchors"] = time.perf_counter() - t1
    # gravity gate
    passed = [c for c in cands if tilt_deg(c.S[:3, :3], gravity.u) <= gate]
    if len(passed) < len(cands):
        info["gravity_rejected"] = [c.source for c in cands if all(c is not p for p in passed)]
    passed = score_candidates(passed, nodes, bmap, reg, scorer)
    best = passed[0] if passed else None
    if best is None:
        t1 = time.perf_counter()
        R_level = rotation_between(gravity.u, Z)
        yaws = wall_yaws(R_level, wall_normals(nodes)[0], ref.wall_min_horizontal)
        fb = fallback_candidates(nodes, bmap, reg, R_level, yaws, yaw_prior=yaw_prior)
        tm["fallback"] = time.perf_counter() - t1
        if fb:
            best = fb[0]
        else:
            why = ("fewer than three object instances of map classes" if S_g is None else
                   "candidates failed the gravity gate")
            if not len(yaws):
                why += "; no wall normals for the orientation fallback"
            return Placement(None, reason=why, nodes=n_nodes, gravity=gravity.source, info=info, timings=tm)
    t1 = time.perf_counter()
    S, rinfo = orientation_aware(best.S, nodes, bmap, ref, reg, gravity)
    tm["refinement"] = time.perf_counter() - t1
    rho, _ = scorer.rho(S[None])
    k = float(kappa(rho, reg.kappa_tau_m)[0])
    info["refinement"] = rinfo
    info["kappa_before_refinement"] = round(best.kappa, 3)
    return Placement(S=S, source=best.source, kappa=k, matches=best.matches, nodes=n_nodes,
                     gravity=gravity.source, info=info, timings=tm)
