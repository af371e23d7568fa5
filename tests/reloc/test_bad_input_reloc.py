"""Bad input found by a user trial (issue 12): unwritable outputs, damaged frame files, off-grid
trajectories, and run.json recording the detector.

Every user error is one line on stderr naming the file (and field or line), exit status 2, no
traceback, nothing left behind; unwritable outputs are refused before any work. One tiny
geometry-only tour (fast renderer, 64x48, 30 frames) is rendered per module.
"""

from __future__ import annotations

import json
import shutil

import numpy as np
import pytest

from reloc.cli import main as reloc_main

from vrformats.camera import write_tum
from vrformats.frames import FrameFileError, read_channels
from vrformats.tour import Tour
from synth.cli import main as synth_main
from synth.scene.model import boxes_document, load_layout
from synth.tour.render import TourSpec, render_tour
from cli_errors import nothing_left, one_line_error


W, H, N = 64, 48, 30


@pytest.fixture(scope="module")
def world(tmp_path_factory):
    root = tmp_path_factory.mktemp("bad_input_reloc")
    d = root / "tour"
    render_tour(TourSpec(layout="apt_0", path="query", out=str(d), renderer="fast", width=W, height=H, frames=N),
                progress=False)
    m = root / "map.json"
    m.write_text(json.dumps(boxes_document(load_layout("apt_0"))))
    return {"tour": d, "map": m}


@pytest.fixture
def blocker(tmp_path):
    """A regular file where a folder is expected."""
    f = tmp_path / "a_file"
    f.write_text("not a folder\n")
    return f


def _tour_with(world, tmp_path, frame: int, data: bytes):
    """A copy of the tiny tour with one frame file replaced by ``data``."""
    d = tmp_path / "damaged"
    shutil.copytree(world["tour"], d)
    (d / "frames" / f"{frame:06d}.exr").write_bytes(data)
    return d


