"""``reloc bench stability``: how far an experiment's figures move under what another machine changes.

Another processor changes an experiment's inputs in their last bits, in two places:

* **the detector**: onnxruntime's kernels, thread count and graph optimisation change the learned
  detector's output (``reloc.detection.learned.Perturbation``: a one-level 8-bit input jitter with
  several seeds, onnxruntime with 2 threads, graph optimisation off);
* **the render**: Cycles' and OpenImageDenoise's arithmetic take other code paths, so the RGB frames
  themselves differ. The render perturbations re-render the design's RGB passes with another Cycles
  seed, the other denoiser prefilter, or one Cycles thread (``synth render --seed/--cycles/--threads``
  in a child process: reloc imports nothing of synth); depth and ids are the unperturbed job's,
  hard-linked (``--geometry-from``), so only the appearance changes. Each such render is a job folder
  ``OUT/renders/<name>/``, resumable like any.

Each perturbation reruns the experiment (its ``methods`` narrowed to ``--methods``, plus those a
``--checks`` file names) in its own folder ``OUT/<name>/``, resumable like any experiment. The report
(``OUT/stability.md``, ``OUT/stability.json``) gives per figure the unperturbed value and interval,
each perturbed value, the spread (max - min, points) and whether every perturbed value lies inside
the unperturbed interval; per tour the largest loss; per render perturbation how much the RGB
changed; and with ``--checks``, per check its margin to its bound beside the largest move any
perturbation caused. ``--max-spread``, ``--max-tour-loss`` and the checks make it a gate (exit 1).
"""

from __future__ import annotations

import dataclasses
import json
import subprocess
import sys
from pathlib import Path

import numpy as np

from vrformats.atomic import write_json_atomic, write_text_atomic
from vrformats.cli import add_json, add_quiet, add_workers, fraction
from vrformats.errors import UserError

# the default perturbations of the detector: name -> {"detector": Perturbation settings}
DEFAULT_PERTURBATIONS = {
    "jitter-1": {"detector": {"input_jitter": 1, "seed": 1}},
    "jitter-2": {"detector": {"input_jitter": 1, "seed": 2}},
    "jitter-3": {"detector": {"input_jitter": 1, "seed": 3}},
    "threads-2": {"detector": {"threads": 2}},
    "no-graph-opt": {"detector": {"graph_optimization": False}},
}
PREFILTERS = ("NONE", "FAST", "ACCURATE")  # OpenImageDenoise's (synth.render.settings.DENOISE_PREFILTERS)
# the figures compared: (label, mode, key in "all" or "factors")
FIGURES = (("closure 1 m/10°", "closure", "recall_1m_10deg"), ("closure 0.25 m/5°", "closure", "recall_25cm_5deg"),
           ("causal 1 m/10°", "causal", "recall_1m_10deg"), ("closure day", "closure", "day"),
           ("closure evening", "closure", "evening"), ("closure night", "closure", "night"),
           ("closure ΔL", "closure", "delta_L"), ("closure kept", "closure", "kept"))
PERTURBATION_FORMS = ("jitter:SEED[:LEVELS], threads:N, no-graph-opt (the detector); render-seed:N, "
                      "prefilter:NONE|FAST|ACCURATE, render-threads:N (the render)")


