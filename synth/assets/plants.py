"""Potted plants: plant and small_plant share one generator and one sampler (pot + seeded foliage)."""
from __future__ import annotations

import math

import numpy as np

from .materials import CERAMIC, LEAF, MATERIALS
from .primitives import (
    Builder,
    box,
    clamp,
    concat,
    cylinder,
    ellipsoid,
    fit_meshes,
    mesh_from,
    param,
    revolve,
    rod,
    rotation,
    transform,
)
from .sampling import ParamSampler


def _pot(b, w, d, h, p, default_frac, default_hfrac):
    shape = param(p, "pot_shape", "round")
    pcol = param(p, "pot_color", CERAMIC[0])
    pmat = param(p, "pot_material", "ceramic")
    if pmat not in MATERIALS:
        pmat = "ceramic"
    frac = clamp(param(p, "pot_width_frac", default_frac), 0.2, 1.0)
    ph = clamp(param(p, "pot_height_frac", default_hfrac), 0.1, 0.8) * h
    rx, ry = frac * w / 2, frac * d / 2
    soil = ph - min(0.03, 0.1 * ph)
    if shape == "square":
        s = 0.08 * min(rx, ry)
        b.add("pot", pmat, concat([
            box(-rx, rx, -ry, ry, 0, soil),
            box(-rx, -rx + s, -ry, ry, 0, ph), box(rx - s, rx, -ry, ry, 0, ph),
            box(-rx, rx, -ry, -ry + s, 0, ph), box(-rx, rx, ry - s, ry, 0, ph)]), color=pcol)
        b.add("soil", "soil", box(-rx + s, rx - s, -ry + s, ry - s, soil, soil + 0.003), color=(0.12, 0.08, 0.05))
    else:
        taper = 0.78 if shape == "round" else 1.0
        prof = [(0, 0), (taper, 0), (1.0, 1.0), (0.9, 1.0), (0.9 * (taper + (1 - taper) * soil / ph), soil / ph),
                (0, soil / ph)]
        b.add("pot", pmat, revolve(prof, 0, 0, 0, rx, ry, ph, sections=40), color=pcol)
        b.add("soil", "soil", cylinder(0, 0, soil, soil + 0.003, 0.9 * rx, 0.9 * ry, sections=40),
              color=(0.12, 0.08, 0.05))
    return soil


def _foliage(style, seed, n):
    """(name, material, mesh, colour_scale) pieces in unit coordinates; base at the origin."""
    rng = np.random.default_rng(seed)
    out = []
    if style == "spiky":
        for i in range(n):
            a = 2 * math.pi * i / n + rng.uniform(-0.3, 0.3)
            tilt = rng.uniform(0.08, 0.5)
            length = rng.uniform(0.6, 1.0)
            wd = rng.uniform(0.05, 0.09)
            m = box(-wd / 2, wd / 2, -0.006, 0.006, 0, length)
            m = transform(m, rotation(tilt, [1, 0, 0]))
            m = transform(m, rotation(a + math.pi / 2, [0, 0, 1]))
            out.append((f"leaf_{i}", "leaf", m, rng.uniform(0.85, 1.15)))
    elif style in ("palm", "succulent"):
        if style == "palm":
            trunk_h = 0.55
            out.append(("trunk", "wood_dark", rod((0, 0, 0), (0, 0, trunk_h), 0.025, sections=12), None))
            rings = [(n, 0.5, 0.1, 0.35)]
        else:
            trunk_h = 0.0
            rings = [(max(n, 5), 0.5, 0.12, 0.25), (max(n - 2, 4), 0.38, 0.1, 0.75), (max(n - 4, 3), 0.25, 0.08, 1.2)]
        k = 0
        for ring_i, (m_, length, wdt, elev) in enumerate(rings):
            for i in range(m_):
                a = 2 * math.pi * (i + 0.5 * ring_i) / m_ + rng.uniform(-0.2, 0.2)
                el = elev + rng.uniform(-0.15, 0.25)
                ln = length * rng.uniform(0.8, 1.1)
                m = ellipsoid((ln / 2, 0, 0), (ln / 2, wdt * (1.0 if style == "palm" else 0.6), 0.015 if style == "palm"
                                               else 0.04), subdiv=2)
                m = transform(m, rotation(-el, [0, 1, 0]))
                m = transform(m, rotation(a, [0, 0, 1]))
                m = mesh_from(m.vertices + np.array([0, 0, trunk_h]), m.faces)
                out.append((f"leaf_{k}", "leaf", m, rng.uniform(0.85, 1.15)))
                k += 1
    else:  # bush / tree
        trunk_h = 0.5 if style == "tree" else 0.0
        if style == "tree":
            out.append(("trunk", "wood_dark", rod((0, 0, 0), (0, 0, trunk_h + 0.1), 0.03, sections=12), None))
        for i in range(n):
            a = rng.uniform(0, 2 * math.pi)
            s = rng.uniform(0.22, 0.34)
            r = rng.uniform(0.0, 0.5)
            if style == "tree":
                z = trunk_h + rng.uniform(0.1, 0.45)
            else:
                z = rng.uniform(s + 0.05, 0.9 - s * 0.5)
            c = (r * math.cos(a), r * math.sin(a), z)
            out.append((f"foliage_{i}", "leaf", ellipsoid(c, (s, s, 0.85 * s), subdiv=2), rng.uniform(0.85, 1.15)))
            if style != "tree":
                out.append((f"stem_{i}", "leaf", rod((0, 0, 0), c, 0.012, sections=8), 0.6))
    return out


