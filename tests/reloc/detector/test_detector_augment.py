"""The detector's camera augmentation (reloc.detector.augment) against the toolkit's own camera
pipeline (vrformats.sensors, vrformats.tour.tonemap) and against Pillow's JPEG encoder, on the same
frames: the training-time pipeline is a batched copy of those, and these tests keep it one."""

from __future__ import annotations

import io
from dataclasses import replace

import numpy as np
import pytest

from vrformats import color
from vrformats.camera import Intrinsics
from vrformats.sensors import apply_sensor, exposure, load_sensor
from vrformats.tour import tonemap

torch = pytest.importorskip("torch")

from reloc.detector import augment as A  # noqa: E402
from reloc.detector.settings import AugmentConfig  # noqa: E402


def _hdr(seed: int, level: float, h: int = 24, w: int = 32) -> np.ndarray:
    rng = np.random.default_rng(seed)
    return (rng.gamma(1.5, 1.0, (h, w, 3)) * level).astype(np.float32)


def test_srgb_curve_on_tensors_is_formats_color():
    """The tensor ports of the sRGB curve give vrformats.color's values (float64 and float32, knees
    and clipping included; up to the last bits of the two libraries' powers), and decode inverts
    encode."""
    x = np.concatenate([np.linspace(-0.5, 1.5, 2001), [0.0, color.ENCODE_KNEE, color.DECODE_KNEE, 1.0, 1e-9]])
    for dt in (np.float64, np.float32):
        v = x.astype(dt)
        got = A.srgb_encode(torch.from_numpy(v)).numpy()
        assert got.dtype == dt and np.abs(got - color.srgb_encode(v)).max() < 1e-6
        c = np.clip(v, 0.0, 1.0)
        assert np.abs(A.srgb_decode(torch.from_numpy(c)).numpy() - color.srgb_decode(c)).max() < 1e-6
    lin = np.linspace(0.0, 1.0, 1001)
    assert np.abs(color.srgb_decode(color.srgb_encode(lin)) - lin).max() < 1e-12
    assert color.srgb8(np.array([0.0, 1.0, 2.0, -1.0])).tolist() == [0, 255, 255, 0]


def test_tonemap_matches_formats_tour():
    imgs = [_hdr(k, lvl) for k, lvl in enumerate((1.0, 0.05, 0.004, 30.0))]
    x = torch.from_numpy(np.stack(imgs)).permute(0, 3, 1, 2)
    got = A.tonemap(x).permute(0, 2, 3, 1).numpy()
    for k, img in enumerate(imgs):
        want, _ = tonemap(img)
        assert np.abs(got[k] - want).max() < 1e-4


def test_exposure_matches_formats_sensors():
    cm = load_sensor("structured_light").color
    imgs = [_hdr(k, lvl) for k, lvl in enumerate((1.0, 0.3, 0.01, 0.0005))]  # day ... night (gain)
    x = torch.from_numpy(np.stack(imgs)).permute(0, 3, 1, 2).double()
    t, g = A.exposure(x, torch.full((4,), cm.electrons_per_ms, dtype=torch.float64), cm.full_well_e,
                      cm.exposure_percentile, cm.exposure_target, cm.exposure_min_ms, cm.exposure_max_ms, cm.max_gain)
    for k, img in enumerate(imgs):
        want_t, want_g = exposure(cm, img)
        assert t[k].item() == pytest.approx(want_t, rel=1e-6) and g[k].item() == pytest.approx(want_g, rel=1e-6)
    assert g[-1].item() > 1.0 and g[0].item() == 1.0  # the night frame takes gain, the day frame none


@pytest.mark.parametrize("level", [0.5, 0.02, 0.001])
def test_noise_statistics_match_formats_sensors(level):
    """A flat grey frame through both pipelines: the same exposure, so the same mean and the same
    shot + read noise (std within sampling error of each other and of ColorModel.sigma)."""
    sensor = load_sensor("structured_light")
    cm = sensor.color
    h, w = 120, 160
    img = np.full((h, w, 3), level, np.float32)
    img[:4] += level  # a few brighter rows, so the 97th percentile is the flat level
    intr = Intrinsics(fx=100.0, fy=100.0, cx=80.0, cy=60.0, width=w, height=h)
    _, ref = apply_sensor(sensor, np.ones((h, w), np.float32), img, intr, seed=3)
    g = torch.Generator().manual_seed(0)
    x = torch.from_numpy(img).permute(2, 0, 1)[None].double()
    got = A.sensor_noise(x, torch.tensor([cm.electrons_per_ms], dtype=torch.float64),
                         torch.tensor([cm.read_noise_e], dtype=torch.float64), cm.full_well_e, cm.exposure_percentile,
                         cm.exposure_target, cm.exposure_min_ms, cm.exposure_max_ms, cm.max_gain, generator=g)
    got = got[0].permute(1, 2, 0).numpy()[8:]
    ref = np.asarray(ref)[8:]
    t, _ = exposure(cm, img)
    sigma = float(cm.sigma(level, t))
    assert got.mean() == pytest.approx(ref.mean(), rel=0.01)
    assert got.std() == pytest.approx(ref.std(), rel=0.05) and got.std() == pytest.approx(sigma, rel=0.05)


