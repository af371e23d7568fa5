"""``reloc bench stability``: how far an experiment's figures move under last-bit perturbations.

Another processor, another thread count or another onnxruntime build changes the learned detector's
output in its last bits; a result that moves a lot with that is a knife edge, not a measurement.
This benchmark reruns an experiment's detector-dependent rows (VideoReloc with the spec's learned
detector by default) under ``K`` perturbations of the detector (``reloc.detection.learned.
Perturbation``: a one-level 8-bit input jitter with several seeds, onnxruntime with 2 threads,
graph optimisation off), each a full experiment in its own folder (``OUT/<name>/``, resumable like
any experiment), and prints per figure the unperturbed value, each perturbed one and the spread
(max - min over all of them, in points), and per tour the largest loss against the unperturbed
run. ``--max-spread`` and ``--max-tour-loss`` turn it into a pass/fail gate (exit 1).
"""

from __future__ import annotations

import dataclasses
import json
import sys
from pathlib import Path

from vrformats.atomic import write_json_atomic, write_text_atomic
from vrformats.cli import add_json, add_quiet, add_workers, fraction
from vrformats.errors import UserError

# the default perturbations: name -> Perturbation settings
DEFAULT_PERTURBATIONS = {
    "jitter-1": {"input_jitter": 1, "seed": 1},
    "jitter-2": {"input_jitter": 1, "seed": 2},
    "jitter-3": {"input_jitter": 1, "seed": 3},
    "threads-2": {"threads": 2},
    "no-graph-opt": {"graph_optimization": False},
}
# the figures compared: (label, mode, key in "all" or "factors")
FIGURES = (("closure 1 m/10°", "closure", "recall_1m_10deg"), ("closure 0.25 m/5°", "closure", "recall_25cm_5deg"),
           ("causal 1 m/10°", "causal", "recall_1m_10deg"), ("closure day", "closure", "day"),
           ("closure evening", "closure", "evening"), ("closure night", "closure", "night"),
           ("closure ΔL", "closure", "delta_L"), ("closure kept", "closure", "kept"))


def parse_perturbation(text: str) -> tuple[str, dict]:
    """``jitter:SEED``, ``jitter:SEED:LEVELS``, ``threads:N`` or ``no-graph-opt`` -> (name, settings)."""
    from ..detection.learned import Perturbation

    parts = text.split(":")
    try:
        if parts[0] == "jitter" and len(parts) in (2, 3):
            d = {"input_jitter": int(parts[2]) if len(parts) == 3 else 1, "seed": int(parts[1])}
        elif parts[0] == "threads" and len(parts) == 2:
            d = {"threads": int(parts[1])}
        elif parts == ["no-graph-opt"]:
            d = {"graph_optimization": False}
        else:
            raise ValueError("expected jitter:SEED[:LEVELS], threads:N or no-graph-opt")
        Perturbation(**d)
    except ValueError as e:
        raise UserError(f"--perturbation {text}: {e}") from None
    return text.replace(":", "-"), d


def _figure(res: dict, method: str, mode: str, key: str):
    d = res["methods"][method]["modes"][mode]
    return d["all"].get(key) if key in d["all"] else d["factors"].get(key)


def stability(spec, out: Path, perturbations: dict, methods: tuple = ("videoreloc",), workers: int | None = None,
              progress: bool = True) -> dict:
    """Run ``spec`` (its ``methods`` narrowed to ``methods``) unperturbed and under each perturbation;
    returns the report (also ``OUT/stability.json``)."""
    from .runner import run_experiment

    if spec.detector.get("kind") != "learned":
        raise UserError(f"{spec.source}: detector: the stability benchmark perturbs the learned detector; this "
                        f"spec uses {spec.detector.get('kind')}")
    unknown = [m for m in methods if m not in spec.methods]
    if unknown:
        raise UserError(f"--methods: {', '.join(unknown)} not in the spec's methods ({', '.join(spec.methods)})")
    base = dataclasses.replace(spec, methods=tuple(methods), tables=(), replicates=1)
    runs = {"none": base}
    for name, p in perturbations.items():
        det = {**spec.detector, "perturbation": {**spec.detector.get("perturbation", {}), **p}}
        runs[name] = dataclasses.replace(base, name=f"{spec.name} {name}", detector=det)
    results = {}
    for name, sp in runs.items():
        results[name] = run_experiment(sp, out=Path(out) / name, workers=workers, progress=progress, plots=False)
    rep = {"spec": str(spec.source), "methods": list(methods), "perturbations": {"none": {}, **perturbations},
           "figures": [], "tours": []}
    for m in methods:
        for label, mode, key in FIGURES:
            if mode not in results["none"]["methods"][m]["modes"]:
                continue
            vals = {n: _figure(r, m, mode, key) for n, r in results.items()}
            got = [v for v in vals.values() if v is not None]
            rep["figures"].append({"method": m, "figure": label, "mode": mode, "key": key, "values": vals,
                                   "spread": (max(got) - min(got)) if len(got) == len(vals) else None})
        for mode in ("closure", "causal"):
            d0 = results["none"]["methods"][m]["modes"].get(mode)
            if d0 is None:
                continue
            for tour, s in d0["tours"].items():
                vals = {n: r["methods"][m]["modes"][mode]["tours"][tour]["recall_1m_10deg"] for n, r in results.items()}
                rep["tours"].append({"method": m, "mode": mode, "tour": tour, "values": vals,
                                     "worst_loss": max(vals["none"] - v for v in vals.values()),
                                     "spread": max(vals.values()) - min(vals.values())})
    rep["max_spread"] = max((f["spread"] for f in rep["figures"] if f["spread"] is not None and "recall" in f["key"]),
                            default=None)
    rep["max_tour_loss"] = max((t["worst_loss"] for t in rep["tours"]), default=None)
    write_json_atomic(Path(out) / "stability.json", rep)
    write_text_atomic(Path(out) / "stability.md", format_stability(rep) + "\n")
    return rep


