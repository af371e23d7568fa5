"""``synth scene list|show|check|stats|preview|export-boxes|generate|build|rearrange|grade``: layouts from the
command line (docs/layouts.md); the scene sources add theirs to the group (``import-replicacad``: synth.sources,
docs/replicacad.md). Here, above ``synth.scene``, because the commands check, rearrange and plan paths."""

from __future__ import annotations

import json
from collections import Counter
from pathlib import Path

import numpy as np

from vrformats.atomic import write_json_atomic
from vrformats.cli import add_json, add_quiet
from vrformats.errors import UserError, check_output_file


def _print_json(obj) -> None:
    print(json.dumps(obj, indent=2))


def _write_json(path: Path, obj) -> None:
    write_json_atomic(path, obj, indent=1)


def _load(name):
    from ..scene.model import load_layout

    return load_layout(name)


# ---------------------------------------------------------------------------------------------
# scene subcommands


def cmd_list(args) -> int:
    from ..scene.model import list_layouts, load_layout

    names = list_layouts()
    if not names:
        print("no layouts (run `synth scene generate`)")
        return 0
    print(f"{'layout':<10} {'reference':<10} {'objects':>7} {'classes':>7} {'area_m2':>8}")
    for n in names:
        lay = load_layout(n)
        print(f"{n:<10} {lay.reference or '-':<10} {len(lay.objects):>7} {len({o.cls for o in lay.objects}):>7} {lay.stage.area:>8.1f}")
    return 0


def _summary(lay) -> dict:
    return {
        "name": lay.name,
        "reference": lay.reference,
        "seed": lay.seed,
        "floor_area_m2": round(lay.stage.area, 2),
        "ceiling_height_m": lay.stage.ceiling_height,
        "rooms": {r.name: {"type": r.type, "area_m2": round(r.area, 2)} for r in lay.stage.rooms},
        "walls": len(lay.stage.walls),
        "doors": sum(o.kind == "door" for o in lay.stage.openings),
        "windows": sum(o.kind == "window" for o in lay.stage.openings),
        "objects": len(lay.objects),
        "movable": sum(o.movable for o in lay.objects),
        "classes": dict(sorted(Counter(o.cls for o in lay.objects).items())),
        "fixtures": dict(Counter(f.kind for f in lay.fixtures)),
    }


def cmd_show(args) -> int:
    lay = _load(args.name)
    s = _summary(lay)
    if args.json:
        _print_json(s)
        return 0
    print(f"layout {s['name']}" + (f" (rearranged from {s['reference']})" if s["reference"] else ""))
    print(f"  floor area {s['floor_area_m2']} m2, ceiling {s['ceiling_height_m']} m, {s['walls']} walls, {s['doors']} doors, {s['windows']} windows")
    for name, r in s["rooms"].items():
        print(f"  room {name:<10} {r['type']:<9} {r['area_m2']:6.1f} m2")
    print(f"  {s['objects']} objects ({s['movable']} movable) in {len(s['classes'])} classes:")
    print("   " + ", ".join(f"{c} x{n}" for c, n in s["classes"].items()))
    print("  fixtures: " + ", ".join(f"{k} x{v}" for k, v in s["fixtures"].items()))
    return 0


def cmd_stats(args) -> int:
    from .rearrange import target_ranges
    from ..scene.stats import PAPER_RANGES, change_stats

    ref = _load(args.ref)
    st = change_stats(ref, _load(args.var))
    if args.json:
        _print_json(st)
        return 0
    ranges = target_ranges(ref)
    what = "paper" if ranges == PAPER_RANGES else "scaled"  # an imported flat of another size: synth.scene.stats.scaled_ranges
    print(f"{st['variant']} against {st['reference']}:")
    for k, (lo, hi) in ranges.items():
        print(f"  {k:<16} {st[k]:>7}   {what} {lo}-{hi}  {'ok' if lo <= st[k] <= hi else 'OUT OF RANGE'}")
    return 0


def cmd_check(args) -> int:
    from .validity import check_layout

    rep = check_layout(_load(args.name))
    if args.json:
        _print_json(rep.to_dict())
    else:
        print(f"{rep.layout}: {rep.objects} objects, {rep.classes} classes")
        for st in rep.structure:
            print(f"  stage: {st['why']}")
        print(f"  collisions {len(rep.collisions)}, unsupported {len(rep.unsupported)}, "
              f"blocked doors {len(rep.blocked_doors)}, covered openings {len(rep.covered_openings)}")
        for c in rep.collisions:
            print(f"  collision: {c['a']} ({c['classes'][0]}) x {c['b']} ({c['classes'][1]})")
        for u in rep.unsupported:
            print(f"  unsupported: {u['id']} ({u['class']}) on {u['support']}: {u['why']}")
        for d in rep.blocked_doors:
            print(f"  blocked door {d['door']}: {d['why']}")
        for c in rep.covered_openings:
            print(f"  opening {c['opening']} covered by {c['id']} ({c['class']})")
        print("  OK" if rep.ok else "  PROBLEMS FOUND")
    return 0 if rep.ok else 1