def parse_perturbation(text: str) -> tuple[str, dict]:
    """``jitter:SEED[:LEVELS]``, ``threads:N``, ``no-graph-opt`` (the detector) or ``render-seed:N``,
    ``prefilter:NAME``, ``render-threads:N`` (the render) -> (name, {"detector"|"render": settings})."""
    from vrformats.cli import MAX_WORKERS
    from ..detection.learned import Perturbation

    parts = text.split(":")
    try:
        if parts[0] == "jitter" and len(parts) in (2, 3):
            out = {"detector": {"input_jitter": int(parts[2]) if len(parts) == 3 else 1, "seed": int(parts[1])}}
        elif parts[0] == "threads" and len(parts) == 2:
            out = {"detector": {"threads": int(parts[1])}}
        elif parts == ["no-graph-opt"]:
            out = {"detector": {"graph_optimization": False}}
        elif parts[0] == "render-seed" and len(parts) == 2:
            seed = int(parts[1])
            if not 0 <= seed <= 2**31 - 1:
                raise ValueError(f"a Cycles seed is from 0 to {2**31 - 1}")
            out = {"render": {"seed": seed}}
        elif parts[0] == "prefilter" and len(parts) == 2:
            if parts[1] not in PREFILTERS:
                raise ValueError(f"expected one of {', '.join(PREFILTERS)}")
            out = {"render": {"cycles": {"denoise_prefilter": parts[1]}}}
        elif parts[0] == "render-threads" and len(parts) == 2:
            n = int(parts[1])
            if not 1 <= n <= MAX_WORKERS:
                raise ValueError(f"Cycles threads from 1 to {MAX_WORKERS}")
            out = {"render": {"threads": n}}
        else:
            raise ValueError(f"expected {PERTURBATION_FORMS}")
        if "detector" in out:
            Perturbation(**out["detector"])
    except ValueError as e:
        raise UserError(f"--perturbation {text}: {e}") from None
    return text.replace(":", "-"), out


def default_render_perturbations(tours_root: Path) -> dict:
    """The render perturbations of a design whose tours carry Cycles RGB (else none): the next Cycles
    seed, the other denoiser prefilter (FAST <-> ACCURATE; none without the denoiser) and one Cycles
    thread, read from a tour's meta.json."""
    from vrformats.design import list_tours

    metas = [m for m in list_tours(tours_root).values() if (m.get("settings") or {}).get("quality_settings")]
    if not metas:
        return {}
    m = metas[0]
    q = m["settings"]["quality_settings"]
    seed = int(m.get("seed") or 0)
    out = {f"render-seed-{seed + 1}": {"render": {"seed": seed + 1}}}
    if q.get("denoise"):
        other = "ACCURATE" if q.get("denoise_prefilter") != "ACCURATE" else "FAST"
        out[f"prefilter-{other}"] = {"render": {"cycles": {"denoise_prefilter": other}}}
    out["render-threads-1"] = {"render": {"threads": 1}}
    return out


def render_flags(settings: dict) -> list[str]:
    """``synth render`` options of a render perturbation's settings."""
    flags = []
    if "seed" in settings:
        flags += ["--seed", str(settings["seed"])]
    if "threads" in settings:
        flags += ["--threads", str(settings["threads"])]
    for k, v in (settings.get("cycles") or {}).items():
        flags += ["--cycles", f"{k}={v}"]
    return flags


def render_perturbed(spec, job: Path, settings: dict, workers: int, progress: bool) -> None:
    """Re-render the RGB of ``spec``'s design into the job folder ``job`` under ``settings``
    (``synth render`` in a child process that dies with this one; geometry linked from the unperturbed
    job). Resumes a job folder that is there."""
    import importlib.util

    from vrformats.lifetime import child_dies_with_parent, stop_processes

    root = Path(spec.tours_root)
    if importlib.util.find_spec("synth") is None:
        raise UserError("render perturbations re-render the design with synth, which is not installed")
    if not (root / "job_state.json").is_file():
        raise UserError(f"{root}: render perturbations re-render the job whose tours these are, and this folder holds "
                        "no render job (no job_state.json); give --tours the job folder, or --no-render")
    argv = [sys.executable, "-m", "synth.cli", "render", str(spec.render), "--out", str(job), "--geometry-from", str(root),
            "--workers", str(workers), *render_flags(settings)]
    if (job / "job_state.json").is_file():
        argv.append("--resume")
    if not progress:
        argv.append("--quiet")
    proc = subprocess.Popen(argv, stdout=subprocess.DEVNULL if not progress else None, preexec_fn=child_dies_with_parent)
    try:
        rc = proc.wait()
    except KeyboardInterrupt:
        stop_processes([proc])
        raise
    if rc != 0:
        raise UserError(f"{job}: re-rendering failed (synth render exited {rc}; its message is above); the same "
                        "command resumes it")


