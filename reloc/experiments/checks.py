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
* ``METHOD[.MODE].KEY.spread`` (an experiment with ``replicates: N``): the highest minus the lowest
  value of a pooled figure or factor across the replicates;
* a sweep (an experiment with ``sweep:``, :mod:`reloc.experiments.sweep`):
  ``METHOD[.MODE].breaking_point.FACTOR``, the lowest level whose recall falls below the sweep's
  fraction of level 0's (infinity when the method holds at every level), and
  ``METHOD[.MODE].sweep.LEVEL``, the recall at 1 m/10 deg at that level;
* ``METHOD.map_bytes``;
* ``map.KEY`` (the box map built with the experiment's detector) and ``map_oracle.KEY`` (built
  from oracle detections), against the mapping layout's ground truth: built, gt, matched, missing,
  extra, class_errors, and ``map.KIND.KEY`` with KIND object, wall, floor, ceiling and KEY matched,
  median_center_err_m, median_size_err_max_m, median_yaw_err_deg.

Intervals (:mod:`reloc.experiments.intervals`): recall, coverage and Table II's figures carry a 95 %
interval; ``NAME.lo`` and ``NAME.hi`` are its bounds, so that a check can ask for the whole interval
(``videoreloc.closure.recall_1m_10deg.lo >= 0.60``: the lower bound). A comparison of two such
figures (``videoreloc.closure.recall_1m_10deg > appearance.causal.recall_1m_10deg``) is decided on
the interval of their paired difference (the same resampled path segments): ``A > B`` passes when
the difference's lower bound is above 0, ``A >= B`` when it is not below 0, ``A < B`` and ``A <= B``
likewise on the upper bound; ``==`` and ``!=`` compare the point values. ``A >= B - 0.10`` (an offset
after the second metric) moves that 0: the difference's lower bound must not be below -0.10 (A at
most 10 points under B, decided on the paired difference). A plain ``NAME`` against a
number is its point value.

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

from vrformats.errors import SceneFormatError, UserError
from vrformats.fields import clean_name, shown
from vrformats.cli import add_json

from .tables import FACTOR_KEYS, METRICS, interval_figures, read_results

OPS = {">=": operator.ge, "<=": operator.le, ">": operator.gt, "<": operator.lt, "==": operator.eq, "!=": operator.ne}
_EXPR = re.compile(r"^\s*([A-Za-z0-9_.@\-]+)\s*(>=|<=|==|!=|>|<)\s*([A-Za-z0-9_.@\-+eE]+?)"
                   r"(?:\s+([+-])\s*([0-9.]+(?:[eE][+-]?[0-9]+)?))?\s*$")


@dataclass
class Check:
    text: str
    name: str
    left: str
    op: str
    right: str  # a number or a metric name
    offset: float = 0.0  # 'A >= B - 0.10': B's value plus this (for two figures: the bound their difference is compared to)


CHECK_SPEC_KEYS = {"checks", "description"}


