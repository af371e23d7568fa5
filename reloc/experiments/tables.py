"""Evaluation of an experiment and the paper's tables (markdown and JSON), numbered and titled as
in the paper (``PAPER_TABLES``):

* ``main``, Table I: map size, median position/rotation error over returned poses, recall at
  1 m/10 deg and 0.25 m/5 deg over all frames (a missing pose is a failure), pose coverage; one row
  per method and cutoff (``ROWS``), pooled over every query tour;
* ``factors``, Table II: recall at 1 m/10 deg by lighting (day, evening, night, Delta_L = night -
  day; each a mean over layouts) and by layout (unchanged, rearranged, Delta_R, kept = rearranged /
  unchanged; means over tours);
* ``units``, Table III: the localization-unit experiment, when asked;
* ``ablation``, Table IV: orientation-aware refinement, run-level decision, adaptive clips
  (``ABLATIONS``), when asked.

The keys are the file names under ``tables/`` and the names an experiment spec's ``tables:`` uses.
``results.json`` (format ``videoreloc-experiment/1``) holds every figure, fractions in [0, 1]:
``methods.<m>.modes.<mode>.tours.<tour>``, ``.all`` (pooled) and ``.factors``; the tables print
percent. Per-frame methods that localize only some frames (appearance: frames with RGB; the
one-frame unit: every k-th frame) are evaluated over those frames, which ``frames`` states.
``tables/<key>.json`` is ``{"table": "I", "title": ..., "rows": [...]}``.
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np

from formats.atomic import write_json_atomic, write_text_atomic
from formats.camera import read_tum

from .evaluation import summarize

FORMAT = "videoreloc-experiment/1"
LIGHTINGS = ("day", "evening", "night")
METRICS = ("recall_1m_10deg", "recall_25cm_5deg", "median_pos_m", "median_rot_deg", "coverage")
FACTOR_KEYS = ("day", "evening", "night", "delta_L", "unchanged", "rearranged", "delta_R", "kept")

# The paper's tables: key -> (number, caption). The captions leave out the paper's datasets (RIO10,
# ReplicaCAD): these tables are computed on a rendered design, which the title line names instead.
PAPER_TABLES = {
    "main": ("I", "Comparison of recall and pose errors across relocalization methods and evaluation variants"),
    "factors": ("II", "Recall at 1 m/10\u00b0 under illumination and furniture changes"),
    "units": ("III", "Effect of the localization unit"),
    "ablation": ("IV", "Effects of refinement, run-level decisions and adaptive clips"),
}

# Table I rows: (method, mode, label, dagger), in the paper's order (per frame, clip-rigid, ours)
ROWS = (
    ("appearance", "causal", "Appearance ({feature} + PnP), per frame", False),
    ("one_frame", "causal", "One-frame object unit", False),
    ("fpfh_icp", "closure", "FPFH-ICP", True),
    ("appearance", "closure", "Appearance ({feature} + PnP)", True),
    ("videoreloc", "causal", "VideoReloc, causal", False),
    ("videoreloc", "closure", "VideoReloc, with clip closure", False),
    # the upper bound: the same relocalizer on the rendered labels (map and queries), beside the
    # detector the experiment uses
    ("videoreloc_oracle", "causal", "VideoReloc (oracle detections), causal", False),
    ("videoreloc_oracle", "closure", "VideoReloc (oracle detections), with clip closure", False),
)
# the cutoff ``reloc check`` reads for METHOD.KEY
PRIMARY = {"videoreloc": "closure", "videoreloc_oracle": "closure", "fpfh_icp": "closure", "appearance": "causal",
           "one_frame": "causal"}
LABELS = {"videoreloc": "VideoReloc", "videoreloc_oracle": "VideoReloc (oracle detections)", "fpfh_icp": "FPFH-ICP",
          "appearance": "Appearance ({feature} + PnP)", "one_frame": "One-frame object unit"}

# Table IV rows, in the paper's order: (orientation-aware, run-level, adaptive); False = point-to-point
# refinement, no run-level decision, fixed 100-frame clips. The last is VideoReloc itself.
ABLATIONS = ((False, False, False), (True, False, False), (True, True, False), (True, False, True), (True, True, True))


def ablation_name(variant) -> str:
    """The method name of an ablation variant's runs (``ablation_010``: orientation-aware off, ...)."""
    return "ablation_" + "".join("1" if v else "0" for v in variant)


def table_title(key: str) -> str:
    """``Table I: Comparison of ...``: the paper's number and caption of a table."""
    number, caption = PAPER_TABLES[key]
    return f"Table {number}: {caption}"


