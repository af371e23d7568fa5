"""Decor and small objects: cushion, book, vase, bowl, picture, mirror, bin, basket, and ``other`` (a plain
box for anything else); each generator beside its sampler."""
from __future__ import annotations

import math

import numpy as np

from .materials import BOOK, CERAMIC, DARK, FABRIC, LINEN, MATERIALS, PAINT, PLASTIC
from .primitives import Builder, box, clamp, concat, cylinder, ellipsoid, param, revolve, soft_box, y_cylinder
from .sampling import ParamSampler


def generate_cushion(b: Builder, w, d, h, p):
    col = param(p, "color", FABRIC[0])
    style = param(p, "style", "soft")
    b.add("cushion", "fabric", soft_box(-w / 2, w / 2, -d / 2, d / 2, 0, h, e=0.35 if style == "soft" else 0.18),
          color=col)
    if style == "tufted":
        b.add("button", "fabric", cylinder(0, 0, h * 0.86, h * 0.97, min(0.015, 0.1 * w), sections=16),
              color=tuple(c * 0.7 for c in col))


def sample_cushion(s: ParamSampler):
    p = {"color": s.color(FABRIC + LINEN), "style": s.choice(["soft", "firm", "tufted"], [0.6, 0.25, 0.15])}
    w = s.around(0.45, 0.15)
    return (w, s.around(w, 0.08), s.around(0.13, 0.2)), p


def generate_book(b: Builder, w, d, h, p):
    col = param(p, "color", BOOK[0])
    orient = param(p, "orientation", "standing" if w <= h else "lying")
    page = (0.93, 0.91, 0.85)
    if orient == "standing":
        ct = min(0.003, 0.2 * w)
        b.add("cover", "book_cover", concat([
            box(-w / 2, -w / 2 + ct, -d / 2, d / 2, 0, h), box(w / 2 - ct, w / 2, -d / 2, d / 2, 0, h),
            box(-w / 2, w / 2, d / 2 - ct - 0.0005, d / 2 - 0.0005, 0, h)]), color=col)
        b.add("pages", "paper", box(-w / 2 + ct, w / 2 - ct, -d / 2 + 0.003, d / 2 - ct, 0.003, h - 0.003),
              color=page)
        b.add("label", "paper", box(-w / 2 + 0.25 * w, w / 2 - 0.25 * w, d / 2 - 0.0005, d / 2, 0.7 * h, 0.82 * h),
              color=(0.85, 0.8, 0.6))
    else:
        ct = min(0.003, 0.2 * h)
        b.add("cover", "book_cover", concat([
            box(-w / 2, w / 2, -d / 2, d / 2, 0, ct), box(-w / 2, w / 2, -d / 2, d / 2, h - ct, h),
            box(-w / 2, -w / 2 + ct, -d / 2, d / 2, 0, h)]), color=col)
        b.add("pages", "paper", box(-w / 2 + ct, w / 2 - 0.003, -d / 2 + 0.003, d / 2 - 0.003, ct, h - ct),
              color=page)


def sample_book(s: ParamSampler):
    p = {"color": s.color(BOOK), "orientation": s.choice(["standing", "lying"], [0.6, 0.4])}
    t, pw, ph = s.uniform(0.015, 0.05), s.uniform(0.13, 0.22), s.uniform(0.18, 0.3)
    if p["orientation"] == "standing":
        return (t, pw, ph), p
    return (pw, ph, t), p


