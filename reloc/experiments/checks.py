"""``reloc check CHECKS.yaml RESULTS_DIR``: pass/fail robustness assertions on experiment results.

A check file lists assertions; each compares a metric with a number or with another metric::

    checks:
      - videoreloc.closure.recall_1m_10deg >= 0.85
      - videoreloc.delta_L >= -0.03              # the method's primary cutoff (closure for VideoReloc)
      - videoreloc.kept >= 0.75
      - videoreloc.closure.recall_1m_10deg > appearance.causal.recall_1m_10deg
      - {check: "appearance.delta_L < 0", name: "appearance suffers at night"}

Metric names (values are fractions, as in ``results.json``):

* ``METHOD.MODE.KEY``: KEY is recall_1m_10deg, recall_25cm_5deg, median_pos_m, median_rot_deg,
  coverage (pooled over the query tours) or a factor: day, evening, night, delta_L, unchanged,
  rearranged, delta_R, kept (Table II, recall at 1 m/10 deg);
* ``METHOD.KEY``: the same at the method's primary cutoff (videoreloc: closure, fpfh_icp: closure,
  appearance: causal, one_frame: causal);
* ``METHOD.MODE.TOUR.KEY``: one query tour (``videoreloc.closure.apt_1__night__query.coverage``; a
  tour read through a sensor other than ideal is ``TOUR@SENSOR``);
* sensors (an experiment with ``sensors:``): ``METHOD[.MODE].sensor.S`` (recall at 1 m/10 deg over
  sensor S's query tours, a mean over tours, as Table II) and ``METHOD[.MODE].sensor.S.delta`` (that
  minus the reference sensor's); ``METHOD[.MODE].sensor.S.KEY`` with KEY one of the pooled metrics
  above; ``sensor.S.KEY`` for VideoReloc's odometry under S: drift_pct, drift_deg_per_m,
  median_drift_pct, clips_per_100m, odometry_failures (clips that ended on a failed odometry gate),
  odometry_failure_fraction (of all clip ends), no_usable_depth;
* ``METHOD.map_bytes``;
* ``map.KEY`` (the box map built with the experiment's detector) and ``map_oracle.KEY`` (built
  from oracle detections), against the mapping layout's ground truth: built, gt, matched, missing,
  extra, class_errors, and ``map.KIND.KEY`` with KIND object, wall, floor, ceiling and KEY matched,
  median_center_err_m, median_size_err_max_m, median_yaw_err_deg.

Prints a table; exit status 0 when every check passes, 1 when any fails (a metric without a value,
such as evening recall in a design without evening tours, fails), 2 when the check file or the
results are malformed (an unknown metric name is a malformed check).
"""

from __future__ import annotations

import difflib
import json
import math
import operator
import re
from dataclasses import dataclass
from pathlib import Path

from formats.errors import SceneFormatError, UserError
from formats.cli import add_json

from .tables import FACTOR_KEYS, METRICS, read_results

OPS = {">=": operator.ge, "<=": operator.le, ">": operator.gt, "<": operator.lt, "==": operator.eq, "!=": operator.ne}
_EXPR = re.compile(r"^\s*([A-Za-z0-9_.@\-]+)\s*(>=|<=|==|!=|>|<)\s*([A-Za-z0-9_.@\-+eE]+)\s*$")


@dataclass
class Check:
    text: str
    name: str
    left: str
    op: str
    right: str  # a number or a metric name


def parse_checks(path) -> list[Check]:
    from formats.yamlfile import read_yaml

    from ..resources import check_spec

    p = check_spec(path)  # a file, or a shipped name (reloc/specs: demo_checks)
    if not p.is_file():
        raise UserError(f"{p}: check file not found")
    doc = read_yaml(p)
    items = doc.get("checks") if isinstance(doc, dict) else doc
    if not isinstance(items, list) or not items:
        raise SceneFormatError(p, "checks", "expected a non-empty list of assertions like 'videoreloc.kept >= 0.75'")
    out = []
    for i, it in enumerate(items):
        field = f"checks[{i}]"
        name = None
        if isinstance(it, dict):
            unknown = sorted(set(it) - {"check", "name"})
            if unknown or "check" not in it:
                raise SceneFormatError(p, field, "expected {check: 'METRIC OP VALUE', name: ...}")
            name, it = it.get("name"), it["check"]
        if not isinstance(it, str):
            raise SceneFormatError(p, field, f"expected an assertion like 'videoreloc.kept >= 0.75', got {it!r}")
        m = _EXPR.match(it)
        if not m:
            raise SceneFormatError(p, field, f"cannot parse {it!r}: expected METRIC OP VALUE with OP one of "
                                   f"{', '.join(OPS)}")
        out.append(Check(it.strip(), str(name or it.strip()), m.group(1), m.group(2), m.group(3)))
    return out


