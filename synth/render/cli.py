"""``synth tour render``: one tour (a layout x a lighting x a camera path) from the command line
(docs/rendering.md). Its defaults are ``synth.render.settings.DEFAULTS``."""

from __future__ import annotations

from formats.cli import add_quiet, add_workers
from formats.errors import UserError

from .settings import DEFAULTS, DEVICES, QUALITY


def cmd_tour_render(args) -> int:
    from .render_tour import TourSpec, render_tour

    w, h = _size(args.size)
    spec = TourSpec(layout=args.layout, path=args.path, out=args.out, lighting=args.lighting, renderer=args.renderer,
                    quality=args.quality, width=w, height=h, frames=args.frames, seed=args.seed, device=args.device,
                    previews=args.previews, chunk_size=args.chunk_size, workers=args.workers,
                    check_clearance=not args.allow_clearance_breach)
    meta = render_tour(spec, progress=not args.quiet)
    print(f"{args.out}: {meta['n_frames']} frames of {meta['layout']} / {meta['lighting'] or 'geometry only'} / "
          f"{meta['path']} ({meta['renderer']}) in {meta['wall_time_s']:.1f} s")
    return 0


def _size(text: str) -> tuple[int, int]:
    try:
        w, h = (int(v) for v in text.lower().split("x"))
        if w <= 0 or h <= 0:
            raise ValueError
        return w, h
    except ValueError:
        raise UserError(f"--size must look like 640x480, got {text!r}") from None


def register_cli(subparsers) -> None:
    tr = subparsers.add_parser("tour", help="render one tour: a layout x a lighting x a camera path")
    ts = tr.add_subparsers(dest="cmd", required=True)
    a = ts.add_parser("render", help="render (or finish rendering) a tour directory")
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
