"""Orientation cues and orientation-aware refinement (paper Sec. III-E).

* Gravity: the clip-frame vertical u from floor/ceiling plane normals and the direction
  orthogonal to wall normals, else the mean camera-up direction of the clip's frames. (The
  paper's first choice, detector box up-axes, needs a 3D box detector; the oracle and ONNX
  detectors give masks only.) A candidate passes the gravity gate when angle(R u, +Z) is at most
  30 degrees (60 for the camera-up fallback) and is then levelled about the clip centroid.
* Manhattan yaw: levelled wall normals should point along the map's Manhattan axes; a correction
  is accepted with normals of at least five distinct walls (fused wall nodes, not observations:
  one wall seen five times is one wall) whose deviations (mod 90 degrees) have a circular MAD of
  at most 12 degrees; their circular median is the correction.
* Refinement (Eq. 3): Gauss-Newton on a left perturbation about the mapped clip centroid of
  one-sided point-to-box residuals over consistent instances (each instance weighted 1/|P_k|),
  the gravity (tilt) residual and a prior on the change from the input transform; assignments and
  closest points are recomputed every iteration.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from .clips import Node
from ..config import RefinementConfig, RegistrationConfig
from ..geometry import BoxSet, exp_so3, log_so3, make_T, rigid_fit, rot_z, rotation_between
from ..map.boxmap import BoxMap, circular_mad_mod, circular_median_mod
from .surface import SurfaceScorer

Z = np.array([0.0, 0.0, 1.0])


@dataclass
class Gravity:
    u: np.ndarray  # unit clip-frame vertical
    source: str  # structure | camera_up
    n_planes: int = 0

    def gate_deg(self, cfg: RefinementConfig) -> float:
        return cfg.gravity_gate_camera_up_deg if self.source == "camera_up" else cfg.gravity_gate_deg


def camera_up(V: dict[int, np.ndarray]) -> np.ndarray:
    """Mean camera-up direction (OpenCV: -y) of the frames in clip coordinates."""
    ups = np.array([-T[:3, 1] for T in V.values()])
    u = ups.mean(axis=0)
    return u / np.linalg.norm(u)


def estimate_gravity(nodes: list[Node], V: dict[int, np.ndarray], cfg: RefinementConfig | None = None) -> Gravity:
    """The clip-frame vertical from floor/ceiling normals and the direction orthogonal to wall
    normals, else the camera-up direction."""
    cfg = cfg or RefinementConfig()
    cam_u = camera_up(V)
    ups = []
    for n in nodes:
        if n.normals is None or n.cls not in ("floor", "ceiling"):
            continue
        for nv in n.normals:  # normals face the camera: up for floors, down for ceilings
            ups.append(nv if n.cls == "floor" else -nv)
    walls = [nv for n in nodes if n.cls == "wall" and n.normals is not None for nv in n.normals]
    u = np.sum(ups, axis=0) if ups else np.zeros(3)
    n_planes = len(ups)
    if len(walls) >= 2:
        W = np.array(walls)
        _, s, Vt = np.linalg.svd(W, full_matrices=False)
        if len(s) >= 2 and s[1] > cfg.gravity_wall_spread * s[0]:  # two clearly different wall directions
            w = Vt[-1] if len(Vt) == 3 else np.cross(Vt[0], Vt[1])
            w = w / np.linalg.norm(w)
            if w @ cam_u < 0:
                w = -w
            u = u + len(walls) * w
            n_planes += len(walls)
    if n_planes and np.linalg.norm(u) > 1e-9:
        u = u / np.linalg.norm(u)
        if u @ cam_u > math.cos(math.radians(cfg.gravity_max_from_camera_up_deg)):  # a plausible vertical
            return Gravity(u=u, source="structure", n_planes=n_planes)
    return Gravity(u=cam_u, source="camera_up")


def tilt_deg(R: np.ndarray, u: np.ndarray) -> float:
    return math.degrees(math.acos(max(-1.0, min(1.0, float((R @ u) @ Z)))))


def level(S: np.ndarray, u: np.ndarray, centroid: np.ndarray) -> np.ndarray:
    """S rotated about the mapped clip centroid so that R u points along +Z."""
    R = S[:3, :3]
    Rc = rotation_between(R @ u, Z)
    c_map = S[:3, :3] @ centroid + S[:3, 3]
    R2 = Rc @ R
    return make_T(R2, c_map - R2 @ centroid)


def rotate_about_z(S: np.ndarray, yaw: float, centroid: np.ndarray) -> np.ndarray:
    c_map = S[:3, :3] @ centroid + S[:3, 3]
    R2 = rot_z(yaw) @ S[:3, :3]
    return make_T(R2, c_map - R2 @ centroid)


def wall_normals(nodes: list[Node]) -> tuple[np.ndarray, np.ndarray]:
    """Clip-frame plane normals of the wall observations (m, 3), and the distinct wall each was
    seen on (m,): the index of its fused wall node. A wall seen five times gives five normals of
    one wall."""
    ns, ws = [], []
    for k, n in enumerate(nodes):
        if n.cls == "wall" and n.normals is not None:
            ns += list(n.normals)
            ws += [k] * len(n.normals)
    return np.array(ns, float).reshape(-1, 3), np.array(ws, dtype=np.int64)


def horizontal(R: np.ndarray, normals: np.ndarray, min_horizontal: float) -> np.ndarray:
    """Mask of the clip-frame normals whose direction rotated by R is near horizontal (its
    horizontal part at least ``min_horizontal``): the ones that give a yaw."""
    if not len(normals):
        return np.zeros(0, bool)
    return np.linalg.norm((normals @ R.T)[:, :2], axis=1) > min_horizontal


def wall_yaws(R: np.ndarray, normals: np.ndarray,
              min_horizontal: float = RefinementConfig.wall_min_horizontal) -> np.ndarray:
    """Horizontal directions (radians) of clip-frame wall normals rotated by R; near-vertical ones dropped."""
    if not len(normals):
        return np.empty(0)
    m = normals @ R.T
    keep = horizontal(R, normals, min_horizontal)
    return np.arctan2(m[keep, 1], m[keep, 0])


def distinct_walls(R: np.ndarray, normals: np.ndarray, walls: np.ndarray | None, min_horizontal: float) -> int:
    """Number of distinct walls with a normal that gives a yaw under R (``walls`` None: one wall per normal)."""
    keep = horizontal(R, normals, min_horizontal)
    return int(keep.sum()) if walls is None else len(np.unique(np.asarray(walls)[keep]))


def manhattan_correction(S: np.ndarray, normals: np.ndarray, bmap: BoxMap, cfg: RefinementConfig,
                         centroid: np.ndarray, walls: np.ndarray | None = None) -> tuple[np.ndarray, dict]:
    """Yaw correction from wall normals (accepted or not) and what was measured. ``walls``: the
    distinct wall of each normal (``wall_normals``); at least ``manhattan_min_normals`` distinct
    walls are needed, their observations' normals give the median and its MAD."""
    R = S[:3, :3]
    yaws = wall_yaws(R, normals, cfg.wall_min_horizontal)
    n_walls = distinct_walls(R, normals, walls, cfg.wall_min_horizontal)
    info = {"normals": int(len(yaws)), "walls": n_walls, "accepted": False}
    if n_walls < cfg.manhattan_min_normals:
        return S, info
    dev = yaws - bmap.manhattan_yaw
    period = math.pi / 2
    med = circular_median_mod(dev, period=period)
    mad = circular_mad_mod(dev, med, period)
    info.update(median_deg=math.degrees(med), mad_deg=math.degrees(mad))
    if math.degrees(mad) > cfg.manhattan_max_mad_deg:
        return S, info
    info["accepted"] = True
    return rotate_about_z(S, -med, centroid), info


