"""formats.sensors: seeded RGB-D sensor models, checked against closed-form expectations on synthetic frames."""

from __future__ import annotations

import dataclasses
import hashlib
import math

import numpy as np
import pytest

from formats.camera import Intrinsics
from formats.errors import SceneFormatError
from formats.sensors import (ColorModel, DepthModel, Sensor, apply_sensor, frame_seed, incidence_angle, load_sensor,
                             parse_sensor)

W, H = 200, 160
KINECT = Intrinsics(W, H, 580.0, 580.0, (W - 1) / 2, (H - 1) / 2)  # Kinect-v1-like focal length


def rays(intr):
    u = (np.arange(intr.width) - intr.cx) / intr.fx
    v = (np.arange(intr.height) - intr.cy) / intr.fy
    return np.meshgrid(u, v)  # x, y of rays with z = 1


def wall(z, intr=KINECT):
    return np.full((intr.height, intr.width), z, dtype=np.float32)


def tilted_plane(alpha_deg, z0, intr):
    """Plane through (0, 0, z0) whose normal (sin a, 0, cos a) is tilted by alpha about the y axis:
    planar depth z = z0 / (1 + tan(a) x) along the ray (x, y, 1)."""
    x, _ = rays(intr)
    return (z0 / (1.0 + math.tan(math.radians(alpha_deg)) * x)).astype(np.float32)


def only_depth(**kw):
    return Sensor("test", DepthModel(**kw), ColorModel(), "test")


SL = load_sensor("structured_light")
TOF = load_sensor("tof")


# ------------------------------------------------------------------ axial noise


@pytest.mark.parametrize("z", [1.0, 2.0, 3.5])
def test_structured_light_axial_noise_matches_nguyen(z):
    sensor = dataclasses.replace(SL, depth=dataclasses.replace(SL.depth, baseline_m=0.0))  # Gaussian part only
    out, _ = apply_sensor(sensor, wall(z), None, KINECT, seed=11)
    # by hand from the preset's figures (Nguyen et al. 2012), plus their incidence term with the
    # closed-form angle between the wall normal (0, 0, 1) and each pixel's ray
    x, y = rays(KINECT)
    theta = np.arccos(1.0 / np.sqrt(x**2 + y**2 + 1.0))
    sig = 0.0012 + 0.0019 * (z - 0.4) ** 2 + 0.0001 / math.sqrt(z) * theta**2 / (math.pi / 2 - theta) ** 2
    assert np.all(out > 0)  # nothing dropped on a mid-range fronto-parallel wall without RGB
    err = out.astype(np.float64) - z
    assert np.std(err) == pytest.approx(math.sqrt(np.mean(sig**2)), rel=0.10)
    assert np.std(err) == pytest.approx(0.0012 + 0.0019 * (z - 0.4) ** 2, rel=0.10)  # the on-axis figure
    assert np.std(err / sig) == pytest.approx(1.0, rel=0.05)
    assert abs(np.mean(err)) < 4 * np.std(err) / math.sqrt(err.size)  # unbiased


@pytest.mark.parametrize("z", [1.0, 2.0, 3.5])
def test_structured_light_combined_with_quantisation(z):
    out, _ = apply_sensor(SL, wall(z), None, KINECT, seed=5)
    x, y = rays(KINECT)
    theta = np.arccos(1.0 / np.sqrt(x**2 + y**2 + 1.0))
    sig = 0.0012 + 0.0019 * (z - 0.4) ** 2 + 0.0001 / math.sqrt(z) * theta**2 / (math.pi / 2 - theta) ** 2
    dz = z**2 / (580.0 * 0.075) * 0.125  # depth step of one 1/8 px disparity step at z
    expected = math.sqrt(np.mean(sig**2) + dz**2 / 12.0)  # Gaussian + uniform quantisation error
    err = out[out > 0].astype(np.float64) - z
    assert err.size > 0.99 * out.size
    assert np.std(err) == pytest.approx(expected, rel=0.10)


@pytest.mark.parametrize("z", [1.0, 3.0])
def test_tof_noise_linear_in_range(z):
    out, _ = apply_sensor(TOF, wall(z), None, KINECT, seed=3)
    err = out.astype(np.float64) - z
    assert np.all(out > 0)
    assert np.std(err) == pytest.approx(0.0015 + 0.0015 * z, rel=0.10)


# ------------------------------------------------------------------ quantisation