def same_design(base: Path, other: Path, tours) -> None:
    """Refuse a perturbed render whose tours are not the unperturbed ones re-rendered (other poses)."""
    for name in tours:
        a, b = Path(base) / name / "poses.txt", Path(other) / name / "poses.txt"
        if not b.is_file() or a.read_bytes() != b.read_bytes():
            raise UserError(f"{other / name}: not the tour {a.parent} re-rendered (other poses); the tours in {base} "
                            "were not rendered from this spec's render job")


def rgb_difference(base: Path, other: Path, tours) -> dict:
    """How much a render perturbation changed the RGB the methods read, as 8-bit sRGB (what the detector
    and the appearance baseline see): frames compared, frames with any pixel changed, the share of pixels
    changed, and the median PSNR (dB) of the changed frames against the unperturbed ones."""
    from vrformats import frames as fr
    from vrformats import image_quality
    from vrformats.color import srgb8
    from vrformats.tour import Tour

    n = changed = 0
    px = 0.0
    psnr = []
    for name in tours:
        t, o = Tour(Path(base) / name), Tour(Path(other) / name)
        for i in (int(i) for i in t.frame_indices if i % t.rgb_every == 0):  # the frames with RGB
            a = fr.read_frame(t.frame_path(i), depth=False, instance=False, semantic=False).rgb
            b = fr.read_frame(o.frame_path(i), depth=False, instance=False, semantic=False).rgb
            if a is None or b is None:
                continue
            a8, b8 = srgb8(a), srgb8(b)
            n += 1
            diff = a8 != b8
            if diff.any():
                changed += 1
                px += float(diff.any(axis=-1).mean())
                psnr.append(image_quality.psnr(a8, b8))
    return {"frames": n, "frames_changed": changed, "pixels_changed": (px / n) if n else None,
            "psnr_db_median": float(np.median(psnr)) if psnr else None}


def _figure(res: dict, method: str, mode: str, key: str):
    d = res["methods"][method]["modes"][mode]
    return d["all"].get(key) if key in d["all"] else d["factors"].get(key)


def _interval(res: dict, method: str, mode: str, key: str):
    iv = res["methods"][method]["modes"][mode].get("intervals") or {}
    return (iv.get("all") or {}).get(key) or (iv.get("factors") or {}).get(key)


def check_methods(check_file, known) -> list[str]:
    """The methods of ``known`` that a check file's expressions name (``videoreloc.closure...``)."""
    from .checks import parse_checks

    names = []
    for c in parse_checks(check_file):
        for token in (c.left, c.right):
            head = token.split(".")[0]
            if head in known and head not in names:
                names.append(head)
    return names


