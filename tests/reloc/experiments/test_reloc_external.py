"""External relocalizers in reloc experiment: a command on exported tours and a folder of precomputed
trajectories, through the tables and reloc check, with predicted recall; failures, resume, bad specs.

The external program is written by the test: it reads the 7-Scenes export of a query tour with plain
numpy (not the exporter's code) and writes ACE-convention poses (world-to-camera) with a seeded error
of known size, so the recall is known before the experiment runs.
"""

from __future__ import annotations

import json
import sys
import textwrap
from pathlib import Path

import pytest
import yaml

from reloc.cli import main as reloc_main

REPO = Path(__file__).resolve().parents[3]
RGB_EVERY = 4
QUERY_FRAMES = 120

# the program: every frame of the export moved 0.1 m along x (inside 0.25 m / 5 deg), except
# frames whose index is a multiple of 12 (every third exported frame): moved 2 m (a failure)
PROGRAM = textwrap.dedent('''
    import sys, pathlib
    import numpy as np
    from scipy.spatial.transform import Rotation
    export, out, map_out = (pathlib.Path(a) for a in sys.argv[1:4])
    assert (map_out / "model.txt").read_text() == "trained", "map_command did not run first"
    lines = []
    for pose in sorted(export.glob("seq-*/frame-*.pose.txt")):
        index = int(pose.name.split("-")[1].split(".")[0])
        T = np.loadtxt(pose)                              # camera-to-world
        T[0, 3] += 2.0 if index % 12 == 0 else 0.1
        W = np.linalg.inv(T)                              # ACE writes world-to-camera
        x, y, z, w = Rotation.from_matrix(W[:3, :3]).as_quat()
        name = pose.name.replace(".pose.txt", ".color.png")
        lines.append(f"{name} {w} {x} {y} {z} {W[0, 3]} {W[1, 3]} {W[2, 3]} 0 0 0")
    (out / "poses.txt").write_text("\\n".join(lines) + "\\n")
''')
MAP_PROGRAM = "import sys, pathlib; (pathlib.Path(sys.argv[1]) / 'model.txt').write_text('trained')"


def _predicted(frames=QUERY_FRAMES) -> float:
    exported = [i for i in range(frames) if i % RGB_EVERY == 0]
    return sum(i % 12 != 0 for i in exported) / len(exported)


@pytest.fixture(scope="module")
def design(tmp_path_factory):
    from synth.jobs import load_spec, run_job

    root = tmp_path_factory.mktemp("external")
    render = {"name": "ext", "out": str(root / "tours"), "renderer": "blender", "geometry": "fast",
              "quality": "preview", "size": [64, 48], "chunk_size": 600, "designs": [
                  {"layouts": ["apt_0", "apt_1"], "lightings": ["day", "night"],
                   "path": {"name": "query", "frames": QUERY_FRAMES}, "rgb_every": RGB_EVERY},
                  {"layouts": ["apt_0"], "lightings": ["day"], "path": {"name": "mapping", "frames": 600}, "rgb_every": 60}]}
    (root / "render.yaml").write_text(yaml.safe_dump(render))
    assert run_job(load_spec(root / "render.yaml"), progress=False)["failed"] == {}
    (root / "noisy.py").write_text(PROGRAM)
    (root / "train.py").write_text(MAP_PROGRAM)
    return root


def _spec(root: Path, methods: list, name: str = "exp") -> Path:
    doc = {"name": name, "render": "render.yaml", "out": str(root / name), "query": "query", "unchanged": "apt_0",
           "mapping": {"layout": "apt_0", "lighting": "day", "path": "mapping"}, "map": "ground-truth",
           "detector": "oracle", "methods": methods, "workers": 1}
    p = root / f"{name}.yaml"
    p.write_text(yaml.safe_dump(doc, sort_keys=False))
    return p


def _noisy(root: Path, **kw) -> dict:
    return {"name": "noisy", "label": "Noisy ground truth (test program)", "export": "7scenes", "poses": "ace",
            "map_command": f"{sys.executable} {root / 'train.py'} {{map_out}}",
            "command": f"{sys.executable} {root / 'noisy.py'} {{query}} {{out}} {{map_out}}", **kw}


def _gt_recall_tum(folder: Path, tours: Path, shift_every: int) -> None:
    """Precomputed TUM trajectories: every frame of each query tour; frames multiple of ``shift_every`` moved 3 m."""
    from vrformats.camera import read_tum, write_tum

    folder.mkdir(parents=True, exist_ok=True)
    for t in sorted(tours.glob("*__query")):
        frames, poses = read_tum(t / "poses.txt", fps=30.0)
        out = []
        for i, T in zip(frames, poses):
            T = T.copy()
            T[1, 3] += 3.0 if i % shift_every == 0 else 0.0
            out.append(T)
        write_tum(folder / f"{t.name}.txt", out, fps=30.0, frames=list(frames))