def generate_vase(b: Builder, w, d, h, p):
    mat = param(p, "material", "ceramic")
    if mat not in MATERIALS:
        mat = "ceramic"
    col = param(p, "color", CERAMIC[2])
    style = param(p, "style", "classic")
    profiles = {
        "classic": [(0, 0), (0.55, 0), (0.85, 0.15), (1.0, 0.42), (0.8, 0.7), (0.5, 0.85), (0.6, 1.0),
                    (0.5, 1.0), (0.4, 0.86), (0, 0.84)],
        "cylinder": [(0, 0), (1.0, 0), (1.0, 1.0), (0.88, 1.0), (0.88, 0.06), (0, 0.06)],
        "bottle": [(0, 0), (0.9, 0), (1.0, 0.1), (1.0, 0.5), (0.45, 0.72), (0.3, 0.92), (0.36, 1.0),
                   (0.26, 1.0), (0.2, 0.9), (0, 0.88)],
        "bulb": [(0, 0), (0.5, 0), (0.9, 0.15), (1.0, 0.35), (0.9, 0.55), (0.55, 0.75), (0.42, 1.0),
                 (0.34, 1.0), (0.45, 0.75), (0, 0.7)],
    }
    prof = profiles.get(style, profiles["classic"])
    b.add("body", mat, revolve(prof, 0, 0, 0, w / 2, d / 2, h, sections=40), color=col)
    if param(p, "band", False):
        b.add("band", "metal", revolve([(0.95, 0.0), (1.0, 0.0), (1.0, 1.0), (0.95, 1.0), (0.95, 0.0)], 0, 0, 0.0,
                                       w / 2 * 0.6, d / 2 * 0.6, 0.02, sections=40), color=(0.7, 0.6, 0.3))


def sample_vase(s: ParamSampler):
    p = {"material": s.choice(["ceramic", "glass"], [0.75, 0.25]),
         "style": s.choice(["classic", "cylinder", "bottle", "bulb"])}
    p["color"] = s.color(CERAMIC) if p["material"] == "ceramic" else s.color(((0.6, 0.75, 0.75), (0.3, 0.5, 0.4)))
    p["band"] = s.chance(0.2)
    w = s.around(0.15, 0.25)
    return (w, w, s.around(0.3, 0.25)), p


def generate_bowl(b: Builder, w, d, h, p):
    mat = param(p, "material", "ceramic")
    if mat not in MATERIALS:
        mat = "ceramic"
    col = param(p, "color", CERAMIC[0])
    prof = [(0, 0), (0.45, 0), (0.5, 0.1), (0.8, 0.4), (1.0, 1.0), (0.93, 1.0), (0.74, 0.45), (0.42, 0.2),
            (0, 0.17)]
    b.add("bowl", mat, revolve(prof, 0, 0, 0, w / 2, d / 2, h, sections=48), color=col)
    if param(p, "fruit", False):
        rng = np.random.default_rng(param(p, "fruit_seed", 0))
        fr = min(0.22 * w, 0.45 * h)
        fcols = ((0.6, 0.05, 0.03), (0.8, 0.45, 0.02), (0.5, 0.6, 0.05), (0.85, 0.7, 0.1))
        n = 3 + int(rng.integers(3))
        for i in range(n):
            a = 2 * math.pi * i / n + rng.uniform(-0.3, 0.3)
            rr = 0.3 * w / 2 if i else 0.0
            c = (rr * math.cos(a), rr * math.sin(a) * d / w, 0.17 * h + fr * 0.95)
            b.add(f"fruit_{i}", "plastic", ellipsoid(c, (fr, fr, min(fr, 0.95 * (h - c[2]) if h > c[2] else fr)),
                                                 subdiv=2), color=fcols[int(rng.integers(len(fcols)))])


def sample_bowl(s: ParamSampler):
    p = {"material": s.choice(["ceramic", "wood_light", "glass", "metal"], [0.55, 0.2, 0.15, 0.1])}
    p["color"] = s.color(CERAMIC)
    p["fruit"] = s.chance(0.35)
    p["fruit_seed"] = s.seed()
    w = s.around(0.25, 0.2)
    return (w, w, s.around(0.09, 0.2)), p


