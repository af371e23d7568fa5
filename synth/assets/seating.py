"""Seating: chair, stool, armchair, sofa, bench (each generator beside its sampler)."""
from __future__ import annotations

import math

import numpy as np

from .components import four_legs, leg
from .materials import FABRIC, LEATHER, MATERIALS, PAINT
from .primitives import Builder, box, clamp, concat, cylinder, param, rod, soft_box
from .sampling import ParamSampler


def generate_chair(b: Builder, w, d, h, p):
    frame_mat = param(p, "frame_material", "wood_light")
    if frame_mat not in MATERIALS:
        frame_mat = "wood_light"
    frame_col = param(p, "frame_color", PAINT[1]) if frame_mat in ("painted", "metal") else None
    seat_mat = param(p, "seat_material", "wood")
    seat_col = param(p, "seat_color", FABRIC[0])
    if seat_mat not in ("fabric", "leather"):
        seat_mat, seat_col = frame_mat, frame_col
    style = param(p, "leg_style", "square")
    lt = clamp(param(p, "leg_thickness", 0.035), 0.01, 0.2 * min(w, d))
    sh = clamp(param(p, "seat_height", 0.45), 0.3 * h, 0.8 * h)
    st = clamp(param(p, "seat_thickness", 0.04), 0.01, 0.3 * sh)
    back_style = param(p, "back_style", "solid")
    n_slats = int(clamp(param(p, "n_slats", 3), 1, 8))
    arms = param(p, "armrests", False)
    stretchers = param(p, "stretchers", False)
    inset = min(0.01, 0.05 * w)
    lx = w / 2 - inset - lt / 2
    lyf = d / 2 - inset - lt / 2
    lyb = -d / 2 + inset + lt / 2
    az = clamp(sh + 0.21, sh + 0.3 * (h - sh), h - 0.1 * (h - sh))
    front_top = az if arms else sh - st
    b.add("seat", seat_mat, box(-w / 2, w / 2, -d / 2, d / 2, sh - st, sh), color=seat_col)
    b.add("leg_0", frame_mat, leg(-lx, lyf, 0, front_top, lt, style), color=frame_col)
    b.add("leg_1", frame_mat, leg(lx, lyf, 0, front_top, lt, style), color=frame_col)
    b.add("leg_2", frame_mat, leg(-lx, lyb, 0, h, lt, style), color=frame_col)
    b.add("leg_3", frame_mat, leg(lx, lyb, 0, h, lt, style), color=frame_col)
    bx0, bx1 = -lx + lt / 2, lx - lt / 2
    upholstered = back_style == "solid" and seat_mat in ("fabric", "leather")
    bt = lt if upholstered else min(0.022, lt * 0.75)
    by0, by1 = lyb - bt / 2, lyb + bt / 2
    if back_style == "slats":
        rail0 = h - 0.22 * (h - sh)
        b.add("back", frame_mat, box(bx0, bx1, by0, by1, rail0, h), color=frame_col)
        sw = min(0.04, (bx1 - bx0) / (2 * n_slats + 1))
        for i, cx in enumerate(np.linspace(bx0, bx1, n_slats + 2)[1:-1]):
            b.add(f"back_slat_{i}", frame_mat, box(cx - sw / 2, cx + sw / 2, by0 + 0.002, by1 - 0.002,
                                                   sh + 0.03, rail0), color=frame_col)
    elif back_style == "rails":
        zs = np.linspace(sh + 0.25 * (h - sh), h, 3)
        rh = min(0.06, 0.12 * (h - sh))
        for i, zt in enumerate(zs):
            nm = "back" if i == len(zs) - 1 else f"back_rail_{i}"
            b.add(nm, frame_mat, box(bx0, bx1, by0, by1, zt - rh, zt), color=frame_col)
    else:
        b.add("back", seat_mat if upholstered else frame_mat,
              box(bx0, bx1, by0, by1, sh + 0.12 * (h - sh), h), color=seat_col if upholstered else frame_col)
    if arms:
        for i, sx in enumerate((-1, 1)):
            b.add(f"armrest_{i}", frame_mat, box(sx * lx - lt / 2 - 0.003, sx * lx + lt / 2 + 0.003, lyb,
                                                 d / 2, az - 0.025, az), color=frame_col)
    if stretchers:
        zs_ = 0.3 * (sh - st)
        tt = 0.6 * lt
        for i, sx in enumerate((-1, 1)):
            b.add(f"stretcher_{i}", frame_mat, box(sx * lx - tt / 2, sx * lx + tt / 2, lyb, lyf,
                                                   zs_ - tt / 2, zs_ + tt / 2), color=frame_col)
        b.add("stretcher_2", frame_mat, box(-lx, lx, lyb - tt / 2, lyb + tt / 2, zs_ + 0.05 - tt / 2,
                                            zs_ + 0.05 + tt / 2), color=frame_col)
    ax = (lt + inset) if arms else 0.0
    b.surf(sh, -w / 2 + ax, w / 2 - ax, by1, d / 2, 0.5)