def _gt(tour_dir: str):
    from formats.tour import Tour

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
    (``sees_rgb_only``: an external method run on an image export, which leaves out geometry-only frames)."""
    if (method == "appearance" and mode == "causal") or sees_rgb_only:
        return [i for i in frames if i % rgb_every == 0]
    if method == "one_frame":
        return frames[::stride]
    return frames


def factors(per_tour: dict, tours: dict, unchanged: str) -> dict:
    """Table II's figures from per-tour recall at 1 m/10 deg (fractions; None when the design lacks it)."""

    def mean(names):
        v = [per_tour[n]["recall_1m_10deg"] for n in names if n in per_tour]
        return float(np.mean(v)) if v else None

    out: dict = {}
    for light in LIGHTINGS:
        out[light] = mean([n for n, t in tours.items() if t["lighting"] == light])
    out["delta_L"] = None if out["day"] is None or out["night"] is None else out["night"] - out["day"]
    out["unchanged"] = mean([n for n, t in tours.items() if t["layout"] == unchanged])
    out["rearranged"] = mean([n for n, t in tours.items() if t["layout"] != unchanged])
    u, r = out["unchanged"], out["rearranged"]
    out["delta_R"] = None if u is None or r is None else r - u
    out["kept"] = None if u is None or r is None or u <= 0 else r / u
    return out


def _clean(d: dict) -> dict:
    return {k: (None if isinstance(v, float) and math.isnan(v) else v) for k, v in d.items()}


def evaluate_experiment(spec, out: Path, queries: dict, files: dict, methods: list, variants: list,
                        valid: set | None = None) -> dict:
    """Every row on every tour; ``valid``: the (method, tour) runs that finished with the current
    inputs (others, failed or stale, count as no poses)."""
    from ..baselines.appearance import AppearanceConfig

    feature = str(spec.appearance.get("feature", AppearanceConfig().feature)).upper()
    gts = {n: _gt(t["dir"]) for n, t in queries.items()}
    map_bytes = {k: f.stat().st_size for k, f in files.items() if f.is_file()}
    method_map = {"videoreloc": "boxes", "one_frame": "boxes", "videoreloc_oracle": "boxes_oracle", "fpfh_icp": "fpfh",
                  "appearance": "appearance"}
    res: dict = {
        "format": FORMAT, "name": spec.name, "description": spec.description, "spec": str(spec.source),
        "map": str(files["boxes"]), "detector": spec.detector_label, "unchanged": spec.unchanged,
        "one_frame_stride": spec.one_frame_stride,
        "tours": queries, "rows": [], "methods": {},
    }
    externals = {e.name: e for e in getattr(spec, "externals", ())}
    modes_of = {m: ([externals[m].mode] if m in externals else [mode for (mm, mode, _, _) in ROWS if mm == m])
                for m in methods}
    for v in variants:
        modes_of[ablation_name(v)] = ["causal", "closure"]
    for m, modes in modes_of.items():
        ext = externals.get(m)
        if ext is not None:  # another relocalizer: its label, its mode, the size of what its map_command wrote
            entry = {"label": ext.label, "map_bytes": _folder_bytes(out / "maps" / m) if ext.map_command else None,
                     "primary": ext.mode, "external": ext.kind, "modes": {}}
        else:
            entry = {"label": LABELS.get(m, m).format(feature=feature), "map_bytes": map_bytes.get(method_map.get(m, "boxes")),
                     "primary": PRIMARY.get(m, "closure"), "modes": {}}
        for mode in modes:
            per, pooled_est, pooled_gt = {}, {}, {}
            for k, (name, t) in enumerate(queries.items()):
                tour, gt = gts[name]
                idx = evaluation_frames(m, mode, [int(i) for i in tour.frame_indices], t["rgb_every"],
                                        spec.one_frame_stride, sees_rgb_only=ext is not None and ext.kind == "command")
                g = {i: gt[i] for i in idx}
                rel = Path("runs") / m / name / f"{mode}.txt"
                est = _estimates(out / rel, t["fps"]) if valid is None or (m, name) in valid else {}
                s = summarize({i: T for i, T in est.items() if i in g}, g)
                s["file"] = str(rel)
                per[name] = _clean(s)
                base = k * 10_000_000
                pooled_est.update({base + i: T for i, T in est.items() if i in g})
                pooled_gt.update({base + i: T for i, T in g.items()})
            entry["modes"][mode] = {"tours": per, "all": _clean(summarize(pooled_est, pooled_gt)),
                                    "factors": factors(per, queries, spec.unchanged)}
        res["methods"][m] = entry
    res["maps"] = {k: q for k in ("boxes", "boxes_oracle") if k in files
                   and (q := map_quality(map_report_path(files[k]))) is not None}
    for m, mode, label, dagger in ROWS:
        if m in methods:
            res["rows"].append({"key": f"{m}.{mode}", "method": m, "mode": mode, "label": label.format(feature=feature),
                                "dagger": dagger})
    for m in methods:  # external methods after the built-in rows, in the spec's order
        if m in externals:
            e = externals[m]
            res["rows"].append({"key": f"{m}.{e.mode}", "method": m, "mode": e.mode, "label": e.label, "dagger": False,
                                "external": True})
    if "units" in spec.tables:
        res["units"] = _units(out, queries, spec.unchanged)
    if variants:
        res["ablation"] = _ablation(res, variants)
    return res