def generate_picture(b: Builder, w, d, h, p):
    fmat = param(p, "frame_material", "wood_dark")
    if fmat not in MATERIALS:
        fmat = "wood_dark"
    fcol = param(p, "frame_color", DARK) if fmat in ("painted", "metal") else None
    fw = clamp(param(p, "frame_width", 0.03), 0.0, 0.2 * min(w, h))
    ccol = param(p, "canvas_color", (0.7, 0.65, 0.55))
    mat_border = clamp(param(p, "mat_width", 0.0), 0.0, 0.25 * min(w, h))
    seed = param(p, "art_seed", 0)
    rec = min(0.006, 0.3 * d) if fw > 0 else min(0.0012, 0.1 * d)
    yc = d / 2 - rec
    if fw > 0:
        b.add("frame", fmat, concat([
            box(-w / 2, w / 2, -d / 2, d / 2, 0, fw), box(-w / 2, w / 2, -d / 2, d / 2, h - fw, h),
            box(-w / 2, -w / 2 + fw, -d / 2, d / 2, fw, h - fw), box(w / 2 - fw, w / 2, -d / 2, d / 2, fw, h - fw)]),
            color=fcol)
    x0, x1, z0, z1 = -w / 2 + fw, w / 2 - fw, fw, h - fw
    if mat_border > 0:
        b.add("mat", "paper", box(x0, x1, -d / 2, yc, z0, z1), color=(0.92, 0.91, 0.88))
        x0, x1, z0, z1 = x0 + mat_border, x1 - mat_border, z0 + mat_border, z1 - mat_border
        yc += 0.0005
    b.add("canvas", "canvas", box(x0, x1, -d / 2, yc, z0, z1), color=ccol)
    rng = np.random.default_rng(seed)
    n = 2 + int(rng.integers(4))
    cw, chh = x1 - x0, z1 - z0
    for i in range(n):
        col = tuple(float(c) for c in np.round(rng.uniform(0.03, 0.9, size=3), 3))
        cx = x0 + cw * rng.uniform(0.2, 0.8)
        cz = z0 + chh * rng.uniform(0.2, 0.8)
        sx = cw * rng.uniform(0.1, 0.35)
        sz = chh * rng.uniform(0.1, 0.35)
        ya, yb = yc + 0.0002 * i, yc + 0.0002 * (i + 1)
        if yb > d / 2 - 0.0002:
            break
        if rng.random() < 0.5:
            m = box(max(cx - sx, x0), min(cx + sx, x1), ya, yb, max(cz - sz, z0), min(cz + sz, z1))
        else:
            r = min(sx, sz, cx - x0, x1 - cx, cz - z0, z1 - cz)
            m = y_cylinder(cx, cz, ya, yb, r, r, sections=32)
        b.add(f"art_{i}", "canvas", m, color=col)


def sample_picture(s: ParamSampler):
    p = {"frame_material": s.choice(["wood_dark", "wood_light", "metal", "painted"])}
    if p["frame_material"] in ("metal", "painted"):
        p["frame_color"] = s.color(PAINT)
    p["frame_width"] = s.choice([0.0, s.uniform(0.015, 0.06)], [0.2, 0.8])
    p["mat_width"] = s.choice([0.0, s.uniform(0.03, 0.08)], [0.6, 0.4])
    p["canvas_color"] = s.color(FABRIC + LINEN)
    p["art_seed"] = s.seed()
    a, b_ = s.around(0.7, 0.3), s.around(0.5, 0.3)
    if s.chance(0.35):
        a, b_ = b_, a
    return (a, s.uniform(0.02, 0.04), b_), p


