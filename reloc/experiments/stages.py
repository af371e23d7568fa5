"""The stage as a controlled factor (issue 55): one experiment's figures on several stage variants of
the same flat, side by side, with each figure's 95 % interval and its spread across the stages.

Each results folder is one ``reloc experiment`` of the same design on one stage variant (a ReplicaCAD
folder that ``tools/replicacad_standin.py --stage NAME`` built, or the real dataset). A figure
*holds across stages* when every stage's value lies inside every other stage's interval; otherwise it
*moves with the stage*, by its spread (largest minus smallest value). Nothing is pooled across stages:
their tours share the path and the layouts, not the images.
"""

from __future__ import annotations

import math
from pathlib import Path

from vrformats.errors import UserError

# (metric as reloc check names it, label); fractions as in results.json
FIGURES = (
    ("videoreloc.closure.recall_1m_10deg", "VideoReloc, with clip closure"),
    ("videoreloc.causal.recall_1m_10deg", "VideoReloc, causal"),
    ("videoreloc_oracle.closure.recall_1m_10deg", "VideoReloc (oracle detections), with clip closure"),
    ("videoreloc_oracle.causal.recall_1m_10deg", "VideoReloc (oracle detections), causal"),
    ("videoreloc.closure.delta_L", "VideoReloc, closure: ΔL (night - day)"),
    ("videoreloc.closure.kept", "VideoReloc, closure: kept"),
    ("fpfh_icp.closure.recall_1m_10deg", "FPFH-ICP†"),
    ("fpfh_icp.closure.kept", "FPFH-ICP†: kept"),
    ("appearance.causal.recall_1m_10deg", "Appearance (ORB + PnP), per frame"),
    ("appearance.causal.delta_R", "Appearance, per frame: ΔR"),
    ("one_frame.causal.recall_1m_10deg", "One-frame object unit"),
    ("map.matched", "learned map: ground-truth boxes found"),
    ("map.extra", "learned map: extra boxes"),
)
SIGNED = {"delta_L", "delta_R"}


def stage_dirs(args: list[str]) -> dict[str, Path]:
    """``NAME=DIR`` or ``DIR`` (named by the folder above an ``experiment`` folder, else by the folder)."""
    out: dict[str, Path] = {}
    for a in args:
        name, sep, d = a.partition("=")
        d = Path(d if sep else a)
        if not sep:
            name = d.parent.name if d.name == "experiment" else d.name
        if not (d / "results.json").is_file():
            raise UserError(f"{d}: no results.json (run reloc experiment on the stage's tours first)")
        if name in out:
            raise UserError(f"{a}: a second stage named {name!r}; name them: NAME=DIR")
        out[name] = d
    return out


def figures_of(results_dir, names=None) -> dict[str, tuple[float | None, tuple[float, float] | None]]:
    """Each figure of one experiment: (value, 95 % interval or None), by its ``reloc check`` name."""
    from .checks import _Resolver
    from .tables import read_results

    results_dir = Path(results_dir)
    results = read_results(results_dir)
    r = _Resolver(results, results_dir / "results.json")
    out = {}
    for name, _ in FIGURES if names is None else [(n, n) for n in names]:
        if name not in r.vals or r.vals[name] is None:
            out[name] = (None, None)
            continue
        v = float(r.vals[name])
        iv = r.boot.interval(r.resamples(name)) if name in r.figs else None
        out[name] = (None if math.isnan(v) else v, None if iv is None else (float(iv[0]), float(iv[1])))
    return out


def stage_table(dirs: dict[str, Path]) -> list[dict]:
    """Per figure: the stages' values and intervals, the spread, and whether it holds across stages."""
    if len(dirs) < 2:
        raise UserError(f"reloc stages: give the results of at least two stage variants, got {len(dirs)}")
    per = {s: figures_of(d) for s, d in dirs.items()}
    rows = []
    for name, label in FIGURES:
        vals = {s: per[s][name] for s in dirs}
        have = {s: v for s, v in vals.items() if v[0] is not None}
        if not have:
            continue
        xs = [v[0] for v in have.values()]
        holds = None
        if all(v[1] is not None for v in have.values()) and len(have) >= 2:
            holds = all(iv[0] - 1e-9 <= x <= iv[1] + 1e-9 for _, (x, _) in have.items() for _, (_, iv) in have.items())
        rows.append({"figure": name, "label": label, "stages": {s: {"value": v[0], "interval": v[1]} for s, v in vals.items()},
                     "spread": max(xs) - min(xs), "holds": holds})
    return rows


def _cell(name: str, v) -> str:
    x, iv = v["value"], v["interval"]
    if x is None:
        return "-"
    if name.startswith("map."):
        return f"{x:.0f}"
    if name.endswith(".kept"):  # as Table II prints it
        s = f"{100 * x:.0f} %"
        return s if iv is None else f"{s} [{100 * iv[0]:.0f}, {100 * iv[1]:.0f}]"
    sign = "+" if name.rsplit(".", 1)[-1] in SIGNED else ""
    s = f"{100 * x:{sign}.1f}"
    return s if iv is None else f"{s} [{100 * iv[0]:{sign}.1f}, {100 * iv[1]:{sign}.1f}]"


def format_stage_table(rows: list[dict]) -> str:
    stages = list(rows[0]["stages"]) if rows else []
    out = ["| Figure | " + " | ".join(stages) + " | spread | across stages |",
           "|---|" + "---|" * (len(stages) + 2)]
    for r in rows:
        sp = f"{r['spread']:.0f}" if r["figure"].startswith("map.") else f"{100 * r['spread']:.1f}"
        h = {True: "holds", False: "moves", None: "-"}[r["holds"]]
        out.append(f"| {r['label']} | " + " | ".join(_cell(r["figure"], r["stages"][s]) for s in stages) + f" | {sp} | {h} |")
    out.append("")
    out.append("Recall and ΔL/ΔR in %, kept in % of the unchanged layout's recall, map figures in boxes; [lo, hi]: each "
               "stage's own 95 % interval (a block bootstrap over its segments). A figure holds across stages when every "
               "stage's value lies inside every other stage's interval; spread: largest minus smallest value.")
    return "\n".join(out)
