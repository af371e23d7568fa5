"""vrformats.sensors: seeded RGB-D sensor models, checked against closed-form expectations on synthetic frames."""

from __future__ import annotations

import dataclasses
import hashlib
import math

import numpy as np
import pytest

from vrformats.camera import Intrinsics
from vrformats.errors import SceneFormatError
from vrformats.sensors import (ColorModel, DepthModel, Motion, Sensor, apply_sensor, exposure, frame_seed,
                             incidence_angle, load_sensor, motion_blur, motion_flow, parse_sensor)

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


SL_DARK = dataclasses.replace(SL, depth=dataclasses.replace(SL.depth, dark_relative=0.02))
TOF_DARK = dataclasses.replace(TOF, depth=dataclasses.replace(TOF.depth, dark_relative=0.005))


def test_presets_keep_depth_in_the_dark():
    """The presets' dark dropout is off: the renders hold no IR reflectivity, and a luminance proxy
    would blank a night frame, which an active sensor does not do."""
    rgb = np.full((H, W, 3), 0.5, dtype=np.float32)
    rgb[40:80, 50:120] = 0.002
    for sensor in (SL, TOF):
        assert sensor.depth.dark_relative == 0
        out, _ = apply_sensor(sensor, wall(2.0), rgb, KINECT, seed=4)
        no_rgb, _ = apply_sensor(sensor, wall(2.0), None, KINECT, seed=4)
        np.testing.assert_array_equal(out, no_rgb)


def test_dark_patch_drops_depth_only_with_rgb():
    rgb = np.full((H, W, 3), 0.5, dtype=np.float32)
    rgb[40:80, 50:120] = 0.002  # luminance / p97 = 0.002 / 0.5 = 0.004 < 0.02
    out, _ = apply_sensor(SL_DARK, wall(2.0), rgb, KINECT, seed=4)
    assert np.all(out[40:80, 50:120] == 0)
    outside = np.ones((H, W), bool)
    outside[40:80, 50:120] = False
    assert np.mean(out[outside] > 0) > 0.99
    out_no_rgb, _ = apply_sensor(SL_DARK, wall(2.0), None, KINECT, seed=4)
    assert np.mean(out_no_rgb[40:80, 50:120] > 0) > 0.99


def relative_patches(level):
    """Background 0.5 (the 97th percentile) with patches at luminance ratios just below / above ``level``,
    and a bright no-depth region (a window) that must not move the reference."""
    rgb = np.full((H, W, 3), 0.5, dtype=np.float32)
    rgb[20:50, 20:60] = 0.5 * level * 0.9
    rgb[20:50, 100:140] = 0.5 * level * 1.1
    z = wall(2.0)
    z[100:160, :] = 0.0  # no depth: a window, 37.5 % of the frame ...
    rgb[100:160, :] = 50.0  # ... far brighter than anything with depth
    return z, rgb


@pytest.mark.parametrize("sensor, level", [(SL_DARK, 0.02), (TOF_DARK, 0.005)])
def test_dark_dropout_is_relative_to_the_frame(sensor, level):
    z, rgb = relative_patches(level)
    out, _ = apply_sensor(sensor, z, rgb, KINECT, seed=4)
    assert np.all(out[20:50, 20:60] == 0)  # ratio 0.9 * level: dropped
    assert np.all(out[20:50, 100:140] > 0)  # ratio 1.1 * level: kept (p97 over valid depth = 0.5, not 50)
    for scale in (1e-4, 1e3):  # a night-like frame (and a brighter one) drop exactly the same pixels
        night, _ = apply_sensor(sensor, z, (rgb * np.float32(scale)).astype(np.float32), KINECT, seed=4)
        np.testing.assert_array_equal(night, out)


def test_black_frame_has_no_dark_dropout():
    out, _ = apply_sensor(SL_DARK, wall(2.0), np.zeros((H, W, 3), np.float32), KINECT, seed=4)
    no_rgb, _ = apply_sensor(SL_DARK, wall(2.0), None, KINECT, seed=4)
    np.testing.assert_array_equal(out, no_rgb)
    assert np.mean(out > 0) > 0.99