def parse_checks(path) -> list[Check]:
    from vrformats.yamlfile import read_yaml

    from ..resources import check_spec

    p = check_spec(path)  # a file, or a shipped name (reloc/specs: demo_checks)
    if not p.is_file():
        raise UserError(f"{p}: check file not found")
    doc = read_yaml(p)
    if isinstance(doc, dict):
        unknown = sorted(map(str, set(doc) - CHECK_SPEC_KEYS))
        if unknown:  # as render and experiment specs do: a misspelt key must not pass silently
            raise SceneFormatError(p, unknown[0], f"unknown key; allowed: {', '.join(sorted(CHECK_SPEC_KEYS))}")
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
            raise SceneFormatError(p, field, f"expected an assertion like 'videoreloc.kept >= 0.75', got {shown(it)}")
        m = _EXPR.match(it)
        if not m:
            raise SceneFormatError(p, field, f"cannot parse {shown(it)}: expected METRIC OP VALUE with OP one of "
                                   f"{', '.join(OPS)}")
        try:
            bound = float(m.group(3))
        except ValueError:
            bound = None  # a metric name
        if bound is not None and not math.isfinite(bound):  # '!= nan' would always pass, '>= nan' always fail
            raise SceneFormatError(p, field, f"{shown(it)}: the bound must be a finite number, got {m.group(3)}")
        if name is not None and not isinstance(name, str):
            raise SceneFormatError(p, f"{field}.name", f"expected text, got {shown(name)}")
        offset = 0.0
        if m.group(4):
            if bound is not None:
                raise SceneFormatError(p, field, f"{shown(it)}: an offset ('- 0.10') follows a metric, not a number")
            offset = float(m.group(5)) * (-1.0 if m.group(4) == "-" else 1.0)
            if not math.isfinite(offset):
                raise SceneFormatError(p, field, f"{shown(it)}: the offset must be a finite number")
        out.append(Check(it.strip(), clean_name(str(name or it.strip()), p, f"{field}.name"), m.group(1), m.group(2), m.group(3),
                         offset))
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
    for key, figs in ((results.get("replicates") or {}).get("figures") or {}).items():  # replicates: N
        m, mode = key.split(".", 1)
        primary = results["methods"].get(m, {}).get("primary") == mode
        for k, st in figs.items():
            if k != "tours":
                vals[f"{key}.{k}.spread"] = st["spread"]
                if primary:
                    vals[f"{m}.{k}.spread"] = st["spread"]
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
    from .sweep import breaking_metrics

    vals.update(breaking_metrics(results))
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


def figure_table(results: dict) -> dict[str, tuple[str, tuple]]:
    """Every metric name that carries an interval -> (run key ``METHOD.MODE``, figure), named as
    ``metric_table`` names them, from ``tables.interval_figures``."""
    out: dict = {}
    for key, parts in interval_figures(results).items():
        m, mode = key.split(".", 1)
        named = {**parts["all"], **parts["factors"],
                 **{f"sensor.{s}.{k}": f for s, figs in parts.get("sensors", {}).items() for k, f in figs.items()}}
        primary = results["methods"][m].get("primary") == mode
        for k, f in named.items():
            out[f"{key}.{k}"] = (key, f)
            if primary:
                out[f"{m}.{k}"] = (key, f)
        for tour, figs in parts["tours"].items():
            for k, f in figs.items():
                out[f"{key}.{tour}.{k}"] = (key, f)
    return out


# What a factor figure compares, for the message when a design has no tours to compute it from
FACTOR_NEEDS = {"day": "day", "evening": "evening", "night": "night", "delta_L": "day and night",
                "unchanged": "unchanged-layout", "rearranged": "rearranged-layout",
                "delta_R": "unchanged-layout and rearranged-layout", "kept": "unchanged-layout and rearranged-layout"}


def design_lacks(name: str) -> str:
    """Why a design has no value for metric ``name``: the query tours it needs, for a factor figure."""
    factor = name.rsplit(".", 1)[-1]
    if factor in FACTOR_NEEDS:
        return f"{factor} needs {FACTOR_NEEDS[factor]} query tours, which its design lacks (check a figure the design has)"
    return "its design or its runs give no value for it"


