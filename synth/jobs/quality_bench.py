"""``synth bench quality``: the views of a design and the command; the renders and measures are
``synth.render.quality``'s (docs/rendering.md#quality-against-time)."""

from __future__ import annotations

import json
import sys
import time
from pathlib import Path

from vrformats.errors import UserError

from ..render.quality import PAPER_DB, format_report, plot, run_view, settings_list


def design_views(spec_name: str, work: Path, replicacad_root: str | None = None, lightings=None,
                 size: tuple[int, int] | None = None, progress=None) -> list[dict]:
    """One view per lighting of the spec's first tour: its layout file, the pose in the middle of
    its path, the intrinsics (the spec's, or ``size``), the seed."""
    from ..sources import spec_source
    from .plan import expand
    from .spec import load_spec

    spec = load_spec(spec_name)
    if replicacad_root and spec.replicacad is None:
        raise UserError(f"--replicacad-root: {spec_name} has no replicacad: section (its layouts are not ReplicaCAD scenes)")
    src = spec_source(spec)
    if src is not None:
        spec = src.prepare(spec, work / "scene", replicacad_root, progress=progress or (lambda m: None))
    plan = expand(spec, work / "job")
    first = next(iter(plan.tours.values()))
    tours = {p.lighting_name: p for p in plan.tours.values()
             if p.layout_file == first.layout_file and p.path_name == first.path_name and p.lighting_name}
    if not tours:
        raise UserError(f"{spec_name}: its first tour's layout and path are rendered in no lighting (geometry only)")
    if lightings:
        unknown = [lt for lt in lightings if lt not in tours]
        if unknown:
            raise UserError(f"--lighting {unknown[0]}: not a lighting of {spec_name}'s first layout and path; "
                            f"its lightings: {', '.join(tours)}")
    intr = first.intr.scaled(*size) if size else first.intr
    i = len(first.frame_ids) // 2
    views = []
    for lt, p in tours.items():
        if lightings and lt not in lightings:
            continue
        views.append({"name": f"{first.layout_name} {lt}", "spec": spec.name, "layout": str(p.layout_file.resolve()),
                      "lighting": p.spec.lighting, "lighting_name": lt, "pose": p.poses[i].tolist(), "path": p.path_name,
                      "frame": int(first.frame_ids[i]), "intrinsics": intr.to_dict(), "seed": spec.seed,
                      "poses_around": p.poses[max(0, i - 2): i + 3].tolist(), "fps": p.path_fps})
    return views


def cmd_quality(args) -> int:
    import tempfile

    from vrformats.atomic import write_json_atomic

    size = None
    if args.size:
        try:
            size = tuple(int(x) for x in args.size.lower().split("x"))
        except ValueError:
            size = ()
        if len(size) != 2 or min(size) <= 0:
            raise UserError(f"--size {args.size}: expected WIDTHxHEIGHT, e.g. 160x120")
    if args.json_out:
        from vrformats.errors import check_output_file

        check_output_file(args.json_out)
    settings = settings_list(quick=args.quick, reference_samples=args.reference_samples)
    say = (lambda m: print(m, file=sys.stderr, flush=True)) if not args.json else (lambda m: None)
    results = []
    with tempfile.TemporaryDirectory(prefix="synth_quality_") as tmp:
        tmp = Path(tmp)
        views = design_views(args.spec, tmp, args.replicacad_root, args.lighting, size, progress=say)
        t0 = time.time()
        for i, v in enumerate(views):
            say(f"{v['name']} ({i + 1}/{len(views)}): {len(settings)} renders ...")
            results.append(run_view(v, settings, tmp / f"view{i}", device=args.device, threads=args.threads, progress=say))
            if args.json_out:
                write_json_atomic(args.json_out, {"views": results, "reference": settings[0]["cycles"], "target_db": PAPER_DB},
                                  indent=1)
    doc = {"views": results, "reference": settings[0]["cycles"], "target_db": PAPER_DB, "wall_s": round(time.time() - t0, 1)}
    if args.plot:
        plot(results, args.plot)
    if args.json:
        print(json.dumps(doc, indent=1))
    else:
        print(format_report(results))
        if args.plot:
            print(f"plot: {args.plot}")
    return 0


def register_cli(sub) -> None:
    """Add ``quality`` to the ``synth bench`` subcommands ``sub`` (``synth.render.bench.register_cli``'s)."""
    from vrformats.cli import add_json, bounded_int, positive_int

    from ..render.quality import REFERENCE
    from ..render.settings import DEVICES

    a = sub.add_parser("quality", help="PSNR and SSIM of each quality preset and Cycles setting against a reference, "
                                       "beside its time")
    a.add_argument("--spec", default="replicacad_6x3",
                   help="the design whose first tour gives the views (a shipped spec name or a file; default: the paper's "
                        "design on the built-in apartment)")
    a.add_argument("--replicacad-root", help="the ReplicaCAD folder, for a spec with a replicacad: section")
    a.add_argument("--lighting", action="append", help="lightings to measure (default: every one of the design)")
    a.add_argument("--size", help="WIDTHxHEIGHT in place of the spec's (the same view, e.g. 160x120 on a small machine)")
    a.add_argument("--device", choices=list(DEVICES), default="cpu")
    a.add_argument("--threads", type=bounded_int(256, lo=0), default=0, metavar="N", help="Cycles threads (0: every core)")
    a.add_argument("--reference-samples", type=positive_int, metavar="N",
                   help=f"samples of the reference (default {REFERENCE['samples']})")
    a.add_argument("--quick", action="store_true", help="the presets and the samples ladder only")
    a.add_argument("--plot", metavar="PNG", help="write the quality-versus-time plot here")
    a.add_argument("--json-out", metavar="FILE", help="write the rows here, after every view (a long run keeps what it measured)")
    add_json(a)
    a.set_defaults(fn=cmd_quality)
