"""Storage casework: nightstand, cabinet, TV stand, bookshelf, wardrobe, shoe rack (each generator beside
its sampler; the carcass itself is ``components.casework``)."""
from __future__ import annotations

import numpy as np

from .components import body_material, casework, four_legs, open_row_surfaces, sample_case
from .materials import DARK, WOODS
from .primitives import INF, Builder, box, clamp, param, rod
from .sampling import ParamSampler


def generate_nightstand(b: Builder, w, d, h, p):
    mat, col = body_material(p)
    n = int(clamp(param(p, "n_drawers", 2), 1, 4))
    open_shelf = param(p, "open_shelf", False)
    legs = param(p, "legs", True)
    lh = clamp(param(p, "leg_height", 0.12), 0.02, 0.35 * h) if legs else 0.0
    handle = param(p, "handle", "knob")
    rows = ([("open", 1, 1.2)] if open_shelf else []) + [("drawers", 1, 1)] * n
    if lh > 0:
        four_legs(b, w, d - 0.045, lh + 0.005, min(0.035, 0.15 * w), "tapered" if mat in WOODS else "square", mat,
                  col, inset=0.02, yoff=-0.0225)
    info = casework(b, "", -w / 2, w / 2, -d / 2, d / 2, lh, h, rows, mat, col, handle=handle)
    open_row_surfaces(b, info)
    b.surf(h, -w / 2, w / 2, -d / 2, info["yc"], INF)


def sample_nightstand(s: ParamSampler):
    p = {}
    sample_case(s, p)
    p["n_drawers"] = s.integer(1, 3)
    p["open_shelf"] = s.chance(0.35)
    p["legs"] = s.chance(0.6)
    p["leg_height"] = s.uniform(0.07, 0.16)
    return (s.around(0.46, 0.15), s.around(0.4, 0.12), s.around(0.55, 0.12)), p


def _cabinet_base(b, w, d, h, p, mat, col, front_space):
    base = param(p, "base", "plinth")
    if base == "legs":
        lh = clamp(param(p, "leg_height", 0.12), 0.02, 0.35 * h)
        four_legs(b, w, d - front_space, lh + 0.005, min(0.035, 0.1 * w), "tapered" if mat in WOODS else "round",
                  mat if mat in WOODS else "metal", None, inset=0.03, yoff=-front_space / 2)
        return lh
    if base == "plinth":
        ph = clamp(param(p, "plinth_height", 0.08), 0.02, 0.25 * h)
        b.add("plinth", "painted", box(-w / 2 + 0.02, w / 2 - 0.02, -d / 2 + 0.02, d / 2 - front_space - 0.04,
                                       0, ph + 0.002), color=DARK)
        return ph
    return 0.0


def generate_cabinet(b: Builder, w, d, h, p):
    mat, col = body_material(p)
    style = param(p, "style", "doors")
    handle = param(p, "handle", "bar")
    nd = int(clamp(param(p, "n_doors", 2 if w >= 0.6 else 1), 1, 4))
    nr = int(clamp(param(p, "n_drawers", 3), 1, 6))
    cols = 2 if w > 1.1 else 1
    if style == "drawers":
        rows = [("drawers", cols, 1)] * nr
    elif style == "mixed":
        rows = [("doors", nd, 2.5), ("drawers", nd, 1)]
    elif style == "open":
        rows = [("doors", nd, 1.0), ("open", 1, 1.0)]
    else:
        rows = [("doors", nd, 1)]
    fs = 0.018 + (0.025 if handle != "none" else 0.0)
    z0 = _cabinet_base(b, w, d, h, p, mat, col, fs)
    info = casework(b, "", -w / 2, w / 2, -d / 2, d / 2, z0, h, rows, mat, col, handle=handle, front_space=fs)
    open_row_surfaces(b, info)
    b.surf(h, -w / 2, w / 2, -d / 2, info["yc"], INF)


