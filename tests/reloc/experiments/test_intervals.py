"""Intervals on an experiment's figures (reloc.experiments.intervals): the block bootstrap over
segments of the query path, its pairing, its coverage on data with a known truth, and the spec key."""

from __future__ import annotations

import numpy as np
import pytest

from vrformats.errors import SceneFormatError
from reloc.experiments.intervals import (Bootstrap, IntervalSettings, factor_figures, figure_values, n_segments,
                                         pooled_figures, segment_counts)


def _units(outcomes: np.ndarray, frames_per_segment: int = 100) -> list[list[int]]:
    """Segment counts of a tour whose segment k succeeds on every frame (outcome 1) or on none (0)."""
    frames = np.arange(len(outcomes) * frames_per_segment)
    ok = np.repeat(outcomes.astype(bool), frames_per_segment)
    return segment_counts(frames, ok, ok, np.ones(len(frames), bool), frames_per_segment, len(outcomes))


def test_segment_counts_count_frames_successes_and_poses_per_segment():
    frames = [0, 1, 99, 100, 250]
    c = segment_counts(frames, [1, 0, 1, 1, 0], [0, 0, 1, 0, 0], [1, 1, 1, 1, 0], 100, n_segments(300, 100))
    assert c == [[3, 2, 1, 3], [1, 1, 0, 1], [1, 0, 0, 0]]
    assert n_segments(901, 100) == 10 and n_segments(900, 100) == 9 and n_segments(0, 100) == 1
    with pytest.raises(ValueError, match="beyond"):
        segment_counts([300], [1], [1], [1], 100, 3)


def test_point_value_is_the_pooled_recall_and_the_interval_holds_it():
    rng = np.random.default_rng(1)
    units = {"a.closure": {f"t{k}": _units(rng.random(9) < 0.7) for k in range(3)}}
    boot = Bootstrap(units, {f"t{k}": "query" for k in range(3)}, IntervalSettings(resamples=500))
    p, res = figure_values(boot, "a.closure", pooled_figures(["t0", "t1", "t2"])["recall_1m_10deg"])
    total = np.sum([np.sum(u, axis=0) for u in units["a.closure"].values()], axis=0)
    assert p == pytest.approx(total[1] / total[0])
    lo, hi = boot.interval(res)
    assert lo <= p <= hi and hi - lo > 0.05


def test_the_same_run_twice_differs_by_exactly_zero_because_draws_are_paired():
    rng = np.random.default_rng(2)
    tours = {f"t{k}": _units(rng.random(9) < 0.5) for k in range(4)}
    boot = Bootstrap({"a.closure": tours, "b.closure": dict(tours)}, {t: "query" for t in tours})
    fig = pooled_figures(list(tours))["recall_1m_10deg"]
    d = figure_values(boot, "a.closure", fig)[1] - figure_values(boot, "b.closure", fig)[1]
    assert boot.interval(d) == [0.0, 0.0]
    # and a difference that is there every time is found, even when both recalls are uncertain
    better = {t: [[n, min(n, s + 10), min(n, s2 + 10), pz] for n, s, s2, pz in u] for t, u in tours.items()}
    boot = Bootstrap({"a.closure": better, "b.closure": tours}, {t: "query" for t in tours})
    d = figure_values(boot, "a.closure", fig)[1] - figure_values(boot, "b.closure", fig)[1]
    lo, hi = boot.interval(d)
    assert lo > 0
    a_iv = boot.interval(figure_values(boot, "a.closure", fig)[1])
    b_iv = boot.interval(figure_values(boot, "b.closure", fig)[1])
    assert a_iv[0] < b_iv[1], "the two single intervals overlap: only pairing shows the difference"


