"""Figures of an experiment (paper Fig. 3): per-tour trajectory plots and recall bars.

``reloc.figures.tour_figure`` draws one query tour with a column per method row (map boxes, the
ground-truth path, the estimates coloured by position error, the rolling error medians); the
column title gives the recall at 1 m/10 deg over ALL ground-truth frames (a frame without a pose is
a failure), or, for a method scored on a subset of the frames (the one-frame unit), the table's
recall over the frames it is scored on.

``recall_bars`` draws the recall at 1 m/10 deg of every table row per lighting (left) and for
unchanged against rearranged layouts (right), from ``results.json``'s factors.

``plot_experiment`` reads an experiment results directory (the ``videoreloc-experiment/1``
schema) and writes ``plots/tour_<tour>.png`` for every tour and ``plots/recall_bars.png``.

Headless: matplotlib's Agg canvas, no pyplot. PNGs are written atomically.
"""

from __future__ import annotations

import math
import re
import sys
from pathlib import Path

import numpy as np
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure
from matplotlib.patches import Patch

from vrformats.atomic import save_figure
from vrformats.camera import read_tum
from vrformats.errors import SceneFormatError, UserError

from ..figures import (  # the per-tour figure lives with reloc run --plot's; re-exported for the experiments
    DPI, ERROR_CMAP, ERROR_MAX_M, POS_THRESHOLD_M, ROLLING_WINDOW, ROT_THRESHOLD_DEG, box_corners, error_colors,
    per_frame, recall_1m_10deg, rolling_median, tour_figure,
)
from .tables import read_results

__all__ = [
    "ERROR_CMAP", "ERROR_MAX_M", "POS_THRESHOLD_M", "ROT_THRESHOLD_DEG", "ROLLING_WINDOW", "DPI",
    "error_colors", "rolling_median", "per_frame", "recall_1m_10deg", "box_corners",
    "tour_figure", "recall_bars", "plot_experiment", "tour_png_name",
]

LIGHTINGS = ("day", "evening", "night")
CHANGES = ("unchanged", "rearranged")


def _factor(results: dict, row: dict, key: str) -> float | None:
    try:
        v = results["methods"][row["method"]]["modes"][row["mode"]]["factors"].get(key)
    except (KeyError, TypeError, AttributeError):
        return None
    if v is None or isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
        return None
    return float(v)


def _factor_interval(results: dict, row: dict, key: str) -> list | None:
    """The 95 % interval of a Table II figure (``reloc.experiments.intervals``), None without one."""
    try:
        iv = results["methods"][row["method"]]["modes"][row["mode"]]["intervals"]["factors"].get(key)
    except (KeyError, TypeError, AttributeError):
        return None
    return iv if isinstance(iv, list) and len(iv) == 2 and all(isinstance(x, (int, float)) for x in iv) else None


def row_label(row: dict) -> str:
    label = str(row.get("label") or row.get("key") or f"{row.get('method')}.{row.get('mode')}")
    return label + (" \u2020" if row.get("dagger") and "\u2020" not in label else "")


def _is_bound(row: dict) -> bool:
    """A row of oracle detections (``videoreloc_oracle``): the upper bound beside the detector's rows."""
    return str(row.get("method") or row.get("key", "")).split(".")[0].endswith("_oracle")