def sample_cabinet(s: ParamSampler):
    p = {}
    sample_case(s, p)
    p["style"] = s.choice(["doors", "drawers", "mixed", "open"])
    p["n_drawers"] = s.integer(3, 4)
    p["base"] = s.choice(["plinth", "legs", "none"], [0.45, 0.4, 0.15])
    p["leg_height"] = s.uniform(0.08, 0.18)
    p["plinth_height"] = s.uniform(0.05, 0.1)
    w = s.around(1.0, 0.25)
    p["n_doors"] = 1 if w < 0.6 else (3 if w > 1.3 else 2)
    return (w, s.around(0.45, 0.15), s.around(0.85, 0.2)), p


def generate_tv_stand(b: Builder, w, d, h, p):
    mat, col = body_material(p, "wood_dark")
    handle = param(p, "handle", "bar")
    mods = p.get("modules") if isinstance(p, dict) else None
    if not isinstance(mods, (list, tuple)) or not mods:
        mods = ["drawers", "open", "drawers"] if w > 1.2 else ["doors", "open"]
    mods = [str(m) for m in mods][:6]
    fs = 0.018 + (0.025 if handle != "none" else 0.0)
    if all(m not in ("drawers", "doors") for m in mods):
        fs = 0.0
    z0 = _cabinet_base(b, w, d, h, p, mat, col, fs)
    xs = np.linspace(-w / 2, w / 2, len(mods) + 1)
    yc = None
    for i, kind in enumerate(mods):
        if kind == "drawers":
            rows = [("drawers", 1, 1), ("drawers", 1, 1)]
        elif kind == "doors":
            rows = [("doors", 1 if (xs[i + 1] - xs[i]) < 0.6 else 2, 1)]
        else:
            rows = [("open", 1, 1), ("open", 1, 1)]
        info = casework(b, f"m{i}_", xs[i], xs[i + 1], -d / 2, d / 2, z0, h, rows, mat, col, handle=handle,
                        front_space=fs)
        open_row_surfaces(b, info)
        yc = info["yc"]
    b.surf(h, -w / 2, w / 2, -d / 2, yc, INF)


def sample_tv_stand(s: ParamSampler):
    p = {}
    sample_case(s, p, probs=(0.3, 0.4, 0.3))
    w = s.around(1.6, 0.2)
    n = 3 if w > 1.4 else 2
    p["modules"] = [s.choice(["drawers", "open", "doors"]) for _ in range(n)]
    p["base"] = s.choice(["legs", "plinth", "none"])
    p["leg_height"] = s.uniform(0.06, 0.15)
    p["plinth_height"] = s.uniform(0.04, 0.08)
    return (w, s.around(0.42, 0.12), s.around(0.5, 0.15)), p


def generate_bookshelf(b: Builder, w, d, h, p):
    mat, col = body_material(p)
    n = int(clamp(param(p, "n_boards", 4), 1, 8))
    t = clamp(param(p, "board_thickness", 0.02), 0.008, 0.05)
    back = param(p, "back", True)
    kick = clamp(param(p, "plinth_height", 0.06), 0.0, 0.1 * h)
    lower_doors = param(p, "lower_doors", False)
    rows = [("open", 1, 1)] * (n + 1)
    if lower_doors:
        rows[0] = ("doors", 2 if w > 0.5 else 1, 1.3)
    info = casework(b, "", -w / 2, w / 2, -d / 2, d / 2, 0.0, h, rows, mat, col, t=t, back=back, kick=kick,
                    handle=param(p, "handle", "knob"))
    open_row_surfaces(b, info)
    b.surf(h, -w / 2, w / 2, -d / 2, info["yc"], INF)


def sample_bookshelf(s: ParamSampler):
    p = {}
    sample_case(s, p, probs=(0.45, 0.3, 0.25))
    p["n_boards"] = s.integer(3, 5)
    p["board_thickness"] = s.uniform(0.016, 0.03)
    p["back"] = s.chance(0.85)
    p["plinth_height"] = s.choice([0.0, s.uniform(0.04, 0.09)])
    p["lower_doors"] = s.chance(0.25)
    return (s.around(0.9, 0.25), s.around(0.32, 0.15), s.around(1.8, 0.2)), p


