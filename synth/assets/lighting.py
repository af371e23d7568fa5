"""Lights: floor lamp, table lamp, ceiling light (each generator beside its sampler). Shades, bulbs and
diffusers are emissive parts."""
from __future__ import annotations

import math

from .materials import CERAMIC, DARK, MATERIALS, SHADE
from .primitives import Builder, box, clamp, concat, cylinder, ellipsoid, param, revolve, rod
from .sampling import ParamSampler


def _shade(b, w, d, z0, z1, style, col, top_ratio):
    t = 0.08
    if style == "cone":
        prof = [(1.0, 0.0), (top_ratio, 1.0), (top_ratio - t, 1.0), (1.0 - t, 0.0), (1.0, 0.0)]
    elif style == "dome":
        prof = [(1.0, 0.0), (0.9, 0.45), (0.6, 0.85), (0.2, 1.0), (0.0, 1.0), (0.0, 0.92), (0.18, 0.92),
                (0.55, 0.78), (0.83, 0.42), (0.92, 0.0), (1.0, 0.0)]
        prof = prof[:4] + [(0.0, 1.0), (0.0, 0.92)] + prof[6:]
    else:
        prof = [(1.0, 0.0), (1.0, 1.0), (1.0 - t, 1.0), (1.0 - t, 0.0), (1.0, 0.0)]
    b.add("shade", "lamp_shade", revolve(prof, 0, 0, z0, w / 2, d / 2, z1 - z0, sections=48), emissive=True, color=col)


def generate_floor_lamp(b: Builder, w, d, h, p):
    mat = param(p, "material", "metal")
    if mat not in MATERIALS:
        mat = "metal"
    col = param(p, "color", DARK) if mat in ("metal", "painted") else None
    shade_style = param(p, "shade_style", "drum")
    scol = param(p, "shade_color", SHADE[0])
    sh = clamp(param(p, "shade_height", 0.3), 0.05, 0.45 * h)
    base = param(p, "base", "disc")
    pr = clamp(param(p, "pole_radius", 0.012), 0.004, 0.05 * min(w, d))
    tr = clamp(param(p, "shade_top_ratio", 0.7), 0.3, 1.0)
    zs0 = h - sh
    _shade(b, w, d, zs0, h, shade_style, scol, tr)
    if base == "tripod":
        zj = 0.4 * h
        for i in range(3):
            a = math.pi / 2 + i * 2 * math.pi / 3
            b.add(f"leg_{i}", mat, rod((math.cos(a) * (w / 2 - 0.02), math.sin(a) * (d / 2 - 0.02), 0.0),
                                       (0, 0, zj), pr * 1.2), color=col)
        b.add("pole", mat, cylinder(0, 0, zj, zs0 + 0.5 * sh, pr, sections=16), color=col)
    else:
        rb = clamp(param(p, "base_radius", 0.14), 0.03, 0.5 * min(w, d))
        bh = min(0.025, 0.05 * h)
        b.add("base", mat, cylinder(0, 0, 0, bh, rb, sections=48), color=col)
        b.add("pole", mat, cylinder(0, 0, bh, zs0 + 0.5 * sh, pr, sections=16), color=col)
    b.add("bulb", "diffuser", ellipsoid((0, 0, zs0 + 0.45 * sh), (0.03, 0.03, 0.04), subdiv=1), emissive=True,
          color=(1.0, 0.95, 0.85))


def sample_floor_lamp(s: ParamSampler):
    p = {"material": s.choice(["metal", "wood_dark", "wood_light"], [0.6, 0.2, 0.2])}
    if p["material"] == "metal":
        p["color"] = s.color(((0.08, 0.08, 0.09), (0.7, 0.6, 0.35), (0.8, 0.8, 0.8)))
    p["shade_style"] = s.choice(["drum", "cone", "dome"])
    p["shade_color"] = s.color(SHADE, 0.02)
    p["shade_height"] = s.uniform(0.22, 0.38)
    p["shade_top_ratio"] = s.uniform(0.5, 0.8)
    p["base"] = s.choice(["disc", "tripod"], [0.65, 0.35])
    p["pole_radius"] = s.uniform(0.009, 0.016)
    w = s.around(0.42, 0.2)
    p["base_radius"] = round(s.uniform(0.5, 0.8) * w / 2, 3)
    return (w, w, s.around(1.6, 0.12)), p