def recall_bars(results: dict, out_png, dpi: float = DPI) -> Path:
    """Grouped bars of recall at 1 m/10 deg per row: lightings (left), unchanged vs rearranged (middle)
    and, in an experiment with more than one sensor, per sensor (right); each bar with its 95 %
    interval as an error bar when the results carry one."""
    import matplotlib

    rows = list(results.get("rows") or [])
    groups_l = [g for g in LIGHTINGS if any(_factor(results, r, g) is not None for r in rows)]
    groups_r = [g for g in CHANGES if any(_factor(results, r, g) is not None for r in rows)]
    sensors = list(results.get("sensors") or []) if len(results.get("sensors") or []) > 1 else []
    panels = [(groups_l, groups_l, "lighting"), (groups_r, groups_r, "layout change")]
    if sensors:
        panels.append(([f"sensor.{s}" for s in sensors], sensors, "sensor"))
    nrow = max(1, len(rows))
    wl, wr = max(1, len(groups_l)), max(1, len(groups_r))
    ws = [wl, wr] + ([len(sensors)] if sensors else [])
    legend_h = 0.25 * ((len(rows) + 1) // 2) + 0.2
    fig_h = 4.2 + legend_h
    fig = Figure(figsize=(float(np.clip(2.5 + 0.32 * nrow * sum(ws), 7.0, 18.0)), fig_h), dpi=dpi)
    FigureCanvasAgg(fig)
    gs = fig.add_gridspec(1, len(ws), width_ratios=ws, left=0.07, right=0.98, top=0.88,
                          bottom=(legend_h + 0.45) / fig_h, wspace=0.15)
    palette = matplotlib.colormaps["tab10"].colors
    bar_w = 0.8 / nrow
    # clip-rigid controls (dagger rows) hatched //; oracle-detection rows, the upper bound, in grey, dotted
    styles = [{"color": ("0.8" if row.get("mode") == "causal" else "0.6") if _is_bound(row)
               else palette[j % len(palette)],
               "hatch": "//" if row.get("dagger") else (".." if _is_bound(row) else None),
               "edgecolor": "0.25" if row.get("dagger") or _is_bound(row) else "white"} for j, row in enumerate(rows)]
    for k, (groups, names, title) in enumerate(panels):
        ax = fig.add_subplot(gs[0, k])
        ax.set_ylim(0, 1.12)
        ticks = np.linspace(0, 1, 6)
        ax.set_yticks(ticks)
        ax.set_yticklabels([f"{int(round(100 * t))}%" if k == 0 else "" for t in ticks], fontsize=8)
        ax.grid(True, axis="y", lw=0.4, alpha=0.5)
        ax.set_axisbelow(True)
        ax.set_title(f"by {title}", fontsize=10)
        if not groups or not rows:
            ax.set_xticks([])
            ax.text(0.5, 0.5, "not in this design", transform=ax.transAxes, ha="center", va="center", color="0.4")
            continue
        x = np.arange(len(groups), dtype=float)
        small = nrow > 4
        for j, row in enumerate(rows):
            pts = [(xi + (j - (nrow - 1) / 2) * bar_w, v)
                   for xi, v in zip(x, (_factor(results, row, g) for g in groups)) if v is not None]
            if not pts:
                continue
            xs, ys = zip(*pts)
            ax.bar(xs, ys, width=bar_w * 0.92, linewidth=0.5, **styles[j])
            # the 95 % interval as an error bar; the value's label sits above the bar's top whisker
            ivs = [_factor_interval(results, row, g) for g in groups if _factor(results, row, g) is not None]
            tops = []
            for xb, yb, iv in zip(xs, ys, ivs):
                if iv is not None:
                    ax.errorbar([xb], [yb], yerr=[[max(0.0, yb - iv[0])], [max(0.0, iv[1] - yb)]], fmt="none",
                                ecolor="0.15", elinewidth=0.8, capsize=2)
                tops.append(max(yb, iv[1]) if iv is not None else yb)
            for xb, yb, top in zip(xs, ys, tops):
                ax.text(xb, min(top, 1.0) + 0.01, f"{100 * yb:.0f}%", ha="center", va="bottom",
                        fontsize=6 if small else 7, rotation=90 if small else 0)
        ax.set_xticks(x)
        ax.set_xticklabels(names, fontsize=9)
        ax.set_xlim(-0.5, len(groups) - 0.5)
    if rows:
        handles = [Patch(facecolor=st["color"], hatch=st["hatch"], edgecolor=st["edgecolor"], label=row_label(r))
                   for st, r in zip(styles, rows)]
        fig.legend(handles=handles, loc="lower center", ncol=2, fontsize=8, frameon=False,
                   bbox_to_anchor=(0.5, 0.02 / fig_h))
    name = results.get("name")
    fig.suptitle("Recall at 1 m/10\u00b0" + (f": {name}" if name else ""), fontsize=11)
    return save_figure(fig, out_png, dpi)


# --------------------------------------------------------------------------------------------
# an experiment directory


def tour_png_name(tour: str) -> str:
    return "tour_" + re.sub(r"[^A-Za-z0-9._-]+", "_", str(tour)) + ".png"


def _resolve(results_dir: Path, p) -> Path:
    p = Path(p)
    if p.is_absolute():
        return p
    for cand in (results_dir / p, results_dir.parent / p, Path.cwd() / p):
        if cand.exists():
            return cand
    return results_dir / p


def _trajectory_file(results_dir: Path, results: dict, row: dict, tour: str) -> Path:
    try:
        f = results["methods"][row["method"]]["modes"][row["mode"]]["tours"][tour].get("file")
    except (KeyError, TypeError, AttributeError):
        f = None
    return results_dir / (f or f"runs/{row['method']}/{tour}/{row['mode']}.txt")


def plot_experiment(results_dir) -> list[Path]:
    """Write ``plots/tour_<tour>.png`` per tour and ``plots/recall_bars.png``; returns the paths written.

    A missing trajectory file is a column without poses; a tour whose ground truth cannot be read
    is skipped with a message on stderr; a missing map leaves the boxes out."""
    from vrformats.tour import Tour

    from ..map.boxmap import BoxMap

    results_dir = Path(results_dir)
    results = read_results(results_dir)
    plots = results_dir / "plots"
    bmap = None
    if results.get("map"):
        try:
            bmap = BoxMap.load(_resolve(results_dir, results["map"]))
        except (UserError, SceneFormatError) as e:
            print(f"reloc plots: map not drawn: {e}", file=sys.stderr)
    rows = list(results.get("rows") or [])
    written: list[Path] = []
    for tname, tinfo in (results.get("tours") or {}).items():
        try:
            tour = Tour(_resolve(results_dir, tinfo["dir"]))
        except (UserError, SceneFormatError, KeyError, TypeError) as e:
            print(f"reloc plots: tour {tname} skipped: ground truth not readable ({e})", file=sys.stderr)
            continue
        fps = float(tinfo.get("fps") or tour.fps)
        gt = {int(i): T for i, T in zip(tour.frame_indices, tour.poses)}
        estimates: dict[str, dict] = {}
        scored: dict[str, tuple] = {}
        for row in rows:
            label = row_label(row)
            if label in estimates:
                label = f"{label} [{row.get('key')}]"
            fig_ = (((results.get("methods") or {}).get(row.get("method")) or {}).get("modes", {})
                    .get(row.get("mode"), {}).get("tours", {}).get(tname) or {})
            if fig_.get("recall_1m_10deg") is not None and fig_.get("frames"):
                scored[label] = (float(fig_["recall_1m_10deg"]), int(fig_["frames"]))
            path = _trajectory_file(results_dir, results, row, tname)
            est: dict = {}
            if path.is_file():
                try:
                    frames, poses = read_tum(path, fps=fps)
                    est = {int(i): T for i, T in zip(frames, poses)}
                except SceneFormatError as e:
                    print(f"reloc plots: {e}", file=sys.stderr)
            estimates[label] = est
        bits = [str(tinfo.get(k)) for k in ("layout", "lighting") if tinfo.get(k) is not None]
        if "rearranged" in tinfo:
            bits.append("rearranged" if tinfo.get("rearranged") else "unchanged")
        if tinfo.get("sensor") not in (None, "ideal"):
            bits.append(f"sensor {tinfo['sensor']}")
        title = f"{tname}" + (f"  ({', '.join(bits)}; {len(gt)} frames)" if bits else f"  ({len(gt)} frames)")
        written.append(tour_figure(bmap, gt, estimates, plots / tour_png_name(tname), title=title, scored=scored))
    written.append(recall_bars(results, plots / "recall_bars.png"))
    if results.get("sweep"):
        from .sweep import plot_sweep

        plot_sweep(results, plots / "sweep.png")
        written.append(plots / "sweep.png")
    return written
