"""``reloc run``: stream a tour through VideoReloc and write its trajectories (paper Sec. IV-A).

Outputs, in ``--out``:

* ``causal.txt``: frame i's pose frozen from evidence up to frame i: the run's latest saved
  placement propagated with odometry (``T_i = S_c C_c^-1 C(i)``), or, before the run's first clip
  closes, the latest per-frame localization propagated the same way;
* ``closure.txt``: frozen when the clip containing i closes, after the run-level decision and the
  pose-graph update (``T_i = S_c V_i``);
* ``budget_B.txt`` with ``--budget B``: delayed-output replay, frozen at the latest processed
  frame b with ``0 <= b - i <= B``;
* ``frames.json``: per frame, its clip, run and where each pose came from;
* ``clips.json``: per clip, frames, end reason, placement source, kappa, the reason when unplaced;
* ``clip_poses.npz``: the clip partition and within-clip odometry (``frames``, ``clip``, ``V``:
  frame i's pose in its clip's frame), which the clip-rigid controls reuse (paper Table IV, dagger).

TUM lines (camera-to-world, OpenCV axes) exist only for frames that have an estimate; a missing
frame is a failure for ``reloc eval``. Files are written atomically at the end.
"""

from __future__ import annotations

import sys
import time
from pathlib import Path

import numpy as np

from vrformats.atomic import save_npz_atomic, write_json_atomic
from vrformats.camera import write_tum
from vrformats.errors import UserError, check_output_folder
from vrformats.cli import add_quiet, add_sensor, positive_int

from .online import Backend, ClipState
from ..frontend.clips import fuse
from ..config import Config
from ..detection.base import Detector, check_rgb_schedule, needs_rgb
from ..detection.factory import detector_record
from ..frontend.stream import FrontEnd, PoseEvent, default_detector, make_pose_stream, read_frame
from ..geometry import inv_T
from ..frontend.localize import clip_rng, localize_clip
from ..map.boxmap import BoxMap


