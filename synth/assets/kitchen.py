"""Kitchen: counter run (with an optional sink), fridge, stove (each generator beside its sampler)."""
from __future__ import annotations

import numpy as np

from .components import body_material, casework, handle_mesh
from .materials import APPLIANCE, DARK, MARBLE, MATERIALS, PAINT
from .primitives import INF, Builder, box, clamp, concat, cylinder, param, rod
from .sampling import ParamSampler


def generate_kitchen_counter(b: Builder, w, d, h, p):
    mat, col = body_material(p, "painted")
    wt_mat = param(p, "worktop_material", "marble")
    if wt_mat not in MATERIALS:
        wt_mat = "marble"
    wt_col = param(p, "worktop_color", MARBLE[0]) if wt_mat in ("marble", "painted") else None
    wt = clamp(param(p, "worktop_thickness", 0.035), 0.01, 0.1 * h)
    handle = param(p, "handle", "bar")
    ph = clamp(param(p, "plinth_height", 0.1), 0.0, 0.2 * h)
    n_mod = int(clamp(param(p, "n_modules", max(1, int(round(w / 0.6)))), 1, 10))
    sink = param(p, "sink", True)
    sink_mod = int(clamp(param(p, "sink_module", n_mod // 2), 0, n_mod - 1))
    styles = p.get("module_styles") if isinstance(p, dict) else None
    if not isinstance(styles, (list, tuple)):
        styles = []
    overhang = min(0.025, 0.05 * d)
    fs = 0.018 + (0.025 if handle != "none" else 0.0)
    zt = h - wt
    if ph > 0:
        b.add("plinth", "painted", box(-w / 2, w / 2, -d / 2, d / 2 - overhang - fs - 0.05, 0, ph + 0.002),
              color=DARK)
    xs = np.linspace(-w / 2, w / 2, n_mod + 1)
    for i in range(n_mod):
        st = str(styles[i]) if i < len(styles) else ("doors" if i == sink_mod and sink else
                                                     ("drawers" if i % 2 else "mixed"))
        mw = xs[i + 1] - xs[i]
        if sink and i == sink_mod:
            st = "doors"
        if st == "drawers":
            rows = [("drawers", 1, 1)] * 3
        elif st == "mixed":
            rows = [("doors", 2 if mw > 0.7 else 1, 3), ("drawers", 1, 1)]
        else:
            rows = [("doors", 2 if mw > 0.7 else 1, 1)]
        casework(b, f"m{i}_", xs[i], xs[i + 1], -d / 2, d / 2 - overhang, ph, zt, rows, mat, col,
                 handle=handle, front_space=fs, top=not (sink and i == sink_mod), kick=0.0)
    if sink:
        mw = xs[sink_mod + 1] - xs[sink_mod]
        cx = (xs[sink_mod] + xs[sink_mod + 1]) / 2
        sw = clamp(param(p, "sink_width", 0.5), 0.2, mw - 0.1)
        sd = clamp(0.4, 0.15, d - 0.18)
        sx0, sx1 = cx - sw / 2, cx + sw / 2
        sy0, sy1 = -d / 2 + 0.1, -d / 2 + 0.1 + sd
        b.add("worktop_0", wt_mat, box(-w / 2, sx0, -d / 2, d / 2, zt, h), color=wt_col)
        b.add("worktop_1", wt_mat, box(sx1, w / 2, -d / 2, d / 2, zt, h), color=wt_col)
        b.add("worktop_2", wt_mat, box(sx0, sx1, -d / 2, sy0, zt, h), color=wt_col)
        b.add("worktop_3", wt_mat, box(sx0, sx1, sy1, d / 2, zt, h), color=wt_col)
        depth = clamp(0.18, 0.05, zt - ph - 0.05)
        zb = h - 0.002 - depth
        st_ = 0.008
        basin = concat([
            box(sx0, sx1, sy0, sy1, zb, zb + st_),
            box(sx0, sx0 + st_, sy0, sy1, zb, h - 0.001),
            box(sx1 - st_, sx1, sy0, sy1, zb, h - 0.001),
            box(sx0, sx1, sy0, sy0 + st_, zb, h - 0.001),
            box(sx0, sx1, sy1 - st_, sy1, zb, h - 0.001),
        ])
        b.add("sink", "metal", basin)
        b.add("drain", "metal", cylinder(cx, (sy0 + sy1) / 2, zb + st_, zb + st_ + 0.002, 0.035), color=DARK)
        b.surf(h, -w / 2, sx0, -d / 2, d / 2, INF)
        b.surf(h, sx1, w / 2, -d / 2, d / 2, INF)
    else:
        b.add("worktop", wt_mat, box(-w / 2, w / 2, -d / 2, d / 2, zt, h), color=wt_col)
        b.surf(h, -w / 2, w / 2, -d / 2, d / 2, INF)


def sample_kitchen_counter(s: ParamSampler):
    p = {}
    p["material"] = s.choice(["painted", "wood_light", "wood_dark"], [0.6, 0.25, 0.15])
    if p["material"] == "painted":
        p["color"] = s.color(PAINT, 0.02)
    p["worktop_material"] = s.choice(["marble", "wood_light", "wood_dark"], [0.6, 0.25, 0.15])
    if p["worktop_material"] == "marble":
        p["worktop_color"] = s.color(MARBLE, 0.02)
    p["worktop_thickness"] = s.uniform(0.028, 0.045)
    p["handle"] = s.choice(["bar", "knob", "none"], [0.6, 0.2, 0.2])
    p["plinth_height"] = s.uniform(0.08, 0.13)
    w = round(s.choice([1.2, 1.8, 2.4, 3.0]) * s.uniform(0.95, 1.05), 3)
    n = max(1, int(round(w / 0.6)))
    p["n_modules"] = n
    p["sink"] = s.chance(0.6)
    p["sink_module"] = s.integer(0, n - 1)
    p["sink_width"] = s.uniform(0.4, 0.52)
    p["module_styles"] = [s.choice(["drawers", "mixed", "doors"]) for _ in range(n)]
    return (w, s.uniform(0.6, 0.65), s.uniform(0.88, 0.92)), p


def generate_fridge(b: Builder, w, d, h, p):
    mat = param(p, "material", "metal")
    if mat not in ("metal", "painted", "plastic"):
        mat = "metal"
    col = param(p, "color", APPLIANCE[0])
    style = param(p, "style", "bottom_freezer")
    hd, ft = 0.04, 0.04
    yc = d / 2 - hd - ft
    gz = min(0.05, 0.05 * h)
    b.add("body", mat, box(-w / 2, w / 2, -d / 2, yc, 0, h), color=col)
    b.add("grille", "plastic", box(-w / 2 + 0.02, w / 2 - 0.02, yc, yc + ft * 0.5, 0.005, gz), color=DARK)
    g = 0.004
    doors = []
    if style == "side_by_side":
        doors = [(-w / 2, -0.05 * w, gz, h, "v_r"), (-0.05 * w, w / 2, gz, h, "v_l")]
    elif style == "single":
        doors = [(-w / 2, w / 2, gz, h, "v_r")]
    elif style == "top_freezer":
        zs = gz + 0.72 * (h - gz)
        doors = [(-w / 2, w / 2, gz, zs, "v_r"), (-w / 2, w / 2, zs, h, "v_r")]
    else:
        zs = gz + 0.33 * (h - gz)
        doors = [(-w / 2, w / 2, gz, zs, "h"), (-w / 2, w / 2, zs, h, "v_r")]
    for i, (x0, x1, z0, z1, hk) in enumerate(doors):
        b.add(f"door_{i}", mat, box(x0 + g, x1 - g, yc, yc + ft, z0 + g, z1 - g), color=col)
        if hk == "h":
            length = min(0.6 * (x1 - x0), 0.45)
            hm = handle_mesh("bar", (x0 + x1) / 2, z1 - 0.06, yc + ft, hd, length, False)
        else:
            length = clamp(0.4 * (z1 - z0), 0.1, 0.6)
            cx = x1 - 0.05 if hk == "v_r" else x0 + 0.05
            cz = clamp(z0 + 0.55 * (z1 - z0) if z1 - z0 < 0.8 else 1.05, z0 + length / 2 + 0.03,
                       z1 - length / 2 - 0.03)
            if z1 - z0 < 0.8:
                cz = clamp(z0 + length / 2 + 0.06, z0 + length / 2 + 0.03, z1 - length / 2 - 0.03)
            hm = handle_mesh("bar", cx, cz, yc + ft, hd, length, True)
        b.add(f"handle_{i}", "metal", hm, color=(0.7, 0.7, 0.72))
    b.surf(h, -w / 2, w / 2, -d / 2, yc + ft, INF)


def sample_fridge(s: ParamSampler):
    p = {"material": s.choice(["metal", "painted"], [0.5, 0.5])}
    p["color"] = s.color(APPLIANCE, 0.02)
    p["style"] = s.choice(["bottom_freezer", "top_freezer", "single", "side_by_side"], [0.45, 0.3, 0.15, 0.1])
    w = s.around(0.9, 0.05) if p["style"] == "side_by_side" else s.around(0.6, 0.1)
    return (w, s.around(0.66, 0.08), s.uniform(1.7, 1.95)), p


def generate_stove(b: Builder, w, d, h, p):
    mat = param(p, "material", "metal")
    if mat not in ("metal", "painted"):
        mat = "metal"
    col = param(p, "color", APPLIANCE[1])
    kind = param(p, "burner_type", "gas")
    hd, ft = 0.035, 0.02
    yc = d / 2 - hd - ft
    bh = 0.02 if kind == "gas" else 0.002
    pt = 0.008
    zp = h - bh - pt
    b.add("body", mat, box(-w / 2, w / 2, -d / 2, yc, 0, zp), color=col)
    b.add("cooktop", "glass" if kind != "gas" else "metal", box(-w / 2, w / 2, -d / 2, yc + ft, zp, h - bh),
          color=DARK)
    r_big = clamp(0.16 * min(w, d), 0.02, 0.24 * min(w, d))
    r_small = 0.75 * r_big
    y_mid = (-d / 2 + yc + ft) / 2
    dy = 0.25 * (yc + ft + d / 2)
    pos = [(-w / 4, y_mid + dy, r_big), (w / 4, y_mid + dy, r_small), (-w / 4, y_mid - dy, r_small),
           (w / 4, y_mid - dy, r_big)]
    for i, (x, y, r) in enumerate(pos):
        if kind == "gas":
            m = concat([cylinder(x, y, h - bh, h - bh * 0.45, r, sections=32),
                        cylinder(x, y, h - bh * 0.45, h, 0.55 * r, sections=32)])
        else:
            m = cylinder(x, y, h - bh, h, r, sections=48)
        b.add(f"burner_{i}", "metal" if kind == "gas" else "glass", m,
              color=(0.15, 0.15, 0.15) if kind == "gas" else (0.25, 0.25, 0.27))
    # oven door with window and handle, control strip with knobs, storage drawer
    zd0 = min(0.12, 0.15 * h)
    zd1 = zp - min(0.12, 0.15 * h)
    b.add("oven_door", mat, box(-w / 2 + 0.005, w / 2 - 0.005, yc, yc + ft, zd0, zd1), color=col)
    b.add("oven_window", "glass", box(-w / 2 + 0.07, w / 2 - 0.07, yc + ft, yc + ft + 0.002,
                                      zd0 + 0.06, zd1 - 0.1), color=DARK)
    b.add("oven_handle", "metal", handle_mesh("bar", 0.0, zd1 - 0.04, yc + ft, hd, 0.7 * w, False))
    b.add("drawer", mat, box(-w / 2 + 0.005, w / 2 - 0.005, yc, yc + ft, 0.01, zd0 - 0.005), color=col)
    n_k = 4 if w < 0.7 else 5
    zk = (zd1 + zp) / 2
    for i, x in enumerate(np.linspace(-w / 2 + 0.08, w / 2 - 0.08, n_k)):
        b.add(f"knob_{i}", "plastic", rod((x, yc, zk), (x, yc + ft + 0.02, zk), 0.016, sections=16), color=DARK)


def sample_stove(s: ParamSampler):
    p = {"material": s.choice(["metal", "painted"])}
    p["color"] = s.color(APPLIANCE, 0.02)
    p["burner_type"] = s.choice(["gas", "induction"])
    return (round(s.choice([0.5, 0.6, 0.6, 0.9]) * s.uniform(0.98, 1.02), 3), s.uniform(0.58, 0.65),
            s.uniform(0.85, 0.92)), p