def generate_mirror(b: Builder, w, d, h, p):
    shape = param(p, "shape", "rect")
    fmat = param(p, "frame_material", "metal")
    if fmat not in MATERIALS:
        fmat = "metal"
    fcol = param(p, "frame_color", (0.7, 0.6, 0.35)) if fmat in ("painted", "metal") else None
    fw = clamp(param(p, "frame_width", 0.03), 0.003, 0.2 * min(w, h))
    rec = min(0.004, 0.3 * d)
    if shape == "round":
        b.add("frame", fmat, y_cylinder(0, h / 2, -d / 2, d / 2, w / 2, h / 2, sections=64,
                                        r_in=max(0.05, 1 - fw / (min(w, h) / 2))), color=fcol)
        b.add("pane", "mirror", y_cylinder(0, h / 2, -d / 2, d / 2 - rec, w / 2 - fw + 0.002, h / 2 - fw + 0.002,
                                           sections=64))
        b.add("backing", "wood_dark", y_cylinder(0, h / 2, -d / 2, -d / 2 + 0.004, w / 2 - fw + 0.003,
                                                 h / 2 - fw + 0.003, sections=64))
    else:
        b.add("frame", fmat, concat([
            box(-w / 2, w / 2, -d / 2, d / 2, 0, fw), box(-w / 2, w / 2, -d / 2, d / 2, h - fw, h),
            box(-w / 2, -w / 2 + fw, -d / 2, d / 2, fw, h - fw), box(w / 2 - fw, w / 2, -d / 2, d / 2, fw, h - fw)]),
            color=fcol)
        b.add("pane", "mirror", box(-w / 2 + fw, w / 2 - fw, -d / 2, d / 2 - rec, fw, h - fw))


def sample_mirror(s: ParamSampler):
    p = {"shape": s.choice(["rect", "round"], [0.7, 0.3]),
         "frame_material": s.choice(["metal", "wood_dark", "painted"])}
    if p["frame_material"] != "wood_dark":
        p["frame_color"] = s.color(((0.7, 0.6, 0.35), (0.08, 0.08, 0.09), (0.85, 0.85, 0.83)))
    p["frame_width"] = s.uniform(0.015, 0.05)
    if p["shape"] == "round":
        w = s.around(0.65, 0.2)
        return (w, s.uniform(0.02, 0.04), w), p
    return (s.around(0.6, 0.2), s.uniform(0.02, 0.04), s.around(0.9, 0.25)), p


def generate_bin(b: Builder, w, d, h, p):
    mat = param(p, "material", "metal")
    if mat not in MATERIALS:
        mat = "metal"
    col = param(p, "color", PLASTIC[2])
    shape = param(p, "shape", "round")
    lid = param(p, "lid", False)
    lh = min(0.025, 0.1 * h) if lid else 0.0
    hb = h - lh
    if shape == "square":
        s = min(0.006, 0.05 * min(w, d))
        b.add("body", mat, concat([
            box(-w / 2, w / 2, -d / 2, d / 2, 0, 0.01), box(-w / 2, -w / 2 + s, -d / 2, d / 2, 0, hb),
            box(w / 2 - s, w / 2, -d / 2, d / 2, 0, hb), box(-w / 2, w / 2, -d / 2, -d / 2 + s, 0, hb),
            box(-w / 2, w / 2, d / 2 - s, d / 2, 0, hb)]), color=col)
        if lid:
            b.add("lid", mat, box(-w / 2, w / 2, -d / 2, d / 2, hb, h), color=col)
    else:
        prof = [(0, 0), (0.9, 0), (1.0, 1.0), (0.95, 1.0), (0.86, 0.03), (0, 0.03)]
        b.add("body", mat, revolve(prof, 0, 0, 0, w / 2, d / 2, hb, sections=40), color=col)
        if lid:
            b.add("lid", mat, revolve([(0, 0), (1.0, 0), (0.95, 0.6), (0.4, 1.0), (0, 1.0)], 0, 0, hb, w / 2, d / 2, lh,
                                      sections=40), color=col)
    b.add("liner", "plastic", revolve([(0.0, 0.0), (0.6, 0.0), (0.6, 1.0), (0.0, 1.0)], 0, 0, 0.005,
                                      w / 2 * 0.8, d / 2 * 0.8, 0.01, sections=24), color=DARK)


