"""Graded factors in an experiment (issue 29): dose-response tables, plots and breaking points.

An experiment spec's ``sweep`` names one factor and its levels, each level one value of the
design (a layout, a lighting preset or a sensor of the experiment)::

    sweep:
      factor: rearrangement          # rearrangement (layouts) | lighting (lighting presets, e.g. dimmer files)
                                     # | sensor (the experiment's sensors, e.g. noise-scaled files)
      levels:                        # level -> the layout / lighting / sensor name of its query tours
        0: apt_0
        0.25: apt_0_g025
        1.0: apt_0_g100
      fraction: 0.8                  # the breaking point: recall below this fraction of level 0's

For every method (``METHOD.MODE`` run), each level's recall at 1 m/10 deg is the mean over the
query tours of that level (the other factors pooled), with its interval from the experiment's
bootstrap (``reloc.experiments.intervals``: the same resampled path segments as every other
figure, so levels are paired), and its ratio to the lowest level, with an interval. The *breaking
point* is the lowest level whose ratio falls below ``fraction``; a method that holds at every level
has none (``reloc check`` reads it as infinity: ``videoreloc.breaking_point.rearrangement >= 0.5``
passes). A method with no recall at the lowest level has no ratio to it: it is broken from the start,
and its breaking point (and both bounds) is that level. The breaking point has an interval too: ``.lo``, the first level whose ratio's interval
reaches below the fraction (where the method may break), and ``.hi``, the first whose whole interval
lies below it (where it surely breaks); checks should use ``.lo``. ``tables/sweep.md`` holds the
table, ``plots/sweep.png`` the dose-response plot.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from vrformats.errors import SceneFormatError
from vrformats.fields import is_number
from vrformats.atomic import save_figure

from .intervals import OK_COARSE, figure_values

FACTORS = {"rearrangement": "layout", "lighting": "lighting", "sensor": "sensor"}
SWEEP_KEYS = {"factor", "levels", "fraction"}


@dataclass(frozen=True)
class Sweep:
    factor: str
    levels: tuple  # ((level, value), ...) sorted by level
    fraction: float = 0.8

    @property
    def field(self) -> str:
        return FACTORS[self.factor]

    def as_dict(self) -> dict:
        return {"factor": self.factor, "levels": [[lv, v] for lv, v in self.levels], "fraction": self.fraction}


def parse_sweep(doc, source) -> Sweep | None:
    """The ``sweep`` section of an experiment spec (None when absent); errors name the file and key."""
    if doc is None:
        return None
    if not isinstance(doc, dict):
        raise SceneFormatError(source, "sweep", "expected a mapping with factor, levels, fraction")
    unknown = sorted(map(str, set(doc) - SWEEP_KEYS))
    if unknown:
        raise SceneFormatError(source, f"sweep.{unknown[0]}", f"unknown key; allowed: {', '.join(sorted(SWEEP_KEYS))}")
    factor = doc.get("factor")
    if factor not in FACTORS:
        raise SceneFormatError(source, "sweep.factor", f"expected one of {', '.join(FACTORS)}, got {factor!r}")
    levels = doc.get("levels")
    if not isinstance(levels, dict) or not levels:
        raise SceneFormatError(source, "sweep.levels", "expected a mapping of level -> name (layout, lighting or sensor)")
    out = []
    for lv, name in levels.items():
        if not is_number(lv) or lv < 0:
            raise SceneFormatError(source, f"sweep.levels.{lv}", f"expected a level >= 0, got {lv!r}")
        if not isinstance(name, str) or not name:
            raise SceneFormatError(source, f"sweep.levels.{lv}", f"expected the name of a {FACTORS[factor]}, got {name!r}")
        out.append((float(lv), name))
    if len(out) < 2:
        raise SceneFormatError(source, "sweep.levels", "a sweep needs at least two levels")
    names = [n for _, n in out]
    if len(set(names)) != len(names):
        raise SceneFormatError(source, "sweep.levels", "two levels name the same tours")
    fraction = doc.get("fraction", 0.8)
    if not is_number(fraction) or not 0 < fraction < 1:
        raise SceneFormatError(source, "sweep.fraction", f"expected a fraction in (0, 1), got {fraction!r}")
    return Sweep(factor, tuple(sorted(out)), float(fraction))


def level_tours(tours: dict, sweep: Sweep, reference_sensor: str = "ideal") -> dict[float, tuple]:
    """{level: the query tours (reading names) of that level}. For layouts and lightings, the
    reference sensor's readings; for sensors, every reading through that sensor."""
    out = {}
    for lv, value in sweep.levels:
        if sweep.factor == "sensor":
            sel = [n for n, t in tours.items() if t.get("sensor", "ideal") == value]
        else:
            sel = [n for n, t in tours.items() if t.get(sweep.field) == value and t.get("sensor", "ideal") == reference_sensor]
        out[lv] = tuple(sorted(sel))
    return out