def test_quantisation_levels_are_disparity_steps():
    f, B, step = 580.0, 0.075, 0.125
    x, _ = rays(KINECT)
    z = (1.5 + 0.3 * (x - x.min()) / (x.max() - x.min())).astype(np.float32)  # slanted: 1.5 .. 1.8 m
    out, _ = apply_sensor(only_depth(baseline_m=B, disparity_step_px=step), z, None, KINECT, seed=0)
    k_lo = round(f * B / (1.8 * step))
    k_hi = round(f * B / (1.5 * step))
    levels = np.array([f * B / (k * step) for k in range(k_lo, k_hi + 1)], dtype=np.float32)
    assert set(np.unique(out).tolist()) == set(levels.tolist())
    # and each pixel takes the level nearest its true disparity
    k = np.rint(f * B / z.astype(np.float64) / step)
    np.testing.assert_array_equal(out, (f * B / (k * step)).astype(np.float32))


def test_quantisation_focal_defaults_to_tour_fx():
    intr = Intrinsics(W, H, 400.0, 400.0, (W - 1) / 2, (H - 1) / 2)
    out, _ = apply_sensor(only_depth(baseline_m=0.075), wall(2.0, intr), None, intr, seed=0)
    k = round(400.0 * 0.075 / 2.0 / 0.125)
    assert np.all(out == np.float32(400.0 * 0.075 / (k * 0.125)))


# ------------------------------------------------------------------ dropouts


def test_incidence_angle_from_depth_matches_closed_form():
    intr = Intrinsics(160, 120, 300.0, 300.0, 79.5, 59.5)
    z = tilted_plane(50.0, 2.0, intr)
    x, y = rays(intr)
    n = np.array([math.sin(math.radians(50.0)), 0.0, math.cos(math.radians(50.0))])
    expected = np.arccos(np.abs(n[0] * x + n[2]) / np.sqrt(x**2 + y**2 + 1.0))
    np.testing.assert_allclose(incidence_angle(z, intr), expected, atol=1e-3)


@pytest.mark.parametrize("alpha, kept", [(82.0, False), (60.0, True)])
def test_grazing_incidence_dropout(alpha, kept):
    narrow = Intrinsics(160, 120, 2000.0, 2000.0, 79.5, 59.5)  # +-2.3 deg field: incidence ~ alpha everywhere
    z = tilted_plane(alpha, 2.0, narrow)
    assert z.min() > 0.5 and z.max() < 4.5
    out, _ = apply_sensor(SL, z, None, narrow, seed=1)
    valid = np.mean(out > 0)
    assert valid > 0.99 if kept else valid < 0.01


def test_out_of_range_is_zero():
    for z in (0.3, 5.0):
        for s in (SL, TOF, only_depth(min_range_m=0.5, max_range_m=4.5)):
            out, _ = apply_sensor(s, wall(z), None, KINECT, seed=2)
            assert np.all(out == 0), (s.name, z)
    out, _ = apply_sensor(only_depth(min_range_m=0.5, max_range_m=4.5), wall(4.0), None, KINECT, seed=2)
    assert np.all(out == np.float32(4.0))


def test_dark_patch_drops_depth_only_with_rgb():
    rgb = np.full((H, W, 3), 0.5, dtype=np.float32)
    rgb[40:80, 50:120] = 0.002  # luminance 0.002 < the preset's 0.01
    out, _ = apply_sensor(SL, wall(2.0), rgb, KINECT, seed=4)
    assert np.all(out[40:80, 50:120] == 0)
    outside = np.ones((H, W), bool)
    outside[40:80, 50:120] = False
    assert np.mean(out[outside] > 0) > 0.99
    out_no_rgb, _ = apply_sensor(SL, wall(2.0), None, KINECT, seed=4)
    assert np.mean(out_no_rgb[40:80, 50:120] > 0) > 0.99


def test_tof_depth_edges_fly_or_drop():
    intr = Intrinsics(200, 400, 580.0, 580.0, 99.5, 199.5)
    z = np.full((400, 200), 3.0, np.float32)
    z[:, :100] = 1.0  # edge between columns 99 and 100
    out, _ = apply_sensor(TOF, z, None, intr, seed=9)
    far = np.r_[0:98, 102:200]
    assert np.all(out[:, far] > 0)  # away from the edge: nothing dropped
    assert np.all(np.abs(out[:, far] - z[:, far]) < 6 * (0.0015 + 0.0015 * 3.0))
    edge = out[:, 99:101]
    dropped = np.mean(edge == 0)
    assert dropped == pytest.approx(0.5, abs=0.08)  # edge_dropout 0.5
    kept = edge[edge > 0]
    flying = np.mean((kept > 1.0 + 0.02) & (kept < 3.0 - 0.05))  # strictly between the two surfaces
    # flying probability 0.3, drawn independently of dropout; a uniform blend falls within the
    # 0.02 / 0.05 m margins with probability 0.965
    assert flying == pytest.approx(0.3 * 0.965, abs=0.08)


