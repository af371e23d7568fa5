"""Issue 42, parts 3 and 4: a night tour that would render black is refused before anything renders
(``synth.scene.lighting.dark_tour_problem``, ``synth render`` and its dry run), ``synth path show``
measures clearance from the path's own obstacle rule, and a dry run with ``--calibration`` prints
the estimate for this machine."""

from __future__ import annotations

import json
import os
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
import yaml

from vrformats.errors import SceneFormatError
from jobspecs import write_spec
from replicacad_real_fixture import write_real_fixture
from synth.cli import main as synth_main
from synth.jobs import expand, load_spec
from synth.paths.files import load_path, save_path
from synth.sources.replicacad.importer import load_replicacad
from synth.scene.lighting import DARK_MIN_FRAMES, chosen_lamps, dark_tour_problem, lamp_visibility, load_lighting
from synth.scene.model import dump_yaml, layout_to_dict, load_layout, object_box, resolve_layout_path

QUERY = Path(__file__).resolve().parents[3] / "scenes" / "paths" / "query.txt"


@pytest.fixture(scope="module")
def apt0_rc(tmp_path_factory):
    return load_replicacad(write_real_fixture(tmp_path_factory.mktemp("rcad_night")), "apt_0")


def _poses(n=400):
    return np.asarray(load_path(QUERY).poses)[:n]


def test_shipped_night_tours_pass_and_a_lamp_in_a_cupboard_fails(apt0_rc):
    night = load_lighting("night")
    for name in ("apt_0", "apt_1", "apt_3"):  # the demo's night tours
        assert dark_tour_problem(night, load_layout(resolve_layout_path(name)), _poses(900)) is None
    from synth.paths.views import plan_views

    lay = apt0_rc.copy()
    poses = np.asarray(plan_views([lay], 120, seed=1).poses)
    assert dark_tour_problem(night, lay, poses) is None
    # the black tour: the lamp night lights first is shut in the fridge, the others are gone
    fridge = next(o for o in lay.objects if o.cls == "fridge")
    first = chosen_lamps(lay, 1)[0]
    lay.fixtures = [replace(f, position=tuple(object_box(fridge).center)) if f.id == first else f
                    for f in lay.fixtures if f.kind != "lamp" or f.id == first]
    why = dark_tour_problem(night, lay, poses)
    assert why is not None and "in sight from 0% of the tour's poses" in why
    assert dark_tour_problem(load_lighting("day"), lay, poses) is None  # sunlit: not checked
    assert dark_tour_problem(night, lay, poses[: DARK_MIN_FRAMES - 1]) is None  # short tours are not checked
    lay.fixtures = [f for f in lay.fixtures if f.kind != "lamp"]
    assert "has none" in dark_tour_problem(night, lay, poses)


def test_segment_box_test_against_cases_worked_by_hand():
    from synth.scene.geometry import OrientedBox
    from synth.scene.lighting import _segments_hit_box

    box = OrientedBox(1, "cabinet", (2.0, 0.0, 1.0), (1.0, 0.4, 2.0), np.pi / 4)  # turned 45 deg
    a = np.array([[0.0, 0.0, 1.0], [0.0, 1.0, 1.0], [0.0, 0.0, 1.0], [0.0, 0.0, 3.0], [2.0, 0.0, 1.0], [4.0, 0.0, 1.0]])
    b = np.array([[4.0, 0.0, 1.0], [4.0, 1.0, 1.0], [1.5, 0.0, 1.0], [4.0, 0.0, 3.0], [2.0, 0.0, 1.5], [3.0, 0.0, 1.0]])
    # through it; 1 m beside it (the turned box reaches 0.49 m off its centre line); stopping at x 1.5,
    # short of its face on y = 0 (x = 2 - 0.2 / sin 45 deg = 1.717); over it; from inside it; beyond it
    assert _segments_hit_box(a, b, box).tolist() == [True, False, False, False, True, False]


def test_render_warns_of_a_black_night_tour_naming_the_field(tmp_path, capsys):
    lay = load_layout(resolve_layout_path("apt_0"))
    lay.name = "dark_flat"
    lay.objects = [o for o in lay.objects if o.cls not in ("table_lamp", "floor_lamp")]
    lay.fixtures = [f for f in lay.fixtures if f.kind != "lamp"]
    lf = tmp_path / "dark_flat.yaml"
    lf.write_text(dump_yaml(layout_to_dict(lay)))
    spec = write_spec(tmp_path, designs=[{"layouts": [str(lf)], "lightings": ["day", "night"],
                                          "path": {"name": "query", "frames": 200}}], out=str(tmp_path / "out"))
    plan = expand(load_spec(spec), check_light=True)
    assert len(plan.warnings) == 1
    assert plan.warnings[0].endswith(f"designs[0].lightings[1]: lighting 'night' lights only lamps, and layout "
                                     f"'dark_flat' has none in {lf} on path 'query'")
    assert expand(load_spec(spec)).warnings == []  # readers of rendered tours do not check


def test_path_show_uses_the_paths_obstacle_rule(tmp_path, capsys, apt0_rc):
    """A path planned with obstacles: band keeps 0.3 m from objects at the camera's height only; show
    measured it against every object (0.000 m: the floor rug under the camera) and named the
    built-in apt_0 in its hint."""
    lf = tmp_path / "apt_0.yaml"
    lf.write_text(dump_yaml(layout_to_dict(apt0_rc)))
    from synth.paths.shipped import plan_path

    path = plan_path("query", [apt0_rc], 300, seed=0, name="query", obstacles="band")
    path.meta["layouts"] = [str(lf)]
    pf = save_path(path, tmp_path / "query.txt")
    assert synth_main(["path", "show", str(pf)]) == 0
    out = capsys.readouterr().out
    line = next(ln for ln in out.splitlines() if "min clearance" in ln)
    assert "from band obstacles as planned" in line
    assert float(line.split(": ")[1].split(" m")[0]) >= 0.3 - 1e-3
    assert synth_main(["path", "show", str(pf), "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["obstacles"] == "band"


def test_dry_run_with_a_calibration_file_prints_this_machines_estimate(tmp_path, capsys):
    spec = write_spec(tmp_path, out=str(tmp_path / "out"))
    cal = {"format": "synth-calibration", "version": 1, "seconds_per_frame": {"geometry": 0.5, "rgb": 2.0},
           "cpu_count": 4, "device": "CPU", "devices": {}, "spec": {"quality": "preview", "width": 64, "height": 48},
           "date": "2026-01-01T00:00:00+00:00", "toolkit_version": "0.1.0"}
    f = tmp_path / "cal.json"
    f.write_text(json.dumps(cal))
    assert synth_main(["render", str(spec), "--dry-run", "--calibration", str(f)]) == 0
    out = capsys.readouterr().out
    line = next(ln for ln in out.splitlines() if "estimate with" in ln)
    here = os.cpu_count()
    assert f"({here} CPUs" in line
    if here != 4:
        assert f"the file's 4-CPU figures x {4 / here:g}" in line
    cal["device"] = "NVIDIA H200"
    cal["devices"] = {"rgb": "NVIDIA H200"}
    f.write_text(json.dumps(cal))
    assert synth_main(["render", str(spec), "--dry-run", "--calibration", str(f)]) == 0
    assert "no estimate for this machine: the calibration was measured on NVIDIA H200" in capsys.readouterr().out