def test_bright_relative_dropout():
    rgb = np.full((H, W, 3), 0.5, dtype=np.float32)
    rgb[0:3, :] = 0.5 * 3.5  # 1.9 % of the pixels: the 97th percentile stays 0.5
    rgb[3:4, :] = 0.5 * 2.5
    out, _ = apply_sensor(only_depth(bright_relative=3.0), wall(2.0), rgb, KINECT, seed=0)
    assert np.all(out[0:3] == 0) and np.all(out[3:] == np.float32(2.0))


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


CAM = ColorModel(electrons_per_ms=1000.0, full_well_e=10000.0, read_noise_e=3.0, exposure_percentile=97.0,
                 exposure_target=0.8, exposure_min_ms=0.05, exposure_max_ms=30.0, max_gain=8.0)


def only_color(m=CAM):
    return Sensor("test", DepthModel(), m, "test")


def grey(L, shape=(100, 100)):
    return np.full(shape + (3,), L, dtype=np.float32)


@pytest.mark.parametrize("L", [1000.0, 1.0, 0.5, 0.1, 0.01, 0.0])
def test_exposure_policy(L):
    # by hand: t = target * full_well / (electrons_per_ms * L) = 8 / L ms, clamped to [0.05, 30];
    # at 30 ms a gain of (8 / L) / 30, at most 8, makes up the rest; a black frame: the maximums
    want = 0.8 * 10000.0 / (1000.0 * L) if L else math.inf
    t_exp, gain = exposure(CAM, grey(L))
    assert t_exp == pytest.approx(min(max(want, 0.05), 30.0), rel=1e-6)  # rel: L is a float32
    assert gain == pytest.approx(min(max(want / 30.0, 1.0), 8.0), rel=1e-6)
    assert (gain > 1.0) == (t_exp == 30.0 and want > 30.0)  # gain only at the maximum exposure


def test_exposure_meters_the_chosen_percentile():
    rgb = grey(0.1)
    rgb[:5] = 1.0  # 5 % of the pixels: the 97th percentile is 1.0, the median 0.1
    assert exposure(CAM, rgb) == pytest.approx((8.0, 1.0))
    assert exposure(dataclasses.replace(CAM, exposure_percentile=50.0), rgb) == pytest.approx((30.0, 80.0 / 30.0))
    assert exposure(ColorModel(), rgb) == (0.0, 1.0)  # colour model off
    # Rec. 709 luminance: a pure green frame is metered at 0.7152 of its value
    g = np.zeros((10, 10, 3), np.float32)
    g[..., 1] = 1.0
    assert exposure(CAM, g)[0] == pytest.approx(8.0 / 0.7152)


@pytest.mark.parametrize("L_hi, L_lo", [(1.0, 0.05), (0.01, 0.004)])
def test_color_noise_in_electrons(L_hi, L_lo):
    """Two radiance levels in one frame (the brighter one sets the exposure); noise std in scene units
    sqrt(e + read^2) / (electrons_per_ms * t) with e = electrons_per_ms * t * L, whatever the gain."""
    rgb = grey(L_hi, (100, 200))
    rgb[:, 100:] = L_lo
    want = 0.8 * 10000.0 / (1000.0 * L_hi)
    t_exp, gain = min(want, 30.0), min(max(want / 30.0, 1.0), 8.0)  # (8 ms, 1) and (30 ms, 8)
    _, out = apply_sensor(only_color(), wall(2.0, Intrinsics(200, 100, 580, 580, 99.5, 49.5)), rgb,
                          Intrinsics(200, 100, 580, 580, 99.5, 49.5), seed=6)
    assert out.dtype == rgb.dtype and out.min() >= 0.0
    k = 1000.0 * t_exp  # electrons per unit of scene value
    for L, patch in ((L_hi, out[:, :100]), (L_lo, out[:, 100:])):
        patch = patch.astype(np.float64)
        e = k * L
        assert e * gain < 10000.0 - 8 * math.sqrt(e)  # no clipping in this check
        assert np.std(patch) == pytest.approx(math.sqrt(e + 3.0**2) / k, rel=0.10)
        assert abs(np.mean(patch) - L) < 5 * np.std(patch) / math.sqrt(patch.size)  # unbiased