def cmd_export_boxes(args) -> int:
    from ..scene.model import boxes_document

    check_output_file(args.out)
    doc = boxes_document(_load(args.name))
    out = Path(args.out)
    _write_json(out, doc)
    print(f"wrote {len(doc['boxes'])} boxes of {doc['layout']} to {out} ({out.stat().st_size / 1024:.1f} kB)")
    return 0


def cmd_preview(args) -> int:
    from ..scene.preview import plot_layout

    lay = _load(args.name)
    ref = _load(args.diff) if args.diff else None
    out = plot_layout(lay, args.out, ref=ref)
    print(f"wrote {out}")
    return 0


def cmd_generate(args) -> int:
    """Regenerate the built-in layouts apt_0..apt_5 (deterministic)."""
    from tqdm import tqdm

    from .apartment import DEFAULT_SEED, generate_apartment
    from ..resources import generated_dir
    from .rearrange import BUILTIN_VARIANTS, make_variant, reference_walkway
    from ..scene.model import save_layout

    out = Path(args.out_dir) if args.out_dir else generated_dir("layouts")
    ref = generate_apartment(DEFAULT_SEED, "apt_0")
    save_layout(ref, out / "apt_0.yaml")
    unknown = sorted(set(args.only or ()) - {v.name for v in BUILTIN_VARIANTS})
    if unknown:
        raise UserError(f"--only {unknown[0]}: not a built-in variant; choose from {', '.join(v.name for v in BUILTIN_VARIANTS)}")
    specs = [v for v in BUILTIN_VARIANTS if not args.only or v.name in args.only]
    walkway = reference_walkway(ref)
    for spec in tqdm(specs, desc="variants", unit="layout", disable=args.quiet):
        save_layout(make_variant(ref, spec, walkway=walkway), out / f"{spec.name}.yaml")
    print(f"wrote apt_0 and {len(specs)} variants to {out}")  # the result: --quiet drops only the progress bar
    return 0


def cmd_build(args) -> int:
    """The scene pipeline: generate apt_0..apt_5, check them, print their change statistics, plot them."""
    from tqdm import tqdm

    from .apartment import DEFAULT_SEED, generate_apartment
    from .validity import check_layout
    from ..scene.preview import plot_layout
    from .rearrange import BUILTIN_VARIANTS, make_variant, reference_walkway
    from ..scene.model import boxes_document, save_layout
    from ..scene.stats import change_stats

    out = Path(args.out)
    (out / "layouts").mkdir(parents=True, exist_ok=True)
    ref = generate_apartment(DEFAULT_SEED, "apt_0")
    layouts = [ref]
    walkway = reference_walkway(ref)
    for spec in tqdm(BUILTIN_VARIANTS, desc="rearranging", unit="layout"):
        layouts.append(make_variant(ref, spec, walkway=walkway))
    rows = []
    for lay in tqdm(layouts, desc="checking + previews", unit="layout"):
        save_layout(lay, out / "layouts" / f"{lay.name}.yaml")
        rep = check_layout(lay)
        plot_layout(lay, out / "previews" / f"{lay.name}.png", ref=ref if lay is not ref else None)
        _write_json(out / "boxes" / f"{lay.name}.json", boxes_document(lay))
        st = change_stats(ref, lay) if lay is not ref else None
        rows.append((lay, rep, st))
    print()
    s = _summary(ref)
    print(f"apt_0: {s['floor_area_m2']} m2, {len(s['rooms'])} rooms, {s['objects']} objects in {len(s['classes'])} classes")
    _print_stats_table(rows)
    print(f"\nlayouts, boxes and previews in {out}/ (previews: {out / 'previews'})")
    return 0 if all(r.ok for _, r, _ in rows) else 1


def _print_stats_table(rows, ranges: dict | None = None) -> None:
    """Objects, check and change statistics per layout against the paper's ranges, or ``ranges``
    (scaled for an imported flat) (rows: (layout, report, stats|None))."""
    from ..scene.stats import PAPER_RANGES

    ranges = ranges or PAPER_RANGES
    label = "paper" if ranges == PAPER_RANGES else "target"
    w = max([7] + [len(lay.name) for lay, _, _ in rows])
    print(f"{'layout':<{w}} {'objects':>7} {'check':>6} " + " ".join(f"{k:>15}" for k in ranges))
    print(f"{label:<{w}} {'':>7} {'':>6} " + " ".join(f"{f'{lo}-{hi}':>15}" for lo, hi in ranges.values()))
    for lay, rep, st in rows:
        vals = " ".join(f"{st[k]:>15}" for k in ranges) if st else " ".join(f"{'-':>15}" for _ in ranges)
        print(f"{lay.name:<{w}} {len(lay.objects):>7} {'ok' if rep.ok else 'FAIL':>6} {vals}")