def test_coverage_on_segment_correlated_data_is_near_nominal_where_frames_would_not_be():
    """A known truth: every frame of a segment shares one outcome, drawn with p = 0.7. The block
    bootstrap's 95 % interval holds p in most of 200 simulated experiments; one that counted frames
    as independent (a binomial interval over 3,000 frames) would hold it far less often."""
    rng = np.random.default_rng(3)
    p, hits, naive_hits = 0.7, 0, 0
    for _ in range(200):
        tours = {f"t{k}": _units(rng.random(10) < p) for k in range(3)}
        boot = Bootstrap({"m.closure": tours}, {t: "query" for t in tours}, IntervalSettings(resamples=400,
                                                                                            seed=int(rng.integers(1e6))))
        est, res = figure_values(boot, "m.closure", pooled_figures(list(tours))["recall_1m_10deg"])
        lo, hi = boot.interval(res)
        hits += lo <= p <= hi
        half = 1.96 * np.sqrt(est * (1 - est) / 3000)
        naive_hits += est - half <= p <= est + half
    assert hits / 200 >= 0.85, hits
    assert naive_hits / 200 < 0.5, naive_hits


def test_factor_figures_pair_lightings_and_layouts():
    tours = {"apt_0__day": {"lighting": "day", "layout": "apt_0"}, "apt_0__night": {"lighting": "night", "layout": "apt_0"},
             "apt_1__day": {"lighting": "day", "layout": "apt_1"}, "apt_1__night": {"lighting": "night", "layout": "apt_1"}}
    figs = factor_figures(tours, "apt_0", "ideal", ["ideal"], ("day", "evening", "night"))
    assert figs["delta_L"][0] == "diff" and figs["delta_L"][2] == (("apt_0__night", "apt_1__night"),
                                                                   ("apt_0__day", "apt_1__day"))
    assert figs["kept"][0] == "ratio" and "evening" not in figs
    units = {"m.closure": {t: _units(np.array([1, 1, 0, 1] if "day" in t else [1, 0, 0, 0])) for t in tours}}
    boot = Bootstrap(units, {t: "query" for t in tours}, IntervalSettings(resamples=300))
    p, res = figure_values(boot, "m.closure", figs["delta_L"])
    assert p == pytest.approx(0.25 - 0.75)
    lo, hi = boot.interval(res)
    assert lo <= p <= hi <= 0


def test_draws_do_not_depend_on_the_order_of_runs_or_tours():
    rng = np.random.default_rng(4)
    tours = {f"t{k}": _units(rng.random(7) < 0.6) for k in range(3)}
    fig = pooled_figures(["t0", "t1", "t2"])["recall_1m_10deg"]
    a = Bootstrap({"x.causal": {"z": tours["t0"]}, "m.closure": tours}, {**{t: "query" for t in tours}, "z": "query"})
    b = Bootstrap({"m.closure": dict(reversed(list(tours.items())))}, {t: "query" for t in tours})
    assert a.interval(figure_values(a, "m.closure", fig)[1]) == b.interval(figure_values(b, "m.closure", fig)[1])


def test_tours_of_one_path_must_have_the_same_segments():
    with pytest.raises(ValueError, match="segments"):
        Bootstrap({"m.closure": {"a": _units(np.ones(3)), "b": _units(np.ones(4))}}, {"a": "q", "b": "q"})


@pytest.mark.parametrize("doc, field", [
    ({"level": 1.5}, "intervals.level"), ({"level": "high"}, "intervals.level"),
    ({"resamples": 10}, "intervals.resamples"), ({"resamples": True}, "intervals.resamples"),
    ({"segment_frames": 0}, "intervals.segment_frames"), ({"seed": -1}, "intervals.seed"),
    ({"segments": 100}, "intervals.segments"), ([1, 2], "intervals"),
])
def test_bad_interval_settings_are_one_line_naming_the_key(doc, field):
    with pytest.raises(SceneFormatError) as e:
        IntervalSettings.from_spec("spec.yaml", doc)
    assert f"spec.yaml: {field}:" in str(e.value) and "\n" not in str(e.value)


def test_interval_settings_defaults_and_overrides():
    assert IntervalSettings.from_spec("s.yaml", None) == IntervalSettings()
    s = IntervalSettings.from_spec("s.yaml", {"level": 0.9, "resamples": 500, "segment_frames": 50, "seed": 7})
    assert (s.level, s.resamples, s.segment_frames, s.seed) == (0.9, 500, 50, 7)