class _Resolver:
    """Values of a check's tokens: numbers, metrics, ``METRIC.lo``/``.hi`` bounds and, for two figures
    with intervals, their paired difference."""

    def __init__(self, results: dict, path: Path):
        self.results, self.path = results, path
        self.vals = metric_table(results)
        self.figs = figure_table(results)
        self._boot = None

    @property
    def boot(self):
        if self._boot is None:
            from .tables import bootstrap_of

            self._boot = bootstrap_of(self.results)
        return self._boot

    def _name(self, token: str, field: str) -> str:
        if token not in self.vals:
            close = difflib.get_close_matches(token, list(self.vals), n=2)
            hint = f"; did you mean {' or '.join(close)}?" if close else ""
            raise SceneFormatError(self.path, field, f"unknown metric {token!r}{hint}")
        return token

    def resamples(self, name: str):
        key, fig = self.figs[name]
        from .intervals import figure_values

        return figure_values(self.boot, key, fig)[1]

    def value(self, token: str, field: str) -> tuple[float | None, list | None, str | None]:
        """(value, interval of the value or None, figure name when it has an interval)."""
        try:
            return float(token), None, None
        except ValueError:
            pass
        base, _, bound = token.rpartition(".")
        if bound in ("lo", "hi") and base and token not in self.vals:
            name = self._name(base, field)
            if name not in self.figs:
                if self.vals[name] is None:
                    raise SceneFormatError(self.path, field, f"{token!r}: this experiment has no {name}: "
                                           f"{design_lacks(name)}")
                raise SceneFormatError(self.path, field, f"{token!r}: {name} has no interval (recall, coverage and "
                                       "Table II's figures have one; rerun reloc experiment if these results predate them)")
            iv = self.boot.interval(self.resamples(name))
            return (None if iv is None else iv[0 if bound == "lo" else 1]), iv, None
        name = self._name(token, field)
        v = self.vals[name]
        v = None if v is None or (isinstance(v, float) and math.isnan(v)) else float(v)
        return v, None, (name if name in self.figs else None)


def run_checks(check_file, results_dir) -> list[dict]:
    checks = parse_checks(check_file)
    results = read_results(results_dir)
    r = _Resolver(results, Path(check_file))
    rows = []
    for i, c in enumerate(checks):
        field = f"checks[{i}]"
        a, a_iv, a_fig = r.value(c.left, field)
        b, b_iv, b_fig = r.value(c.right, field)
        if b is not None:
            b = b + c.offset
        interval, on, margin = a_iv or b_iv, None, None
        if a_fig and b_fig and c.op not in ("==", "!="):  # two figures: their paired difference decides
            interval = r.boot.interval(r.resamples(a_fig) - r.resamples(b_fig))
            on = "difference"
            if interval is None or a is None or b is None:
                ok = False
            else:
                bound = interval[0] if c.op in (">", ">=") else interval[1]
                ok = OPS[c.op](bound, c.offset)
                margin = bound - c.offset if c.op in (">", ">=") else c.offset - bound
        else:
            ok = a is not None and b is not None and OPS[c.op](a, b)
            if a is not None and b is not None and c.op not in ("==", "!="):
                margin = (a - b) if c.op in (">", ">=") else (b - a)
        # margin: how far the deciding quantity (the value, or the difference's interval bound) lies from
        # where the check would flip, positive on the passing side, in the check's own units
        rows.append({"check": c.name, "expression": c.text, "value": a, "against": b, "interval": interval,
                     "interval_of": on or ("value" if interval else None), "passed": bool(ok), "margin": margin,
                     "why": None if ok else ("no value" if a is None or b is None or (on and interval is None)
                                             else ("the interval of the difference does not exclude it" if on
                                                   else "false"))})
    return rows


def _fmt(v) -> str:
    return "-" if v is None else f"{v:.4g}"


def _fmt_iv(r: dict) -> str:
    iv = r.get("interval")
    if iv is None:
        return "-"
    text = f"[{iv[0]:.3g}, {iv[1]:.3g}]"
    return f"diff {text}" if r.get("interval_of") == "difference" else text


def format_checks(rows: list[dict]) -> str:
    w = max(len(r["check"]) for r in rows)
    wi = max(8, *(len(_fmt_iv(r)) for r in rows))
    lines = [f"{'check':<{w}}  {'value':>9}  {'against':>9}  {'interval':<{wi}}  result"]
    for r in rows:
        res = "pass" if r["passed"] else f"FAIL ({r['why']})"
        lines.append(f"{r['check']:<{w}}  {_fmt(r['value']):>9}  {_fmt(r['against']):>9}  {_fmt_iv(r):<{wi}}  {res}")
    n_fail = sum(not r["passed"] for r in rows)
    lines.append(f"{len(rows) - n_fail} passed, {n_fail} failed")
    return "\n".join(lines)


def failure_message(r: dict) -> str:
    """A failed check in one line: its expression, the value, the bound and the interval that decided."""
    iv = _fmt_iv(r)
    return (f"{r['expression']}: value {_fmt(r['value'])}, against {_fmt(r['against'])}"
            + ("" if iv == "-" else f", interval {iv}") + f" ({r['why']})")


