"""Furniture components shared by several families: legs, handles, cabinet casework (carcass, rows of
drawers / doors / open shelves) and the body material of casework (``body_material`` reads what
``sample_case`` samples)."""
from __future__ import annotations

import numpy as np
import trimesh

from .materials import MATERIALS, PAINT
from .primitives import MIN_THICKNESS, box, clamp, concat, cylinder, param, revolve, rod
from .sampling import ParamSampler


def leg(cx, cy, z0, z1, t, style="square", sections=16) -> trimesh.Trimesh:
    if style == "round":
        return cylinder(cx, cy, z0, z1, t / 2.0, sections=sections)
    if style == "tapered":
        r = t / 2.0
        return revolve([(0, 0), (0.6, 0), (1.0, 1.0), (0, 1.0)], cx, cy, z0, r, r, max(z1 - z0, MIN_THICKNESS),
                       sections)
    return box(cx - t / 2.0, cx + t / 2.0, cy - t / 2.0, cy + t / 2.0, z0, z1)


def handle_mesh(kind, cx, cz, y_face, depth, length, vertical) -> trimesh.Trimesh | None:
    if kind == "none" or depth <= 0:
        return None
    if kind == "knob":
        r = min(0.012, depth * 0.6)
        return rod((cx, y_face, cz), (cx, y_face + depth, cz), r, sections=16)
    t = 0.006
    yb = y_face + 0.55 * depth
    if vertical:
        bar = box(cx - t, cx + t, yb, y_face + depth, cz - length / 2, cz + length / 2)
        s0 = box(cx - t * 0.7, cx + t * 0.7, y_face, yb, cz - length / 2 + 0.005, cz - length / 2 + 0.015)
        s1 = box(cx - t * 0.7, cx + t * 0.7, y_face, yb, cz + length / 2 - 0.015, cz + length / 2 - 0.005)
    else:
        bar = box(cx - length / 2, cx + length / 2, yb, y_face + depth, cz - t, cz + t)
        s0 = box(cx - length / 2 + 0.005, cx - length / 2 + 0.015, y_face, yb, cz - t * 0.7, cz + t * 0.7)
        s1 = box(cx + length / 2 - 0.015, cx + length / 2 - 0.005, y_face, yb, cz - t * 0.7, cz + t * 0.7)
    return concat([bar, s0, s1])


