"""Beds: frame, headboard, mattress and duvet (the generator beside its sampler)."""
from __future__ import annotations

import numpy as np

from .components import body_material, four_legs
from .materials import FABRIC, LINEN, PAINT
from .primitives import INF, Builder, box, clamp, param, soft_box
from .sampling import ParamSampler


def generate_bed(b: Builder, w, d, h, p):
    fmat, fcol = body_material(p, "wood_light")
    hb_style = param(p, "headboard_style", "panel")
    hb_col = param(p, "headboard_color", FABRIC[0])
    lh = clamp(param(p, "leg_height", 0.1), 0.0, 0.2 * h)
    ftop = clamp(param(p, "frame_height", 0.32), lh + 0.05, 0.55 * h)
    mth = clamp(param(p, "mattress_thickness", 0.22), 0.05, 0.8 * (h - ftop))
    hbt = clamp(param(p, "headboard_thickness", 0.06), 0.02, 0.1 * d)
    footboard = param(p, "footboard", False)
    fbt = min(0.04, 0.05 * d) if footboard else 0.0
    mcol = param(p, "mattress_color", LINEN[0])
    duvet = param(p, "duvet", True)
    dcol = param(p, "duvet_color", FABRIC[5])
    y0, y1 = -d / 2 + hbt, d / 2 - fbt
    if lh > 0.005:
        four_legs(b, w, y1 - y0, lh + 0.005, 0.05, "square", fmat, fcol, inset=0.03, yoff=(y0 + y1) / 2)
    else:
        lh = 0.0
    b.add("frame", fmat, box(-w / 2, w / 2, y0, y1, lh, ftop), color=fcol)
    if hb_style == "upholstered":
        b.add("headboard_post", fmat, box(-w / 2, w / 2, -d / 2, -d / 2 + hbt * 0.4, 0, ftop + 0.1), color=fcol)
        b.add("headboard", "fabric", soft_box(-w / 2, w / 2, -d / 2, -d / 2 + hbt, ftop - 0.05, h, e=0.2),
              color=hb_col)
    elif hb_style == "slats":
        pt = min(0.06, 0.05 * w)
        for i, sx in enumerate((-1, 1)):
            xa, xb = sorted((sx * w / 2, sx * (w / 2 - pt)))
            b.add(f"headboard_post_{i}", fmat, box(xa, xb, -d / 2, y0, 0, h), color=fcol)
        b.add("headboard", fmat, box(-w / 2 + pt, w / 2 - pt, -d / 2, y0, h - 0.08, h), color=fcol)
        n = max(3, int((w - 2 * pt) / 0.15))
        for i, cx in enumerate(np.linspace(-w / 2 + pt, w / 2 - pt, n + 2)[1:-1]):
            b.add(f"headboard_slat_{i}", fmat, box(cx - 0.025, cx + 0.025, -d / 2 + 0.01, y0 - 0.01, ftop, h - 0.08),
                  color=fcol)
    else:
        b.add("headboard", fmat, box(-w / 2, w / 2, -d / 2, y0, 0, h), color=fcol)
    if footboard:
        fh = min(ftop + clamp(param(p, "footboard_height", 0.1), 0.0, 0.3), h)
        b.add("footboard", fmat, box(-w / 2, w / 2, y1, d / 2, 0, fh), color=fcol)
    mz0 = ftop - min(0.05, 0.3 * mth)
    mt = mz0 + mth
    mx = min(0.03, 0.05 * w)
    my0, my1 = y0 + 0.01, y1 - 0.015
    b.add("mattress", "mattress", soft_box(-w / 2 + mx, w / 2 - mx, my0, my1, mz0, mt, e=0.15), color=mcol)
    if duvet:
        dy0 = my0 + 0.3 * (my1 - my0)
        dz = min(0.03, 0.2 * mth)
        b.add("duvet", "fabric", soft_box(-w / 2 + mx - 0.02, w / 2 - mx + 0.02, dy0, my1 + 0.01,
                                          mz0 + 0.35 * mth, mt + dz, e=0.15), color=dcol)
        b.surf(mt, -w / 2 + mx, w / 2 - mx, my0, dy0, INF)
        b.surf(mt + dz, -w / 2 + mx, w / 2 - mx, dy0, my1, INF)
    else:
        b.surf(mt, -w / 2 + mx, w / 2 - mx, my0, my1, INF)


def sample_bed(s: ParamSampler):
    p = {}
    p["material"] = s.choice(["wood_light", "wood_dark", "painted"], [0.4, 0.35, 0.25])
    if p["material"] == "painted":
        p["color"] = s.color(PAINT)
    p["headboard_style"] = s.choice(["panel", "upholstered", "slats"])
    p["headboard_color"] = s.color(FABRIC)
    p["leg_height"] = s.choice([0.0, s.uniform(0.05, 0.16)])
    p["frame_height"] = s.uniform(0.26, 0.4)
    p["mattress_thickness"] = s.uniform(0.18, 0.26)
    p["headboard_thickness"] = s.uniform(0.04, 0.1)
    p["footboard"] = s.chance(0.3)
    p["footboard_height"] = s.uniform(0.0, 0.15)
    p["mattress_color"] = s.color(LINEN, 0.02)
    p["duvet"] = s.chance(0.75)
    p["duvet_color"] = s.color(FABRIC + LINEN)
    w = round(s.choice([0.9, 1.4, 1.6, 1.8]) + s.uniform(0.04, 0.12), 3)
    return (w, s.uniform(2.02, 2.2), s.uniform(0.75, 1.25)), p
