"""The sRGB transfer function (IEC 61966-2-1), both directions: the one home of its constants.

``srgb_encode`` (linear -> sRGB, clipped to [0, 1] first) is what every 8-bit image of the toolkit
goes through (``srgb8``: previews, ``vrformats.tour.tonemap``, the detectors' inputs); ``srgb_decode``
(sRGB -> linear) turns sRGB colours (black-body fits, texture values) into linear light.

These work on numpy arrays. The detector's training runs the same curve on PyTorch tensors
(``reloc.detector.augment.srgb_encode`` / ``srgb_decode``), written with these constants
(``tests/reloc/detector/test_detector_augment.py`` compares them).
"""

from __future__ import annotations

import numpy as np

ENCODE_KNEE = 0.0031308  # linear values up to this are encoded linearly ...
DECODE_KNEE = 0.04045  # ... to sRGB values up to this (= 12.92 * ENCODE_KNEE, rounded)
SLOPE = 12.92  # the linear segment
OFFSET = 0.055  # the power segment: (1 + OFFSET) * x ** (1 / GAMMA) - OFFSET
GAMMA = 2.4


def srgb_encode(x: np.ndarray) -> np.ndarray:
    """Linear [0, 1] -> sRGB-encoded [0, 1] (values outside [0, 1] are clipped first)."""
    x = np.clip(x, 0.0, 1.0)
    return np.where(x <= ENCODE_KNEE, SLOPE * x, (1.0 + OFFSET) * np.power(x, 1.0 / GAMMA) - OFFSET)


def srgb_decode(c) -> np.ndarray:
    """sRGB-encoded values in [0, 1] -> linear, in float64 (no clipping: callers pass [0, 1])."""
    c = np.asarray(c, dtype=np.float64)
    return np.where(c <= DECODE_KNEE, c / SLOPE, ((c + OFFSET) / (1.0 + OFFSET)) ** GAMMA)


def srgb8(x: np.ndarray) -> np.ndarray:
    """Linear [0, 1] -> 8-bit sRGB (rounded)."""
    return (srgb_encode(x) * 255.0 + 0.5).astype(np.uint8)
