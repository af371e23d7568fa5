"""Graded rearrangement (synth.layout.graded, ``synth scene grade``): nested levels of change.

Nesting is checked on the written files, by comparing every object's pose with the base's
(not through the operator's own bookkeeping); level 0 is compared with the shipped layout file
byte for byte; validity through synth's layout check and the shipped query path's clearance.
"""

from __future__ import annotations

import pytest

from vrformats.errors import UserError
from synth.cli import main as synth_main
from synth.layout.graded import BEYOND, check_strengths, graded_variants, level_name, moved_ids
from synth.layout.validity import check_layout
from synth.paths.clearance import clearance_report
from synth.paths.files import load_path
from synth.scene.model import load_layout, resolve_layout_path

LEVELS = [0.0, 0.1, 0.25, 0.5, 1.0]


@pytest.fixture(scope="module")
def graded(tmp_path_factory):
    out = tmp_path_factory.mktemp("graded")
    assert synth_main(["scene", "grade", "apt_0", "--levels", *map(str, LEVELS), "--beyond", "--seed", "3",
                       "--out", str(out)]) == 0
    return out


@pytest.mark.slow
def test_levels_are_nested_valid_and_level_0_is_the_base_byte_for_byte(graded):
    base = load_layout("apt_0")
    assert (graded / "apt_0.yaml").read_bytes() == resolve_layout_path("apt_0").read_bytes()
    path = load_path("query")
    prev, sizes = set(), []
    for lv in LEVELS[1:] + [BEYOND]:
        var = load_layout(graded / f"{level_name('apt_0', lv)}.yaml")
        moved = moved_ids(base, var)
        assert prev <= moved, lv  # each level keeps every move of the one below
        assert check_layout(var).ok, lv
        assert clearance_report(path, var)["ok"], lv
        sizes.append(len(moved))
        prev = moved
    assert sizes == sorted(sizes) and sizes[0] >= 5 and sizes[-2] >= 60  # 10 % moves some; 100 % most
    beyond = load_layout(graded / "apt_0_gbeyond.yaml")
    assert len({o.id for o in beyond.objects} - {o.id for o in base.objects}) > 0  # added
    assert len({o.id for o in base.objects} - {o.id for o in beyond.objects}) > 0  # removed
    fixed = [o for o in base.objects if not o.movable]
    assert any(o.id in moved_ids(base, beyond) for o in fixed)  # and the fixed fittings moved
    assert not any(o.id in moved_ids(base, load_layout(graded / "apt_0_g100.yaml")) for o in fixed)


def test_same_seed_same_levels_other_seed_other_moves():
    base = load_layout("apt_0")
    a = graded_variants(base, [0, 0.25], seed=1)
    b = graded_variants(base, [0, 0.25], seed=1)
    c = graded_variants(base, [0, 0.25], seed=2)
    assert a[0][1] is base and a[1][1] == b[1][1]
    assert moved_ids(base, a[1][1]) != moved_ids(base, c[1][1])
    # a level computed alone is the same layout as in a longer sweep: the sequence does not depend on the levels asked
    longer = dict(graded_variants(base, [0.1, 0.25, 0.5], seed=1))
    assert longer[0.25] == a[1][1]


