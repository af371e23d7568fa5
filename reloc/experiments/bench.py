"""``reloc bench``: every benchmark of the relocalizer's side, one subcommand each:

- ``frontend``: front-end throughput by stage (here);
- ``odometry``: the odometry speed/accuracy trade-off (:mod:`reloc.experiments.bench_odometry`);
- ``stability``: an experiment's figures under last-bit perturbations (:mod:`reloc.experiments.stability`);
- ``detector-speed``: learned-detector models side by side (:mod:`reloc.detection.bench_speed`);
- ``map-rules``: what each map-building rule costs (:mod:`reloc.map.bench_rules`);
- ``sensors``: a tour's read speed through each sensor model (:mod:`vrformats.bench_sensors`).

``reloc bench frontend`` streams a tour through the front-end (adaptive clips, registration and
refinement at every clip closure) and reports milliseconds per frame for each stage: reading the
EXR files (io), odometry, detection, observation and fusion, registration, refinement. Frames per
second are given with and without io, as the median over ``--repeat`` runs (the machine is noisy).
"""

from __future__ import annotations

from vrformats.cli import add_json, positive_int

import json
import statistics
import time

from ..config import Config
from ..frontend.stream import STAGES, FrontEnd, default_detector, make_pose_stream, read_frame
from ..map.boxmap import BoxMap


def bench_frontend(tour, bmap: BoxMap, frames: int = 600, poses: str = "odometry", cfg: Config | None = None,
                   repeat: int = 1, progress: bool = False) -> dict:
    cfg = cfg or Config()
    idx = [int(i) for i in tour.frame_indices][:frames]
    runs = []
    for _ in range(repeat):
        det = default_detector(tour, bmap, cfg)
        fe = FrontEnd(bmap, tour.K, det, make_pose_stream(poses, tour, cfg), config=cfg)
        io = 0.0
        clips = placed = 0
        t0 = time.perf_counter()
        for i in idx:
            t = time.perf_counter()
            fd = read_frame(tour, i, det, rgb=cfg.odometry.method == "hybrid")
            io += time.perf_counter() - t
            for r in fe.add(fd, tour.pose(i)):
                clips += 1
                placed += r.placement.ok
        for r in fe.finish():
            clips += 1
            placed += r.placement.ok
        total = time.perf_counter() - t0
        tm = dict(fe.timings)
        tm["io"] = io
        runs.append({"total": total, "stages": tm, "clips": clips, "placed": placed})
    n = len(idx)
    med = {s: statistics.median(r["stages"][s] for r in runs) * 1000 / n for s in STAGES}
    tot = statistics.median(r["total"] for r in runs)
    io = statistics.median(r["stages"]["io"] for r in runs)
    return {
        "tour": str(tour.root),
        "size": f"{tour.intrinsics.width}x{tour.intrinsics.height}",
        "frames": n,
        "poses": poses,
        "odometry": {"method": cfg.odometry.method, "width": cfg.odometry.width, "stride": cfg.odometry.stride},
        "repeat": repeat,
        "ms_per_frame": {k: round(v, 2) for k, v in med.items()},
        "fps_without_io": round(n / max(tot - io, 1e-9), 1),
        "fps_with_io": round(n / tot, 1),
        "clips": runs[-1]["clips"],
        "placed": runs[-1]["placed"],
    }


def format_frontend(rep: dict) -> str:
    lines = [f"front-end on {rep['tour']} ({rep['size']}, {rep['frames']} frames, poses {rep['poses']}, "
             f"odometry {rep['odometry']}, median of {rep['repeat']} run(s))", "",
             "| stage | ms/frame |", "|---|---|"]
    for s, v in rep["ms_per_frame"].items():
        lines.append(f"| {s} | {v:.2f} |")
    lines += ["", f"frames/s without io: {rep['fps_without_io']}   with io: {rep['fps_with_io']}   "
              f"clips: {rep['clips']} (placed {rep['placed']})"]
    return "\n".join(lines)


def cmd_frontend(args) -> int:
    from vrformats.tour import Tour

    from ..config import load_config

    tour = Tour(args.tour)
    cfg = load_config(args.config) if args.config else Config()
    bmap = BoxMap.load(args.map, config=cfg.map)
    rep = bench_frontend(tour, bmap, frames=args.frames, poses=args.poses, cfg=cfg, repeat=args.repeat)
    print(json.dumps(rep, indent=2) if args.json else format_frontend(rep))
    return 0


def cmd_odometry(args) -> int:
    from . import bench_odometry

    return bench_odometry.run(args)


def cmd_detector_speed(args) -> int:
    from ..detection import bench_speed

    return bench_speed.run(args)


def cmd_map_rules(args) -> int:
    from ..map import bench_rules

    return bench_rules.run(args)


def cmd_sensors(args) -> int:
    from vrformats import bench_sensors

    return bench_sensors.run(args)


def register_cli(subparsers) -> None:
    p = subparsers.add_parser("bench", help="benchmarks that print figures (front-end stages, odometry trade-off, stability, "
                                            "detector speed, map rules, sensor read speed)")
    sub = p.add_subparsers(dest="cmd", required=True)
    a = sub.add_parser("frontend", help="front-end frames per second by stage")
    a.add_argument("--tour", required=True)
    a.add_argument("--map", required=True)
    a.add_argument("--frames", type=positive_int, default=600)
    a.add_argument("--poses", choices=("odometry", "gt"), default="odometry")
    a.add_argument("--repeat", type=int, default=3)
    a.add_argument("--config")
    add_json(a, "the report")
    a.set_defaults(fn=cmd_frontend)
    from vrformats import bench_sensors

    from . import bench_odometry, stability
    from ..detection import bench_speed
    from ..map import bench_rules

    # the benchmarks whose options their own module adds: (subcommand, help, module, command)
    for name, text, module, fn in (
            ("stability", "an experiment's figures under last-bit perturbations of the learned detector", stability,
             stability.cmd_stability),
            ("odometry", "odometry speed against drift per metre for resolutions and strides", bench_odometry,
             cmd_odometry),
            ("detector-speed", "learned-detector models side by side: median ms per frame", bench_speed,
             cmd_detector_speed),
            ("map-rules", "what each map-building rule costs: boxes matched, missing, extra per relaxed rule",
             bench_rules, cmd_map_rules),
            ("sensors", "a tour's read speed, valid depth and exposure through each sensor model", bench_sensors,
             cmd_sensors)):
        a = sub.add_parser(name, help=text)
        module.add_arguments(a)
        a.set_defaults(fn=fn)

