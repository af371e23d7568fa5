"""PSNR and SSIM of vrformats.image_quality, against scikit-image's implementations of the same
definitions (a second implementation, not a reading of ours)."""

from __future__ import annotations

import numpy as np
import pytest

from vrformats import image_quality as iq

from skimage import metrics as skimage_metrics  # noqa: E402  (the test extra installs scikit-image)


def images(seed=0, noise=0.05, shape=(48, 64, 3)):
    rng = np.random.default_rng(seed)
    a = rng.random(shape).astype(np.float32)
    b = np.clip(a + rng.normal(0, noise, a.shape), 0, 1).astype(np.float32)
    return a, b


@pytest.mark.parametrize("noise", [0.01, 0.05, 0.2])
def test_psnr_and_ssim_agree_with_scikit_image(noise):
    a, b = images(noise=noise)
    a8, b8 = iq.as_srgb8(a), iq.as_srgb8(b)
    assert iq.psnr(a, b) == pytest.approx(skimage_metrics.peak_signal_noise_ratio(a8, b8, data_range=255), abs=1e-9)
    ya, yb = (x.astype(np.float64) @ iq.LUMA for x in (a8, b8))
    want = skimage_metrics.structural_similarity(ya, yb, gaussian_weights=True, sigma=1.5, use_sample_covariance=False,
                                                 data_range=255)
    assert iq.ssim(a, b) == pytest.approx(want, abs=1e-9)


def test_identical_images_and_mismatched_shapes():
    a, _ = images()
    assert iq.psnr(a, a) == float("inf") and iq.ssim(a, a) == pytest.approx(1.0)
    assert iq.db(0.0) == float("inf") and iq.db(255.0**2) == pytest.approx(0.0)
    with pytest.raises(ValueError, match="different shapes"):
        iq.psnr(a, a[:-1])
    with pytest.raises(ValueError, match="different shapes"):
        iq.ssim(a, a[:, :-1])


def test_an_8bit_image_is_taken_as_it_is():
    a, b = images()
    assert iq.psnr(iq.as_srgb8(a), iq.as_srgb8(b)) == iq.psnr(a, b)
