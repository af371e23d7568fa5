"""Adaptive clips and per-clip graph construction (paper Sec. III-C).

A clip is an odometry-connected run of frames with within-clip poses V_i (camera to clip
coordinates, V of the first frame = identity). Its observations (every fifth frame and the last
frame) are mapped into clip coordinates and fused: connected components of nearby same-class
observations become nodes k with class, mean center and accumulated surface samples P_k. That
node set is the clip's local scene graph L_c that registration places in the map.

Clips start at 100 frames and grow by 50 up to 600; a clip closes at a checkpoint once it has at
least 20 nodes and 2 m of camera path, and ends early at a capture gap or inconsistent odometry
(:class:`ClipPolicy`).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components

from vrformats.boxes import STRUCTURE_KINDS

from ..config import ClipConfig, ObservationConfig
from ..geometry import farthest_point_sample
from .observations import Observation


@dataclass
class Node:
    cls: str
    center: np.ndarray  # (3,) clip frame
    samples: np.ndarray  # (n, 3) clip frame
    n_obs: int
    frames: list[int]
    normals: np.ndarray | None = None  # (m, 3) observation plane normals (structure)

    @property
    def structure(self) -> bool:
        return self.cls in STRUCTURE_KINDS


@dataclass
class Clip:
    """Frames, within-clip poses and observations of one clip."""

    id: int
    start: int
    frames: list[int] = field(default_factory=list)
    V: dict[int, np.ndarray] = field(default_factory=dict)
    observations: list[Observation] = field(default_factory=list)  # camera frame
    observed_frames: set[int] = field(default_factory=set)
    end_reason: str = ""  # "closed" | "gap: ..." | "end of tour" | "max length"

    def __len__(self) -> int:
        return len(self.frames)

    @property
    def end(self) -> int:
        return self.frames[-1]

    def path_length(self) -> float:
        if len(self.frames) < 2:
            return 0.0
        P = np.array([self.V[i][:3, 3] for i in self.frames])
        return float(np.linalg.norm(np.diff(P, axis=0), axis=1).sum())

    def clip_observations(self) -> list[Observation]:
        """Observations mapped into clip coordinates by their frame's V_i."""
        return [o.transformed(self.V[o.frame]) for o in self.observations if o.frame in self.V]

    def frame_observations(self) -> dict[int, list[Observation]]:
        out: dict[int, list[Observation]] = {}
        for o in self.observations:
            out.setdefault(o.frame, []).append(o)
        return out


def fuse(observations: list[Observation], cfg: ObservationConfig | None = None) -> list[Node]:
    """Connected components of nearby same-class observations (clip frame) -> nodes. Walls join
    by plane (similar normals, small plane offset), floors and ceilings by a wider radius."""
    cfg = cfg or ObservationConfig()
    by_class: dict[str, list[Observation]] = {}
    for o in observations:
        by_class.setdefault(o.cls, []).append(o)
    nodes: list[Node] = []
    for cls in sorted(by_class):
        obs = by_class[cls]
        C = np.array([o.center for o in obs])
        D = np.linalg.norm(C[:, None] - C[None], axis=-1)
        if cls == "wall":
            N = np.array([o.normal if o.normal is not None else np.zeros(3) for o in obs])
            has = np.linalg.norm(N, axis=1) > 0.5
            cosang = np.abs(N @ N.T)
            offset = np.abs(np.einsum("ij,ikj->ik", N, C[None, :, :] - C[:, None, :]))  # |n_i . (c_k - c_i)|
            A = (has[:, None] & has[None, :] & (cosang >= np.cos(np.radians(cfg.wall_fusion_normal_deg)))
                 & (offset <= cfg.wall_fusion_offset_m) & (offset.T <= cfg.wall_fusion_offset_m)
                 & (D <= cfg.wall_fusion_radius_m))
            A |= (~has[:, None] | ~has[None, :]) & (D <= cfg.fusion_radius_m)
        elif cls in ("floor", "ceiling"):
            A = D <= cfg.floor_fusion_radius_m
        else:
            A = D <= cfg.fusion_radius_m
        n_comp, labels = connected_components(coo_matrix(A), directed=False)
        for c in range(n_comp):
            members = [obs[i] for i in np.flatnonzero(labels == c)]
            S = np.concatenate([o.samples for o in members])
            if len(S) > cfg.max_node_samples:
                S = S[farthest_point_sample(S, cfg.max_node_samples)]
            normals = [o.normal for o in members if o.normal is not None]
            nodes.append(Node(
                cls=cls,
                center=np.mean([o.center for o in members], axis=0),
                samples=S,
                n_obs=len(members),
                frames=sorted({o.frame for o in members}),
                normals=np.array(normals) if normals else None,
            ))
    return nodes


class ClipPolicy:
    """When a growing clip closes (Sec. IV-A)."""

    def __init__(self, cfg: ClipConfig | None = None):
        self.cfg = cfg or ClipConfig()

    def is_checkpoint(self, length: int) -> bool:
        c = self.cfg
        if not c.adaptive:
            return length == c.start_frames
        return length >= c.start_frames and (length - c.start_frames) % c.grow_frames == 0

    def should_close(self, length: int, n_nodes: int, path_m: float) -> bool:
        c = self.cfg
        if not c.adaptive:
            return length >= c.start_frames
        if length >= c.max_frames:
            return True
        return self.is_checkpoint(length) and n_nodes >= c.min_nodes and path_m >= c.min_path_m
