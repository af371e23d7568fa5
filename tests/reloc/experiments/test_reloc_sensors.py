"""The sensor factor of reloc experiment (issue 15): specs, the factor arithmetic, odometry drift and
clip end reasons against hand values, and a tiny design read through two sensors end to end."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest
import yaml

from vrformats.camera import pose_from_ypr
from reloc.cli import main as reloc_main
from reloc.experiments import tables
from reloc.evaluation import END_REASONS, end_reason_kind, odometry_drift
from jobspecs import write_experiment_spec

REPO = Path(__file__).resolve().parents[3]


# ---------------------------------------------------------------------------------------------
# figures against hand-computed values


def test_odometry_drift_against_hand_values():
    # a straight 4 m walk along x in 41 frames; the odometry overestimates the motion by 2 % and turns
    # by 0.5 deg per metre about z: endpoint error 0.08 m over 4 m (2 %), 2 deg over 4 m
    gt = {i: pose_from_ypr((0.1 * i, 0.0, 1.5), yaw=0.0) for i in range(41)}
    V = {}
    for i in range(41):
        T = np.linalg.inv(gt[0]) @ gt[i]
        a = math.radians(0.5 * 0.1 * i)  # about the camera's y axis
        Ry = np.array([[math.cos(a), 0, math.sin(a)], [0, 1, 0], [-math.sin(a), 0, math.cos(a)]])
        E = np.eye(4)
        E[:3, :3] = T[:3, :3] @ Ry
        E[:3, 3] = 1.02 * T[:3, 3]
        V[i] = E
    d = odometry_drift({0: V}, gt)
    assert d["clips"] == 1 and d["path_m"] == pytest.approx(4.0)
    assert d["drift_pct"] == pytest.approx(2.0, abs=1e-6)
    assert d["drift_deg_per_m"] == pytest.approx(0.5, abs=1e-6)
    assert d["median_drift_pct"] == pytest.approx(2.0, abs=1e-6)
    # a second, perfect clip of 1 m halves nothing but adds path: pooled 0.08 m / 5 m
    gt2 = {100 + i: pose_from_ypr((0.0, 0.1 * i, 1.5), yaw=1.0) for i in range(11)}
    V2 = {k: np.linalg.inv(gt2[100]) @ T for k, T in gt2.items()}
    d2 = odometry_drift({0: V, 1: V2}, {**gt, **gt2})
    assert d2["drift_pct"] == pytest.approx(100 * 0.08 / 5.0, abs=1e-6)
    assert d2["median_drift_pct"] == pytest.approx(1.0, abs=1e-6)  # median of 2 % and 0 %
    # clips of one frame or without ground truth count for nothing
    assert odometry_drift({0: {5: np.eye(4)}}, gt)["clips"] == 0
    assert odometry_drift({}, gt)["drift_pct"] is None


@pytest.mark.parametrize("reason, kind", [
    ("closed", "closed"), ("max length", "max length"), ("end of tour", "end of tour"),
    ("gap: fitness 0.20 < 0.3", "odometry failure"), ("gap: rotation 12.0 deg > 10 deg", "odometry failure"),
    ("gap", "odometry failure"), ("gap: no valid depth", "no usable depth"),
    ("gap: valid depth 2.0% < 5.0%", "no usable depth"), ("gap: reference frame: no valid depth", "no usable depth"),
])
def test_clip_end_reasons(reason, kind):
    assert end_reason_kind(reason) == kind and kind in END_REASONS


def test_sensor_factors_match_hand_computation():
    tours, per = {}, {}
    recall = {"ideal": {"apt_0": 0.9, "apt_1": 0.7}, "tof": {"apt_0": 0.8, "apt_1": 0.4}, "sl": {"apt_0": 0.5, "apt_1": 0.1}}
    for s, by_layout in recall.items():
        for layout, r in by_layout.items():
            for light in ("day", "night"):
                n = tables.reading_name(f"{layout}__{light}__query", s)
                tours[n] = {"layout": layout, "lighting": light, "sensor": s}
                per[n] = {"recall_1m_10deg": r - (0.1 if light == "night" else 0.0)}
    f = tables.factors(per, tours, "apt_0", ["ideal", "tof", "sl"], "ideal")
    # lighting and layout from the reference (ideal) tours only
    assert f["day"] == pytest.approx(0.8) and f["night"] == pytest.approx(0.7)
    assert f["unchanged"] == pytest.approx(0.85) and f["rearranged"] == pytest.approx(0.65)
    assert f["sensor.ideal"] == pytest.approx(0.75)
    assert f["sensor.tof"] == pytest.approx(0.55) and f["sensor.tof.delta"] == pytest.approx(-0.2)
    assert f["sensor.sl"] == pytest.approx(0.25) and f["sensor.sl.delta"] == pytest.approx(-0.5)
    assert "sensor.ideal.delta" not in f
    # one sensor: no sensor columns (Table II as before)
    ideal = {n: t for n, t in tours.items() if t["sensor"] == "ideal"}
    assert not any(k.startswith("sensor.") for k in tables.factors(per, ideal, "apt_0", ["ideal"], "ideal"))
    assert tables.reading_name("apt_0__day__query", "ideal") == "apt_0__day__query"
    assert tables.reading_name("apt_0__day__query", "tof") == "apt_0__day__query@tof"


# ---------------------------------------------------------------------------------------------
# bad specs: one line naming the file and the key, exit 2, nothing written


@pytest.mark.parametrize("changes, file, message", [
    ({"sensors": ["kinect9"]}, "exp.yaml", "sensors[0]: unknown sensor preset 'kinect9'; known: ideal, structured_light, tof"),
    ({"sensors": ["ideal", "tof", "tof"]}, "exp.yaml", "sensors[2]: sensor 'tof' is listed twice"),
    ({"sensors": []}, "exp.yaml", "sensors: expected a non-empty list"),
    ({"sensors": [3]}, "exp.yaml", "sensors[0]: expected a sensor preset name or a sensor YAML file"),
    ({"sensors": ["ideal", "missing.yaml"]}, "exp.yaml", "sensors[1]: sensor file"),
    ({"sensors": ["ideal", "nan.yaml"]}, "nan.yaml", "depth.sigma_a: expected a finite number, got nan"),
    ({"sensors": ["ideal", "neg.yaml"]}, "neg.yaml", "depth.lateral_px: must be >= 0.0"),
    ({"sensors": ["ideal", "fake_ideal.yaml"]}, "exp.yaml", "the name 'ideal' is the preset without effects"),
    ({"sensors": ["ideal", "badname.yaml"]}, "badname.yaml", "name: expected a name of letters"),
    ({"map_sensor": "kinect9"}, "exp.yaml", "map_sensor: unknown sensor preset"),
    ({"seed": -1}, "exp.yaml", "seed: expected a non-negative integer"),
])
def test_bad_sensor_specs_are_one_line_exit_2(tmp_path, capsys, changes, file, message):
    (tmp_path / "nan.yaml").write_text("name: nan\ndepth: {sigma_a: .nan}\n")
    (tmp_path / "neg.yaml").write_text("name: neg\ndepth: {lateral_px: -1}\n")
    (tmp_path / "fake_ideal.yaml").write_text("name: ideal\ndepth: {sigma_a: 0.01}\n")
    (tmp_path / "badname.yaml").write_text("name: my.sensor\ndepth: {sigma_a: 0.01}\n")
    assert reloc_main(["experiment", str(write_experiment_spec(tmp_path, **changes)), "--quiet"]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("reloc: error:") and message in err and len(err.splitlines()) == 1, err
    assert f"{tmp_path / file}" in err, err
    assert not (tmp_path / "exp").exists()


# ---------------------------------------------------------------------------------------------
# a tiny design through two sensors, end to end


@pytest.fixture(scope="module")
def sensor_design(tmp_path_factory):
    """Two 150-frame geometry-only query tours (apt_0, apt_1) and a 30-frame mapping tour, 64x48;
    an experiment reading them through the ideal sensor and a user-defined one."""
    from synth.jobs import load_spec, run_job

    root = tmp_path_factory.mktemp("sensor_design")
    render = {"name": "fast", "out": str(root / "tours"), "renderer": "fast", "size": [64, 48], "chunk_size": 600,
              "designs": [{"layouts": ["apt_0", "apt_1"], "path": {"name": "query", "frames": 150}},
                          {"layouts": ["apt_0"], "path": {"name": "mapping", "frames": 30}}]}
    (root / "render.yaml").write_text(yaml.safe_dump(render))
    assert run_job(load_spec(root / "render.yaml"), progress=False)["failed"] == {}
    (root / "noisy.yaml").write_text("name: noisy\nsource: a test sensor\n"
                                     "depth: {sigma_a: 0.002, sigma_b: 0.0015, max_range_m: 6.0, lateral_px: 0.3}\n")
    exp = {"name": "sensors", "render": "render.yaml", "out": str(root / "exp"), "query": "query", "unchanged": "apt_0",
           "mapping": {"layout": "apt_0", "lighting": "geometry", "path": "mapping"}, "map": "ground-truth",
           "methods": ["videoreloc"], "workers": 1, "detector": "oracle", "sensors": ["ideal", "noisy.yaml"], "seed": 1}
    (root / "exp.yaml").write_text(yaml.safe_dump(exp))
    return root


@pytest.mark.slow
def test_experiment_through_two_sensors(sensor_design, capsys):
    root = sensor_design
    exp = root / "exp"
    argv = ["experiment", str(root / "exp.yaml"), "--quiet"]
    assert reloc_main(argv) == 0
    out = capsys.readouterr().out
    assert "4 runs and 2 maps computed now" in out  # 2 tours x 2 sensors; a (ground-truth) map per sensor
    for t in ("apt_0__geometry__query", "apt_1__geometry__query"):
        assert (exp / "runs" / "videoreloc" / t / "closure.txt").is_file()
        assert (exp / "runs" / "videoreloc" / f"{t}@noisy" / "closure.txt").is_file()
    res = json.loads((exp / "results.json").read_text())
    assert res["sensors"] == ["ideal", "noisy"] and res["reference_sensor"] == "ideal"
    assert res["tours"]["apt_1__geometry__query@noisy"]["sensor"] == "noisy"
    mode = res["methods"]["videoreloc"]["modes"]["closure"]
    f = mode["factors"]
    per = mode["tours"]
    assert f["sensor.noisy"] == pytest.approx(np.mean([per[f"{t}@noisy"]["recall_1m_10deg"] for t in
                                                       ("apt_0__geometry__query", "apt_1__geometry__query")]))
    assert f["sensor.noisy.delta"] == pytest.approx(f["sensor.noisy"] - f["sensor.ideal"])
    # Table I and the layout columns pool the reference sensor's tours only
    assert mode["all"]["frames"] == 300 and mode["sensors"]["noisy"]["frames"] == 300
    assert f["unchanged"] == pytest.approx(per["apt_0__geometry__query"]["recall_1m_10deg"])
    odo = res["sensor_figures"]["noisy"]["odometry"]
    assert odo["clips"] >= 2 and odo["drift_pct"] is not None and odo["drift_pct"] >= 0
    assert sum(res["sensor_figures"]["ideal"]["clip_ends"].values()) == res["sensor_figures"]["ideal"]["odometry"]["clips"]
    md = (exp / "tables" / "sensors.md").read_text()
    assert "| noisy |" in md and "drift (% of path)" in md
    iv = mode["intervals"]["sensors"]["noisy"]["recall_1m_10deg"]  # the table prints each recall's interval
    row = next(ln for ln in md.splitlines() if ln.startswith("| noisy |"))
    assert f"{100 * mode['sensors']['noisy']['recall_1m_10deg']:.1f} [{100 * iv[0]:.1f}, {100 * iv[1]:.1f}]" in row
    assert "95 % interval" in md
    fac = (exp / "tables" / "factors.md").read_text()
    assert "Δ noisy" in fac and "(lighting and layout: sensor ideal)" in fac
    assert (exp / "plots" / "tour_apt_0__geometry__query_noisy.png").is_file()
    # the check language reaches every sensor figure
    checks = root / "checks.yaml"
    checks.write_text(yaml.safe_dump({"checks": [
        "videoreloc.sensor.noisy >= 0", "videoreloc.sensor.noisy.delta <= 1", "videoreloc.closure.sensor.noisy.coverage > 0",
        "sensor.noisy.drift_pct >= 0", "sensor.ideal.odometry_failure_fraction >= 0",
        "videoreloc.closure.apt_0__geometry__query@noisy.coverage > 0"]}))
    assert reloc_main(["check", str(checks), str(exp)]) == 0
    capsys.readouterr()
    # a rerun computes nothing; an edited sensor file recomputes that sensor's runs only
    assert reloc_main(argv) == 0
    assert "0 runs and 0 maps computed now" in capsys.readouterr().out
    (root / "noisy.yaml").write_text((root / "noisy.yaml").read_text().replace("sigma_a: 0.002", "sigma_a: 0.003"))
    assert reloc_main(argv) == 0
    assert "2 runs and 0 maps computed now" in capsys.readouterr().out


def test_built_maps_see_the_sensor(sensor_design, tmp_path, capsys):
    """map: build with two sensors: each box map is built from the mapping tour read through its
    sensor, the same as building it by hand from that reading (and the two differ)."""
    from vrformats.tour import Tour
    from reloc.map.build import build_map
    from reloc.map.document import dumps_map

    root = sensor_design
    sensor = tmp_path / "coarse.yaml"  # coarse enough to move the boxes of the 30-frame mapping tour
    sensor.write_text("name: coarse\ndepth: {sigma_a: 0.02, sigma_b: 0.01}\n")
    doc = yaml.safe_load((root / "exp.yaml").read_text())
    doc.update(render=str(root / "render.yaml"), out=str(tmp_path / "exp"), map="build", sensors=["ideal", str(sensor)])
    (tmp_path / "exp.yaml").write_text(yaml.safe_dump(doc))
    assert reloc_main(["experiment", str(tmp_path / "exp.yaml"), "--quiet", "--no-plots"]) == 0
    capsys.readouterr()
    maps = tmp_path / "exp" / "maps"
    mtour = root / "tours" / "apt_0__geometry__mapping"
    for f, s in ((maps / "videoreloc_map.json", None), (maps / "coarse" / "videoreloc_map.json", sensor)):
        assert f.read_text() == dumps_map(build_map(Tour(mtour, sensor=s, sensor_seed=1), progress=False)[0])
    assert (maps / "videoreloc_map.json").read_text() != (maps / "coarse" / "videoreloc_map.json").read_text()


def test_a_sensor_for_another_resolution_is_refused(sensor_design, tmp_path, capsys):
    root = sensor_design
    (tmp_path / "vga.yaml").write_text("name: vga\nresolution: [640, 480]\ndepth: {sigma_a: 0.001}\n")
    doc = yaml.safe_load((root / "exp.yaml").read_text())
    doc.update(render=str(root / "render.yaml"), out=str(tmp_path / "exp"), sensors=["ideal", "vga.yaml"])
    (tmp_path / "exp.yaml").write_text(yaml.safe_dump(doc))
    assert reloc_main(["experiment", str(tmp_path / "exp.yaml"), "--quiet"]) == 2
    err = capsys.readouterr().err.strip()
    assert f"{tmp_path / 'vga.yaml'}: resolution: sensor 'vga' is 640x480, but tour" in err and "is 64x48" in err
    assert len(err.splitlines()) == 1 and not (tmp_path / "exp").exists()
    # the same through reloc run
    assert reloc_main(["run", "--map", str(root / "exp" / "maps" / "videoreloc_map.json"), "--tour",
                       str(root / "tours" / "apt_0__geometry__query"), "--out", str(tmp_path / "run"),
                       "--sensor", str(tmp_path / "vga.yaml"), "--quiet"]) == 2
    assert "resolution" in capsys.readouterr().err