def _truncated(world, frame: int) -> bytes:
    b = (world["tour"] / "frames" / f"{frame:06d}.exr").read_bytes()
    return b[: len(b) // 2]


# ---------------------------------------------------------------------------------------------
# 1. unwritable --out: refused before any work, one line, exit 2


@pytest.mark.parametrize("where", ["under_file", "is_file", "proc"])
def test_reloc_run_unwritable_out_fails_fast(world, tmp_path, blocker, capsys, monkeypatch, where):
    import reloc.backend.run

    def no_work(*a, **k):
        raise AssertionError("the tour was processed before --out was checked")

    monkeypatch.setattr(reloc.backend.run, "relocalize", no_work)
    out = {"under_file": blocker / "run", "is_file": blocker, "proc": "/proc/forbidden"}[where]
    assert reloc_main(["run", "--map", str(world["map"]), "--tour", str(world["tour"]), "--out", str(out),
                       "--quiet"]) == 2
    one_line_error(capsys.readouterr().err, out)
    nothing_left(tmp_path, keep={"a_file"})
    assert blocker.read_text() == "not a folder\n"


def test_relocalize_checks_out_before_reading_frames(world, tmp_path, blocker, monkeypatch):
    """The API too: no frame is read when the output folder cannot be made."""
    import reloc.backend.run
    from reloc.map.boxmap import BoxMap
    from vrformats.errors import UserError

    def no_read(*a, **k):
        raise AssertionError("a frame was read before --out was checked")

    monkeypatch.setattr(reloc.backend.run, "read_frame", no_read)
    with pytest.raises(UserError, match="a_file"):
        reloc.backend.run.relocalize(Tour(world["tour"]), BoxMap.load(world["map"]), blocker / "run", progress=False)


@pytest.mark.parametrize("where", ["under_file", "proc"])
def test_reloc_map_build_unwritable_out_fails_fast(world, tmp_path, blocker, capsys, monkeypatch, where):
    import reloc.map.cli

    def no_work(*a, **k):
        raise AssertionError("the map was built before --out was checked")

    monkeypatch.setattr(reloc.map.cli, "build_map", no_work)
    out = blocker / "map.json" if where == "under_file" else "/proc/forbidden/map.json"
    assert reloc_main(["map", "build", str(world["tour"]), "--out", str(out), "--quiet"]) == 2
    one_line_error(capsys.readouterr().err, out)
    # the --report file is checked as well
    rep = blocker / "report.json"
    assert reloc_main(["map", "build", str(world["tour"]), "--out", str(tmp_path / "m.json"), "--report", str(rep),
                       "--quiet"]) == 2
    one_line_error(capsys.readouterr().err, rep)
    nothing_left(tmp_path, keep={"a_file"})


def test_reloc_map_build_out_is_a_folder(world, tmp_path, capsys):
    (tmp_path / "maps").mkdir()
    assert reloc_main(["map", "build", str(world["tour"]), "--out", str(tmp_path / "maps"), "--quiet"]) == 2
    assert "it is a folder" in one_line_error(capsys.readouterr().err, tmp_path / "maps")


def test_reloc_map_ground_truth_unwritable_out(world, tmp_path, blocker, capsys):
    out = blocker / "gt.json"
    assert reloc_main(["map", "ground-truth", str(world["tour"]), "--out", str(out)]) == 2
    one_line_error(capsys.readouterr().err, out)
    nothing_left(tmp_path, keep={"a_file"})


def test_reloc_experiment_unwritable_out_fails_fast(tmp_path, blocker, capsys, monkeypatch):
    import yaml

    import reloc.experiments.runner
    from jobspecs import write_experiment_spec

    def no_work(*a, **k):
        raise AssertionError("the design was read before --out was checked")

    monkeypatch.setattr(reloc.experiments.runner, "design_tours", no_work)
    spec = write_experiment_spec(tmp_path)
    out = blocker / "exp"
    assert reloc_main(["experiment", str(spec), "--out", str(out), "--quiet"]) == 2
    one_line_error(capsys.readouterr().err, out)
    # the spec's own out as well
    doc = yaml.safe_load(spec.read_text())
    spec.write_text(yaml.safe_dump({**doc, "out": str(blocker / "exp2")}))
    assert reloc_main(["experiment", str(spec), "--quiet"]) == 2
    one_line_error(capsys.readouterr().err, blocker / "exp2")
    nothing_left(tmp_path, keep={"a_file", "exp.yaml"})


@pytest.mark.parametrize("where", ["under_file", "is_folder", "proc"])
def test_synth_export_boxes_unwritable_out(tmp_path, blocker, capsys, where):
    (tmp_path / "folder").mkdir()
    out = {"under_file": blocker / "boxes.json", "is_folder": tmp_path / "folder",
           "proc": "/proc/forbidden/boxes.json"}[where]
    assert synth_main(["scene", "export-boxes", "apt_0", "--out", str(out)]) == 2
    one_line_error(capsys.readouterr().err, out)
    nothing_left(tmp_path, keep={"a_file", "folder"})
    assert not list((tmp_path / "folder").iterdir())


def test_output_checks_create_nothing(tmp_path):
    from vrformats.errors import check_output_file, check_output_folder

    check_output_folder(tmp_path / "a" / "b")
    check_output_file(tmp_path / "c" / "d.json")
    (tmp_path / "e.json").write_text("{}")
    check_output_file(tmp_path / "e.json")  # an existing file is overwritten
    nothing_left(tmp_path, keep={"e.json"})


# ---------------------------------------------------------------------------------------------
# 2. map building fails on a damaged frame, as reloc run does


@pytest.mark.parametrize("damage", ["truncated", "random"])
def test_map_build_fails_on_a_damaged_frame(world, tmp_path, capfd, damage):
    data = _truncated(world, 5) if damage == "truncated" else np.random.default_rng(0).bytes(3000)
    d = _tour_with(world, tmp_path, 5, data)  # frame 5: visited with the default stride of 5
    out = tmp_path / "m.json"
    assert reloc_main(["map", "build", str(d), "--out", str(out), "--quiet"]) == 2
    cap = capfd.readouterr()
    one_line_error(cap.err, d / "frames" / "000005.exr", "unreadable EXR")
    assert not out.exists() and not list(tmp_path.glob(".*tmp*"))


def test_map_build_fails_on_a_missing_frame(world, tmp_path, capsys):
    d = tmp_path / "partial"
    shutil.copytree(world["tour"], d)
    (d / "frames" / "000010.exr").unlink()
    assert reloc_main(["map", "build", str(d), "--out", str(tmp_path / "m.json"), "--quiet"]) == 2
    one_line_error(capsys.readouterr().err, d / "frames" / "000010.exr", "not found")
    assert not (tmp_path / "m.json").exists()


def test_map_build_of_the_intact_tour_still_works(world, tmp_path, capsys):
    assert reloc_main(["map", "build", str(world["tour"]), "--out", str(tmp_path / "m.json"), "--stride", "1",
                       "--quiet"]) == 0, capsys.readouterr().err
    assert json.loads((tmp_path / "m.json").read_text())["boxes"]


# ---------------------------------------------------------------------------------------------
# 3. a damaged EXR: a plain reason, and none of OpenEXR's noise


@pytest.mark.parametrize("data, reason", [
    ("truncated", "unreadable EXR (truncated or damaged)"),
    (b"not an exr", "unreadable EXR (not an EXR file)"),
    (b"", "unreadable EXR (not an EXR file, it is empty)"),
])
def test_damaged_exr_reason_without_library_noise(world, tmp_path, capfd, data, reason):
    p = tmp_path / "000000.exr"
    p.write_bytes(_truncated(world, 0) if data == "truncated" else data)
    with pytest.raises(FrameFileError) as e:
        read_channels(p)
    assert str(e.value) == f"{p}: {reason}"
    cap = capfd.readouterr()
    assert cap.out == "" and cap.err == "", cap
    print("still ours")  # the descriptors are back
    assert capfd.readouterr().out == "still ours\n"


def test_reloc_run_on_a_truncated_frame_is_one_clean_line(world, tmp_path, capfd):
    d = _tour_with(world, tmp_path, 3, _truncated(world, 3))
    out = tmp_path / "run"
    assert reloc_main(["run", "--map", str(world["map"]), "--tour", str(d), "--out", str(out), "--frames", "6",
                       "--poses", "gt", "--quiet"]) == 2
    cap = capfd.readouterr()
    line = one_line_error(cap.err, d / "frames" / "000003.exr", "unreadable EXR (truncated or damaged)")
    assert "EXR_ERR" not in cap.err + cap.out and "part index" not in line and "Warning" not in cap.out
    assert not out.exists()


# ---------------------------------------------------------------------------------------------
# 4. reloc eval: lines off the frame grid, past the tour or repeated are errors naming the line


def _run_dir(world, tmp_path, extra: str | None, after: int = 5):
    """A run output with the tour's ground truth as causal and closure; ``extra`` is inserted as
    a line after the ``after``-th pose line of causal.txt."""
    t = Tour(world["tour"])
    out = tmp_path / "run"
    for name in ("causal", "closure"):
        write_tum(out / f"{name}.txt", t.poses, fps=t.fps, frames=t.frame_indices, header="ground truth")
    if extra is not None:
        lines = (out / "causal.txt").read_text().splitlines()
        lines.insert(1 + after, extra)  # one header line
        (out / "causal.txt").write_text("\n".join(lines) + "\n")
    return out, t


@pytest.mark.parametrize("t_text, message", [
    ("1.65", "not a frame time"),  # frame 49.5 at 30 fps
    ("999", "frame 29970 (t = 999) is not in the tour"),
    ("-0.033333", "frame -1"),
    ("0.133333", "frame 4 (t = 0.133333) already given on line 6"),  # duplicate of frame 4
])
def test_eval_rejects_bad_trajectory_lines(world, tmp_path, capsys, t_text, message):
    out, t = _run_dir(world, tmp_path, None)
    line = (out / "causal.txt").read_text().splitlines()[1].split()
    out, _ = _run_dir(world, tmp_path / "x", " ".join([t_text] + line[1:]))
    assert reloc_main(["eval", str(out), "--gt", str(world["tour"])]) == 2
    err = one_line_error(capsys.readouterr().err, out / "causal.txt", "line 7", message)
    assert "Traceback" not in err


def test_eval_tolerates_float_print_noise(world, tmp_path, capsys):
    out, t = _run_dir(world, tmp_path, None)
    lines = (out / "closure.txt").read_text().splitlines()
    # times printed with 4 decimals: frame 1 at 30 fps is 0.0333 (t * fps = 0.999)
    lines[1:] = [" ".join([f"{float(ln.split()[0]):.4f}"] + ln.split()[1:]) for ln in lines[1:]]
    (out / "closure.txt").write_text("\n".join(lines) + "\n")
    assert reloc_main(["eval", str(out), "--gt", str(world["tour"]), "--json"]) == 0
    rep = json.loads(capsys.readouterr().out)
    assert rep["closure"]["recall_1m_10deg"] == 1.0 and rep["closure"]["coverage"] == 1.0


def test_read_tum_strict_off_by_default(tmp_path):
    """Other readers (paths, render jobs) keep reading any time as its nearest frame."""
    from vrformats.camera import read_tum

    p = tmp_path / "t.txt"
    p.write_text("1.65 0 0 0 0 0 0 1\n1.65 0 0 0 0 0 0 1\n")
    frames, _ = read_tum(p, fps=30.0)
    assert frames.tolist() == [50, 50]


# ---------------------------------------------------------------------------------------------
# 5. run.json records the detector and its corruption settings


def test_run_json_records_the_detector_and_its_corruption(world, tmp_path, capsys):
    out = tmp_path / "run"
    assert reloc_main(["run", "--map", str(world["map"]), "--tour", str(world["tour"]), "--out", str(out),
                       "--frames", "8", "--poses", "gt", "--miss-rate", "0.25", "--confusion-rate", "0.1",
                       "--mask-px", "2", "--spurious", "0.5", "--detector-seed", "7", "--seed", "3", "--quiet"]) == 0
    capsys.readouterr()
    run = json.loads((out / "run.json").read_text())
    assert run["detector"]["name"] == "oracle" and run["seed"] == 3
    assert run["detector"]["corruption"] == {"miss_rate": 0.25, "confusion_rate": 0.1, "mask_px": 2,
                                             "spurious_per_frame": 0.5, "seed": 7, "active": True}
    # a clean run says so
    clean = tmp_path / "clean"
    assert reloc_main(["run", "--map", str(world["map"]), "--tour", str(world["tour"]), "--out", str(clean),
                       "--frames", "8", "--poses", "gt", "--quiet"]) == 0
    c = json.loads((clean / "run.json").read_text())["detector"]["corruption"]
    assert c["active"] is False and c["miss_rate"] == 0.0


def test_experiment_runs_record_the_spec_detector(world, tmp_path):
    """The experiment's VideoReloc runs go through relocalize with the spec's ``detector`` settings."""
    from reloc.experiments.methods.common import detector_for as _detector
    from reloc.map.boxmap import BoxMap
    from reloc.backend.run import relocalize

    from reloc.config import Config

    t, bmap = Tour(world["tour"]), BoxMap.load(world["map"])
    det = _detector({"kind": "oracle", "corruption": {"miss_rate": 0.1, "seed": 5}}, t, bmap,
                    Config().replace("detection.min_mask_pixels", 7))
    assert det.min_pixels == 7  # the config's detection settings reach the detector
    relocalize(t, bmap, tmp_path / "run", detector=det, poses="gt", frames=6, progress=False)
    c = json.loads((tmp_path / "run" / "run.json").read_text())["detector"]["corruption"]
    assert c["miss_rate"] == 0.1 and c["seed"] == 5 and c["active"] is True


# ---------------------------------------------------------------------------------------------
# a fault sweep: the detector commands and reloc run's corruption options


def test_detector_eval_on_a_geometry_only_tour_is_one_line(world, capsys):
    from reloc.resources import SHIPPED_MODEL

    assert reloc_main(["detector", "eval", str(world["tour"]), "--model", str(SHIPPED_MODEL), "--quiet"]) == 2
    one_line_error(capsys, str(world['tour']), "no frame with RGB")


def test_detector_train_on_a_file_that_is_no_training_set_is_one_line(tmp_path, capsys):
    np.save(tmp_path / "a.npy", np.zeros(3))
    np.savez(tmp_path / "b.npz", x=np.zeros(3))
    (tmp_path / "c.txt").write_text("not an archive\n")
    for f, why in (("a.npy", "not an .npz archive"), ("b.npz", "holds header, blob and sizes"),
                   ("c.txt", "not an .npz archive")):
        assert reloc_main(["detector", "train", str(tmp_path / f), "--out", str(tmp_path / "run"), "--quiet"]) == 2
        one_line_error(capsys, tmp_path / f, "not a training set from reloc detector pack", why)
    assert not (tmp_path / "run").exists()


@pytest.mark.parametrize("option, value, says", [
    ("--spurious", "1e12", "--spurious: expected a mean from 0 to 100 detections per frame"),
    ("--spurious", "nan", "--spurious: expected a mean from 0 to 100"),
    ("--mask-px", "1000000000", "--mask-px: expected whole pixels from 0 to 64"),
    ("--mask-px", "-1", "--mask-px: expected whole pixels from 0 to 64"),
    ("--budget", "-1", "argument --budget: expected a positive integer"),
])
def test_reloc_run_refuses_corruption_and_budgets_out_of_range(world, tmp_path, capsys, option, value, says):
    try:
        rc = reloc_main(["run", "--map", str(world["map"]), "--tour", str(world["tour"]), "--out", str(tmp_path / "r"),
                         option, value, "--quiet"])
    except SystemExit as e:  # an option argparse refuses: its one-line error, then exit
        rc = e.code
    assert rc == 2
    one_line_error(capsys, says, prog=("reloc", "reloc run"))
    assert not (tmp_path / "r").exists()