class Relocalizer:
    """VideoReloc over a frame stream: front-end, back-end and the three output cutoffs."""

    def __init__(self, bmap: BoxMap, K: np.ndarray, detector: Detector, poses, cfg: Config | None = None,
                 budgets=(), seed: int = 0):
        self.cfg = cfg or Config()
        self.map = bmap
        self.detector = detector
        self.seed = seed
        self.backend = Backend(bmap, self.cfg)
        self.fe = FrontEnd(bmap, K, detector, poses, config=self.cfg, seed=seed, predict=self.backend.predict,
                           on_frame=self._on_frame)
        self.budgets = sorted({int(b) for b in budgets if int(b) > 0})
        self.causal: dict[int, tuple[np.ndarray, str]] = {}
        self.closure: dict[int, tuple[np.ndarray, str]] = {}
        self.budget_out: dict[int, dict[int, tuple[np.ndarray, str]]] = {b: {} for b in self.budgets}
        self.frame_info: dict[int, dict] = {}
        self._chain_pose: dict[int, np.ndarray] = {}  # frames still awaiting a budget freeze
        self._frame_clip: dict[int, ClipState] = {}  # frames whose clip has closed
        self._frame_fix: dict[int, np.ndarray] = {}  # run -> run-to-map G from per-frame localization
        self._order: list[int] = []  # frames in stream order (for budgets)
        self._frozen_upto = {b: 0 for b in self.budgets}
        self.frame_localizations = 0

    # -- streaming -------------------------------------------------------------------------------

    def add(self, frame, gt_pose=None) -> None:
        for res in self.fe.add(frame, gt_pose):
            self._closed(res)

    def finish(self) -> None:
        for res in self.fe.finish():
            self._closed(res)
        for b in self.budgets:  # the stream ended: the rest freeze at the last processed frame
            self._freeze_budget(b, len(self._order))

    # -- per frame ---------------------------------------------------------------------------------

    def _on_frame(self, ev: PoseEvent, clip, chain: int) -> None:
        i = ev.index
        self._order.append(i)
        if ev.pose is None:
            self.frame_info[i] = {"clip": None, "run": None}
        else:
            self.frame_info[i] = {"clip": clip.id, "run": chain}
            self._chain_pose[i] = ev.pose
            if self.cfg.backend.frame_localization and self.backend.run_to_map(chain) is None \
                    and i in clip.observed_frames:
                self._frame_localize(i, clip, chain, ev.pose)
            est = self._estimate(i)
            if est is not None:
                self.causal[i] = est
        for b in self.budgets:
            self._freeze_budget(b, len(self._order) - b)

    def _frame_localize(self, i: int, clip, chain: int, chain_pose: np.ndarray) -> None:
        """Per-frame localization at run starts (causal evaluation, Sec. IV-A)."""
        obs = [o for o in clip.observations if o.frame == i]
        if not obs:
            return
        nodes = fuse(obs, self.cfg.observation)
        self.frame_localizations += 1
        p = localize_clip(nodes, {i: obs}, {i: np.eye(4)}, self.map, self.cfg, clip_rng(self.seed + 1, i), anchors=False)
        if p.S is not None and p.kappa >= self.cfg.backend.track_min_kappa:
            self._frame_fix[chain] = p.S @ inv_T(chain_pose)
            self.backend.add_frame_hypothesis(chain, self._frame_fix[chain])

    def _estimate(self, i: int) -> tuple[np.ndarray, str] | None:
        """The best pose of frame i from the evidence processed so far."""
        st = self._frame_clip.get(i)
        if st is not None and st.S is not None:
            return st.S @ st.res.clip.V[i], st.source
        info = self.frame_info.get(i)
        if not info or info["run"] is None or i not in self._chain_pose:
            return None
        g = self.backend.run_to_map(info["run"])
        if g is not None:
            return g[0] @ self._chain_pose[i], f"propagated {g[1].source}"
        G = self._frame_fix.get(info["run"])
        if G is not None:
            return G @ self._chain_pose[i], "frame"
        return None

    def _freeze_budget(self, b: int, upto: int) -> None:
        """Freeze every frame at stream position < upto (its latest processed frame is i + b)."""
        out = self.budget_out[b]
        for pos in range(self._frozen_upto[b], max(self._frozen_upto[b], upto)):
            i = self._order[pos]
            est = self._estimate(i)
            if est is not None:
                out[i] = est
        self._frozen_upto[b] = max(self._frozen_upto[b], upto)
        self._trim()

    def _trim(self) -> None:
        """Forget chain poses no output can still need (bounded memory)."""
        if not self.budgets:
            return
        done = min(self._frozen_upto.values())
        for pos in range(max(0, done - 1 - 50), done - 1):
            i = self._order[pos]
            if i in self._frame_clip:
                self._chain_pose.pop(i, None)

    # -- per clip ----------------------------------------------------------------------------------

    def _closed(self, res) -> None:
        st = self.backend.add(res)
        for i in res.clip.frames:
            self._frame_clip[i] = st
            if not self.budgets:
                self._chain_pose.pop(i, None)
        # clip closure freezes the poses of its frames with the back-end value now
        if st.S is not None:
            for i, V in res.clip.V.items():
                self.closure[i] = (st.S @ V, st.source)

    # -- results -----------------------------------------------------------------------------------

    def clip_table(self) -> list[dict]:
        rows = []
        for st in self.backend.clips:
            c, p = st.res.clip, st.res.placement
            rows.append({
                "clip": c.id, "run": st.run, "start": c.start, "end": c.end, "frames": len(c),
                "end_reason": c.end_reason, "nodes": len(st.res.nodes),
                "front_source": st.front_source, "source": st.source, "kappa": round(p.kappa, 3),
                "reason": p.reason or None, "demoted": st.demoted,
            })
        return rows


def relocalize(tour, bmap: BoxMap, out, cfg: Config | None = None, detector: Detector | None = None,
               poses: str = "odometry", budgets=(), frames: int | None = None, seed: int = 0,
               progress: bool = True) -> dict:
    check_output_folder(out)  # before the tour is processed, not after
    cfg = cfg or Config()
    detector = detector or default_detector(tour, bmap, cfg)
    check_rgb_schedule(tour, cfg.observation.stride, detector, "observation.stride")
    idx = [int(i) for i in tour.frame_indices][:frames]
    r = Relocalizer(bmap, tour.K, detector, make_pose_stream(poses, tour, cfg), cfg=cfg, budgets=budgets, seed=seed)
    bar = None
    if progress:
        from tqdm import tqdm

        bar = tqdm(total=len(idx), desc="reloc run", unit="frame", file=sys.stderr)
    t0 = time.perf_counter()
    rgb = needs_rgb(detector) or cfg.odometry.method == "hybrid"
    degenerate = Degenerate(cfg, needs_rgb(detector))
    for i in idx:
        fd = read_frame(tour, i, detector, rgb=rgb)
        degenerate.see(fd)
        r.add(fd, tour.pose(i))
        if bar is not None:
            bar.update(1)
    r.finish()
    if bar is not None:
        bar.close()
    degenerate.check(tour.root, len(idx))
    seconds = time.perf_counter() - t0
    return write_outputs(r, out, tour, idx, seconds, poses, degenerate=degenerate.summary(len(idx)))


