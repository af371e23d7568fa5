"""Dose-response sweeps in experiments (reloc.experiments.sweep).

The figures are checked on a results dict built here, whose per-segment counts are known by
construction (a method that gets every frame at level 0 and fewer at each level), so each level's
recall, its ratio to level 0 and the breaking point can be written down by hand; the spec's
``sweep`` section is checked for its one-line errors.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from vrformats.errors import SceneFormatError
from reloc.experiments.checks import metric_table
from reloc.experiments.sweep import breaking_metrics, parse_sweep, plot_sweep, sweep_table
from reloc.experiments.sweep import compute_sweep as _compute
from reloc.experiments.tables import bootstrap_of


def compute_sweep(res, sweep):
    return _compute(res, sweep, bootstrap_of(res))

LEVELS = {0: "L0", 0.5: "L50", 1.0: "L100"}


def _results(rates: dict) -> dict:
    """Two methods on three layouts (one tour each, 10 segments of 100 frames): at each level
    ``rates[method][level]`` of every segment's frames are within 1 m / 10 deg."""
    tours = {f"{v}__day__query": {"layout": v, "lighting": "day", "path": "query", "sensor": "ideal"}
             for v in LEVELS.values()}
    methods = {}
    for m, by_level in rates.items():
        units = {}
        for lv, v in LEVELS.items():
            ok = int(round(100 * by_level[lv]))
            units[f"{v}__day__query"] = [[100, ok, ok, 100]] * 10
        methods[m] = {"label": m, "primary": "closure", "modes": {"closure": {"units": units, "all": {}, "factors": {}}}}
    return {"tours": tours, "methods": methods, "reference_sensor": "ideal",
            "intervals": {"settings": {"resamples": 200}},
            "rows": [{"key": f"{m}.closure", "label": m.upper(), "method": m, "mode": "closure"} for m in rates]}


def test_levels_ratios_and_breaking_points_from_known_counts(tmp_path):
    sweep = parse_sweep({"factor": "rearrangement", "levels": LEVELS, "fraction": 0.8}, "s.yaml")
    res = _results({"strong": {0: 0.9, 0.5: 0.85, 1.0: 0.8}, "weak": {0: 0.9, 0.5: 0.6, 1.0: 0.3}})
    res["sweep"] = compute_sweep(res, sweep)
    strong, weak = res["sweep"]["runs"]["strong.closure"], res["sweep"]["runs"]["weak.closure"]
    assert [r["recall"] for r in weak["levels"]] == pytest.approx([0.9, 0.6, 0.3])
    assert [r["ratio"] for r in weak["levels"]] == pytest.approx([1.0, 2 / 3, 1 / 3])
    assert weak["breaking_point"] == 0.5 and strong["breaking_point"] is None  # 0.8/0.9 = 0.89 holds
    assert weak["levels"][1]["ci"] == pytest.approx([0.6, 0.6])  # every segment alike: no spread
    m = metric_table(res)
    assert m["weak.breaking_point.rearrangement"] == 0.5 and m["strong.breaking_point.rearrangement"] == math.inf
    assert m["weak.closure.sweep.1"] == pytest.approx(0.3) and breaking_metrics(res)["weak.sweep.0.5"] == pytest.approx(0.6)
    md, rows = sweep_table(res)
    assert "| WEAK | 90.0 [90.0, 90.0] | 60.0 [60.0, 60.0] | 30.0 [30.0, 30.0] | 0.5 [0.5, 0.5] |" in md
    assert m["weak.breaking_point.rearrangement.lo"] == 0.5 and m["strong.breaking_point.rearrangement.hi"] == math.inf
    assert "| STRONG |" in md and "none (holds)" in md and len(rows) == 2
    plot_sweep(res, tmp_path / "sweep.png")
    assert (tmp_path / "sweep.png").stat().st_size > 5000


