"""The streaming front-end: frames in, placed clips out (paper Secs. III-C to III-E).

:class:`FrontEnd` takes frames one at a time. A pose stream (RGB-D odometry, or ground truth for
experiments that isolate registration) gives each frame its pose in the current odometry chain;
a chain break (capture gap, inconsistent odometry) ends the clip. Every fifth frame of the video
(frame index a multiple of ``observation.stride``: where a render job with ``rgb_every`` 5 puts
RGB) and a clip's last frame are detected and observed (a detector that needs RGB finds nothing on
a last frame without it); at each checkpoint (100, 150, ... 600 frames) the
observations are fused and the clip closes once it has enough nodes and camera travel. A closed
clip is localized (:func:`reloc.frontend.localize.localize_clip`) and returned as a :class:`ClipResult`.

Within one chain, consecutive clips are connected by boundary odometry
``O_c = chain_pose(p)^-1 chain_pose(q)`` between the last frame p of clip c and the first frame q
of clip c+1, which the back-end uses for tracking and runs.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from typing import Callable, Protocol

import numpy as np

from .clips import Clip, ClipPolicy, Node, fuse
from ..config import Config
from ..detection.base import Detector, FrameData, needs_labels
from ..detection.oracle import OracleDetector
from ..geometry import inv_T
from .localize import Placement, clip_rng, localize_clip
from ..map.boxmap import BoxMap
from .observations import observe

STAGES = ("io", "odometry", "detection", "observation", "registration", "refinement")


@dataclass
class PoseEvent:
    index: int
    pose: np.ndarray | None  # camera -> chain coordinates; None: no usable depth, in no clip
    new_chain: bool = False  # this frame starts a new chain (first frame, or after a break)
    reason: str = ""  # why the previous chain ended


class PoseStream(Protocol):
    def add(self, frame: FrameData, gt_pose: np.ndarray | None = None) -> list[PoseEvent]: ...

    def flush(self) -> list[PoseEvent]: ...


class GroundTruthPoses:
    """Within-clip poses from the tour's ground truth (isolates registration from odometry)."""

    name = "gt"

    def __init__(self):
        self._first = True

    def add(self, frame: FrameData, gt_pose=None) -> list[PoseEvent]:
        if gt_pose is None:
            raise ValueError("ground-truth poses need the frame's pose")
        ev = PoseEvent(frame.index, np.asarray(gt_pose, float), new_chain=self._first)
        self._first = False
        return [ev]

    def flush(self) -> list[PoseEvent]:
        return []


class OdometryPoses:
    """Within-clip poses from RGB-D odometry (:class:`reloc.frontend.odometry.OdometryChain`)."""

    name = "odometry"

    def __init__(self, K, width: int, height: int, config=None):
        from .odometry import OdometryChain

        self.chain = OdometryChain(K, width, height, config)
        self.use_rgb = self.chain.config.method == "hybrid"

    def _events(self, poses) -> list[PoseEvent]:
        return [PoseEvent(c.frame_index, c.V, new_chain=c.new_clip, reason=c.reason) for c in poses]

    def add(self, frame: FrameData, gt_pose=None) -> list[PoseEvent]:
        return self._events(self.chain.add(frame.index, frame.depth, frame.rgb if self.use_rgb else None))

    def flush(self) -> list[PoseEvent]:
        return self._events(self.chain.flush())


class StaticPoses:
    """Identity for every frame: enough for one-frame units, where V_i = I by definition."""

    name = "none"

    def __init__(self):
        self._first = True

    def add(self, frame: FrameData, gt_pose=None) -> list[PoseEvent]:
        ev = PoseEvent(frame.index, np.eye(4), new_chain=self._first)
        self._first = False
        return [ev]

    def flush(self) -> list[PoseEvent]:
        return []


@dataclass
class ClipResult:
    clip: Clip
    nodes: list[Node]
    placement: Placement
    chain: int  # odometry chain (a run candidate): clips of one chain are connected
    chain_poses: dict[int, np.ndarray]  # frame -> camera-to-chain pose (first and last frames)
    timings: dict = field(default_factory=dict)

    @property
    def S(self) -> np.ndarray | None:
        return self.placement.S

    def frame_poses(self, S: np.ndarray | None = None) -> dict[int, np.ndarray]:
        """T_i = S V_i for every frame of the clip (Eq. 1)."""
        S = self.placement.S if S is None else S
        if S is None:
            return {}
        return {i: S @ V for i, V in self.clip.V.items()}