class Degenerate:
    """Frames a tour should not have: less valid depth than ``odometry.min_valid_depth_fraction``, or no
    RGB on a frame the detector reads (every ``observation.stride``-th). Counted per tour; a tour with a
    larger share than ``odometry.max_degenerate_fraction`` fails with one line."""

    def __init__(self, cfg: Config, rgb_needed: bool):
        self.cfg, self.rgb_needed = cfg, rgb_needed
        self.no_depth: list[int] = []
        self.no_rgb: list[int] = []

    def see(self, fd) -> None:
        d = fd.depth
        valid = np.count_nonzero(np.isfinite(d) & (d > 0)) if d is not None else 0
        if d is None or valid < self.cfg.odometry.min_valid_depth_fraction * d.size:
            self.no_depth.append(int(fd.index))
        if self.rgb_needed and fd.index % self.cfg.observation.stride == 0 and fd.rgb is None:
            self.no_rgb.append(int(fd.index))

    def frames(self) -> list[int]:
        return sorted(set(self.no_depth) | set(self.no_rgb))

    def summary(self, n: int) -> dict:
        bad = self.frames()
        return {"no_usable_depth": len(self.no_depth), "no_rgb": len(self.no_rgb), "frames": len(bad),
                "fraction": round(len(bad) / n, 4) if n else 0.0, "first": bad[:10]}

    def check(self, where, n: int) -> None:
        bad = self.frames()
        limit = self.cfg.odometry.max_degenerate_fraction
        if n and len(bad) > limit * n:
            raise UserError(f"{where}: {len(bad)} of {n} frames are degenerate ({len(self.no_depth)} without usable depth, "
                            f"{len(self.no_rgb)} without the RGB the detector reads), more than "
                            f"odometry.max_degenerate_fraction = {limit}; first: {', '.join(map(str, bad[:5]))}")


def write_outputs(r: Relocalizer, out, tour, idx, seconds: float, poses: str, degenerate: dict | None = None) -> dict:
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    fps = tour.fps

    def tum(name, d):
        fr = [i for i in idx if i in d]
        write_tum(out / name, [d[i][0] for i in fr], fps=fps, frames=fr,
                  header=f"VideoReloc {name[:-4]} trajectory of {tour.root} (camera-to-world, OpenCV axes)")

    for stale in out.glob("budget_*.txt"):  # a previous run's budgets would mislead reloc eval
        if stale.stem.split("_", 1)[1] not in {str(b) for b in r.budget_out}:
            stale.unlink()
    tum("causal.txt", r.causal)
    tum("closure.txt", r.closure)
    for b, d in r.budget_out.items():
        tum(f"budget_{b}.txt", d)
    frames = []
    for i in idx:
        info = r.frame_info.get(i, {"clip": None, "run": None})
        row = {"frame": i, "clip": info["clip"], "run": info["run"],
               "causal": r.causal[i][1] if i in r.causal else None,
               "closure": r.closure[i][1] if i in r.closure else None}
        for b, d in r.budget_out.items():
            row[f"budget_{b}"] = d[i][1] if i in d else None
        frames.append(row)
    clips = r.clip_table()
    summary = {
        "tour": str(tour.root), "map": r.map.source, "frames": len(idx), "poses": poses,
        "seconds": round(seconds, 2), "fps": round(len(idx) / max(seconds, 1e-9), 1),
        "clips": len(clips), "placed_by_front_end": sum(c["front_source"] is not None for c in clips),
        "runs": len({c["run"] for c in clips}),
        "causal_frames": len(r.causal), "closure_frames": len(r.closure),
        "frame_localizations": r.frame_localizations,
        "budgets": list(r.budget_out),
        "detector": detector_record(r.detector), "seed": r.seed,
        "stage_ms_per_frame": {k: round(v * 1000 / max(len(idx), 1), 2) for k, v in r.fe.timings.items()},
        "degenerate_frames": degenerate or {"no_usable_depth": 0, "no_rgb": 0, "frames": 0, "fraction": 0.0, "first": []},
    }
    if not clips:
        summary["note"] = "no clip was formed: no frame had usable depth"
    elif not r.closure:
        reasons = sorted({c["reason"] for c in clips if c["reason"]})
        summary["note"] = "no clip was placed: " + "; ".join(reasons[:3])
    write_clip_poses(out / CLIP_POSES, r.backend.clips)
    write_json_atomic(out / "frames.json", frames, indent=None)
    write_json_atomic(out / "clips.json", clips)
    write_json_atomic(out / "run.json", summary)
    return summary


CLIP_POSES = "clip_poses.npz"


def write_clip_poses(path: Path, clips) -> None:
    fr, cl, V = [], [], []
    for st in clips:
        c = st.res.clip
        for i in c.frames:
            if i in c.V:
                fr.append(i)
                cl.append(c.id)
                V.append(c.V[i])
    save_npz_atomic(path, frames=np.asarray(fr, np.int64), clip=np.asarray(cl, np.int64),
                    V=np.asarray(V, np.float64).reshape(-1, 4, 4))