def casework(b, pfx, x0, x1, y0, y1, z0, z1, rows, mat, color=None, *, front_mat=None, front_color=None,
             t=0.018, back=True, top=True, bottom=True, kick=0.0, handle="bar", front_space=None,
             front_gap=0.003):
    """Cabinet carcass with rows (bottom to top) of ("open" | "drawers" | "doors", n_columns, weight).

    Fronts and handles occupy the last ``front_space`` metres in +y.  Returns a dict with the
    carcass front ``yc``, inner x/y ranges and the (kind, zlo, zhi) interior interval of each row."""
    closed = any(r[0] != "open" for r in rows)
    ft = 0.018 if closed else 0.0
    hd = 0.025 if (closed and handle != "none") else 0.0
    if front_space is None:
        front_space = ft + hd
    if closed and front_space < ft + hd:
        ft = 0.45 * front_space
        hd = front_space - ft if handle != "none" else 0.0
    ft = min(ft, 0.3 * (y1 - y0))
    yc = y1 - front_space
    width = x1 - x0
    t = clamp(t, 0.004, min(0.15 * width, 0.15 * (z1 - z0)))
    bt = min(0.008, 0.1 * (yc - y0)) if back else 0.0
    front_mat = front_mat or mat
    front_color = front_color if front_color is not None else color
    b.add(f"{pfx}side_l", mat, box(x0, x0 + t, y0, yc, z0, z1), color=color)
    b.add(f"{pfx}side_r", mat, box(x1 - t, x1, y0, yc, z0, z1), color=color)
    zb = z0 + max(kick, 0.0)
    if kick > 0:
        b.add(f"{pfx}kick", mat, box(x0 + t, x1 - t, yc - 0.03, yc - 0.012, z0, zb), color=color)
    if bottom:
        b.add(f"{pfx}bottom", mat, box(x0 + t, x1 - t, y0, yc, zb, zb + t), color=color)
    if top:
        b.add(f"{pfx}top", mat, box(x0, x1, y0, yc, z1 - t, z1), color=color)
    if back:
        b.add(f"{pfx}back", mat, box(x0 + t, x1 - t, y0, y0 + bt, zb, z1), color=color)
    zi0 = zb + (t if bottom else 0.0)
    zi1 = z1 - (t if top else 0.0)
    nr = max(len(rows), 1)
    avail = max(zi1 - zi0 - t * (nr - 1), 1e-3)
    wsum = sum(max(float(r[2]), 1e-3) for r in rows) or 1.0
    intervals = []
    z = zi0
    for i, r in enumerate(rows):
        hh = avail * max(float(r[2]), 1e-3) / wsum
        intervals.append((r[0], z, z + hh))
        z += hh
        if i < nr - 1:
            b.add(f"{pfx}board_{i}", mat, box(x0 + t, x1 - t, y0 + bt, yc, z, z + t), color=color)
            z += t
    g = front_gap
    hi_idx = 0
    for i, (kind, zlo, zhi) in enumerate(intervals):
        if kind == "open":
            continue
        n = max(int(rows[i][1]), 1)
        flo = (zb if i == 0 else zlo - t / 2.0)
        fhi = (z1 if top else zi1) if i == nr - 1 else zhi + t / 2.0
        xs = np.linspace(x0, x1, n + 1)
        for j in range(n):
            fx0, fx1 = xs[j] + g, xs[j + 1] - g
            fz0, fz1 = flo + g, fhi - g
            nm = "drawer" if kind == "drawers" else "door"
            b.add(f"{pfx}{nm}_{i}_{j}", front_mat, box(fx0, fx1, yc, yc + ft, fz0, fz1), color=front_color)
            fw, fh = fx1 - fx0, fz1 - fz0
            if kind == "drawers":
                length = clamp(0.35 * fw, 0.06, 0.3)
                hm = handle_mesh(handle, (fx0 + fx1) / 2, (fz0 + fz1) / 2, yc + ft, hd, length, False)
            else:
                length = clamp(0.3 * fh, 0.08, 0.4)
                right = (j < n / 2.0) if n > 1 else True
                off = 0.045 if handle == "bar" else 0.05
                cx = fx1 - off if right else fx0 + off
                if fh > 1.0:
                    cz = clamp(1.0, fz0 + length / 2 + 0.05, fz1 - length / 2 - 0.05)
                else:
                    cz = clamp(fz1 - 0.06 - length / 2, (fz0 + fz1) / 2, fz1)
                    if handle == "knob":
                        cz = clamp(fz1 - 0.06, (fz0 + fz1) / 2, fz1)
                hm = handle_mesh(handle, cx, cz, yc + ft, hd, length, True)
            if hm is not None:
                b.add(f"{pfx}handle_{hi_idx}", "metal", hm)
                hi_idx += 1
    return {
        "yc": yc,
        "front": yc + ft,
        "inner": (x0 + t, x1 - t, y0 + bt, yc),
        "rows": intervals,
        "t": t,
    }


def open_row_surfaces(b, info):
    xi0, xi1, yi0, yi1 = info["inner"]
    for kind, zlo, zhi in info["rows"]:
        if kind == "open":
            b.surf(zlo, xi0, xi1, yi0, yi1, zhi - zlo)


def four_legs(b, w, d, z1, t, style, mat, color=None, inset=0.02, z0=0.0, xoff=0.0, yoff=0.0, n_mid=0):
    lx = w / 2.0 - inset - t / 2.0
    ly = d / 2.0 - inset - t / 2.0
    pts = [(-lx, -ly), (lx, -ly), (-lx, ly), (lx, ly)]
    if n_mid:
        pts += [(0.0, -ly), (0.0, ly)]
    for i, (x, y) in enumerate(pts):
        b.add(f"leg_{i}", mat, leg(x + xoff, y + yoff, z0, z1, t, style), color=color)
    return lx, ly


def body_material(p, default="wood_light"):
    mat = param(p, "material", default)
    if mat not in MATERIALS:
        mat = default
    col = param(p, "color", PAINT[0]) if mat in ("painted", "metal", "plastic") else None
    return mat, col


def sample_case(s: ParamSampler, p, mats=("wood_light", "wood_dark", "painted"), probs=(0.4, 0.3, 0.3)):
    p["material"] = s.choice(list(mats), list(probs))
    if p["material"] in ("painted", "metal", "plastic"):
        p["color"] = s.color(PAINT, 0.02)
    p["handle"] = s.choice(["bar", "knob", "none"], [0.55, 0.35, 0.1])