def test_color_saturates_at_the_full_well():
    for L, bright, gain, t_exp in ((1.0, 5.0, 1.0, 8.0), (0.01, 1.0, 8.0, 30.0)):
        rgb = grey(L)
        rgb[:2] = bright  # 2 % of the pixels: the exposure is still set by L
        assert exposure(CAM, rgb) == pytest.approx((t_exp, gain))
        _, out = apply_sensor(only_color(), wall(2.0, Intrinsics(100, 100, 580, 580, 49.5, 49.5)), rgb,
                              Intrinsics(100, 100, 580, 580, 49.5, 49.5), seed=2)
        clip = 10000.0 / (gain * 1000.0 * t_exp)  # the digital value g e clips at the full well
        assert bright > clip
        np.testing.assert_allclose(out[:2], clip, rtol=1e-6)
        assert out.max() == pytest.approx(clip, rel=1e-6)


def test_black_pixels_read_noise_clipped_at_zero():
    rgb = grey(1.0)
    rgb[50:] = 0.0
    _, out = apply_sensor(only_color(), wall(2.0, Intrinsics(100, 100, 580, 580, 49.5, 49.5)), rgb,
                          Intrinsics(100, 100, 580, 580, 49.5, 49.5), seed=7)
    black = out[50:]
    assert np.mean(black > 0) == pytest.approx(0.5, abs=0.05)  # read noise clipped at 0: half stay 0
    # the positive half of N(0, 3 e-) in scene units: mean 3 sqrt(2 / pi) / (1000 * 8) over those
    assert np.mean(black[black > 0]) == pytest.approx(3.0 * math.sqrt(2 / math.pi) / 8000.0, rel=0.05)


def test_structured_light_colour_preset():
    # the preset: 2500 e-/ms at 1.0, full well 10,000 e-, read noise 3 e-: a frame whose 97th
    # percentile is 1.0 gets t = 0.8 * 10000 / 2500 ms and 8000 e- per unit of scene value
    levels = [0.0, 0.01, 0.1, 0.5, 1.0]
    rgb = np.zeros((100, 100 * len(levels), 3), np.float32)
    for i, v in enumerate(levels):
        rgb[:, 100 * i:100 * (i + 1)] = v
    intr = Intrinsics(500, 100, 580, 580, 249.5, 49.5)
    assert exposure(SL.color, rgb) == pytest.approx((8000.0 / 2500.0, 1.0))
    _, out = apply_sensor(SL, wall(2.0, intr), rgb, intr, seed=6)
    for i, v in enumerate(levels[1:], start=1):
        patch = out[:, 100 * i:100 * (i + 1)].astype(np.float64)
        assert np.std(patch) == pytest.approx(math.sqrt(8000.0 * v + 9.0) / 8000.0, rel=0.10)
        assert abs(np.mean(patch) - v) < 5 * np.std(patch) / math.sqrt(patch.size)


# ------------------------------------------------------------------ motion blur

BLUR_INTR = Intrinsics(96, 8, 200.0, 200.0, 47.5, 3.5)