def _folder_bytes(d: Path) -> int | None:
    """Bytes of the files under ``d`` (an external method's map), None when it does not exist."""
    if not d.is_dir():
        return None
    return sum(f.stat().st_size for f in d.rglob("*") if f.is_file())


def map_report_path(map_file) -> Path:
    """Where an experiment keeps a built map's report (build counts, errors against the ground
    truth): ``videoreloc_map.json`` -> ``videoreloc_map.report.json``."""
    p = Path(map_file)
    return p.with_name(p.stem + ".report.json")


def map_quality(report_path: Path) -> dict | None:
    """A built box map against the mapping layout's ground truth (``reloc.map.scoring.box_errors``
    in the map's build report): boxes built, matched, missing and extra, median errors by kind."""
    try:
        rep = json.loads(Path(report_path).read_text())
    except (OSError, ValueError):
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


def _units(out: Path, queries: dict, unchanged: str) -> list[dict]:
    reps = {}
    for name in queries:
        p = out / "runs" / "one_frame" / name / "units.json"
        if p.is_file():
            reps[name] = json.loads(p.read_text())
    rows = []
    lengths = sorted({u["unit"] for r in reps.values() for u in r["units"]})
    for L in lengths:
        row = {"unit": L}
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
        m = "videoreloc" if v == (True, True, True) else ablation_name(v)
        if m not in res["methods"]:
            continue
        modes = res["methods"][m]["modes"]
        row = {"orientation_aware": v[0], "run_level": v[1], "adaptive": v[2]}
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


def size_text(n) -> str:
    if n is None:
        return "-"
    if n < 1024 * 1024:
        return f"{n / 1024:.0f} kB"
    return f"{n / 1024 / 1024:.1f} MB"


def _label(row: dict) -> str:
    return row["label"] + ("†" if row["dagger"] else "")


def main_table(res: dict) -> tuple[str, list[dict]]:
    n_tours = len(res["tours"])
    frames = sum(t["frames"] for t in res["tours"].values())
    det = res.get("detector")
    lines = [f"**{table_title('main')}** ({n_tours} query tours, {frames} frames"
             f"{f'; detections: {det}' if det else ''})", "",
             "| Method | Map size | Pos. / rot. | 1 m/10° | 0.25 m/5° | Coverage | Frames evaluated |",
             "|---|---|---|---|---|---|---|"]
    rows = []
    for r in res["rows"]:
        m = res["methods"][r["method"]]
        a = m["modes"][r["mode"]]["all"]
        med = ("-" if a["median_pos_m"] is None else f"{100 * a['median_pos_m']:.0f} cm / {a['median_rot_deg']:.1f}°")
        lines.append(f"| {_label(r)} | {size_text(m['map_bytes'])} | {med} | {pct(a['recall_1m_10deg'])} | "
                     f"{pct(a['recall_25cm_5deg'])} | {pct(a['coverage'])} | {a['frames']} |")
        rows.append({"key": r["key"], "label": _label(r), "map_bytes": m["map_bytes"], **a})
    lines += ["", "Recall (%) over all evaluated frames, a frame without a pose counts as a failure; median errors "
              "over returned poses. † clip-rigid control: VideoReloc's clip partition and within-clip odometry, "
              "one clip-to-map transform per clip at clip closure, no cross-clip back-end. Per-frame appearance "
              "is evaluated on the frames with RGB, the one-frame unit on every "
              f"{res['one_frame_stride']}th frame."]
    ext = [m for m in res["methods"].values() if m.get("external")]
    if ext:
        lines[-1] += (" External methods: a command on exported tours is evaluated on the frames its export holds "
                      "(those with RGB), trajectories on every frame; their map size is what map_command wrote.")
    maps = res.get("maps") or {}
    for k, label in (("boxes", f"Box map built with the {res.get('detector') or 'oracle'} detector"),
                     ("boxes_oracle", "Box map built from oracle detections")):
        if k in maps:
            lines += ["", map_line(label, maps[k])]
    return "\n".join(lines), rows


