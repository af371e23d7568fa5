"""Bathroom: toilet, bathtub, washbasin (each generator beside its sampler)."""
from __future__ import annotations

from .components import casework, sample_case
from .materials import MATERIALS, PAINT, WHITE
from .primitives import INF, Builder, box, clamp, concat, cylinder, param, revolve, rod, soft_box
from .sampling import ParamSampler


def generate_toilet(b: Builder, w, d, h, p):
    col = param(p, "color", WHITE)
    seat_col = param(p, "seat_color", WHITE)
    td = clamp(param(p, "tank_depth", 0.17), 0.05, 0.35 * d)
    sh = clamp(param(p, "seat_height", 0.42), 0.3 * h, 0.75 * h)
    tz0 = clamp(param(p, "tank_bottom", sh + 0.02), sh - 0.1, h - 0.1)
    lid = param(p, "lid", True)
    b.add("tank", "ceramic", soft_box(-w / 2, w / 2, -d / 2, -d / 2 + td, tz0, h, e=0.2), color=col)
    b.add("flush_button", "metal", cylinder(0, -d / 2 + td / 2, h - 0.004, h, min(0.02, td / 4), sections=24))
    by0 = -d / 2 + td - 0.05
    cy = (by0 + d / 2) / 2
    ry = (d / 2 - by0) / 2
    rx = 0.88 * w / 2
    rim = sh - 0.03
    bowl_prof = [(0.0, 0.0), (0.55, 0.0), (0.75, 0.45), (1.0, 1.0), (0.84, 1.0), (0.5, 0.55), (0.0, 0.5)]
    z_b0 = 0.18 * sh
    b.add("bowl", "ceramic", revolve(bowl_prof, 0, cy, z_b0, rx, ry, rim - z_b0, sections=48), color=col)
    b.add("base", "ceramic", revolve([(0, 0), (0.5, 0), (0.42, 1.0), (0, 1.0)], 0, cy - 0.1 * ry, 0, rx, ry * 0.75,
                                     z_b0 + 0.02, sections=48), color=col)
    ring = [(0.72, 0.0), (1.0, 0.0), (1.0, 1.0), (0.72, 1.0), (0.72, 0.0)]
    b.add("seat", "plastic", revolve(ring, 0, cy, rim, rx, ry, sh - rim, sections=48), color=seat_col)
    if lid:
        b.add("lid", "plastic", cylinder(0, cy, sh, sh + 0.015, rx * 0.98, ry * 0.98, sections=48), color=seat_col)
    b.surf(h, -w / 2, w / 2, -d / 2, -d / 2 + td, INF, margin=0.015)


def sample_toilet(s: ParamSampler):
    p = {"color": s.color((WHITE,), 0.02), "lid": s.chance(0.6)}
    p["seat_color"] = p["color"] if s.chance(0.8) else s.color(((0.1, 0.1, 0.1), (0.5, 0.35, 0.2)))
    p["tank_depth"] = s.uniform(0.14, 0.2)
    p["seat_height"] = s.uniform(0.4, 0.44)
    return (s.around(0.38, 0.1), s.around(0.66, 0.08), s.around(0.78, 0.08)), p


def generate_bathtub(b: Builder, w, d, h, p):
    col = param(p, "color", WHITE)
    style = param(p, "style", "built_in")
    rw = clamp(param(p, "rim_width", 0.07), 0.02, 0.2 * min(w, d))
    tap = param(p, "tap", True)
    fh = clamp(param(p, "feet_height", 0.1), 0.02, 0.3 * h) if style == "feet" else 0.0
    tap_h = min(0.1, 0.2 * h) if tap else 0.0
    zr = h - tap_h
    z0 = fh
    fl = clamp(0.12, 0.02, 0.5 * (zr - z0))
    re = min(rw * 1.8, 0.25 * w)  # wider rim at the -x end (tap end)
    if style == "feet":
        e = 0.3
        b.add("shell", "ceramic", soft_box(-w / 2, w / 2, -d / 2, d / 2, z0, z0 + fl + 0.05, e=e), color=col)
        b.add("rim_0", "ceramic", soft_box(-w / 2, -w / 2 + re + 0.03, -d / 2, d / 2, z0, zr, e=e), color=col)
        b.add("rim_1", "ceramic", soft_box(w / 2 - rw - 0.03, w / 2, -d / 2, d / 2, z0, zr, e=e), color=col)
        b.add("rim_2", "ceramic", soft_box(-w / 2, w / 2, -d / 2, -d / 2 + rw + 0.03, z0, zr, e=e), color=col)
        b.add("rim_3", "ceramic", soft_box(-w / 2, w / 2, d / 2 - rw - 0.03, d / 2, z0, zr, e=e), color=col)
        for i, (sx, sy) in enumerate(((-1, -1), (1, -1), (-1, 1), (1, 1))):
            b.add(f"foot_{i}", "metal", cylinder(sx * (w / 2 - 0.12), sy * (d / 2 - 0.1), 0, z0 + 0.02, 0.035,
                                                 sections=16))
        b.add("basin", "ceramic", box(-w / 2 + re, w / 2 - rw, -d / 2 + rw, d / 2 - rw, z0, z0 + fl),
              color=(col[0] * 0.92, col[1] * 0.92, col[2] * 0.95))
    else:
        b.add("rim_0", "ceramic", box(-w / 2, -w / 2 + re, -d / 2, d / 2, 0, zr), color=col)
        b.add("rim_1", "ceramic", box(w / 2 - rw, w / 2, -d / 2, d / 2, 0, zr), color=col)
        b.add("rim_2", "ceramic", box(-w / 2 + re, w / 2 - rw, -d / 2, -d / 2 + rw, 0, zr), color=col)
        b.add("rim_3", "ceramic", box(-w / 2 + re, w / 2 - rw, d / 2 - rw, d / 2, 0, zr), color=col)
        b.add("basin", "ceramic", box(-w / 2 + re, w / 2 - rw, -d / 2 + rw, d / 2 - rw, 0, fl),
              color=(col[0] * 0.92, col[1] * 0.92, col[2] * 0.95))
    b.add("drain", "metal", cylinder(-w / 2 + re + 0.1, 0, z0 + fl, z0 + fl + 0.003, 0.03, sections=24))
    if tap:
        tx = -w / 2 + re / 2
        b.add("tap", "metal", concat([cylinder(tx, 0, zr - 0.01, h - 0.02, 0.015, sections=16),
                                     rod((tx, 0, h - 0.035), (-w / 2 + re + 0.08, 0, h - 0.035), 0.013),
                                     box(tx - 0.01, tx + 0.01, -0.04, 0.04, h - 0.02, h)]))