def missing_levels(tours: dict, sweep: Sweep, reference_sensor: str = "ideal") -> list[str]:
    """The levels no query tour belongs to, as ``sweep.levels.L (name)``: the design lacks them."""
    return [f"sweep.levels.{lv:g} ({v})" for (lv, v), sel in zip(sweep.levels, level_tours(tours, sweep, reference_sensor).values())
            if not sel]


def compute_sweep(res: dict, sweep: Sweep, boot) -> dict:
    """The sweep's figures for every run of ``res`` (results.json before it is written): per run
    ``METHOD.MODE``, per level its recall and interval, its ratio to the lowest level and interval,
    and the breaking point. ``boot``: the experiment's resamples (``tables.bootstrap_of(res)``)."""
    sel = level_tours(res["tours"], sweep, res.get("reference_sensor", "ideal"))
    lv0 = sweep.levels[0][0]
    runs = {}
    for m, entry in res["methods"].items():
        for mode, d in entry["modes"].items():
            if d.get("units") is None:
                continue
            key = f"{m}.{mode}"
            rows = []
            for lv, value in sweep.levels:
                if not sel[lv]:
                    rows.append({"level": lv, "value": value, "tours": 0, "recall": None, "ci": None, "ratio": None,
                                 "ratio_ci": None})
                    continue
                p, r = figure_values(boot, key, ("mean", OK_COARSE, (sel[lv],)))
                q, rr = figure_values(boot, key, ("ratio", OK_COARSE, (sel[lv], sel[lv0]))) if sel[lv0] else (None, None)
                rows.append({"level": lv, "value": value, "tours": len(sel[lv]), "recall": p, "ci": boot.interval(r),
                             "ratio": q, "ratio_ci": boot.interval(rr) if rr is not None else None})
            def first(pred):
                hit = [row["level"] for row in rows if pred(row)]
                return hit[0] if hit else None

            f = sweep.fraction
            if rows[0]["recall"] == 0:  # no recall on the reference level: no ratio, broken from the start
                runs[key] = {"levels": rows, "breaking_point": lv0, "breaking_point_lo": lv0, "breaking_point_hi": lv0,
                             "broken_at_reference": True}
                continue
            runs[key] = {"levels": rows,
                         "breaking_point": first(lambda r: r["ratio"] is not None and r["ratio"] < f),
                         # the interval of the breaking point: the first level whose ratio may be below the
                         # fraction (its interval's lower bound is) and the first where it surely is (upper bound)
                         "breaking_point_lo": first(lambda r: r["ratio_ci"] is not None and r["ratio_ci"][0] < f),
                         "breaking_point_hi": first(lambda r: r["ratio_ci"] is not None and r["ratio_ci"][1] < f)}
    return {**sweep.as_dict(), "runs": runs}


def breaking_metrics(results: dict) -> dict:
    """``reloc check`` names of the sweep: ``METHOD[.MODE].breaking_point.FACTOR`` (infinity when the
    method holds at every level), its bounds ``.lo`` (the first level whose ratio's interval reaches
    below the fraction: where it may break) and ``.hi`` (the first whose whole interval is below: where
    it surely breaks), and ``METHOD[.MODE].sweep.LEVEL`` (recall at that level)."""
    sw = results.get("sweep")
    if not sw:
        return {}
    vals = {}
    for key, run in sw["runs"].items():
        m, mode = key.split(".", 1)
        primary = results["methods"].get(m, {}).get("primary") == mode
        inf = lambda v: math.inf if v is None else v  # noqa: E731
        bp = f"breaking_point.{sw['factor']}"
        figs = {bp: inf(run["breaking_point"]), f"{bp}.lo": inf(run.get("breaking_point_lo")),
                f"{bp}.hi": inf(run.get("breaking_point_hi"))}
        figs.update({f"sweep.{row['level']:g}": row["recall"] for row in run["levels"]})
        for k, v in figs.items():
            vals[f"{key}.{k}"] = v
            if primary:
                vals[f"{m}.{k}"] = v
    return vals


