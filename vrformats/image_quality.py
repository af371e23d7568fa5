"""How close one rendered image is to another, in the 8-bit sRGB the methods read (the detector and the
appearance baseline see ``vrformats.color.srgb8`` of the linear RGB): PSNR and SSIM.

The one home of these measures: the stability benchmark's render perturbations
(``reloc.experiments.stability``) and the quality-versus-time benchmark (``synth bench quality``)
use them.
"""

from __future__ import annotations

import numpy as np

from .color import srgb8

SSIM_SIGMA = 1.5  # Wang et al. 2004: Gaussian window, K1 = 0.01, K2 = 0.03, on 8-bit luma
LUMA = np.array([0.299, 0.587, 0.114])


def as_srgb8(img: np.ndarray) -> np.ndarray:
    """8-bit sRGB of a linear float image; an 8-bit image is taken as it is."""
    return img if img.dtype == np.uint8 else srgb8(np.asarray(img, np.float32))


def mse(a: np.ndarray, b: np.ndarray) -> float:
    """Mean squared difference of two images as 8-bit sRGB (in 8-bit steps squared)."""
    a8, b8 = as_srgb8(a).astype(np.float64), as_srgb8(b).astype(np.float64)
    if a8.shape != b8.shape:
        raise ValueError(f"images of different shapes: {a8.shape} and {b8.shape}")
    return float(np.mean((a8 - b8) ** 2))


def db(mse_8bit: float) -> float:
    """PSNR in dB of a mean squared error in 8-bit steps; inf for 0."""
    return float("inf") if mse_8bit <= 0.0 else float(10.0 * np.log10(255.0**2 / mse_8bit))


def psnr(a: np.ndarray, b: np.ndarray) -> float:
    """PSNR in dB of two images (linear float RGB, or 8-bit sRGB) as 8-bit sRGB; inf when equal."""
    return db(mse(a, b))


def ssim(a: np.ndarray, b: np.ndarray) -> float:
    """Mean SSIM of two images' 8-bit luma (Gaussian window of sigma 1.5, K1 0.01, K2 0.03), over the
    pixels whose window lies inside the image: scikit-image's ``structural_similarity`` with
    ``gaussian_weights=True, use_sample_covariance=False, data_range=255``."""
    from scipy.ndimage import gaussian_filter

    x, y = (as_srgb8(im).astype(np.float64) @ LUMA for im in (a, b))
    if x.shape != y.shape:
        raise ValueError(f"images of different shapes: {x.shape} and {y.shape}")

    def g(z):
        return gaussian_filter(z, SSIM_SIGMA, truncate=3.5, mode="nearest")

    mx, my = g(x), g(y)
    sxx, syy, sxy = g(x * x) - mx * mx, g(y * y) - my * my, g(x * y) - mx * my
    c1, c2 = (0.01 * 255) ** 2, (0.03 * 255) ** 2
    s = ((2 * mx * my + c1) * (2 * sxy + c2)) / ((mx * mx + my * my + c1) * (sxx + syy + c2))
    pad = int(3.5 * SSIM_SIGMA + 0.5)  # the window's half width: the border, where it leaves the image, is not counted
    return float(s[pad:-pad, pad:-pad].mean())
