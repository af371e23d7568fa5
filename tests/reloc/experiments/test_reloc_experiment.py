"""reloc experiment, tables and checks: spec validation, the factor arithmetic, the check language,
and (with Blender) a whole tiny design end to end, rerun and resumed."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest
import yaml

from reloc.experiments import tables
from reloc.cli import main as reloc_main
from reloc.experiments.spec import load_experiment

from vrformats.design import write_design
from jobspecs import write_experiment_spec

REPO = Path(__file__).resolve().parents[3]


# ---------------------------------------------------------------------------------------------
# factors and evaluation frames, against hand-computed values


def _tours():
    t = {}
    for layout in ("apt_0", "apt_1", "apt_3"):
        for light in ("day", "evening", "night"):
            t[f"{layout}__{light}__query"] = {"layout": layout, "lighting": light}
    return t


def test_factors_match_hand_computation():
    tours = _tours()
    recall = {"apt_0": {"day": 0.9, "evening": 0.8, "night": 0.7},
              "apt_1": {"day": 0.6, "evening": 0.5, "night": 0.3},
              "apt_3": {"day": 0.3, "evening": 0.2, "night": 0.2}}
    per = {n: {"recall_1m_10deg": recall[t["layout"]][t["lighting"]]} for n, t in tours.items()}
    f = tables.factors(per, tours, "apt_0")
    assert f["day"] == pytest.approx((0.9 + 0.6 + 0.3) / 3)
    assert f["night"] == pytest.approx((0.7 + 0.3 + 0.2) / 3)
    assert f["delta_L"] == pytest.approx(1.2 / 3 - 1.8 / 3)
    assert f["unchanged"] == pytest.approx(0.8)
    assert f["rearranged"] == pytest.approx((0.6 + 0.5 + 0.3 + 0.3 + 0.2 + 0.2) / 6)
    assert f["delta_R"] == pytest.approx(0.35 - 0.8)
    assert f["kept"] == pytest.approx(0.35 / 0.8)
    # a design without evening tours and without an unchanged layout: those factors are None
    no_eve = {n: t for n, t in tours.items() if t["lighting"] != "evening" and t["layout"] != "apt_0"}
    g = tables.factors({n: per[n] for n in no_eve}, no_eve, "apt_0")
    assert g["evening"] is None and g["unchanged"] is None and g["kept"] is None and g["delta_R"] is None
    assert g["delta_L"] == pytest.approx((0.3 + 0.2) / 2 - (0.6 + 0.3) / 2)


def test_evaluation_frames_of_per_frame_methods():
    frames = list(range(20))
    assert tables.evaluation_frames("appearance", "causal", frames, 5, 7) == [0, 5, 10, 15]
    assert tables.evaluation_frames("appearance", "closure", frames, 5, 7) == frames  # clip-rigid: every frame
    assert tables.evaluation_frames("one_frame", "causal", frames, 5, 7) == [0, 7, 14]
    assert tables.evaluation_frames("videoreloc", "causal", frames, 5, 7) == frames


# ---------------------------------------------------------------------------------------------
# reloc check


def _results(tmp_path) -> Path:
    """A results folder with two methods, values chosen by hand."""
    def mode(recall, day, night, unchanged, rearranged):
        return {"all": {"recall_1m_10deg": recall, "recall_25cm_5deg": recall / 2, "median_pos_m": 0.1,
                        "median_rot_deg": 1.0, "coverage": 1.0, "frames": 100},
                "factors": {"day": day, "evening": None, "night": night, "delta_L": night - day,
                            "unchanged": unchanged, "rearranged": rearranged, "delta_R": rearranged - unchanged,
                            "kept": rearranged / unchanged},
                "tours": {"apt_1__night__query": {"recall_1m_10deg": 0.5, "coverage": 0.9}}}

    res = {"format": tables.FORMAT, "methods": {
        "videoreloc": {"primary": "closure", "map_bytes": 20000,
                       "modes": {"closure": mode(0.9, 0.9, 0.89, 0.95, 0.8), "causal": mode(0.8, 0.8, 0.8, 0.9, 0.7)}},
        "appearance": {"primary": "causal", "map_bytes": 2_000_000,
                       "modes": {"causal": mode(0.5, 0.6, 0.4, 0.7, 0.4)}}}}
    d = tmp_path / "res"
    d.mkdir()
    (d / "results.json").write_text(json.dumps(res))
    return d


def _write_checks(tmp_path, items) -> Path:
    p = tmp_path / "checks.yaml"
    p.write_text(yaml.safe_dump({"checks": items}))
    return p


def test_checks_pass_fail_and_exit_status(tmp_path, capsys):
    res = _results(tmp_path)
    good = _write_checks(tmp_path, [
        "videoreloc.closure.recall_1m_10deg >= 0.85",
        "videoreloc.delta_L >= -0.03",  # primary cutoff (closure): 0.89 - 0.9
        "videoreloc.kept >= 0.75",  # 0.8 / 0.95
        {"check": "videoreloc.closure.recall_1m_10deg > appearance.causal.recall_1m_10deg", "name": "beats appearance"},
        "appearance.delta_L < 0",
        "videoreloc.closure.apt_1__night__query.coverage >= 0.9",
        "videoreloc.map_bytes < 150000",
    ])
    assert reloc_main(["check", str(good), str(res)]) == 0
    out = capsys.readouterr().out
    assert "7 passed, 0 failed" in out and "beats appearance" in out
    bad = _write_checks(tmp_path, ["videoreloc.causal.kept >= 0.8",  # 0.7 / 0.9 = 0.78
                                   "videoreloc.closure.evening >= 0.5",  # no evening tours: no value
                                   "videoreloc.closure.recall_1m_10deg >= 0.85"])
    assert reloc_main(["check", str(bad), str(res), "--json"]) == 1
    rows = json.loads(capsys.readouterr().out)
    assert [r["passed"] for r in rows] == [False, False, True]
    assert rows[0]["value"] == pytest.approx(0.7 / 0.9) and rows[1]["why"] == "no value"


def _feasible(name: str) -> tuple[float, float]:
    """The values a metric can take: fractions in [0, 1], differences of fractions in [-1, 1],
    kept (a ratio) and sizes, counts and errors from 0 up."""
    key = name.rsplit(".", 1)[-1]
    if key in ("delta_L", "delta_R", "delta"):
        return -1.0, 1.0
    if key in ("kept", "map_bytes", "drift_pct", "built", "gt", "matched", "missing", "extra", "class_errors") or key.endswith(
            ("_m", "_deg")):
        return 0.0, math.inf
    return 0.0, 1.0


def _has_interval(name: str) -> bool:
    """Whether reloc check gives a metric an interval (recall, coverage and Table II's figures)."""
    from reloc.experiments.intervals import COUNT_OF

    if ".sensor." in f".{name}" and not name.startswith("sensor."):  # a method's recall through a sensor, or its delta
        return True
    return not name.startswith("map") and name.rsplit(".", 1)[-1] in (*COUNT_OF, *tables.FACTOR_KEYS)


class _StubResolver:
    """reloc check's resolver on constructed values (``VALUES``): ``NAME.lo``/``.hi`` are values of their
    own, and a figure's resamples are constant at its value, so a comparison of two figures is decided
    on the difference of their values."""

    VALUES: dict = {}

    def __init__(self, results, path):
        from reloc.experiments.intervals import Bootstrap, IntervalSettings

        self.boot = Bootstrap({}, {}, IntervalSettings(resamples=100))

    def value(self, token, field):
        try:
            return float(token), None, None
        except ValueError:
            pass
        v = self.VALUES[token]
        if token.rsplit(".", 1)[-1] in ("lo", "hi"):
            return v, [v, v], None
        return v, None, (token if _has_interval(token) else None)

    def resamples(self, name):
        return np.full(100, self.VALUES[name])


_SENSORS = ("ideal", "structured_light", "tof")


@pytest.mark.parametrize("spec", ["demo_checks.yaml", "demo_sensor_checks.yaml", "replicacad_checks.yaml"])
def test_every_demo_check_can_fail(monkeypatch, tmp_path, spec):
    """Each check of the shipped check files (reloc/specs/demo_checks.yaml, demo_sensor_checks.yaml)
    passes on constructed values and fails when its metric (a point value, an interval's bound, or one
    side of a paired comparison) moves, within what the metric can take, to the wrong side: a check
    that no possible result can fail would be a defect."""
    from reloc.experiments import checks as ck

    path = REPO / "reloc" / "specs" / spec
    items = ck.parse_checks(path)
    sensor_factors = {f"sensor.{s}{d}": None for s in _SENSORS for d in ("", ".delta")}
    metrics = set(ck.metric_table({"methods": {m: {"primary": "closure", "modes": {
        mode: {"all": {}, "factors": dict(sensor_factors)} for mode in ("causal", "closure")}} for m in
        ("videoreloc", "videoreloc_oracle", "appearance", "fpfh_icp", "one_frame")},
        "sensor_figures": {s: {"odometry": {}, "clip_ends": {}} for s in _SENSORS},
        "maps": {"boxes": {"by_kind": {k: {} for k in ("object", "wall", "floor", "ceiling")}},
                 "boxes_oracle": {"by_kind": {}}}}))
    known = metrics | {f"{m}.{b}" for m in metrics if _has_interval(m) for b in ("lo", "hi")}
    assert any(c.left.endswith(".lo") for c in items), "the demo's checks compare bounds"

    def feasible(name):
        return _feasible(name.removesuffix(".lo").removesuffix(".hi"))

    good: dict[str, float] = {}
    for _ in range(10):  # rounds until every check holds (an offset check and its reverse push each other)
        before = dict(good)
        for c in items:  # a passing value for each metric: the threshold with a margin on the right side
            for side in (c.left, c.right):
                try:
                    float(side)
                except ValueError:
                    assert side in known, f"{c.text}: unknown metric {side}"
            if c.left in good and (c.right in good or c.right not in known):  # already decided: must hold
                if ck.OPS[c.op](good[c.left], good[c.right] + c.offset if c.right in known else float(c.right)):
                    continue
            if c.right in known:
                if c.left in good and c.right not in good:  # the left side is set already: put the right below it
                    good[c.right] = good[c.left] - c.offset - 0.05 if c.op in (">", ">=") else good[c.left] - c.offset + 0.05
                    continue
                good.setdefault(c.right, 0.5)
            r = good[c.right] + c.offset if c.right in known else float(c.right)  # 'A >= B - 0.10': B's value plus the offset
            lo, hi = feasible(c.left)
            room = (hi - r) if c.op in (">", ">=") else (r - lo)  # how far the passing side reaches
            assert room > 0, f"{c.text}: cannot pass"
            step = 0.5 * room if math.isfinite(room) else max(abs(r) * 0.2, 0.05)
            good[c.left] = r + step if c.op in (">", ">=") else r - step
        if good == before:
            break
    monkeypatch.setattr(ck, "_Resolver", _StubResolver)
    monkeypatch.setattr(_StubResolver, "VALUES", dict(good))
    res_dir = tmp_path  # run_checks reads a results.json; the values come from the stub
    (res_dir / "results.json").write_text("{}")
    assert all(r["passed"] for r in ck.run_checks(path, res_dir)), "the demo-like values must pass"
    for i, c in enumerate(items):
        bad = dict(good)
        r = good[c.right] + c.offset if c.right in known else float(c.right)
        lo, hi = feasible(c.left)
        bad[c.left] = max(lo, r - 0.01) if c.op in (">", ">=") else min(hi, r + 0.01)
        monkeypatch.setattr(_StubResolver, "VALUES", bad)
        rows = ck.run_checks(path, res_dir)
        assert not rows[i]["passed"], f"{c.text} does not fail at {c.left} = {bad[c.left]}"


@pytest.mark.parametrize("items, message", [
    (["videoreloc.closure.recal_1m_10deg >= 0.85"], "did you mean videoreloc.closure.recall_1m_10deg"),
    (["videoreloc.kept >= fast"], "unknown metric 'fast'"),
    (["videoreloc.kept => 0.75"], "cannot parse"),
    ([{"name": "x"}], "checks[0]: expected {check:"),
    ([3], "checks[0]: expected an assertion"),
    ([], "non-empty list"),
])
def test_malformed_checks_exit_2(tmp_path, capsys, items, message):
    res = _results(tmp_path)
    assert reloc_main(["check", str(_write_checks(tmp_path, items)), str(res)]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("reloc: error:") and message in err and len(err.splitlines()) == 1, err


def test_check_file_or_results_missing_exit_2(tmp_path, capsys):
    res = _results(tmp_path)
    assert reloc_main(["check", str(tmp_path / "none.yaml"), str(res)]) == 2
    p = _write_checks(tmp_path, ["videoreloc.kept >= 0.75"])
    assert reloc_main(["check", str(p), str(tmp_path)]) == 2
    assert "results.json: not found" in capsys.readouterr().err
    (tmp_path / "broken.yaml").write_text("checks: [\n")
    assert reloc_main(["check", str(tmp_path / "broken.yaml"), str(res)]) == 2


# ---------------------------------------------------------------------------------------------
# experiment spec validation


def test_shipped_experiment_spec_validates():
    s = load_experiment(REPO / "reloc" / "specs" / "demo_experiment.yaml")
    assert s.methods == ("videoreloc", "videoreloc_oracle", "fpfh_icp", "appearance", "one_frame")
    assert s.unchanged == "apt_0" and s.detector["kind"] == "learned"
    assert s.detector["model"] == str(REPO / "reloc" / "models" / "detector_v2_160x120.onnx")
    assert s.render == (REPO / "render_jobs" / "demo.yaml").resolve()  # render: demo, a shipped name


def test_a_bare_name_is_a_shipped_spec_and_a_file_wins(tmp_path, monkeypatch, capsys):
    """reloc experiment NAME, reloc check NAME: a bare name is a spec of reloc/specs, a file of that
    name wins, and an unknown name is one line listing the shipped ones (exit 2). An experiment
    spec's render: is a file relative to it, or the name of a render spec synth ships."""
    from vrformats.errors import SceneFormatError
    from reloc.experiments.checks import parse_checks

    monkeypatch.chdir(tmp_path)
    assert load_experiment("demo_experiment").source == REPO / "reloc" / "specs" / "demo_experiment.yaml"
    assert len(parse_checks("demo_checks")) == len(parse_checks(REPO / "reloc" / "specs" / "demo_checks.yaml")) > 5
    (tmp_path / "demo_experiment").write_text(write_experiment_spec(tmp_path, name="mine").read_text())
    assert load_experiment("demo_experiment").name == "mine"
    assert load_experiment(write_experiment_spec(tmp_path, render="demo")).render == (REPO / "render_jobs" / "demo.yaml").resolve()
    with pytest.raises(SceneFormatError, match=r"exp.yaml: render: .*nowhere: no such file, and no shipped render job "
                                               r"spec of that name; shipped: demo, detector_eval, quickstart, reference"):
        load_experiment(write_experiment_spec(tmp_path, render="nowhere"))
    for argv, shipped in ((["experiment", "nosuch"], "demo_experiment, demo_sensors_experiment, demo_tables, "
                                                     "quickstart_experiment, reference_experiment"),
                          (["check", "nosuch", str(tmp_path)], "demo_checks, demo_sensor_checks")):
        assert reloc_main(argv) == 2
        err = capsys.readouterr().err.strip()
        assert len(err.splitlines()) == 1 and err.startswith("reloc: error: nosuch: no such file") and shipped in err, err


@pytest.mark.parametrize("changes, message", [
    ({"colour": 1}, "colour: unknown key"),
    ({"render": "nowhere.yaml"}, "render: render job spec"),
    ({"methods": ["videoreloc", "hloc"]}, "methods[1]: unknown method 'hloc'"),
    ({"methods": ["fpfh_icp"]}, "reuse VideoReloc's clips: add videoreloc"),
    ({"tables": ["units", "bogus"]}, "tables: expected a list of units, ablation"),
    ({"detector": {"kind": "oracle", "miss_rate": 2.0}}, "detector: corruption.miss_rate"),
    ({"detector": {"kind": "oracle", "miss": 0.1}}, "detector.miss: unknown setting"),
    ({"detector": {"miss_rate": 0.1}}, "detector.miss_rate: corrupts the oracle's detections (add kind: oracle)"),
    ({"detector": "yolo"}, "detector: expected one of learned, oracle, onnx"),
    ({"detector": {"kind": "learned", "model": "nowhere.onnx"}}, "detector.model: model file"),
    ({"detector": {"kind": "oracle", "model": "x.onnx"}}, "detector.model: the oracle detector reads the rendered"),
    ({"detector": "oracle"}, "methods: videoreloc_oracle is the oracle row beside another detector"),
    ({"config": {"clips": {"nope": 1}}}, "clips.nope: unknown setting"),
    ({"one_frame_stride": 0}, "one_frame_stride: expected a positive integer"),
    ({"unchanged": None}, "unchanged: missing"),
    ({"map": "magic"}, "map: expected build or ground-truth"),
    ({"replicates": 0}, "replicates: expected a positive integer, got 0"),
    ({"replicates": True}, "replicates: expected a positive integer"),
    ({"seed": -1}, "seed: expected a non-negative integer, got -1"),
    ({"intervals": {"level": 95}}, "intervals.level: must be in [0.5, 1)"),
    ({"intervals": {"resamples": 5}}, "intervals.resamples: expected an integer >= 100"),
    ({"intervals": {"blocks": 5}}, "intervals.blocks: unknown key"),
    ({"detector": {"kind": "learned", "perturbation": {"input_jitter": -1}}},
     "detector.perturbation: perturbation.input_jitter: expected a non-negative integer"),
    ({"detector": {"kind": "learned", "perturbation": {"graph_optimization": "no"}}},
     "detector.perturbation: perturbation.graph_optimization: expected true or false"),
    ({"detector": {"kind": "learned", "perturbation": {"jitter": 1}}}, "detector.perturbation.jitter: unknown setting"),
    ({"detector": {"kind": "oracle", "perturbation": {"input_jitter": 1}}},
     "detector.perturbation: only the learned detector takes a perturbation"),
])
def test_bad_experiment_specs_are_one_line_exit_2(tmp_path, capsys, changes, message):
    assert reloc_main(["experiment", str(write_experiment_spec(tmp_path, **changes)), "--quiet"]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("reloc: error:") and message in err and len(err.splitlines()) == 1, err
    assert not (tmp_path / "exp").exists()


def test_replicate_specs_reseed_every_stochastic_part(tmp_path):
    from reloc.experiments.spec import replicate_spec

    s = load_experiment(write_experiment_spec(tmp_path, seed=4, replicates=3))
    assert s.replicates == 3 and replicate_spec(s, 0) is s
    r2 = replicate_spec(s, 2)
    assert r2.seed == 6 and r2.replicates == 1 and r2.detector["perturbation"] == {"input_jitter": 1, "seed": 2}
    assert s.detector.get("perturbation") is None  # the experiment's own spec is untouched
    o = load_experiment(write_experiment_spec(tmp_path, detector={"kind": "oracle", "miss_rate": 0.1, "seed": 5},
                                              methods=["videoreloc"]))
    assert replicate_spec(o, 1).detector["corruption"] == {"miss_rate": 0.1, "seed": 6}


def _render_spec(tmp_path, **design_changes) -> Path:
    """render_jobs/demo.yaml with its query design changed (its out stays the tests' tours folder)."""
    doc = yaml.safe_load((REPO / "render_jobs" / "demo.yaml").read_text())
    doc["designs"][0].update(design_changes)
    for k in [k for k, v in design_changes.items() if v is None]:
        del doc["designs"][0][k]
    p = tmp_path / "render.yaml"
    p.write_text(yaml.safe_dump(doc))
    return p


@pytest.mark.parametrize("design, field, message", [
    ({"rgb_every": 10}, "designs[0].rgb_every", "RGB on every 10th frame, but the learned detector looks at every 5th"),
    ({"rgb_every": 3}, "designs[0].rgb_every", "every 5th query frame (config.observation.stride)"),
    ({"lightings": None, "rgb_every": None}, "designs[0].lightings", "a geometry-only design renders no RGB"),
])
def test_a_render_job_without_rgb_where_the_detector_looks(tmp_path, capsys, design, field, message):
    """The learned detector sees only RGB frames: the spec check names the render job's design field."""
    render = _render_spec(tmp_path, **design)
    assert reloc_main(["experiment", str(write_experiment_spec(tmp_path, render=str(render))), "--quiet"]) == 2
    err = capsys.readouterr().err.strip()
    assert f"{render}: {field}: " in err and message in err and len(err.splitlines()) == 1, err
    assert not (tmp_path / "exp").exists()
    # the oracle reads label images, which every frame has: the same render job is fine for it
    assert reloc_main(["experiment", str(write_experiment_spec(tmp_path, render=str(render), detector="oracle",
                                               methods=["videoreloc"])), "--quiet"]) == 2
    assert "no rendered design" in capsys.readouterr().err


def test_one_frame_stride_must_fall_on_rgb_frames(tmp_path, capsys):
    assert reloc_main(["experiment", str(write_experiment_spec(tmp_path, one_frame_stride=12)), "--quiet"]) == 2
    err = capsys.readouterr().err
    assert "designs[0].rgb_every: RGB on every 5th frame" in err and "every 12th query frame (one_frame_stride)" in err


@pytest.mark.parametrize("content, message", [
    (b"", "not a readable ONNX model"),
    (b"not a protobuf at all" * 10, "not a readable ONNX model"),
])
def test_corrupt_detector_model_is_one_line(tmp_path, capsys, content, message):
    (tmp_path / "bad.onnx").write_bytes(content)
    spec = write_experiment_spec(tmp_path, detector={"kind": "learned", "model": "bad.onnx"})
    assert reloc_main(["experiment", str(spec), "--quiet"]) == 2
    err = capsys.readouterr().err.strip()
    assert f"{spec}: detector.model: {tmp_path / 'bad.onnx'}" in err and message in err, err
    assert len(err.splitlines()) == 1, err
    assert not (tmp_path / "exp").exists()


def test_a_foreign_onnx_model_is_named(tmp_path, capsys):
    """An ONNX file of another format (here: a YOLO-style test model) is not taken for the learned detector."""
    onnx = pytest.importorskip("onnx")
    from onnx import TensorProto, helper

    g = helper.make_graph([helper.make_node("Identity", ["x"], ["y"])], "g",
                          [helper.make_tensor_value_info("x", TensorProto.FLOAT, [1, 3, 8, 8])],
                          [helper.make_tensor_value_info("y", TensorProto.FLOAT, [1, 3, 8, 8])])
    onnx.save(helper.make_model(g, opset_imports=[helper.make_opsetid("", 17)]), tmp_path / "other.onnx")
    spec = write_experiment_spec(tmp_path, detector={"kind": "learned", "model": "other.onnx"})
    assert reloc_main(["experiment", str(spec), "--quiet"]) == 2
    err = capsys.readouterr().err.strip()
    assert f"{tmp_path / 'other.onnx'}: format: expected a videoreloc-segnet/1 model" in err, err


def _planned_design(tmp_path) -> Path:
    """design.json as ``synth render demo`` writes it before any frame is rendered."""
    from synth.jobs import expand, load_spec

    plan = expand(load_spec(REPO / "render_jobs" / "demo.yaml"), out=tmp_path / "tours")
    write_design(plan.out, plan.spec.name, plan.spec.source,
                 {n: {"layout": p.layout_name, "lighting": p.lighting_name, "path": p.path_name,
                      "n_frames": len(p.frame_ids)} for n, p in plan.tours.items()})
    return plan.out


@pytest.mark.slow
def test_unrendered_design_names_the_missing_tours_and_the_command(tmp_path, capsys):
    assert reloc_main(["experiment", str(write_experiment_spec(tmp_path)), "--quiet"]) == 2  # nothing on disk at all
    err = capsys.readouterr().err.strip()
    assert "no rendered design" in err and "synth render" in err and len(err.splitlines()) == 1, err
    _planned_design(tmp_path)  # planned, nothing rendered yet
    assert reloc_main(["experiment", str(write_experiment_spec(tmp_path)), "--quiet"]) == 2
    err = capsys.readouterr().err
    assert "10 tour(s) not rendered" in err and "synth render" in err and "--resume" in err
    assert not (tmp_path / "exp").exists()


def test_wrong_names_in_the_design(tmp_path, capsys):
    _planned_design(tmp_path)
    assert reloc_main(["experiment", str(write_experiment_spec(tmp_path, unchanged="apt_2")), "--quiet"]) == 2
    assert "unchanged: layout 'apt_2' has no query tour" in capsys.readouterr().err
    assert reloc_main(["experiment", str(write_experiment_spec(tmp_path, query="walk")), "--quiet"]) == 2
    assert "has no tours of path 'walk'" in capsys.readouterr().err
    assert reloc_main(["experiment", str(write_experiment_spec(tmp_path, mapping={"layout": "apt_1", "lighting": "day",
                                                                  "path": "mapping"})), "--quiet"]) == 2
    assert "has no tour apt_1__day__mapping" in capsys.readouterr().err


def test_malformed_design_file_is_one_line(tmp_path, capsys):
    root = _planned_design(tmp_path)
    (root / "design.json").write_text('{"format": "videoreloc-design/1", "tours": [1]')
    assert reloc_main(["experiment", str(write_experiment_spec(tmp_path)), "--quiet"]) == 2
    err = capsys.readouterr().err.strip()
    assert "design.json: line 1: not valid JSON" in err and len(err.splitlines()) == 1, err


# ---------------------------------------------------------------------------------------------
# a whole tiny design, end to end (Blender renders a few RGB frames; geometry from the fast renderer)


@pytest.fixture(scope="module")
def tiny_design(tmp_path_factory):
    from synth.jobs import load_spec, run_job

    root = tmp_path_factory.mktemp("design")
    # 160x120: the shipped learned detector's resolution (it refuses tours of another size)
    render = {"name": "tiny", "out": str(root / "tours"), "renderer": "blender", "geometry": "fast",
              "quality": "preview", "size": [160, 120], "chunk_size": 600, "designs": [
                  {"layouts": ["apt_0", "apt_1"], "lightings": ["day", "night"], "path": {"name": "query", "frames": 450},
                   "rgb_every": 150},
                  {"layouts": ["apt_0"], "lightings": ["day"], "path": {"name": "mapping", "frames": 1800},
                   "rgb_every": 120}]}
    (root / "render.yaml").write_text(yaml.safe_dump(render))
    s = run_job(load_spec(root / "render.yaml"), progress=False)
    assert s["failed"] == {}
    exp = {"name": "tiny", "render": "render.yaml", "out": str(root / "exp"), "query": "query", "unchanged": "apt_0",
           "mapping": {"layout": "apt_0", "lighting": "day", "path": "mapping"}, "map": "ground-truth",
           "methods": ["videoreloc", "fpfh_icp", "appearance", "one_frame"], "one_frame_stride": 50, "workers": 2,
           "detector": "oracle"}
    (root / "exp.yaml").write_text(yaml.safe_dump(exp))
    return root


# two of tiny_design's four query tours, the unchanged layout by day and the rearranged one at night (so
# every layout and every lighting of the design), and its mapping tour
PAIR = ("apt_0__day__query", "apt_1__night__query")


@pytest.fixture(scope="module")
def tiny_pair(tiny_design):
    """A tours folder holding links to PAIR's tours and the mapping tour of ``tiny_design`` (no design.json:
    an experiment reads the tours it finds there). The experiments that test a feature (tables, replicates,
    the learned detector, a sweep) run on it, at half the cost of all four query tours;
    test_experiment_end_to_end_rerun_and_resume keeps the whole design."""
    d = tiny_design / "pair"
    d.mkdir(exist_ok=True)
    for name in (*PAIR, "apt_0__day__mapping"):
        if not (d / name).exists():
            (d / name).symlink_to(tiny_design / "tours" / name, target_is_directory=True)
    return d


@pytest.mark.slow
def test_tables_iii_and_iv_with_intervals_end_to_end(tiny_design, tiny_pair, capsys):
    """tables: [units, ablation] on the tiny design: every unit length writes its trajectory, whose
    recall matches units.json; Tables III and IV print intervals, and the ablation rows' paired
    differences to the full method are in results.json."""
    spec = yaml.safe_load((tiny_design / "exp.yaml").read_text())
    spec.update({"out": str(tiny_design / "exp_tables"), "methods": ["videoreloc", "one_frame"],
                 "tables": ["units", "ablation"], "tours": str(tiny_pair)})
    (tiny_design / "exp_tables.yaml").write_text(yaml.safe_dump(spec))
    assert reloc_main(["experiment", str(tiny_design / "exp_tables.yaml"), "--quiet", "--no-plots"]) == 0
    capsys.readouterr()
    exp = tiny_design / "exp_tables"
    res = json.loads((exp / "results.json").read_text())
    assert sorted(res["tours"]) == sorted(PAIR)
    for u in res["units"]:
        assert sorted(u["segments"]) == sorted(res["tours"])
        iv = u["intervals"]["all_recall_1m_10deg"]
        assert iv[0] <= u["all_recall_1m_10deg"] + 1e-12 and u["all_recall_1m_10deg"] <= iv[1] + 1e-12
        for name in res["tours"]:  # the unit's trajectory gives units.json's recall
            rep = json.loads((exp / "runs" / "one_frame" / name / "units.json").read_text())
            row = next(r for r in rep["units"] if r["unit"] == u["unit"])
            frames = list(range(450))[:: 50 if u["unit"] == 1 else 1]
            got = _tum_recall(exp / "runs" / "one_frame" / name / tables.unit_file(u["unit"]),
                              Path(res["tours"][name]["dir"]) / "poses.txt", frames)
            assert got == pytest.approx(row["recall_1m_10deg"]), (u["unit"], name)
    assert len(res["ablation"]) == 5
    for a in res["ablation"]:
        assert a["intervals"]["closure_coarse"] is not None
        if a["method"] != "videoreloc":
            lo, hi = a["intervals"]["closure_coarse_delta"]
            assert lo <= a["closure_coarse_delta"] + 1e-12 and a["closure_coarse_delta"] <= hi + 1e-12
    units_md = (exp / "tables" / "units.md").read_text()
    abl_md = (exp / "tables" / "ablation.md").read_text()
    assert "-frame clip | " in units_md and " [" in units_md and "95 % interval" in units_md
    assert "against all on" in abl_md and "95 % interval" in abl_md


@pytest.mark.slow
def test_replicates_and_the_stability_benchmark_with_the_learned_detector(tiny_design, tiny_pair, capsys):
    """replicates: 2 reruns the experiment reseeded, the second with the learned detector's input
    jittered; results.json, Table I and reloc check report the spread. reloc bench stability reruns
    VideoReloc under a perturbation and reports each figure's values and spread."""
    spec = yaml.safe_load((tiny_design / "exp.yaml").read_text())
    spec.update({"out": str(tiny_design / "exp_rep"), "map": "build", "detector": "learned", "methods": ["videoreloc"],
                 "config": {"observation": {"stride": 150}}, "replicates": 2, "tours": str(tiny_pair)})
    (tiny_design / "exp_rep.yaml").write_text(yaml.safe_dump(spec))
    argv = ["experiment", str(tiny_design / "exp_rep.yaml"), "--quiet", "--no-plots"]
    assert reloc_main(argv) == 0
    out = capsys.readouterr().out
    exp = tiny_design / "exp_rep"
    res = json.loads((exp / "results.json").read_text())
    r1 = json.loads((exp / "replicates" / "r1" / "results.json").read_text())
    reps = res["replicates"]
    assert reps["count"] == 2 and [r["seed"] for r in reps["replicates"]] == [0, 1]
    assert reps["replicates"][1]["detector"] == {"input_jitter": 1, "seed": 1}
    vals = reps["figures"]["videoreloc.closure"]["recall_1m_10deg"]
    assert vals["values"] == [res["methods"]["videoreloc"]["modes"]["closure"]["all"]["recall_1m_10deg"],
                              r1["methods"]["videoreloc"]["modes"]["closure"]["all"]["recall_1m_10deg"]]
    assert vals["spread"] == pytest.approx(max(vals["values"]) - min(vals["values"]))
    run = json.loads((exp / "replicates" / "r1" / "runs" / "videoreloc" / "apt_1__night__query" / "run.json").read_text())
    assert run["seed"] == 1 and run["detector"]["perturbation"]["input_jitter"] == 1
    assert "1 m/10°, 2 replicates" in out and f"{2 * len(PAIR)} runs and 2 maps computed now" in out  # a run a tour each
    assert reloc_main(argv) == 0 and "0 runs and 0 maps computed now" in capsys.readouterr().out  # resumes
    checks = tiny_design / "rep_checks.yaml"
    checks.write_text(yaml.safe_dump({"checks": [f"videoreloc.closure.recall_1m_10deg.spread <= {vals['spread'] + 1e-6:.6f}",
                                                 f"videoreloc.recall_1m_10deg.spread >= {vals['spread'] - 1e-6:.6f}"]}))
    assert reloc_main(["check", str(checks), str(exp)]) == 0
    assert "2 passed, 0 failed" in capsys.readouterr().out

    st = tiny_design / "stab"
    assert reloc_main(["bench", "stability", str(tiny_design / "exp_rep.yaml"), "--perturbation", "jitter:5",
                       "--out", str(st), "--quiet", "--json"]) == 0
    rep = json.loads(capsys.readouterr().out)
    assert rep["perturbations"] == {"none": {}, "jitter-5": {"detector": {"input_jitter": 1, "seed": 5}}}
    assert rep["renders"] == {}  # a detector perturbation renders nothing
    fig = next(f for f in rep["figures"] if f["figure"] == "closure 1 m/10°")
    assert fig["values"]["none"] == vals["values"][0]  # the unperturbed rerun gives the experiment's figure
    assert fig["spread"] == pytest.approx(abs(fig["values"]["none"] - fig["values"]["jitter-5"]))
    assert len(rep["tour_recalls"]) == 2 * len(PAIR) and (st / "stability.md").is_file() and (st / "jitter-5" / "results.json").is_file()
    # the thresholds are fractions 0..1 (issue 43: -1 could never pass); at 0 the run fails exactly when
    # a tour lost something (or a recall moved), as the report says, and passes otherwise
    base = ["bench", "stability", str(tiny_design / "exp_rep.yaml"), "--perturbation", "jitter:5", "--out", str(st), "--quiet"]
    for opt, key, says in (("--max-tour-loss", "max_tour_loss", "unstable: a tour lost"),
                           ("--max-spread", "max_spread", "unstable: a recall spread")):
        assert rep[key] is not None, key
        moved = rep[key] > 0
        assert reloc_main(base + [opt, "0"]) == (1 if moved else 0), (key, rep[key])
        assert (says in capsys.readouterr().err) == moved
        assert reloc_main(base + [opt, "1"]) == 0  # nothing can lose or move more than everything
        capsys.readouterr()


def _tum_recall(path: Path, gt_path: Path, frames: list[int]) -> float:
    """Recall at 1 m/10 deg from TUM files, parsed and compared independently of reloc.experiments.evaluation."""
    from scipy.spatial.transform import Rotation

    def read(p):
        out = {}
        for line in p.read_text().splitlines():
            if line.startswith("#") or not line.strip():
                continue
            v = [float(x) for x in line.split()]
            out[int(round(v[0] * 30.0))] = (np.array(v[1:4]), Rotation.from_quat(v[4:8]))
        return out

    est, gt = read(path), read(gt_path)
    ok = 0
    for i in frames:
        if i in est:
            dp = np.linalg.norm(est[i][0] - gt[i][0])
            dr = np.degrees((gt[i][1].inv() * est[i][1]).magnitude())
            ok += dp <= 1.0 and dr <= 10.0
    return ok / len(frames)


@pytest.mark.blender
@pytest.mark.slow
def test_experiment_end_to_end_rerun_and_resume(tiny_design, capsys):
    root = tiny_design
    exp = root / "exp"
    assert reloc_main(["experiment", str(root / "exp.yaml"), "--quiet"]) == 0
    printed = capsys.readouterr().out
    res = json.loads((exp / "results.json").read_text())
    assert [r["key"] for r in res["rows"]] == ["appearance.causal", "one_frame.causal", "fpfh_icp.closure",
                                               "appearance.closure", "videoreloc.causal", "videoreloc.closure"]
    assert len(res["tours"]) == 4 and res["failed"] == {}
    # figures agree with an independent reading of the trajectory files
    for name, t in res["tours"].items():
        gt = Path(t["dir"]) / "poses.txt"
        all_frames = list(range(450))
        for key, frames in (("videoreloc.closure", all_frames), ("videoreloc.causal", all_frames),
                            ("fpfh_icp.closure", all_frames), ("appearance.causal", [0, 150, 300]),
                            ("one_frame.causal", list(range(0, 450, 50)))):
            m, mode = key.split(".")
            got = res["methods"][m]["modes"][mode]["tours"][name]
            assert got["frames"] == len(frames)
            assert got["recall_1m_10deg"] == pytest.approx(_tum_recall(exp / got["file"], gt, frames)), (key, name)
    # the unchanged tours: VideoReloc with clip closure localizes nearly everything
    vr = res["methods"]["videoreloc"]["modes"]["closure"]
    assert vr["tours"]["apt_0__day__query"]["recall_1m_10deg"] > 0.8
    f = vr["factors"]
    assert f["delta_L"] == pytest.approx(f["night"] - f["day"]) and f["evening"] is None
    assert f["kept"] == pytest.approx(f["rearranged"] / f["unchanged"])
    # tables, plots and the report exist and carry the rows
    main = (exp / "tables" / "main.md").read_text()
    for r in res["rows"]:
        assert r["label"] in main and r["label"] in printed
    factors = json.loads((exp / "tables" / "factors.json").read_text())
    assert factors["table"] == "II" and factors["rows"][0]["key"] == "appearance.causal"
    report = (exp / "report.html").read_text()
    pngs = sorted((exp / "plots").glob("*.png"))
    assert len(pngs) == 5 and all(p.name in report for p in pngs)
    # the clip-rigid controls used VideoReloc's clips: same partition
    from reloc.backend.run import load_clip_poses

    clips = load_clip_poses(exp / "runs" / "videoreloc" / "apt_1__night__query")
    fp = json.loads((exp / "runs" / "fpfh_icp" / "apt_1__night__query" / "clips.json").read_text())
    assert len(fp) == len(clips)
    # a rerun computes nothing and changes no result
    before = {p: p.stat().st_mtime_ns for p in (exp / "runs").rglob("*.txt")}
    assert reloc_main(["experiment", str(root / "exp.yaml"), "--quiet", "--no-plots"]) == 0
    assert "0 runs and 0 maps computed now" in capsys.readouterr().out
    assert {p: p.stat().st_mtime_ns for p in (exp / "runs").rglob("*.txt")} == before
    # a killed run (no done marker) is redone alone, to the same result
    (exp / "runs" / "appearance" / "apt_1__day__query" / "done.json").unlink()
    assert reloc_main(["experiment", str(root / "exp.yaml"), "--quiet", "--no-plots"]) == 0
    assert "1 runs and 0 maps computed now" in capsys.readouterr().out
    assert json.loads((exp / "results.json").read_text())["methods"] == res["methods"]
    # a changed setting reruns exactly what depends on it
    spec = yaml.safe_load((root / "exp.yaml").read_text())
    (root / "exp2.yaml").write_text(yaml.safe_dump({**spec, "appearance": {"top_k": 4}}))
    assert reloc_main(["experiment", str(root / "exp2.yaml"), "--quiet", "--no-plots"]) == 0
    assert "4 runs and 1 maps computed now" in capsys.readouterr().out
    (root / "exp3.yaml").write_text(yaml.safe_dump({**spec, "appearance": {"top_k": 4},
                                                    "config": {"registration": {"center_match_m": 0.45}}}))
    assert reloc_main(["experiment", str(root / "exp3.yaml"), "--quiet", "--no-plots"]) == 0
    assert "16 runs and 0 maps computed now" in capsys.readouterr().out  # VideoReloc, its controls, one-frame
    # a corrupt frame: that run fails with the file named, its old files no longer count, the tables say
    # they are incomplete; once the file is back, a rerun completes them
    frame = Path(res["tours"]["apt_1__day__query"]["dir"]) / "frames" / "000150.exr"
    good = frame.read_bytes()
    (exp / "runs" / "videoreloc" / "apt_1__day__query" / "done.json").unlink()
    frame.write_bytes(b"not an exr")
    try:
        assert reloc_main(["experiment", str(root / "exp3.yaml"), "--quiet", "--no-plots"]) == 1
        cap = capsys.readouterr()
        assert "failed: videoreloc/apt_1__day__query" in cap.err and "000150.exr" in cap.err
        assert (exp / "tables" / "main.md").read_text().startswith("**Incomplete: 1 run(s) failed**")
        broken = json.loads((exp / "results.json").read_text())["methods"]["videoreloc"]["modes"]["closure"]
        assert broken["tours"]["apt_1__day__query"]["coverage"] == 0.0  # no stale poses evaluated
        assert broken["tours"]["apt_0__day__query"]["coverage"] > 0.9
    finally:
        frame.write_bytes(good)
    assert reloc_main(["experiment", str(root / "exp3.yaml"), "--quiet", "--no-plots"]) == 0
    assert "1 runs and 0 maps computed now" in capsys.readouterr().out
    assert not (exp / "tables" / "main.md").read_text().startswith("**Incomplete")
    # checks on the real results
    p = root / "checks.yaml"
    p.write_text(yaml.safe_dump({"checks": ["videoreloc.closure.apt_0__day__query.recall_1m_10deg >= 0.8",
                                            "videoreloc.delta_L >= -0.03", "fpfh_icp.map_bytes > videoreloc.map_bytes"]}))
    assert reloc_main(["check", str(p), str(exp)]) == 0
    # intervals: every run's segment counts give back its figures, every interval holds its point value
    res = json.loads((exp / "results.json").read_text())
    assert res["intervals"]["segments"] == {"query": 5}  # 450 frames in segments of 100
    for m, e in res["methods"].items():
        for mode, d in e["modes"].items():
            for name, u in d["units"].items():
                tot = np.sum(u, axis=0)
                got = d["tours"][name]
                assert tot[0] == got["frames"] and tot[1] == round(got["recall_1m_10deg"] * got["frames"])
                assert tot[3] == round(got["coverage"] * got["frames"])
            for part in ("all", "factors"):
                for k, iv in d["intervals"][part].items():
                    v = d[part][k]
                    assert (iv is None) == (v is None) or v is None, (m, mode, k)
                    if iv is not None:
                        assert iv[0] - 1e-9 <= v <= iv[1] + 1e-9, (m, mode, k, v, iv)
    main_md = (exp / "tables" / "main.md").read_text()
    vr = res["methods"]["videoreloc"]["modes"]["closure"]
    lo, hi = vr["intervals"]["all"]["recall_1m_10deg"]
    assert f"[{100 * lo:.1f}, {100 * hi:.1f}]" in main_md and "block bootstrap over 5 segments" in main_md
    # checks on bounds and on a paired difference, on the real results
    p.write_text(yaml.safe_dump({"checks": [f"videoreloc.closure.recall_1m_10deg.lo >= {lo - 0.01:.4f}",
                                            f"videoreloc.closure.recall_1m_10deg.hi <= {hi + 0.01:.4f}",
                                            "videoreloc.closure.recall_1m_10deg >= videoreloc.closure.recall_1m_10deg"]}))
    assert reloc_main(["check", str(p), str(exp)]) == 0
    assert "diff [0, 0]" in capsys.readouterr().out
    p.write_text(yaml.safe_dump({"checks": [f"videoreloc.closure.recall_1m_10deg.lo >= {lo + 0.001:.4f}"]}))
    assert reloc_main(["check", str(p), str(exp)]) == 1
    p.write_text(yaml.safe_dump({"checks": ["videoreloc.closure.recall_1m_10deg > videoreloc.closure.recall_1m_10deg"]}))
    assert reloc_main(["check", str(p), str(exp)]) == 1
    for bad, says in (("videoreloc.map_bytes.lo >= 1", "has no interval"),
                      ("videoreloc.closure.recal_1m_10deg.lo >= 0.5", "unknown metric")):
        p.write_text(yaml.safe_dump({"checks": [bad]}))
        assert reloc_main(["check", str(p), str(exp)]) == 2
        err = capsys.readouterr().err.strip()
        assert says in err and "checks[0]" in err and len(err.splitlines()) == 1


def test_units_and_ablation_tables_from_run_outputs(tmp_path):
    """Table III pools the per-tour unit reports weighted by frames; Table IV lists the variants in the
    paper's order."""
    from reloc.experiments.tables import ABLATIONS, ablation_name

    queries = {"apt_0__day__query": {"layout": "apt_0"}, "apt_1__day__query": {"layout": "apt_1"}}
    for name, (r1, r250, n1) in zip(queries, ((0.5, 1.0, 10), (0.2, 0.6, 30))):
        d = tmp_path / "runs" / "one_frame" / name
        d.mkdir(parents=True)
        (d / "units.json").write_text(json.dumps({"units": [
            {"unit": 1, "recall_1m_10deg": r1, "recall_25cm_5deg": r1 / 2, "frames": n1, "sampled_every": 15},
            {"unit": 250, "recall_1m_10deg": r250, "recall_25cm_5deg": r250, "frames": 450, "sampled_every": 1}]}))
    rows = tables._units(tmp_path, queries, "apt_0")
    assert [r["unit"] for r in rows] == [1, 250]
    assert rows[0]["all_recall_1m_10deg"] == pytest.approx((0.5 * 10 + 0.2 * 30) / 40)
    assert rows[0]["unchanged_recall_1m_10deg"] == 0.5 and rows[1]["rearranged_recall_1m_10deg"] == 0.6
    assert rows[1]["all_recall_1m_10deg"] == pytest.approx(0.8)
    md, _ = tables.units_table({"units": rows})
    assert "| one frame (every 15th frame) | 27.5 | 13.8 | 50.0 | 20.0 |" in md
    assert "| 250-frame clip | 80.0 | 80.0 | 100.0 | 60.0 |" in md

    def mode(c, f):
        return {"all": {"recall_1m_10deg": c, "recall_25cm_5deg": f}}

    res = {"methods": {("videoreloc" if v == (True, True, True) else ablation_name(v)):
                       {"modes": {"closure": mode(0.5 + 0.1 * k, 0.3), "causal": mode(0.4, 0.2 + 0.05 * k)}}
                       for k, v in enumerate(ABLATIONS)}}
    rows = tables._ablation(res, [v for v in ABLATIONS if v != (True, True, True)])
    assert [(r["orientation_aware"], r["run_level"], r["adaptive"]) for r in rows] == list(ABLATIONS)
    md, _ = tables.ablation_table({"ablation": rows})
    assert md.splitlines()[4] == "|  |  |  | 50.0 | 30.0 | 40.0 | 20.0 | - |"  # no interval without segment counts
    assert "| ✓ | ✓ | ✓ | 90.0 | 30.0 | 40.0 | 40.0 | - |" in md.splitlines()


def test_units_and_ablation_tables_carry_intervals(tmp_path):
    """Tables III and IV get intervals from the same draws as Tables I and II: each unit's recall from
    its trajectory (``unit_L.txt``, the one-frame unit's ``causal.txt``) counted per path segment, each
    ablation row's from its runs, and an ablation row's difference to the full method is paired (a row
    that equals it has the interval [0, 0], one that fails where it succeeds a negative one)."""
    from vrformats.camera import write_tum
    from reloc.experiments.intervals import IntervalSettings

    n = 400
    queries = {f"apt_{k}__day__query": {"layout": f"apt_{k}", "lighting": "day", "frames": n, "fps": 30.0,
                                        "path": "query"} for k in (0, 1)}
    gt = {i: np.eye(4) for i in range(n)}
    for i in gt:
        gt[i] = gt[i].copy()
        gt[i][0, 3] = 0.01 * i

    class _Tour:
        frame_indices = list(range(n))

    gts = {q: (_Tour(), gt) for q in queries}
    for k, name in enumerate(queries):
        d = tmp_path / "runs" / "one_frame" / name
        d.mkdir(parents=True)
        (d / "units.json").write_text(json.dumps({"units": [
            {"unit": 1, "recall_1m_10deg": 0.5, "recall_25cm_5deg": 0.5, "frames": n // 10, "sampled_every": 10},
            {"unit": 100, "recall_1m_10deg": 0.5, "recall_25cm_5deg": 0.5, "frames": n, "sampled_every": 1}]}))
        right = [i for i in range(n) if (i // 100) % 2 == 0]  # the unit succeeds on segments 0 and 2
        write_tum(d / tables.unit_file(100), [gt[i] for i in right], fps=30.0, frames=right)
        write_tum(d / tables.unit_file(1), [gt[i] for i in range(0, n, 10)], fps=30.0, frames=list(range(0, n, 10)))
    rows = tables._units(tmp_path, queries, "apt_0", gts, IntervalSettings(resamples=200), stride=10)
    assert [sorted(r["segments"]) for r in rows] == [sorted(queries)] * 2
    assert rows[1]["segments"]["apt_1__day__query"] == [[100, 100, 100, 100], [100, 0, 0, 0]] * 2

    def counts(ok):  # per segment of 100 frames: frames, ok at both cutoffs, posed
        return [[100, 100 * o, 100 * o, 100 * o] for o in ok]

    full, weaker = counts([1, 1, 1, 1]), counts([1, 0, 1, 1])
    res = {"tours": queries, "unchanged": "apt_0", "units": rows, "intervals": {"settings": {"resamples": 200}},
           "methods": {m: {"modes": {mode: {"units": {q: c for q in queries}, "all": {}} for mode in ("closure", "causal")}}
                       for m, c in (("videoreloc", full), ("ablation_110", full), ("ablation_100", weaker))}}
    res["ablation"] = [{"method": m, "orientation_aware": True, "run_level": m != "ablation_100", "adaptive": m == "videoreloc",
                        "closure_coarse": v, "closure_fine": v, "causal_coarse": v, "causal_fine": v}
                       for m, v in (("ablation_100", 0.75), ("ablation_110", 1.0), ("videoreloc", 1.0))]
    tables.add_intervals(res, IntervalSettings(resamples=200))
    tables.add_table_intervals(res)
    u100 = rows[1]["intervals"]
    lo, hi = u100["all_recall_1m_10deg"]
    assert 0.0 <= lo < 0.5 < hi <= 1.0  # 2 of 4 segments succeed: the interval spans the point value
    assert u100["unchanged_recall_1m_10deg"] is not None and "rearranged_recall_1m_10deg" in u100
    assert rows[0]["intervals"]["all_recall_1m_10deg"] == [1.0, 1.0]  # every sampled frame right
    by = {a["method"]: a for a in res["ablation"]}
    assert by["ablation_110"]["intervals"]["closure_coarse_delta"] == [0.0, 0.0]
    assert by["ablation_100"]["closure_coarse_delta"] == pytest.approx(-0.25)
    dlo, dhi = by["ablation_100"]["intervals"]["closure_coarse_delta"]
    assert -1.0 <= dlo < -0.25 < dhi <= 0.0
    assert "closure_coarse_delta" not in by["videoreloc"]["intervals"]
    md, out_rows = tables.units_table(res)
    assert "| 100-frame clip | 50.0 [" in md and "95 % interval" in md
    assert all("segments" not in r for r in out_rows)  # the table's rows stay small
    md, _ = tables.ablation_table(res)
    assert "| -25.0 [" in md and "| +0.0 [+0.0, +0.0] |" in md


# ---------------------------------------------------------------------------------------------
# the tables are numbered and titled as in the paper

# the paper's \caption{} texts, by the number LaTeX gives each table (main results, then the factors
# table that the experiments section inputs first, then units and ablations); the captions' dataset
# names ("on RIO10 and ReplicaCAD", "in ReplicaCAD", "on RIO10") are left out: the design is rendered
PAPER_CAPTIONS = {
    "main": ("I", "Comparison of recall and pose errors across relocalization methods and evaluation variants"),
    "factors": ("II", "Recall at 1 m/10\u00b0 under illumination and furniture changes"),
    "units": ("III", "Effect of the localization unit"),
    "ablation": ("IV", "Effects of refinement, run-level decisions and adaptive clips"),
}


def _table_results(lightings=("day", "night")) -> dict:
    """results.json-like figures for two VideoReloc rows, with the units and ablation tables."""
    tours = {f"apt_{k}__{light}__query": {"layout": f"apt_{k}", "lighting": light, "frames": 100}
             for k in (0, 1) for light in lightings}
    allm = {"recall_1m_10deg": 0.9, "recall_25cm_5deg": 0.8, "median_pos_m": 0.05, "median_rot_deg": 1.0,
            "coverage": 1.0, "frames": 100 * len(tours)}
    fac = {k: 0.5 for k in tables.FACTOR_KEYS}
    rows = [{"key": f"videoreloc.{m}", "method": "videoreloc", "mode": m, "label": f"VideoReloc, {m}",
             "dagger": False} for m in ("causal", "closure")]
    unit = {"unit": 30, "all_recall_1m_10deg": 0.5, "all_recall_25cm_5deg": 0.4, "unchanged_recall_1m_10deg": 0.6,
            "rearranged_recall_1m_10deg": 0.4}
    abl = {"orientation_aware": True, "run_level": True, "adaptive": True, "closure_coarse": 0.9,
           "closure_fine": 0.8, "causal_coarse": 0.7, "causal_fine": 0.6}
    return {"tours": tours, "rows": rows, "one_frame_stride": 15, "units": [unit], "ablation": [abl],
            "methods": {"videoreloc": {"map_bytes": 20000, "modes": {m: {"all": allm, "factors": fac}
                                                                      for m in ("causal", "closure")}}}}


def test_tables_are_numbered_and_titled_as_in_the_paper(tmp_path):
    from reloc.experiments.report import TABLE_ORDER

    res = _table_results()
    made = tables.make_tables(res)
    assert list(made) == ["main", "factors", "units", "ablation"]  # the paper's order, I to IV
    for key, (md, _) in made.items():
        number, caption = PAPER_CAPTIONS[key]
        assert md.splitlines()[0].startswith(f"**Table {number}: {caption}**"), md.splitlines()[0]
    tables.write_tables(res, tmp_path)
    for key, (number, caption) in PAPER_CAPTIONS.items():
        doc = json.loads((tmp_path / "tables" / f"{key}.json").read_text())
        assert (doc["table"], doc["title"]) == (number, caption) and doc["rows"] == made[key][1]
    assert TABLE_ORDER[:len(PAPER_CAPTIONS)] == tuple((k, f"Table {n}: {c}") for k, (n, c) in PAPER_CAPTIONS.items())


@pytest.mark.parametrize("lightings", [("day", "evening", "night"), ("day",), (None,)])
def test_factors_table_columns_line_up(lightings):
    """Header, separator and rows have one cell per column, also in a geometry-only design (no lightings)."""
    md, _ = tables.factors_table(_table_results(lightings))
    lines = [x for x in md.splitlines() if x.startswith("|")]
    head = [c.strip() for c in lines[0].strip("|").split("|")]
    assert head == ["Method", *[x for x in lightings if x], "ΔL", "unchanged", "rearranged", "ΔR", "kept"]
    assert {len(x.strip("|").split("|")) for x in lines} == {len(head)}


# ---------------------------------------------------------------------------------------------
# the done-key covers the code


def _copy_sources(root: Path, files) -> None:
    from reloc.experiments.fingerprint import SOURCE_ROOT

    for f in files:
        dst = root / f.relative_to(SOURCE_ROOT)
        dst.parent.mkdir(parents=True, exist_ok=True)
        dst.write_bytes(f.read_bytes())


def _flip_one_byte(path: Path) -> None:
    data = bytearray(path.read_bytes())
    k = data.rindex(b"#")  # inside a comment: the module still means the same to Python
    data[k + 1] = ord("!") if data[k + 1] != ord("!") else ord("?")
    path.write_bytes(bytes(data))


@pytest.fixture
def fresh_fingerprint():
    """code_fingerprint is computed once per process: forget it before and after a test that moves it."""
    from reloc.experiments.fingerprint import code_fingerprint

    code_fingerprint.cache_clear()
    yield
    code_fingerprint.cache_clear()


@pytest.mark.slow
def test_code_fingerprint_covers_reloc_and_the_format_modules_it_imports(tmp_path, fresh_fingerprint):
    from reloc.experiments import fingerprint as E

    files = E.code_files()
    rel = {f.relative_to(E.SOURCE_ROOT).as_posix() for f in files}
    # every module of reloc, and the format modules that reloc reads tours with, directly or not
    assert {p.relative_to(REPO).as_posix() for p in (REPO / "reloc").rglob("*.py")} <= rel
    assert {"vrformats/__init__.py", "vrformats/tour.py", "vrformats/camera.py", "vrformats/frames.py", "vrformats/errors.py"} <= rel
    assert not any(r.startswith("synth/") for r in rel)  # reloc computes nothing with synth's code
    outside = sorted(p for p in (REPO / "synth").rglob("*.py") if p.relative_to(REPO).as_posix() not in rel)
    assert outside
    # a copy of the sources gives the same fingerprint; one byte changed in any covered file changes it
    copy = tmp_path / "src"
    _copy_sources(copy, files + outside)
    fp = E.code_fingerprint()
    assert E.source_fingerprint(copy) == fp == E.code_fingerprint() and len(fp) == 16
    for name in ("reloc/experiments/tables.py", "vrformats/frames.py"):
        _flip_one_byte(copy / name)
        changed = E.source_fingerprint(copy)
        assert changed != fp, name
        (copy / name).write_bytes((REPO / name).read_bytes())
    assert E.source_fingerprint(copy) == fp
    # a file outside (not imported by reloc) does not count; a library version does
    _flip_one_byte(copy / next(p for p in outside if b"#" in p.read_bytes()).relative_to(REPO))
    assert E.source_fingerprint(copy) == fp
    versions = E.library_versions()
    assert {"python", "numpy", "scipy", "open3d"} <= set(versions)
    assert E.source_fingerprint(copy, versions={**versions, "numpy": "0.0"}) != fp


def test_project_packages_are_the_ones_pyproject_ships():
    """The fingerprint follows imports into PROJECT_PACKAGES only: every top-level package is there."""
    from reloc.experiments.fingerprint import PROJECT_PACKAGES

    import tomllib

    found = sorted(p.parent.name for p in REPO.glob("*/__init__.py"))
    assert sorted(PROJECT_PACKAGES) == found
    listed = tomllib.loads((REPO / "pyproject.toml").read_text())["tool"]["setuptools"]["packages"]
    assert sorted({x.split(".")[0] for x in listed}) == found


@pytest.fixture(scope="module")
def fast_design(tmp_path_factory):
    """Two 150-frame geometry-only query tours (apt_0, apt_1) and a 30-frame mapping tour, 64x48."""
    from synth.jobs import load_spec, run_job

    root = tmp_path_factory.mktemp("fast_design")
    render = {"name": "fast", "out": str(root / "tours"), "renderer": "fast", "size": [64, 48], "chunk_size": 600,
              "designs": [{"layouts": ["apt_0", "apt_1"], "path": {"name": "query", "frames": 150}},
                          {"layouts": ["apt_0"], "path": {"name": "mapping", "frames": 30}}]}
    (root / "render.yaml").write_text(yaml.safe_dump(render))
    assert run_job(load_spec(root / "render.yaml"), progress=False)["failed"] == {}
    exp = {"name": "fast", "render": "render.yaml", "out": str(root / "exp"), "query": "query", "unchanged": "apt_0",
           "mapping": {"layout": "apt_0", "lighting": "geometry", "path": "mapping"}, "map": "ground-truth",
           "methods": ["videoreloc", "one_frame"], "one_frame_stride": 50, "workers": 1, "detector": "oracle"}
    (root / "exp.yaml").write_text(yaml.safe_dump(exp))
    return root


def _done_markers(exp: Path) -> dict:
    marks = {p.relative_to(exp).as_posix(): json.loads(p.read_text()) for p in (exp / "runs").rglob("done.json")}
    marks.update({p.name: json.loads(p.read_text()) for p in (exp / "maps").glob("*.done.json")})
    return marks


@pytest.mark.slow
def test_a_code_change_recomputes_every_result(fast_design, capsys, monkeypatch, tmp_path, fresh_fingerprint):
    from reloc.experiments import fingerprint as E

    exp = fast_design / "exp"
    argv = ["experiment", str(fast_design / "exp.yaml"), "--quiet", "--no-plots"]
    assert reloc_main(argv) == 0
    assert "4 runs and 1 maps computed now" in capsys.readouterr().out
    marks = _done_markers(exp)
    assert len(marks) == 5 and {m["code"] for m in marks.values()} == {E.code_fingerprint()}
    assert json.loads((exp / "results.json").read_text())["code"] == E.code_fingerprint()
    # the same code: nothing is recomputed
    assert reloc_main(argv) == 0
    assert "0 runs and 0 maps computed now" in capsys.readouterr().out
    assert _done_markers(exp) == marks
    # the same sources read from elsewhere, and a module reloc does not import changed: still nothing
    files = E.code_files()
    outside = [p for p in (REPO / "synth").rglob("*.py") if p not in set(files)]
    copy = tmp_path / "src"
    _copy_sources(copy, files + outside)
    _flip_one_byte(copy / next(p for p in outside if b"#" in p.read_bytes()).relative_to(REPO))
    monkeypatch.setattr(E, "SOURCE_ROOT", copy)
    E.code_fingerprint.cache_clear()
    assert reloc_main(argv) == 0
    assert "0 runs and 0 maps computed now" in capsys.readouterr().out
    # one byte of one covered module changed: every map and run is computed again, and says with what
    _flip_one_byte(copy / "vrformats" / "frames.py")
    E.code_fingerprint.cache_clear()
    changed = E.code_fingerprint()
    assert changed != marks["runs/videoreloc/apt_0__geometry__query/done.json"]["code"]
    assert reloc_main(argv) == 0
    assert "4 runs and 1 maps computed now" in capsys.readouterr().out
    again = _done_markers(exp)
    assert set(again) == set(marks) and {m["code"] for m in again.values()} == {changed}
    assert all(again[k]["key"] != marks[k]["key"] for k in marks)
    assert json.loads((exp / "results.json").read_text())["code"] == changed


# ---------------------------------------------------------------------------------------------
# the learned detector in runs, maps and experiments (tiny_design: query RGB every 150th frame,
# mapping RGB every 120th)


def test_learned_detector_needs_rgb_where_it_looks(tiny_design, tmp_path, capsys):
    """``reloc run --detector learned`` on a tour whose RGB misses the observation frames: one line
    naming the tour's meta.json and rgb_every, exit 2, nothing written."""
    tour = tiny_design / "tours" / "apt_1__night__query"
    gt_map = tmp_path / "gt.json"
    assert reloc_main(["map", "ground-truth", str(tiny_design / "tours" / "apt_0__day__mapping"),
                       "--out", str(gt_map)]) == 0
    capsys.readouterr()
    out = tmp_path / "run"
    assert reloc_main(["run", "--map", str(gt_map), "--tour", str(tour), "--out", str(out), "--detector", "learned",
                       "--quiet"]) == 2
    err = capsys.readouterr().err.strip()
    assert f"{tour}/meta.json: rgb_every: RGB on every 150th frame, but the learned detector looks at every 5th " \
           f"(observation.stride)" in err and len(err.splitlines()) == 1, err
    assert not out.exists()
    cfg = tmp_path / "cfg.yaml"
    cfg.write_text("observation: {stride: 150}\n")  # observe where the RGB is: it runs
    assert reloc_main(["run", "--map", str(gt_map), "--tour", str(tour), "--out", str(out), "--detector", "learned",
                       "--config", str(cfg), "--frames", "160", "--quiet"]) == 0
    run = json.loads((out / "run.json").read_text())
    assert run["detector"]["name"] == "learned" and run["detector"]["model"].endswith("detector_v2_160x120.onnx")


def test_geometry_only_tour_has_nothing_for_the_learned_detector(fast_design, tmp_path, capsys):
    tour = fast_design / "tours" / "apt_0__geometry__mapping"
    out = tmp_path / "map.json"
    assert reloc_main(["map", "build", str(tour), "--out", str(out), "--detector", "learned", "--quiet"]) == 2
    err = capsys.readouterr().err.strip()
    assert f"{tour}/meta.json: lighting: a geometry-only tour has no RGB" in err and len(err.splitlines()) == 1, err
    assert not out.exists()


def test_map_built_with_the_learned_detector(tiny_design, tmp_path, capsys):
    """Without ground-truth ids: the learned detector on the mapping tour's RGB frames (every 120th),
    fused across views by the untracked segmentation; its errors are reported against the truth."""
    tour = tiny_design / "tours" / "apt_0__day__mapping"
    out, rep = tmp_path / "map.json", tmp_path / "report.json"
    assert reloc_main(["map", "build", str(tour), "--out", str(out), "--report", str(rep), "--detector", "learned",
                       "--quiet"]) == 0
    line = capsys.readouterr().out
    r = json.loads(rep.read_text())
    assert r["build"]["frames_in_tour"] == 1800 and r["build"]["frames_used"] == 15, r["build"]
    doc = json.loads(out.read_text())
    assert doc["mapping"]["ids"] != "track"  # the learned detector knows no instance ids
    e = r["errors"]
    assert e["match"] == "nearest" and len(e["boxes"]) >= 5  # 15 views of a whole apartment find some
    assert "GT unobserved" in line and f"{len(doc['boxes'])} boxes" in line


@pytest.mark.slow
def test_experiment_with_the_learned_detector_and_the_oracle_row(tiny_design, tiny_pair, capsys):
    """The default detector is the learned one; ``videoreloc_oracle`` adds the labelled upper-bound
    row with its own map; both maps are scored against the ground truth in results.json."""
    spec = yaml.safe_load((tiny_design / "exp.yaml").read_text())
    spec.update({"out": str(tiny_design / "exp_learned"), "map": "build", "detector": "learned",
                 "methods": ["videoreloc", "videoreloc_oracle", "one_frame"], "one_frame_stride": 150,
                 "config": {"observation": {"stride": 150}}, "tours": str(tiny_pair)})
    (tiny_design / "exp_learned.yaml").write_text(yaml.safe_dump(spec))
    assert reloc_main(["experiment", str(tiny_design / "exp_learned.yaml"), "--quiet", "--no-plots"]) == 0
    text = capsys.readouterr().out
    res = json.loads((tiny_design / "exp_learned" / "results.json").read_text())
    assert res["detector"] == "learned (detector_v2_160x120.onnx)" and "detections: learned" in text
    keys = [r["key"] for r in res["rows"]]
    assert {"videoreloc.closure", "videoreloc_oracle.closure", "one_frame.causal"} <= set(keys)
    assert "VideoReloc (oracle detections), with clip closure" in text
    assert set(res["maps"]) == {"boxes", "boxes_oracle"}
    assert res["maps"]["boxes"]["frames_used"] == 15 and res["maps"]["boxes_oracle"]["frames_used"] == 360
    assert "Box map built with the learned" in text and "Box map built from oracle detections" in text
    runs = tiny_design / "exp_learned" / "runs"
    assert json.loads((runs / "videoreloc" / "apt_1__night__query" / "run.json").read_text())["detector"]["name"] \
        == "learned"
    assert json.loads((runs / "videoreloc_oracle" / "apt_1__night__query" / "run.json").read_text())["detector"][
        "name"] == "oracle"


@pytest.mark.slow
def test_a_sensor_sweep_end_to_end_with_its_table_plot_and_check(tiny_design, tiny_pair, capsys):
    """sweep: over the experiment's sensors (ideal and structured light with its noise doubled) on the
    tiny design: results.json carries each level's recall and interval, tables/sweep.md and
    plots/sweep.png are written, and reloc check reads the breaking point."""
    (tiny_design / "sl_x2.yaml").write_text(yaml.safe_dump({"name": "sl_x2", "base": "structured_light",
                                                             "noise_scale": 2}))
    spec = yaml.safe_load((tiny_design / "exp.yaml").read_text())
    spec.update({"out": str(tiny_design / "exp_sweep"), "methods": ["videoreloc"], "sensors": ["ideal", "sl_x2.yaml"],
                 "sweep": {"factor": "sensor", "levels": {0: "ideal", 2: "sl_x2"}, "fraction": 0.5},
                 "tours": str(tiny_pair)})
    (tiny_design / "exp_sweep.yaml").write_text(yaml.safe_dump(spec))
    assert reloc_main(["experiment", str(tiny_design / "exp_sweep.yaml"), "--quiet"]) == 0
    capsys.readouterr()
    exp = tiny_design / "exp_sweep"
    res = json.loads((exp / "results.json").read_text())
    run = res["sweep"]["runs"]["videoreloc.closure"]
    assert [r["level"] for r in run["levels"]] == [0, 2] and all(r["tours"] == len(PAIR) for r in run["levels"])
    for r in run["levels"]:
        assert r["ci"][0] - 1e-9 <= r["recall"] <= r["ci"][1] + 1e-9
    assert run["levels"][0]["recall"] == pytest.approx(res["methods"]["videoreloc"]["modes"]["closure"]["factors"]
                                                       ["sensor.ideal"])
    assert "Dose-response: sensor" in (exp / "tables" / "sweep.md").read_text()
    assert (exp / "plots" / "sweep.png").stat().st_size > 5000
    checks = tiny_design / "sweep_checks.yaml"
    checks.write_text(yaml.safe_dump({"checks": ["videoreloc.breaking_point.sensor >= 0", "videoreloc.sweep.0 >= 0"]}))
    assert reloc_main(["check", str(checks), str(exp)]) == 0


@pytest.mark.slow
def test_reloc_stages_puts_stage_variants_side_by_side(tiny_design, tiny_pair, tmp_path, capsys):
    """reloc stages (issue 55): two results folders of one design. The same results twice: every figure
    holds, spread 0. A copy whose VideoReloc closure recall is moved outside the first one's interval:
    that figure moves with the stage, by the difference; one line for bad input."""
    import shutil

    spec = yaml.safe_load((tiny_design / "exp.yaml").read_text())
    spec.update({"out": str(tmp_path / "a" / "experiment"), "methods": ["videoreloc"], "tours": str(tiny_pair),
                 "render": str(tiny_design / "render.yaml")})
    (tmp_path / "exp.yaml").write_text(yaml.safe_dump(spec))
    assert reloc_main(["experiment", str(tmp_path / "exp.yaml"), "--quiet", "--no-plots"]) == 0
    a = tmp_path / "a" / "experiment"
    shutil.copytree(a, tmp_path / "b" / "experiment")
    capsys.readouterr()
    assert reloc_main(["stages", str(a), str(tmp_path / "b" / "experiment"), "--json"]) == 0
    rows = {r["figure"]: r for r in json.loads(capsys.readouterr().out)}
    r = rows["videoreloc.closure.recall_1m_10deg"]
    assert set(r["stages"]) == {"a", "b"} and r["spread"] == 0 and r["holds"] is True
    lo, hi = r["stages"]["a"]["interval"]
    assert lo <= r["stages"]["a"]["value"] <= hi
    # stage b's recall moved below a's interval
    res_b = json.loads((tmp_path / "b" / "experiment" / "results.json").read_text())
    moved = max(0.0, lo - 0.2)
    res_b["methods"]["videoreloc"]["modes"]["closure"]["all"]["recall_1m_10deg"] = moved
    (tmp_path / "b" / "experiment" / "results.json").write_text(json.dumps(res_b))
    assert reloc_main(["stages", f"plain={a}", f"scan={tmp_path / 'b' / 'experiment'}", "--save", str(tmp_path / "s.json")]) == 0
    out = capsys.readouterr().out
    line = next(x for x in out.splitlines() if x.startswith("| VideoReloc, with clip closure |"))
    assert line.endswith("| moves |") and "| plain | scan |" in out
    saved = {r["figure"]: r for r in json.loads((tmp_path / "s.json").read_text())["rows"]}
    assert saved["videoreloc.closure.recall_1m_10deg"]["spread"] == pytest.approx(r["stages"]["a"]["value"] - moved)
    # bad input: one line, exit 2
    assert reloc_main(["stages", str(a)]) == 2
    assert "at least two stage variants" in capsys.readouterr().err
    assert reloc_main(["stages", str(a), str(tmp_path / "nothing")]) == 2
    assert "no results.json" in capsys.readouterr().err


def test_a_check_may_compare_with_another_metric_plus_an_offset(tmp_path, capsys):
    """'A >= B - 0.10' (issue 55: the learned detector within 10 points of oracle detections): B's value
    plus the offset; on figures with intervals the paired difference's bound is compared to the offset."""
    res = _results(tmp_path)
    checks = _write_checks(tmp_path, ["videoreloc.closure.recall_1m_10deg >= appearance.causal.recall_1m_10deg + 0.3",
                                      "videoreloc.closure.recall_1m_10deg >= appearance.causal.recall_1m_10deg + 0.5",
                                      "appearance.causal.recall_1m_10deg >= videoreloc.closure.recall_1m_10deg - 0.45"])
    assert reloc_main(["check", str(checks), str(res), "--json"]) == 1
    rows = json.loads(capsys.readouterr().out)
    assert [r["passed"] for r in rows] == [True, False, True]
    assert rows[0]["against"] == pytest.approx(0.8) and rows[0]["margin"] == pytest.approx(0.1)
    assert rows[2]["margin"] == pytest.approx(0.05)
    bad = _write_checks(tmp_path, ["videoreloc.kept >= 0.75 - 0.1"])
    assert reloc_main(["check", str(bad), str(res)]) == 2
    assert "an offset ('- 0.10') follows a metric" in capsys.readouterr().err