# ------------------------------------------------------------------ colour


def test_color_shot_and_read_noise():
    levels = [0.0, 0.01, 0.1, 0.5, 1.0]
    rgb = np.zeros((100, 100 * len(levels), 3), np.float32)
    for i, s in enumerate(levels):
        rgb[:, 100 * i:100 * (i + 1)] = s
    _, out = apply_sensor(SL, wall(2.0, Intrinsics(500, 100, 580, 580, 249.5, 49.5)), rgb,
                          Intrinsics(500, 100, 580, 580, 249.5, 49.5), seed=6)
    assert out.dtype == rgb.dtype and out.min() >= 0.0
    for i, s in enumerate(levels[1:], start=1):
        patch = out[:, 100 * i:100 * (i + 1)].astype(np.float64)
        assert np.std(patch) == pytest.approx(math.sqrt(s / 10000.0 + (3.0 / 10000.0) ** 2), rel=0.10)
        assert abs(np.mean(patch) - s) < 5 * np.std(patch) / math.sqrt(patch.size)
    black = out[:, :100]
    assert np.mean(black > 0) == pytest.approx(0.5, abs=0.05)  # read noise clipped at 0: half stay 0


# ------------------------------------------------------------------ seeding, identity, inputs


def test_same_seed_same_frame_other_seed_other_frame():
    z = tilted_plane(30.0, 2.0, KINECT)
    rgb = np.full((H, W, 3), 0.3, np.float32)
    for s in (SL, TOF):
        a = apply_sensor(s, z, rgb, KINECT, seed=123)
        b = apply_sensor(s, z, rgb, KINECT, seed=123)
        c = apply_sensor(s, z, rgb, KINECT, seed=124)
        np.testing.assert_array_equal(a[0], b[0])
        np.testing.assert_array_equal(a[1], b[1])
        assert not np.array_equal(a[0], c[0]) and not np.array_equal(a[1], c[1])
        # depth noise does not depend on whether the reader asked for RGB (no dark pixels here)
        np.testing.assert_array_equal(apply_sensor(s, z, None, KINECT, seed=123)[0], a[0])


def test_frame_seed_is_a_stable_hash():
    expected = int.from_bytes(hashlib.sha256("apt_0__day__query\x1f7\x1fstructured_light\x1f0".encode()).digest()[:8], "big") >> 1
    assert frame_seed("apt_0__day__query", 7, "structured_light") == expected == 2239792999303427310
    assert frame_seed("apt_0__day__query", 8, "structured_light") != expected
    assert frame_seed("apt_0__day__query", 7, "tof") != expected
    assert frame_seed("apt_0__day__query", 7, "structured_light", seed=1) != expected
    assert 0 <= expected < 2**63


def test_ideal_is_identity():
    ideal = load_sensor("ideal")
    assert ideal.is_ideal
    z = tilted_plane(30.0, 2.0, KINECT)
    rgb = np.random.default_rng(0).random((H, W, 3)).astype(np.float32)
    d, c = apply_sensor(ideal, z, rgb, KINECT, seed=1)
    np.testing.assert_array_equal(d, z)
    np.testing.assert_array_equal(c, rgb)
    assert apply_sensor(ideal, z, None, KINECT, seed=1)[1] is None


def test_inputs_not_modified_and_zero_stays_zero():
    z = tilted_plane(30.0, 2.0, KINECT)
    z[50:70, 60:90] = 0.0  # no-hit holes
    z[:, :5] = 0.0
    rgb = np.full((H, W, 3), 0.4, np.float32)
    z0, rgb0 = z.copy(), rgb.copy()
    for s in (SL, TOF):
        d, c = apply_sensor(s, z, rgb, KINECT, seed=8)
        np.testing.assert_array_equal(z, z0)
        np.testing.assert_array_equal(rgb, rgb0)
        assert d.dtype == np.float32 and d.shape == z.shape and c.shape == rgb.shape
        assert np.all(d[z0 == 0] == 0)
        assert np.mean(d[z0 > 0] > 0) > 0.9