def load_clip_poses(run_dir) -> dict[int, dict[int, np.ndarray]]:
    """clip id -> {frame: V_i} from a ``reloc run`` output (the clip partition and odometry)."""
    from vrformats.errors import UserError

    path = Path(run_dir) / CLIP_POSES
    if not path.is_file():
        raise UserError(f"{path}: not found (the clip-rigid controls need a VideoReloc run of this tour)")
    with np.load(path) as z:
        out: dict[int, dict[int, np.ndarray]] = {}
        for i, c, V in zip(z["frames"].tolist(), z["clip"].tolist(), z["V"]):
            out.setdefault(int(c), {})[int(i)] = V
    return out


def plot_run(out, tour, bmap=None, png=None) -> Path:
    """``OUT/trajectory.png`` (or ``png``): the run's causal and closure trajectories over the map,
    against the tour's ground truth (``reloc.figures.run_figure``)."""
    from vrformats.camera import read_tum

    from ..figures import run_figure

    out = Path(out)
    trajs = {}
    for name, label in (("causal", "causal"), ("closure", "with clip closure")):
        f = out / f"{name}.txt"
        if f.is_file():
            frames, poses = read_tum(f, fps=tour.fps)
            trajs[label] = {int(i): T for i, T in zip(frames, poses)}
    return run_figure(tour, trajs, png or out / "trajectory.png", bmap=bmap)


def cmd_run(args) -> int:
    from vrformats.tour import Tour

    from ..config import load_config
    from ..detection.factory import build_detector, detector_spec_from_args

    check_output_folder(args.out)
    tour = Tour(args.tour, sensor=args.sensor, sensor_seed=args.sensor_seed)
    cfg = load_config(args.config) if args.config else Config()
    bmap = BoxMap.load(args.map, config=cfg.map)
    if args.point_to_point:
        cfg = cfg.replace("refinement.orientation_aware", False)
    if args.no_run_level:
        cfg = cfg.replace("backend.run_level", False)
    if args.fixed_clips:
        cfg = cfg.replace("clips.adaptive", False).replace("clips.start_frames", 100)
    det = build_detector(detector_spec_from_args(args), tour.class_names(), vocabulary=bmap.class_set,
                         config=cfg.detection)
    s = relocalize(tour, bmap, args.out, cfg=cfg, detector=det, poses=args.poses,
                   budgets=[args.budget] if args.budget else [], frames=args.frames, seed=args.seed,
                   progress=not args.quiet)
    print(f"{s['frames']} frames in {s['seconds']:.1f} s ({s['fps']} frames/s): {s['clips']} clips in {s['runs']} "
          f"run(s), {s['placed_by_front_end']} placed by the front-end; poses: causal {s['causal_frames']}, "
          f"closure {s['closure_frames']} -> {args.out}")
    if not args.no_plot:
        print(f"plot: {plot_run(args.out, tour, bmap)}")
    if "note" in s:
        print(f"note: {s['note']}")
    dg = s["degenerate_frames"]
    if dg["frames"]:
        print(f"note: {dg['frames']} degenerate frame(s) ({dg['no_usable_depth']} without usable depth, {dg['no_rgb']} "
              f"without RGB): {', '.join(map(str, dg['first']))}{', ...' if dg['frames'] > len(dg['first']) else ''}")
    return 0


def register_cli(subparsers) -> None:
    from ..detection.factory import add_detector_arguments

    p = subparsers.add_parser("run", help="relocalize a tour: causal.txt, closure.txt, frames.json, clips.json, trajectory.png")
    p.add_argument("--map", required=True, help="map file (videoreloc-boxes/1 JSON)")
    p.add_argument("--tour", required=True, help="rendered tour directory")
    p.add_argument("--out", required=True, help="output directory")
    p.add_argument("--budget", type=positive_int, help="also write budget_B.txt: delayed-output replay with B frames")
    p.add_argument("--poses", choices=("odometry", "gt"), default="odometry",
                   help="within-clip poses: RGB-D odometry (default) or ground truth")
    p.add_argument("--frames", type=positive_int, help="only the first N frames")
    p.add_argument("--config", help="YAML overrides of the paper's thresholds")
    p.add_argument("--point-to-point", action="store_true", help="ablation: point-to-point refinement")
    p.add_argument("--no-run-level", action="store_true", help="ablation: no run-level decision")
    p.add_argument("--fixed-clips", action="store_true", help="ablation: fixed 100-frame clips")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--no-plot", action="store_true", help="do not draw OUT/trajectory.png (the trajectories over the map)")
    add_sensor(p, "read the tour")
    add_quiet(p)
    add_detector_arguments(p)
    p.set_defaults(fn=cmd_run)