class FrontEnd:
    def __init__(self, bmap: BoxMap, K: np.ndarray, detector: Detector, poses: PoseStream,
                 config: Config | None = None, seed: int = 0, localize: bool = True,
                 yaw_prior: Callable[[Clip], float | None] | None = None,
                 predict: Callable[[int, np.ndarray], np.ndarray | None] | None = None,
                 on_frame: Callable[[PoseEvent, "Clip | None", int], None] | None = None):
        self.map = bmap
        self.K = np.asarray(K, float)
        self.detector = detector
        self.poses = poses
        self.cfg = config or Config()
        self.policy = ClipPolicy(self.cfg.clips)
        self.seed = int(seed)  # a clip's random draws come from clip_rng(seed, its first frame)
        self.localize = localize
        self.yaw_prior = yaw_prior
        self.predict = predict  # (chain, camera-to-chain pose of the clip's first frame) -> S_pred
        self.on_frame = on_frame  # called for every frame once it has a pose (or has none)
        self.timings = {s: 0.0 for s in STAGES}
        self.frames_in = 0
        self._pending: dict[int, FrameData] = {}
        self._clip: Clip | None = None
        self._chain = -1
        self._chain_pose: dict[int, np.ndarray] = {}
        self._clip_start_pose: np.ndarray | None = None
        self._last: FrameData | None = None
        self._next_id = 0
        self.unposed: list[int] = []  # frames without a pose (no usable depth)

    # -- streaming -------------------------------------------------------------------------------

    def add(self, frame: FrameData, gt_pose: np.ndarray | None = None) -> list[ClipResult]:
        t = time.perf_counter()
        events = self.poses.add(frame, gt_pose)
        self.timings["odometry"] += time.perf_counter() - t
        return self.feed(frame, events)

    def feed(self, frame: FrameData, events: list[PoseEvent]) -> list[ClipResult]:
        """Like :meth:`add` with pose events computed elsewhere (one pose stream, several front-ends)."""
        self.frames_in += 1
        self._pending[frame.index] = frame
        out = []
        for ev in events:
            out += self._event(ev)
        return out

    def finish(self, events: list[PoseEvent] | None = None) -> list[ClipResult]:
        """End of the stream: the pose stream's delayed events (or ``events``), then the open clip."""
        if events is None:
            t = time.perf_counter()
            events = self.poses.flush() if self.poses is not None else []
            self.timings["odometry"] += time.perf_counter() - t
        out = []
        for ev in events:
            out += self._event(ev)
        if self._clip is not None and len(self._clip):
            out.append(self._close("end of tour"))
        return out

    def _event(self, ev: PoseEvent) -> list[ClipResult]:
        out = []
        frame = self._pending.pop(ev.index, None)
        if frame is None:  # the pose stream reported a frame we never saw: ignore it
            return out
        if ev.pose is None:  # no usable depth: the open clip ends, the frame belongs to none
            if self._clip is not None and len(self._clip):
                out.append(self._close(f"gap: {ev.reason}" if ev.reason else "gap: no usable depth"))
            self.unposed.append(ev.index)
            if self.on_frame:
                self.on_frame(ev, None, self._chain)
            return out
        if ev.new_chain:
            if self._clip is not None and len(self._clip):
                out.append(self._close(f"gap: {ev.reason}" if ev.reason else "gap"))
            self._chain += 1
        if self._clip is None:
            self._clip = Clip(id=self._next_id, start=ev.index)
            self._next_id += 1
            self._clip_start_pose = ev.pose
            self._chain_pose = {}
        clip = self._clip
        clip.frames.append(ev.index)
        clip.V[ev.index] = inv_T(self._clip_start_pose) @ ev.pose
        self._chain_pose[ev.index] = ev.pose
        n = len(clip)
        checkpoint = self.policy.is_checkpoint(n) or n >= self.cfg.clips.max_frames
        if ev.index % self.cfg.observation.stride == 0 or checkpoint:
            self._observe(clip, frame)
        self._last = frame
        if self.on_frame:
            self.on_frame(ev, clip, self._chain)
        if checkpoint:
            path = clip.path_length()
            t = time.perf_counter()
            nodes = fuse(clip.clip_observations(), self.cfg.observation) if self.cfg.clips.adaptive else None
            self.timings["observation"] += time.perf_counter() - t
            if self.policy.should_close(n, len(nodes or ()), path):
                out.append(self._close("closed" if n < self.cfg.clips.max_frames else "max length", nodes))
        return out

    def _observe(self, clip: Clip, frame: FrameData) -> bool:
        """Detect and observe a frame once; True when new observations were added."""
        if frame.index in clip.observed_frames:
            return False
        t = time.perf_counter()
        dets = self.detector.detect(frame)
        # a detector that also gives 3D boxes (Map-Det3D-like) offers them as better centers
        boxes3d = self.detector.boxes3d(frame) if hasattr(self.detector, "boxes3d") else None
        t2 = time.perf_counter()
        obs = observe(frame.index, frame.depth, self.K, dets, self.cfg.observation,
                      self.cfg.refinement.plane_min_points, self.cfg.refinement.plane_max_rms_m,
                      boxes3d=boxes3d, det_cfg=self.cfg.detection)
        t3 = time.perf_counter()
        self.timings["detection"] += t2 - t
        self.timings["observation"] += t3 - t2
        clip.observations += obs
        clip.observed_frames.add(frame.index)
        return True

    def _close(self, reason: str, nodes: list[Node] | None = None) -> ClipResult:
        """Close the open clip; ``nodes``: its fusion at this checkpoint, if already computed."""
        clip = self._clip
        clip.end_reason = reason
        if self._last is not None and self._last.index == clip.end:
            if self._observe(clip, self._last):  # the clip's last frame is always observed
                nodes = None
        if nodes is None:
            t = time.perf_counter()
            nodes = fuse(clip.clip_observations(), self.cfg.observation)
            self.timings["observation"] += time.perf_counter() - t
        if self.localize:
            prior = self.yaw_prior(clip) if self.yaw_prior else None
            pred = None
            if self.predict is not None and self.cfg.backend.tracking:
                pred = self.predict(self._chain, self._chain_pose[clip.start])
            placement = localize_clip(nodes, clip.frame_observations(), clip.V, self.map, self.cfg,
                                      clip_rng(self.seed, clip.start), yaw_prior=prior, prediction=pred)
        else:
            placement = Placement(None, reason="localization off", nodes=len(nodes))
        tm = placement.timings
        self.timings["registration"] += sum(v for k, v in tm.items() if k != "refinement")
        self.timings["refinement"] += tm.get("refinement", 0.0)
        ends = {clip.start: self._chain_pose[clip.start], clip.end: self._chain_pose[clip.end]}
        res = ClipResult(clip=clip, nodes=nodes, placement=placement, chain=self._chain, chain_poses=ends,
                         timings=dict(tm))
        clip.observations = []  # the nodes keep what later stages need; bounded memory
        self._clip = None
        self._chain_pose = {}
        return res