def test_a_method_at_zero_on_the_reference_level_is_broken_there_not_holding(tmp_path):
    """No recall at level 0 leaves no ratio to level 0: the method is broken from the start, which
    the table, the figures and the checks must say (not "none (holds)", not infinity)."""
    sweep = parse_sweep({"factor": "rearrangement", "levels": LEVELS, "fraction": 0.8}, "s.yaml")
    res = _results({"dead": {0: 0.0, 0.5: 0.0, 1.0: 0.0}, "ok": {0: 0.9, 0.5: 0.85, 1.0: 0.8}})
    res["sweep"] = compute_sweep(res, sweep)
    dead = res["sweep"]["runs"]["dead.closure"]
    assert (dead["breaking_point_lo"], dead["breaking_point"], dead["breaking_point_hi"]) == (0, 0, 0)
    m = metric_table(res)
    assert m["dead.breaking_point.rearrangement"] == 0 and m["ok.breaking_point.rearrangement"] == math.inf
    md, _ = sweep_table(res)
    dead_row = next(line for line in md.splitlines() if line.startswith("| DEAD |"))
    assert "holds" not in dead_row and "no recall at level 0" in dead_row, dead_row
    assert "none (holds)" in next(line for line in md.splitlines() if line.startswith("| OK |"))


def test_a_noisy_level_has_an_interval_that_holds_its_recall():
    sweep = parse_sweep({"factor": "rearrangement", "levels": LEVELS}, "s.yaml")
    res = _results({"m": {0: 0.9, 0.5: 0.6, 1.0: 0.3}})
    rng = np.random.default_rng(0)
    res["methods"]["m"]["modes"]["closure"]["units"]["L50__day__query"] = [
        [100, int(k), int(k), 100] for k in rng.integers(20, 100, 10)]
    run = compute_sweep(res, sweep)["runs"]["m.closure"]
    out = run["levels"][1]
    assert out["ci"][0] < out["recall"] < out["ci"][1] and out["ratio_ci"][0] < out["ratio"] < out["ratio_ci"][1]
    # the breaking point's bounds: the first level whose ratio interval reaches below 80 %, and the
    # first whose whole interval is below it
    lo = next(r["level"] for r in run["levels"] if r["ratio_ci"][0] < 0.8)
    hi = next(r["level"] for r in run["levels"] if r["ratio_ci"][1] < 0.8)
    assert (run["breaking_point_lo"], run["breaking_point"], run["breaking_point_hi"]) == (lo, 0.5, hi)
    assert lo <= 0.5 <= hi


@pytest.mark.parametrize("doc, field", [
    ({"factor": "furniture", "levels": LEVELS}, "sweep.factor"),
    ({"factor": "rearrangement", "levels": {0: "L0"}}, "sweep.levels"),
    ({"factor": "rearrangement", "levels": {0: "L0", -1: "L50"}}, "sweep.levels.-1"),
    ({"factor": "rearrangement", "levels": {0: "L0", 0.5: "L0"}}, "sweep.levels"),
    ({"factor": "rearrangement", "levels": LEVELS, "fraction": 1.2}, "sweep.fraction"),
    ({"factor": "rearrangement", "levels": LEVELS, "step": 1}, "sweep.step"),
    ([1, 2], "sweep"),
])
def test_bad_sweeps_name_the_file_and_key(doc, field):
    with pytest.raises(SceneFormatError) as e:
        parse_sweep(doc, "exp.yaml")
    assert e.value.field == field and str(e.value).startswith("exp.yaml: ")