def test_jpeg_like_is_close_to_pillow():
    """A grey (L-mode) JPEG by Pillow uses the same luminance table and scaling: the DCT copy
    lands within about a level of it on average, and much closer to it than to the input."""
    from PIL import Image

    rng = np.random.default_rng(0)
    base = np.kron(rng.integers(0, 256, (6, 8)), np.ones((8, 8)))  # blocks of flat grey
    img = np.clip(base + rng.normal(0, 12, base.shape), 0, 255).round().astype(np.uint8)
    for q in (30, 75):
        buf = io.BytesIO()
        Image.fromarray(img, "L").save(buf, format="JPEG", quality=q)
        pil = np.asarray(Image.open(io.BytesIO(buf.getvalue()))).astype(float)
        x = torch.from_numpy(img.astype(np.float64))[None, None].repeat(1, 3, 1, 1)
        ours = A.jpeg_like(x, torch.tensor([float(q)], dtype=torch.float64))[0, 0].numpy()
        assert np.abs(ours - pil).mean() < 1.5
        assert np.abs(ours - pil).mean() < 0.5 * np.abs(img - pil).mean()


def test_motion_blur_identity_and_smear():
    x = torch.zeros(2, 3, 16, 32, dtype=torch.float64)
    x[:, :, :, 16] = 1.0  # a vertical line
    same = A.motion_blur(x, torch.zeros(2, dtype=torch.float64), torch.zeros(2, dtype=torch.float64),
                         torch.zeros(2, dtype=torch.float64), 8)
    assert torch.allclose(same, x, atol=1e-9)
    smear = A.motion_blur(x, torch.tensor([8.0, 8.0], dtype=torch.float64), torch.tensor([0.0, np.pi / 2], dtype=torch.float64),
                          torch.zeros(2, dtype=torch.float64), 8)
    row = smear[0, 0, 8]
    assert (row > 0.05).sum() >= 7 and row.sum().item() == pytest.approx(1.0, abs=1e-6)  # spread along x, energy kept
    assert torch.allclose(smear[1, 0, 4:12], x[1, 0, 4:12], atol=1e-6)  # shifted along the line: unchanged inside


def test_camera_augment_off_returns_the_frame_and_on_is_seeded():
    rng = np.random.default_rng(1)  # grey-ish scenes: each pixel's channels within 10 % of each other
    lin = [(rng.gamma(1.5, 1.0, (48, 64, 1)) * rng.uniform(0.9, 1.1, (48, 64, 3)) * lvl).astype(np.float32)
           for lvl in (1.0, 0.01)]
    x8, scales = [], []
    for img in lin:
        s, sc = tonemap(img)
        x8.append(np.round(s * 255).astype(np.uint8))
        scales.append(sc)
    X = torch.from_numpy(np.stack(x8)).permute(0, 3, 1, 2)
    SC = torch.tensor(scales, dtype=torch.float32)
    off = replace(AugmentConfig(), brightness_log2=(0.0, 0.0), white_balance_log2=0.0, blur_prob=0.0, sensor_prob=0.0,
                  jpeg_prob=0.0).with_sensor()
    y = A.camera_augment(X, SC, off, torch.Generator().manual_seed(0))
    assert (y * 255 - X.float()).abs().mean() < 1.0  # re-exposed to the same frame, up to 8-bit steps
    on = AugmentConfig().with_sensor()
    a = A.camera_augment(X, SC, on, torch.Generator().manual_seed(5))
    b = A.camera_augment(X, SC, on, torch.Generator().manual_seed(5))
    c = A.camera_augment(X, SC, on, torch.Generator().manual_seed(6))
    assert torch.equal(a, b) and not torch.equal(a, c)
    assert a.shape == (2, 3, 48, 64) and a.min() >= 0 and a.max() <= 1
    assert (torch.round(a * 255) - a * 255).abs().max() < 1e-3  # 8-bit steps, as the camera delivers


def test_the_darkest_simulated_scene_still_shows_the_scene():
    """Brightness is floored at min_p97: a frame dimmed a millionfold goes through the colour camera
    at that floor, noisy but still correlated with the clean frame (not noise alone)."""
    rng = np.random.default_rng(2)
    img = (rng.gamma(1.5, 1.0, (48, 64, 1)) * np.ones((1, 1, 3)) * 0.01).astype(np.float32)
    img[:, :32] *= 4.0  # structure: a bright half
    s, sc = tonemap(img)
    X = torch.from_numpy(np.round(s * 255).astype(np.uint8))[None].permute(0, 3, 1, 2)
    cfg = replace(AugmentConfig(), brightness_log2=(20.0, -20.0), white_balance_log2=0.0, blur_prob=0.0,
                  sensor_prob=1.0, jpeg_prob=0.0).with_sensor()
    y = A.camera_augment(X, torch.tensor([sc], dtype=torch.float32), cfg, torch.Generator().manual_seed(0))
    a = y[0].mean(0).numpy()
    assert a[:, :32].mean() > a[:, 32:].mean() + 0.1  # the bright half is still brighter
    clean = X[0].float().mean(0).numpy()
    assert np.corrcoef(a.ravel(), clean.ravel())[0, 1] > 0.3