def metric_table(results: dict) -> dict[str, float | None]:
    """Every metric name ``reloc check`` knows, with its value (None when the design lacks it)."""
    vals: dict[str, float | None] = {}
    for m, entry in results.get("methods", {}).items():
        vals[f"{m}.map_bytes"] = entry.get("map_bytes")
        for mode, d in entry.get("modes", {}).items():
            flat = {**{k: d["all"].get(k) for k in METRICS}, **{k: d["factors"].get(k) for k in FACTOR_KEYS},
                    **{k: v for k, v in d["factors"].items() if k.startswith("sensor.")},
                    **{f"sensor.{s}.{k}": summ.get(k) for s, summ in (d.get("sensors") or {}).items() for k in METRICS}}
            for k, v in flat.items():
                vals[f"{m}.{mode}.{k}"] = v
                if mode == entry.get("primary"):
                    vals[f"{m}.{k}"] = v
            for tour, s in d.get("tours", {}).items():
                for k in METRICS:
                    vals[f"{m}.{mode}.{tour}.{k}"] = s.get(k)
    for s, f in (results.get("sensor_figures") or {}).items():
        odo = f.get("odometry") or {}
        for k in ("drift_pct", "drift_deg_per_m", "median_drift_pct"):
            vals[f"sensor.{s}.{k}"] = odo.get(k)
        vals[f"sensor.{s}.clips_per_100m"] = f.get("clips_per_100m")
        ends = f.get("clip_ends") or {}
        n = sum(ends.values())
        vals[f"sensor.{s}.odometry_failures"] = ends.get("odometry failure")
        vals[f"sensor.{s}.no_usable_depth"] = ends.get("no usable depth")
        vals[f"sensor.{s}.odometry_failure_fraction"] = ends.get("odometry failure", 0) / n if n else None
    for key, name in (("boxes", "map"), ("boxes_oracle", "map_oracle")):
        q = (results.get("maps") or {}).get(key)
        if q is None:
            continue
        for k in ("built", "gt", "matched", "missing", "extra", "class_errors"):
            vals[f"{name}.{k}"] = q.get(k)
        for kind, e in q.get("by_kind", {}).items():
            for k in ("matched", "median_center_err_m", "median_size_err_max_m", "median_yaw_err_deg"):
                vals[f"{name}.{kind}.{k}"] = e.get(k)
    return vals


def _value(token: str, vals: dict, path: Path, field: str) -> float | None:
    try:
        return float(token)
    except ValueError:
        pass
    if token not in vals:
        close = difflib.get_close_matches(token, list(vals), n=2)
        hint = f"; did you mean {' or '.join(close)}?" if close else ""
        raise SceneFormatError(path, field, f"unknown metric {token!r}{hint}")
    v = vals[token]
    return None if v is None or (isinstance(v, float) and math.isnan(v)) else float(v)


def run_checks(check_file, results_dir) -> list[dict]:
    checks = parse_checks(check_file)
    results = read_results(results_dir)
    vals = metric_table(results)
    rows = []
    for i, c in enumerate(checks):
        a = _value(c.left, vals, Path(check_file), f"checks[{i}]")
        b = _value(c.right, vals, Path(check_file), f"checks[{i}]")
        ok = a is not None and b is not None and OPS[c.op](a, b)
        rows.append({"check": c.name, "expression": c.text, "value": a, "against": b, "passed": bool(ok),
                     "why": None if ok else ("no value" if a is None or b is None else "false")})
    return rows


def _fmt(v) -> str:
    return "-" if v is None else f"{v:.4g}"


def format_checks(rows: list[dict]) -> str:
    w = max(len(r["check"]) for r in rows)
    lines = [f"{'check':<{w}}  {'value':>9}  {'against':>9}  result"]
    for r in rows:
        res = "pass" if r["passed"] else f"FAIL ({r['why']})"
        lines.append(f"{r['check']:<{w}}  {_fmt(r['value']):>9}  {_fmt(r['against']):>9}  {res}")
    n_fail = sum(not r["passed"] for r in rows)
    lines.append(f"{len(rows) - n_fail} passed, {n_fail} failed")
    return "\n".join(lines)


def cmd_check(args) -> int:
    rows = run_checks(args.checks, args.results)
    if args.json:
        print(json.dumps(rows, indent=2))
    else:
        print(format_checks(rows))
    return 0 if all(r["passed"] for r in rows) else 1


def register_cli(subparsers) -> None:
    p = subparsers.add_parser("check", help="pass/fail robustness checks on experiment results (exit 1 on a failure)")
    p.add_argument("checks", metavar="CHECKS.yaml", help="check spec, or a shipped name (reloc/specs: demo_checks, ...)")
    p.add_argument("results", metavar="RESULTS_DIR", help="a reloc experiment results folder")
    add_json(p, "the table of checks")
    p.set_defaults(fn=cmd_check)