def test_an_experiment_spec_with_a_sweep_is_refused_in_one_line_before_anything_runs(tmp_path, capsys):
    """A sweep level whose tours the design lacks, and a sensor level that is not one of the
    experiment's sensors: exit 2, one line naming the key, no output folder."""
    import yaml

    from reloc.cli import main as reloc_main
    from reloc.resources import experiment_spec

    doc = yaml.safe_load(experiment_spec("sweep_rearrangement_experiment").read_text())
    doc["out"] = str(tmp_path / "exp")
    doc["render"] = str(experiment_spec("sweep_rearrangement_experiment").parents[1].parent / "render_jobs" /
                        "sweep_rearrangement.yaml")
    doc["sweep"] = {"factor": "sensor", "levels": {0: "ideal", 1: "structured_light"}}
    f = tmp_path / "e.yaml"
    f.write_text(yaml.safe_dump(doc))
    assert reloc_main(["experiment", str(f)]) == 2
    err = capsys.readouterr().err.strip()
    assert "sweep.levels.1" in err and "structured_light" in err and len(err.splitlines()) == 1
    assert not (tmp_path / "exp").exists()


def test_every_shipped_sweep_check_can_fail(tmp_path, capsys):
    """reloc/specs/sweep_checks.yaml on constructed results: all pass where VideoReloc holds and the
    baselines break early, and every one fails in the opposite world, so none is a check that no
    result could fail."""
    import json

    from reloc.cli import main as reloc_main
    from reloc.resources import check_spec

    levels = {0: "L0", 0.25: "L25", 0.5: "L50", 0.75: "L75", 1.0: "L100", 1.25: "LB"}
    holds = {lv: 0.9 for lv in levels}
    breaks = {lv: (0.9 if lv == 0 else 0.2) for lv in levels}

    def world(vr, base) -> dict:
        tours = {f"{v}__day__query": {"layout": v, "lighting": "day", "path": "query", "sensor": "ideal"}
                 for v in levels.values()}
        methods = {}
        for m, primary, rates in (("videoreloc", "closure", vr), ("videoreloc_oracle", "closure", vr),
                                  ("fpfh_icp", "closure", base), ("appearance", "causal", base)):
            units = {f"{v}__day__query": [[100, int(100 * rates[lv]), 0, 100]] * 10 for lv, v in levels.items()}
            methods[m] = {"label": m, "primary": primary, "modes": {primary: {"units": units, "all": {}, "factors": {}}}}
        res = {"format": "videoreloc-experiment/1", "tours": tours, "methods": methods, "reference_sensor": "ideal",
               "intervals": {"settings": {"resamples": 200}}, "rows": []}
        res["sweep"] = compute_sweep(res, parse_sweep({"factor": "rearrangement", "levels": levels}, "s.yaml"))
        return res

    checks = check_spec("sweep_checks")
    n = len(__import__("yaml").safe_load(checks.read_text())["checks"])
    for name, res, want in (("good", world(holds, breaks), 0), ("bad", world(breaks, holds), 1)):
        d = tmp_path / name
        d.mkdir()
        (d / "results.json").write_text(json.dumps(res))
        assert reloc_main(["check", str(checks), str(d)]) == want
        out = capsys.readouterr().out
        assert (f"{n} passed, 0 failed" if want == 0 else f"0 passed, {n} failed") in out, out


def test_a_check_on_a_figure_the_design_cannot_have_says_so(tmp_path, capsys):
    """A day-only design has no night-minus-day loss: ``reloc check`` must say the design lacks it
    (which lightings it needs), not advise rerunning the experiment."""
    import json

    import yaml

    from reloc.cli import main as reloc_main
    from tests.cli_errors import one_line_error

    res = _results({"videoreloc": {0: 0.9, 0.5: 0.85, 1.0: 0.8}})  # three layouts, all by day
    (tmp_path / "exp").mkdir()
    (tmp_path / "exp" / "results.json").write_text(json.dumps(res))
    checks = tmp_path / "checks.yaml"
    checks.write_text(yaml.safe_dump({"checks": ["videoreloc.delta_L.lo >= -0.45"]}))
    assert reloc_main(["check", str(checks), str(tmp_path / "exp")]) == 2
    line = one_line_error(capsys, "checks.yaml", "checks[0]", "delta_L", "night")
    assert "rerun" not in line and "predate" not in line, line