@pytest.mark.blender
@pytest.mark.slow
def test_external_command_and_trajectories_through_tables_and_checks(design, capsys):
    root = design
    _gt_recall_tum(root / "slam", root / "tours", shift_every=5)
    spec = _spec(root, ["videoreloc", _noisy(root), {"name": "slam", "trajectories": "slam", "poses": "tum",
                                                      "label": "Precomputed SLAM"}])
    assert reloc_main(["experiment", str(spec), "--quiet"]) == 0
    out = capsys.readouterr().out
    res = json.loads((root / "exp" / "results.json").read_text())
    assert "Noisy ground truth (test program)" in (root / "exp" / "report.html").read_text()  # plots and report too
    noisy = res["methods"]["noisy"]["modes"]["causal"]
    assert noisy["all"]["recall_1m_10deg"] == pytest.approx(_predicted())  # exactly the predicted fraction
    assert noisy["all"]["recall_25cm_5deg"] == pytest.approx(_predicted())  # 0.1 m is inside 0.25 m too
    for tour in noisy["tours"].values():
        assert tour["recall_1m_10deg"] == pytest.approx(_predicted())
    slam = res["methods"]["slam"]["modes"]["causal"]["all"]
    assert slam["recall_1m_10deg"] == pytest.approx(1 - len(range(0, QUERY_FRAMES, 5)) / QUERY_FRAMES)
    assert res["methods"]["noisy"]["map_bytes"] == len("trained")
    # the rows and labels in Table I and the factors in Table II
    assert "Noisy ground truth (test program)" in out and "Precomputed SLAM" in out
    assert res["methods"]["noisy"]["modes"]["causal"]["factors"]["kept"] == pytest.approx(1.0)
    # reloc check keys
    checks = root / "checks.yaml"
    predicted = _predicted()
    checks.write_text(yaml.safe_dump({"checks": [
        f"noisy.causal.recall_1m_10deg >= {predicted - 1e-6}",
        f"noisy.recall_1m_10deg <= {predicted + 1e-6}",
        "noisy.delta_L == 0",
        "slam.causal.recall_1m_10deg > noisy.causal.recall_1m_10deg",
    ]}))
    # a comparison of two methods is decided on their paired interval: the 120-frame tours hold two
    # 100-frame segments, and in the second (20 frames) both score 0.8, so a resample of that one alone
    # ties them and the interval of the difference reaches 0
    assert reloc_main(["check", str(checks), str(root / "exp")]) == 1
    assert "slam.causal.recall_1m_10deg > noisy" in capsys.readouterr().out
    # in 12-frame segments every segment has slam at 0.75-0.83 and noisy at 2/3 (one failure among its three
    # exported frames): the difference is above 0 in every resample (re-evaluated only: nothing reruns)
    doc = yaml.safe_load(spec.read_text())
    spec.write_text(yaml.safe_dump({**doc, "intervals": {"segment_frames": 12}}, sort_keys=False))
    assert reloc_main(["experiment", str(spec), "--quiet", "--no-plots"]) == 0
    assert "0 runs and 0 maps computed now" in capsys.readouterr().out
    assert reloc_main(["check", str(checks), str(root / "exp")]) == 0
    checks.write_text(yaml.safe_dump({"checks": [f"noisy.causal.recall_1m_10deg >= {predicted + 0.01}"]}))
    assert reloc_main(["check", str(checks), str(root / "exp")]) == 1  # the check can fail
    # the exports were made once and hold what the command read
    exp_dir = root / "exp" / "exports" / "7scenes__auto"
    assert sorted(p.name for p in exp_dir.iterdir()) == sorted(
        ["apt_0__day__mapping"] + [p.name for p in (root / "tours").glob("*__query")])
    # a rerun recomputes nothing; a new version reruns the method (and only it)
    capsys.readouterr()
    stamps = {p: p.stat().st_mtime_ns for p in (root / "exp" / "runs").rglob("done.json")}
    assert reloc_main(["experiment", str(spec), "--quiet", "--no-plots"]) == 0
    assert "0 runs and 0 maps computed now" in capsys.readouterr().out
    assert stamps == {p: p.stat().st_mtime_ns for p in (root / "exp" / "runs").rglob("done.json")}
    spec2 = _spec(root, ["videoreloc", _noisy(root, version=2), {"name": "slam", "trajectories": "slam", "poses": "tum",
                                                                  "label": "Precomputed SLAM"}])
    assert reloc_main(["experiment", str(spec2), "--quiet", "--no-plots"]) == 0
    assert "5 runs and 0 maps" in capsys.readouterr().out  # noisy's map_command and its four query runs, nothing else