def _sample_frame(s: ParamSampler, p: dict, key="frame_material", color_key="frame_color",
                  options=("wood_light", "wood_dark", "metal", "painted"), probs=None):
    p[key] = s.choice(list(options), probs)
    if p[key] in ("painted", "metal"):
        p[color_key] = s.color(PAINT if p[key] == "painted" else ((0.08, 0.08, 0.09), (0.6, 0.6, 0.62)))


def sample_chair(s: ParamSampler):
    p = {}
    _sample_frame(s, p, probs=[0.35, 0.3, 0.15, 0.2])
    p["seat_material"] = s.choice(["wood", "fabric", "leather"], [0.45, 0.4, 0.15])
    if p["seat_material"] != "wood":
        p["seat_color"] = s.color(FABRIC if p["seat_material"] == "fabric" else LEATHER)
    p["leg_style"] = s.choice(["square", "round", "tapered"], [0.45, 0.35, 0.2])
    p["leg_thickness"] = s.uniform(0.018, 0.026) if p["frame_material"] == "metal" else s.uniform(0.028, 0.045)
    p["seat_height"] = s.uniform(0.43, 0.48)
    p["seat_thickness"] = s.uniform(0.03, 0.06)
    p["back_style"] = s.choice(["solid", "slats", "rails"])
    p["n_slats"] = s.integer(3, 5)
    p["armrests"] = s.chance(0.2)
    p["stretchers"] = s.chance(0.35)
    w = s.around(0.45, 0.12) + (0.08 if p["armrests"] else 0.0)
    return (round(w, 3), s.around(0.5, 0.12), s.around(0.86, 0.1)), p


def generate_stool(b: Builder, w, d, h, p):
    mat = param(p, "material", "wood_light")
    if mat not in MATERIALS:
        mat = "wood_light"
    col = param(p, "color", PAINT[1]) if mat in ("painted", "metal") else None
    seat_mat = param(p, "seat_material", "wood")
    seat_col = param(p, "seat_color", FABRIC[0])
    if seat_mat not in ("fabric", "leather"):
        seat_mat, seat_col = mat, col
    shape = param(p, "seat_shape", "round")
    n_legs = int(clamp(param(p, "n_legs", 4), 3, 4))
    if shape == "square":
        n_legs = 4
    style = param(p, "leg_style", "round")
    lt = clamp(param(p, "leg_thickness", 0.03), 0.01, 0.2 * min(w, d))
    st = clamp(param(p, "seat_thickness", 0.04), 0.01, 0.3 * h)
    footrest = param(p, "footrest", False)
    zt = h - st
    if shape == "square":
        b.add("seat", seat_mat, box(-w / 2, w / 2, -d / 2, d / 2, zt, h), color=seat_col)
    else:
        b.add("seat", seat_mat, cylinder(0, 0, zt, h, w / 2, d / 2, sections=48), color=seat_col)
    r = lt / 2
    if n_legs == 3:
        angles = [math.pi / 2 + k * 2 * math.pi / 3 for k in range(3)]
    else:
        angles = [math.pi / 4 + k * math.pi / 2 for k in range(4)]
    feet, tops = [], []
    for a in angles:
        ca, sa = math.cos(a), math.sin(a)
        if shape == "square":
            ux, uy = math.copysign(1, ca), math.copysign(1, sa)
            foot = (ux * (w / 2 - r - 0.004), uy * (d / 2 - r - 0.004))
            top = (ux * 0.72 * (w / 2 - r), uy * 0.72 * (d / 2 - r))
        else:
            foot = (ca * (w / 2 - r - 0.004), sa * (d / 2 - r - 0.004))
            top = (ca * 0.62 * w / 2, sa * 0.62 * d / 2)
        feet.append(foot)
        tops.append(top)
    for i, (f, t_) in enumerate(zip(feet, tops)):
        b.add(f"leg_{i}", mat, rod((f[0], f[1], 0.0), (t_[0], t_[1], zt), r, square=(style == "square")),
              color=col)
    if footrest:
        zf = 0.3 * h
        k = zf / zt
        pts = [(f[0] + (t_[0] - f[0]) * k, f[1] + (t_[1] - f[1]) * k) for f, t_ in zip(feet, tops)]
        for i in range(len(pts)):
            a0, a1 = pts[i], pts[(i + 1) % len(pts)]
            b.add(f"footrest_{i}", mat, rod((a0[0], a0[1], zf), (a1[0], a1[1], zf), 0.6 * r,
                                            square=(style == "square")), color=col)
    f = 0.7071 if shape != "square" else 1.0
    b.surf(h, -f * w / 2, f * w / 2, -f * d / 2, f * d / 2, 0.5)