def stability(spec, out: Path, perturbations: dict, methods: tuple = ("videoreloc",), workers: int | None = None,
              progress: bool = True, checks=None) -> dict:
    """Run ``spec`` (its ``methods`` narrowed to ``methods`` and those ``checks`` names) unperturbed and under
    each perturbation (name -> {"detector": settings} or {"render": settings}); returns the report (also
    ``OUT/stability.json`` and ``OUT/stability.md``)."""
    from .checks import run_checks
    from .runner import design_tours, run_experiment

    if spec.detector.get("kind") != "learned" and any("detector" in p for p in perturbations.values()):
        raise UserError(f"{spec.source}: detector: the detector perturbations perturb the learned detector; this "
                        f"spec uses {spec.detector.get('kind')} (ask for render perturbations only)")
    unknown = [m for m in methods if m not in spec.methods]
    if unknown:
        raise UserError(f"--methods: {', '.join(unknown)} not in the spec's methods ({', '.join(spec.methods)})")
    if checks is not None:
        methods = tuple(dict.fromkeys([*methods, *check_methods(checks, spec.methods)]))
    out = Path(out)
    base = dataclasses.replace(spec, methods=tuple(methods), tables=(), replicates=1)
    queries, mapping = design_tours(base)  # an unrendered design is refused before anything renders
    tours = sorted({t["tour"] for t in queries.values()} | {mapping["tour"]})
    runs = {"none": base}
    renders = {}
    for name, p in perturbations.items():
        if "detector" in p:
            det = {**spec.detector, "perturbation": {**spec.detector.get("perturbation", {}), **p["detector"]}}
            runs[name] = dataclasses.replace(base, name=f"{spec.name} {name}", detector=det)
        else:
            job = out / "renders" / name
            render_perturbed(base, job, p["render"], workers or spec.workers or 1, progress)
            same_design(base.tours_root, job, tours)
            renders[name] = {"job": str(job), "settings": p["render"], **rgb_difference(base.tours_root, job, tours)}
            runs[name] = dataclasses.replace(base, name=f"{spec.name} {name}", tours_root=job)
    results = {}
    for name, sp in runs.items():
        results[name] = run_experiment(sp, out=out / name, workers=workers, progress=progress, plots=False)
    rep = {"spec": str(spec.source), "tours": str(spec.tours_root), "methods": list(methods),
           "perturbations": {"none": {}, **perturbations}, "renders": renders, "figures": [], "tour_recalls": []}
    for m in methods:
        for label, mode, key in FIGURES:
            if mode not in results["none"]["methods"][m]["modes"]:
                continue
            vals = {n: _figure(r, m, mode, key) for n, r in results.items()}
            got = [v for v in vals.values() if v is not None]
            iv = _interval(results["none"], m, mode, key)
            inside = None if iv is None or len(got) < len(vals) else all(iv[0] - 1e-12 <= v <= iv[1] + 1e-12 for v in got)
            rep["figures"].append({"method": m, "figure": label, "mode": mode, "key": key, "values": vals,
                                   "interval": iv, "inside": inside,
                                   "spread": (max(got) - min(got)) if len(got) == len(vals) else None})
        for mode in ("closure", "causal"):
            d0 = results["none"]["methods"][m]["modes"].get(mode)
            if d0 is None:
                continue
            for tour, s in d0["tours"].items():
                vals = {n: r["methods"][m]["modes"][mode]["tours"][tour]["recall_1m_10deg"] for n, r in results.items()}
                rep["tour_recalls"].append({"method": m, "mode": mode, "tour": tour, "values": vals,
                                            "worst_loss": max(vals["none"] - v for v in vals.values()),
                                            "spread": max(vals.values()) - min(vals.values())})
    rep["max_spread"] = max((f["spread"] for f in rep["figures"] if f["spread"] is not None and "recall" in f["key"]),
                            default=None)
    rep["max_tour_loss"] = max((t["worst_loss"] for t in rep["tour_recalls"]), default=None)
    if checks is not None:
        rep["checks_file"] = str(checks)
        rows = {n: run_checks(checks, out / n) for n in results}
        rep["checks"] = []
        for k, r0 in enumerate(rows["none"]):
            margins = {n: rs[k]["margin"] for n, rs in rows.items()}
            m0 = margins["none"]
            moves = [v - m0 for v in margins.values() if v is not None and m0 is not None]
            complete = len(moves) == len(margins)
            # largest_move: the largest change either way (another machine may move it the other way);
            # toward_bound: the largest loss of margin, what a perturbation did to bring the check nearer failing
            rep["checks"].append({"check": r0["check"], "expression": r0["expression"], "margins": margins,
                                  "passed": {n: rs[k]["passed"] for n, rs in rows.items()},
                                  "largest_move": max(abs(x) for x in moves) if complete else None,
                                  "toward_bound": max(0.0, -min(moves)) if complete else None})
        rep["checks_failed"] = sorted({n for n, rs in rows.items() for r in rs if not r["passed"]})
    write_json_atomic(out / "stability.json", rep)
    write_text_atomic(out / "stability.md", format_stability(rep) + "\n")
    return rep


