"""``reloc check --junit``: the checks as JUnit XML, read back by junitparser (the parser CI report
tools such as publish-unit-test-result build on), on a results folder whose figures are known by
construction (tests.reloc.experiments.test_sweep's results: every segment alike, so each interval
is its point)."""

from __future__ import annotations

import json

import pytest
import yaml

from reloc.cli import main as reloc_main
from tests.reloc.experiments.test_sweep import _results

junitparser = pytest.importorskip("junitparser")


def _exp(tmp_path):
    res = _results({"videoreloc": {0: 0.9, 0.5: 0.85, 1.0: 0.8}})  # recall (0.9 + 0.85 + 0.8) / 3 = 0.85
    (tmp_path / "exp").mkdir()
    (tmp_path / "exp" / "results.json").write_text(json.dumps(res))
    return tmp_path / "exp"


def test_junit_has_one_testcase_per_check_and_failures_carry_value_bound_and_interval(tmp_path, capsys):
    exp = _exp(tmp_path)
    spec = tmp_path / "ci_checks.yaml"
    spec.write_text(yaml.safe_dump({"checks": [
        {"name": "recall holds", "check": "videoreloc.recall_1m_10deg.lo >= 0.80"},
        {"name": "recall too high a bar", "check": "videoreloc.recall_1m_10deg.lo >= 0.90"},
        "videoreloc.day.lo >= 0.5"]}))
    report = tmp_path / "reports" / "checks.xml"
    report.parent.mkdir()
    assert reloc_main(["check", str(spec), str(exp), "--junit", str(report)]) == 1
    table = capsys.readouterr().out
    assert "2 passed, 1 failed" in table
    xml = junitparser.JUnitXml.fromfile(str(report))
    suites = list(xml) if isinstance(xml, junitparser.JUnitXml) else [xml]
    assert len(suites) == 1
    suite = suites[0]
    assert suite.name == "reloc.check.ci_checks" and (suite.tests, suite.failures, suite.errors) == (3, 1, 0)
    cases = {c.name: c for c in suite}
    assert set(cases) == {"recall holds", "recall too high a bar", "videoreloc.day.lo >= 0.5"}
    assert all(c.classname == "reloc.check.ci_checks" for c in cases.values())
    assert cases["recall holds"].is_passed and cases["videoreloc.day.lo >= 0.5"].is_passed
    bad = cases["recall too high a bar"]
    assert not bad.is_passed
    (failure,) = bad.result
    assert isinstance(failure, junitparser.Failure)
    # the value (the lower bound 0.85), the bound it was held to, the interval [0.85, 0.85]
    assert "value 0.85" in failure.message and "against 0.9" in failure.message and "[0.85, 0.85]" in failure.message
    assert json.loads(failure.text)["against"] == 0.9
    assert [p.name for p in suite.properties()] == ["results"]
    assert sorted(p.name for p in report.parent.iterdir()) == ["checks.xml"]  # no temporary file left


def test_all_pass_is_exit_0_and_a_bad_junit_path_is_one_line_before_any_work(tmp_path, capsys):
    from tests.cli_errors import one_line_error

    exp = _exp(tmp_path)
    spec = tmp_path / "ok.yaml"
    spec.write_text(yaml.safe_dump({"checks": ["videoreloc.recall_1m_10deg.lo >= 0.80"]}))
    assert reloc_main(["check", str(spec), str(exp), "--junit", str(tmp_path / "ok.xml")]) == 0
    suite = next(iter(junitparser.JUnitXml.fromfile(str(tmp_path / "ok.xml"))))
    assert (suite.tests, suite.failures) == (1, 0)
    capsys.readouterr()
    assert reloc_main(["check", str(spec), str(exp), "--junit", str(spec / "dir.xml")]) == 2  # below a file
    one_line_error(capsys, "dir.xml")
