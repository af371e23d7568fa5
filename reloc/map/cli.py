"""The ``reloc map`` commands: ``ground-truth`` (a tour's ground-truth boxes as a map), ``build``
(a map from a rendered mapping tour, with its errors against the tour's ground truth) and ``show``.
"""

from __future__ import annotations

import json
import sys
from collections import Counter

from vrformats.atomic import write_text_atomic
from vrformats.errors import UserError, check_output_file
from vrformats.cli import add_quiet

from .build import build_map
from .document import dumps_map, map_from_tour
from .scoring import errors_against_ground_truth
from .settings import DEFAULT_STRIDE, MapBuildSettings


def summary_line(doc: dict, size_bytes: int, errors: dict | None, report: dict | None = None) -> str:
    kinds = Counter(b.get("kind", "object") for b in doc["boxes"])
    parts = [f"{len(doc['boxes'])} boxes ("
             + ", ".join(f"{kinds.get(k, 0)} {k}s" for k in ("object", "wall", "floor", "ceiling")) + ")",
             f"{size_bytes / 1024:.1f} kB"]
    if report is not None:
        parts.append(f"{report['frames_used']}/{report['frames_in_tour']} frames in {report['wall_time_s']:.1f} s")
    if errors is not None:
        errs = []
        for k, e in errors["by_kind"].items():
            if e["matched"]:
                errs.append(f"{k} {e['median_center_err_m']:.3f}/{e['median_size_err_max_m']:.3f}")
        parts.append("median center/size err m: " + (", ".join(errs) or "-"))
        parts.append(f"{errors['gt_unobserved']} GT unobserved, {errors['built_unmatched']} unmatched")
    return "; ".join(parts)


def cmd_ground_truth(args) -> int:
    check_output_file(args.out)
    doc = map_from_tour(args.tour)
    out = write_text_atomic(args.out, dumps_map(doc))
    print(f"wrote {len(doc['boxes'])} boxes of {doc['layout']} to {out} ({out.stat().st_size / 1024:.1f} kB)")
    return 0


def cmd_build(args) -> int:
    check_output_file(args.out)
    if args.report:
        check_output_file(args.report)
    from vrformats.tour import Tour

    tour = Tour(args.tour)  # UserError when missing or malformed
    detector = None
    if args.detector != "oracle":
        from ..detection.factory import build_detector, detector_spec_from_args

        detector = build_detector(detector_spec_from_args(args), tour.class_names())
    doc, report = build_map(tour.root, detector=detector, stride=args.stride, voxel=args.voxel, progress=not args.quiet)
    for w in report["warnings"]:
        print(f"warning: {w}", file=sys.stderr)
    if not doc["boxes"]:
        raise UserError(report["warnings"][0] if report["warnings"] else f"{args.tour}: no boxes built")
    from .boxmap import BoxMap

    BoxMap(doc, source=str(args.out))  # validates what is about to be written
    out = write_text_atomic(args.out, dumps_map(doc))
    errors = errors_against_ground_truth(tour, doc)  # None without ground truth
    if args.report:
        write_text_atomic(args.report, json.dumps({"build": report, "errors": errors}, indent=1) + "\n")
    print(f"{out}: " + summary_line(doc, out.stat().st_size, errors, report))
    return 0


def cmd_show(args) -> int:
    from .boxmap import BoxMap

    if args.gt and not args.plot:
        raise UserError("--gt: only with --plot FILE (the figure of the map against the ground truth)")
    if args.plot:
        check_output_file(args.plot)
    bmap = BoxMap.load(args.file)
    s = bmap.summary()
    for k, v in s.items():
        if isinstance(v, dict):
            v = ", ".join(f"{a} {b}" for a, b in v.items())
        print(f"{k:<18} {v}")
    if args.plot:
        from vrformats.yamlfile import read_json

        from ..figures import map_figure

        doc = read_json(args.file)
        gt_doc = errors = None
        if args.gt:
            from vrformats.tour import Tour

            tour = Tour(args.gt)
            gt_doc = tour.objects()
            errors = errors_against_ground_truth(tour, doc)
            print(summary_line(doc, bmap.size_bytes, errors, None))
        print(f"plot: {map_figure(doc, args.plot, gt_doc, errors)}")
    return 0


def register_cli(subparsers) -> None:
    """Add the ``map`` command group: ground-truth, build, show."""
    g = subparsers.add_parser("map", help="box maps: a tour's ground truth, built from a mapping tour, summary")
    ms = g.add_subparsers(dest="cmd", required=True)
    a = ms.add_parser("ground-truth", help="the ground-truth boxes of a tour's layout (its objects.json) as a map")
    a.add_argument("tour", metavar="TOUR_DIR", help="tour directory")
    a.add_argument("--out", required=True, help="map file (.json)")
    a.set_defaults(fn=cmd_ground_truth)
    a = ms.add_parser("build", help="build a map from a rendered mapping tour (oracle or learned detector)")
    a.add_argument("tour", metavar="TOUR_DIR", help="tour directory")
    a.add_argument("--out", required=True, help="map file (.json)")
    a.add_argument("--stride", type=int, default=DEFAULT_STRIDE, help=f"use every N-th frame (default {DEFAULT_STRIDE})")
    a.add_argument("--voxel", type=float, default=MapBuildSettings.voxel,
                   help=f"voxel size in metres (default {MapBuildSettings.voxel:g})")
    a.add_argument("--report", metavar="FILE.json", help="write the build report and per-box errors against the tour's ground truth")
    add_quiet(a)
    from ..detection.factory import add_detector_arguments

    add_detector_arguments(a)
    a.set_defaults(fn=cmd_build)
    a = ms.add_parser("show", help="summary of a map file; --plot: the map top-down, against the ground truth with --gt")
    a.add_argument("file")
    a.add_argument("--plot", metavar="FILE.png", help="draw the map's object and wall boxes top-down")
    a.add_argument("--gt", metavar="TOUR_DIR", help="with --plot: colour the boxes against this tour's ground truth "
                   "(matched, other class, extra, missed)")
    a.set_defaults(fn=cmd_show)
