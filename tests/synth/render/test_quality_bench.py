"""synth bench quality: a tiny run of the real thing (Cycles, 16x12, a few samples) and its bad input.

What is checked against what: the rows are the settings asked for, each rendered once; the paper
and standard presets are the paper preset at 64 and 16 samples, rows of the sweep too, so their images
(rendered in the same process, same seed) must measure the same; the references' own noise is read from their
difference; errors are one line naming the option."""

from __future__ import annotations

import json
import sys
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))
from cli_errors import exit_code, one_line_error  # noqa: E402

from synth.cli import main  # noqa: E402
from synth.render import quality  # noqa: E402


@pytest.fixture(scope="module")
def run(tmp_path_factory):
    d = tmp_path_factory.mktemp("quality")
    out = d / "q.json"
    rc = main(["bench", "quality", "--size", "16x12", "--lighting", "night", "--quick", "--reference-samples", "8",
               "--json-out", str(out), "--plot", str(d / "q.png")])
    return rc, json.loads(out.read_text()), d


def test_rows_times_and_measures(run):
    rc, doc, d = run
    assert rc == 0 and (d / "q.png").stat().st_size > 10_000
    (v,) = doc["views"]
    assert v["view"]["lighting_name"] == "night" and v["view"]["intrinsics"]["width"] == 16
    assert v["device"] == "CPU" and v["geometry_s"] > 0
    names = [r["setting"] for r in v["rows"]]
    want = [s["name"] for s in quality.settings_list(quick=True, reference_samples=8)]
    assert names == want
    assert {r["role"] for r in v["rows"]} == {"reference", "preset", "sweep"}
    for r in v["rows"]:
        assert r["seconds"] > 0 and r["over_geometry"] > 0
        if r["role"] != "reference":
            assert 0 < r["psnr_raw_db"] < 100 and -1 <= r["ssim"] <= 1
            assert r["psnr_db"] is None or r["psnr_db"] >= r["psnr_raw_db"]  # the reference's noise taken out
    # a preset that is the paper preset at one of the ladder's sample counts (paper, standard) measures as that row
    same = 0
    for p in (r for r in v["rows"] if r["role"] == "preset"):
        for r in v["rows"]:
            if r["role"] == "sweep" and not r["extra"] and {**quality.QUALITY["paper"], **r["cycles"]} == p["cycles"]:
                assert (p["psnr_raw_db"], p["ssim"]) == (r["psnr_raw_db"], r["ssim"]), (p["setting"], r["setting"])
                same += 1
    assert same == 2
    ref = v["reference"]
    assert ref["cycles"]["samples"] == 8 and len(ref["seconds"]) == 2
    assert ref["psnr_db"] == pytest.approx(ref["psnr_one_against_other_db"] + 6.02, abs=0.01)  # a quarter of the MSE


def test_report_and_cheapest(run):
    _, doc, _ = run
    text = quality.format_report(doc["views"])
    assert "| preset paper |" in text and "reference: the average of two renders of 8 samples" in text
    v = doc["views"][0]
    # a target below every row: the fastest row; above every row and the reference: none
    c = quality.cheapest(v, target_db=1.0)
    assert c is not None and c["seconds"] == min(r["seconds"] for r in v["rows"] if r["role"] != "reference")
    assert quality.cheapest(v, target_db=500.0) is None


@pytest.mark.parametrize("argv, names", [
    (["--size", "0x12"], ["--size", "WIDTHxHEIGHT"]),
    (["--size", "big"], ["--size"]),
    (["--lighting", "dusk"], ["--lighting dusk", "day"]),
    (["--replicacad-root", "/nowhere"], ["--replicacad-root", "replicacad_6x3"]),
    (["--spec", "no_such_spec"], ["no_such_spec"]),
])
def test_bad_input_is_one_line(argv, names, capsys, tmp_path):
    rc = exit_code(main, ["bench", "quality", "--quick", "--json-out", str(tmp_path / "q.json"), *argv])
    assert rc != 0
    one_line_error(capsys, *names)
    assert not (tmp_path / "q.json").exists()


def test_each_setting_renders_as_in_a_fresh_process(tmp_path, run):
    """With persistent data Cycles keeps the sampling pattern of the most samples rendered so far: the
    worker renders fewest samples first, so a 16-sample image after a 128-sample one (in the list) is
    the one a fresh process renders."""
    import subprocess

    import numpy as np

    from synth.render.settings import QUALITY

    v = run[1]["views"][0]["view"]

    def render(settings, out):
        job = {"layout": v["layout"], "lighting": v["lighting"], "pose": v["pose"], "intrinsics": v["intrinsics"], "seed": 0,
               "device": "cpu", "threads": 0, "out_dir": str(out), "base": dict(QUALITY["paper"]), "settings": settings}
        jf = tmp_path / f"{out.name}.json"
        jf.write_text(json.dumps(job))
        p = subprocess.run([sys.executable, "-m", "synth.blender.quality_worker", str(jf)], capture_output=True, text=True)
        assert p.returncode == 0, p.stderr[-1500:]
        return [np.load(out / f"{k}.npy") for k in range(len(settings))]

    both = render([{"cycles": {"samples": 128}}, {"cycles": {"samples": 16}}], tmp_path / "both")
    alone = render([{"cycles": {"samples": 16}}], tmp_path / "alone")
    assert np.array_equal(both[1], alone[0]) and not np.array_equal(both[0], both[1])
