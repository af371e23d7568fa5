"""The ``synth path`` command group: plan (query, mapping), generate, show, check, preview."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from vrformats.errors import UnknownNameError, UserError
from vrformats.cli import add_json, positive_int

from .clearance import CLEARANCE_TOL, range_text, describe_object, clearance_report, declared_clearance, replan_command
from .files import load_path, save_path
from .mapping import plan_mapping_path
from .model import DEFAULTS, CameraPath
from .query import plan_query_path
from .shipped import SHIPPED, generate_shipped
from .summary import path_summary, plot_path

__all__ = ["register_cli"]


def _layout(name):
    from ..scene.model import load_layout

    return load_layout(name)


def _layout_ref(arg: str) -> str:
    """How a planned path's metadata names a layout given on the command line: a built-in name as
    given, a file by its absolute path. A layout file keeps its own name inside (an imported
    ReplicaCAD ``apt_0`` is called ``apt_0``), so recording that name would make ``synth path
    check``, replanning and the render checks read the built-in layout of the same name instead."""
    from ..scene.model import layouts_dir, resolve_layout_path

    f = resolve_layout_path(arg)
    if Path(arg).suffix == "" and not Path(arg).exists() and f == layouts_dir() / f"{arg}.yaml":
        return arg
    return str(f.resolve())


def _record_layouts(path: CameraPath, args_layouts: list[str]) -> None:
    path.meta["layouts"] = [_layout_ref(a) for a in args_layouts]


def _cmd_plan_query(args) -> int:
    lays = [_layout(n) for n in args.layouts]
    path = plan_query_path(lays, frames=args.frames, seed=args.seed, fps=args.fps, speed=args.speed,
                           clearance=args.clearance, obstacles=args.obstacles, name=args.name or Path(args.out).stem)
    _record_layouts(path, args.layouts)
    out = save_path(path, args.out)
    st = path.meta["stats"]
    print(f"wrote {out} (+ {out.with_suffix('.yaml').name}): {len(path)} frames, {st['length_m']:.1f} m, "
          f"min clearance {st['min_clearance_m']:.3f} m over {len(lays)} layout(s)")
    return 0


def _cmd_plan_mapping(args) -> int:
    lay = _layout(args.layout)
    path = plan_mapping_path(lay, frames=args.frames, seed=args.seed, fps=args.fps, speed=args.speed,
                             clearance=args.clearance, obstacles=args.obstacles, name=args.name or Path(args.out).stem)
    _record_layouts(path, [args.layout])
    out = save_path(path, args.out)
    st = path.meta["stats"]
    print(f"wrote {out} (+ {out.with_suffix('.yaml').name}): {len(path)} frames, {st['length_m']:.1f} m, "
          f"sweep spacing {path.meta['planner']['sweep_spacing_m']:.2f} m, min clearance {st['min_clearance_m']:.3f} m")
    return 0


def _default_layout(path: CameraPath, name):
    if name:
        return _layout(name)
    lays = path.meta.get("layouts") or []
    if lays:
        try:
            return _layout(lays[0])
        except UserError:
            return None
    return None


def _cmd_preview(args) -> int:
    path = load_path(args.path)
    lay = _default_layout(path, args.layout)
    if lay is None:
        raise UserError(f"path '{path.name}' names no layout it was planned on; give --layout")
    out = plot_path(path, lay, args.out)
    print(f"wrote {out}")
    return 0


def _cmd_show(args) -> int:
    import json

    path = load_path(args.path)
    lay = _default_layout(path, args.layout)
    s = path_summary(path, lay)
    if args.json:
        print(json.dumps(s, indent=2))
        return 0
    print(f"camera path {s['name']}" + (f" ({s['kind']}, seed {s['seed']})" if s.get("kind") else ""))
    if s.get("layouts"):
        print(f"  planned on: {', '.join(s['layouts'])}")
    print(f"  frames {s['frames']} at {s['fps']:g} fps: duration {s['duration_s']:.1f} s, length {s['length_m']:.1f} m, "
          f"mean speed {s['mean_speed_mps']:.2f} m/s")
    if s["height_m"]:
        print(f"  height {s['height_m'][0]:.2f}-{s['height_m'][1]:.2f} m, pitch {s['pitch_deg'][0]:.1f} to "
              f"{s['pitch_deg'][1]:.1f} deg, max yaw rate {s['max_yaw_rate_deg_s']:.0f} deg/s")
    if lay is not None:
        rooms = ", ".join(f"{r} ({n} frames)" for r, n in s["rooms_frames"].items())
        print(f"  rooms visited in {lay.name}: {rooms or 'none'}")
        c = declared_clearance(path)
        # the layout as given, else the file the path was planned on (an imported apt_0 is not the built-in one)
        lay_arg = args.layout or str((path.meta.get("layouts") or [lay.name])[0])
        note = (f" (below the path's {c:g} m clearance: see `synth path check {args.path} --layout {lay_arg}`)"
                if c is not None and s["min_clearance_m"] is not None and s["min_clearance_m"] < c - CLEARANCE_TOL else "")
        rule = "" if s["obstacles"] == "all" else f", from {s['obstacles']} obstacles as planned"
        print(f"  min clearance in {lay.name}: {s['min_clearance_m']:.3f} m{rule}{note}")
    else:
        print("  rooms visited: unknown (give --layout)")
    return 0


def _cmd_check(args) -> int:
    import json

    path = load_path(args.path)
    names = args.layout or [str(n) for n in path.meta.get("layouts") or []]
    if not names:
        raise UserError(f"camera path '{path.name}' names no layout it was planned on; give --layout")
    if args.clearance is not None and not (math.isfinite(args.clearance) and args.clearance >= 0):
        raise UserError(f"--clearance must be >= 0, got {args.clearance!r}")
    lays = []
    for n in names:
        try:
            lays.append(_layout(n))
        except UnknownNameError:
            if args.layout:
                raise
            raise UserError(f"camera path '{path.name}' was planned on layout '{n}', which is not in "
                            f"scenes/layouts; give its file with --layout") from None
    reps = [clearance_report(path, lay, args.clearance) for lay in lays]
    ok = all(r["ok"] for r in reps)
    if args.json:
        print(json.dumps({"path": path.name, "ok": ok, "layouts": reps}, indent=2))
        return 0 if ok else 1
    c = reps[0]["clearance_m"]
    if ok:
        worst = min(reps, key=lambda r: r["min_clearance_m"] if r["min_clearance_m"] is not None else np.inf)
        print(f"OK: camera path '{path.name}' keeps {c:g} m clearance in {', '.join(r['layout'] for r in reps)} "
              f"(min {worst['min_clearance_m']:.3f} m, in {worst['layout']} at frame {worst['min_frame']})")
        return 0
    for r, arg in zip(reps, names):
        if r["ok"]:
            print(f"{r['layout']}: ok (min {r['min_clearance_m']:.3f} m)")
            continue
        print(f"{r['layout']}: {r['frames_below']} frames closer than {c:g} m (min {r['min_clearance_m']:.3f} m at "
              f"frame {r['min_frame']}, {describe_object(r['nearest'])})")
        for rg in r["ranges"]:
            print(f"  {range_text(rg)}")
        if r["frames_outside"] and not args.layout:
            from ..scene.model import resolve_layout_path

            print(f"  {r['frames_outside']} frames lie outside every room of {resolve_layout_path(arg)}: if the path was "
                  f"planned on another layout named '{r['layout']}' (an imported one), give its file with --layout")
    bad = [arg for r, arg in zip(reps, names) if not r["ok"]]
    print(f"PROBLEMS FOUND: camera path '{path.name}' breaks its {c:g} m clearance in {len(bad)} of {len(reps)} "
          f"layout(s); replan it: {replan_command(path, bad)}")
    return 1


def _cmd_generate(args) -> int:
    for f in generate_shipped(args.out_dir, args.only):
        p = load_path(f)
        st = p.meta["stats"]
        print(f"wrote {f} (+ .yaml): {len(p)} frames, {st['length_m']:.1f} m, min clearance {st['min_clearance_m']:.3f} m, "
              f"rooms {', '.join(st['rooms'])}")
    return 0


def register_cli(subparsers) -> None:
    """Add the ``path`` group to the ``synth`` command line."""
    grp = subparsers.add_parser("path", help="camera paths: plan (query, mapping), show, check, preview")
    sub = grp.add_subparsers(dest="cmd", required=True)
    plan = sub.add_parser("plan", help="plan a camera path and write it (TUM + .yaml)")
    ps = plan.add_subparsers(dest="kind", required=True)

    d = DEFAULTS

    def common(a, frames):
        a.add_argument("--frames", type=positive_int, default=frames, help=f"default {frames}")
        a.add_argument("--seed", type=int, default=d.seed)
        a.add_argument("--fps", type=float, default=d.fps, help=f"default {d.fps:g}")
        a.add_argument("--speed", type=float, default=d.speed, help=f"m/s (default {d.speed:g})")
        a.add_argument("--clearance", type=float, default=d.clearance, help=f"m from obstacles and walls (default {d.clearance:g})")
        a.add_argument("--obstacles", choices=("band", "all"), default=d.obstacles,
                       help="all: every object but ceiling-mounted ones (default); band: objects reaching the camera height band")
        a.add_argument("--name", help="path name (default: the output file's stem)")
        a.add_argument("--out", required=True, help="trajectory file (.txt); the .yaml sidecar goes next to it")

    a = ps.add_parser("query", help="a walk through every room, clear of the objects of every layout given")
    a.add_argument("--layouts", nargs="+", required=True, metavar="LAYOUT")
    common(a, d.query_frames)
    a.set_defaults(fn=_cmd_plan_query)
    a = ps.add_parser("mapping", help="a cross-hatch tour of one layout")
    a.add_argument("--layout", required=True)
    common(a, d.mapping_frames)
    a.set_defaults(fn=_cmd_plan_mapping)
    a = sub.add_parser("generate", help="rewrite the shipped paths (scenes/paths: query, mapping)")
    a.add_argument("--out-dir", help="default: scenes/paths of a checkout or $SYNTH_SCENES_DIR; installed: ./scenes/paths")
    a.add_argument("--only", nargs="*", choices=sorted(SHIPPED))
    a.set_defaults(fn=_cmd_generate)
    a = sub.add_parser("show", help="frames, length, duration, speed, heights, rooms visited")
    a.add_argument("path", help="path name (scenes/paths/NAME.txt) or file")
    a.add_argument("--layout", help="layout for rooms and clearance (default: the first it was planned on)")
    add_json(a)
    a.set_defaults(fn=_cmd_show)
    a = sub.add_parser("check", help="does the path keep its declared clearance in these layouts? (exit 1 if not)")
    a.add_argument("path", help="path name or file")
    a.add_argument("--layout", action="append", metavar="LAYOUT",
                   help="layout to check (repeat for several; default: the layouts it was planned on)")
    a.add_argument("--clearance", type=float, help="m (default: the clearance the path was planned with)")
    add_json(a)
    a.set_defaults(fn=_cmd_check)
    a = sub.add_parser("preview", help="top-down plot of a path over a layout")
    a.add_argument("path", help="path name or file")
    a.add_argument("--layout", help="default: the first layout it was planned on")
    a.add_argument("--out", required=True)
    a.set_defaults(fn=_cmd_preview)