def junit_xml(rows: list[dict], suite: str, results_dir, seconds: float = 0.0) -> str:
    """The checks as JUnit XML, the report CI servers read: one ``testsuite`` named ``reloc.check.SUITE``,
    one ``testcase`` per check (its name the check's, classname the suite), a ``failure`` for a failed
    check whose message carries the value, the bound and the interval; properties name the results."""
    import datetime
    import socket
    import xml.etree.ElementTree as ET

    fails = [r for r in rows if not r["passed"]]
    ts = ET.Element("testsuite", {
        "name": f"reloc.check.{suite}", "tests": str(len(rows)), "failures": str(len(fails)), "errors": "0",
        "skipped": "0", "time": f"{seconds:.3f}", "hostname": socket.gethostname(),
        "timestamp": datetime.datetime.now(datetime.timezone.utc).replace(microsecond=0).isoformat()})
    props = ET.SubElement(ts, "properties")
    ET.SubElement(props, "property", {"name": "results", "value": str(results_dir)})
    for r in rows:
        tc = ET.SubElement(ts, "testcase", {"classname": f"reloc.check.{suite}", "name": r["check"], "time": "0"})
        if not r["passed"]:
            f = ET.SubElement(tc, "failure", {"message": failure_message(r), "type": "CheckFailed"})
            f.text = json.dumps({k: r[k] for k in ("expression", "value", "against", "interval", "interval_of", "why")})
        else:
            out = ET.SubElement(tc, "system-out")
            out.text = f"{r['expression']}: value {_fmt(r['value'])}, against {_fmt(r['against'])}, interval {_fmt_iv(r)}"
    suites = ET.Element("testsuites", {"name": "reloc check", "tests": str(len(rows)), "failures": str(len(fails)),
                                       "errors": "0", "time": f"{seconds:.3f}"})
    suites.append(ts)
    ET.indent(suites)
    return '<?xml version="1.0" encoding="utf-8"?>\n' + ET.tostring(suites, encoding="unicode") + "\n"




def record_checks(rows: list[dict], check_file, results_dir) -> Path | None:
    """Record the rows in ``RESULTS_DIR/results.json`` (``checks``: the check spec and the rows) and rewrite
    the report with them where the folder has one (``report.write_report``). A rerun of the experiment
    writes results.json anew, so checks never outlive the results they judged. A folder that cannot be
    written to, or whose experiment is running (its lock), is one line on stderr: the checks' own exit
    status does not change."""
    import sys

    from vrformats.atomic import write_json_atomic
    from vrformats.lifetime import folder_lock

    results_dir = Path(results_dir)
    target = results_dir / "results.json"
    try:
        with folder_lock(results_dir, "reloc check"):
            results = read_results(results_dir)
            results["checks"] = {"file": str(check_file), "rows": rows}
            write_json_atomic(target, results)
            if (results_dir / "report.md").is_file():
                from .report import write_report

                write_report(results_dir)
        return target
    except (OSError, UserError) as e:
        why = e.strerror if isinstance(e, OSError) and e.strerror else str(e)
        print(f"reloc check: the checks were not recorded in {target} ({why}); the report keeps no record of them",
              file=sys.stderr)
        return None


def cmd_check(args) -> int:
    import time

    from vrformats.atomic import write_text_atomic
    from vrformats.errors import check_output_file

    from ..resources import check_spec

    if args.junit:
        check_output_file(args.junit)
    t0 = time.perf_counter()
    rows = run_checks(args.checks, args.results)
    if args.junit:
        write_text_atomic(args.junit, junit_xml(rows, Path(args.checks).stem, args.results, time.perf_counter() - t0))
    record_checks(rows, check_spec(args.checks), args.results)
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
    p.add_argument("--junit", metavar="FILE.xml", help="also write the checks as JUnit XML (one testcase per check) for a CI server")
    p.set_defaults(fn=cmd_check)
