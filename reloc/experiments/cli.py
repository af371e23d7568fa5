"""``reloc eval``: recall and errors of a ``reloc run`` output against a tour's ground truth.

For each trajectory (causal, closure, and any budget_B), over ALL ground-truth frames: recall at
1 m/10 deg and 0.25 m/5 deg (a frame without a pose is a failure), median position and rotation
error over the returned poses, and pose coverage.

``--poses CONVENTION``: OUT is instead one pose file of another relocalizer, written in that
convention (``vrformats.poses``: tum, ace, colmap, mapfree; always stated, never guessed); named
conventions map file names to tour frames through ``--names`` (the export folder, whose
``export.json`` "frames" is used, or a JSON file ``{"frames": {name: index}}``). The report is the
same, with one output labelled by the file's name.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

from vrformats.atomic import write_json_atomic
from vrformats.camera import read_tum
from vrformats.errors import SceneFormatError, UserError
from vrformats.cli import add_json

from ..evaluation import summarize

TRAJECTORIES = ("causal", "closure")


def evaluate_run(out_dir, tour) -> dict:
    """Recall and errors of each trajectory of a run. A line whose time is off the frame grid,
    repeats a frame or names a frame the tour does not have is an error naming file and line."""
    out = Path(out_dir)
    if not out.is_dir():
        raise UserError(f"{out}: run output directory not found")
    gt = {int(i): T for i, T in zip(tour.frame_indices, tour.poses)}
    names = list(TRAJECTORIES) + sorted(p.stem for p in out.glob("budget_*.txt"))
    rep: dict = {"run": str(out), "gt": str(tour.root), "frames": len(gt)}
    for name in names:
        path = out / f"{name}.txt"
        if not path.is_file():
            raise UserError(f"{path}: trajectory file not found (is {out} a reloc run output?)")
        frames, poses, lines = read_tum(path, fps=tour.fps, strict=True, lines=True)
        for i, ln in zip(frames, lines):
            if int(i) not in gt:
                raise SceneFormatError(path, f"line {ln}", f"frame {int(i)} (t = {int(i) / tour.fps:g}) is not in the "
                                       f"tour {tour.root} ({len(gt)} frames, {min(gt)}..{max(gt)})")
        est = {int(i): T for i, T in zip(frames, poses)}
        s = summarize(est, gt)
        s.pop("frames", None)
        rep[name] = s
    return rep


def evaluate_poses(pose_file, convention: str, tour, names=None) -> dict:
    """Recall and errors of one pose file in ``convention`` (``vrformats.poses``) against ``tour``.

    ``names`` (named conventions): an export folder, a manifest JSON file, or its ``"frames"`` dict.
    Tour frames without a pose are misses; with a named convention, over the frames the export holds
    (an image export leaves out geometry-only frames, as ``reloc experiment`` scores external methods).
    The report has ``evaluate_run``'s shape, its one output labelled by the file's name."""
    from vrformats.poses import NAMED, check_convention, load_names, read_poses

    conv = check_convention(convention)
    path = Path(pose_file)
    if conv in NAMED:
        if names is None:
            raise UserError(f"{path}: the {conv} convention names frames by file name: give --names EXPORT_DIR "
                            f"(its export.json) or a JSON file {{\"frames\": {{name: frame index}}}}")
        if not isinstance(names, dict):
            names = load_names(names)
    gt = {int(i): T for i, T in zip(tour.frame_indices, tour.poses)}
    est = read_poses(path, conv, names=names if conv in NAMED else None, fps=tour.fps, frames=set(gt))
    scored = gt
    if conv in NAMED:  # an image tool saw only the frames its export holds (no geometry-only frames)
        held = {int(i) for i in names.values()}
        scored = {i: T for i, T in gt.items() if i in held}
    s = summarize(est, scored)
    s.pop("frames", None)
    rep: dict = {"run": str(path), "convention": conv, "gt": str(tour.root), "frames": len(scored)}
    if len(scored) != len(gt):
        rep["evaluated_on"] = f"the {len(scored)} of {len(gt)} tour frames the export holds"
    label = path.name if path.name not in rep else f"{path.name} (poses)"
    rep[label] = s
    return rep


def format_eval(rep: dict) -> str:
    conv = f" ({rep['convention']} poses)" if rep.get("convention") else ""
    on = f"; evaluated on {rep['evaluated_on']}" if rep.get("evaluated_on") else ""
    lines = [f"{rep['run']}{conv} against {rep['gt']} ({rep['frames']} frames{on})", "",
             "| output | 1 m/10 deg | 0.25 m/5 deg | median pos (m) | median rot (deg) | coverage |",
             "|---|---|---|---|---|---|"]
    for k, v in rep.items():
        if not isinstance(v, dict):
            continue
        med = (f"{v['median_pos_m']:.3f} | {v['median_rot_deg']:.2f}" if v["coverage"] > 0 else "- | -")
        lines.append(f"| {k} | {100 * v['recall_1m_10deg']:.1f} | {100 * v['recall_25cm_5deg']:.1f} | {med} | "
                     f"{100 * v['coverage']:.1f} |")
    return "\n".join(lines)


def cmd_eval(args) -> int:
    from vrformats.errors import check_output_file
    from vrformats.poses import NAMED, check_convention
    from vrformats.tour import Tour

    if args.poses is None:
        if args.names is not None:
            raise UserError(f"--names {args.names}: only with --poses CONVENTION (a reloc run folder needs no names)")
    else:
        conv = check_convention(args.poses, where="--poses")
        if conv in NAMED and args.names is None:
            raise UserError(f"{args.out_dir}: --poses {conv} names frames by file name: give --names EXPORT_DIR "
                            f"(its export.json) or a JSON file {{\"frames\": {{name: frame index}}}}")
    if args.save:
        check_output_file(args.save)
    tour = Tour(args.gt)
    if args.poses is None:
        rep = evaluate_run(args.out_dir, tour)
    else:
        rep = evaluate_poses(args.out_dir, args.poses, tour, names=args.names)
    if args.save:
        write_json_atomic(args.save, rep)
    print(json.dumps(rep, indent=2) if args.json else format_eval(rep))
    if args.plot:
        bmap = None
        if args.map:
            from ..map.boxmap import BoxMap

            bmap = BoxMap.load(args.map)
        if args.poses is None:
            from ..backend.run import plot_run

            png = plot_run(args.out_dir, tour, bmap, png=args.plot)
        else:
            from ..figures import run_figure

            png = run_figure(tour, {f"{Path(args.out_dir).name} ({args.poses})": _poses_of(args, tour)}, args.plot, bmap=bmap)
        print(f"plot: {png}", file=sys.stderr if args.json else sys.stdout)
    return 0


def _poses_of(args, tour) -> dict:
    """The pose file of ``reloc eval --poses`` as {frame: camera-to-world}, read as ``evaluate_poses`` reads it."""
    from vrformats.poses import NAMED, check_convention, load_names, read_poses

    conv = check_convention(args.poses)
    names = load_names(args.names) if conv in NAMED else None
    return read_poses(Path(args.out_dir), conv, names=names, fps=tour.fps, frames={int(i) for i in tour.frame_indices})


def register_cli(subparsers) -> None:
    p = subparsers.add_parser("eval", help="recall at 1 m/10 deg and 0.25 m/5 deg of a reloc run output or a pose file")
    p.add_argument("out_dir", metavar="OUT", help="a reloc run output directory, or with --poses a pose file")
    p.add_argument("--poses", metavar="CONVENTION", default=None,
                   help="OUT is a pose file in this convention: tum (t tx ty tz qx qy qz qw, camera-to-world), "
                        "ace (ACE test_ace.py poses_*.txt), colmap (hloc results: name qw qx qy qz tx ty tz), "
                        "mapfree (map-free benchmark: name qw..tz confidence); the last three are world-to-camera")
    p.add_argument("--names", metavar="EXPORT", default=None,
                   help="for ace/colmap/mapfree: the export folder (its export.json) or a JSON file "
                        "{\"frames\": {file name: tour frame index}} mapping the file's names to frames")
    p.add_argument("--gt", required=True, metavar="TOUR_DIR", help="the tour with the ground-truth poses")
    add_json(p)
    p.add_argument("--save", metavar="FILE.json", help="also write the JSON here")
    p.add_argument("--plot", metavar="FILE.png", help="also draw the trajectories over the map against the ground truth")
    p.add_argument("--map", metavar="MAP.json", help="with --plot: the map to draw (default: none)")
    p.set_defaults(fn=cmd_eval)


def cmd_stages(args) -> int:
    """``reloc stages``: one design's figures on several stage variants, side by side (issue 55)."""
    from .stages import format_stage_table, stage_dirs, stage_table

    rows = stage_table(stage_dirs(args.results))
    if args.json:
        print(json.dumps(rows, indent=1))
    else:
        print(format_stage_table(rows))
    if args.save:
        write_json_atomic(Path(args.save), {"format": "videoreloc-stages/1", "results": [str(Path(a.partition("=")[2] or a))
                                                                                          for a in args.results], "rows": rows},
                          indent=1)
    return 0


def register_stages_cli(subparsers) -> None:
    p = subparsers.add_parser("stages", help="one design's figures on several stage variants (results folders), "
                                             "with intervals, spread and whether each holds across stages")
    p.add_argument("results", nargs="+", metavar="[NAME=]RESULTS_DIR",
                   help="reloc experiment results of the same design on each stage variant")
    add_json(p)
    p.add_argument("--save", metavar="FILE.json", help="also write the rows as JSON here")
    p.set_defaults(fn=cmd_stages)