def sample_bin(s: ParamSampler):
    p = {"material": s.choice(["metal", "plastic"]), "shape": s.choice(["round", "square"], [0.65, 0.35])}
    p["color"] = s.color(PLASTIC + ((0.7, 0.7, 0.72),))
    p["lid"] = s.chance(0.4)
    w = s.around(0.3, 0.15)
    return (w, w if p["shape"] == "round" else s.around(w, 0.15), s.around(0.4, 0.15)), p


def generate_basket(b: Builder, w, d, h, p):
    col = param(p, "color", (0.55, 0.4, 0.22))
    shape = param(p, "shape", "rect")
    mat = "wicker"
    rim_h = min(0.03, 0.12 * h)
    if shape == "round":
        prof = [(0, 0), (0.85, 0), (1.0, 1.0), (0.93, 1.0), (0.8, 0.05), (0, 0.05)]
        b.add("body", mat, revolve(prof, 0, 0, 0, w / 2 * 0.97, d / 2 * 0.97, h - rim_h * 0.5, sections=40), color=col)
        b.add("rim", mat, revolve([(0.9, 0.0), (1.0, 0.0), (1.0, 1.0), (0.9, 1.0), (0.9, 0.0)], 0, 0, h - rim_h, w / 2,
                                  d / 2, rim_h, sections=40), color=tuple(c * 0.8 for c in col))
    else:
        s = min(0.012, 0.05 * min(w, d))
        i = 0.01
        b.add("body", mat, concat([
            box(-w / 2 + i, w / 2 - i, -d / 2 + i, d / 2 - i, 0, 0.015),
            box(-w / 2 + i, -w / 2 + i + s, -d / 2 + i, d / 2 - i, 0, h - rim_h),
            box(w / 2 - i - s, w / 2 - i, -d / 2 + i, d / 2 - i, 0, h - rim_h),
            box(-w / 2 + i, w / 2 - i, -d / 2 + i, -d / 2 + i + s, 0, h - rim_h),
            box(-w / 2 + i, w / 2 - i, d / 2 - i - s, d / 2 - i, 0, h - rim_h)]), color=col)
        r = s + i
        b.add("rim", mat, concat([
            box(-w / 2, w / 2, -d / 2, -d / 2 + r, h - rim_h, h), box(-w / 2, w / 2, d / 2 - r, d / 2, h - rim_h, h),
            box(-w / 2, -w / 2 + r, -d / 2, d / 2, h - rim_h, h), box(w / 2 - r, w / 2, -d / 2, d / 2, h - rim_h, h)]),
            color=tuple(c * 0.8 for c in col))
    if param(p, "liner", False):
        lcol = param(p, "liner_color", LINEN[1])
        if shape == "round":
            liner = cylinder(0, 0, 0.015, 0.3 * h, 0.83 * w / 2, 0.83 * d / 2, sections=40)
        else:
            liner = box(-w / 2 + 0.03, w / 2 - 0.03, -d / 2 + 0.03, d / 2 - 0.03, 0.015, 0.3 * h)
        b.add("liner", "fabric", liner, color=lcol)


def sample_basket(s: ParamSampler):
    p = {"shape": s.choice(["rect", "round"]),
         "color": s.color(((0.55, 0.4, 0.22), (0.35, 0.25, 0.15), (0.75, 0.65, 0.45)))}
    p["liner"] = s.chance(0.3)
    p["liner_color"] = s.color(LINEN + FABRIC)
    w = s.around(0.4, 0.2)
    return (w, w if p["shape"] == "round" else s.around(0.3, 0.2), s.around(0.3, 0.2)), p


def generate_other(b: Builder, w, d, h, p):
    mat = param(p, "material", "painted")
    if mat not in MATERIALS:
        mat = "painted"
    b.add("box", mat, box(-w / 2, w / 2, -d / 2, d / 2, 0, h), color=param(p, "color", PAINT[2]))


def sample_other(s: ParamSampler):
    p = {"color": s.color(PAINT + PLASTIC)}
    return (s.around(0.4, 0.3), s.around(0.4, 0.3), s.around(0.4, 0.3)), p