def generate_table_lamp(b: Builder, w, d, h, p):
    bmat = param(p, "base_material", "ceramic")
    if bmat not in MATERIALS:
        bmat = "ceramic"
    bcol = param(p, "base_color", CERAMIC[0])
    bstyle = param(p, "base_style", "gourd")
    shade_style = param(p, "shade_style", "cone")
    scol = param(p, "shade_color", SHADE[0])
    sh = clamp(param(p, "shade_height", 0.4 * h), 0.03, 0.6 * h)
    tr = clamp(param(p, "shade_top_ratio", 0.7), 0.3, 1.0)
    bh = clamp(param(p, "base_height", 0.4 * h), 0.02, h - sh)
    br = clamp(param(p, "base_radius", 0.3 * min(w, d)), 0.01, 0.48 * min(w, d))
    zs0 = h - sh
    _shade(b, w, d, zs0, h, shade_style, scol, tr)
    if bstyle == "ball":
        prof = [(0, 0), (0.5, 0), (0.9, 0.2), (1.0, 0.5), (0.9, 0.8), (0.5, 0.97), (0.15, 1.0), (0, 1.0)]
    elif bstyle == "cylinder":
        prof = [(0, 0), (1.0, 0), (1.0, 1.0), (0, 1.0)]
    elif bstyle == "cone":
        prof = [(0, 0), (1.0, 0), (0.35, 1.0), (0, 1.0)]
    else:
        prof = [(0, 0), (0.6, 0), (0.95, 0.25), (1.0, 0.45), (0.7, 0.75), (0.3, 0.9), (0.2, 1.0), (0, 1.0)]
    b.add("base", bmat, revolve(prof, 0, 0, 0, br, br, bh, sections=40), color=bcol)
    b.add("stem", "metal", cylinder(0, 0, bh - 0.005, zs0 + 0.4 * sh, min(0.008, 0.2 * br), sections=16),
          color=(0.6, 0.55, 0.4))
    b.add("bulb", "diffuser", ellipsoid((0, 0, zs0 + 0.4 * sh), (0.025, 0.025, 0.032), subdiv=1), emissive=True,
          color=(1.0, 0.95, 0.85))


def sample_table_lamp(s: ParamSampler):
    p = {"base_material": s.choice(["ceramic", "metal", "glass", "wood_light"], [0.5, 0.25, 0.15, 0.1])}
    p["base_color"] = s.color(CERAMIC)
    p["base_style"] = s.choice(["gourd", "ball", "cylinder", "cone"])
    p["shade_style"] = s.choice(["drum", "cone"])
    p["shade_color"] = s.color(SHADE, 0.02)
    p["shade_top_ratio"] = s.uniform(0.55, 0.85)
    w = s.around(0.3, 0.2)
    h = s.around(0.48, 0.2)
    p["shade_height"] = round(s.uniform(0.35, 0.45) * h, 3)
    p["base_height"] = round(s.uniform(0.3, 0.45) * h, 3)
    p["base_radius"] = round(s.uniform(0.25, 0.38) * w, 3)
    return (w, w, h), p


def generate_ceiling_light(b: Builder, w, d, h, p):
    shape = param(p, "shape", "round")
    mat = param(p, "rim_material", "metal")
    if mat not in MATERIALS:
        mat = "metal"
    rim = min(0.015, 0.08 * min(w, d))
    if shape == "square":
        b.add("diffuser", "diffuser", box(-w / 2 + rim, w / 2 - rim, -d / 2 + rim, d / 2 - rim, 0, h),
              emissive=True, color=(1.0, 0.98, 0.92))
        zr = 0.35 * h
        b.add("rim", mat, concat([
            box(-w / 2, w / 2, -d / 2, -d / 2 + rim, zr, h), box(-w / 2, w / 2, d / 2 - rim, d / 2, zr, h),
            box(-w / 2, -w / 2 + rim, -d / 2, d / 2, zr, h), box(w / 2 - rim, w / 2, -d / 2, d / 2, zr, h)]),
            color=(0.8, 0.8, 0.8))
    else:
        b.add("diffuser", "diffuser", cylinder(0, 0, 0, h, w / 2 - rim, d / 2 - rim, sections=64), emissive=True,
              color=(1.0, 0.98, 0.92))
        fr = 1.0 - rim / (w / 2)
        b.add("rim", mat, revolve([(fr, 0.0), (1.0, 0.0), (1.0, 1.0), (fr, 1.0), (fr, 0.0)], 0, 0, 0.35 * h, w / 2,
                                  d / 2, 0.65 * h, sections=64), color=(0.8, 0.8, 0.8))


def sample_ceiling_light(s: ParamSampler):
    p = {"shape": s.choice(["round", "square"], [0.7, 0.3]), "rim_material": s.choice(["metal", "painted"])}
    w = s.around(0.4, 0.25)
    return (w, w if p["shape"] == "round" else s.around(w, 0.05), s.around(0.08, 0.25)), p
