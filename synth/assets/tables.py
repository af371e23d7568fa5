"""Tables: dining, coffee and side tables (one generator), desk (each generator beside its sampler)."""
from __future__ import annotations

import math

from .components import casework, four_legs, leg
from .materials import DARK, MARBLE, MATERIALS, PAINT, WOODS
from .primitives import INF, Builder, box, clamp, cylinder, param
from .sampling import ParamSampler


def _generate_table(b: Builder, w, d, h, p, kind="dining_table"):
    shape = param(p, "top_shape", "rect")
    tmat = param(p, "top_material", "wood_light")
    if tmat not in MATERIALS:
        tmat = "wood_light"
    tcol = param(p, "top_color", PAINT[0]) if tmat in ("painted", "marble", "glass") else None
    lmat = param(p, "leg_material", tmat if tmat in WOODS else "metal")
    if lmat not in MATERIALS:
        lmat = "metal"
    lcol = param(p, "leg_color", DARK) if lmat in ("painted", "metal") else None
    base = param(p, "base", "legs4")
    if shape == "round" and base == "panels":
        base = "legs4"
    lstyle = param(p, "leg_style", "square")
    lt = clamp(param(p, "leg_thickness", 0.05), 0.01, 0.2 * min(w, d))
    tt = clamp(param(p, "top_thickness", 0.035), 0.005, 0.3 * h)
    inset = clamp(param(p, "leg_inset", 0.05), 0.0, 0.2 * min(w, d))
    apron = param(p, "apron", False) and base in ("legs4",) and shape == "rect"
    shelf = param(p, "shelf", False) and base in ("legs4", "panels") and shape == "rect"
    zt = h - tt
    if shape == "round":
        b.add("top", tmat, cylinder(0, 0, zt, h, w / 2, d / 2, sections=64), color=tcol)
    else:
        b.add("top", tmat, box(-w / 2, w / 2, -d / 2, d / 2, zt, h), color=tcol)
    lx = w / 2 - inset - lt / 2
    ly = d / 2 - inset - lt / 2
    inner = None
    if base in ("legs4", "legs3"):
        if shape == "round":
            n = 3 if base == "legs3" else 4
            a0 = math.pi / 2 if n == 3 else math.pi / 4
            pts = [(math.cos(a0 + k * 2 * math.pi / n) * lx, math.sin(a0 + k * 2 * math.pi / n) * ly)
                   for k in range(n)]
        elif base == "legs3":
            pts = [(-lx, -ly), (lx, -ly), (0.0, ly)]
        else:
            pts = [(-lx, -ly), (lx, -ly), (-lx, ly), (lx, ly)]
        for i, (x, y) in enumerate(pts):
            b.add(f"leg_{i}", lmat, leg(x, y, 0, zt, lt, lstyle), color=lcol)
        inner = (lx, ly)
        if apron:
            ah = clamp(param(p, "apron_height", 0.08), 0.02, 0.3 * zt)
            at = min(0.02, lt / 2)
            for i, sy in enumerate((-1, 1)):
                b.add(f"apron_{i}", lmat if lmat in WOODS else tmat,
                      box(-lx, lx, sy * (ly + lt / 2 - at), sy * (ly + lt / 2), zt - ah, zt),
                      color=lcol if lmat in WOODS else tcol)
            for i, sx in enumerate((-1, 1)):
                b.add(f"apron_{i + 2}", lmat if lmat in WOODS else tmat,
                      box(sx * (lx + lt / 2 - at), sx * (lx + lt / 2), -ly, ly, zt - ah, zt),
                      color=lcol if lmat in WOODS else tcol)
    elif base == "panels":
        pt = clamp(lt, 0.015, 0.1 * w)
        for i, sx in enumerate((-1, 1)):
            xa, xb = sorted((sx * (w / 2 - inset), sx * (w / 2 - inset - pt)))
            b.add(f"leg_{i}", lmat, box(xa, xb, -d / 2 + inset / 2, d / 2 - inset / 2, 0, zt), color=lcol)
        inner = (w / 2 - inset - pt, d / 2 - inset / 2)
    elif shape == "rect" and w > 1.3 * d:  # trestle: two pedestals with feet along y
        rc = clamp(0.04 + 0.03 * min(w, d), 0.02, 0.1 * min(w, d))
        fy = 0.4 * d
        fh = min(0.05, 0.1 * zt)
        for i, sx in enumerate((-1, 1)):
            x = sx * 0.3 * w
            b.add(f"foot_{i}", lmat, box(x - rc, x + rc, -fy, fy, 0, fh), color=lcol)
            b.add(f"column_{i}", lmat, box(x - 0.7 * rc, x + 0.7 * rc, -0.7 * rc * 2, 0.7 * rc * 2, fh, zt - fh),
                  color=lcol)
            b.add(f"cleat_{i}", lmat, box(x - rc, x + rc, -fy, fy, zt - fh, zt), color=lcol)
        b.add("stretcher", lmat, box(-0.3 * w, 0.3 * w, -0.5 * rc, 0.5 * rc, 0.45 * zt, 0.45 * zt + 2 * rc),
              color=lcol)
    else:  # pedestal
        rc = clamp(0.04 + 0.05 * min(w, d), 0.02, 0.15 * min(w, d))
        rb = clamp(0.32 * min(w, d), 1.5 * rc, 0.45 * min(w, d))
        bh = min(0.03, 0.1 * zt)
        b.add("base", lmat, cylinder(0, 0, 0, bh, rb, sections=48), color=lcol)
        b.add("column", lmat, cylinder(0, 0, bh, zt, rc, sections=32), color=lcol)
        b.add("column_cap", lmat, cylinder(0, 0, zt - 0.02, zt, rc * 2.5, sections=32), color=lcol)
    if shelf and inner is not None:
        sx, sy = inner
        zsh = clamp(param(p, "shelf_height", 0.12), 0.03, 0.5 * zt)
        sth = min(0.02, 0.1 * zt)
        b.add("shelf", tmat if tmat != "glass" else "wood_dark", box(-sx, sx, -sy, sy, zsh, zsh + sth),
              color=tcol if tmat != "glass" else None)
        b.surf(zsh + sth, -sx + lt / 2, sx - lt / 2, -sy + lt / 2, sy - lt / 2, zt - zsh - sth - 0.02)
    f = 0.7071 if shape == "round" else 1.0
    b.surf(h, -f * w / 2, f * w / 2, -f * d / 2, f * d / 2, INF)


