"""tools/gpu_calibration.py, the script a GPU machine runs, on this machine's CPU: it prepares the built-in
design's calibration jobs, renders one preset in every lighting, packs the frames, and writes a
calibration file that the dry run's own reader (synth.jobs.estimate.load_calibration) accepts; the
report compares the packed frames with a second run's (the same device here: equal)."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[3]
TOOL = ROOT / "tools" / "gpu_calibration.py"


def tool(*argv):
    p = subprocess.run([sys.executable, str(TOOL), *map(str, argv)], capture_output=True, text=True, cwd=ROOT)
    assert p.returncode == 0, p.stdout[-2000:] + p.stderr[-2000:]
    return p.stdout


def test_prepare_run_pack_report(tmp_path):
    from synth.jobs.estimate import load_calibration

    prep, out, out2 = tmp_path / "prep", tmp_path / "out", tmp_path / "out2"
    tool("prepare", prep, "--frames", "3", "--size", "80x60")
    m = json.loads((prep / "manifest.json").read_text())
    assert list(m["apartments"]) == ["builtin"]  # no --replicacad-root
    a = m["apartments"]["builtin"]
    assert a["spec"] == "replicacad_6x3" and a["width"] == 80 and list(a["lightings"]) == ["day", "evening", "night"]
    for o in (out, out2):
        tool("run", prep, o, "--device", "cpu", "--middle-only", "--only", "preview/builtin/*")
    res = json.loads((out / "results.json").read_text())
    assert set(res["jobs"]) == {"geometry/builtin", "preview/builtin/day", "preview/builtin/evening", "preview/builtin/night"}
    assert all(r["ok"] and r["device"] == "CPU" and r["setup"]["layout_meshes"] >= 0 for r in res["jobs"].values())
    packed = tmp_path / "packed"
    tool("pack", out, packed)
    assert {p.name for p in packed.iterdir()} == {"geometry_builtin.npz", "rgb_builtin.npz", "results.json"}
    text = tool("report", prep, out, "--cpu", out2, "--calibration-dir", tmp_path / "cal")
    (f,) = (tmp_path / "cal").iterdir()
    cal = load_calibration(f)
    assert f.name == "calibration_replicacad_6x3_preview_gpu.json"
    assert cal["spec"]["quality"] == "preview" and set(cal["rgb_seconds_per_frame_by_lighting"]) == {"day", "evening", "night"}
    assert cal["startup_s"]["rgb"] > 0
    # the same CPU, seed and settings twice: depth and ids equal, RGB equal (PSNR inf)
    assert "| geometry/builtin | 1 |  | 0.00e+00 | 1.000000 |" in text
    assert "| preview/builtin/night | 1 | inf / inf |" in text
