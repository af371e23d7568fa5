"""``synth tour render|check|show|export``: one tour (a layout x a lighting x a camera path) from the
command line (docs/rendering.md, docs/external_relocalizers.md). ``render``'s defaults are
``synth.render.settings.DEFAULTS``.

``synth dataset check|show|export`` are the old names of ``synth tour check|show|export``: they
still work, after one line on stderr saying so, and will be removed.
"""

from __future__ import annotations

import functools
import json
import sys

from vrformats.cli import add_json, add_quiet, add_sensor, add_workers
from vrformats.errors import UserError

from ..render.settings import DEFAULTS, DEVICES, QUALITY


def cmd_tour_render(args) -> int:
    from .render import TourSpec, render_tour

    w, h = _size(args.size)
    spec = TourSpec(layout=args.layout, path=args.path, out=args.out, lighting=args.lighting, renderer=args.renderer,
                    quality=args.quality, width=w, height=h, frames=args.frames, seed=args.seed, device=args.device,
                    previews=args.previews, chunk_size=args.chunk_size, workers=args.workers,
                    check_clearance=not args.allow_clearance_breach)
    meta = render_tour(spec, progress=not args.quiet)
    print(f"{args.out}: {meta['n_frames']} frames of {meta['layout']} / {meta['lighting'] or 'geometry only'} / "
          f"{meta['path']} ({meta['renderer']}) in {meta['wall_time_s']:.1f} s")
    return 0


def cmd_check(args) -> int:
    from .check import check_tour, format_report
    from .summary import design_summary, format_summary, is_design_folder

    if is_design_folder(args.dir):  # a render job's folder: what it holds, tour by tour
        s = design_summary(args.dir)
        print(json.dumps(s, indent=2) if args.json else format_summary(s))
        return 0 if s["complete"] == len(s["tours"]) else 1
    rep = check_tour(args.dir, consistency_pairs=args.pairs)
    if args.json:
        print(json.dumps(rep, indent=2))
    else:
        print(format_report(rep))
    return 0 if rep["ok"] else 1


def cmd_show(args) -> int:
    from vrformats.tour import Tour

    from .show import contact_sheet

    from .summary import design_mosaic, is_design_folder

    if is_design_folder(args.dir):  # a render job's folder: the first frame of every tour
        print(f"wrote {design_mosaic(args.dir, args.out, path=args.path)}")
        return 0
    tour = Tour(args.dir)
    if args.strip is not None:
        from .show import tour_strip

        print(f"wrote {tour_strip(tour, args.out, count=args.strip)}")
        return 0
    if args.video:
        from .show import tour_video

        out, n = tour_video(tour, args.out, every=args.every, fps=args.fps)
        print(f"wrote {out} ({n} frames)")
        return 0
    index = int(tour.frame_indices[0]) if args.frame is None else args.frame
    out = contact_sheet(tour, index, args.out, exposure=args.exposure)
    print(f"wrote {out}")
    return 0


def cmd_export(args) -> int:
    from vrformats import export

    m = export.export_tour(args.dir, args.format, args.out, role=args.role, exposure=args.exposure,
                           progress=not args.quiet and sys.stderr.isatty(), sensor=args.sensor,
                           sensor_seed=args.sensor_seed)
    print(export.summary_line(m, args.out))
    intr = m.get("intrinsics") or {}
    note = (intr.get("ace") or {}).get("note") or (intr.get("dsacstar") or {}).get("resize_note")
    if note:
        print(f"note: {note}")
    return 0


def _size(text: str) -> tuple[int, int]:
    """``--size WIDTHxHEIGHT``, within the bounds a spec's ``size`` has (``vrformats.fields.frame_size``)."""
    from vrformats.fields import frame_size

    try:
        w, h = (int(v) for v in text.lower().split("x"))
        if w <= 0 or h <= 0:
            raise ValueError
    except ValueError:
        raise UserError(f"--size must look like 640x480, got {text[:40]!r}") from None
    try:
        return frame_size("--size", [w, h], "size")
    except UserError as e:  # "--size: size: 99999x99999 is too large ...": name the option once
        raise UserError(str(e).replace("--size: size: ", "--size: ", 1)) from None


def register_cli(subparsers) -> None:
    """Add the ``tour`` command group to ``synth``."""
    tr = subparsers.add_parser("tour", help="one tour (a layout x a lighting x a camera path): render it, check it, "
                                            "look at a frame, export it")
    ts = tr.add_subparsers(dest="cmd", required=True)
    _add_render(ts)
    _add_check_show_export(ts)


def register_old_names(subparsers) -> None:
    """Add ``dataset`` (check|show|export), the old name of ``synth tour check|show|export``, to ``synth``."""
    old = subparsers.add_parser("dataset", help="old name of synth tour check|show|export (warns; will be removed)")
    _add_check_show_export(old.add_subparsers(dest="cmd", required=True), old_name=True)


