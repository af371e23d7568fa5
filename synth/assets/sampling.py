"""``ParamSampler``: the random draws the per-class samplers make (``sample_<class>`` in each family module).

A sampler turns a ``numpy.random.Generator`` into a size (w, d, h) and a params dict; the family
modules call only these methods, so the stream an instance consumes is the sequence of calls its
sampler makes.
"""
from __future__ import annotations

import numpy as np

__all__ = ["ParamSampler"]


class ParamSampler:
    """Draws an instance's size and style parameters from ``rng`` as plain Python values (YAML-able).

    Each method draws from ``rng`` exactly once per call (``color``: one choice, then three uniforms), so
    a sampler's sequence of calls fixes the random stream it consumes."""

    def __init__(self, rng: np.random.Generator):
        self.rng = rng

    def uniform(self, lo, hi, digits=3):
        """A uniform value in [lo, hi), rounded to ``digits`` decimals."""
        return round(float(self.rng.uniform(lo, hi)), digits)

    def around(self, base, frac=0.15, digits=3):
        """``base`` scaled by a uniform factor in [1 - frac, 1 + frac), rounded to ``digits`` decimals."""
        return round(float(base * self.rng.uniform(1 - frac, 1 + frac)), digits)

    def choice(self, options, probs=None):
        """One of ``options`` (weights ``probs``, normalised; uniform when None)."""
        if probs is not None:
            probs = np.asarray(probs, dtype=float)
            probs = probs / probs.sum()
        return options[int(self.rng.choice(len(options), p=probs))]

    def integer(self, lo, hi):
        """An integer in [lo, hi], both ends included."""
        return int(self.rng.integers(lo, hi + 1))

    def chance(self, prob=0.5):
        """True with probability ``prob``."""
        return bool(self.rng.random() < prob)

    def color(self, palette, jitter=0.04):
        """A colour of ``palette`` with each channel moved by up to +-``jitter`` (clipped to [0, 1])."""
        base = np.asarray(self.choice(palette), dtype=float)
        return [round(float(v), 3) for v in np.clip(base + self.rng.uniform(-jitter, jitter, 3), 0.0, 1.0)]

    def seed(self):
        """A seed for a generator's own rng (foliage, fruit, art): an integer in [0, 2**31 - 1)."""
        return int(self.rng.integers(0, 2 ** 31 - 1))