@pytest.mark.parametrize("levels, message", [
    (["0", "1.5"], "expected a number in [0, 1]"),
    (["-0.1", "0.5"], "expected a number in [0, 1]"),
    (["0.5"], "at least two levels"),
    (["0.5", "0.5"], "listed twice"),
])
def test_bad_levels_are_one_line_exit_2_and_write_nothing(tmp_path, capsys, levels, message):
    out = tmp_path / "g"
    assert synth_main(["scene", "grade", "apt_0", "--levels", *levels, "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip()
    assert message in err and "--levels" in err and len(err.splitlines()) == 1
    assert not out.exists()
    with pytest.raises(UserError):
        check_strengths([float(x) for x in levels] + ([True] if levels == ["0.5"] else []))


# ---------------------------------------------------------------------------------------------
# the lighting dimmer and the sensor noise scale


def test_dimmer_runs_from_day_through_evening_to_night_and_below():
    import dataclasses

    from synth.scene.lighting import dimmed_preset, load_lighting

    def bare(p):
        return dataclasses.replace(p, name="", description="", source="")

    for level, name in ((0, "day"), (0.5, "evening"), (1.0, "night")):
        assert bare(dimmed_preset(level)) == bare(load_lighting(name))  # the shipped presets are its stops
    levels = [0, 0.25, 0.5, 0.75, 1.0, 1.25, 1.5]
    ps = [dimmed_preset(v) for v in levels]
    sun = [p.sun["strength"] if p.sun else 0.0 for p in ps]
    sky = [p.sky_strength for p in ps]
    assert sun == sorted(sun, reverse=True) and sky == sorted(sky, reverse=True) and sun[2] == 0.0
    assert 0 < sun[1] < sun[0]  # between day and evening the sun fades, not switches
    lamps = [(p.lamp.count, p.lamp.power) for p in ps[4:]]
    assert lamps[0][0] == 2 and lamps[1][0] == 1 and lamps[2][0] == 1 and lamps[0][1] > lamps[1][1] > lamps[2][1]
    assert [p.name for p in ps[:2]] == ["dimmer_0", "dimmer_0.25"]


@pytest.mark.parametrize("level", [1.6, -0.1, "dark", True])
def test_a_bad_dimmer_level_names_the_file_and_field(tmp_path, level):
    import yaml

    from vrformats.errors import SceneFormatError
    from synth.scene.lighting import load_lighting

    f = tmp_path / "dim.yaml"
    f.write_text(yaml.safe_dump({"name": "dim", "dimmer": level}))
    with pytest.raises(SceneFormatError) as e:
        load_lighting(f)
    assert e.value.field == "dimmer" and str(f) in str(e.value) and "[0, 1.5]" in str(e.value)
    f.write_text(yaml.safe_dump({"name": "dim", "dimmer": 0.75, "sun": None}))
    with pytest.raises(SceneFormatError, match="dimmer preset holds name, description and dimmer only"):
        load_lighting(f)


def test_a_dimmer_file_goes_through_a_render_job(tmp_path, capsys):
    """A render spec naming a dimmer file plans like any preset; a bad level stops it in one line,
    exit 2, before anything is written."""
    import yaml

    good, bad = tmp_path / "dim75.yaml", tmp_path / "dim9.yaml"
    good.write_text(yaml.safe_dump({"name": "dim75", "dimmer": 0.75}))
    bad.write_text(yaml.safe_dump({"name": "dim9", "dimmer": 9}))
    for lit, code in ((good, 0), (bad, 2)):
        spec = tmp_path / f"job_{lit.stem}.yaml"
        out = tmp_path / f"out_{lit.stem}"
        spec.write_text(yaml.safe_dump({"name": "j", "out": str(out), "size": [32, 24], "quality": "preview",
                                        "designs": [{"layouts": ["apt_0"], "lightings": [str(lit)],
                                                     "path": {"name": "query", "frames": 3}, "rgb_every": 1}]}))
        if code == 0:
            from synth.jobs import load_spec

            job = load_spec(spec)
            assert [str(x) for x in job.designs[0].lightings] == [str(good)]
            continue
        assert synth_main(["render", str(spec)]) == 2
        err = capsys.readouterr().err.strip()
        assert "dimmer" in err and "[0, 1.5]" in err and len(err.splitlines()) == 1 and not out.exists()


def test_noise_scale_multiplies_every_noise_and_0_is_ideal(tmp_path):
    import numpy as np
    import yaml

    from vrformats.camera import Intrinsics
    from vrformats.errors import SceneFormatError
    from vrformats.sensors import apply_sensor, load_sensor, scale_noise

    sl = load_sensor("structured_light")
    assert scale_noise(sl, 0).is_ideal
    h, w = 60, 80
    intr = Intrinsics(width=w, height=h, fx=50.0, fy=50.0, cx=40.0, cy=30.0)
    depth = np.full((h, w), 2.0, np.float32)
    for level in (0.5, 0.002):  # a bright frame and a night frame (exposure at its maximum, gain)
        img = np.full((h, w, 3), level, np.float32)
        img[:4] *= 2
        rgb = {k: apply_sensor(scale_noise(sl, k), depth, img, intr, seed=1)[1][8:].std() / level for k in (1, 2, 3)}
        assert rgb[2] / rgb[1] == pytest.approx(2.0, rel=0.08) and rgb[3] / rgb[1] == pytest.approx(3.0, rel=0.08)
    d = {k: apply_sensor(scale_noise(sl, k), depth, None, intr, seed=2)[0] for k in (1, 2)}
    assert d[2][d[2] > 0].std() / d[1][d[1] > 0].std() == pytest.approx(2.0, rel=0.1)
    f = tmp_path / "sl_x2.yaml"
    f.write_text(yaml.safe_dump({"name": "sl_x2", "base": "structured_light", "noise_scale": 2}))
    s2 = load_sensor(f)
    assert s2.name == "sl_x2" and s2.depth.sigma_a == pytest.approx(2 * sl.depth.sigma_a)
    f.write_text(yaml.safe_dump({"name": "sl_bad", "base": "structured_light", "noise_scale": -1}))
    with pytest.raises(SceneFormatError) as e:
        load_sensor(f)
    assert e.value.field == "noise_scale" and str(f) in str(e.value)


@pytest.mark.slow
def test_the_shipped_levels_come_from_the_command_they_name():
    """scenes/layouts/apt_0_g025 .. apt_0_gbeyond are what `synth scene grade apt_0 --levels 0 0.25
    0.5 0.75 1 --beyond --seed 0` makes (compared by class, pose to 1 mm and id, not byte for byte:
    placement is floating point, and another processor may differ in the last bit)."""
    import numpy as np

    base = load_layout("apt_0")
    walkway = np.asarray(load_path("query").poses)[::3, :2, 3]
    made = dict(graded_variants(base, [0, 0.25, 0.5, 0.75, 1.0], seed=0, walkway=walkway, beyond=True))
    for lv in (0.25, 0.5, 0.75, 1.0, BEYOND):
        shipped = load_layout(level_name("apt_0", lv))
        a = sorted((o.id, o.cls) for o in made[lv].objects)
        assert a == sorted((o.id, o.cls) for o in shipped.objects), lv
        by = shipped.by_id()
        for o in made[lv].objects:
            assert np.allclose(o.position, by[o.id].position, atol=1e-3), (lv, o.id)