def _pct(v) -> str:
    return "-" if v is None else f"{100 * v:.1f}"


def _ci(iv) -> str:
    return "" if not iv else f" [{100 * iv[0]:.1f}, {100 * iv[1]:.1f}]"


def sweep_table(res: dict) -> tuple[str, list[dict]]:
    """Markdown: one row per run, one column per level (recall % [interval]), and the breaking point."""
    sw = res["sweep"]
    labels = {r["key"]: r["label"] + (" †" if r.get("dagger") else "") for r in res.get("rows", [])}
    levels = [lv for lv, _ in sw["levels"]]
    head = ["method"] + [f"{lv:g} ({v})" for lv, v in sw["levels"]] + [
        f"breaking point (< {100 * sw['fraction']:.0f} % of level {levels[0]:g}) [may, surely]"]
    lines = [f"**Dose-response: {sw['factor']}** (recall at 1 m/10 deg, % [95 % interval], mean over each level's "
             "query tours)", "", "| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    rows = []
    for key, run in sw["runs"].items():
        def lv(v) -> str:
            return "none" if v is None else f"{v:g}"

        bp = run["breaking_point"]
        cells = [f"{_pct(r['recall'])}{_ci(r['ci'])}" for r in run["levels"]]
        span = f" [{lv(run.get('breaking_point_lo'))}, {lv(run.get('breaking_point_hi'))}]"
        verdict = ("none (holds)" if bp is None else f"{bp:g}") + span
        if run.get("broken_at_reference"):
            verdict = f"{bp:g}: no recall at level {levels[0]:g}"
        lines.append("| " + " | ".join([labels.get(key, key)] + cells + [verdict])
                     + " |")
        rows.append({"key": key, "breaking_point": bp, "levels": run["levels"]})
    lines += ["", "Ratio to level " + f"{levels[0]:g}" + " (% [95 % interval], paired: the same resampled path segments):", "",
              "| method | " + " | ".join(f"{lv:g}" for lv in levels) + " |", "|" + "---|" * (len(levels) + 1)]
    for key, run in sw["runs"].items():
        lines.append("| " + " | ".join([labels.get(key, key)] + [f"{_pct(r['ratio'])}{_ci(r['ratio_ci'])}"
                                                                 for r in run["levels"]]) + " |")
    return "\n".join(lines) + "\n", rows


def plot_sweep(res: dict, path) -> None:
    """Recall against level per run, with the intervals as error bars and the breaking fraction of
    each run's level-0 recall dashed."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    sw = res["sweep"]
    labels = {r["key"]: r["label"] for r in res.get("rows", [])}
    fig, ax = plt.subplots(figsize=(7, 4.2))
    for key, run in sw["runs"].items():
        pts = [r for r in run["levels"] if r["recall"] is not None]
        if not pts:
            continue
        x = [r["level"] for r in pts]
        y = [100 * r["recall"] for r in pts]
        lo = [100 * (r["recall"] - r["ci"][0]) if r["ci"] else 0 for r in pts]
        hi = [100 * (r["ci"][1] - r["recall"]) if r["ci"] else 0 for r in pts]
        line = ax.errorbar(x, y, yerr=[lo, hi], marker="o", capsize=3, label=labels.get(key, key))
        ax.axhline(100 * sw["fraction"] * pts[0]["recall"], color=line[0].get_color(), ls=":", lw=0.8)
    ax.set_xticks([lv for lv, _ in sw["levels"]], [f"{lv:g}\n{v}" for lv, v in sw["levels"]], fontsize=7)
    ax.set_xlabel(f"{sw['factor']} level")
    ax.set_ylabel("recall at 1 m / 10 deg (%)")
    ax.set_ylim(0, 105)
    ax.grid(alpha=0.3)
    ax.legend(fontsize=7, loc="lower left")
    ax.set_title(f"Dose-response: {sw['factor']} (dotted: {100 * sw['fraction']:.0f} % of each method's level 0)", fontsize=9)
    fig.tight_layout()
    save_figure(fig, path, dpi=120)
    plt.close(fig)
