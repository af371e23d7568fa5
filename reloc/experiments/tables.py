"""Evaluation of an experiment and the paper's tables (markdown and JSON), numbered and titled as
in the paper (``PAPER_TABLES``):

* ``main``, Table I: map size, median position/rotation error over returned poses, recall at
  1 m/10 deg and 0.25 m/5 deg over all frames (a missing pose is a failure), pose coverage; one row
  per method and cutoff (the registered methods' rows, :mod:`reloc.experiments.methods`), pooled
  over every query tour;
* ``factors``, Table II: recall at 1 m/10 deg by lighting (day, evening, night, Delta_L = night -
  day; each a mean over layouts) and by layout (unchanged, rearranged, Delta_R, kept = rearranged /
  unchanged; means over tours);
* ``units``, Table III: the localization-unit experiment, when asked;
* ``ablation``, Table IV: orientation-aware refinement, run-level decision, adaptive clips
  (``ABLATIONS``), when asked;
* ``sensors`` (not in the paper), when the spec reads the tours through more than one sensor: per
  sensor, recall of every row and VideoReloc's within-clip odometry (drift per metre, clips, how
  clips ended: ``sensor_table``).

Sensors: a query tour read through sensor S (other than ``ideal``) is the query ``TOUR@S``
(``reading_name``). Table I and Table II's lighting and layout columns pool the reference sensor's
queries (``ideal`` when the spec lists it, else its first sensor); Table II adds ``sensor.S``
(recall over S's queries, a mean over tours) and ``sensor.S.delta`` (that minus the reference's).

The keys are the file names under ``tables/`` and the names an experiment spec's ``tables:`` uses.
``results.json`` (format ``videoreloc-experiment/1``) holds every figure, fractions in [0, 1]:
``methods.<m>.modes.<mode>.tours.<tour>``, ``.all`` (pooled) and ``.factors``; the tables print
percent. Per-frame methods that localize only some frames (appearance: frames with RGB; the
one-frame unit: every k-th frame) are evaluated over those frames, which ``frames`` states.
``tables/<key>.json`` is ``{"table": "I", "title": ..., "rows": [...]}``.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from vrformats.atomic import write_json_atomic, write_text_atomic
from vrformats.camera import read_tum
from vrformats.errors import SceneFormatError
from vrformats.yamlfile import read_json

from . import methods as registry
from ..evaluation import END_REASONS, THRESHOLDS, end_reason_kind, odometry_drift, pose_errors, summarize
from .intervals import (OK_COARSE, OK_FINE, Bootstrap, IntervalSettings, factor_figures, figure_values, n_segments,
                        pooled_figures, segment_counts, tour_figures, units_note)
from .methods.common import map_report_path, unit_file  # noqa: F401  (where the runs and maps keep them)

FORMAT = "videoreloc-experiment/1"
LIGHTINGS = ("day", "evening", "night")
METRICS = ("recall_1m_10deg", "recall_25cm_5deg", "median_pos_m", "median_rot_deg", "coverage")
FACTOR_KEYS = ("day", "evening", "night", "delta_L", "unchanged", "rearranged", "delta_R", "kept")

# The paper's tables: key -> (number, caption). The captions leave out the paper's datasets (RIO10,
# ReplicaCAD): these tables are computed on a rendered design, which the title line names instead.
EXTRA_TABLES = {  # tables the paper does not have: key -> (None, title)
    "sensors": (None, "Sensor factor: recall and VideoReloc's odometry per RGB-D sensor model"),
    "sweep": (None, "Dose-response: recall per level of one graded factor, and breaking points"),
}
PAPER_TABLES = {
    "main": ("I", "Comparison of recall and pose errors across relocalization methods and evaluation variants"),
    "factors": ("II", "Recall at 1 m/10\u00b0 under illumination and furniture changes"),
    "units": ("III", "Effect of the localization unit"),
    "ablation": ("IV", "Effects of refinement, run-level decisions and adaptive clips"),
}

# Table I's rows, each method's label and the cutoff ``reloc check`` reads for METHOD.KEY (its primary
# mode) are the registered methods' (reloc.experiments.methods: Method.rows, .label, .primary); rows in
# the paper's order (per frame, clip-rigid, ours, the oracle's upper bound), then external methods.

# Table IV rows, in the paper's order: (orientation-aware, run-level, adaptive); False = point-to-point
# refinement, no run-level decision, fixed 100-frame clips. The last is VideoReloc itself.
ABLATIONS = ((False, False, False), (True, False, False), (True, True, False), (True, False, True), (True, True, True))


SENSOR_SEP = "@"


def reading_name(tour: str, sensor: str) -> str:
    """The name of a query tour read through a sensor: the tour's name for ``ideal`` (the render as it
    is), ``TOUR@SENSOR`` otherwise; runs, results and check keys use it."""
    return tour if sensor == "ideal" else f"{tour}{SENSOR_SEP}{sensor}"


def _table_method(table: str) -> str:
    """The registered method whose runs make an optional table (units: one_frame; ablation: videoreloc,
    its variants' runs ``ablation_name``)."""
    return registry.table_method(table).name


def ablation_name(variant) -> str:
    """The method name of an ablation variant's runs (``ablation_010``: orientation-aware off, ...)."""
    return "ablation_" + "".join("1" if v else "0" for v in variant)


def table_title(key: str) -> str:
    """``Table I: Comparison of ...``: the paper's number and caption of a table."""
    number, caption = PAPER_TABLES[key]
    return f"Table {number}: {caption}"


def _gt(tour_dir: str):
    from vrformats.tour import Tour

    t = Tour(tour_dir)
    return t, {int(i): T for i, T in zip(t.frame_indices, t.poses)}


def _estimates(path: Path, fps: float) -> dict[int, np.ndarray]:
    if not path.is_file():
        return {}
    frames, poses = read_tum(path, fps=fps)
    return {int(i): T for i, T in zip(frames, poses)}


def evaluation_frames(method: str, mode: str, frames: list[int], rgb_every: int, stride: int,
                      sees_rgb_only: bool = False) -> list[int]:
    """The frames a row is evaluated on: all, except per-frame methods that see only some frames
    (a registered method's ``Method.frames``: per-frame appearance, the frames with RGB; the one-frame
    unit, every ``stride``-th; ``sees_rgb_only``: an external method run on an image export, which
    leaves out geometry-only frames)."""
    if sees_rgb_only:
        return [i for i in frames if i % rgb_every == 0]
    m = registry.get(method) if method in registry.names() else None
    if m is not None and m.frames is not None:
        return m.frames(mode, frames, rgb_every, stride)
    return frames


def factors(per_tour: dict, tours: dict, unchanged: str, sensors: list | None = None, reference: str = "ideal") -> dict:
    """Table II's figures from per-tour recall at 1 m/10 deg (fractions; None when the design lacks it).

    ``tours``: every query (``reading_name`` -> info with ``sensor``); lighting and layout use the
    ``reference`` sensor's; with more than one of ``sensors``, ``sensor.S`` and ``sensor.S.delta``."""

    def mean(names):
        v = [per_tour[n]["recall_1m_10deg"] for n in names if n in per_tour]
        return float(np.mean(v)) if v else None

    all_tours = tours
    tours = {n: t for n, t in tours.items() if t.get("sensor", "ideal") == reference}
    out: dict = {}
    for light in LIGHTINGS:
        out[light] = mean([n for n, t in tours.items() if t["lighting"] == light])
    out["delta_L"] = None if out["day"] is None or out["night"] is None else out["night"] - out["day"]
    out["unchanged"] = mean([n for n, t in tours.items() if t["layout"] == unchanged])
    out["rearranged"] = mean([n for n, t in tours.items() if t["layout"] != unchanged])
    u, r = out["unchanged"], out["rearranged"]
    out["delta_R"] = None if u is None or r is None else r - u
    out["kept"] = None if u is None or r is None or u <= 0 else r / u
    if sensors and len(sensors) > 1:
        for s in sensors:
            out[f"sensor.{s}"] = mean([n for n, t in all_tours.items() if t.get("sensor", "ideal") == s])
        ref = out.get(f"sensor.{reference}")
        for s in sensors:
            v = out[f"sensor.{s}"]
            if s != reference:
                out[f"sensor.{s}.delta"] = None if v is None or ref is None else v - ref
    return out


def _clean(d: dict) -> dict:
    return {k: (None if isinstance(v, float) and math.isnan(v) else v) for k, v in d.items()}


def evaluate_experiment(spec, out: Path, queries: dict, files: dict, methods: list, variants: list,
                        valid: set | None = None, map_files: dict | None = None) -> dict:
    """Every row on every tour; ``valid``: the (method, tour) runs that finished with the current
    inputs (others, failed or stale, count as no poses). ``files``: the reference sensor's maps;
    ``map_files``: sensor -> its maps (the quality of each sensor's box map)."""
    fields: dict = {}  # the labels' fields ({feature}: the appearance baseline's feature)
    for method in registry.all_methods():
        fields.update(method.label_fields(spec))
    by_dir: dict = {}
    gts = {n: by_dir[t["dir"]] if t["dir"] in by_dir else by_dir.setdefault(t["dir"], _gt(t["dir"]))
           for n, t in queries.items()}
    map_bytes = {k: f.stat().st_size for k, f in files.items() if f.is_file()}
    registered = {m: registry.get(m) for m in methods if m in registry.names()}
    sensors = list(getattr(spec, "sensor_names", ["ideal"]))
    reference = getattr(spec, "reference_sensor", "ideal")
    settings = getattr(spec, "intervals", None) or IntervalSettings()
    res: dict = {
        "format": FORMAT, "name": spec.name, "description": spec.description, "spec": str(spec.source),
        "map": str(files["boxes"]), "detector": spec.detector_label, "unchanged": spec.unchanged,
        "one_frame_stride": spec.one_frame_stride,
        "tours": queries, "rows": [], "methods": {},
        "sensors": sensors, "reference_sensor": reference,
    }
    if getattr(spec, "map_sensor", None) is not None:
        res["map_sensor"] = spec.map_sensor["name"]
    externals = {e.name: e for e in getattr(spec, "externals", ())}
    modes_of = {m: ([externals[m].mode] if m in externals else registered[m].modes if m in registered else [])
                for m in methods}
    for v in variants:
        modes_of[ablation_name(v)] = ["causal", "closure"]
    for m, modes in modes_of.items():
        ext = externals.get(m)
        if ext is not None:  # another relocalizer: its label, its mode, the size of what its map_command wrote
            entry = {"label": ext.label, "map_bytes": _folder_bytes(out / "maps" / m) if ext.map_command else None,
                     "primary": ext.mode, "external": ext.kind, "modes": {}}
        else:
            rm = registered.get(m)  # None: an ablation variant (labelled by its name, its key the closure mode)
            entry = {"label": rm.label.format(**fields) if rm else m, "map_bytes": map_bytes.get(rm.uses if rm else "boxes"),
                     "primary": rm.primary if rm else "closure", "modes": {}}
        for mode in modes:
            per, pooled_est, pooled_gt, units = {}, {}, {}, {}
            by_sensor: dict = {s: ({}, {}) for s in sensors}
            for k, (name, t) in enumerate(queries.items()):
                tour, gt = gts[name]
                idx = evaluation_frames(m, mode, [int(i) for i in tour.frame_indices], t["rgb_every"],
                                        spec.one_frame_stride, sees_rgb_only=ext is not None and ext.kind == "command")
                g = {i: gt[i] for i in idx}
                rel = Path("runs") / m / name / f"{mode}.txt"
                est = _estimates(out / rel, t["fps"]) if valid is None or (m, name) in valid else {}
                e = {i: T for i, T in est.items() if i in g}
                s = summarize(e, g)
                s["file"] = str(rel)
                per[name] = _clean(s)
                units[name] = _segment_counts(e, g, settings, t)
                base = k * 10_000_000
                s_est, s_gt = by_sensor.setdefault(t.get("sensor", "ideal"), ({}, {}))
                s_est.update({base + i: T for i, T in est.items() if i in g})
                s_gt.update({base + i: T for i, T in g.items()})
            pooled_est, pooled_gt = by_sensor[reference]
            entry["modes"][mode] = {"tours": per, "all": _clean(summarize(pooled_est, pooled_gt)),
                                    "factors": factors(per, queries, spec.unchanged, sensors, reference),
                                    "units": units}
            if len(sensors) > 1:
                entry["modes"][mode]["sensors"] = {s: _clean(summarize(*by_sensor[s])) for s in sensors}
        res["methods"][m] = entry
    add_intervals(res, settings)
    res["maps"] = {k: q for k in ("boxes", "boxes_oracle") if k in files
                   and (q := map_quality(map_report_path(files[k]))) is not None}
    if len(sensors) > 1:
        res["sensor_figures"] = sensor_figures(out, queries, sensors, gts, map_files or {}, spec, valid)
    for m, row in registry.rows(methods):
        res["rows"].append({"key": f"{m}.{row.mode}", "method": m, "mode": row.mode, "label": row.label.format(**fields),
                            "dagger": row.dagger})
    for m in methods:  # external methods after the built-in rows, in the spec's order
        if m in externals:
            e = externals[m]
            res["rows"].append({"key": f"{m}.{e.mode}", "method": m, "mode": e.mode, "label": e.label, "dagger": False,
                                "external": True})
    if "units" in spec.tables:
        res["units"] = _units(out, {n: t for n, t in queries.items() if t.get("sensor", "ideal") == reference},
                              spec.unchanged, gts, settings, spec.one_frame_stride)
    if variants:
        res["ablation"] = _ablation(res, variants)
    add_table_intervals(res)
    if getattr(spec, "sweep", None) is not None:
        from .sweep import compute_sweep

        res["sweep"] = compute_sweep(res, spec.sweep, bootstrap_of(res))
    return res


def _segment_counts(est: dict, gt: dict, settings: IntervalSettings, tour: dict) -> list[list[int]]:
    """A run's per-frame outcomes on one tour, counted per segment of its path (``intervals``)."""
    frames = sorted(gt)
    done, pos, rot = pose_errors(est, gt)
    err = {int(i): (p, r) for i, p, r in zip(done, pos, rot)}
    ok = {k: [i in err and err[i][0] <= tp and err[i][1] <= tr for i in frames] for k, (tp, tr) in THRESHOLDS.items()}
    n = n_segments(max(int(tour["frames"]), max(frames, default=0) + 1), settings.segment_frames)
    return segment_counts(frames, ok["recall_1m_10deg"], ok["recall_25cm_5deg"], [i in err for i in frames],
                          settings.segment_frames, n)


def bootstrap_of(res: dict) -> Bootstrap:
    """The resamples of an experiment's results (``results.json``): every run's segment counts, the
    tours' paths and the interval settings it was computed with."""
    units = {f"{m}.{mode}": d["units"] for m, e in res["methods"].items() for mode, d in e["modes"].items()
             if d.get("units") is not None}
    units.update({unit_key(u["unit"]): u["segments"] for u in res.get("units") or () if u.get("segments")})
    st = IntervalSettings(**(res.get("intervals") or {}).get("settings", {}))
    return Bootstrap(units, {n: t.get("path", "query") for n, t in res["tours"].items()}, st)


def interval_figures(res: dict) -> dict[str, dict]:
    """Per run ``METHOD.MODE`` that has segment counts, its figures as :mod:`.intervals` computes
    them, by part: ``all`` (Table I, pooled over the reference sensor's tours), ``factors`` (Table
    II), ``tours`` ({tour: figures}) and, with more than one sensor, ``sensors`` ({sensor: pooled
    figures}). The one definition that the tables' intervals and ``reloc check`` both read."""
    tours = res.get("tours") or {}
    sensors = res.get("sensors") or ["ideal"]
    reference = res.get("reference_sensor", "ideal")
    ref_tours = [n for n, t in tours.items() if t.get("sensor", "ideal") == reference]
    common = {"all": pooled_figures(ref_tours),
              "factors": factor_figures(tours, res.get("unchanged"), reference, sensors, LIGHTINGS)}
    if len(sensors) > 1:
        common["sensors"] = {s: pooled_figures([n for n, t in tours.items() if t.get("sensor", "ideal") == s])
                             for s in sensors}
    return {f"{m}.{mode}": {**common, "tours": {n: tour_figures(n) for n in d["units"]}}
            for m, entry in (res.get("methods") or {}).items() for mode, d in entry.get("modes", {}).items()
            if d.get("units") is not None}


def add_intervals(res: dict, settings: IntervalSettings) -> None:
    """Every figure's interval into ``res``: ``modes.MODE.intervals`` = {all, factors, tours, sensors}
    of ``[lo, hi]`` (None where it has none), and ``res["intervals"]``: the settings and units."""
    res["intervals"] = {"settings": settings.as_dict(), "method": "block bootstrap over segments of the query path, "
                        "tours resampled together (paired)"}
    boot = bootstrap_of(res)
    reference = res.get("reference_sensor", "ideal")
    n_ref = sum(1 for t in res["tours"].values() if t.get("sensor", "ideal") == reference)
    res["intervals"]["segments"] = {p: n for p, n in sorted(boot.n_segments.items())}
    res["intervals"]["note"] = units_note(boot.n_segments, settings, n_ref)
    for key, parts in interval_figures(res).items():
        m, mode = key.split(".", 1)

        def ci(figs: dict) -> dict:
            return {k: boot.interval(figure_values(boot, key, f)[1]) for k, f in figs.items()}

        iv = {"all": ci(parts["all"]), "factors": ci(parts["factors"]),
              "tours": {n: ci(f) for n, f in parts["tours"].items()}}
        if "sensors" in parts:
            iv["sensors"] = {sn: ci(f) for sn, f in parts["sensors"].items()}
        res["methods"][m]["modes"][mode]["intervals"] = iv


def add_table_intervals(res: dict) -> None:
    """Intervals of Tables III and IV, from the same draws as every other figure: per localization
    unit its pooled recall over all, the unchanged and the rearranged tours (``units[k].intervals``);
    per ablation row its closure and causal recall and, for closure at 1 m/10 deg, the paired
    difference to the row with every component on (``ablation[k].intervals``)."""
    if not res.get("units") and not res.get("ablation"):
        return
    boot = bootstrap_of(res)
    unchanged = res.get("unchanged")
    for u in res.get("units") or ():
        seg = u.get("segments")
        if not seg:
            continue
        groups = {"all": list(seg), "unchanged": [n for n in seg if res["tours"][n]["layout"] == unchanged],
                  "rearranged": [n for n in seg if res["tours"][n]["layout"] != unchanged]}
        u["intervals"] = {f"{g}_{k}": boot.interval(figure_values(boot, unit_key(u["unit"]), ("pooled", c, (tuple(ns),)))[1])
                          for g, ns in groups.items() if ns for k, c in (("recall_1m_10deg", OK_COARSE),
                                                                         ("recall_25cm_5deg", OK_FINE))}
    reference = res.get("reference_sensor", "ideal")
    coarse = pooled_figures([n for n, t in res["tours"].items() if t.get("sensor", "ideal") == reference])
    ablated = _table_method("ablation")
    full = next((r for r in res.get("ablation") or () if r["method"] == ablated), None)
    for a in res.get("ablation") or ():
        m = a["method"]
        iv = {}
        for mode in ("closure", "causal"):
            got = (res["methods"][m]["modes"][mode].get("intervals") or {}).get("all") or {}
            iv[f"{mode}_coarse"] = got.get("recall_1m_10deg")
            iv[f"{mode}_fine"] = got.get("recall_25cm_5deg")
        if full is not None and a is not full and coarse and f"{m}.closure" in boot.units \
                and a["closure_coarse"] is not None and full["closure_coarse"] is not None:
            fig = coarse["recall_1m_10deg"]
            d = figure_values(boot, f"{m}.closure", fig)[1] - figure_values(boot, f"{ablated}.closure", fig)[1]
            a["closure_coarse_delta"] = a["closure_coarse"] - full["closure_coarse"]
            iv["closure_coarse_delta"] = boot.interval(d)
        a["intervals"] = iv


def replicate_summary(reps: list[dict], specs: list) -> dict:
    """What ``replicates: N`` adds to ``results.json``: per replicate its seed and detector
    perturbation, and per row key (``METHOD.MODE``) every pooled figure, factor and per-tour recall
    across the replicates (``values``, replicate 0 first) with their ``spread`` (max - min) and
    standard deviation (``sd``, N - 1 in the denominator)."""
    def stats(values: list) -> dict:
        v = [x for x in values if x is not None]
        return {"values": values, "spread": (max(v) - min(v)) if len(v) == len(values) and v else None,
                "sd": float(np.std(v, ddof=1)) if len(v) == len(values) and len(v) > 1 else None}

    figs: dict = {}
    base = reps[0]
    for m, entry in base["methods"].items():
        for mode, d in entry["modes"].items():
            key = f"{m}.{mode}"
            per = [r["methods"].get(m, {}).get("modes", {}).get(mode) for r in reps]
            if any(x is None for x in per):
                continue
            f = {k: stats([x["all"].get(k) for x in per]) for k in ("recall_1m_10deg", "recall_25cm_5deg", "coverage")}
            f.update({k: stats([x["factors"].get(k) for x in per]) for k in FACTOR_KEYS})
            f["tours"] = {t: stats([x["tours"].get(t, {}).get("recall_1m_10deg") for x in per]) for t in d["tours"]}
            figs[key] = f
    return {"count": len(reps),
            "replicates": [{"seed": sp.seed, "detector": sp.detector.get("perturbation") or sp.detector.get("corruption") or {}}
                           for sp in specs],
            "figures": figs}


def sensor_figures(out: Path, queries: dict, sensors: list, gts: dict, map_files: dict, spec, valid) -> dict:
    """Per sensor: VideoReloc's within-clip odometry against ground truth (``odometry_drift`` over its
    clips in every query tour read through the sensor, from ``clip_poses.npz``) and how its clips
    ended (``clips.json``, counted by ``end_reason_kind``), and the quality of the sensor's box map."""
    from ..backend.run import load_clip_poses

    method = next(iter(registry.clip_methods(spec.methods)), None)  # whose clips give the odometry
    out_figs: dict = {}
    for s in sensors:
        names = [n for n, t in queries.items() if t.get("sensor", "ideal") == s]
        clips_all: dict = {}
        gt_all: dict = {}
        ends = {k: 0 for k in END_REASONS}
        n_runs = 0
        for k, n in enumerate(names):
            d = out / "runs" / str(method) / n
            if method is None or (valid is not None and (method, n) not in valid) or not (d / "clips.json").is_file():
                continue
            n_runs += 1
            base = k * 10_000_000
            for c, V in load_clip_poses(d).items():
                clips_all[base + c] = {base + i: T for i, T in V.items()}
            gt_all.update({base + i: T for i, T in gts[n][1].items()})
            for c in read_json(d / "clips.json", expect_object=False):
                ends[end_reason_kind(c.get("end_reason"))] += 1
        odo = odometry_drift(clips_all, gt_all) if n_runs else {}
        frames = sum(queries[n]["frames"] for n in names)
        fig = {"method": method, "tours": len(names), "runs": n_runs, "frames": frames, "odometry": odo,
               "clip_ends": ends, "clips_per_100m": (100.0 * sum(ends.values()) / odo["path_m"]
                                                     if odo.get("path_m") else None)}
        mf = map_files.get(spec.map_sensor_of(s)) if hasattr(spec, "map_sensor_of") else None
        if mf and "boxes" in mf:
            fig["map"] = map_quality(map_report_path(mf["boxes"]))
        out_figs[s] = fig
    return out_figs


def _folder_bytes(d: Path) -> int | None:
    """Bytes of the files under ``d`` (an external method's map), None when it does not exist."""
    if not d.is_dir():
        return None
    return sum(f.stat().st_size for f in d.rglob("*") if f.is_file())


def map_quality(report_path: Path) -> dict | None:
    """A built box map against the mapping layout's ground truth (``reloc.map.scoring.box_errors``
    in the map's build report): boxes built, matched, missing and extra, median errors by kind."""
    try:
        rep = read_json(report_path)
    except (SceneFormatError, OSError, ValueError):
        return None
    e = rep.get("errors")
    if not e:
        return None
    bk = e["by_kind"]
    return {
        "frames_used": rep["build"].get("frames_used"),
        "built": sum(k["built"] for k in bk.values()), "gt": sum(k["gt"] for k in bk.values()),
        "matched": sum(k["matched"] for k in bk.values()), "missing": e["gt_unobserved"],
        "extra": e["built_unmatched"], "class_errors": e["class_errors"],
        "by_kind": {k: {x: v[x] for x in ("gt", "built", "matched", "median_center_err_m", "median_size_err_max_m",
                                          "median_yaw_err_deg")} for k, v in bk.items()},
    }


def map_line(label: str, q: dict) -> str:
    """One sentence on a built map's quality for the tables' notes."""
    kinds = "; ".join(f"{k}s {v['matched']}/{v['gt']}" + (f", {100 * v['median_center_err_m']:.0f} cm" if
                                                          v["median_center_err_m"] is not None else "")
                      for k, v in q["by_kind"].items() if v["gt"])
    return (f"{label}: {q['built']} boxes from {q['frames_used']} frames; against the {q['gt']} ground-truth boxes "
            f"{q['matched']} matched, {q['missing']} missing, {q['extra']} extra ({kinds}: matched/ground truth, "
            f"median center error).")


def unit_key(length: int) -> str:
    """The run key of a localization unit's segment counts in the bootstrap (``bootstrap_of``)."""
    return f"unit_{int(length)}"


def _units(out: Path, queries: dict, unchanged: str, gts: dict | None = None,
           settings: IntervalSettings | None = None, stride: int = 1) -> list[dict]:
    reps = {}
    for name in queries:
        p = out / "runs" / _table_method("units") / name / "units.json"
        if p.is_file():
            reps[name] = read_json(p)
    rows = []
    lengths = sorted({u["unit"] for r in reps.values() for u in r["units"]})
    for L in lengths:
        row = {"unit": L}
        if gts is not None and reps:  # per-segment outcomes for the intervals, when every tour has the unit's poses
            seg = {}
            for name in reps:
                f = out / "runs" / _table_method("units") / name / unit_file(L)
                if not f.is_file():
                    break
                tour, gt = gts[name]
                frames = [int(i) for i in tour.frame_indices]
                g = {i: gt[i] for i in (frames[::max(1, stride)] if L == 1 else frames)}
                est = _estimates(f, queries[name]["fps"])
                seg[name] = _segment_counts({i: T for i, T in est.items() if i in g}, g,
                                            settings or IntervalSettings(), queries[name])
            else:
                row["segments"] = seg
        for group, names in (("all", list(reps)), ("unchanged", [n for n in reps if queries[n]["layout"] == unchanged]),
                             ("rearranged", [n for n in reps if queries[n]["layout"] != unchanged])):
            us = [u for n in names for u in reps[n]["units"] if u["unit"] == L]
            w = sum(u["frames"] for u in us)
            for key in ("recall_1m_10deg", "recall_25cm_5deg"):
                row[f"{group}_{key}"] = sum(u[key] * u["frames"] for u in us) / w if w else None
            if group == "all":
                row["frames"] = w
                row["sampled_every"] = us[0]["sampled_every"] if us else None
        rows.append(row)
    return rows


def _ablation(res: dict, variants: list) -> list[dict]:
    rows = []
    for v in ABLATIONS:
        m = _table_method("ablation") if v == (True, True, True) else ablation_name(v)
        if m not in res["methods"]:
            continue
        modes = res["methods"][m]["modes"]
        row = {"orientation_aware": v[0], "run_level": v[1], "adaptive": v[2], "method": m}
        for mode in ("closure", "causal"):
            a = modes[mode]["all"]
            row[f"{mode}_coarse"] = a["recall_1m_10deg"]
            row[f"{mode}_fine"] = a["recall_25cm_5deg"]
        rows.append(row)
    return rows


# ---------------------------------------------------------------------------------------------
# formatting


def pct(v, signed: bool = False) -> str:
    if v is None or (isinstance(v, float) and math.isnan(v)):
        return "-"
    return f"{100 * v:+.1f}" if signed else f"{100 * v:.1f}"


def pct_ci(v, iv, signed: bool = False) -> str:
    """``77.8 [70.1, 84.9]``: a fraction in percent with its interval (``intervals``), when it has one."""
    if iv is None or v is None or (isinstance(v, float) and math.isnan(v)):
        return pct(v, signed)
    return f"{pct(v, signed)} [{pct(iv[0], signed)}, {pct(iv[1], signed)}]"


def ratio_ci(v, iv) -> str:
    """kept: ``100 % [84, 118]``."""
    if v is None:
        return "-"
    text = f"{100 * v:.0f} %"
    return text if iv is None else f"{text} [{100 * iv[0]:.0f}, {100 * iv[1]:.0f}]"


def _replicate_cell(reps: dict, key: str) -> str:
    f = (reps.get("figures") or {}).get(key, {}).get("recall_1m_10deg")
    if not f or f["spread"] is None:
        return "-"
    v = f["values"]
    return f"{pct(min(v))}-{pct(max(v))} ({100 * f['spread']:.1f})"


def _intervals(res: dict, row: dict) -> dict:
    return res["methods"][row["method"]]["modes"][row["mode"]].get("intervals") or {}


def _interval_note(res: dict) -> list[str]:
    note = (res.get("intervals") or {}).get("note")
    return ["", note] if note else []


def size_text(n) -> str:
    if n is None:
        return "-"
    if n < 1024 * 1024:
        return f"{n / 1024:.0f} kB"
    return f"{n / 1024 / 1024:.1f} MB"


def _label(row: dict) -> str:
    return row["label"] + ("†" if row["dagger"] else "")


def _reference_tours(res: dict) -> dict:
    ref = res.get("reference_sensor", "ideal")
    return {n: t for n, t in res["tours"].items() if t.get("sensor", "ideal") == ref}


def _sensor_note(res: dict) -> str:
    """'; sensor: ideal' when the experiment reads its tours through more than one sensor."""
    return f"; sensor: {res.get('reference_sensor', 'ideal')}" if len(res.get("sensors") or []) > 1 else ""


def main_table(res: dict) -> tuple[str, list[dict]]:
    tours = _reference_tours(res)
    n_tours = len(tours)
    frames = sum(t["frames"] for t in tours.values())
    det = res.get("detector")
    reps = res.get("replicates") or {}
    n_rep = reps.get("count", 1)
    rep_head = f" 1 m/10°, {n_rep} replicates |" if n_rep > 1 else ""
    lines = [f"**{table_title('main')}** ({n_tours} query tours, {frames} frames"
             f"{f'; detections: {det}' if det else ''}{_sensor_note(res)})", "",
             f"| Method | Map size | Pos. / rot. | 1 m/10° | 0.25 m/5° | Coverage | Frames evaluated |{rep_head}",
             "|---|---|---|---|---|---|---|" + ("---|" if n_rep > 1 else "")]
    rows = []
    for r in res["rows"]:
        m = res["methods"][r["method"]]
        a = m["modes"][r["mode"]]["all"]
        med = ("-" if a["median_pos_m"] is None else f"{100 * a['median_pos_m']:.0f} cm / {a['median_rot_deg']:.1f}°")
        iv = _intervals(res, r).get("all") or {}
        lines.append(f"| {_label(r)} | {size_text(m['map_bytes'])} | {med} | "
                     f"{pct_ci(a['recall_1m_10deg'], iv.get('recall_1m_10deg'))} | "
                     f"{pct_ci(a['recall_25cm_5deg'], iv.get('recall_25cm_5deg'))} | "
                     f"{pct_ci(a['coverage'], iv.get('coverage'))} | {a['frames']} |"
                     + (f" {_replicate_cell(reps, r['key'])} |" if n_rep > 1 else ""))
        rows.append({"key": r["key"], "label": _label(r), "map_bytes": m["map_bytes"], **a,
                     **{f"{k}_interval": v for k, v in iv.items()}})
    lines += ["", "Recall (%) over all evaluated frames, a frame without a pose counts as a failure; median errors "
              "over returned poses. † clip-rigid control: VideoReloc's clip partition and within-clip odometry, "
              "one clip-to-map transform per clip at clip closure, no cross-clip back-end. Per-frame appearance "
              "is evaluated on the frames with RGB, the one-frame unit on every "
              f"{res['one_frame_stride']}th frame."]
    ext = [m for m in res["methods"].values() if m.get("external")]
    if ext:
        lines[-1] += (" External methods: a command on exported tours is evaluated on the frames its export holds "
                      "(those with RGB), trajectories on every frame; their map size is what map_command wrote.")
    lines += _interval_note(res)
    if n_rep > 1:
        lines += ["", f"Replicates: the experiment run {n_rep} times with its stochastic parts reseeded (random draws, "
                  "sensor noise; the learned detector's input jittered by one 8-bit level, which is what another "
                  "processor amounts to); the column gives the lowest and highest recall and their spread (points)."]
    maps = res.get("maps") or {}
    for k, label in (("boxes", f"Box map built with the {res.get('detector') or 'oracle'} detector"),
                     ("boxes_oracle", "Box map built from oracle detections")):
        if k in maps:
            lines += ["", map_line(label, maps[k])]
    return "\n".join(lines), rows


def factors_table(res: dict) -> tuple[str, list[dict]]:
    lights = [x for x in LIGHTINGS if any(t["lighting"] == x for t in _reference_tours(res).values())]
    sensors = list(res.get("sensors") or [])
    ref = res.get("reference_sensor", "ideal")
    others = [s for s in sensors if s != ref] if len(sensors) > 1 else []

    def line(cells) -> str:
        return "| " + " | ".join(cells) + " |"

    head = ["Method", *lights, "ΔL", "unchanged", "rearranged", "ΔR", "kept"]
    if others:
        head += [ref, *(x for s in others for x in (s, f"Δ {s}"))]
    lines = [f"**{table_title('factors')}**" + (f" (lighting and layout: sensor {ref})" if others else ""), "",
             line(head), "|---" * len(head) + "|"]
    rows = []
    for r in res["rows"]:
        f = res["methods"][r["method"]]["modes"][r["mode"]]["factors"]
        iv = _intervals(res, r).get("factors") or {}

        def c(k, signed=False):
            return pct_ci(f.get(k), iv.get(k), signed)

        cells = [_label(r), *(c(x) for x in lights), c("delta_L", True), c("unchanged"),
                 c("rearranged"), c("delta_R", True), ratio_ci(f["kept"], iv.get("kept"))]
        if others:
            cells += [c(f"sensor.{ref}")]
            cells += [x for s in others for x in (c(f"sensor.{s}"), c(f"sensor.{s}.delta", True))]
        lines.append(line(cells))
        rows.append({"key": r["key"], "label": _label(r), **f, **{f"{k}_interval": v for k, v in iv.items()}})
    lines += ["", "Recall (%); lighting columns average the layouts, unchanged/rearranged average the tours. "
              "ΔL = night - day and ΔR = rearranged - unchanged (points); kept = rearranged / unchanged."]
    if others:
        lines[-1] += (f" Sensor columns: recall over every query tour read through that sensor (a mean over tours); "
                      f"Δ = that sensor - {ref} (points). The other columns use the {ref} sensor's tours.")
    lines += _interval_note(res)
    return "\n".join(lines), rows


def sensor_table(res: dict) -> tuple[str, list[dict]]:
    """Per sensor: every row's recall at 1 m/10 deg (its pooled frames), VideoReloc's within-clip
    odometry drift and clip counts, and how its clips ended."""
    figs = res.get("sensor_figures") or {}
    sensors = list(res.get("sensors") or [])
    rows_r = res["rows"]
    head = ["Sensor", *(_label(r) for r in rows_r), "drift (% of path)", "drift (°/m)", "clips / 100 m",
            *END_REASONS]
    lines = [f"**{EXTRA_TABLES['sensors'][1]}**", "", "| " + " | ".join(head) + " |", "|---" * len(head) + "|"]
    rows = []
    for s in sensors:
        f = figs.get(s) or {}
        odo = f.get("odometry") or {}
        ends = f.get("clip_ends") or {}
        rec = {r["key"]: res["methods"][r["method"]]["modes"][r["mode"]].get("sensors", {}).get(s, {}).get("recall_1m_10deg")
               for r in rows_r}
        rec_iv = {r["key"]: ((_intervals(res, r).get("sensors") or {}).get(s) or {}).get("recall_1m_10deg")
                  for r in rows_r}
        drift = "-" if odo.get("drift_pct") is None else f"{odo['drift_pct']:.2f}"
        deg = "-" if odo.get("drift_deg_per_m") is None else f"{odo['drift_deg_per_m']:.2f}"
        c100 = "-" if f.get("clips_per_100m") is None else f"{f['clips_per_100m']:.1f}"
        lines.append("| " + " | ".join([s, *(pct_ci(rec[r["key"]], rec_iv[r["key"]]) for r in rows_r), drift, deg, c100,
                                         *(str(ends.get(k, 0)) for k in END_REASONS)]) + " |")
        rows.append({"sensor": s, "recall_1m_10deg": rec, "recall_1m_10deg_interval": rec_iv, **{k: odo.get(k) for k in ("drift_pct", "drift_deg_per_m",
                                                                                     "median_drift_pct", "path_m")},
                     "clips_per_100m": f.get("clips_per_100m"), "clip_ends": ends})
    method = next((f.get("method") for f in figs.values() if f.get("method")), "videoreloc")
    lines += ["", f"Recall (%) at 1 m/10° over every frame of the query tours read through each sensor. Odometry: "
              f"{method}'s clips (its within-clip RGB-D odometry) against ground truth, each clip aligned at its "
              "first frame: endpoint error / ground-truth path length, summed over clips. Clip ends: closed (enough "
              "evidence), max length, end of tour, odometry failure (a gate failed: the run breaks there), no usable "
              "depth (too few valid depth pixels)."]
    lines += _interval_note(res)
    return "\n".join(lines), rows


def units_table(res: dict) -> tuple[str, list[dict]]:
    lines = [f"**{table_title('units')}**", "",
             "| Unit | 1 m/10° | 0.25 m/5° | unchanged 1 m/10° | rearranged 1 m/10° |", "|---|---|---|---|---|"]
    for u in res["units"]:
        name = "one frame" if u["unit"] == 1 else f"{u['unit']}-frame clip"
        if u["unit"] == 1 and (u.get("sampled_every") or 1) > 1:
            name += f" (every {u['sampled_every']}th frame)"
        iv = u.get("intervals") or {}
        cells = [pct_ci(u[k], iv.get(k)) for k in ("all_recall_1m_10deg", "all_recall_25cm_5deg",
                                                   "unchanged_recall_1m_10deg", "rearranged_recall_1m_10deg")]
        lines.append(f"| {name} | " + " | ".join(cells) + " |")
    lines += ["", "Each unit is registered independently, without tracking or a pose graph; recall (%) over all "
              "frames, measured when the unit closes."]
    if any(u.get("intervals") for u in res["units"]):
        lines += _interval_note(res)
    return "\n".join(lines), [{k: v for k, v in u.items() if k != "segments"} for u in res["units"]]


def ablation_table(res: dict) -> tuple[str, list[dict]]:
    ck = lambda b: "✓" if b else ""  # noqa: E731
    lines = [f"**{table_title('ablation')}**", "",
             "| orientation-aware | run-level | adaptive | closure 1 m/10° | closure 0.25 m/5° | causal 1 m/10° | "
             "causal 0.25 m/5° | closure 1 m/10° against all on |", "|---|---|---|---|---|---|---|---|"]
    for a in res["ablation"]:
        iv = a.get("intervals") or {}
        cells = [pct_ci(a[k], iv.get(k)) for k in ("closure_coarse", "closure_fine", "causal_coarse", "causal_fine")]
        delta = pct_ci(a.get("closure_coarse_delta"), iv.get("closure_coarse_delta"), signed=True) \
            if "closure_coarse_delta" in a else "-"
        lines.append(f"| {ck(a['orientation_aware'])} | {ck(a['run_level'])} | {ck(a['adaptive'])} | "
                     + " | ".join(cells) + f" | {delta} |")
    lines += ["", "Recall (%) over all frames. Empty cells: point-to-point refinement, no run-level decision, "
              "fixed 100-frame clips. Tracking and the pose graph stay on. The last column: the row's closure recall "
              "minus that of the row with every component on, with the interval of the paired difference."]
    if any(a.get("intervals") for a in res["ablation"]):
        lines += _interval_note(res)
    return "\n".join(lines), res["ablation"]


def make_tables(res: dict) -> dict[str, tuple[str, list]]:
    t = {"main": main_table(res), "factors": factors_table(res)}
    if res.get("units"):
        t["units"] = units_table(res)
    if res.get("ablation"):
        t["ablation"] = ablation_table(res)
    if len(res.get("sensors") or []) > 1:
        t["sensors"] = sensor_table(res)
    if res.get("sweep"):
        from .sweep import sweep_table

        t["sweep"] = sweep_table(res)
    failed = res.get("failed") or {}
    if failed:  # a failed run has no poses: its tour counts as failures, which the reader must know
        warn = (f"**Incomplete: {len(failed)} run(s) failed** ({', '.join(sorted(failed)[:3])}"
                f"{', ...' if len(failed) > 3 else ''}); their frames count as failures below.\n\n")
        t = {k: (warn + md, rows) for k, (md, rows) in t.items()}
    return t


def write_tables(res: dict, out: Path) -> None:
    d = Path(out) / "tables"
    made = make_tables(res)
    for name, (md, rows) in made.items():
        number, caption = PAPER_TABLES.get(name) or EXTRA_TABLES[name]
        write_text_atomic(d / f"{name}.md", md + "\n")
        write_json_atomic(d / f"{name}.json", {"table": number, "title": caption, "rows": rows})
    for stale in d.glob("*.md"):  # a table no longer asked for
        if stale.stem not in made:
            stale.unlink()
            stale.with_suffix(".json").unlink(missing_ok=True)


def read_results(results_dir) -> dict:
    """``results.json`` of an experiment results folder; a missing or malformed one is one line naming it."""
    return read_json(Path(results_dir) / "results.json",
                     missing=f"not found (is {results_dir} a reloc experiment results folder?)")


def format_all(out: Path) -> str:
    res = read_results(out)
    return "\n\n".join(md for md, _ in make_tables(res).values())