def factors_table(res: dict) -> tuple[str, list[dict]]:
    lights = [x for x in LIGHTINGS if any(t["lighting"] == x for t in res["tours"].values())]

    def line(cells) -> str:
        return "| " + " | ".join(cells) + " |"

    head = ["Method", *lights, "ΔL", "unchanged", "rearranged", "ΔR", "kept"]
    lines = [f"**{table_title('factors')}**", "", line(head), "|---" * len(head) + "|"]
    rows = []
    for r in res["rows"]:
        f = res["methods"][r["method"]]["modes"][r["mode"]]["factors"]
        kept = "-" if f["kept"] is None else f"{100 * f['kept']:.0f} %"
        lines.append(line([_label(r), *(pct(f[x]) for x in lights), pct(f["delta_L"], True), pct(f["unchanged"]),
                           pct(f["rearranged"]), pct(f["delta_R"], True), kept]))
        rows.append({"key": r["key"], "label": _label(r), **f})
    lines += ["", "Recall (%); lighting columns average the layouts, unchanged/rearranged average the tours. "
              "ΔL = night - day and ΔR = rearranged - unchanged (points); kept = rearranged / unchanged."]
    return "\n".join(lines), rows


def units_table(res: dict) -> tuple[str, list[dict]]:
    lines = [f"**{table_title('units')}**", "",
             "| Unit | 1 m/10° | 0.25 m/5° | unchanged 1 m/10° | rearranged 1 m/10° |", "|---|---|---|---|---|"]
    for u in res["units"]:
        name = "one frame" if u["unit"] == 1 else f"{u['unit']}-frame clip"
        if u["unit"] == 1 and (u.get("sampled_every") or 1) > 1:
            name += f" (every {u['sampled_every']}th frame)"
        lines.append(f"| {name} | {pct(u['all_recall_1m_10deg'])} | {pct(u['all_recall_25cm_5deg'])} | "
                     f"{pct(u['unchanged_recall_1m_10deg'])} | {pct(u['rearranged_recall_1m_10deg'])} |")
    lines += ["", "Each unit is registered independently, without tracking or a pose graph; recall (%) over all "
              "frames, measured when the unit closes."]
    return "\n".join(lines), res["units"]


def ablation_table(res: dict) -> tuple[str, list[dict]]:
    ck = lambda b: "✓" if b else ""  # noqa: E731
    lines = [f"**{table_title('ablation')}**", "",
             "| orientation-aware | run-level | adaptive | closure 1 m/10° | closure 0.25 m/5° | causal 1 m/10° | "
             "causal 0.25 m/5° |", "|---|---|---|---|---|---|---|"]
    for a in res["ablation"]:
        lines.append(f"| {ck(a['orientation_aware'])} | {ck(a['run_level'])} | {ck(a['adaptive'])} | "
                     f"{pct(a['closure_coarse'])} | {pct(a['closure_fine'])} | {pct(a['causal_coarse'])} | "
                     f"{pct(a['causal_fine'])} |")
    lines += ["", "Recall (%) over all frames. Empty cells: point-to-point refinement, no run-level decision, "
              "fixed 100-frame clips. Tracking and the pose graph stay on."]
    return "\n".join(lines), res["ablation"]


def make_tables(res: dict) -> dict[str, tuple[str, list]]:
    t = {"main": main_table(res), "factors": factors_table(res)}
    if res.get("units"):
        t["units"] = units_table(res)
    if res.get("ablation"):
        t["ablation"] = ablation_table(res)
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
        number, caption = PAPER_TABLES[name]
        write_text_atomic(d / f"{name}.md", md + "\n")
        write_json_atomic(d / f"{name}.json", {"table": number, "title": caption, "rows": rows})
    for stale in d.glob("*.md"):  # a table no longer asked for
        if stale.stem not in made:
            stale.unlink()
            stale.with_suffix(".json").unlink(missing_ok=True)


def format_all(out: Path) -> str:
    res = json.loads((Path(out) / "results.json").read_text())
    return "\n\n".join(md for md, _ in make_tables(res).values())