def _check_out_file(out: Path, suffixes=(".yaml", ".yml")) -> None:
    """Refuse, before any work, a layout ``--out`` that could not be written; creates nothing."""
    if out.suffix not in suffixes:
        raise UserError(f"--out: cannot write {out}: a layout file ends in {' or '.join(suffixes)}")
    try:
        check_output_file(out)
    except UserError as e:
        raise UserError(f"--out: {e}") from None


def cmd_rearrange(args) -> int:
    """A new rearranged variant of BASE from a seed: the operator, ranges and checks of apt_1..apt_5."""
    from .validity import check_layout
    from .rearrange import new_problems, new_variant, target_ranges
    from ..scene.model import save_layout
    from ..scene.stats import change_stats

    out = Path(args.out)
    if args.seed < 0:
        raise UserError(f"--seed must be >= 0, got {args.seed}")
    if args.attempts <= 0:
        raise UserError(f"--attempts must be positive, got {args.attempts}")
    _check_out_file(out)
    ref = _load(args.base)
    var = new_variant(ref, args.name or out.stem, args.seed, attempts=args.attempts)  # synth.rearrange's code path
    save_layout(var, out)
    rep, ref_rep = check_layout(var), check_layout(ref)
    st = change_stats(ref, var)
    print(f"{var.name}: rearranged from {ref.name} (seed {args.seed}, attempt {var.meta['attempt']}), "
          f"{len(var.objects)} objects")
    _print_stats_table([(ref, ref_rep, None), (var, rep, st)], target_ranges(ref))
    from .rearrange import is_imported
    from ..scene.stats import change_table, scale_note

    print()
    if is_imported(ref):
        print(scale_note(ref))
    print("\n".join(change_table(st, target_ranges(ref))))
    print(f"wrote {out}")
    # a reference that does not check clean (an imported scene) only asks the variant to add no problem
    return 0 if (rep.ok or (not ref_rep.ok and not new_problems(ref_rep, rep))) else 1


def cmd_grade(args) -> int:
    """Nested variants of BASE at graded strengths (synth.layout.graded), one file per level."""
    from vrformats.atomic import write_bytes_atomic

    from .graded import BEYOND, check_strengths, graded_variants, level_name, moved_ids
    from .rearrange import target_ranges
    from .validity import check_layout
    from ..scene.model import resolve_layout_path, save_layout
    from ..scene.stats import change_stats

    levels = check_strengths(args.levels, "--levels")
    if len(levels) + bool(args.beyond) < 2:
        raise UserError("--levels: a graded set needs at least two levels (e.g. --levels 0 0.5 1)")
    if args.seed < 0:
        raise UserError(f"--seed must be >= 0, got {args.seed}")
    out = Path(args.out)
    if out.exists() and not out.is_dir():
        raise UserError(f"--out: {out} exists and is not a folder")
    from ..paths.files import load_path

    base_file = resolve_layout_path(args.base)
    ref = _load(args.base)
    path = load_path(args.path)
    # the levels keep out of the camera path they will be rendered with (as apt_1..apt_5 keep out of
    # apt_0's walkway), so that the experiments' shared path stays valid in every level
    walkway = np.asarray(path.poses)[::3, :2, 3].copy()
    variants = graded_variants(ref, levels, args.seed, walkway=walkway, beyond=args.beyond)
    rows, files = [], []
    prev: set = set()
    for level, var in variants:
        moved = moved_ids(ref, var)
        if not prev <= moved:  # cannot happen by construction; a layout that broke it must not be written
            raise RuntimeError(f"level {level}: the moved objects are not a superset of the level below's")
        prev = moved
        rows.append((var, check_layout(var), change_stats(ref, var) if var is not ref else None))
    out.mkdir(parents=True, exist_ok=True)
    for (level, var), _ in zip(variants, rows):
        f = out / f"{level_name(ref.name, level) if var is not ref else ref.name}.yaml"
        if var is ref:  # level 0 is the base itself, byte for byte
            write_bytes_atomic(f, base_file.read_bytes())
        else:
            save_layout(var, f)
        files.append(f)
    # the camera path every level is rendered with must keep its clearance in every level
    from ..paths.clearance import clearance_report
    from ..paths.files import save_path

    reps = [clearance_report(path, var) for _, var in variants]
    path_note = f"path {path.name}: clear of every level (min {min(r['min_clearance_m'] for r in reps):.2f} m)"
    if not all(r["ok"] for r in reps):
        from ..paths.query import plan_query_path

        bad = [r["layout"] for r in reps if not r["ok"]]
        new = plan_query_path([var for _, var in variants], frames=len(path.poses), seed=args.seed,
                              name=f"{path.name}_{ref.name}_graded")
        pf = save_path(new, out / "paths" / f"{new.name}.txt")
        path_note = (f"path {path.name} comes too close to objects in {', '.join(bad)}: replanned on every level "
                     f"-> {pf} (render the levels with it)")
    _print_stats_table(rows, target_ranges(ref))
    print()
    print(f"{'level':>7} {'layout':<16} {'units moved':>12} {'fixed moved':>12}")
    for (level, var), (_, rep, st) in zip(variants, rows):
        um = var.meta.get("units_moved", 0) if var is not ref else 0
        print(f"{level if level == BEYOND else format(level, '.2f'):>7} {var.name:<16} "
              f"{f'{um}/' + str(var.meta.get('units', '-')):>12} {var.meta.get('fixed_moved', 0):>12}")
    print(path_note)
    print(f"wrote {len(files)} layouts to {out}")
    return 0 if all(rep.ok for _, rep, _ in rows) else 1


