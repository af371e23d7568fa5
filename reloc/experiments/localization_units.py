"""The localization-unit experiment (the paper's Table III, "Effect of the localization unit").

Each unit of L consecutive frames (1, 30, 100, 250) is registered independently: same map,
detector, registration and refinement as VideoReloc, but no tracking and no pose graph. Recall is
over all frames of the tour, measured when the unit closes (T_i = S_unit V_i); frames whose unit
was not placed count as failures. One pass over the tour feeds every unit length, sharing one
odometry stream.

One-frame units are the expensive row (one registration per frame); ``one_frame_stride`` > 1
evaluates them on every k-th frame only and reports recall over those frames, which the output
states.
"""

from __future__ import annotations

from vrformats.cli import add_json, add_quiet, positive_int

import dataclasses
import sys
import time

import numpy as np

from ..config import Config
from ..detection.base import Detector, check_rgb_schedule, needs_rgb
from ..detection.factory import detector_record
from ..evaluation import summarize
from ..frontend.stream import FrontEnd, StaticPoses, default_detector, make_pose_stream, read_frame
from ..map.boxmap import BoxMap

DEFAULT_LENGTHS = (1, 30, 100, 250)


def run_units(tour, bmap: BoxMap, lengths=DEFAULT_LENGTHS, detector: Detector | None = None,
              poses: str = "odometry", cfg: Config | None = None, frames: int | None = None,
              one_frame_stride: int = 1, seed: int = 0, progress: bool = True, estimates: dict | None = None) -> dict:
    """Recall of each unit length over the tour; ``estimates`` (a dict), when given, receives
    {length: {frame: pose}} of the placed units."""
    cfg = cfg or Config()
    detector = detector or default_detector(tour, bmap, cfg)
    if any(L > 1 for L in lengths):
        check_rgb_schedule(tour, cfg.observation.stride, detector, "observation.stride")
    if 1 in lengths:
        check_rgb_schedule(tour, one_frame_stride, detector, "one_frame_stride")
    idx = [int(i) for i in tour.frame_indices]
    if frames:
        idx = idx[:frames]
    gt = {i: tour.pose(i) for i in idx}
    fronts: dict[int, FrontEnd] = {}
    for L in lengths:
        c = dataclasses.replace(cfg, clips=dataclasses.replace(cfg.clips, adaptive=False, start_frames=int(L)))
        stream = StaticPoses() if L == 1 else None
        fronts[L] = FrontEnd(bmap, tour.K, detector, stream, config=c, seed=seed)
    shared = make_pose_stream(poses, tour, cfg) if any(L > 1 for L in lengths) else None
    est: dict[int, dict[int, np.ndarray]] = {L: {} for L in lengths}
    placed: dict[int, list[int]] = {L: [0, 0] for L in lengths}
    io_t = odo_t = 0.0
    rgb = needs_rgb(detector)
    bar = None
    if progress:
        from tqdm import tqdm

        bar = tqdm(total=len(idx), desc=f"units {','.join(map(str, lengths))}", unit="frame", file=sys.stderr)

    def collect(L, results):
        for r in results:
            placed[L][1] += 1
            if r.S is not None:
                placed[L][0] += 1
                est[L].update(r.frame_poses())

    one_frames = set(idx[:: max(1, one_frame_stride)])
    t_start = time.perf_counter()
    for i in idx:
        t = time.perf_counter()
        fd = read_frame(tour, i, detector, rgb=rgb)
        io_t += time.perf_counter() - t
        t = time.perf_counter()
        events = shared.add(fd, gt[i]) if shared is not None else []
        odo_t += time.perf_counter() - t
        for L, fe in fronts.items():
            if L == 1:
                if i in one_frames:
                    collect(L, fe.add(fd, gt[i]))
            else:
                collect(L, fe.feed(fd, events))
        if bar is not None:
            bar.update(1)
    tail = shared.flush() if shared is not None else []
    for L, fe in fronts.items():
        collect(L, fe.finish(tail if L > 1 else None))
    if bar is not None:
        bar.close()
    if estimates is not None:
        estimates.update(est)
    rows = []
    for L in lengths:
        g = {i: gt[i] for i in (sorted(one_frames) if L == 1 else idx)}
        s = summarize({i: T for i, T in est[L].items() if i in g}, g)
        s.update(unit=int(L), units=placed[L][1], placed_units=placed[L][0],
                 sampled_every=int(one_frame_stride) if L == 1 else 1)
        rows.append(s)
    return {
        "tour": str(tour.root),
        "map": bmap.source,
        "poses": poses,
        "detector": getattr(detector, "name", type(detector).__name__),
        "detector_settings": detector_record(detector),
        "frames": len(idx),
        "seconds": round(time.perf_counter() - t_start, 2),
        "io_seconds": round(io_t, 2),
        "odometry_seconds": round(odo_t, 2),
        "units": rows,
    }