# ---------------------------------------------------------------------------------------------
# reading a tour into the front-end


def make_pose_stream(kind: str, tour, cfg: Config) -> PoseStream:
    """The within-clip pose source of ``reloc run`` and the units: ``odometry`` or ``gt``."""
    if kind == "gt":
        return GroundTruthPoses()
    if kind == "odometry":
        return OdometryPoses(tour.K, tour.intrinsics.width, tour.intrinsics.height, cfg.odometry)
    raise ValueError(f"unknown pose source {kind!r} (expected odometry or gt)")


def default_detector(tour, bmap: BoxMap, cfg: Config | None = None) -> Detector:
    """The oracle detector (the tour's label images) over the map's classes, with ``cfg.detection``."""
    cfg = cfg or Config()
    return OracleDetector(tour.class_names(), vocabulary=bmap.class_set, min_pixels=cfg.detection.min_mask_pixels)


def read_frame(tour, i: int, detector: Detector, rgb: bool) -> FrameData:
    """Frame i of a tour as the front-end reads it (label images only for the oracle)."""
    labels = needs_labels(detector)
    f = tour.frame(int(i), rgb=rgb, depth=True, instance=labels, semantic=labels)
    depth = f.depth if f.depth is not None else np.zeros((tour.intrinsics.height, tour.intrinsics.width), np.float32)
    return FrameData(index=int(i), depth=depth, K=tour.K, rgb=f.rgb, instance=f.instance, semantic=f.semantic)