# ------------------------------------------------------------------ bad input


def test_unknown_preset():
    with pytest.raises(SceneFormatError) as e:
        load_sensor("kinect_v7")
    assert "sensor_presets" in str(e.value) and "sensor" == e.value.field and "kinect_v7" in str(e.value)


@pytest.mark.parametrize("text, field", [
    ("depth:\n  sigma_a: -0.001\n", "depth.sigma_a"),
    ("depth:\n  sigma_b: .nan\n", "depth.sigma_b"),
    ("depth:\n  sigma_q: 0.1\n", "depth.sigma_q"),
    ("colour:\n  full_well_e: 100\n", "colour"),
    ("color:\n  read_noise_e: -3\n  full_well_e: 100\n", "color.read_noise_e"),
    ("depth:\n  edge_dropout: 1.5\n", "depth.edge_dropout"),
    ("depth:\n  max_incidence_deg: 120\n", "depth.max_incidence_deg"),
    ("depth:\n  sigma_a: abc\n", "depth.sigma_a"),
])
def test_bad_sensor_file_names_file_and_key(tmp_path, text, field):
    p = tmp_path / "cam.yaml"
    p.write_text("name: cam\n" + text)
    with pytest.raises(SceneFormatError) as e:
        load_sensor(p)
    assert e.value.field == field
    assert str(e.value).startswith(f"{p}: {field}: ")
    assert "\n" not in str(e.value)


def test_user_file_and_round_trip_of_presets(tmp_path):
    p = tmp_path / "cheap.yaml"
    p.write_text("name: cheap\nsource: my bench test\ndepth:\n  sigma_a: 0.004\n  max_range_m: null\n")
    s = load_sensor(str(p))
    assert s.name == "cheap" and s.source == "my bench test"
    assert s.depth.sigma_a == 0.004 and math.isinf(s.depth.max_range_m) and s.color.is_ideal
    for name in ("ideal", "structured_light", "tof"):
        assert load_sensor(name).name == name and load_sensor(name).source
    assert parse_sensor({"depth": {"sigma_a": 0.001}}, "x/y.yaml").name == "y"


# ---- a tour read through a sensor (formats.tour.Tour(sensor=...)) ----------------------------------


@pytest.fixture(scope="module")
def small_tour(tmp_path_factory):
    from synth.tour import TourSpec, render_tour

    out = tmp_path_factory.mktemp("tour") / "apt_0__geometry__query"
    render_tour(TourSpec(layout="apt_0", path="query", out=str(out), renderer="fast", width=64, height=48, frames=4),
                progress=False)
    return out


def test_a_tour_read_through_a_sensor(small_tour):
    from formats.tour import Tour

    plain = Tour(small_tour).frame(2)
    assert np.array_equal(Tour(small_tour, sensor="ideal").frame(2).depth, plain.depth)  # ideal: the render itself
    a = Tour(small_tour, sensor="structured_light").frame(2)
    b = Tour(small_tour, sensor="structured_light").frame(2, rgb=False, instance=False, semantic=False)
    assert not np.array_equal(a.depth, plain.depth) and np.array_equal(a.depth, b.depth)  # same noise for every reader
    assert np.array_equal(a.instance, plain.instance)  # labels are not measured by the camera
    valid = (a.depth > 0) & (plain.depth > 0)
    assert valid.mean() > 0.3 and np.median(np.abs(a.depth - plain.depth)[valid]) < 0.05
    c = Tour(small_tour, sensor="structured_light", sensor_seed=1).frame(2)
    assert not np.array_equal(a.depth, c.depth)  # another seed, other noise
    d = Tour(small_tour, sensor="structured_light").frame(3)
    assert not np.array_equal(a.depth[valid & (d.depth > 0)] - plain.depth[valid & (d.depth > 0)],
                              d.depth[valid & (d.depth > 0)] - plain.depth[valid & (d.depth > 0)])


def test_reloc_run_names_an_unknown_sensor(small_tour, tmp_path, capsys):
    from reloc.cli import main as reloc_main

    m = tmp_path / "map.json"
    assert reloc_main(["map", "ground-truth", str(small_tour), "--out", str(m)]) == 0
    assert reloc_main(["run", "--map", str(m), "--tour", str(small_tour), "--out", str(tmp_path / "run"),
                       "--sensor", "kinect9", "--detector", "oracle", "--quiet"]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "sensor" in err and "kinect9" in err, err
    assert not (tmp_path / "run").exists()