def _skew(v: np.ndarray) -> np.ndarray:
    """(..., 3) -> (..., 3, 3) cross-product matrices."""
    O = np.zeros(v.shape[:-1] + (3, 3))
    O[..., 0, 1], O[..., 0, 2] = -v[..., 2], v[..., 1]
    O[..., 1, 0], O[..., 1, 2] = v[..., 2], -v[..., 0]
    O[..., 2, 0], O[..., 2, 1] = -v[..., 1], v[..., 0]
    return O


def refine(S0: np.ndarray, nodes: list[Node], bmap: BoxMap, cfg: RefinementConfig, reg: RegistrationConfig,
           gravity: Gravity | None, scorer: SurfaceScorer | None = None) -> tuple[np.ndarray, dict]:
    """Eq. 3 from input S0; returns the refined transform and diagnostics."""
    if scorer is None:
        scorer = SurfaceScorer(bmap, [n.cls for n in nodes], [n.samples for n in nodes])
    if not cfg.orientation_aware:
        return refine_point_to_point(S0, nodes, bmap, cfg, reg, scorer)
    centroid = _centroid(nodes)
    sig_f = cfg.sigma_f_m
    sig_g = math.radians(cfg.sigma_g_deg)
    sig_r = math.radians(cfg.prior_rotation_deg)
    sig_t = cfg.prior_translation_m
    R0, c0 = S0[:3, :3], S0[:3, :3] @ centroid + S0[:3, 3]
    boxes = BoxSet(bmap.centers, bmap.sizes, bmap.yaws)
    S = S0.copy()
    used = 0
    for it in range(cfg.iterations):
        rho, asg = scorer.rho(S[None])
        rho, asg = rho[0], asg[0]
        consistent = np.flatnonzero(rho < reg.kappa_tau_m)
        used = len(consistent)
        c_map = S[:3, :3] @ centroid + S[:3, 3]
        Js, rs = [], []
        for k in consistent:
            P = nodes[k].samples @ S[:3, :3].T + S[:3, 3]
            box = boxes[int(asg[k])]
            e = box.excess(P)  # box-frame displacement from the closest box point, zero on free axes
            out = e != 0.0
            outside = out.any(axis=1)
            if not outside.any():
                continue
            r = e[outside]
            Rb = box.rotation()
            w = 1.0 / (sig_f * math.sqrt(len(P)))
            Pw = P[outside]
            Jw = np.concatenate([-_skew(Pw - c_map), np.broadcast_to(np.eye(3), (len(Pw), 3, 3))], axis=2)
            Jl = np.einsum("ji,pjk->pik", Rb, Jw) * out[outside][..., None]  # rows of free axes zeroed
            Js.append(Jl.reshape(-1, 6) * w)
            rs.append(r.reshape(-1) * w)
        if gravity is not None:
            g = S[:3, :3] @ gravity.u
            Jg = np.zeros((2, 6))
            Jg[:, :3] = -_skew(g)[:2]
            Js.append(Jg / sig_g)
            rs.append(g[:2] / sig_g)
        # prior on the change from S0 (rotation, and translation of the mapped centroid)
        Jp = np.zeros((6, 6))
        Jp[:3, :3] = np.eye(3) / sig_r
        Jp[3:, 3:] = np.eye(3) / sig_t
        Js.append(Jp)
        rs.append(np.concatenate([log_so3(S[:3, :3] @ R0.T) / sig_r, (c_map - c0) / sig_t]))
        J, r = np.concatenate(Js), np.concatenate(rs)
        delta = -np.linalg.solve(J.T @ J + 1e-9 * np.eye(6), J.T @ r)
        Rd = exp_so3(delta[:3])
        R2 = Rd @ S[:3, :3]
        c2 = c_map + delta[3:]
        S = make_T(R2, c2 - R2 @ centroid)
        if np.linalg.norm(delta[:3]) < 1e-5 and np.linalg.norm(delta[3:]) < 1e-4:
            break
    return S, {"iterations": it + 1, "consistent": int(used)}