@pytest.mark.slow
@pytest.mark.blender
def test_external_command_reads_exports_through_every_sensor(design, capsys):
    """With sensors, the command's exports are the tours read through each sensor (the frames every
    other method gets), its map_command runs once per map sensor, and its rows count per sensor."""
    import numpy as np

    from vrformats.export import depth16, read_manifest
    from vrformats.tour import Tour

    root = design
    spec = _spec(root, [_noisy(root)], name="exp_sensors")
    doc = yaml.safe_load(spec.read_text())
    doc.update(sensors=["ideal", "tof"], seed=2)
    spec.write_text(yaml.safe_dump(doc, sort_keys=False))
    assert reloc_main(["experiment", str(spec), "--quiet", "--no-plots"]) == 0
    assert "10 runs and 2 maps computed now" in capsys.readouterr().out  # 4 tours x 2 sensors; a map per sensor
    exp = root / "exp_sensors"
    res = json.loads((exp / "results.json").read_text())
    noisy = res["methods"]["noisy"]["modes"]["causal"]
    assert noisy["factors"]["sensor.tof"] == pytest.approx(_predicted())  # poses do not depend on the sensor
    assert noisy["factors"]["sensor.tof.delta"] == pytest.approx(0.0)
    assert (exp / "maps" / "noisy@tof" / "model.txt").read_text() == "trained"
    ex = exp / "exports" / "7scenes__auto"
    for name in ("apt_0__day__mapping@tof", "apt_1__night__query@tof"):
        m = read_manifest(ex / name)
        assert m["sensor"]["name"] == "tof" and m["sensor"]["seed"] == 2
        tour = Tour(root / "tours" / name.split("@")[0], sensor="tof", sensor_seed=2)
        f = next(iter(m["frames"].items()))
        dpath = ex / name / f[0].replace(".color.png", ".depth.png")
        got = np.asarray(__import__("cv2").imread(str(dpath), -1))
        np.testing.assert_array_equal(got, depth16(tour.frame(f[1]).depth, 1000.0))
    assert read_manifest(ex / "apt_1__night__query").get("sensor") is None


@pytest.mark.blender
@pytest.mark.slow
def test_a_failing_command_is_a_failed_run_with_its_stderr(design, capsys):
    root = design
    (root / "fail.py").write_text("import sys\nif 'night' in sys.argv[1]:\n    sys.exit('boom: no GPU here')\n"
                                  "open(sys.argv[2] + '/poses.txt', 'w').close()\n")
    spec = _spec(root, ["videoreloc", {"name": "flaky", "export": "ace", "poses": "ace",
                                       "command": f"{sys.executable} {root / 'fail.py'} {{tour}} {{out}}"}], name="exp_fail")
    assert reloc_main(["experiment", str(spec), "--quiet", "--no-plots"]) == 1
    err = capsys.readouterr().err
    assert "flaky/apt_0__night__query: flaky on apt_0__night__query: exit status 1: boom: no GPU here" in err
    assert "flaky/apt_0__day__query: flaky on apt_0__day__query: wrote no poses" in err  # an empty file
    res = json.loads((root / "exp_fail" / "results.json").read_text())
    assert res["methods"]["videoreloc"]["modes"]["closure"]["all"]["recall_1m_10deg"] > 0  # the others went on
    assert res["methods"]["flaky"]["modes"]["causal"]["all"]["recall_1m_10deg"] == 0
    assert (root / "exp_fail" / "runs" / "flaky" / "apt_0__night__query" / "command.log").is_file()


@pytest.mark.parametrize("entry, field, message", [
    ({"name": "x", "command": "run {query} {outt}", "export": "ace", "poses": "ace"}, "methods[1].command",
     "unknown placeholder {outt}"),
    ({"name": "x", "command": "run {query}", "export": "jpeg", "poses": "ace"}, "methods[1].export", "one of 7scenes"),
    ({"name": "x", "command": "run {query}", "export": "ace", "poses": "guess"}, "methods[1].poses", "never guessed"),
    ({"name": "x", "command": "run {query}", "export": "ace"}, "methods[1].poses", "pose convention"),
    ({"name": "x", "command": "run {map_out}", "export": "ace", "poses": "ace"}, "methods[1].command", "add a map_command"),
    ({"name": "videoreloc", "command": "run", "export": "ace", "poses": "ace"}, "methods[1].name", "built-in"),
    ({"name": "x.y", "command": "run", "export": "ace", "poses": "ace"}, "methods[1].name", "letters, digits"),
    ({"name": "x", "command": "run", "trajectories": "t", "poses": "tum"}, "methods[1]", "either command"),
    ({"name": "x", "trajectories": "nowhere", "poses": "tum"}, "methods[1].trajectories", "not found"),
    ({"name": "x", "command": "run {query}", "export": "ace", "poses": "ace", "mode": "later"}, "methods[1].mode",
     "causal or closure"),
    ({"name": "x", "command": "run {query}", "export": "ace", "poses": "ace", "extra": 1}, "methods[1].extra",
     "unknown key"),
])
def test_bad_external_method_is_one_line(tmp_path, capsys, entry, field, message):
    doc = yaml.safe_load((REPO / "reloc" / "specs" / "demo_experiment.yaml").read_text())
    doc["render"] = str(REPO / "render_jobs" / "demo.yaml")
    doc["methods"] = ["videoreloc", entry]
    doc["out"] = str(tmp_path / "out")
    spec = tmp_path / "exp.yaml"
    spec.write_text(yaml.safe_dump(doc))
    assert reloc_main(["experiment", str(spec), "--quiet"]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and f"{spec}: {field}" in err and message in err, err
    assert not (tmp_path / "out").exists()