def _sample_table_common(s: ParamSampler, p, top_opts=("wood_light", "wood_dark", "painted", "glass", "marble"),
                         probs=(0.35, 0.3, 0.15, 0.1, 0.1)):
    p["top_material"] = s.choice(list(top_opts), list(probs))
    if p["top_material"] in ("painted", "marble", "glass"):
        p["top_color"] = s.color(PAINT if p["top_material"] == "painted" else
                                 (MARBLE if p["top_material"] == "marble" else ((0.75, 0.85, 0.85),)), 0.02)
    if p["top_material"] in WOODS:
        p["leg_material"] = s.choice([p["top_material"], "metal"], [0.75, 0.25])
    else:
        p["leg_material"] = s.choice(["metal", "wood_dark", "wood_light"])
    if p["leg_material"] == "metal":
        p["leg_color"] = s.color(((0.08, 0.08, 0.09), (0.6, 0.6, 0.62), (0.7, 0.55, 0.3)))
    p["leg_style"] = s.choice(["square", "round", "tapered"])
    p["top_thickness"] = s.uniform(0.02, 0.05)


def generate_dining_table(b: Builder, w, d, h, p):
    _generate_table(b, w, d, h, p, "dining_table")


def sample_dining_table(s: ParamSampler):
    p = {}
    _sample_table_common(s, p)
    p["top_shape"] = s.choice(["rect", "round"], [0.75, 0.25])
    p["base"] = s.choice(["legs4", "pedestal"], [0.8, 0.2] if p["top_shape"] == "rect" else [0.5, 0.5])
    p["leg_thickness"] = s.uniform(0.04, 0.07) if p["leg_material"] != "metal" else s.uniform(0.025, 0.045)
    p["leg_inset"] = s.uniform(0.02, 0.09)
    p["apron"] = s.chance(0.5)
    p["apron_height"] = s.uniform(0.06, 0.1)
    h = s.uniform(0.72, 0.77)
    if p["top_shape"] == "round":
        w = s.around(1.05, 0.15)
        return (w, w, h), p
    return (s.around(1.6, 0.2), s.around(0.9, 0.12), h), p


def generate_coffee_table(b: Builder, w, d, h, p):
    _generate_table(b, w, d, h, p, "coffee_table")


def sample_coffee_table(s: ParamSampler):
    p = {}
    _sample_table_common(s, p)
    p["top_shape"] = s.choice(["rect", "round"], [0.75, 0.25])
    p["base"] = s.choice(["legs4", "panels"], [0.7, 0.3]) if p["top_shape"] == "rect" else s.choice(["legs4", "legs3",
                                                                                            "pedestal"])
    p["leg_thickness"] = s.uniform(0.03, 0.06)
    p["leg_inset"] = s.uniform(0.01, 0.06)
    p["shelf"] = s.chance(0.4)
    p["shelf_height"] = s.uniform(0.08, 0.15)
    h = s.around(0.42, 0.12)
    if p["top_shape"] == "round":
        w = s.around(0.8, 0.15)
        return (w, w, h), p
    return (s.around(1.0, 0.25), s.around(0.55, 0.2), h), p