def format_units(rep: dict) -> str:
    lines = [f"Localization units on {rep['tour']} ({rep['frames']} frames, poses: {rep['poses']}, "
             f"detector: {rep['detector']})",
             "",
             "| Unit | 1 m/10 deg | 0.25 m/5 deg | placed units | median pos (m) / rot (deg) |",
             "|---|---|---|---|---|"]
    for r in rep["units"]:
        name = "one frame" if r["unit"] == 1 else f"{r['unit']}-frame clip"
        if r["unit"] == 1 and r["sampled_every"] > 1:
            name += f" (every {r['sampled_every']}th frame)"
        med = (f"{r['median_pos_m']:.3f} / {r['median_rot_deg']:.2f}" if r["coverage"] > 0 else "-")
        lines.append(f"| {name} | {100 * r['recall_1m_10deg']:.1f} | {100 * r['recall_25cm_5deg']:.1f} | "
                     f"{r['placed_units']}/{r['units']} | {med} |")
    lines.append("")
    lines.append("Recall (%) over all frames, measured when each unit closes; frames of unplaced units fail.")
    return "\n".join(lines)


def _lengths(text: str) -> tuple[int, ...]:
    from vrformats.errors import UserError

    try:
        vals = tuple(int(x) for x in text.split(","))
    except ValueError:
        raise UserError(f"--lengths must be comma-separated frame counts like 1,30,100,250, got {text!r}") from None
    if not vals or any(v < 1 for v in vals):
        raise UserError(f"--lengths: every unit needs at least one frame, got {text!r}")
    return vals


def cmd_units(args) -> int:
    import json

    from vrformats.tour import Tour

    from ..config import Config, load_config
    from ..detection.factory import build_detector, detector_spec_from_args
    from vrformats.atomic import write_json_atomic

    tour = Tour(args.tour)
    cfg = load_config(args.config) if args.config else Config()
    bmap = BoxMap.load(args.map, config=cfg.map)
    det = build_detector(detector_spec_from_args(args), tour.class_names(), vocabulary=bmap.class_set,
                         config=cfg.detection)
    rep = run_units(tour, bmap, lengths=_lengths(args.lengths), detector=det, poses=args.poses, cfg=cfg,
                    frames=args.frames, one_frame_stride=args.one_frame_stride, seed=args.seed,
                    progress=not args.quiet)
    if args.out:
        write_json_atomic(args.out, rep)
    print(json.dumps(rep, indent=2) if args.json else format_units(rep))
    return 0


def register_cli(subparsers) -> None:
    from ..detection.factory import add_detector_arguments

    p = subparsers.add_parser("units",
                              help="the paper's Table III: independent 1/30/100/250-frame units, recall per length")
    p.add_argument("--map", required=True, help="map file (videoreloc-boxes/1 JSON)")
    p.add_argument("--tour", required=True, help="rendered tour directory")
    p.add_argument("--lengths", default=",".join(map(str, DEFAULT_LENGTHS)), help="unit lengths in frames (default 1,30,100,250)")
    p.add_argument("--poses", choices=("odometry", "gt"), default="odometry",
                   help="within-unit poses: RGB-D odometry (default) or the tour's ground truth")
    p.add_argument("--frames", type=positive_int, help="only the first N frames of the tour")
    p.add_argument("--one-frame-stride", type=int, default=1,
                   help="evaluate one-frame units on every k-th frame only (the expensive row)")
    p.add_argument("--config", help="YAML overrides of the paper's thresholds")
    p.add_argument("--seed", type=int, default=0)
    add_json(p)
    p.add_argument("--out", help="also write the JSON report here")
    add_quiet(p)
    add_detector_arguments(p)
    p.set_defaults(fn=cmd_units)