def refine_point_to_point(S0, nodes, bmap, cfg, reg, scorer) -> tuple[np.ndarray, dict]:
    """Ablation (Table III): refit on consistent object centers and their boxes' centers."""
    S = S0.copy()
    used = 0
    for it in range(cfg.iterations):
        rho, asg = scorer.rho(S[None])
        ks = [k for k in np.flatnonzero(rho[0] < reg.kappa_tau_m) if not nodes[k].structure]
        used = len(ks)
        if len(ks) < 3:
            break
        S_new = rigid_fit(np.array([nodes[k].center for k in ks]), bmap.centers[asg[0, ks]])
        done = np.allclose(S_new, S, atol=1e-6)
        S = S_new
        if done:
            break
    return S, {"iterations": it + 1, "consistent": int(used)}


def _centroid(nodes: list[Node]) -> np.ndarray:
    if not nodes:
        return np.zeros(3)
    return np.mean([n.center for n in nodes], axis=0)


def orientation_aware(S0: np.ndarray, nodes: list[Node], bmap: BoxMap, cfg: RefinementConfig,
                      reg: RegistrationConfig, gravity: Gravity) -> tuple[np.ndarray, dict]:
    """The cue sequence of Sec. III-E: level, refine, Manhattan yaw, refine again if corrected."""
    scorer = SurfaceScorer(bmap, [n.cls for n in nodes], [n.samples for n in nodes])
    centroid = _centroid(nodes)
    info: dict = {}
    if not cfg.orientation_aware:
        S, r = refine_point_to_point(S0, nodes, bmap, cfg, reg, scorer)
        info["refine"] = r
        return S, info
    S = level(S0, gravity.u, centroid)
    S, info["refine"] = refine(S, nodes, bmap, cfg, reg, gravity, scorer)
    normals, walls = wall_normals(nodes)
    S2, info["manhattan"] = manhattan_correction(S, normals, bmap, cfg, centroid, walls)
    if info["manhattan"]["accepted"]:
        S, info["refine2"] = refine(S2, nodes, bmap, cfg, reg, gravity, scorer)
    return S, info