def sample_stool(s: ParamSampler):
    p = {}
    p["material"] = s.choice(["wood_light", "wood_dark", "metal", "painted"])
    if p["material"] in ("metal", "painted"):
        p["color"] = s.color(PAINT)
    p["seat_material"] = s.choice(["wood", "fabric", "leather"], [0.6, 0.25, 0.15])
    if p["seat_material"] != "wood":
        p["seat_color"] = s.color(FABRIC if p["seat_material"] == "fabric" else LEATHER)
    p["seat_shape"] = s.choice(["round", "square"], [0.65, 0.35])
    p["n_legs"] = 4 if p["seat_shape"] == "square" else s.choice([3, 4])
    p["leg_style"] = s.choice(["round", "square"])
    p["leg_thickness"] = s.uniform(0.022, 0.035)
    p["seat_thickness"] = s.uniform(0.03, 0.05)
    h = s.choice([s.around(0.46, 0.08), s.around(0.65, 0.1), s.around(0.76, 0.06)])
    p["footrest"] = bool(h > 0.58 and s.chance(0.8))
    w = s.around(0.38, 0.15)
    d = w if p["seat_shape"] == "round" else s.around(w, 0.08)
    return (w, d, h), p


def _generate_upholstered(b: Builder, w, d, h, p, default_seats):
    fmat = param(p, "material", "fabric")
    if fmat not in ("fabric", "leather"):
        fmat = "fabric"
    col = param(p, "color", FABRIC[0])
    n = int(clamp(param(p, "n_seats", default_seats), 1, 4))
    lh = clamp(param(p, "leg_height", 0.08), 0.0, 0.25 * h)
    leg_mat = param(p, "leg_material", "wood_dark")
    if leg_mat not in MATERIALS:
        leg_mat = "wood_dark"
    arm_style = param(p, "arm_style", "box")
    aw = clamp(param(p, "arm_width", 0.15), 0.03, 0.2 * w) if arm_style != "none" else 0.0
    bt = clamp(param(p, "back_thickness", 0.18), 0.05, 0.35 * d)
    sh = clamp(param(p, "seat_height", 0.44), lh + 0.1 * h, 0.8 * h)
    ct = clamp(param(p, "cushion_thickness", 0.13), 0.02, 0.6 * (sh - lh))
    ah = clamp(param(p, "arm_height", 0.62), sh + 0.04, h)
    back_cushions = param(p, "back_cushions", True)
    bc = clamp(0.14, 0.02, 0.2 * d) if back_cushions else 0.0
    if lh > 0.005:
        lt = 0.04
        four_legs(b, w, d, lh + 0.005, lt, "tapered" if leg_mat.startswith("wood") else "round", leg_mat,
                  inset=0.04, n_mid=1 if n >= 3 else 0)
    else:
        lh = 0.0
    b.add("base", fmat, box(-w / 2 + aw, w / 2 - aw, -d / 2 + bt, d / 2, lh, sh - ct), color=col)
    b.add("back", fmat, soft_box(-w / 2, w / 2, -d / 2, -d / 2 + bt, lh, h, e=0.12), color=col)
    if aw > 0:
        for i, sx in enumerate((-1, 1)):
            xa, xb = sorted((sx * w / 2, sx * (w / 2 - aw)))
            if arm_style == "roll":
                rr = aw / 2
                arm = concat([box(xa, xb, -d / 2, d / 2, lh, ah - rr),
                              rod(((xa + xb) / 2, -d / 2, ah - rr), ((xa + xb) / 2, d / 2, ah - rr), rr,
                                  sections=24)])
            else:
                arm = soft_box(xa, xb, -d / 2, d / 2, lh, ah, e=0.12)
            b.add(f"arm_{i}", fmat, arm, color=col)
    xs = np.linspace(-w / 2 + aw, w / 2 - aw, n + 1)
    g = 0.004
    for i in range(n):
        b.add(f"seat_cushion_{i}", fmat,
              soft_box(xs[i] + g, xs[i + 1] - g, -d / 2 + bt + bc, d / 2, sh - ct, sh, e=0.25), color=col)
        if back_cushions:
            b.add(f"back_cushion_{i}", fmat,
                  soft_box(xs[i] + g, xs[i + 1] - g, -d / 2 + bt - 0.01, -d / 2 + bt + bc, sh - ct,
                           sh + 0.88 * (h - sh), e=0.25), color=col)
    b.surf(sh, -w / 2 + aw, w / 2 - aw, -d / 2 + bt + bc, d / 2, 0.5)