def step_edge(intr=BLUR_INTR):
    """0 left of column 48, 1 from it on (per channel 1, 0.5, 0.25)."""
    rgb = np.zeros((intr.height, intr.width, 3), np.float32)
    rgb[:, intr.width // 2:] = [1.0, 0.5, 0.25]
    return rgb


def ramp(L, intr=BLUR_INTR):
    """A step at u = 47.5 (halfway between the pixels on either side, as bilinear sampling sees it)
    convolved with a box of width L px: a linear ramp of width L."""
    u = np.arange(intr.width, dtype=np.float64)
    return np.clip((u - (intr.width / 2 - 0.5)) / L + 0.5, 0.0, 1.0)


def pose(R=np.eye(3), t=(0.0, 0.0, 0.0)):
    T = np.eye(4)
    T[:3, :3], T[:3, 3] = R, t
    return T


def rot(axis, angle):
    from scipy.spatial.transform import Rotation

    return Rotation.from_rotvec(np.asarray(axis, float) / np.linalg.norm(axis) * angle).as_matrix()


T0 = pose(rot([0.3, -1.0, 0.2], 0.7), (1.0, 2.0, -0.5))  # an arbitrary world pose of the frame
DT = 1.0 / 30.0


def moving(T, R_rel=np.eye(3), d_rel=(0.0, 0.0, 0.0), prev=True, nxt=True):
    """Motion with neighbours at -DT / +DT: the camera moved by d_rel (its own axes) and turned by R_rel per frame."""
    d = np.asarray(d_rel, float)
    nb = pose(T[:3, :3] @ R_rel, T[:3, 3] + T[:3, :3] @ d)
    pb = pose(T[:3, :3] @ R_rel.T, T[:3, 3] - T[:3, :3] @ d)
    return Motion(T, pb if prev else None, nb if nxt else None, DT, DT)


def test_motion_flow_closed_form():
    intr = Intrinsics(40, 30, 100.0, 110.0, 19.5, 14.5)
    z = np.full((30, 40), 2.0)
    z[:, :10] = 0.0  # no depth: at infinity
    # the camera moved +0.1 m along its x axis: a point X is at X - (0.1, 0, 0) in the new camera,
    # so it appears fx * 0.1 / z px to the left; points at infinity do not move
    f = motion_flow(z, intr, np.eye(3), np.array([-0.1, 0.0, 0.0]))
    np.testing.assert_allclose(f[:, 10:, 0], -100.0 * 0.1 / 2.0, atol=1e-9)
    np.testing.assert_allclose(f[..., 1], 0.0, atol=1e-9)
    np.testing.assert_allclose(f[:, :10], 0.0, atol=1e-9)
    # a small turn about the y axis by a: the centre ray moves by fx * tan(a) px, whatever the depth
    a = 0.01
    R = rot([0, 1, 0], a).T  # camera turned by +a: points rotate by -a in its frame
    f = motion_flow(z, intr, R, np.zeros(3))
    x = (np.arange(40) - 19.5) / 100.0
    expected_u = 100.0 * np.tan(np.arctan(x) - a) + 19.5 - np.arange(40)  # row cy: exact
    np.testing.assert_allclose(f[14:16, :, 0], np.broadcast_to(expected_u, (2, 40)), atol=0.01)


@pytest.mark.parametrize("L", [4.0, 10.0])
def test_motion_blur_of_a_step_edge_is_a_ramp(L):
    # a fronto-parallel plane at z, the camera translating along its x axis at v: blur L = v t fx / z
    z, t_ms = 1.5, 20.0
    v = L * z / (t_ms / 1000.0 * BLUR_INTR.fx)
    rgb = step_edge()
    out = motion_blur(rgb, np.full((8, 96), z, np.float32), BLUR_INTR, moving(T0, d_rel=(v * DT, 0, 0)), t_ms)
    assert out.shape == rgb.shape and out.dtype == rgb.dtype
    for c, level in enumerate((1.0, 0.5, 0.25)):
        np.testing.assert_allclose(out[..., c], level * np.broadcast_to(ramp(L), (8, 96)), atol=0.03 * level)
    # the same from one neighbour only (a tour's ends: the other side extrapolated)
    for prev, nxt in ((False, True), (True, False)):
        m = moving(T0, d_rel=(v * DT, 0, 0), prev=prev, nxt=nxt)
        one = motion_blur(rgb, np.full((8, 96), z, np.float32), BLUR_INTR, m, t_ms)
        np.testing.assert_allclose(one, out, atol=1e-5)


def test_no_motion_no_blur():
    rgb = step_edge()
    z = np.full((8, 96), 1.5, np.float32)
    assert motion_blur(rgb, z, BLUR_INTR, None, 20.0) is rgb
    assert motion_blur(rgb, z, BLUR_INTR, Motion(T0, T0.copy(), T0.copy()), 20.0) is rgb  # at rest
    assert motion_blur(rgb, z, BLUR_INTR, Motion(T0), 20.0) is rgb  # no neighbours
    # a slow camera (under a pixel of blur over the exposure): no blur
    assert motion_blur(rgb, z, BLUR_INTR, moving(T0, d_rel=(0.0001, 0, 0)), 20.0) is rgb


def test_rotation_blur_is_independent_of_depth():
    # a turn about the camera's y axis at omega: blur fx * omega * t px everywhere, whatever the depth
    t_ms, L = 20.0, 8.0
    omega = L / (BLUR_INTR.fx * t_ms / 1000.0)
    z = np.random.default_rng(0).uniform(0.5, 5.0, (8, 96)).astype(np.float32)
    z[2:4] = 0.0  # no depth: rotation-only flow, the same
    m = moving(T0, R_rel=rot([0, 1, 0], omega * DT))
    out = motion_blur(step_edge(), z, BLUR_INTR, m, t_ms)
    # the field is +-0.24 rad wide: the blur at the edge (centre) is fx * omega * t; tolerance for the
    # (1 + x^2) growth away from it and the sampling
    np.testing.assert_allclose(out[..., 0], np.broadcast_to(ramp(L), (8, 96)), atol=0.04)


def test_motion_blur_through_apply_sensor_uses_the_exposure_time():
    # nearly noiseless camera (1e9 e-/ms); a grey step (0 | 1): t = 0.8 * 2.5e10 / (1e9 * p97 = 1.0) = 20 ms,
    # and 1.0 gives 2e10 e-, under the full well
    m = ColorModel(electrons_per_ms=1e9, full_well_e=2.5e10, motion_blur=True)
    rgb = np.repeat(step_edge()[..., :1], 3, axis=2)
    assert exposure(m, rgb) == pytest.approx((20.0, 1.0))
    z, L = 1.5, 6.0
    v = L * z / (0.020 * BLUR_INTR.fx)
    depth = np.full((8, 96), z, np.float32)
    motion = moving(T0, d_rel=(v * DT, 0, 0))
    d_out, out = apply_sensor(only_color(m), depth, rgb, BLUR_INTR, seed=1, motion=motion)
    assert d_out is depth  # depth is not blurred (an ideal depth model here)
    np.testing.assert_allclose(out[..., 0], np.broadcast_to(ramp(L), (8, 96)), atol=0.03)
    # off: the same noise, no blur; no motion: no blur
    _, sharp = apply_sensor(only_color(dataclasses.replace(m, motion_blur=False)), depth, rgb, BLUR_INTR, seed=1,
                            motion=motion)
    np.testing.assert_allclose(sharp, rgb, atol=1e-4)
    np.testing.assert_array_equal(apply_sensor(only_color(m), depth, rgb, BLUR_INTR, seed=1)[1], sharp)
    # the preset's depth does not depend on the motion either
    np.testing.assert_array_equal(apply_sensor(SL, depth, rgb, BLUR_INTR, 3, motion=motion)[0],
                                  apply_sensor(SL, depth, rgb, BLUR_INTR, 3)[0])


def test_blur_samples_are_capped():
    # 40 px of blur with at most 4 samples: a staircase of 4 (bilinear) steps 10 px apart
    z, t_ms, L = 1.5, 20.0, 40.0
    v = L * z / (t_ms / 1000.0 * BLUR_INTR.fx)
    out = motion_blur(step_edge(), np.full((8, 96), z, np.float32), BLUR_INTR, moving(T0, d_rel=(v * DT, 0, 0)),
                      t_ms, samples_max=4)
    assert set(np.round(out[0, :, 0], 4).tolist()) <= {0.0, 0.125, 0.25, 0.375, 0.5, 0.625, 0.75, 0.875, 1.0}


# ------------------------------------------------------------------ seeding, identity, inputs


def test_same_seed_same_frame_other_seed_other_frame():
    z = tilted_plane(30.0, 2.0, KINECT)
    rgb = np.full((H, W, 3), 0.3, np.float32)
    motion = moving(T0, d_rel=(0.05, 0.0, 0.0))
    for s in (SL, TOF):
        a = apply_sensor(s, z, rgb, KINECT, seed=123, motion=motion)
        b = apply_sensor(s, z, rgb, KINECT, 123, motion=motion)
        c = apply_sensor(s, z, rgb, KINECT, seed=124, motion=motion)
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
    d, c = apply_sensor(ideal, z, rgb, KINECT, seed=1, motion=moving(T0, d_rel=(0.5, 0.0, 0.0)))
    assert d is z and c is rgb
    np.testing.assert_array_equal(d, z)
    np.testing.assert_array_equal(c, rgb)
    assert apply_sensor(ideal, z, None, KINECT, seed=1)[1] is None
    assert ColorModel().is_ideal and DepthModel().is_ideal and ideal.color == ColorModel()


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
    ("depth:\n  dark_threshold: 0.01\n", "depth.dark_threshold"),  # the old absolute threshold
    ("depth:\n  dark_relative: -0.02\n", "depth.dark_relative"),
    ("depth:\n  dark_relative: .nan\n", "depth.dark_relative"),
    ("depth:\n  bright_relative: .nan\n", "depth.bright_relative"),
    ("depth:\n  dark_relative: .inf\n", "depth.dark_relative"),
    ("color:\n  full_well_e: 10000\n  read_noise_e: 3\n", "color.electrons_per_ms"),  # old meaning: refused
    ("color:\n  electrons_per_ms: -1500\n  full_well_e: 10000\n", "color.electrons_per_ms"),
    ("color:\n  electrons_per_ms: .nan\n  full_well_e: 10000\n", "color.electrons_per_ms"),
    ("color:\n  electrons_per_ms: 1500\n", "color.full_well_e"),
    ("color:\n  electrons_per_ms: 1500\n  full_well_e: 10000\n  exposure_time_ms: 5\n", "color.exposure_time_ms"),
    ("color:\n  electrons_per_ms: 1500\n  full_well_e: 10000\n  exposure_max_ms: -33\n", "color.exposure_max_ms"),
    ("color:\n  electrons_per_ms: 1500\n  full_well_e: 10000\n  exposure_max_ms: .inf\n", "color.exposure_max_ms"),
    ("color:\n  electrons_per_ms: 1500\n  full_well_e: 10000\n  exposure_min_ms: 0\n", "color.exposure_min_ms"),
    ("color:\n  electrons_per_ms: 1500\n  full_well_e: 10000\n  exposure_min_ms: 40\n", "color.exposure_min_ms"),
    ("color:\n  electrons_per_ms: 1500\n  full_well_e: 10000\n  exposure_target: 1.5\n", "color.exposure_target"),
    ("color:\n  electrons_per_ms: 1500\n  full_well_e: 10000\n  exposure_percentile: 101\n", "color.exposure_percentile"),
    ("color:\n  electrons_per_ms: 1500\n  full_well_e: 10000\n  max_gain: 0.5\n", "color.max_gain"),
    ("color:\n  electrons_per_ms: 1500\n  full_well_e: 10000\n  max_gain: .nan\n", "color.max_gain"),
    ("color:\n  electrons_per_ms: 1500\n  full_well_e: 10000\n  motion_blur: 1\n", "color.motion_blur"),
    ("color:\n  electrons_per_ms: 1500\n  full_well_e: 10000\n  motion_blur: yes please\n", "color.motion_blur"),
    ("color:\n  electrons_per_ms: 1500\n  full_well_e: 10000\n  blur_samples_max: 2.5\n", "color.blur_samples_max"),
    ("color:\n  electrons_per_ms: 1500\n  full_well_e: 10000\n  blur_samples_max: 0\n", "color.blur_samples_max"),
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
    c = parse_sensor({"color": {"electrons_per_ms": 100, "full_well_e": 5000, "motion_blur": True,
                                "blur_samples_max": 8}}, "c.yaml").color
    assert c == ColorModel(electrons_per_ms=100.0, full_well_e=5000.0, motion_blur=True, blur_samples_max=8)
    assert isinstance(c.blur_samples_max, int)
    for name in ("structured_light", "tof"):
        col = load_sensor(name).color
        assert col.motion_blur and col.electrons_per_ms > 0 and col.exposure_max_ms == pytest.approx(1000 / 30, abs=0.05)


# ---- a tour read through a sensor (vrformats.tour.Tour(sensor=...)) ----------------------------------


@pytest.fixture(scope="module")
def small_tour(tmp_path_factory):
    from synth.tour.render import TourSpec, render_tour

    out = tmp_path_factory.mktemp("tour") / "apt_0__geometry__query"
    render_tour(TourSpec(layout="apt_0", path="query", out=str(out), renderer="fast", width=64, height=48, frames=4),
                progress=False)
    return out


def test_a_tour_read_through_a_sensor(small_tour):
    from vrformats.tour import Tour

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


def test_a_tour_passes_the_motion_around_each_frame(small_tour, monkeypatch):
    import vrformats.sensors as sensors
    from vrformats.tour import Tour

    seen = {}
    real = sensors.apply_sensor

    def spy(sensor, depth, rgb, intr, seed, motion=None):
        seen["motion"] = motion
        return real(sensor, depth, rgb, intr, seed, motion=motion)

    monkeypatch.setattr(sensors, "apply_sensor", spy)
    t = Tour(small_tour, sensor="structured_light")
    n = len(t)
    for k, i in enumerate(t.frame_indices):
        t.frame(int(i))
        m = seen["motion"]
        np.testing.assert_array_equal(m.pose, t.poses[k])
        assert (m.prev_pose is None) == (k == 0) and (m.next_pose is None) == (k == n - 1)
        if k > 0:
            np.testing.assert_array_equal(m.prev_pose, t.poses[k - 1])
            assert m.dt_prev == pytest.approx((i - t.frame_indices[k - 1]) / t.fps)
        if k < n - 1:
            np.testing.assert_array_equal(m.next_pose, t.poses[k + 1])
            assert m.dt_next == pytest.approx((t.frame_indices[k + 1] - i) / t.fps)


def test_a_tour_with_rgb_through_a_sensor(small_tour, tmp_path):
    import shutil

    from vrformats import frames as fr
    from vrformats.sensors import frame_seed
    from vrformats.tour import Tour

    root = tmp_path / small_tour.name
    shutil.copytree(small_tour, root)
    plain = Tour(root)
    u = np.arange(plain.intrinsics.width)
    stripes = np.repeat((0.2 + 0.8 * ((u // 4) % 2))[None, :, None], plain.intrinsics.height, 0)
    for i in plain.frame_indices:
        f = plain.frame(int(i))
        fr.write_frame(plain.frame_path(int(i)), rgb=np.repeat(stripes, 3, 2).astype(np.float32), depth=f.depth,
                       instance=f.instance, semantic=f.semantic)
    t = Tour(root, sensor="structured_light")
    a = t.frame(2)
    b = t.frame(2, rgb=False)
    assert b.rgb is None and np.array_equal(a.depth, b.depth)  # depth alone: the same depth
    raw = Tour(root).frame(2)
    motion = Motion(t.poses[2], t.poses[1], t.poses[3], 1.0 / t.fps, 1.0 / t.fps)
    seed = frame_seed(root.name, 2, "structured_light", 0)
    d, c = apply_sensor(load_sensor("structured_light"), raw.depth, raw.rgb, t.intrinsics, seed, motion=motion)
    np.testing.assert_array_equal(a.rgb, c)
    np.testing.assert_array_equal(a.depth, d)
    assert a.rgb.dtype == np.float32 and not np.array_equal(a.rgb, raw.rgb)


def test_reloc_run_names_an_unknown_sensor(small_tour, tmp_path, capsys):
    from reloc.cli import main as reloc_main

    m = tmp_path / "map.json"
    assert reloc_main(["map", "ground-truth", str(small_tour), "--out", str(m)]) == 0
    assert reloc_main(["run", "--map", str(m), "--tour", str(small_tour), "--out", str(tmp_path / "run"),
                       "--sensor", "kinect9", "--detector", "oracle", "--quiet"]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "sensor" in err and "kinect9" in err, err
    assert not (tmp_path / "run").exists()


def test_read_speed_benchmark_reports_every_preset(small_tour, tmp_path, capsys):
    """The benchmark's figures (not its times): valid-depth fractions against the frames read by
    hand, exposure from the colour model, and a table line per preset."""
    import shutil

    from vrformats import frames as fr
    from vrformats.tour import Tour
    from reloc.cli import main as reloc_main

    root = tmp_path / small_tour.name
    shutil.copytree(small_tour, root)
    plain = Tour(root)
    for i in plain.frame_indices:  # grey RGB on a geometry-only tour
        f = plain.frame(int(i))
        fr.write_frame(plain.frame_path(int(i)), rgb=np.full(f.depth.shape + (3,), 0.3, np.float32), depth=f.depth,
                       instance=f.instance, semantic=f.semantic)
    from vrformats.bench_sensors import bench

    r = bench(root, frames=4)
    rows = {x["sensor"]: x for x in r["rows"]}
    assert list(rows) == ["ideal", "structured_light", "tof"] and r["frames"] == 4
    assert rows["ideal"]["ratio"] == 1.0 and rows["ideal"]["exposure_ms"] is None
    for name, x in rows.items():
        t = Tour(root, sensor=name)
        assert x["valid_depth"] == pytest.approx(np.mean([np.mean(t.frame(int(i)).depth > 0) for i in t.frame_indices]))
        assert x["ms_per_frame"] > 0 and x["depth_only_ms"] > 0
    sl = load_sensor("structured_light").color  # grey 0.3: exposure = target * full well / (e/ms * 0.3)
    assert rows["structured_light"]["exposure_ms"] == pytest.approx(sl.exposure_target * sl.full_well_e
                                                                    / (sl.electrons_per_ms * 0.3), rel=1e-3)
    assert reloc_main(["bench", "sensors", str(root), "--frames", "2", "--sensors", "tof"]) == 0
    out = capsys.readouterr().out
    assert "ideal" in out and "tof" in out and "structured_light" not in out


@pytest.mark.parametrize("width", [640, 160])
def test_lateral_noise_is_in_the_sensors_pixels(width):
    """0.8 px of a 580 px-focal sensor: on a depth ramp the displacement each pixel read is decoded
    exactly; the fraction displaced in u matches P(|round(N(0, s))| >= 1) = 2 (1 - Phi(0.5 / s)) with
    s = 0.8 fx / 580 (0.8 px at VGA, 0.2 px at 160x120)."""
    from scipy.stats import norm

    height = width * 3 // 4
    intr = Intrinsics.from_fov(width, height, 57.0)
    u = np.arange(width)[None, :]
    v = np.arange(height)[:, None]
    z = (1.0 + 0.01 * u + 0.0001 * v).astype(np.float64)  # dz = 0.01 du + 0.0001 dv: both decodable
    sensor = only_depth(lateral_px=0.8, focal_px=580.0)
    out, _ = apply_sensor(sensor, z.astype(np.float32), None, intr, seed=7)
    inner = (slice(8, height - 8), slice(8, width - 8))  # away from the clipped borders
    dz = out[inner].astype(np.float64) - z[inner]
    du = np.rint(dz / 0.01)
    s = 0.8 * intr.fx / 580.0
    expected = 2 * (1 - norm.cdf(0.5 / s))
    assert np.mean(du != 0) == pytest.approx(expected, rel=0.1)


@pytest.mark.parametrize("key", ["max_range_m", "bright_relative"])
def test_no_limit_is_inf_where_a_key_takes_it(tmp_path, key):
    """``max_range_m`` and ``bright_relative`` take ``.inf`` (no limit); other keys refuse it (above)."""
    p = tmp_path / "cam.yaml"
    p.write_text(f"name: cam\ndepth:\n  {key}: .inf\n")
    assert getattr(load_sensor(p).depth, key) == math.inf
