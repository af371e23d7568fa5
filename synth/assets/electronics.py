"""Electronics: laptop, TV (each generator beside its sampler)."""
from __future__ import annotations

import math

from .materials import DARK
from .primitives import Builder, box, clamp, concat, param, rod, rotation, transform
from .sampling import ParamSampler


def generate_laptop(b: Builder, w, d, h, p):
    mat = param(p, "material", "metal")
    if mat not in ("metal", "plastic"):
        mat = "metal"
    col = param(p, "color", (0.7, 0.7, 0.72))
    tilt = math.radians(clamp(param(p, "tilt_deg", 15.0), 0.0, 60.0))
    bt = clamp(param(p, "base_thickness", 0.018), 0.004, 0.3 * h)
    lt = clamp(param(p, "lid_thickness", 0.007), 0.002, 0.05)
    length = max((h - bt) / max(math.cos(tilt), 0.2), 0.01)
    back = length * math.sin(tilt) + lt * math.cos(tilt)
    db = clamp(d - back, 0.4 * d, d)
    y0 = d / 2 - db  # back edge of the base = hinge line
    b.add("base", mat, box(-w / 2, w / 2, y0, d / 2, 0, bt), color=col)
    kx = 0.9 * w / 2
    b.add("keyboard", "plastic", box(-kx, kx, y0 + 0.1 * db, y0 + 0.55 * db, bt, bt + 0.0008), color=DARK)
    b.add("touchpad", "plastic", box(-0.18 * w, 0.18 * w, y0 + 0.62 * db, y0 + 0.92 * db, bt, bt + 0.0005),
          color=tuple(c * 0.85 for c in col))
    tf = rotation(tilt, [1, 0, 0])
    tf[:3, 3] = [0.0, y0, bt]
    lid = box(-w / 2, w / 2, -lt, 0, 0, length)
    scr = box(-w / 2 + 0.012, w / 2 - 0.012, 0, 0.0008, 0.012, length - 0.012)
    b.add("lid", mat, transform(lid, tf), color=col)
    b.add("screen", "screen", transform(scr, tf), color=(0.02, 0.03, 0.05))


def sample_laptop(s: ParamSampler):
    p = {"material": s.choice(["metal", "plastic"], [0.6, 0.4])}
    p["color"] = s.color(((0.7, 0.7, 0.72), (0.2, 0.2, 0.22), (0.1, 0.1, 0.1)), 0.02)
    p["tilt_deg"] = s.uniform(8.0, 25.0, 1)
    p["base_thickness"] = s.uniform(0.014, 0.022)
    p["lid_thickness"] = s.uniform(0.005, 0.009)
    return (s.around(0.33, 0.1), s.around(0.25, 0.08), s.around(0.22, 0.08)), p


def generate_tv(b: Builder, w, d, h, p):
    col = param(p, "color", DARK)
    stand = param(p, "stand", "center")
    pt = clamp(param(p, "panel_thickness", 0.045), 0.005, 0.6 * d)
    fh = clamp(param(p, "foot_height", 0.07), 0.0, 0.3 * h)
    bez = min(0.012, 0.05 * min(w, h))
    py1 = min(d / 2, pt / 2 + 0.01)
    py0 = py1 - pt
    b.add("panel", "plastic", box(-w / 2, w / 2, py0, py1 - 0.0012, fh, h), color=col)
    b.add("screen", "screen", box(-w / 2 + bez, w / 2 - bez, py1 - 0.0012, py1, fh + bez * 1.5, h - bez),
          color=(0.02, 0.025, 0.035))
    if fh > 0:
        if stand == "feet":
            for i, sx in enumerate((-1, 1)):
                x = sx * 0.38 * w
                b.add(f"foot_{i}", "metal", concat([
                    rod((x, -d / 2 + 0.01, 0.005), (x, py0 + pt / 2, fh + 0.02), 0.008, square=True),
                    rod((x, d / 2 - 0.01, 0.005), (x, py0 + pt / 2, fh + 0.02), 0.008, square=True),
                    box(x - 0.01, x + 0.01, -d / 2, d / 2, 0, 0.01)]), color=(0.25, 0.25, 0.27))
        else:
            bw = min(0.3 * w, 0.4)
            b.add("foot", "metal", box(-bw / 2, bw / 2, -d / 2, d / 2, 0, 0.012), color=(0.25, 0.25, 0.27))
            b.add("neck", "metal", box(-0.04, 0.04, py0 - 0.015, py0 + 0.005, 0.012, fh + 0.15 * (h - fh)),
                  color=(0.25, 0.25, 0.27))


def sample_tv(s: ParamSampler):
    p = {"color": s.color(((0.03, 0.03, 0.035), (0.15, 0.15, 0.16)), 0.01), "stand": s.choice(["center", "feet"])}
    p["panel_thickness"] = s.uniform(0.03, 0.06)
    p["foot_height"] = s.uniform(0.04, 0.1)
    w = s.around(1.2, 0.25)
    return (w, s.uniform(0.12, 0.25), round(w * 9 / 16 + 0.03 + p["foot_height"], 3)), p