def generate_side_table(b: Builder, w, d, h, p):
    _generate_table(b, w, d, h, p, "side_table")


def sample_side_table(s: ParamSampler):
    p = {}
    _sample_table_common(s, p)
    p["top_shape"] = s.choice(["rect", "round"])
    p["base"] = s.choice(["legs4", "legs3", "pedestal"], [0.5, 0.2, 0.3])
    p["leg_thickness"] = s.uniform(0.025, 0.045)
    p["leg_inset"] = s.uniform(0.01, 0.04)
    p["shelf"] = s.chance(0.3)
    p["shelf_height"] = s.uniform(0.1, 0.2)
    w = s.around(0.5, 0.2)
    d = w if p["top_shape"] == "round" else s.around(w, 0.1)
    return (w, d, s.around(0.55, 0.15)), p


def generate_desk(b: Builder, w, d, h, p):
    tmat = param(p, "top_material", "wood_light")
    if tmat not in MATERIALS:
        tmat = "wood_light"
    tcol = param(p, "top_color", PAINT[0]) if tmat in ("painted",) else None
    bmat = param(p, "body_material", tmat)
    if bmat not in MATERIALS:
        bmat = tmat
    bcol = param(p, "body_color", PAINT[0]) if bmat in ("painted", "metal") else None
    base = param(p, "base", "drawers")
    side = param(p, "drawer_side", "right")
    n_dr = int(clamp(param(p, "n_drawers", 3), 1, 5))
    lstyle = param(p, "leg_style", "square")
    lt = clamp(param(p, "leg_thickness", 0.045), 0.01, 0.2 * min(w, d))
    tt = clamp(param(p, "top_thickness", 0.03), 0.005, 0.2 * h)
    handle = param(p, "handle", "bar")
    zt = h - tt
    b.add("top", tmat, box(-w / 2, w / 2, -d / 2, d / 2, zt, h), color=tcol)
    inset = min(0.03, 0.05 * w)
    if base == "panels":
        pt = min(0.025, 0.08 * w)
        for i, sx in enumerate((-1, 1)):
            xa, xb = sorted((sx * (w / 2 - inset), sx * (w / 2 - inset - pt)))
            b.add(f"leg_{i}", bmat, box(xa, xb, -d / 2 + inset, d / 2 - inset, 0, zt), color=bcol)
        b.add("modesty_panel", bmat, box(-w / 2 + inset + pt, w / 2 - inset - pt, -d / 2 + 0.04, -d / 2 + 0.058,
                                         0.4 * zt, zt), color=bcol)
    elif base == "drawers":
        pw = clamp(0.4, 0.2 * w, 0.45 * w)
        sgn = 1 if side != "left" else -1
        xa, xb = sorted((sgn * (w / 2 - inset), sgn * (w / 2 - inset - pw)))
        casework(b, "pedestal_", xa, xb, -d / 2 + inset, d / 2 - inset * 0.5, 0.0, zt,
                 [("drawers", 1, 1)] * n_dr, bmat, bcol, handle=handle, top=True)
        lx = w / 2 - inset - lt / 2
        ly = d / 2 - inset - lt / 2
        for i, y in enumerate((-ly, ly)):
            b.add(f"leg_{i}", bmat, leg(-sgn * lx, y, 0, zt, lt, lstyle), color=bcol)
    else:
        four_legs(b, w, d, zt, lt, lstyle, bmat, bcol, inset=inset)
    b.surf(h, -w / 2, w / 2, -d / 2, d / 2, INF)


def sample_desk(s: ParamSampler):
    p = {}
    p["top_material"] = s.choice(["wood_light", "wood_dark", "painted"], [0.4, 0.35, 0.25])
    if p["top_material"] == "painted":
        p["top_color"] = s.color(PAINT)
    p["body_material"] = s.choice([p["top_material"], "metal", "painted"], [0.6, 0.2, 0.2])
    if p["body_material"] in ("painted", "metal"):
        p["body_color"] = s.color(PAINT)
    p["base"] = s.choice(["drawers", "legs", "panels"], [0.45, 0.35, 0.2])
    p["drawer_side"] = s.choice(["right", "left"], [0.7, 0.3])
    p["n_drawers"] = s.integer(2, 4)
    p["leg_style"] = s.choice(["square", "round"])
    p["leg_thickness"] = s.uniform(0.035, 0.055)
    p["top_thickness"] = s.uniform(0.022, 0.04)
    p["handle"] = s.choice(["bar", "knob"])
    return (s.around(1.2, 0.2), s.around(0.62, 0.12), s.uniform(0.72, 0.77)), p