def register_cli(subparsers):
    sc = subparsers.add_parser("scene", help="layouts: list, show, check, stats, preview, export boxes")
    ss = sc.add_subparsers(dest="cmd", required=True)

    a = ss.add_parser("list", help="list the layouts in scenes/layouts")
    a.set_defaults(fn=cmd_list)
    a = ss.add_parser("show", help="summary of a layout")
    a.add_argument("name", help="layout name (apt_0) or file")
    add_json(a)
    a.set_defaults(fn=cmd_show)
    a = ss.add_parser("stats", help="change statistics of VAR against REF (paper Sec. IV-A)")
    a.add_argument("ref")
    a.add_argument("var")
    add_json(a)
    a.set_defaults(fn=cmd_stats)
    a = ss.add_parser("check", help="interpenetrations, unsupported objects, blocked doors (exit 1 if any)")
    a.add_argument("name", help="layout name or file")
    add_json(a)
    a.set_defaults(fn=cmd_check)
    a = ss.add_parser("export-boxes", help="ground-truth boxes in the relocalizer's map format")
    a.add_argument("name")
    a.add_argument("--out", required=True)
    a.set_defaults(fn=cmd_export_boxes)
    a = ss.add_parser("preview", help="top-down plot of a layout (with --diff: changes against REF)")
    a.add_argument("name")
    a.add_argument("--diff", metavar="REF")
    a.add_argument("--out", required=True)
    a.set_defaults(fn=cmd_preview)
    a = ss.add_parser("generate", help="regenerate the built-in layouts apt_0..apt_5")
    a.add_argument("--out-dir", help="default: scenes/layouts of a checkout or $SYNTH_SCENES_DIR; installed: ./scenes/layouts")
    a.add_argument("--only", nargs="*", help="variant names to regenerate (apt_0 is always written)")
    add_quiet(a)
    a.set_defaults(fn=cmd_generate)
    a = ss.add_parser("build", help="the scene pipeline: generate, check, stats, boxes and previews into --out")
    a.add_argument("--out", default="out/scenes")
    a.set_defaults(fn=cmd_build)
    a = ss.add_parser("rearrange", help="a new rearranged variant of BASE from a seed (paper's change ranges, checked)")
    a.add_argument("base", help="layout to rearrange (name or file), e.g. apt_0")
    a.add_argument("--seed", type=int, required=True, help="variant seed (sub-seeds seed*1000+k are tried in turn)")
    a.add_argument("--out", required=True, help="layout file to write (.yaml)")
    a.add_argument("--name", help="layout name (default: the output file's stem)")
    a.add_argument("--attempts", type=int, default=40, help="sub-seeds to try before giving up (default 40)")
    a.set_defaults(fn=cmd_rearrange)
    a = ss.add_parser("grade", help="nested variants of BASE at graded strengths 0..1 (each level adds moves and nothing else)")
    a.add_argument("base", help="layout to rearrange (name or file), e.g. apt_0")
    a.add_argument("--levels", type=float, nargs="+", required=True,
                   help="strengths in [0, 1]: the fraction of movable objects moved (0 = the base itself)")
    a.add_argument("--beyond", action="store_true",
                   help="one more level: every movable object and the fixed fittings moved, objects removed and added")
    a.add_argument("--seed", type=int, default=0, help="the move sequence's seed (default 0)")
    a.add_argument("--path", default="query", help="camera path the levels must keep clear of (default query); "
                                                   "replanned on every level, into OUT/paths/, if they do not")
    a.add_argument("--out", required=True, help="folder for the level layouts (<base>_g<percent>.yaml)")
    a.set_defaults(fn=cmd_grade)
    return ss  # the scene sources add their commands (synth.sources: import-replicacad)