def sample_bathtub(s: ParamSampler):
    p = {"color": s.color((WHITE,), 0.02), "style": s.choice(["built_in", "feet"], [0.7, 0.3])}
    p["rim_width"] = s.uniform(0.05, 0.09)
    p["tap"] = s.chance(0.7)
    p["feet_height"] = s.uniform(0.08, 0.14)
    return (s.around(1.7, 0.1), s.around(0.75, 0.1), s.around(0.6, 0.1)), p


def generate_washbasin(b: Builder, w, d, h, p):
    col = param(p, "color", WHITE)
    style = param(p, "style", "pedestal")
    shape = param(p, "basin_shape", "rect")
    fhgt = clamp(param(p, "faucet_height", 0.13), 0.03, 0.3 * h)
    bdz = clamp(param(p, "basin_depth", 0.15), 0.04, 0.4 * h)
    rz = h - fhgt
    zb = rz - bdz
    back = min(0.08, 0.3 * d)
    if shape == "round":
        prof = [(0, 0), (0.6, 0), (0.95, 0.75), (1.0, 1.0), (0.88, 1.0), (0.55, 0.25), (0, 0.2)]
        b.add("basin", "ceramic", revolve(prof, 0, back * 0.3, zb, w / 2, d / 2 - back * 0.3, bdz, sections=48),
              color=col)
        b.add("deck", "ceramic", box(-min(0.12, 0.3 * w), min(0.12, 0.3 * w), -d / 2, -d / 2 + back,
                                     rz - 0.03, rz), color=col)
    else:
        s = min(0.035, 0.1 * w)
        b.add("basin", "ceramic", concat([
            box(-w / 2, w / 2, -d / 2, d / 2, zb, zb + 0.3 * bdz),
            box(-w / 2, -w / 2 + s, -d / 2, d / 2, zb, rz),
            box(w / 2 - s, w / 2, -d / 2, d / 2, zb, rz),
            box(-w / 2, w / 2, -d / 2, -d / 2 + back, zb, rz),
            box(-w / 2, w / 2, d / 2 - s, d / 2, zb, rz),
        ]), color=col)
        b.add("drain", "metal", cylinder(0, (back - s) / 2, zb + 0.3 * bdz, zb + 0.3 * bdz + 0.002, 0.02, sections=24))
    fy = -d / 2 + back / 2
    spout = min(0.12, 0.35 * d)
    b.add("faucet", "metal", concat([
        cylinder(0, fy, rz - 0.005, h - 0.02, 0.016, sections=16),
        rod((0, fy, h - 0.035), (0, fy + spout, h - 0.035), 0.012),
        box(-0.008, 0.008, fy - 0.01, fy + 0.04, h - 0.02, h),
    ]))
    if style == "vanity":
        mat = param(p, "cabinet_material", "wood_light")
        if mat not in MATERIALS:
            mat = "wood_light"
        mcol = param(p, "cabinet_color", PAINT[0]) if mat in ("painted", "metal", "plastic") else None
        casework(b, "vanity_", -w / 2 + 0.01, w / 2 - 0.01, -d / 2, d / 2 - 0.01, 0.0, zb,
                 [("doors", 2 if w > 0.5 else 1, 1)], mat, mcol, handle=param(p, "handle", "bar"), kick=0.05)
    else:
        b.add("pedestal", "ceramic", revolve([(0, 0), (1.0, 0), (0.7, 0.6), (0.8, 1.0), (0, 1.0)], 0, -0.15 * d, 0,
                                             min(0.11, 0.25 * w), min(0.11, 0.3 * d), zb + 0.01, sections=32),
              color=col)


def sample_washbasin(s: ParamSampler):
    p = {"color": s.color((WHITE,), 0.02), "style": s.choice(["pedestal", "vanity"])}
    p["basin_shape"] = s.choice(["rect", "round"])
    p["faucet_height"] = s.uniform(0.1, 0.16)
    p["basin_depth"] = s.uniform(0.12, 0.17)
    if p["style"] == "vanity":
        q = {}
        sample_case(s, q)
        p["cabinet_material"] = q["material"]
        if "color" in q:
            p["cabinet_color"] = q["color"]
        p["handle"] = q["handle"]
    return (s.around(0.6, 0.2), s.around(0.46, 0.12), s.uniform(0.92, 1.02)), p