def generate_wardrobe(b: Builder, w, d, h, p):
    mat, col = body_material(p)
    nd = int(clamp(param(p, "n_doors", 2 if w < 1.4 else 3), 1, 5))
    drawers = param(p, "drawers", False)
    handle = param(p, "handle", "bar")
    cornice = param(p, "cornice", True)
    mirror_door = param(p, "mirror_door", False)
    kick = clamp(param(p, "plinth_height", 0.07), 0.0, 0.1 * h)
    ch = min(0.05, 0.05 * h) if cornice else 0.0
    fs = 0.018 + (0.025 if handle != "none" else 0.0)
    rows = ([("drawers", 2 if w > 0.9 else 1, 0.16)] if drawers else []) + [("doors", nd, 1)]
    info = casework(b, "", -w / 2, w / 2, -d / 2, d / 2, 0.0, h - ch, rows, mat, col, handle=handle, kick=kick,
                    front_space=fs, t=0.02)
    if ch > 0:
        b.add("cornice", mat, box(-w / 2, w / 2, -d / 2, min(info["front"] + 0.005, d / 2), h - ch, h), color=col)
    if mirror_door:
        # a mirror pane on the first door
        for part in b.parts:
            if part[0].startswith("door_") and part[0].endswith("_0"):
                m = part[2]
                lo, hi = m.bounds
                inset = 0.06
                b.add("mirror", "mirror", box(lo[0] + inset, hi[0] - inset, hi[1], hi[1] + 0.003,
                                              lo[2] + inset, hi[2] - inset))
                break
    b.surf(h, -w / 2, w / 2, -d / 2, info["yc"], INF)


def sample_wardrobe(s: ParamSampler):
    p = {}
    sample_case(s, p, probs=(0.4, 0.3, 0.3))
    p["handle"] = s.choice(["bar", "knob"], [0.7, 0.3])
    w = round(s.choice([1.0, 1.2, 1.5, 1.8]) * s.uniform(0.92, 1.08), 3)
    p["n_doors"] = 2 if w < 1.4 else s.choice([2, 3])
    p["drawers"] = s.chance(0.35)
    p["cornice"] = s.chance(0.5)
    p["mirror_door"] = s.chance(0.2)
    p["plinth_height"] = s.uniform(0.04, 0.1)
    return (w, s.around(0.6, 0.08), s.uniform(1.9, 2.3)), p


def generate_shoe_rack(b: Builder, w, d, h, p):
    mat, col = body_material(p)
    style = param(p, "style", "boards")
    n = int(clamp(param(p, "n_levels", 2), 1, 5))
    if style == "bars":
        t = min(0.025, 0.1 * w)
        tt = min(0.02, 0.1 * h)
        b.add("top", mat, box(-w / 2, w / 2, -d / 2, d / 2, h - tt, h), color=col)
        for i, sx in enumerate((-1, 1)):
            xa, xb = sorted((sx * w / 2, sx * (w / 2 - t)))
            b.add(f"side_{i}", mat, box(xa, xb, -d / 2, d / 2, 0, h - tt), color=col)
        levels = np.linspace(0.06, h - tt, n + 1)[:-1] + 0.0
        rr = 0.009
        for i, z in enumerate(levels):
            z = max(z, rr)
            for j, (y, dz) in enumerate(((d / 2 - 0.04, 0.0), (-d / 2 + 0.04, 0.04 * d / 0.3))):
                b.add(f"bar_{i}_{j}", "metal", rod((-w / 2 + t, y, z + dz), (w / 2 - t, y, z + dz), rr,
                                                   sections=12))
            b.surf(z + rr, -w / 2 + t, w / 2 - t, -d / 2 + 0.04, d / 2 - 0.04, (h - tt) / n - 0.03, margin=0.0)
        b.surf(h, -w / 2, w / 2, -d / 2, d / 2, INF)
        return
    rows = [("open", 1, 1)] * n
    info = casework(b, "", -w / 2, w / 2, -d / 2, d / 2, 0.0, h, rows, mat, col, back=False, kick=0.0)
    open_row_surfaces(b, info)
    b.surf(h, -w / 2, w / 2, -d / 2, d / 2, INF)


def sample_shoe_rack(s: ParamSampler):
    p = {}
    sample_case(s, p, probs=(0.4, 0.3, 0.3))
    p["style"] = s.choice(["boards", "bars"])
    p["n_levels"] = s.integer(2, 3)
    return (s.around(0.8, 0.2), s.around(0.3, 0.12), s.around(0.5, 0.2)), p