def _sample_upholstered(s: ParamSampler, sofa):
    p = {}
    p["material"] = s.choice(["fabric", "leather"], [0.75, 0.25])
    p["color"] = s.color(FABRIC if p["material"] == "fabric" else LEATHER)
    p["leg_height"] = s.choice([0.0, s.uniform(0.04, 0.16)], [0.25, 0.75])
    p["leg_material"] = s.choice(["wood_dark", "wood_light", "metal"])
    p["arm_style"] = s.choice(["box", "roll"], [0.7, 0.3])
    p["arm_width"] = s.uniform(0.1, 0.22) if sofa else s.uniform(0.1, 0.2)
    p["back_thickness"] = s.uniform(0.14, 0.24)
    p["seat_height"] = s.uniform(0.4, 0.47)
    p["cushion_thickness"] = s.uniform(0.1, 0.16)
    p["arm_height"] = s.uniform(0.55, 0.68)
    p["back_cushions"] = s.chance(0.6)
    if sofa:
        p["n_seats"] = s.choice([2, 3], [0.45, 0.55])
        w = round(p["n_seats"] * s.uniform(0.55, 0.72) + 2 * p["arm_width"], 3)
        return (w, s.around(0.9, 0.12), s.around(0.85, 0.1)), p
    p["n_seats"] = 1
    return (s.around(0.8, 0.15), s.around(0.82, 0.12), s.around(0.86, 0.12)), p


def generate_armchair(b: Builder, w, d, h, p):
    _generate_upholstered(b, w, d, h, p, 1)


def sample_armchair(s: ParamSampler):
    return _sample_upholstered(s, False)


def generate_sofa(b: Builder, w, d, h, p):
    _generate_upholstered(b, w, d, h, p, 3 if w > 1.9 else 2)


def sample_sofa(s: ParamSampler):
    return _sample_upholstered(s, True)


def generate_bench(b: Builder, w, d, h, p):
    mat = param(p, "material", "wood_light")
    if mat not in MATERIALS:
        mat = "wood_light"
    col = param(p, "color", PAINT[1]) if mat in ("painted", "metal") else None
    style = param(p, "style", "legs")
    lstyle = param(p, "leg_style", "square")
    lt = clamp(param(p, "leg_thickness", 0.045), 0.01, 0.25 * min(w, d))
    st = clamp(param(p, "seat_thickness", 0.04), 0.01, 0.25 * h)
    cushion = param(p, "cushion", False)
    ccol = param(p, "cushion_color", FABRIC[2])
    shelf = param(p, "shelf", False)
    ct = min(0.06, 0.15 * h) if cushion else 0.0
    zs1 = h - ct
    zs0 = zs1 - st
    b.add("seat", mat, box(-w / 2, w / 2, -d / 2, d / 2, zs0, zs1), color=col)
    if cushion:
        b.add("cushion", "fabric", soft_box(-w / 2 + 0.01, w / 2 - 0.01, -d / 2 + 0.01, d / 2 - 0.01, zs1 - 0.01,
                                            h, e=0.3), color=ccol)
    overhang = min(0.06, 0.08 * w)
    if style == "panels":
        pt = min(lt, 0.1 * w)
        for i, sx in enumerate((-1, 1)):
            xa, xb = sorted((sx * (w / 2 - overhang), sx * (w / 2 - overhang - pt)))
            b.add(f"leg_{i}", mat, box(xa, xb, -d / 2 + 0.01, d / 2 - 0.01, 0, zs0), color=col)
        lx, ly = w / 2 - overhang - pt, d / 2 - 0.01
    else:
        lx, ly = four_legs(b, w, d, zs0, lt, lstyle, mat, col, inset=overhang)
        lx, ly = lx - lt / 2, ly + lt / 2
    if shelf:
        zsh = clamp(0.12, 0.05, 0.5 * zs0)
        b.add("shelf", mat, box(-lx - 0.005, lx + 0.005, -ly, ly, zsh, zsh + 0.018), color=col)
        b.surf(zsh + 0.018, -lx, lx, -ly, ly, zs0 - zsh - 0.018)
    b.surf(h, -w / 2, w / 2, -d / 2, d / 2, 0.5)


def sample_bench(s: ParamSampler):
    p = {"material": s.choice(["wood_light", "wood_dark", "painted", "metal"], [0.4, 0.3, 0.2, 0.1])}
    if p["material"] in ("painted", "metal"):
        p["color"] = s.color(PAINT)
    p["style"] = s.choice(["legs", "panels"])
    p["leg_style"] = s.choice(["square", "round", "tapered"])
    p["leg_thickness"] = s.uniform(0.035, 0.055)
    p["seat_thickness"] = s.uniform(0.03, 0.06)
    p["cushion"] = s.chance(0.3)
    if p["cushion"]:
        p["cushion_color"] = s.color(FABRIC)
    p["shelf"] = s.chance(0.3)
    return (s.around(1.2, 0.25), s.around(0.4, 0.15), s.around(0.46, 0.08)), p