def format_stability(rep: dict) -> str:
    names = list(rep["perturbations"])
    pct = lambda v: "-" if v is None else f"{100 * v:.1f}"  # noqa: E731
    lines = [f"Stability of {rep['spec']} (tours {rep['tours']}) under perturbations of the detector and the render", ""]
    if rep.get("renders"):
        lines += ["Render perturbations (RGB re-rendered, depth and ids linked from the unperturbed job; 8-bit sRGB "
                  "against the unperturbed frames):", "",
                  "| perturbation | RGB frames | changed | pixels changed | median PSNR of the changed (dB) |",
                  "|---|---|---|---|---|"]
        for n, r in rep["renders"].items():
            psnr = "-" if r["psnr_db_median"] is None else f"{r['psnr_db_median']:.1f}"
            lines.append(f"| {n} | {r['frames']} | {r['frames_changed']} | {pct(r['pixels_changed'])} % | {psnr} |")
        lines.append("")
    lines += ["| method | figure | " + " | ".join(names) + " | unperturbed interval | spread | all inside |",
              "|---" * (len(names) + 5) + "|"]
    for f in rep["figures"]:
        if all(v is None for v in f["values"].values()):
            continue  # a figure the design cannot have (ΔL without night tours, say)
        iv = "-" if f.get("interval") is None else f"[{pct(f['interval'][0])}, {pct(f['interval'][1])}]"
        inside = {True: "yes", False: "**no**", None: "-"}[f.get("inside")]
        lines.append(f"| {f['method']} | {f['figure']} | " + " | ".join(pct(f["values"][n]) for n in names)
                     + f" | {iv} | {pct(f['spread'])} | {inside} |")
    lines += ["", "| method | tour (mode) | " + " | ".join(names) + " | worst loss |", "|---" * (len(names) + 3) + "|"]
    for t in sorted(rep["tour_recalls"], key=lambda t: (t["method"], t["mode"], t["tour"])):
        lines.append(f"| {t['method']} | {t['tour']} ({t['mode']}) | " + " | ".join(pct(t["values"][n]) for n in names)
                     + f" | {pct(t['worst_loss'])} |")
    lines += ["", "Recall (%) at 1 m/10° unless the figure says otherwise; spread: highest - lowest over the unperturbed "
              "and every perturbed run (points); all inside: every perturbed value lies inside the unperturbed run's "
              "95 % interval; worst loss: the unperturbed tour's recall minus its lowest perturbed one. Largest spread "
              f"of a recall: {pct(rep['max_spread'])} points; largest loss of a tour: {pct(rep['max_tour_loss'])} points."]
    if rep.get("checks") is not None:
        num = lambda v: "-" if v is None else f"{v:.3g}"  # noqa: E731
        lines += ["", f"Checks of {rep['checks_file']}: the margin to the bound (positive: passing; the deciding "
                  "quantity's distance from where the check flips, in its own units: fractions for figures, boxes "
                  "or bytes for the map), unperturbed and under each perturbation, beside the largest move:", "",
                  "| check | " + " | ".join(names) + " | largest move | toward the bound | margin >= largest move |",
                  "|---" * (len(names) + 4) + "|"]
        for c in rep["checks"]:
            cells = [num(c["margins"][n]) + ("" if c["passed"][n] else " **FAIL**") for n in names]
            m0, mv = c["margins"]["none"], c["largest_move"]
            holds = "-" if m0 is None or mv is None else ("yes" if m0 >= mv else "**no**")
            lines.append(f"| {c['check']} | " + " | ".join(cells) + f" | {num(mv)} | {num(c['toward_bound'])} | {holds} |")
        failed = rep.get("checks_failed") or []
        lines += ["", "Every check passes under every perturbation." if not failed
                  else f"Checks fail under: {', '.join(failed)}."]
    return "\n".join(lines)