def _plant(b, w, d, h, p, default_style, default_frac, default_hfrac, default_n):
    soil = _pot(b, w, d, h, p, default_frac, default_hfrac)
    style = param(p, "style", default_style)
    seed = param(p, "foliage_seed", 0)
    n = int(clamp(param(p, "n_clusters", default_n), 1, 30))
    lcol = param(p, "leaf_color", LEAF[0])
    pieces = _foliage(style, seed, n)
    meshes = fit_meshes([m for _, _, m, _ in pieces], (-w / 2, -d / 2, soil), (w / 2, d / 2, h))
    for (name, mat, _, cs), m in zip(pieces, meshes):
        col = None if cs is None else tuple(float(min(1.0, c * cs)) for c in lcol)
        b.add(name, mat, m, color=col)


def _sample_plant(s: ParamSampler, small=False):
    p = {}
    p["pot_shape"] = s.choice(["round", "cylinder", "square"], [0.5, 0.3, 0.2])
    p["pot_material"] = s.choice(["ceramic", "plastic", "wicker"], [0.7, 0.2, 0.1])
    p["pot_color"] = s.color(CERAMIC if p["pot_material"] != "wicker" else ((0.55, 0.4, 0.22),))
    p["leaf_color"] = s.color(LEAF, 0.03)
    p["foliage_seed"] = s.seed()
    if small:
        p["style"] = s.choice(["succulent", "bush", "spiky"])
        p["pot_width_frac"] = s.uniform(0.6, 0.9)
        p["pot_height_frac"] = s.uniform(0.35, 0.55)
        p["n_clusters"] = s.integer(5, 9)
        w = s.around(0.18, 0.25)
        return (w, s.around(w, 0.05), s.around(0.3, 0.25)), p
    p["style"] = s.choice(["bush", "tree", "spiky", "palm"])
    p["pot_width_frac"] = s.uniform(0.45, 0.7)
    p["pot_height_frac"] = s.uniform(0.22, 0.38)
    p["n_clusters"] = s.integer(6, 12) if p["style"] != "spiky" else s.integer(9, 16)
    w = s.around(0.48, 0.25)
    return (w, s.around(w, 0.08), s.around(1.1, 0.25)), p


def generate_plant(b: Builder, w, d, h, p):
    _plant(b, w, d, h, p, "bush", 0.55, 0.3, 7)


def sample_plant(s: ParamSampler):
    return _sample_plant(s, False)


def generate_small_plant(b: Builder, w, d, h, p):
    _plant(b, w, d, h, p, "succulent", 0.75, 0.45, 6)


def sample_small_plant(s: ParamSampler):
    return _sample_plant(s, True)