def format_stability(rep: dict) -> str:
    names = list(rep["perturbations"])
    pct = lambda v: "-" if v is None else f"{100 * v:.1f}"  # noqa: E731
    lines = [f"Stability of {rep['spec']} under last-bit perturbations of the learned detector", "",
             "| method | figure | " + " | ".join(names) + " | spread |", "|---" * (len(names) + 3) + "|"]
    for f in rep["figures"]:
        lines.append(f"| {f['method']} | {f['figure']} | " + " | ".join(pct(f["values"][n]) for n in names)
                     + f" | {pct(f['spread'])} |")
    lines += ["", "| method | tour (mode) | " + " | ".join(names) + " | worst loss |", "|---" * (len(names) + 3) + "|"]
    for t in sorted(rep["tours"], key=lambda t: (t["method"], t["mode"], t["tour"])):
        lines.append(f"| {t['method']} | {t['tour']} ({t['mode']}) | " + " | ".join(pct(t["values"][n]) for n in names)
                     + f" | {pct(t['worst_loss'])} |")
    lines += ["", "Recall (%) at 1 m/10° unless the figure says otherwise; spread: highest - lowest over the unperturbed "
              "and every perturbed run (points); worst loss: the unperturbed tour's recall minus its lowest perturbed "
              f"one. Largest spread of a recall: {pct(rep['max_spread'])} points; largest loss of a tour: "
              f"{pct(rep['max_tour_loss'])} points."]
    return "\n".join(lines)


def cmd_stability(args) -> int:
    from .spec import load_experiment

    spec = load_experiment(args.spec)
    if args.tours:
        spec.tours_root = Path(args.tours)
    perts = dict(parse_perturbation(p) for p in args.perturbation) if args.perturbation else dict(DEFAULT_PERTURBATIONS)
    out = Path(args.out) if args.out else Path(spec.out).with_name(Path(spec.out).name + "_stability")
    from .runner import check_not_a_render_folder

    check_not_a_render_folder(out, "the stability benchmark")
    rep = stability(spec, out, perts, methods=tuple(args.methods.split(",")), workers=args.workers,
                    progress=not args.quiet)
    print(json.dumps(rep, indent=1) if args.json else format_stability(rep))
    bad = []
    if args.max_spread is not None and (rep["max_spread"] is None or rep["max_spread"] > args.max_spread):
        bad.append(f"a recall spread {rep['max_spread']} > {args.max_spread}")
    if args.max_tour_loss is not None and (rep["max_tour_loss"] is None or rep["max_tour_loss"] > args.max_tour_loss):
        bad.append(f"a tour lost {rep['max_tour_loss']} > {args.max_tour_loss}")
    if bad:
        print("unstable: " + "; ".join(bad), file=sys.stderr)
        return 1
    return 0


def add_arguments(a) -> None:
    a.add_argument("spec", metavar="SPEC.yaml", help="experiment spec (or a shipped name: demo_experiment)")
    a.add_argument("--tours", help="folder of the rendered tours (default: the render spec's out)")
    a.add_argument("--out", help="results folder (default: the spec's out + _stability)")
    a.add_argument("--methods", default="videoreloc", help="comma-separated methods to rerun (default videoreloc)")
    a.add_argument("--perturbation", action="append", metavar="P",
                   help="jitter:SEED[:LEVELS], threads:N or no-graph-opt; repeat for several (default: "
                        "jitter:1, jitter:2, jitter:3, threads:2, no-graph-opt)")
    a.add_argument("--max-spread", type=fraction, metavar="F",
                   help="fail (exit 1) when a recall's spread exceeds this fraction (0..1)")
    a.add_argument("--max-tour-loss", type=fraction, metavar="F",
                   help="fail (exit 1) when a tour loses more than this fraction (0..1)")
    add_workers(a, "processes", default=None)
    add_quiet(a)
    add_json(a, "the report")