def cmd_stability(args) -> int:
    from ..resources import check_spec
    from .runner import check_not_a_render_folder
    from .spec import load_experiment

    perts = dict(parse_perturbation(p) for p in args.perturbation) if args.perturbation else None
    checks = check_spec(args.checks) if args.checks else None
    if checks is not None and not Path(checks).is_file():
        raise UserError(f"--checks {args.checks}: check file not found")
    spec = load_experiment(args.spec)
    if args.tours:
        spec.tours_root = Path(args.tours)
    if perts is None:
        perts = dict(DEFAULT_PERTURBATIONS) if spec.detector.get("kind") == "learned" else {}
        if not args.no_render:
            perts.update(default_render_perturbations(Path(spec.tours_root)))
        if not perts:
            raise UserError(f"{spec.source}: nothing to perturb: no learned detector, and "
                            + ("--no-render" if args.no_render else f"no Cycles RGB in {spec.tours_root}"))
    elif args.no_render and any("render" in p for p in perts.values()):
        raise UserError("--no-render: the --perturbation list names a render perturbation")
    out = Path(args.out) if args.out else Path(spec.out).with_name(Path(spec.out).name + "_stability")
    check_not_a_render_folder(out, "the stability benchmark")
    rep = stability(spec, out, perts, methods=tuple(args.methods.split(",")), workers=args.workers,
                    progress=not args.quiet, checks=checks)
    print(json.dumps(rep, indent=1) if args.json else format_stability(rep))
    bad = []
    if args.max_spread is not None and (rep["max_spread"] is None or rep["max_spread"] > args.max_spread):
        bad.append(f"a recall spread {rep['max_spread']} > {args.max_spread}")
    if args.max_tour_loss is not None and (rep["max_tour_loss"] is None or rep["max_tour_loss"] > args.max_tour_loss):
        bad.append(f"a tour lost {rep['max_tour_loss']} > {args.max_tour_loss}")
    if rep.get("checks_failed"):
        bad.append(f"checks fail under {', '.join(rep['checks_failed'])}")
    if bad:
        print("unstable: " + "; ".join(bad), file=sys.stderr)
        return 1
    return 0


def add_arguments(a) -> None:
    a.add_argument("spec", metavar="SPEC.yaml", help="experiment spec (or a shipped name: demo_experiment)")
    a.add_argument("--tours", help="folder of the rendered tours (default: the render spec's out); render perturbations "
                   "need the job folder itself")
    a.add_argument("--out", help="results folder (default: the spec's out + _stability)")
    a.add_argument("--methods", default="videoreloc", help="comma-separated methods to rerun (default videoreloc)")
    a.add_argument("--perturbation", action="append", metavar="P",
                   help=f"{PERTURBATION_FORMS}; repeat for several (default: jitter:1, jitter:2, jitter:3, threads:2, "
                        "no-graph-opt with a learned detector, and for Cycles RGB render-seed:SEED+1, the other "
                        "prefilter, render-threads:1)")
    a.add_argument("--no-render", action="store_true", help="leave out the default render perturbations (no re-rendering)")
    a.add_argument("--checks", metavar="CHECKS.yaml",
                   help="also rerun the methods these checks name, evaluate them under every perturbation, and report "
                        "each check's margin beside the largest move (or a shipped name: demo_checks); a check that "
                        "fails under a perturbation fails the benchmark (exit 1)")
    a.add_argument("--max-spread", type=fraction, metavar="F",
                   help="fail (exit 1) when a recall's spread exceeds this fraction (0..1)")
    a.add_argument("--max-tour-loss", type=fraction, metavar="F",
                   help="fail (exit 1) when a tour loses more than this fraction (0..1)")
    add_workers(a, "processes", default=None)
    add_quiet(a)
    add_json(a, "the report")