def _old_name(fn, cmd: str):
    """``fn`` after one line on stderr: ``synth dataset CMD`` is the old name of ``synth tour CMD``."""
    @functools.wraps(fn)
    def run(args) -> int:
        print(f"synth dataset {cmd} is an old name: use synth tour {cmd}; it will be removed", file=sys.stderr)
        return fn(args)
    return run


def _add_render(sub) -> None:
    a = sub.add_parser("render", help="render (or finish rendering) a tour directory")
    a.add_argument("layout", help="layout name (apt_0) or file")
    a.add_argument("path", help="camera path name (query, mapping) or TUM file")
    a.add_argument("--out", required=True, help="tour directory")
    a.add_argument("--lighting", help="lighting preset (day, evening, night) or file; omit for geometry only")
    a.add_argument("--renderer", choices=["blender", "fast"], default=DEFAULTS.renderer)
    a.add_argument("--quality", default=DEFAULTS.quality, help=f"{' | '.join(QUALITY)} (default {DEFAULTS.quality})")
    a.add_argument("--size", default=DEFAULTS.size, help=f"WIDTHxHEIGHT (default {DEFAULTS.size})")
    a.add_argument("--frames", type=int, help="render the first N frames of the path")
    a.add_argument("--seed", type=int, default=DEFAULTS.seed, help=f"Cycles seed (default {DEFAULTS.seed})")
    a.add_argument("--device", default=DEFAULTS.device, choices=list(DEVICES), help=f"GPU: OptiX, else CUDA (default {DEFAULTS.device})")
    a.add_argument("--previews", action="store_true", help="also write 8-bit PNG previews")
    add_workers(a, "Blender processes")
    a.add_argument("--chunk-size", type=int, default=DEFAULTS.chunk_size, help=f"frames per Blender process (default {DEFAULTS.chunk_size})")
    a.add_argument("--allow-clearance-breach", action="store_true",
                   help="render even where the path comes closer to an object than its declared clearance "
                        "(checked for layouts the path was not planned on)")
    add_quiet(a)
    a.set_defaults(fn=cmd_tour_render)


def _add_check_show_export(sub, old_name: bool = False) -> None:
    """``check``, ``show`` and ``export`` under ``synth tour`` (or, with ``old_name``, ``synth dataset``)."""
    fn = _old_name if old_name else (lambda f, _cmd: f)
    a = sub.add_parser("check", help="completeness, channels, depth, ids and pose/depth consistency of a tour "
                                    "(exit 1 if problems are found)")
    a.add_argument("dir", help="tour directory (holds camera.json, poses.txt, frames/), or a render job's folder "
                   "(a summary of its tours)")
    add_json(a, "the full report")
    a.add_argument("--pairs", type=int, default=8, help="neighbouring frame pairs for the depth consistency test")
    a.set_defaults(fn=fn(cmd_check, "check"))
    a = sub.add_parser("show", help="contact sheet of one frame (RGB, depth, instance, semantic), a strip or an animation "
                                   "of a tour, or a mosaic of a render job's tours")
    a.add_argument("dir", help="tour directory, or a render job's folder (a mosaic of its tours' first frames)")
    a.add_argument("--frame", type=int, help="frame index (default: the first)")
    a.add_argument("--out", required=True, help="output image (.png)")
    a.add_argument("--exposure", type=float, help="linear RGB scale (default: automatic)")
    mode = a.add_mutually_exclusive_group()
    mode.add_argument("--strip", type=int, nargs="?", const=6, metavar="N",
                      help="a contact strip of N frames along the tour (default 6), RGB | depth | ids per row (.png/.jpg)")
    mode.add_argument("--video", action="store_true", help="an animation, RGB | depth | ids side by side (.gif; .mp4 "
                      "with imageio-ffmpeg)")
    a.add_argument("--every", type=int, help="with --video: every N-th frame (default: the tour's RGB frames)")
    a.add_argument("--path", help="for a render job's folder (a mosaic of every tour's first frame): only the tours "
                   "of this camera path")
    a.add_argument("--fps", type=float, default=10.0, help="with --video: frames per second (default 10)")
    a.set_defaults(fn=fn(cmd_show, "show"))
    a = sub.add_parser("export", help="write a tour in a layout other relocalizers read: 7scenes (DSAC*, ACE, hloc), "
                                     "ace (ACE/DSAC* train|test), tum-rgbd (RGB-D SLAM, evo), colmap (hloc)")
    a.add_argument("dir", help="tour directory")
    a.add_argument("--format", required=True, help="7scenes | ace | dsacstar | tum-rgbd | colmap")
    a.add_argument("--out", required=True, help="export folder (new or empty; the same export again resumes "
                                                "or does nothing)")
    a.add_argument("--role", default="query", help="mapping (ACE train/, 7-Scenes train split) | query (default)")
    a.add_argument("--exposure", default="auto", help="auto (per frame, default) | fixed (one factor per tour: "
                                                      "the median auto factor) | FACTOR (linear RGB scale)")
    add_sensor(a, "export the frames")
    add_quiet(a)
    a.set_defaults(fn=fn(cmd_export, "export"))
