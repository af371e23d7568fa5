"""Procedural, parameterised mesh generators for the object classes of the synthetic apartment.

Every generator builds an object from simple primitives (boxes, cylinders, surfaces of revolution,
icospheres) in the object's local frame:

* metres; z up; origin at the centre of the bottom face of the object's bounding box;
* x = width, y = depth, z = height; the object's FRONT faces local +y (backrests, headboards, the
  back of pictures and mirrors are at -y; screens and doors face +y);
* for a size (w, d, h) the union of all parts has axis-aligned bounds exactly
  [-w/2, w/2] x [-d/2, d/2] x [0, h].  Generators lay out their parts to fill that box; a final
  per-axis affine fit (close to the identity for every generator) removes the remaining millimetre
  slack, so the bounds hold exactly for any size.

Public API: ``MATERIALS``, ``Part``, ``Surface``, ``sample_params``, ``make_parts``, ``make_mesh``,
``support_surfaces``, ``known_classes``.  The class names follow ``scenes/classes.yaml`` (all
classes except the structure ones: wall, floor, ceiling).  No bpy, no network, deterministic.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Callable

import numpy as np
import trimesh

from formats.errors import UnknownNameError



__all__ = [
    "MATERIALS",
    "Part",
    "Surface",
    "sample_params",
    "make_parts",
    "make_mesh",
    "support_surfaces",
    "known_classes",
    "UnknownClassError",
]

MATERIALS: tuple[str, ...] = (
    "wood_light",
    "wood_dark",
    "fabric",
    "leather",
    "metal",
    "plastic",
    "ceramic",
    "glass",
    "leaf",
    "soil",
    "paper",
    "book_cover",
    "screen",
    "lamp_shade",
    "diffuser",
    "mattress",
    "painted",
    "mirror",
    "marble",
    "canvas",
    "wicker",
)


class UnknownClassError(UnknownNameError, ValueError):
    """An object class without a mesh generator (a ValueError, and a UserError for the CLIs)."""


@dataclass(frozen=True)
class Part:
    name: str
    material: str
    mesh: trimesh.Trimesh
    emissive: bool = False
    color: tuple[float, float, float] | None = None


@dataclass(frozen=True)
class Surface:
    """A supporting rectangle in the object's local frame.

    ``z`` is the height of the surface above the object's bottom; ``xmin..xmax`` x ``ymin..ymax`` the
    usable area (about 2 cm inside the supporting board's edges, excluding arm- and backrests);
    ``clearance`` the free height above it (to the next board for shelves, 0.5 for seats,
    ``inf`` for open tops); ``band`` how far above ``z`` a resting object's bottom may be (0 for
    boards; a ReplicaCAD receptacle's box height, ``synth.replicacad.receptacles``)."""

    z: float
    xmin: float
    xmax: float
    ymin: float
    ymax: float
    clearance: float
    band: float = 0.0  # the bottom of what stands here may lie up to this far above z (a receptacle box: synth.replicacad.receptacles)


# ----------------------------------------------------------------------------------------------
# colour palettes (approximate linear RGB)

_FABRIC = (
    (0.42, 0.42, 0.44), (0.12, 0.16, 0.30), (0.55, 0.48, 0.38), (0.20, 0.32, 0.20),
    (0.45, 0.17, 0.11), (0.72, 0.69, 0.62), (0.10, 0.10, 0.11), (0.60, 0.42, 0.12),
    (0.30, 0.12, 0.20), (0.25, 0.38, 0.45),
)
_LEATHER = ((0.25, 0.12, 0.06), (0.07, 0.06, 0.06), (0.45, 0.28, 0.15), (0.60, 0.55, 0.50))
_PAINT = (
    (0.85, 0.85, 0.83), (0.08, 0.08, 0.09), (0.50, 0.52, 0.50), (0.35, 0.45, 0.38),
    (0.20, 0.28, 0.40), (0.75, 0.70, 0.60),
)
_CERAMIC = (
    (0.90, 0.90, 0.88), (0.15, 0.15, 0.16), (0.60, 0.35, 0.25), (0.30, 0.45, 0.55),
    (0.75, 0.65, 0.50), (0.50, 0.55, 0.45),
)
_LEAF = ((0.10, 0.30, 0.08), (0.15, 0.38, 0.12), (0.08, 0.25, 0.12), (0.22, 0.40, 0.10))
_BOOK = (
    (0.55, 0.08, 0.08), (0.08, 0.18, 0.45), (0.10, 0.35, 0.15), (0.85, 0.75, 0.20),
    (0.12, 0.12, 0.12), (0.80, 0.80, 0.78), (0.45, 0.20, 0.45), (0.85, 0.40, 0.10),
    (0.30, 0.55, 0.65),
)
_SHADE = ((0.95, 0.92, 0.85), (0.90, 0.85, 0.75), (0.85, 0.85, 0.85), (0.80, 0.75, 0.65))
_PLASTIC = ((0.90, 0.90, 0.90), (0.10, 0.10, 0.10), (0.50, 0.50, 0.52), (0.15, 0.30, 0.55))
_APPLIANCE = ((0.92, 0.92, 0.92), (0.65, 0.66, 0.68), (0.12, 0.12, 0.13))
_MARBLE = ((0.90, 0.89, 0.87), (0.15, 0.15, 0.16), (0.60, 0.60, 0.58))
_LINEN = ((0.92, 0.92, 0.90), (0.85, 0.82, 0.75), (0.70, 0.75, 0.80))
_DARK = (0.04, 0.04, 0.045)
_WHITE = (0.9, 0.9, 0.88)

_WOODS = ("wood_light", "wood_dark")
_INF = float("inf")
_MIN_T = 1e-4  # thinnest slab a primitive gets


# ----------------------------------------------------------------------------------------------
# parameter access


def _get(p: dict, key: str, default):
    """params[key] coerced to the type of ``default``; the default when missing or unusable."""
    if not p or key not in p or p[key] is None:
        return default
    v = p[key]
    try:
        if isinstance(default, bool):
            return bool(v)
        if isinstance(default, int):
            return int(v)
        if isinstance(default, float):
            f = float(v)
            return f if math.isfinite(f) else default
        if isinstance(default, str):
            return str(v)
        if isinstance(default, tuple):
            t = tuple(float(x) for x in v)
            return t if len(t) == len(default) else default
    except (TypeError, ValueError):
        return default
    return v


def _clamp(v: float, lo: float, hi: float) -> float:
    if hi < lo:
        return lo
    return min(max(v, lo), hi)


def _col(c) -> tuple[float, float, float] | None:
    if c is None:
        return None
    return tuple(float(min(max(v, 0.0), 1.0)) for v in c[:3])


# ----------------------------------------------------------------------------------------------
# primitives (all return fresh trimesh.Trimesh objects)


def _mesh(v, f) -> trimesh.Trimesh:
    return trimesh.Trimesh(np.asarray(v, dtype=np.float64), np.asarray(f, dtype=np.int64), process=False)


def _box(x0, x1, y0, y1, z0, z1) -> trimesh.Trimesh:
    lo = np.array([min(x0, x1), min(y0, y1), min(z0, z1)], dtype=np.float64)
    hi = np.array([max(x0, x1), max(y0, y1), max(z0, z1)], dtype=np.float64)
    hi = np.maximum(hi, lo + _MIN_T)
    m = trimesh.creation.box(bounds=np.array([lo, hi]))
    return _mesh(m.vertices, m.faces)


def _cyl(cx, cy, z0, z1, rx, ry=None, sections=32) -> trimesh.Trimesh:
    """Vertical (elliptic) cylinder."""
    ry = rx if ry is None else ry
    hgt = max(z1 - z0, _MIN_T)
    m = trimesh.creation.cylinder(radius=1.0, height=hgt, sections=sections)
    v = m.vertices * np.array([max(rx, _MIN_T), max(ry, _MIN_T), 1.0]) + np.array([cx, cy, z0 + hgt / 2.0])
    return _mesh(v, m.faces)


def _rod(p0, p1, r, square=False, sections=12) -> trimesh.Trimesh:
    """Cylinder (or square bar) of radius / half-width r between points p0 and p1."""
    p0 = np.asarray(p0, dtype=np.float64)
    p1 = np.asarray(p1, dtype=np.float64)
    vec = p1 - p0
    length = float(np.linalg.norm(vec))
    if length < _MIN_T:
        vec = np.array([0.0, 0.0, 1.0])
        length = _MIN_T
    r = max(r, _MIN_T)
    if square:
        m = trimesh.creation.box(extents=[2 * r, 2 * r, length])
    else:
        m = trimesh.creation.cylinder(radius=r, height=length, sections=sections)
    tf = trimesh.geometry.align_vectors([0.0, 0.0, 1.0], vec / length)
    tf[:3, 3] = (p0 + p1) / 2.0
    v = trimesh.transform_points(m.vertices, tf)
    return _mesh(v, m.faces)


def _ycyl(cx, cz, y0, y1, rx, rz, sections=48, r_in=None) -> trimesh.Trimesh:
    """(Elliptic) cylinder or annulus (r_in as a fraction of the radius) whose axis runs along y."""
    y0, y1 = min(y0, y1), max(y0, y1)
    y1 = max(y1, y0 + _MIN_T)
    seg = [[0.0, y0, 0.0], [0.0, y1, 0.0]]
    if r_in is None:
        m = trimesh.creation.cylinder(radius=1.0, segment=seg, sections=sections)
    else:
        m = trimesh.creation.annulus(r_min=float(r_in), r_max=1.0, segment=seg, sections=sections)
    v = m.vertices * np.array([max(rx, _MIN_T), 1.0, max(rz, _MIN_T)]) + np.array([cx, 0.0, cz])
    return _mesh(v, m.faces)


def _rev(profile, cx=0.0, cy=0.0, z0=0.0, sx=1.0, sy=1.0, sz=1.0, sections=48) -> trimesh.Trimesh:
    """Surface of revolution of a (r, z) profile (counter-clockwise, closed or ending on the axis),
    scaled by (sx, sy, sz) and moved to (cx, cy, z0)."""
    m = trimesh.creation.revolve(np.asarray(profile, dtype=np.float64), sections=sections)
    v = m.vertices * np.array([sx, sy, sz]) + np.array([cx, cy, z0])
    return _mesh(v, m.faces)


def _ell(center, radii, subdiv=2) -> trimesh.Trimesh:
    m = trimesh.creation.icosphere(subdivisions=subdiv, radius=1.0)
    v = m.vertices * np.maximum(np.asarray(radii, dtype=np.float64), _MIN_T) + np.asarray(center, dtype=np.float64)
    return _mesh(v, m.faces)


_SOFT_CACHE: dict[tuple[float, int], tuple[np.ndarray, np.ndarray]] = {}


def _soft_box(x0, x1, y0, y1, z0, z1, e=0.3, subdiv=3) -> trimesh.Trimesh:
    """Rounded box (superellipsoid) exactly filling the given bounds."""
    key = (float(e), int(subdiv))
    if key not in _SOFT_CACHE:
        s = trimesh.creation.icosphere(subdivisions=subdiv, radius=1.0)
        v = np.sign(s.vertices) * np.abs(s.vertices) ** e
        v = v / np.abs(v).max(axis=0)
        _SOFT_CACHE[key] = (v, np.asarray(s.faces))
    v, f = _SOFT_CACHE[key]
    lo = np.array([min(x0, x1), min(y0, y1), min(z0, z1)])
    hi = np.array([max(x0, x1), max(y0, y1), max(z0, z1)])
    hi = np.maximum(hi, lo + _MIN_T)
    return _mesh((v + 1.0) / 2.0 * (hi - lo) + lo, f.copy())


def _transform(m: trimesh.Trimesh, tf) -> trimesh.Trimesh:
    return _mesh(trimesh.transform_points(m.vertices, np.asarray(tf)), m.faces)


def _rot(angle, axis, point=(0.0, 0.0, 0.0)):
    return trimesh.transformations.rotation_matrix(angle, axis, point)


def _cat(meshes) -> trimesh.Trimesh:
    meshes = [m for m in meshes if m is not None and len(m.faces)]
    verts, faces, off = [], [], 0
    for m in meshes:
        verts.append(np.asarray(m.vertices, dtype=np.float64))
        faces.append(np.asarray(m.faces, dtype=np.int64) + off)
        off += len(m.vertices)
    if not verts:
        return _mesh(np.zeros((0, 3)), np.zeros((0, 3), dtype=np.int64))
    return _mesh(np.vstack(verts), np.vstack(faces))


def _fit_meshes(meshes, lo, hi):
    """Affinely map the union of ``meshes`` (per axis) onto the box [lo, hi]."""
    lo = np.asarray(lo, dtype=np.float64)
    hi = np.asarray(hi, dtype=np.float64)
    allv = np.vstack([m.vertices for m in meshes])
    blo, bhi = allv.min(axis=0), allv.max(axis=0)
    s = (hi - lo) / np.maximum(bhi - blo, 1e-12)
    return [_mesh((m.vertices - blo) * s + lo, m.faces) for m in meshes]


# ----------------------------------------------------------------------------------------------
# builder


class _Builder:
    def __init__(self):
        self.parts: list[list] = []  # [name, material, mesh, emissive, color]
        self.surfaces: list[tuple] = []
        self._names: dict[str, int] = {}

    def add(self, name, material, mesh, emissive=False, color=None):
        if material not in MATERIALS:  # pragma: no cover - programming error
            raise AssertionError(f"material {material!r} not in MATERIALS")
        if name in self._names:
            self._names[name] += 1
            name = f"{name}_{self._names[name]}"
        else:
            self._names[name] = 0
        self.parts.append([name, material, mesh, bool(emissive), _col(color)])

    def surf(self, z, xmin, xmax, ymin, ymax, clearance, margin=0.02):
        mx = min(margin, 0.15 * (xmax - xmin))
        my = min(margin, 0.15 * (ymax - ymin))
        self.surfaces.append((z, xmin + mx, xmax - mx, ymin + my, ymax - my, clearance))


def _finish(b: _Builder, w, d, h) -> tuple[list[Part], list[Surface]]:
    lo = np.array([-w / 2.0, -d / 2.0, 0.0])
    hi = np.array([w / 2.0, d / 2.0, h])
    meshes = [p[2] for p in b.parts]
    allv = np.vstack([m.vertices for m in meshes])
    blo, bhi = allv.min(axis=0), allv.max(axis=0)
    s = (hi - lo) / np.maximum(bhi - blo, 1e-12)
    parts = []
    for name, mat, m, em, col in b.parts:
        v = np.clip((m.vertices - blo) * s + lo, lo, hi)
        parts.append(Part(name=name, material=mat, mesh=_mesh(v, m.faces), emissive=em, color=col))
    surfs = []
    for z, x0, x1, y0, y1, cl in b.surfaces:
        z2 = float(np.clip((z - blo[2]) * s[2], 0.0, h))
        xa = float(np.clip((x0 - blo[0]) * s[0] + lo[0], lo[0], hi[0]))
        xb = float(np.clip((x1 - blo[0]) * s[0] + lo[0], lo[0], hi[0]))
        ya = float(np.clip((y0 - blo[1]) * s[1] + lo[1], lo[1], hi[1]))
        yb = float(np.clip((y1 - blo[1]) * s[1] + lo[1], lo[1], hi[1]))
        c2 = float(cl * s[2]) if math.isfinite(cl) else _INF
        if xb - xa > 1e-3 and yb - ya > 1e-3:
            surfs.append(Surface(z=z2, xmin=xa, xmax=xb, ymin=ya, ymax=yb, clearance=c2))
    return parts, surfs


# ----------------------------------------------------------------------------------------------
# shared components


def _leg(cx, cy, z0, z1, t, style="square", sections=16) -> trimesh.Trimesh:
    if style == "round":
        return _cyl(cx, cy, z0, z1, t / 2.0, sections=sections)
    if style == "tapered":
        r = t / 2.0
        return _rev([(0, 0), (0.6, 0), (1.0, 1.0), (0, 1.0)], cx, cy, z0, r, r, max(z1 - z0, _MIN_T), sections)
    return _box(cx - t / 2.0, cx + t / 2.0, cy - t / 2.0, cy + t / 2.0, z0, z1)


def _handle_mesh(kind, cx, cz, y_face, depth, length, vertical) -> trimesh.Trimesh | None:
    if kind == "none" or depth <= 0:
        return None
    if kind == "knob":
        r = min(0.012, depth * 0.6)
        return _rod((cx, y_face, cz), (cx, y_face + depth, cz), r, sections=16)
    t = 0.006
    yb = y_face + 0.55 * depth
    if vertical:
        bar = _box(cx - t, cx + t, yb, y_face + depth, cz - length / 2, cz + length / 2)
        s0 = _box(cx - t * 0.7, cx + t * 0.7, y_face, yb, cz - length / 2 + 0.005, cz - length / 2 + 0.015)
        s1 = _box(cx - t * 0.7, cx + t * 0.7, y_face, yb, cz + length / 2 - 0.015, cz + length / 2 - 0.005)
    else:
        bar = _box(cx - length / 2, cx + length / 2, yb, y_face + depth, cz - t, cz + t)
        s0 = _box(cx - length / 2 + 0.005, cx - length / 2 + 0.015, y_face, yb, cz - t * 0.7, cz + t * 0.7)
        s1 = _box(cx + length / 2 - 0.015, cx + length / 2 - 0.005, y_face, yb, cz - t * 0.7, cz + t * 0.7)
    return _cat([bar, s0, s1])


def _casework(b, pfx, x0, x1, y0, y1, z0, z1, rows, mat, color=None, *, front_mat=None, front_color=None,
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
    t = _clamp(t, 0.004, min(0.15 * width, 0.15 * (z1 - z0)))
    bt = min(0.008, 0.1 * (yc - y0)) if back else 0.0
    front_mat = front_mat or mat
    front_color = front_color if front_color is not None else color
    b.add(f"{pfx}side_l", mat, _box(x0, x0 + t, y0, yc, z0, z1), color=color)
    b.add(f"{pfx}side_r", mat, _box(x1 - t, x1, y0, yc, z0, z1), color=color)
    zb = z0 + max(kick, 0.0)
    if kick > 0:
        b.add(f"{pfx}kick", mat, _box(x0 + t, x1 - t, yc - 0.03, yc - 0.012, z0, zb), color=color)
    if bottom:
        b.add(f"{pfx}bottom", mat, _box(x0 + t, x1 - t, y0, yc, zb, zb + t), color=color)
    if top:
        b.add(f"{pfx}top", mat, _box(x0, x1, y0, yc, z1 - t, z1), color=color)
    if back:
        b.add(f"{pfx}back", mat, _box(x0 + t, x1 - t, y0, y0 + bt, zb, z1), color=color)
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
            b.add(f"{pfx}board_{i}", mat, _box(x0 + t, x1 - t, y0 + bt, yc, z, z + t), color=color)
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
            b.add(f"{pfx}{nm}_{i}_{j}", front_mat, _box(fx0, fx1, yc, yc + ft, fz0, fz1), color=front_color)
            fw, fh = fx1 - fx0, fz1 - fz0
            if kind == "drawers":
                length = _clamp(0.35 * fw, 0.06, 0.3)
                hm = _handle_mesh(handle, (fx0 + fx1) / 2, (fz0 + fz1) / 2, yc + ft, hd, length, False)
            else:
                length = _clamp(0.3 * fh, 0.08, 0.4)
                right = (j < n / 2.0) if n > 1 else True
                off = 0.045 if handle == "bar" else 0.05
                cx = fx1 - off if right else fx0 + off
                if fh > 1.0:
                    cz = _clamp(1.0, fz0 + length / 2 + 0.05, fz1 - length / 2 - 0.05)
                else:
                    cz = _clamp(fz1 - 0.06 - length / 2, (fz0 + fz1) / 2, fz1)
                    if handle == "knob":
                        cz = _clamp(fz1 - 0.06, (fz0 + fz1) / 2, fz1)
                hm = _handle_mesh(handle, cx, cz, yc + ft, hd, length, True)
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


def _open_row_surfaces(b, info):
    xi0, xi1, yi0, yi1 = info["inner"]
    for kind, zlo, zhi in info["rows"]:
        if kind == "open":
            b.surf(zlo, xi0, xi1, yi0, yi1, zhi - zlo)


def _legs4(b, w, d, z1, t, style, mat, color=None, inset=0.02, z0=0.0, xoff=0.0, yoff=0.0, n_mid=0):
    lx = w / 2.0 - inset - t / 2.0
    ly = d / 2.0 - inset - t / 2.0
    pts = [(-lx, -ly), (lx, -ly), (-lx, ly), (lx, ly)]
    if n_mid:
        pts += [(0.0, -ly), (0.0, ly)]
    for i, (x, y) in enumerate(pts):
        b.add(f"leg_{i}", mat, _leg(x + xoff, y + yoff, z0, z1, t, style), color=color)
    return lx, ly


# ----------------------------------------------------------------------------------------------
# seating


def _gen_chair(b, w, d, h, p):
    frame_mat = _get(p, "frame_material", "wood_light")
    if frame_mat not in MATERIALS:
        frame_mat = "wood_light"
    frame_col = _get(p, "frame_color", _PAINT[1]) if frame_mat in ("painted", "metal") else None
    seat_mat = _get(p, "seat_material", "wood")
    seat_col = _get(p, "seat_color", _FABRIC[0])
    if seat_mat not in ("fabric", "leather"):
        seat_mat, seat_col = frame_mat, frame_col
    style = _get(p, "leg_style", "square")
    lt = _clamp(_get(p, "leg_thickness", 0.035), 0.01, 0.2 * min(w, d))
    sh = _clamp(_get(p, "seat_height", 0.45), 0.3 * h, 0.8 * h)
    st = _clamp(_get(p, "seat_thickness", 0.04), 0.01, 0.3 * sh)
    back_style = _get(p, "back_style", "solid")
    n_slats = int(_clamp(_get(p, "n_slats", 3), 1, 8))
    arms = _get(p, "armrests", False)
    stretchers = _get(p, "stretchers", False)
    inset = min(0.01, 0.05 * w)
    lx = w / 2 - inset - lt / 2
    lyf = d / 2 - inset - lt / 2
    lyb = -d / 2 + inset + lt / 2
    az = _clamp(sh + 0.21, sh + 0.3 * (h - sh), h - 0.1 * (h - sh))
    front_top = az if arms else sh - st
    b.add("seat", seat_mat, _box(-w / 2, w / 2, -d / 2, d / 2, sh - st, sh), color=seat_col)
    b.add("leg_0", frame_mat, _leg(-lx, lyf, 0, front_top, lt, style), color=frame_col)
    b.add("leg_1", frame_mat, _leg(lx, lyf, 0, front_top, lt, style), color=frame_col)
    b.add("leg_2", frame_mat, _leg(-lx, lyb, 0, h, lt, style), color=frame_col)
    b.add("leg_3", frame_mat, _leg(lx, lyb, 0, h, lt, style), color=frame_col)
    bx0, bx1 = -lx + lt / 2, lx - lt / 2
    upholstered = back_style == "solid" and seat_mat in ("fabric", "leather")
    bt = lt if upholstered else min(0.022, lt * 0.75)
    by0, by1 = lyb - bt / 2, lyb + bt / 2
    if back_style == "slats":
        rail0 = h - 0.22 * (h - sh)
        b.add("back", frame_mat, _box(bx0, bx1, by0, by1, rail0, h), color=frame_col)
        sw = min(0.04, (bx1 - bx0) / (2 * n_slats + 1))
        for i, cx in enumerate(np.linspace(bx0, bx1, n_slats + 2)[1:-1]):
            b.add(f"back_slat_{i}", frame_mat, _box(cx - sw / 2, cx + sw / 2, by0 + 0.002, by1 - 0.002,
                                                   sh + 0.03, rail0), color=frame_col)
    elif back_style == "rails":
        zs = np.linspace(sh + 0.25 * (h - sh), h, 3)
        rh = min(0.06, 0.12 * (h - sh))
        for i, zt in enumerate(zs):
            nm = "back" if i == len(zs) - 1 else f"back_rail_{i}"
            b.add(nm, frame_mat, _box(bx0, bx1, by0, by1, zt - rh, zt), color=frame_col)
    else:
        b.add("back", seat_mat if upholstered else frame_mat,
              _box(bx0, bx1, by0, by1, sh + 0.12 * (h - sh), h), color=seat_col if upholstered else frame_col)
    if arms:
        for i, sx in enumerate((-1, 1)):
            b.add(f"armrest_{i}", frame_mat, _box(sx * lx - lt / 2 - 0.003, sx * lx + lt / 2 + 0.003, lyb,
                                                  d / 2, az - 0.025, az), color=frame_col)
    if stretchers:
        zs_ = 0.3 * (sh - st)
        tt = 0.6 * lt
        for i, sx in enumerate((-1, 1)):
            b.add(f"stretcher_{i}", frame_mat, _box(sx * lx - tt / 2, sx * lx + tt / 2, lyb, lyf,
                                                    zs_ - tt / 2, zs_ + tt / 2), color=frame_col)
        b.add("stretcher_2", frame_mat, _box(-lx, lx, lyb - tt / 2, lyb + tt / 2, zs_ + 0.05 - tt / 2,
                                             zs_ + 0.05 + tt / 2), color=frame_col)
    ax = (lt + inset) if arms else 0.0
    b.surf(sh, -w / 2 + ax, w / 2 - ax, by1, d / 2, 0.5)


def _gen_stool(b, w, d, h, p):
    mat = _get(p, "material", "wood_light")
    if mat not in MATERIALS:
        mat = "wood_light"
    col = _get(p, "color", _PAINT[1]) if mat in ("painted", "metal") else None
    seat_mat = _get(p, "seat_material", "wood")
    seat_col = _get(p, "seat_color", _FABRIC[0])
    if seat_mat not in ("fabric", "leather"):
        seat_mat, seat_col = mat, col
    shape = _get(p, "seat_shape", "round")
    n_legs = int(_clamp(_get(p, "n_legs", 4), 3, 4))
    if shape == "square":
        n_legs = 4
    style = _get(p, "leg_style", "round")
    lt = _clamp(_get(p, "leg_thickness", 0.03), 0.01, 0.2 * min(w, d))
    st = _clamp(_get(p, "seat_thickness", 0.04), 0.01, 0.3 * h)
    footrest = _get(p, "footrest", False)
    zt = h - st
    if shape == "square":
        b.add("seat", seat_mat, _box(-w / 2, w / 2, -d / 2, d / 2, zt, h), color=seat_col)
    else:
        b.add("seat", seat_mat, _cyl(0, 0, zt, h, w / 2, d / 2, sections=48), color=seat_col)
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
        b.add(f"leg_{i}", mat, _rod((f[0], f[1], 0.0), (t_[0], t_[1], zt), r, square=(style == "square")),
              color=col)
    if footrest:
        zf = 0.3 * h
        k = zf / zt
        pts = [(f[0] + (t_[0] - f[0]) * k, f[1] + (t_[1] - f[1]) * k) for f, t_ in zip(feet, tops)]
        for i in range(len(pts)):
            a0, a1 = pts[i], pts[(i + 1) % len(pts)]
            b.add(f"footrest_{i}", mat, _rod((a0[0], a0[1], zf), (a1[0], a1[1], zf), 0.6 * r,
                                             square=(style == "square")), color=col)
    f = 0.7071 if shape != "square" else 1.0
    b.surf(h, -f * w / 2, f * w / 2, -f * d / 2, f * d / 2, 0.5)


def _gen_upholstered(b, w, d, h, p, default_seats):
    fmat = _get(p, "material", "fabric")
    if fmat not in ("fabric", "leather"):
        fmat = "fabric"
    col = _get(p, "color", _FABRIC[0])
    n = int(_clamp(_get(p, "n_seats", default_seats), 1, 4))
    lh = _clamp(_get(p, "leg_height", 0.08), 0.0, 0.25 * h)
    leg_mat = _get(p, "leg_material", "wood_dark")
    if leg_mat not in MATERIALS:
        leg_mat = "wood_dark"
    arm_style = _get(p, "arm_style", "box")
    aw = _clamp(_get(p, "arm_width", 0.15), 0.03, 0.2 * w) if arm_style != "none" else 0.0
    bt = _clamp(_get(p, "back_thickness", 0.18), 0.05, 0.35 * d)
    sh = _clamp(_get(p, "seat_height", 0.44), lh + 0.1 * h, 0.8 * h)
    ct = _clamp(_get(p, "cushion_thickness", 0.13), 0.02, 0.6 * (sh - lh))
    ah = _clamp(_get(p, "arm_height", 0.62), sh + 0.04, h)
    back_cushions = _get(p, "back_cushions", True)
    bc = _clamp(0.14, 0.02, 0.2 * d) if back_cushions else 0.0
    if lh > 0.005:
        lt = 0.04
        _legs4(b, w, d, lh + 0.005, lt, "tapered" if leg_mat.startswith("wood") else "round", leg_mat,
               inset=0.04, n_mid=1 if n >= 3 else 0)
    else:
        lh = 0.0
    b.add("base", fmat, _box(-w / 2 + aw, w / 2 - aw, -d / 2 + bt, d / 2, lh, sh - ct), color=col)
    b.add("back", fmat, _soft_box(-w / 2, w / 2, -d / 2, -d / 2 + bt, lh, h, e=0.12), color=col)
    if aw > 0:
        for i, sx in enumerate((-1, 1)):
            xa, xb = sorted((sx * w / 2, sx * (w / 2 - aw)))
            if arm_style == "roll":
                rr = aw / 2
                arm = _cat([_box(xa, xb, -d / 2, d / 2, lh, ah - rr),
                            _rod(((xa + xb) / 2, -d / 2, ah - rr), ((xa + xb) / 2, d / 2, ah - rr), rr,
                                 sections=24)])
            else:
                arm = _soft_box(xa, xb, -d / 2, d / 2, lh, ah, e=0.12)
            b.add(f"arm_{i}", fmat, arm, color=col)
    xs = np.linspace(-w / 2 + aw, w / 2 - aw, n + 1)
    g = 0.004
    for i in range(n):
        b.add(f"seat_cushion_{i}", fmat,
              _soft_box(xs[i] + g, xs[i + 1] - g, -d / 2 + bt + bc, d / 2, sh - ct, sh, e=0.25), color=col)
        if back_cushions:
            b.add(f"back_cushion_{i}", fmat,
                  _soft_box(xs[i] + g, xs[i + 1] - g, -d / 2 + bt - 0.01, -d / 2 + bt + bc, sh - ct,
                            sh + 0.88 * (h - sh), e=0.25), color=col)
    b.surf(sh, -w / 2 + aw, w / 2 - aw, -d / 2 + bt + bc, d / 2, 0.5)


def _gen_armchair(b, w, d, h, p):
    _gen_upholstered(b, w, d, h, p, 1)


def _gen_sofa(b, w, d, h, p):
    _gen_upholstered(b, w, d, h, p, 3 if w > 1.9 else 2)


def _gen_bench(b, w, d, h, p):
    mat = _get(p, "material", "wood_light")
    if mat not in MATERIALS:
        mat = "wood_light"
    col = _get(p, "color", _PAINT[1]) if mat in ("painted", "metal") else None
    style = _get(p, "style", "legs")
    lstyle = _get(p, "leg_style", "square")
    lt = _clamp(_get(p, "leg_thickness", 0.045), 0.01, 0.25 * min(w, d))
    st = _clamp(_get(p, "seat_thickness", 0.04), 0.01, 0.25 * h)
    cushion = _get(p, "cushion", False)
    ccol = _get(p, "cushion_color", _FABRIC[2])
    shelf = _get(p, "shelf", False)
    ct = min(0.06, 0.15 * h) if cushion else 0.0
    zs1 = h - ct
    zs0 = zs1 - st
    b.add("seat", mat, _box(-w / 2, w / 2, -d / 2, d / 2, zs0, zs1), color=col)
    if cushion:
        b.add("cushion", "fabric", _soft_box(-w / 2 + 0.01, w / 2 - 0.01, -d / 2 + 0.01, d / 2 - 0.01, zs1 - 0.01,
                                             h, e=0.3), color=ccol)
    overhang = min(0.06, 0.08 * w)
    if style == "panels":
        pt = min(lt, 0.1 * w)
        for i, sx in enumerate((-1, 1)):
            xa, xb = sorted((sx * (w / 2 - overhang), sx * (w / 2 - overhang - pt)))
            b.add(f"leg_{i}", mat, _box(xa, xb, -d / 2 + 0.01, d / 2 - 0.01, 0, zs0), color=col)
        lx, ly = w / 2 - overhang - pt, d / 2 - 0.01
    else:
        lx, ly = _legs4(b, w, d, zs0, lt, lstyle, mat, col, inset=overhang)
        lx, ly = lx - lt / 2, ly + lt / 2
    if shelf:
        zsh = _clamp(0.12, 0.05, 0.5 * zs0)
        b.add("shelf", mat, _box(-lx - 0.005, lx + 0.005, -ly, ly, zsh, zsh + 0.018), color=col)
        b.surf(zsh + 0.018, -lx, lx, -ly, ly, zs0 - zsh - 0.018)
    b.surf(h, -w / 2, w / 2, -d / 2, d / 2, 0.5)


# ----------------------------------------------------------------------------------------------
# tables


def _gen_table(b, w, d, h, p, kind="dining_table"):
    shape = _get(p, "top_shape", "rect")
    tmat = _get(p, "top_material", "wood_light")
    if tmat not in MATERIALS:
        tmat = "wood_light"
    tcol = _get(p, "top_color", _PAINT[0]) if tmat in ("painted", "marble", "glass") else None
    lmat = _get(p, "leg_material", tmat if tmat in _WOODS else "metal")
    if lmat not in MATERIALS:
        lmat = "metal"
    lcol = _get(p, "leg_color", _DARK) if lmat in ("painted", "metal") else None
    base = _get(p, "base", "legs4")
    if shape == "round" and base == "panels":
        base = "legs4"
    lstyle = _get(p, "leg_style", "square")
    lt = _clamp(_get(p, "leg_thickness", 0.05), 0.01, 0.2 * min(w, d))
    tt = _clamp(_get(p, "top_thickness", 0.035), 0.005, 0.3 * h)
    inset = _clamp(_get(p, "leg_inset", 0.05), 0.0, 0.2 * min(w, d))
    apron = _get(p, "apron", False) and base in ("legs4",) and shape == "rect"
    shelf = _get(p, "shelf", False) and base in ("legs4", "panels") and shape == "rect"
    zt = h - tt
    if shape == "round":
        b.add("top", tmat, _cyl(0, 0, zt, h, w / 2, d / 2, sections=64), color=tcol)
    else:
        b.add("top", tmat, _box(-w / 2, w / 2, -d / 2, d / 2, zt, h), color=tcol)
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
            b.add(f"leg_{i}", lmat, _leg(x, y, 0, zt, lt, lstyle), color=lcol)
        inner = (lx, ly)
        if apron:
            ah = _clamp(_get(p, "apron_height", 0.08), 0.02, 0.3 * zt)
            at = min(0.02, lt / 2)
            for i, sy in enumerate((-1, 1)):
                b.add(f"apron_{i}", lmat if lmat in _WOODS else tmat,
                      _box(-lx, lx, sy * (ly + lt / 2 - at), sy * (ly + lt / 2), zt - ah, zt),
                      color=lcol if lmat in _WOODS else tcol)
            for i, sx in enumerate((-1, 1)):
                b.add(f"apron_{i + 2}", lmat if lmat in _WOODS else tmat,
                      _box(sx * (lx + lt / 2 - at), sx * (lx + lt / 2), -ly, ly, zt - ah, zt),
                      color=lcol if lmat in _WOODS else tcol)
    elif base == "panels":
        pt = _clamp(lt, 0.015, 0.1 * w)
        for i, sx in enumerate((-1, 1)):
            xa, xb = sorted((sx * (w / 2 - inset), sx * (w / 2 - inset - pt)))
            b.add(f"leg_{i}", lmat, _box(xa, xb, -d / 2 + inset / 2, d / 2 - inset / 2, 0, zt), color=lcol)
        inner = (w / 2 - inset - pt, d / 2 - inset / 2)
    elif shape == "rect" and w > 1.3 * d:  # trestle: two pedestals with feet along y
        rc = _clamp(0.04 + 0.03 * min(w, d), 0.02, 0.1 * min(w, d))
        fy = 0.4 * d
        fh = min(0.05, 0.1 * zt)
        for i, sx in enumerate((-1, 1)):
            x = sx * 0.3 * w
            b.add(f"foot_{i}", lmat, _box(x - rc, x + rc, -fy, fy, 0, fh), color=lcol)
            b.add(f"column_{i}", lmat, _box(x - 0.7 * rc, x + 0.7 * rc, -0.7 * rc * 2, 0.7 * rc * 2, fh, zt - fh),
                  color=lcol)
            b.add(f"cleat_{i}", lmat, _box(x - rc, x + rc, -fy, fy, zt - fh, zt), color=lcol)
        b.add("stretcher", lmat, _box(-0.3 * w, 0.3 * w, -0.5 * rc, 0.5 * rc, 0.45 * zt, 0.45 * zt + 2 * rc),
              color=lcol)
    else:  # pedestal
        rc = _clamp(0.04 + 0.05 * min(w, d), 0.02, 0.15 * min(w, d))
        rb = _clamp(0.32 * min(w, d), 1.5 * rc, 0.45 * min(w, d))
        bh = min(0.03, 0.1 * zt)
        b.add("base", lmat, _cyl(0, 0, 0, bh, rb, sections=48), color=lcol)
        b.add("column", lmat, _cyl(0, 0, bh, zt, rc, sections=32), color=lcol)
        b.add("column_cap", lmat, _cyl(0, 0, zt - 0.02, zt, rc * 2.5, sections=32), color=lcol)
    if shelf and inner is not None:
        sx, sy = inner
        zsh = _clamp(_get(p, "shelf_height", 0.12), 0.03, 0.5 * zt)
        sth = min(0.02, 0.1 * zt)
        b.add("shelf", tmat if tmat != "glass" else "wood_dark", _box(-sx, sx, -sy, sy, zsh, zsh + sth),
              color=tcol if tmat != "glass" else None)
        b.surf(zsh + sth, -sx + lt / 2, sx - lt / 2, -sy + lt / 2, sy - lt / 2, zt - zsh - sth - 0.02)
    f = 0.7071 if shape == "round" else 1.0
    b.surf(h, -f * w / 2, f * w / 2, -f * d / 2, f * d / 2, _INF)


def _gen_dining_table(b, w, d, h, p):
    _gen_table(b, w, d, h, p, "dining_table")


def _gen_coffee_table(b, w, d, h, p):
    _gen_table(b, w, d, h, p, "coffee_table")


def _gen_side_table(b, w, d, h, p):
    _gen_table(b, w, d, h, p, "side_table")


def _gen_desk(b, w, d, h, p):
    tmat = _get(p, "top_material", "wood_light")
    if tmat not in MATERIALS:
        tmat = "wood_light"
    tcol = _get(p, "top_color", _PAINT[0]) if tmat in ("painted",) else None
    bmat = _get(p, "body_material", tmat)
    if bmat not in MATERIALS:
        bmat = tmat
    bcol = _get(p, "body_color", _PAINT[0]) if bmat in ("painted", "metal") else None
    base = _get(p, "base", "drawers")
    side = _get(p, "drawer_side", "right")
    n_dr = int(_clamp(_get(p, "n_drawers", 3), 1, 5))
    lstyle = _get(p, "leg_style", "square")
    lt = _clamp(_get(p, "leg_thickness", 0.045), 0.01, 0.2 * min(w, d))
    tt = _clamp(_get(p, "top_thickness", 0.03), 0.005, 0.2 * h)
    handle = _get(p, "handle", "bar")
    zt = h - tt
    b.add("top", tmat, _box(-w / 2, w / 2, -d / 2, d / 2, zt, h), color=tcol)
    inset = min(0.03, 0.05 * w)
    if base == "panels":
        pt = min(0.025, 0.08 * w)
        for i, sx in enumerate((-1, 1)):
            xa, xb = sorted((sx * (w / 2 - inset), sx * (w / 2 - inset - pt)))
            b.add(f"leg_{i}", bmat, _box(xa, xb, -d / 2 + inset, d / 2 - inset, 0, zt), color=bcol)
        b.add("modesty_panel", bmat, _box(-w / 2 + inset + pt, w / 2 - inset - pt, -d / 2 + 0.04, -d / 2 + 0.058,
                                          0.4 * zt, zt), color=bcol)
    elif base == "drawers":
        pw = _clamp(0.4, 0.2 * w, 0.45 * w)
        sgn = 1 if side != "left" else -1
        xa, xb = sorted((sgn * (w / 2 - inset), sgn * (w / 2 - inset - pw)))
        _casework(b, "pedestal_", xa, xb, -d / 2 + inset, d / 2 - inset * 0.5, 0.0, zt,
                  [("drawers", 1, 1)] * n_dr, bmat, bcol, handle=handle, top=True)
        lx = w / 2 - inset - lt / 2
        ly = d / 2 - inset - lt / 2
        for i, y in enumerate((-ly, ly)):
            b.add(f"leg_{i}", bmat, _leg(-sgn * lx, y, 0, zt, lt, lstyle), color=bcol)
    else:
        _legs4(b, w, d, zt, lt, lstyle, bmat, bcol, inset=inset)
    b.surf(h, -w / 2, w / 2, -d / 2, d / 2, _INF)


# ----------------------------------------------------------------------------------------------
# storage


def _body_mat(p, default="wood_light"):
    mat = _get(p, "material", default)
    if mat not in MATERIALS:
        mat = default
    col = _get(p, "color", _PAINT[0]) if mat in ("painted", "metal", "plastic") else None
    return mat, col


def _gen_nightstand(b, w, d, h, p):
    mat, col = _body_mat(p)
    n = int(_clamp(_get(p, "n_drawers", 2), 1, 4))
    open_shelf = _get(p, "open_shelf", False)
    legs = _get(p, "legs", True)
    lh = _clamp(_get(p, "leg_height", 0.12), 0.02, 0.35 * h) if legs else 0.0
    handle = _get(p, "handle", "knob")
    rows = ([("open", 1, 1.2)] if open_shelf else []) + [("drawers", 1, 1)] * n
    if lh > 0:
        _legs4(b, w, d - 0.045, lh + 0.005, min(0.035, 0.15 * w), "tapered" if mat in _WOODS else "square", mat,
               col, inset=0.02, yoff=-0.0225)
    info = _casework(b, "", -w / 2, w / 2, -d / 2, d / 2, lh, h, rows, mat, col, handle=handle)
    _open_row_surfaces(b, info)
    b.surf(h, -w / 2, w / 2, -d / 2, info["yc"], _INF)


def _cabinet_base(b, w, d, h, p, mat, col, front_space):
    base = _get(p, "base", "plinth")
    if base == "legs":
        lh = _clamp(_get(p, "leg_height", 0.12), 0.02, 0.35 * h)
        _legs4(b, w, d - front_space, lh + 0.005, min(0.035, 0.1 * w), "tapered" if mat in _WOODS else "round",
               mat if mat in _WOODS else "metal", None, inset=0.03, yoff=-front_space / 2)
        return lh
    if base == "plinth":
        ph = _clamp(_get(p, "plinth_height", 0.08), 0.02, 0.25 * h)
        b.add("plinth", "painted", _box(-w / 2 + 0.02, w / 2 - 0.02, -d / 2 + 0.02, d / 2 - front_space - 0.04,
                                        0, ph + 0.002), color=_DARK)
        return ph
    return 0.0


def _gen_cabinet(b, w, d, h, p):
    mat, col = _body_mat(p)
    style = _get(p, "style", "doors")
    handle = _get(p, "handle", "bar")
    nd = int(_clamp(_get(p, "n_doors", 2 if w >= 0.6 else 1), 1, 4))
    nr = int(_clamp(_get(p, "n_drawers", 3), 1, 6))
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
    info = _casework(b, "", -w / 2, w / 2, -d / 2, d / 2, z0, h, rows, mat, col, handle=handle, front_space=fs)
    _open_row_surfaces(b, info)
    b.surf(h, -w / 2, w / 2, -d / 2, info["yc"], _INF)


def _gen_tv_stand(b, w, d, h, p):
    mat, col = _body_mat(p, "wood_dark")
    handle = _get(p, "handle", "bar")
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
        info = _casework(b, f"m{i}_", xs[i], xs[i + 1], -d / 2, d / 2, z0, h, rows, mat, col, handle=handle,
                         front_space=fs)
        _open_row_surfaces(b, info)
        yc = info["yc"]
    b.surf(h, -w / 2, w / 2, -d / 2, yc, _INF)


def _gen_bookshelf(b, w, d, h, p):
    mat, col = _body_mat(p)
    n = int(_clamp(_get(p, "n_boards", 4), 1, 8))
    t = _clamp(_get(p, "board_thickness", 0.02), 0.008, 0.05)
    back = _get(p, "back", True)
    kick = _clamp(_get(p, "plinth_height", 0.06), 0.0, 0.1 * h)
    lower_doors = _get(p, "lower_doors", False)
    rows = [("open", 1, 1)] * (n + 1)
    if lower_doors:
        rows[0] = ("doors", 2 if w > 0.5 else 1, 1.3)
    info = _casework(b, "", -w / 2, w / 2, -d / 2, d / 2, 0.0, h, rows, mat, col, t=t, back=back, kick=kick,
                     handle=_get(p, "handle", "knob"))
    _open_row_surfaces(b, info)
    b.surf(h, -w / 2, w / 2, -d / 2, info["yc"], _INF)


def _gen_wardrobe(b, w, d, h, p):
    mat, col = _body_mat(p)
    nd = int(_clamp(_get(p, "n_doors", 2 if w < 1.4 else 3), 1, 5))
    drawers = _get(p, "drawers", False)
    handle = _get(p, "handle", "bar")
    cornice = _get(p, "cornice", True)
    mirror_door = _get(p, "mirror_door", False)
    kick = _clamp(_get(p, "plinth_height", 0.07), 0.0, 0.1 * h)
    ch = min(0.05, 0.05 * h) if cornice else 0.0
    fs = 0.018 + (0.025 if handle != "none" else 0.0)
    rows = ([("drawers", 2 if w > 0.9 else 1, 0.16)] if drawers else []) + [("doors", nd, 1)]
    info = _casework(b, "", -w / 2, w / 2, -d / 2, d / 2, 0.0, h - ch, rows, mat, col, handle=handle, kick=kick,
                     front_space=fs, t=0.02)
    if ch > 0:
        b.add("cornice", mat, _box(-w / 2, w / 2, -d / 2, min(info["front"] + 0.005, d / 2), h - ch, h), color=col)
    if mirror_door:
        # a mirror pane on the first door
        for part in b.parts:
            if part[0].startswith("door_") and part[0].endswith("_0"):
                m = part[2]
                lo, hi = m.bounds
                inset = 0.06
                b.add("mirror", "mirror", _box(lo[0] + inset, hi[0] - inset, hi[1], hi[1] + 0.003,
                                               lo[2] + inset, hi[2] - inset))
                break
    b.surf(h, -w / 2, w / 2, -d / 2, info["yc"], _INF)


def _gen_shoe_rack(b, w, d, h, p):
    mat, col = _body_mat(p)
    style = _get(p, "style", "boards")
    n = int(_clamp(_get(p, "n_levels", 2), 1, 5))
    if style == "bars":
        t = min(0.025, 0.1 * w)
        tt = min(0.02, 0.1 * h)
        b.add("top", mat, _box(-w / 2, w / 2, -d / 2, d / 2, h - tt, h), color=col)
        for i, sx in enumerate((-1, 1)):
            xa, xb = sorted((sx * w / 2, sx * (w / 2 - t)))
            b.add(f"side_{i}", mat, _box(xa, xb, -d / 2, d / 2, 0, h - tt), color=col)
        levels = np.linspace(0.06, h - tt, n + 1)[:-1] + 0.0
        rr = 0.009
        for i, z in enumerate(levels):
            z = max(z, rr)
            for j, (y, dz) in enumerate(((d / 2 - 0.04, 0.0), (-d / 2 + 0.04, 0.04 * d / 0.3))):
                b.add(f"bar_{i}_{j}", "metal", _rod((-w / 2 + t, y, z + dz), (w / 2 - t, y, z + dz), rr,
                                                    sections=12))
            b.surf(z + rr, -w / 2 + t, w / 2 - t, -d / 2 + 0.04, d / 2 - 0.04, (h - tt) / n - 0.03, margin=0.0)
        b.surf(h, -w / 2, w / 2, -d / 2, d / 2, _INF)
        return
    rows = [("open", 1, 1)] * n
    info = _casework(b, "", -w / 2, w / 2, -d / 2, d / 2, 0.0, h, rows, mat, col, back=False, kick=0.0)
    _open_row_surfaces(b, info)
    b.surf(h, -w / 2, w / 2, -d / 2, d / 2, _INF)


# ----------------------------------------------------------------------------------------------
# kitchen


def _gen_kitchen_counter(b, w, d, h, p):
    mat, col = _body_mat(p, "painted")
    wt_mat = _get(p, "worktop_material", "marble")
    if wt_mat not in MATERIALS:
        wt_mat = "marble"
    wt_col = _get(p, "worktop_color", _MARBLE[0]) if wt_mat in ("marble", "painted") else None
    wt = _clamp(_get(p, "worktop_thickness", 0.035), 0.01, 0.1 * h)
    handle = _get(p, "handle", "bar")
    ph = _clamp(_get(p, "plinth_height", 0.1), 0.0, 0.2 * h)
    n_mod = int(_clamp(_get(p, "n_modules", max(1, int(round(w / 0.6)))), 1, 10))
    sink = _get(p, "sink", True)
    sink_mod = int(_clamp(_get(p, "sink_module", n_mod // 2), 0, n_mod - 1))
    styles = p.get("module_styles") if isinstance(p, dict) else None
    if not isinstance(styles, (list, tuple)):
        styles = []
    overhang = min(0.025, 0.05 * d)
    fs = 0.018 + (0.025 if handle != "none" else 0.0)
    zt = h - wt
    if ph > 0:
        b.add("plinth", "painted", _box(-w / 2, w / 2, -d / 2, d / 2 - overhang - fs - 0.05, 0, ph + 0.002),
              color=_DARK)
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
        _casework(b, f"m{i}_", xs[i], xs[i + 1], -d / 2, d / 2 - overhang, ph, zt, rows, mat, col,
                  handle=handle, front_space=fs, top=not (sink and i == sink_mod), kick=0.0)
    if sink:
        mw = xs[sink_mod + 1] - xs[sink_mod]
        cx = (xs[sink_mod] + xs[sink_mod + 1]) / 2
        sw = _clamp(_get(p, "sink_width", 0.5), 0.2, mw - 0.1)
        sd = _clamp(0.4, 0.15, d - 0.18)
        sx0, sx1 = cx - sw / 2, cx + sw / 2
        sy0, sy1 = -d / 2 + 0.1, -d / 2 + 0.1 + sd
        b.add("worktop_0", wt_mat, _box(-w / 2, sx0, -d / 2, d / 2, zt, h), color=wt_col)
        b.add("worktop_1", wt_mat, _box(sx1, w / 2, -d / 2, d / 2, zt, h), color=wt_col)
        b.add("worktop_2", wt_mat, _box(sx0, sx1, -d / 2, sy0, zt, h), color=wt_col)
        b.add("worktop_3", wt_mat, _box(sx0, sx1, sy1, d / 2, zt, h), color=wt_col)
        depth = _clamp(0.18, 0.05, zt - ph - 0.05)
        zb = h - 0.002 - depth
        st_ = 0.008
        basin = _cat([
            _box(sx0, sx1, sy0, sy1, zb, zb + st_),
            _box(sx0, sx0 + st_, sy0, sy1, zb, h - 0.001),
            _box(sx1 - st_, sx1, sy0, sy1, zb, h - 0.001),
            _box(sx0, sx1, sy0, sy0 + st_, zb, h - 0.001),
            _box(sx0, sx1, sy1 - st_, sy1, zb, h - 0.001),
        ])
        b.add("sink", "metal", basin)
        b.add("drain", "metal", _cyl(cx, (sy0 + sy1) / 2, zb + st_, zb + st_ + 0.002, 0.035), color=_DARK)
        b.surf(h, -w / 2, sx0, -d / 2, d / 2, _INF)
        b.surf(h, sx1, w / 2, -d / 2, d / 2, _INF)
    else:
        b.add("worktop", wt_mat, _box(-w / 2, w / 2, -d / 2, d / 2, zt, h), color=wt_col)
        b.surf(h, -w / 2, w / 2, -d / 2, d / 2, _INF)


def _gen_fridge(b, w, d, h, p):
    mat = _get(p, "material", "metal")
    if mat not in ("metal", "painted", "plastic"):
        mat = "metal"
    col = _get(p, "color", _APPLIANCE[0])
    style = _get(p, "style", "bottom_freezer")
    hd, ft = 0.04, 0.04
    yc = d / 2 - hd - ft
    gz = min(0.05, 0.05 * h)
    b.add("body", mat, _box(-w / 2, w / 2, -d / 2, yc, 0, h), color=col)
    b.add("grille", "plastic", _box(-w / 2 + 0.02, w / 2 - 0.02, yc, yc + ft * 0.5, 0.005, gz), color=_DARK)
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
        b.add(f"door_{i}", mat, _box(x0 + g, x1 - g, yc, yc + ft, z0 + g, z1 - g), color=col)
        if hk == "h":
            length = min(0.6 * (x1 - x0), 0.45)
            hm = _handle_mesh("bar", (x0 + x1) / 2, z1 - 0.06, yc + ft, hd, length, False)
        else:
            length = _clamp(0.4 * (z1 - z0), 0.1, 0.6)
            cx = x1 - 0.05 if hk == "v_r" else x0 + 0.05
            cz = _clamp(z0 + 0.55 * (z1 - z0) if z1 - z0 < 0.8 else 1.05, z0 + length / 2 + 0.03,
                        z1 - length / 2 - 0.03)
            if z1 - z0 < 0.8:
                cz = _clamp(z0 + length / 2 + 0.06, z0 + length / 2 + 0.03, z1 - length / 2 - 0.03)
            hm = _handle_mesh("bar", cx, cz, yc + ft, hd, length, True)
        b.add(f"handle_{i}", "metal", hm, color=(0.7, 0.7, 0.72))
    b.surf(h, -w / 2, w / 2, -d / 2, yc + ft, _INF)


def _gen_stove(b, w, d, h, p):
    mat = _get(p, "material", "metal")
    if mat not in ("metal", "painted"):
        mat = "metal"
    col = _get(p, "color", _APPLIANCE[1])
    kind = _get(p, "burner_type", "gas")
    hd, ft = 0.035, 0.02
    yc = d / 2 - hd - ft
    bh = 0.02 if kind == "gas" else 0.002
    pt = 0.008
    zp = h - bh - pt
    b.add("body", mat, _box(-w / 2, w / 2, -d / 2, yc, 0, zp), color=col)
    b.add("cooktop", "glass" if kind != "gas" else "metal", _box(-w / 2, w / 2, -d / 2, yc + ft, zp, h - bh),
          color=_DARK)
    r_big = _clamp(0.16 * min(w, d), 0.02, 0.24 * min(w, d))
    r_small = 0.75 * r_big
    y_mid = (-d / 2 + yc + ft) / 2
    dy = 0.25 * (yc + ft + d / 2)
    pos = [(-w / 4, y_mid + dy, r_big), (w / 4, y_mid + dy, r_small), (-w / 4, y_mid - dy, r_small),
           (w / 4, y_mid - dy, r_big)]
    for i, (x, y, r) in enumerate(pos):
        if kind == "gas":
            m = _cat([_cyl(x, y, h - bh, h - bh * 0.45, r, sections=32),
                      _cyl(x, y, h - bh * 0.45, h, 0.55 * r, sections=32)])
        else:
            m = _cyl(x, y, h - bh, h, r, sections=48)
        b.add(f"burner_{i}", "metal" if kind == "gas" else "glass", m,
              color=(0.15, 0.15, 0.15) if kind == "gas" else (0.25, 0.25, 0.27))
    # oven door with window and handle, control strip with knobs, storage drawer
    zd0 = min(0.12, 0.15 * h)
    zd1 = zp - min(0.12, 0.15 * h)
    b.add("oven_door", mat, _box(-w / 2 + 0.005, w / 2 - 0.005, yc, yc + ft, zd0, zd1), color=col)
    b.add("oven_window", "glass", _box(-w / 2 + 0.07, w / 2 - 0.07, yc + ft, yc + ft + 0.002,
                                       zd0 + 0.06, zd1 - 0.1), color=_DARK)
    b.add("oven_handle", "metal", _handle_mesh("bar", 0.0, zd1 - 0.04, yc + ft, hd, 0.7 * w, False))
    b.add("drawer", mat, _box(-w / 2 + 0.005, w / 2 - 0.005, yc, yc + ft, 0.01, zd0 - 0.005), color=col)
    n_k = 4 if w < 0.7 else 5
    zk = (zd1 + zp) / 2
    for i, x in enumerate(np.linspace(-w / 2 + 0.08, w / 2 - 0.08, n_k)):
        b.add(f"knob_{i}", "plastic", _rod((x, yc, zk), (x, yc + ft + 0.02, zk), 0.016, sections=16), color=_DARK)


# ----------------------------------------------------------------------------------------------
# bedroom / bathroom


def _gen_bed(b, w, d, h, p):
    fmat, fcol = _body_mat(p, "wood_light")
    hb_style = _get(p, "headboard_style", "panel")
    hb_col = _get(p, "headboard_color", _FABRIC[0])
    lh = _clamp(_get(p, "leg_height", 0.1), 0.0, 0.2 * h)
    ftop = _clamp(_get(p, "frame_height", 0.32), lh + 0.05, 0.55 * h)
    mth = _clamp(_get(p, "mattress_thickness", 0.22), 0.05, 0.8 * (h - ftop))
    hbt = _clamp(_get(p, "headboard_thickness", 0.06), 0.02, 0.1 * d)
    footboard = _get(p, "footboard", False)
    fbt = min(0.04, 0.05 * d) if footboard else 0.0
    mcol = _get(p, "mattress_color", _LINEN[0])
    duvet = _get(p, "duvet", True)
    dcol = _get(p, "duvet_color", _FABRIC[5])
    y0, y1 = -d / 2 + hbt, d / 2 - fbt
    if lh > 0.005:
        _legs4(b, w, y1 - y0, lh + 0.005, 0.05, "square", fmat, fcol, inset=0.03, yoff=(y0 + y1) / 2)
    else:
        lh = 0.0
    b.add("frame", fmat, _box(-w / 2, w / 2, y0, y1, lh, ftop), color=fcol)
    if hb_style == "upholstered":
        b.add("headboard_post", fmat, _box(-w / 2, w / 2, -d / 2, -d / 2 + hbt * 0.4, 0, ftop + 0.1), color=fcol)
        b.add("headboard", "fabric", _soft_box(-w / 2, w / 2, -d / 2, -d / 2 + hbt, ftop - 0.05, h, e=0.2),
              color=hb_col)
    elif hb_style == "slats":
        pt = min(0.06, 0.05 * w)
        for i, sx in enumerate((-1, 1)):
            xa, xb = sorted((sx * w / 2, sx * (w / 2 - pt)))
            b.add(f"headboard_post_{i}", fmat, _box(xa, xb, -d / 2, y0, 0, h), color=fcol)
        b.add("headboard", fmat, _box(-w / 2 + pt, w / 2 - pt, -d / 2, y0, h - 0.08, h), color=fcol)
        n = max(3, int((w - 2 * pt) / 0.15))
        for i, cx in enumerate(np.linspace(-w / 2 + pt, w / 2 - pt, n + 2)[1:-1]):
            b.add(f"headboard_slat_{i}", fmat, _box(cx - 0.025, cx + 0.025, -d / 2 + 0.01, y0 - 0.01, ftop, h - 0.08),
                  color=fcol)
    else:
        b.add("headboard", fmat, _box(-w / 2, w / 2, -d / 2, y0, 0, h), color=fcol)
    if footboard:
        fh = min(ftop + _clamp(_get(p, "footboard_height", 0.1), 0.0, 0.3), h)
        b.add("footboard", fmat, _box(-w / 2, w / 2, y1, d / 2, 0, fh), color=fcol)
    mz0 = ftop - min(0.05, 0.3 * mth)
    mt = mz0 + mth
    mx = min(0.03, 0.05 * w)
    my0, my1 = y0 + 0.01, y1 - 0.015
    b.add("mattress", "mattress", _soft_box(-w / 2 + mx, w / 2 - mx, my0, my1, mz0, mt, e=0.15), color=mcol)
    if duvet:
        dy0 = my0 + 0.3 * (my1 - my0)
        dz = min(0.03, 0.2 * mth)
        b.add("duvet", "fabric", _soft_box(-w / 2 + mx - 0.02, w / 2 - mx + 0.02, dy0, my1 + 0.01,
                                           mz0 + 0.35 * mth, mt + dz, e=0.15), color=dcol)
        b.surf(mt, -w / 2 + mx, w / 2 - mx, my0, dy0, _INF)
        b.surf(mt + dz, -w / 2 + mx, w / 2 - mx, dy0, my1, _INF)
    else:
        b.surf(mt, -w / 2 + mx, w / 2 - mx, my0, my1, _INF)


def _gen_toilet(b, w, d, h, p):
    col = _get(p, "color", _WHITE)
    seat_col = _get(p, "seat_color", _WHITE)
    td = _clamp(_get(p, "tank_depth", 0.17), 0.05, 0.35 * d)
    sh = _clamp(_get(p, "seat_height", 0.42), 0.3 * h, 0.75 * h)
    tz0 = _clamp(_get(p, "tank_bottom", sh + 0.02), sh - 0.1, h - 0.1)
    lid = _get(p, "lid", True)
    b.add("tank", "ceramic", _soft_box(-w / 2, w / 2, -d / 2, -d / 2 + td, tz0, h, e=0.2), color=col)
    b.add("flush_button", "metal", _cyl(0, -d / 2 + td / 2, h - 0.004, h, min(0.02, td / 4), sections=24))
    by0 = -d / 2 + td - 0.05
    cy = (by0 + d / 2) / 2
    ry = (d / 2 - by0) / 2
    rx = 0.88 * w / 2
    rim = sh - 0.03
    bowl_prof = [(0.0, 0.0), (0.55, 0.0), (0.75, 0.45), (1.0, 1.0), (0.84, 1.0), (0.5, 0.55), (0.0, 0.5)]
    z_b0 = 0.18 * sh
    b.add("bowl", "ceramic", _rev(bowl_prof, 0, cy, z_b0, rx, ry, rim - z_b0, sections=48), color=col)
    b.add("base", "ceramic", _rev([(0, 0), (0.5, 0), (0.42, 1.0), (0, 1.0)], 0, cy - 0.1 * ry, 0, rx, ry * 0.75,
                                  z_b0 + 0.02, sections=48), color=col)
    ring = [(0.72, 0.0), (1.0, 0.0), (1.0, 1.0), (0.72, 1.0), (0.72, 0.0)]
    b.add("seat", "plastic", _rev(ring, 0, cy, rim, rx, ry, sh - rim, sections=48), color=seat_col)
    if lid:
        b.add("lid", "plastic", _cyl(0, cy, sh, sh + 0.015, rx * 0.98, ry * 0.98, sections=48), color=seat_col)
    b.surf(h, -w / 2, w / 2, -d / 2, -d / 2 + td, _INF, margin=0.015)


def _gen_bathtub(b, w, d, h, p):
    col = _get(p, "color", _WHITE)
    style = _get(p, "style", "built_in")
    rw = _clamp(_get(p, "rim_width", 0.07), 0.02, 0.2 * min(w, d))
    tap = _get(p, "tap", True)
    fh = _clamp(_get(p, "feet_height", 0.1), 0.02, 0.3 * h) if style == "feet" else 0.0
    tap_h = min(0.1, 0.2 * h) if tap else 0.0
    zr = h - tap_h
    z0 = fh
    fl = _clamp(0.12, 0.02, 0.5 * (zr - z0))
    re = min(rw * 1.8, 0.25 * w)  # wider rim at the -x end (tap end)
    if style == "feet":
        e = 0.3
        b.add("shell", "ceramic", _soft_box(-w / 2, w / 2, -d / 2, d / 2, z0, z0 + fl + 0.05, e=e), color=col)
        b.add("rim_0", "ceramic", _soft_box(-w / 2, -w / 2 + re + 0.03, -d / 2, d / 2, z0, zr, e=e), color=col)
        b.add("rim_1", "ceramic", _soft_box(w / 2 - rw - 0.03, w / 2, -d / 2, d / 2, z0, zr, e=e), color=col)
        b.add("rim_2", "ceramic", _soft_box(-w / 2, w / 2, -d / 2, -d / 2 + rw + 0.03, z0, zr, e=e), color=col)
        b.add("rim_3", "ceramic", _soft_box(-w / 2, w / 2, d / 2 - rw - 0.03, d / 2, z0, zr, e=e), color=col)
        for i, (sx, sy) in enumerate(((-1, -1), (1, -1), (-1, 1), (1, 1))):
            b.add(f"foot_{i}", "metal", _cyl(sx * (w / 2 - 0.12), sy * (d / 2 - 0.1), 0, z0 + 0.02, 0.035,
                                             sections=16))
        b.add("basin", "ceramic", _box(-w / 2 + re, w / 2 - rw, -d / 2 + rw, d / 2 - rw, z0, z0 + fl),
              color=(col[0] * 0.92, col[1] * 0.92, col[2] * 0.95))
    else:
        b.add("rim_0", "ceramic", _box(-w / 2, -w / 2 + re, -d / 2, d / 2, 0, zr), color=col)
        b.add("rim_1", "ceramic", _box(w / 2 - rw, w / 2, -d / 2, d / 2, 0, zr), color=col)
        b.add("rim_2", "ceramic", _box(-w / 2 + re, w / 2 - rw, -d / 2, -d / 2 + rw, 0, zr), color=col)
        b.add("rim_3", "ceramic", _box(-w / 2 + re, w / 2 - rw, d / 2 - rw, d / 2, 0, zr), color=col)
        b.add("basin", "ceramic", _box(-w / 2 + re, w / 2 - rw, -d / 2 + rw, d / 2 - rw, 0, fl),
              color=(col[0] * 0.92, col[1] * 0.92, col[2] * 0.95))
    b.add("drain", "metal", _cyl(-w / 2 + re + 0.1, 0, z0 + fl, z0 + fl + 0.003, 0.03, sections=24))
    if tap:
        tx = -w / 2 + re / 2
        b.add("tap", "metal", _cat([_cyl(tx, 0, zr - 0.01, h - 0.02, 0.015, sections=16),
                                     _rod((tx, 0, h - 0.035), (-w / 2 + re + 0.08, 0, h - 0.035), 0.013),
                                     _box(tx - 0.01, tx + 0.01, -0.04, 0.04, h - 0.02, h)]))


def _gen_washbasin(b, w, d, h, p):
    col = _get(p, "color", _WHITE)
    style = _get(p, "style", "pedestal")
    shape = _get(p, "basin_shape", "rect")
    fhgt = _clamp(_get(p, "faucet_height", 0.13), 0.03, 0.3 * h)
    bdz = _clamp(_get(p, "basin_depth", 0.15), 0.04, 0.4 * h)
    rz = h - fhgt
    zb = rz - bdz
    back = min(0.08, 0.3 * d)
    if shape == "round":
        prof = [(0, 0), (0.6, 0), (0.95, 0.75), (1.0, 1.0), (0.88, 1.0), (0.55, 0.25), (0, 0.2)]
        b.add("basin", "ceramic", _rev(prof, 0, back * 0.3, zb, w / 2, d / 2 - back * 0.3, bdz, sections=48),
              color=col)
        b.add("deck", "ceramic", _box(-min(0.12, 0.3 * w), min(0.12, 0.3 * w), -d / 2, -d / 2 + back,
                                      rz - 0.03, rz), color=col)
    else:
        s = min(0.035, 0.1 * w)
        b.add("basin", "ceramic", _cat([
            _box(-w / 2, w / 2, -d / 2, d / 2, zb, zb + 0.3 * bdz),
            _box(-w / 2, -w / 2 + s, -d / 2, d / 2, zb, rz),
            _box(w / 2 - s, w / 2, -d / 2, d / 2, zb, rz),
            _box(-w / 2, w / 2, -d / 2, -d / 2 + back, zb, rz),
            _box(-w / 2, w / 2, d / 2 - s, d / 2, zb, rz),
        ]), color=col)
        b.add("drain", "metal", _cyl(0, (back - s) / 2, zb + 0.3 * bdz, zb + 0.3 * bdz + 0.002, 0.02, sections=24))
    fy = -d / 2 + back / 2
    spout = min(0.12, 0.35 * d)
    b.add("faucet", "metal", _cat([
        _cyl(0, fy, rz - 0.005, h - 0.02, 0.016, sections=16),
        _rod((0, fy, h - 0.035), (0, fy + spout, h - 0.035), 0.012),
        _box(-0.008, 0.008, fy - 0.01, fy + 0.04, h - 0.02, h),
    ]))
    if style == "vanity":
        mat = _get(p, "cabinet_material", "wood_light")
        if mat not in MATERIALS:
            mat = "wood_light"
        mcol = _get(p, "cabinet_color", _PAINT[0]) if mat in ("painted", "metal", "plastic") else None
        _casework(b, "vanity_", -w / 2 + 0.01, w / 2 - 0.01, -d / 2, d / 2 - 0.01, 0.0, zb,
                  [("doors", 2 if w > 0.5 else 1, 1)], mat, mcol, handle=_get(p, "handle", "bar"), kick=0.05)
    else:
        b.add("pedestal", "ceramic", _rev([(0, 0), (1.0, 0), (0.7, 0.6), (0.8, 1.0), (0, 1.0)], 0, -0.15 * d, 0,
                                          min(0.11, 0.25 * w), min(0.11, 0.3 * d), zb + 0.01, sections=32),
              color=col)


# ----------------------------------------------------------------------------------------------
# lights


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
    b.add("shade", "lamp_shade", _rev(prof, 0, 0, z0, w / 2, d / 2, z1 - z0, sections=48), emissive=True, color=col)


def _gen_floor_lamp(b, w, d, h, p):
    mat = _get(p, "material", "metal")
    if mat not in MATERIALS:
        mat = "metal"
    col = _get(p, "color", _DARK) if mat in ("metal", "painted") else None
    shade_style = _get(p, "shade_style", "drum")
    scol = _get(p, "shade_color", _SHADE[0])
    sh = _clamp(_get(p, "shade_height", 0.3), 0.05, 0.45 * h)
    base = _get(p, "base", "disc")
    pr = _clamp(_get(p, "pole_radius", 0.012), 0.004, 0.05 * min(w, d))
    tr = _clamp(_get(p, "shade_top_ratio", 0.7), 0.3, 1.0)
    zs0 = h - sh
    _shade(b, w, d, zs0, h, shade_style, scol, tr)
    if base == "tripod":
        zj = 0.4 * h
        for i in range(3):
            a = math.pi / 2 + i * 2 * math.pi / 3
            b.add(f"leg_{i}", mat, _rod((math.cos(a) * (w / 2 - 0.02), math.sin(a) * (d / 2 - 0.02), 0.0),
                                        (0, 0, zj), pr * 1.2), color=col)
        b.add("pole", mat, _cyl(0, 0, zj, zs0 + 0.5 * sh, pr, sections=16), color=col)
    else:
        rb = _clamp(_get(p, "base_radius", 0.14), 0.03, 0.5 * min(w, d))
        bh = min(0.025, 0.05 * h)
        b.add("base", mat, _cyl(0, 0, 0, bh, rb, sections=48), color=col)
        b.add("pole", mat, _cyl(0, 0, bh, zs0 + 0.5 * sh, pr, sections=16), color=col)
    b.add("bulb", "diffuser", _ell((0, 0, zs0 + 0.45 * sh), (0.03, 0.03, 0.04), subdiv=1), emissive=True,
          color=(1.0, 0.95, 0.85))


def _gen_table_lamp(b, w, d, h, p):
    bmat = _get(p, "base_material", "ceramic")
    if bmat not in MATERIALS:
        bmat = "ceramic"
    bcol = _get(p, "base_color", _CERAMIC[0])
    bstyle = _get(p, "base_style", "gourd")
    shade_style = _get(p, "shade_style", "cone")
    scol = _get(p, "shade_color", _SHADE[0])
    sh = _clamp(_get(p, "shade_height", 0.4 * h), 0.03, 0.6 * h)
    tr = _clamp(_get(p, "shade_top_ratio", 0.7), 0.3, 1.0)
    bh = _clamp(_get(p, "base_height", 0.4 * h), 0.02, h - sh)
    br = _clamp(_get(p, "base_radius", 0.3 * min(w, d)), 0.01, 0.48 * min(w, d))
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
    b.add("base", bmat, _rev(prof, 0, 0, 0, br, br, bh, sections=40), color=bcol)
    b.add("stem", "metal", _cyl(0, 0, bh - 0.005, zs0 + 0.4 * sh, min(0.008, 0.2 * br), sections=16),
          color=(0.6, 0.55, 0.4))
    b.add("bulb", "diffuser", _ell((0, 0, zs0 + 0.4 * sh), (0.025, 0.025, 0.032), subdiv=1), emissive=True,
          color=(1.0, 0.95, 0.85))


def _gen_ceiling_light(b, w, d, h, p):
    shape = _get(p, "shape", "round")
    mat = _get(p, "rim_material", "metal")
    if mat not in MATERIALS:
        mat = "metal"
    rim = min(0.015, 0.08 * min(w, d))
    if shape == "square":
        b.add("diffuser", "diffuser", _box(-w / 2 + rim, w / 2 - rim, -d / 2 + rim, d / 2 - rim, 0, h),
              emissive=True, color=(1.0, 0.98, 0.92))
        zr = 0.35 * h
        b.add("rim", mat, _cat([
            _box(-w / 2, w / 2, -d / 2, -d / 2 + rim, zr, h), _box(-w / 2, w / 2, d / 2 - rim, d / 2, zr, h),
            _box(-w / 2, -w / 2 + rim, -d / 2, d / 2, zr, h), _box(w / 2 - rim, w / 2, -d / 2, d / 2, zr, h)]),
            color=(0.8, 0.8, 0.8))
    else:
        b.add("diffuser", "diffuser", _cyl(0, 0, 0, h, w / 2 - rim, d / 2 - rim, sections=64), emissive=True,
              color=(1.0, 0.98, 0.92))
        fr = 1.0 - rim / (w / 2)
        b.add("rim", mat, _rev([(fr, 0.0), (1.0, 0.0), (1.0, 1.0), (fr, 1.0), (fr, 0.0)], 0, 0, 0.35 * h, w / 2,
                               d / 2, 0.65 * h, sections=64), color=(0.8, 0.8, 0.8))


# ----------------------------------------------------------------------------------------------
# plants and small objects


def _pot(b, w, d, h, p, default_frac, default_hfrac):
    shape = _get(p, "pot_shape", "round")
    pcol = _get(p, "pot_color", _CERAMIC[0])
    pmat = _get(p, "pot_material", "ceramic")
    if pmat not in MATERIALS:
        pmat = "ceramic"
    frac = _clamp(_get(p, "pot_width_frac", default_frac), 0.2, 1.0)
    ph = _clamp(_get(p, "pot_height_frac", default_hfrac), 0.1, 0.8) * h
    rx, ry = frac * w / 2, frac * d / 2
    soil = ph - min(0.03, 0.1 * ph)
    if shape == "square":
        s = 0.08 * min(rx, ry)
        b.add("pot", pmat, _cat([
            _box(-rx, rx, -ry, ry, 0, soil),
            _box(-rx, -rx + s, -ry, ry, 0, ph), _box(rx - s, rx, -ry, ry, 0, ph),
            _box(-rx, rx, -ry, -ry + s, 0, ph), _box(-rx, rx, ry - s, ry, 0, ph)]), color=pcol)
        b.add("soil", "soil", _box(-rx + s, rx - s, -ry + s, ry - s, soil, soil + 0.003), color=(0.12, 0.08, 0.05))
    else:
        taper = 0.78 if shape == "round" else 1.0
        prof = [(0, 0), (taper, 0), (1.0, 1.0), (0.9, 1.0), (0.9 * (taper + (1 - taper) * soil / ph), soil / ph),
                (0, soil / ph)]
        b.add("pot", pmat, _rev(prof, 0, 0, 0, rx, ry, ph, sections=40), color=pcol)
        b.add("soil", "soil", _cyl(0, 0, soil, soil + 0.003, 0.9 * rx, 0.9 * ry, sections=40),
              color=(0.12, 0.08, 0.05))
    return soil


def _foliage(style, seed, n):
    """(name, material, mesh, colour_scale) pieces in unit coordinates; base at the origin."""
    rng = np.random.default_rng(seed)
    out = []
    if style == "spiky":
        for i in range(n):
            a = 2 * math.pi * i / n + rng.uniform(-0.3, 0.3)
            tilt = rng.uniform(0.08, 0.5)
            length = rng.uniform(0.6, 1.0)
            wd = rng.uniform(0.05, 0.09)
            m = _box(-wd / 2, wd / 2, -0.006, 0.006, 0, length)
            m = _transform(m, _rot(tilt, [1, 0, 0]))
            m = _transform(m, _rot(a + math.pi / 2, [0, 0, 1]))
            out.append((f"leaf_{i}", "leaf", m, rng.uniform(0.85, 1.15)))
    elif style in ("palm", "succulent"):
        if style == "palm":
            trunk_h = 0.55
            out.append(("trunk", "wood_dark", _rod((0, 0, 0), (0, 0, trunk_h), 0.025, sections=12), None))
            rings = [(n, 0.5, 0.1, 0.35)]
        else:
            trunk_h = 0.0
            rings = [(max(n, 5), 0.5, 0.12, 0.25), (max(n - 2, 4), 0.38, 0.1, 0.75), (max(n - 4, 3), 0.25, 0.08, 1.2)]
        k = 0
        for ring_i, (m_, length, wdt, elev) in enumerate(rings):
            for i in range(m_):
                a = 2 * math.pi * (i + 0.5 * ring_i) / m_ + rng.uniform(-0.2, 0.2)
                el = elev + rng.uniform(-0.15, 0.25)
                ln = length * rng.uniform(0.8, 1.1)
                m = _ell((ln / 2, 0, 0), (ln / 2, wdt * (1.0 if style == "palm" else 0.6), 0.015 if style == "palm"
                                          else 0.04), subdiv=2)
                m = _transform(m, _rot(-el, [0, 1, 0]))
                m = _transform(m, _rot(a, [0, 0, 1]))
                m = _mesh(m.vertices + np.array([0, 0, trunk_h]), m.faces)
                out.append((f"leaf_{k}", "leaf", m, rng.uniform(0.85, 1.15)))
                k += 1
    else:  # bush / tree
        trunk_h = 0.5 if style == "tree" else 0.0
        if style == "tree":
            out.append(("trunk", "wood_dark", _rod((0, 0, 0), (0, 0, trunk_h + 0.1), 0.03, sections=12), None))
        for i in range(n):
            a = rng.uniform(0, 2 * math.pi)
            s = rng.uniform(0.22, 0.34)
            r = rng.uniform(0.0, 0.5)
            if style == "tree":
                z = trunk_h + rng.uniform(0.1, 0.45)
            else:
                z = rng.uniform(s + 0.05, 0.9 - s * 0.5)
            c = (r * math.cos(a), r * math.sin(a), z)
            out.append((f"foliage_{i}", "leaf", _ell(c, (s, s, 0.85 * s), subdiv=2), rng.uniform(0.85, 1.15)))
            if style != "tree":
                out.append((f"stem_{i}", "leaf", _rod((0, 0, 0), c, 0.012, sections=8), 0.6))
    return out


def _plant(b, w, d, h, p, default_style, default_frac, default_hfrac, default_n):
    soil = _pot(b, w, d, h, p, default_frac, default_hfrac)
    style = _get(p, "style", default_style)
    seed = _get(p, "foliage_seed", 0)
    n = int(_clamp(_get(p, "n_clusters", default_n), 1, 30))
    lcol = _get(p, "leaf_color", _LEAF[0])
    pieces = _foliage(style, seed, n)
    meshes = _fit_meshes([m for _, _, m, _ in pieces], (-w / 2, -d / 2, soil), (w / 2, d / 2, h))
    for (name, mat, _, cs), m in zip(pieces, meshes):
        col = None if cs is None else tuple(float(min(1.0, c * cs)) for c in lcol)
        b.add(name, mat, m, color=col)


def _gen_plant(b, w, d, h, p):
    _plant(b, w, d, h, p, "bush", 0.55, 0.3, 7)


def _gen_small_plant(b, w, d, h, p):
    _plant(b, w, d, h, p, "succulent", 0.75, 0.45, 6)


def _gen_cushion(b, w, d, h, p):
    col = _get(p, "color", _FABRIC[0])
    style = _get(p, "style", "soft")
    b.add("cushion", "fabric", _soft_box(-w / 2, w / 2, -d / 2, d / 2, 0, h, e=0.35 if style == "soft" else 0.18),
          color=col)
    if style == "tufted":
        b.add("button", "fabric", _cyl(0, 0, h * 0.86, h * 0.97, min(0.015, 0.1 * w), sections=16),
              color=tuple(c * 0.7 for c in col))


def _gen_book(b, w, d, h, p):
    col = _get(p, "color", _BOOK[0])
    orient = _get(p, "orientation", "standing" if w <= h else "lying")
    page = (0.93, 0.91, 0.85)
    if orient == "standing":
        ct = min(0.003, 0.2 * w)
        b.add("cover", "book_cover", _cat([
            _box(-w / 2, -w / 2 + ct, -d / 2, d / 2, 0, h), _box(w / 2 - ct, w / 2, -d / 2, d / 2, 0, h),
            _box(-w / 2, w / 2, d / 2 - ct - 0.0005, d / 2 - 0.0005, 0, h)]), color=col)
        b.add("pages", "paper", _box(-w / 2 + ct, w / 2 - ct, -d / 2 + 0.003, d / 2 - ct, 0.003, h - 0.003),
              color=page)
        b.add("label", "paper", _box(-w / 2 + 0.25 * w, w / 2 - 0.25 * w, d / 2 - 0.0005, d / 2, 0.7 * h, 0.82 * h),
              color=(0.85, 0.8, 0.6))
    else:
        ct = min(0.003, 0.2 * h)
        b.add("cover", "book_cover", _cat([
            _box(-w / 2, w / 2, -d / 2, d / 2, 0, ct), _box(-w / 2, w / 2, -d / 2, d / 2, h - ct, h),
            _box(-w / 2, -w / 2 + ct, -d / 2, d / 2, 0, h)]), color=col)
        b.add("pages", "paper", _box(-w / 2 + ct, w / 2 - 0.003, -d / 2 + 0.003, d / 2 - 0.003, ct, h - ct),
              color=page)


def _gen_vase(b, w, d, h, p):
    mat = _get(p, "material", "ceramic")
    if mat not in MATERIALS:
        mat = "ceramic"
    col = _get(p, "color", _CERAMIC[2])
    style = _get(p, "style", "classic")
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
    b.add("body", mat, _rev(prof, 0, 0, 0, w / 2, d / 2, h, sections=40), color=col)
    if _get(p, "band", False):
        b.add("band", "metal", _rev([(0.95, 0.0), (1.0, 0.0), (1.0, 1.0), (0.95, 1.0), (0.95, 0.0)], 0, 0, 0.0,
                                    w / 2 * 0.6, d / 2 * 0.6, 0.02, sections=40), color=(0.7, 0.6, 0.3))


def _gen_bowl(b, w, d, h, p):
    mat = _get(p, "material", "ceramic")
    if mat not in MATERIALS:
        mat = "ceramic"
    col = _get(p, "color", _CERAMIC[0])
    prof = [(0, 0), (0.45, 0), (0.5, 0.1), (0.8, 0.4), (1.0, 1.0), (0.93, 1.0), (0.74, 0.45), (0.42, 0.2),
            (0, 0.17)]
    b.add("bowl", mat, _rev(prof, 0, 0, 0, w / 2, d / 2, h, sections=48), color=col)
    if _get(p, "fruit", False):
        rng = np.random.default_rng(_get(p, "fruit_seed", 0))
        fr = min(0.22 * w, 0.45 * h)
        fcols = ((0.6, 0.05, 0.03), (0.8, 0.45, 0.02), (0.5, 0.6, 0.05), (0.85, 0.7, 0.1))
        n = 3 + int(rng.integers(3))
        for i in range(n):
            a = 2 * math.pi * i / n + rng.uniform(-0.3, 0.3)
            rr = 0.3 * w / 2 if i else 0.0
            c = (rr * math.cos(a), rr * math.sin(a) * d / w, 0.17 * h + fr * 0.95)
            b.add(f"fruit_{i}", "plastic", _ell(c, (fr, fr, min(fr, 0.95 * (h - c[2]) if h > c[2] else fr)),
                                                 subdiv=2), color=fcols[int(rng.integers(len(fcols)))])


def _gen_picture(b, w, d, h, p):
    fmat = _get(p, "frame_material", "wood_dark")
    if fmat not in MATERIALS:
        fmat = "wood_dark"
    fcol = _get(p, "frame_color", _DARK) if fmat in ("painted", "metal") else None
    fw = _clamp(_get(p, "frame_width", 0.03), 0.0, 0.2 * min(w, h))
    ccol = _get(p, "canvas_color", (0.7, 0.65, 0.55))
    mat_border = _clamp(_get(p, "mat_width", 0.0), 0.0, 0.25 * min(w, h))
    seed = _get(p, "art_seed", 0)
    rec = min(0.006, 0.3 * d) if fw > 0 else min(0.0012, 0.1 * d)
    yc = d / 2 - rec
    if fw > 0:
        b.add("frame", fmat, _cat([
            _box(-w / 2, w / 2, -d / 2, d / 2, 0, fw), _box(-w / 2, w / 2, -d / 2, d / 2, h - fw, h),
            _box(-w / 2, -w / 2 + fw, -d / 2, d / 2, fw, h - fw), _box(w / 2 - fw, w / 2, -d / 2, d / 2, fw, h - fw)]),
            color=fcol)
    x0, x1, z0, z1 = -w / 2 + fw, w / 2 - fw, fw, h - fw
    if mat_border > 0:
        b.add("mat", "paper", _box(x0, x1, -d / 2, yc, z0, z1), color=(0.92, 0.91, 0.88))
        x0, x1, z0, z1 = x0 + mat_border, x1 - mat_border, z0 + mat_border, z1 - mat_border
        yc += 0.0005
    b.add("canvas", "canvas", _box(x0, x1, -d / 2, yc, z0, z1), color=ccol)
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
            m = _box(max(cx - sx, x0), min(cx + sx, x1), ya, yb, max(cz - sz, z0), min(cz + sz, z1))
        else:
            r = min(sx, sz, cx - x0, x1 - cx, cz - z0, z1 - cz)
            m = _ycyl(cx, cz, ya, yb, r, r, sections=32)
        b.add(f"art_{i}", "canvas", m, color=col)


def _gen_mirror(b, w, d, h, p):
    shape = _get(p, "shape", "rect")
    fmat = _get(p, "frame_material", "metal")
    if fmat not in MATERIALS:
        fmat = "metal"
    fcol = _get(p, "frame_color", (0.7, 0.6, 0.35)) if fmat in ("painted", "metal") else None
    fw = _clamp(_get(p, "frame_width", 0.03), 0.003, 0.2 * min(w, h))
    rec = min(0.004, 0.3 * d)
    if shape == "round":
        b.add("frame", fmat, _ycyl(0, h / 2, -d / 2, d / 2, w / 2, h / 2, sections=64,
                                   r_in=max(0.05, 1 - fw / (min(w, h) / 2))), color=fcol)
        b.add("pane", "mirror", _ycyl(0, h / 2, -d / 2, d / 2 - rec, w / 2 - fw + 0.002, h / 2 - fw + 0.002,
                                      sections=64))
        b.add("backing", "wood_dark", _ycyl(0, h / 2, -d / 2, -d / 2 + 0.004, w / 2 - fw + 0.003, h / 2 - fw + 0.003,
                                            sections=64))
    else:
        b.add("frame", fmat, _cat([
            _box(-w / 2, w / 2, -d / 2, d / 2, 0, fw), _box(-w / 2, w / 2, -d / 2, d / 2, h - fw, h),
            _box(-w / 2, -w / 2 + fw, -d / 2, d / 2, fw, h - fw), _box(w / 2 - fw, w / 2, -d / 2, d / 2, fw, h - fw)]),
            color=fcol)
        b.add("pane", "mirror", _box(-w / 2 + fw, w / 2 - fw, -d / 2, d / 2 - rec, fw, h - fw))


def _gen_bin(b, w, d, h, p):
    mat = _get(p, "material", "metal")
    if mat not in MATERIALS:
        mat = "metal"
    col = _get(p, "color", _PLASTIC[2])
    shape = _get(p, "shape", "round")
    lid = _get(p, "lid", False)
    lh = min(0.025, 0.1 * h) if lid else 0.0
    hb = h - lh
    if shape == "square":
        s = min(0.006, 0.05 * min(w, d))
        b.add("body", mat, _cat([
            _box(-w / 2, w / 2, -d / 2, d / 2, 0, 0.01), _box(-w / 2, -w / 2 + s, -d / 2, d / 2, 0, hb),
            _box(w / 2 - s, w / 2, -d / 2, d / 2, 0, hb), _box(-w / 2, w / 2, -d / 2, -d / 2 + s, 0, hb),
            _box(-w / 2, w / 2, d / 2 - s, d / 2, 0, hb)]), color=col)
        if lid:
            b.add("lid", mat, _box(-w / 2, w / 2, -d / 2, d / 2, hb, h), color=col)
    else:
        prof = [(0, 0), (0.9, 0), (1.0, 1.0), (0.95, 1.0), (0.86, 0.03), (0, 0.03)]
        b.add("body", mat, _rev(prof, 0, 0, 0, w / 2, d / 2, hb, sections=40), color=col)
        if lid:
            b.add("lid", mat, _rev([(0, 0), (1.0, 0), (0.95, 0.6), (0.4, 1.0), (0, 1.0)], 0, 0, hb, w / 2, d / 2, lh,
                                   sections=40), color=col)
    b.add("liner", "plastic", _rev([(0.0, 0.0), (0.6, 0.0), (0.6, 1.0), (0.0, 1.0)], 0, 0, 0.005,
                                   w / 2 * 0.8, d / 2 * 0.8, 0.01, sections=24), color=_DARK)


def _gen_basket(b, w, d, h, p):
    col = _get(p, "color", (0.55, 0.4, 0.22))
    shape = _get(p, "shape", "rect")
    mat = "wicker"
    rim_h = min(0.03, 0.12 * h)
    if shape == "round":
        prof = [(0, 0), (0.85, 0), (1.0, 1.0), (0.93, 1.0), (0.8, 0.05), (0, 0.05)]
        b.add("body", mat, _rev(prof, 0, 0, 0, w / 2 * 0.97, d / 2 * 0.97, h - rim_h * 0.5, sections=40), color=col)
        b.add("rim", mat, _rev([(0.9, 0.0), (1.0, 0.0), (1.0, 1.0), (0.9, 1.0), (0.9, 0.0)], 0, 0, h - rim_h, w / 2,
                               d / 2, rim_h, sections=40), color=tuple(c * 0.8 for c in col))
    else:
        s = min(0.012, 0.05 * min(w, d))
        i = 0.01
        b.add("body", mat, _cat([
            _box(-w / 2 + i, w / 2 - i, -d / 2 + i, d / 2 - i, 0, 0.015),
            _box(-w / 2 + i, -w / 2 + i + s, -d / 2 + i, d / 2 - i, 0, h - rim_h),
            _box(w / 2 - i - s, w / 2 - i, -d / 2 + i, d / 2 - i, 0, h - rim_h),
            _box(-w / 2 + i, w / 2 - i, -d / 2 + i, -d / 2 + i + s, 0, h - rim_h),
            _box(-w / 2 + i, w / 2 - i, d / 2 - i - s, d / 2 - i, 0, h - rim_h)]), color=col)
        r = s + i
        b.add("rim", mat, _cat([
            _box(-w / 2, w / 2, -d / 2, -d / 2 + r, h - rim_h, h), _box(-w / 2, w / 2, d / 2 - r, d / 2, h - rim_h, h),
            _box(-w / 2, -w / 2 + r, -d / 2, d / 2, h - rim_h, h), _box(w / 2 - r, w / 2, -d / 2, d / 2, h - rim_h, h)]),
            color=tuple(c * 0.8 for c in col))
    if _get(p, "liner", False):
        lcol = _get(p, "liner_color", _LINEN[1])
        if shape == "round":
            liner = _cyl(0, 0, 0.015, 0.3 * h, 0.83 * w / 2, 0.83 * d / 2, sections=40)
        else:
            liner = _box(-w / 2 + 0.03, w / 2 - 0.03, -d / 2 + 0.03, d / 2 - 0.03, 0.015, 0.3 * h)
        b.add("liner", "fabric", liner, color=lcol)


def _gen_laptop(b, w, d, h, p):
    mat = _get(p, "material", "metal")
    if mat not in ("metal", "plastic"):
        mat = "metal"
    col = _get(p, "color", (0.7, 0.7, 0.72))
    tilt = math.radians(_clamp(_get(p, "tilt_deg", 15.0), 0.0, 60.0))
    bt = _clamp(_get(p, "base_thickness", 0.018), 0.004, 0.3 * h)
    lt = _clamp(_get(p, "lid_thickness", 0.007), 0.002, 0.05)
    length = max((h - bt) / max(math.cos(tilt), 0.2), 0.01)
    back = length * math.sin(tilt) + lt * math.cos(tilt)
    db = _clamp(d - back, 0.4 * d, d)
    y0 = d / 2 - db  # back edge of the base = hinge line
    b.add("base", mat, _box(-w / 2, w / 2, y0, d / 2, 0, bt), color=col)
    kx = 0.9 * w / 2
    b.add("keyboard", "plastic", _box(-kx, kx, y0 + 0.1 * db, y0 + 0.55 * db, bt, bt + 0.0008), color=_DARK)
    b.add("touchpad", "plastic", _box(-0.18 * w, 0.18 * w, y0 + 0.62 * db, y0 + 0.92 * db, bt, bt + 0.0005),
          color=tuple(c * 0.85 for c in col))
    tf = _rot(tilt, [1, 0, 0])
    tf[:3, 3] = [0.0, y0, bt]
    lid = _box(-w / 2, w / 2, -lt, 0, 0, length)
    scr = _box(-w / 2 + 0.012, w / 2 - 0.012, 0, 0.0008, 0.012, length - 0.012)
    b.add("lid", mat, _transform(lid, tf), color=col)
    b.add("screen", "screen", _transform(scr, tf), color=(0.02, 0.03, 0.05))


def _gen_tv(b, w, d, h, p):
    col = _get(p, "color", _DARK)
    stand = _get(p, "stand", "center")
    pt = _clamp(_get(p, "panel_thickness", 0.045), 0.005, 0.6 * d)
    fh = _clamp(_get(p, "foot_height", 0.07), 0.0, 0.3 * h)
    bez = min(0.012, 0.05 * min(w, h))
    py1 = min(d / 2, pt / 2 + 0.01)
    py0 = py1 - pt
    b.add("panel", "plastic", _box(-w / 2, w / 2, py0, py1 - 0.0012, fh, h), color=col)
    b.add("screen", "screen", _box(-w / 2 + bez, w / 2 - bez, py1 - 0.0012, py1, fh + bez * 1.5, h - bez),
          color=(0.02, 0.025, 0.035))
    if fh > 0:
        if stand == "feet":
            for i, sx in enumerate((-1, 1)):
                x = sx * 0.38 * w
                b.add(f"foot_{i}", "metal", _cat([
                    _rod((x, -d / 2 + 0.01, 0.005), (x, py0 + pt / 2, fh + 0.02), 0.008, square=True),
                    _rod((x, d / 2 - 0.01, 0.005), (x, py0 + pt / 2, fh + 0.02), 0.008, square=True),
                    _box(x - 0.01, x + 0.01, -d / 2, d / 2, 0, 0.01)]), color=(0.25, 0.25, 0.27))
        else:
            bw = min(0.3 * w, 0.4)
            b.add("foot", "metal", _box(-bw / 2, bw / 2, -d / 2, d / 2, 0, 0.012), color=(0.25, 0.25, 0.27))
            b.add("neck", "metal", _box(-0.04, 0.04, py0 - 0.015, py0 + 0.005, 0.012, fh + 0.15 * (h - fh)),
                  color=(0.25, 0.25, 0.27))


def _gen_other(b, w, d, h, p):
    mat = _get(p, "material", "painted")
    if mat not in MATERIALS:
        mat = "painted"
    b.add("box", mat, _box(-w / 2, w / 2, -d / 2, d / 2, 0, h), color=_get(p, "color", _PAINT[2]))


_GENERATORS: dict[str, Callable] = {
    "sofa": _gen_sofa,
    "armchair": _gen_armchair,
    "chair": _gen_chair,
    "stool": _gen_stool,
    "dining_table": _gen_dining_table,
    "coffee_table": _gen_coffee_table,
    "side_table": _gen_side_table,
    "desk": _gen_desk,
    "bed": _gen_bed,
    "nightstand": _gen_nightstand,
    "wardrobe": _gen_wardrobe,
    "bookshelf": _gen_bookshelf,
    "cabinet": _gen_cabinet,
    "tv_stand": _gen_tv_stand,
    "tv": _gen_tv,
    "kitchen_counter": _gen_kitchen_counter,
    "fridge": _gen_fridge,
    "stove": _gen_stove,
    "toilet": _gen_toilet,
    "bathtub": _gen_bathtub,
    "washbasin": _gen_washbasin,
    "floor_lamp": _gen_floor_lamp,
    "table_lamp": _gen_table_lamp,
    "plant": _gen_plant,
    "cushion": _gen_cushion,
    "book": _gen_book,
    "vase": _gen_vase,
    "bowl": _gen_bowl,
    "picture": _gen_picture,
    "mirror": _gen_mirror,
    "bin": _gen_bin,
    "shoe_rack": _gen_shoe_rack,
    "bench": _gen_bench,
    "laptop": _gen_laptop,
    "ceiling_light": _gen_ceiling_light,
    "small_plant": _gen_small_plant,
    "basket": _gen_basket,
    "other": _gen_other,
}

# classes whose surfaces are not meant for placing things on
_NO_SURFACES = frozenset({
    "tv", "stove", "bathtub", "washbasin", "floor_lamp", "table_lamp", "ceiling_light", "plant", "small_plant",
    "cushion", "book", "vase", "bowl", "picture", "mirror", "bin", "basket", "laptop", "other",
})


# ----------------------------------------------------------------------------------------------
# sampling


class _S:
    """rng helpers producing plain Python values."""

    def __init__(self, rng: np.random.Generator):
        self.rng = rng

    def u(self, a, b, nd=3):
        return round(float(self.rng.uniform(a, b)), nd)

    def j(self, base, frac=0.15, nd=3):
        return round(float(base * self.rng.uniform(1 - frac, 1 + frac)), nd)

    def c(self, options, probs=None):
        if probs is not None:
            probs = np.asarray(probs, dtype=float)
            probs = probs / probs.sum()
        return options[int(self.rng.choice(len(options), p=probs))]

    def i(self, lo, hi):  # inclusive
        return int(self.rng.integers(lo, hi + 1))

    def b(self, prob=0.5):
        return bool(self.rng.random() < prob)

    def col(self, palette, jitter=0.04):
        base = np.asarray(self.c(palette), dtype=float)
        return [round(float(v), 3) for v in np.clip(base + self.rng.uniform(-jitter, jitter, 3), 0.0, 1.0)]

    def seed(self):
        return int(self.rng.integers(0, 2 ** 31 - 1))


def _frame_params(s: _S, p: dict, key="frame_material", color_key="frame_color",
                  options=("wood_light", "wood_dark", "metal", "painted"), probs=None):
    p[key] = s.c(list(options), probs)
    if p[key] in ("painted", "metal"):
        p[color_key] = s.col(_PAINT if p[key] == "painted" else ((0.08, 0.08, 0.09), (0.6, 0.6, 0.62)))


def _smp_chair(s):
    p = {}
    _frame_params(s, p, probs=[0.35, 0.3, 0.15, 0.2])
    p["seat_material"] = s.c(["wood", "fabric", "leather"], [0.45, 0.4, 0.15])
    if p["seat_material"] != "wood":
        p["seat_color"] = s.col(_FABRIC if p["seat_material"] == "fabric" else _LEATHER)
    p["leg_style"] = s.c(["square", "round", "tapered"], [0.45, 0.35, 0.2])
    p["leg_thickness"] = s.u(0.018, 0.026) if p["frame_material"] == "metal" else s.u(0.028, 0.045)
    p["seat_height"] = s.u(0.43, 0.48)
    p["seat_thickness"] = s.u(0.03, 0.06)
    p["back_style"] = s.c(["solid", "slats", "rails"])
    p["n_slats"] = s.i(3, 5)
    p["armrests"] = s.b(0.2)
    p["stretchers"] = s.b(0.35)
    w = s.j(0.45, 0.12) + (0.08 if p["armrests"] else 0.0)
    return (round(w, 3), s.j(0.5, 0.12), s.j(0.86, 0.1)), p


def _smp_stool(s):
    p = {}
    p["material"] = s.c(["wood_light", "wood_dark", "metal", "painted"])
    if p["material"] in ("metal", "painted"):
        p["color"] = s.col(_PAINT)
    p["seat_material"] = s.c(["wood", "fabric", "leather"], [0.6, 0.25, 0.15])
    if p["seat_material"] != "wood":
        p["seat_color"] = s.col(_FABRIC if p["seat_material"] == "fabric" else _LEATHER)
    p["seat_shape"] = s.c(["round", "square"], [0.65, 0.35])
    p["n_legs"] = 4 if p["seat_shape"] == "square" else s.c([3, 4])
    p["leg_style"] = s.c(["round", "square"])
    p["leg_thickness"] = s.u(0.022, 0.035)
    p["seat_thickness"] = s.u(0.03, 0.05)
    h = s.c([s.j(0.46, 0.08), s.j(0.65, 0.1), s.j(0.76, 0.06)])
    p["footrest"] = bool(h > 0.58 and s.b(0.8))
    w = s.j(0.38, 0.15)
    d = w if p["seat_shape"] == "round" else s.j(w, 0.08)
    return (w, d, h), p


def _smp_upholstered(s, sofa):
    p = {}
    p["material"] = s.c(["fabric", "leather"], [0.75, 0.25])
    p["color"] = s.col(_FABRIC if p["material"] == "fabric" else _LEATHER)
    p["leg_height"] = s.c([0.0, s.u(0.04, 0.16)], [0.25, 0.75])
    p["leg_material"] = s.c(["wood_dark", "wood_light", "metal"])
    p["arm_style"] = s.c(["box", "roll"], [0.7, 0.3])
    p["arm_width"] = s.u(0.1, 0.22) if sofa else s.u(0.1, 0.2)
    p["back_thickness"] = s.u(0.14, 0.24)
    p["seat_height"] = s.u(0.4, 0.47)
    p["cushion_thickness"] = s.u(0.1, 0.16)
    p["arm_height"] = s.u(0.55, 0.68)
    p["back_cushions"] = s.b(0.6)
    if sofa:
        p["n_seats"] = s.c([2, 3], [0.45, 0.55])
        w = round(p["n_seats"] * s.u(0.55, 0.72) + 2 * p["arm_width"], 3)
        return (w, s.j(0.9, 0.12), s.j(0.85, 0.1)), p
    p["n_seats"] = 1
    return (s.j(0.8, 0.15), s.j(0.82, 0.12), s.j(0.86, 0.12)), p


def _smp_bench(s):
    p = {"material": s.c(["wood_light", "wood_dark", "painted", "metal"], [0.4, 0.3, 0.2, 0.1])}
    if p["material"] in ("painted", "metal"):
        p["color"] = s.col(_PAINT)
    p["style"] = s.c(["legs", "panels"])
    p["leg_style"] = s.c(["square", "round", "tapered"])
    p["leg_thickness"] = s.u(0.035, 0.055)
    p["seat_thickness"] = s.u(0.03, 0.06)
    p["cushion"] = s.b(0.3)
    if p["cushion"]:
        p["cushion_color"] = s.col(_FABRIC)
    p["shelf"] = s.b(0.3)
    return (s.j(1.2, 0.25), s.j(0.4, 0.15), s.j(0.46, 0.08)), p


def _table_common(s, p, top_opts=("wood_light", "wood_dark", "painted", "glass", "marble"),
                  probs=(0.35, 0.3, 0.15, 0.1, 0.1)):
    p["top_material"] = s.c(list(top_opts), list(probs))
    if p["top_material"] in ("painted", "marble", "glass"):
        p["top_color"] = s.col(_PAINT if p["top_material"] == "painted" else
                               (_MARBLE if p["top_material"] == "marble" else ((0.75, 0.85, 0.85),)), 0.02)
    if p["top_material"] in _WOODS:
        p["leg_material"] = s.c([p["top_material"], "metal"], [0.75, 0.25])
    else:
        p["leg_material"] = s.c(["metal", "wood_dark", "wood_light"])
    if p["leg_material"] == "metal":
        p["leg_color"] = s.col(((0.08, 0.08, 0.09), (0.6, 0.6, 0.62), (0.7, 0.55, 0.3)))
    p["leg_style"] = s.c(["square", "round", "tapered"])
    p["top_thickness"] = s.u(0.02, 0.05)


def _smp_dining_table(s):
    p = {}
    _table_common(s, p)
    p["top_shape"] = s.c(["rect", "round"], [0.75, 0.25])
    p["base"] = s.c(["legs4", "pedestal"], [0.8, 0.2] if p["top_shape"] == "rect" else [0.5, 0.5])
    p["leg_thickness"] = s.u(0.04, 0.07) if p["leg_material"] != "metal" else s.u(0.025, 0.045)
    p["leg_inset"] = s.u(0.02, 0.09)
    p["apron"] = s.b(0.5)
    p["apron_height"] = s.u(0.06, 0.1)
    h = s.u(0.72, 0.77)
    if p["top_shape"] == "round":
        w = s.j(1.05, 0.15)
        return (w, w, h), p
    return (s.j(1.6, 0.2), s.j(0.9, 0.12), h), p


def _smp_coffee_table(s):
    p = {}
    _table_common(s, p)
    p["top_shape"] = s.c(["rect", "round"], [0.75, 0.25])
    p["base"] = s.c(["legs4", "panels"], [0.7, 0.3]) if p["top_shape"] == "rect" else s.c(["legs4", "legs3",
                                                                                            "pedestal"])
    p["leg_thickness"] = s.u(0.03, 0.06)
    p["leg_inset"] = s.u(0.01, 0.06)
    p["shelf"] = s.b(0.4)
    p["shelf_height"] = s.u(0.08, 0.15)
    h = s.j(0.42, 0.12)
    if p["top_shape"] == "round":
        w = s.j(0.8, 0.15)
        return (w, w, h), p
    return (s.j(1.0, 0.25), s.j(0.55, 0.2), h), p


def _smp_side_table(s):
    p = {}
    _table_common(s, p)
    p["top_shape"] = s.c(["rect", "round"])
    p["base"] = s.c(["legs4", "legs3", "pedestal"], [0.5, 0.2, 0.3])
    p["leg_thickness"] = s.u(0.025, 0.045)
    p["leg_inset"] = s.u(0.01, 0.04)
    p["shelf"] = s.b(0.3)
    p["shelf_height"] = s.u(0.1, 0.2)
    w = s.j(0.5, 0.2)
    d = w if p["top_shape"] == "round" else s.j(w, 0.1)
    return (w, d, s.j(0.55, 0.15)), p


def _smp_desk(s):
    p = {}
    p["top_material"] = s.c(["wood_light", "wood_dark", "painted"], [0.4, 0.35, 0.25])
    if p["top_material"] == "painted":
        p["top_color"] = s.col(_PAINT)
    p["body_material"] = s.c([p["top_material"], "metal", "painted"], [0.6, 0.2, 0.2])
    if p["body_material"] in ("painted", "metal"):
        p["body_color"] = s.col(_PAINT)
    p["base"] = s.c(["drawers", "legs", "panels"], [0.45, 0.35, 0.2])
    p["drawer_side"] = s.c(["right", "left"], [0.7, 0.3])
    p["n_drawers"] = s.i(2, 4)
    p["leg_style"] = s.c(["square", "round"])
    p["leg_thickness"] = s.u(0.035, 0.055)
    p["top_thickness"] = s.u(0.022, 0.04)
    p["handle"] = s.c(["bar", "knob"])
    return (s.j(1.2, 0.2), s.j(0.62, 0.12), s.u(0.72, 0.77)), p


def _case_params(s, p, mats=("wood_light", "wood_dark", "painted"), probs=(0.4, 0.3, 0.3)):
    p["material"] = s.c(list(mats), list(probs))
    if p["material"] in ("painted", "metal", "plastic"):
        p["color"] = s.col(_PAINT, 0.02)
    p["handle"] = s.c(["bar", "knob", "none"], [0.55, 0.35, 0.1])


def _smp_nightstand(s):
    p = {}
    _case_params(s, p)
    p["n_drawers"] = s.i(1, 3)
    p["open_shelf"] = s.b(0.35)
    p["legs"] = s.b(0.6)
    p["leg_height"] = s.u(0.07, 0.16)
    return (s.j(0.46, 0.15), s.j(0.4, 0.12), s.j(0.55, 0.12)), p


def _smp_cabinet(s):
    p = {}
    _case_params(s, p)
    p["style"] = s.c(["doors", "drawers", "mixed", "open"])
    p["n_drawers"] = s.i(3, 4)
    p["base"] = s.c(["plinth", "legs", "none"], [0.45, 0.4, 0.15])
    p["leg_height"] = s.u(0.08, 0.18)
    p["plinth_height"] = s.u(0.05, 0.1)
    w = s.j(1.0, 0.25)
    p["n_doors"] = 1 if w < 0.6 else (3 if w > 1.3 else 2)
    return (w, s.j(0.45, 0.15), s.j(0.85, 0.2)), p


def _smp_tv_stand(s):
    p = {}
    _case_params(s, p, probs=(0.3, 0.4, 0.3))
    w = s.j(1.6, 0.2)
    n = 3 if w > 1.4 else 2
    p["modules"] = [s.c(["drawers", "open", "doors"]) for _ in range(n)]
    p["base"] = s.c(["legs", "plinth", "none"])
    p["leg_height"] = s.u(0.06, 0.15)
    p["plinth_height"] = s.u(0.04, 0.08)
    return (w, s.j(0.42, 0.12), s.j(0.5, 0.15)), p


def _smp_bookshelf(s):
    p = {}
    _case_params(s, p, probs=(0.45, 0.3, 0.25))
    p["n_boards"] = s.i(3, 5)
    p["board_thickness"] = s.u(0.016, 0.03)
    p["back"] = s.b(0.85)
    p["plinth_height"] = s.c([0.0, s.u(0.04, 0.09)])
    p["lower_doors"] = s.b(0.25)
    return (s.j(0.9, 0.25), s.j(0.32, 0.15), s.j(1.8, 0.2)), p


def _smp_wardrobe(s):
    p = {}
    _case_params(s, p, probs=(0.4, 0.3, 0.3))
    p["handle"] = s.c(["bar", "knob"], [0.7, 0.3])
    w = round(s.c([1.0, 1.2, 1.5, 1.8]) * s.u(0.92, 1.08), 3)
    p["n_doors"] = 2 if w < 1.4 else s.c([2, 3])
    p["drawers"] = s.b(0.35)
    p["cornice"] = s.b(0.5)
    p["mirror_door"] = s.b(0.2)
    p["plinth_height"] = s.u(0.04, 0.1)
    return (w, s.j(0.6, 0.08), s.u(1.9, 2.3)), p


def _smp_shoe_rack(s):
    p = {}
    _case_params(s, p, probs=(0.4, 0.3, 0.3))
    p["style"] = s.c(["boards", "bars"])
    p["n_levels"] = s.i(2, 3)
    return (s.j(0.8, 0.2), s.j(0.3, 0.12), s.j(0.5, 0.2)), p


def _smp_kitchen_counter(s):
    p = {}
    p["material"] = s.c(["painted", "wood_light", "wood_dark"], [0.6, 0.25, 0.15])
    if p["material"] == "painted":
        p["color"] = s.col(_PAINT, 0.02)
    p["worktop_material"] = s.c(["marble", "wood_light", "wood_dark"], [0.6, 0.25, 0.15])
    if p["worktop_material"] == "marble":
        p["worktop_color"] = s.col(_MARBLE, 0.02)
    p["worktop_thickness"] = s.u(0.028, 0.045)
    p["handle"] = s.c(["bar", "knob", "none"], [0.6, 0.2, 0.2])
    p["plinth_height"] = s.u(0.08, 0.13)
    w = round(s.c([1.2, 1.8, 2.4, 3.0]) * s.u(0.95, 1.05), 3)
    n = max(1, int(round(w / 0.6)))
    p["n_modules"] = n
    p["sink"] = s.b(0.6)
    p["sink_module"] = s.i(0, n - 1)
    p["sink_width"] = s.u(0.4, 0.52)
    p["module_styles"] = [s.c(["drawers", "mixed", "doors"]) for _ in range(n)]
    return (w, s.u(0.6, 0.65), s.u(0.88, 0.92)), p


def _smp_fridge(s):
    p = {"material": s.c(["metal", "painted"], [0.5, 0.5])}
    p["color"] = s.col(_APPLIANCE, 0.02)
    p["style"] = s.c(["bottom_freezer", "top_freezer", "single", "side_by_side"], [0.45, 0.3, 0.15, 0.1])
    w = s.j(0.9, 0.05) if p["style"] == "side_by_side" else s.j(0.6, 0.1)
    return (w, s.j(0.66, 0.08), s.u(1.7, 1.95)), p


def _smp_stove(s):
    p = {"material": s.c(["metal", "painted"])}
    p["color"] = s.col(_APPLIANCE, 0.02)
    p["burner_type"] = s.c(["gas", "induction"])
    return (round(s.c([0.5, 0.6, 0.6, 0.9]) * s.u(0.98, 1.02), 3), s.u(0.58, 0.65), s.u(0.85, 0.92)), p


def _smp_bed(s):
    p = {}
    p["material"] = s.c(["wood_light", "wood_dark", "painted"], [0.4, 0.35, 0.25])
    if p["material"] == "painted":
        p["color"] = s.col(_PAINT)
    p["headboard_style"] = s.c(["panel", "upholstered", "slats"])
    p["headboard_color"] = s.col(_FABRIC)
    p["leg_height"] = s.c([0.0, s.u(0.05, 0.16)])
    p["frame_height"] = s.u(0.26, 0.4)
    p["mattress_thickness"] = s.u(0.18, 0.26)
    p["headboard_thickness"] = s.u(0.04, 0.1)
    p["footboard"] = s.b(0.3)
    p["footboard_height"] = s.u(0.0, 0.15)
    p["mattress_color"] = s.col(_LINEN, 0.02)
    p["duvet"] = s.b(0.75)
    p["duvet_color"] = s.col(_FABRIC + _LINEN)
    w = round(s.c([0.9, 1.4, 1.6, 1.8]) + s.u(0.04, 0.12), 3)
    return (w, s.u(2.02, 2.2), s.u(0.75, 1.25)), p


def _smp_toilet(s):
    p = {"color": s.col((_WHITE,), 0.02), "lid": s.b(0.6)}
    p["seat_color"] = p["color"] if s.b(0.8) else s.col(((0.1, 0.1, 0.1), (0.5, 0.35, 0.2)))
    p["tank_depth"] = s.u(0.14, 0.2)
    p["seat_height"] = s.u(0.4, 0.44)
    return (s.j(0.38, 0.1), s.j(0.66, 0.08), s.j(0.78, 0.08)), p


def _smp_bathtub(s):
    p = {"color": s.col((_WHITE,), 0.02), "style": s.c(["built_in", "feet"], [0.7, 0.3])}
    p["rim_width"] = s.u(0.05, 0.09)
    p["tap"] = s.b(0.7)
    p["feet_height"] = s.u(0.08, 0.14)
    return (s.j(1.7, 0.1), s.j(0.75, 0.1), s.j(0.6, 0.1)), p


def _smp_washbasin(s):
    p = {"color": s.col((_WHITE,), 0.02), "style": s.c(["pedestal", "vanity"])}
    p["basin_shape"] = s.c(["rect", "round"])
    p["faucet_height"] = s.u(0.1, 0.16)
    p["basin_depth"] = s.u(0.12, 0.17)
    if p["style"] == "vanity":
        q = {}
        _case_params(s, q)
        p["cabinet_material"] = q["material"]
        if "color" in q:
            p["cabinet_color"] = q["color"]
        p["handle"] = q["handle"]
    return (s.j(0.6, 0.2), s.j(0.46, 0.12), s.u(0.92, 1.02)), p


def _smp_floor_lamp(s):
    p = {"material": s.c(["metal", "wood_dark", "wood_light"], [0.6, 0.2, 0.2])}
    if p["material"] == "metal":
        p["color"] = s.col(((0.08, 0.08, 0.09), (0.7, 0.6, 0.35), (0.8, 0.8, 0.8)))
    p["shade_style"] = s.c(["drum", "cone", "dome"])
    p["shade_color"] = s.col(_SHADE, 0.02)
    p["shade_height"] = s.u(0.22, 0.38)
    p["shade_top_ratio"] = s.u(0.5, 0.8)
    p["base"] = s.c(["disc", "tripod"], [0.65, 0.35])
    p["pole_radius"] = s.u(0.009, 0.016)
    w = s.j(0.42, 0.2)
    p["base_radius"] = round(s.u(0.5, 0.8) * w / 2, 3)
    return (w, w, s.j(1.6, 0.12)), p


def _smp_table_lamp(s):
    p = {"base_material": s.c(["ceramic", "metal", "glass", "wood_light"], [0.5, 0.25, 0.15, 0.1])}
    p["base_color"] = s.col(_CERAMIC)
    p["base_style"] = s.c(["gourd", "ball", "cylinder", "cone"])
    p["shade_style"] = s.c(["drum", "cone"])
    p["shade_color"] = s.col(_SHADE, 0.02)
    p["shade_top_ratio"] = s.u(0.55, 0.85)
    w = s.j(0.3, 0.2)
    h = s.j(0.48, 0.2)
    p["shade_height"] = round(s.u(0.35, 0.45) * h, 3)
    p["base_height"] = round(s.u(0.3, 0.45) * h, 3)
    p["base_radius"] = round(s.u(0.25, 0.38) * w, 3)
    return (w, w, h), p


def _smp_ceiling_light(s):
    p = {"shape": s.c(["round", "square"], [0.7, 0.3]), "rim_material": s.c(["metal", "painted"])}
    w = s.j(0.4, 0.25)
    return (w, w if p["shape"] == "round" else s.j(w, 0.05), s.j(0.08, 0.25)), p


def _smp_plant(s, small=False):
    p = {}
    p["pot_shape"] = s.c(["round", "cylinder", "square"], [0.5, 0.3, 0.2])
    p["pot_material"] = s.c(["ceramic", "plastic", "wicker"], [0.7, 0.2, 0.1])
    p["pot_color"] = s.col(_CERAMIC if p["pot_material"] != "wicker" else ((0.55, 0.4, 0.22),))
    p["leaf_color"] = s.col(_LEAF, 0.03)
    p["foliage_seed"] = s.seed()
    if small:
        p["style"] = s.c(["succulent", "bush", "spiky"])
        p["pot_width_frac"] = s.u(0.6, 0.9)
        p["pot_height_frac"] = s.u(0.35, 0.55)
        p["n_clusters"] = s.i(5, 9)
        w = s.j(0.18, 0.25)
        return (w, s.j(w, 0.05), s.j(0.3, 0.25)), p
    p["style"] = s.c(["bush", "tree", "spiky", "palm"])
    p["pot_width_frac"] = s.u(0.45, 0.7)
    p["pot_height_frac"] = s.u(0.22, 0.38)
    p["n_clusters"] = s.i(6, 12) if p["style"] != "spiky" else s.i(9, 16)
    w = s.j(0.48, 0.25)
    return (w, s.j(w, 0.08), s.j(1.1, 0.25)), p


def _smp_cushion(s):
    p = {"color": s.col(_FABRIC + _LINEN), "style": s.c(["soft", "firm", "tufted"], [0.6, 0.25, 0.15])}
    w = s.j(0.45, 0.15)
    return (w, s.j(w, 0.08), s.j(0.13, 0.2)), p


def _smp_book(s):
    p = {"color": s.col(_BOOK), "orientation": s.c(["standing", "lying"], [0.6, 0.4])}
    t, pw, ph = s.u(0.015, 0.05), s.u(0.13, 0.22), s.u(0.18, 0.3)
    if p["orientation"] == "standing":
        return (t, pw, ph), p
    return (pw, ph, t), p


def _smp_vase(s):
    p = {"material": s.c(["ceramic", "glass"], [0.75, 0.25]), "style": s.c(["classic", "cylinder", "bottle", "bulb"])}
    p["color"] = s.col(_CERAMIC) if p["material"] == "ceramic" else s.col(((0.6, 0.75, 0.75), (0.3, 0.5, 0.4)))
    p["band"] = s.b(0.2)
    w = s.j(0.15, 0.25)
    return (w, w, s.j(0.3, 0.25)), p


def _smp_bowl(s):
    p = {"material": s.c(["ceramic", "wood_light", "glass", "metal"], [0.55, 0.2, 0.15, 0.1])}
    p["color"] = s.col(_CERAMIC)
    p["fruit"] = s.b(0.35)
    p["fruit_seed"] = s.seed()
    w = s.j(0.25, 0.2)
    return (w, w, s.j(0.09, 0.2)), p


def _smp_picture(s):
    p = {"frame_material": s.c(["wood_dark", "wood_light", "metal", "painted"])}
    if p["frame_material"] in ("metal", "painted"):
        p["frame_color"] = s.col(_PAINT)
    p["frame_width"] = s.c([0.0, s.u(0.015, 0.06)], [0.2, 0.8])
    p["mat_width"] = s.c([0.0, s.u(0.03, 0.08)], [0.6, 0.4])
    p["canvas_color"] = s.col(_FABRIC + _LINEN)
    p["art_seed"] = s.seed()
    a, b_ = s.j(0.7, 0.3), s.j(0.5, 0.3)
    if s.b(0.35):
        a, b_ = b_, a
    return (a, s.u(0.02, 0.04), b_), p


def _smp_mirror(s):
    p = {"shape": s.c(["rect", "round"], [0.7, 0.3]), "frame_material": s.c(["metal", "wood_dark", "painted"])}
    if p["frame_material"] != "wood_dark":
        p["frame_color"] = s.col(((0.7, 0.6, 0.35), (0.08, 0.08, 0.09), (0.85, 0.85, 0.83)))
    p["frame_width"] = s.u(0.015, 0.05)
    if p["shape"] == "round":
        w = s.j(0.65, 0.2)
        return (w, s.u(0.02, 0.04), w), p
    return (s.j(0.6, 0.2), s.u(0.02, 0.04), s.j(0.9, 0.25)), p


def _smp_bin(s):
    p = {"material": s.c(["metal", "plastic"]), "shape": s.c(["round", "square"], [0.65, 0.35])}
    p["color"] = s.col(_PLASTIC + ((0.7, 0.7, 0.72),))
    p["lid"] = s.b(0.4)
    w = s.j(0.3, 0.15)
    return (w, w if p["shape"] == "round" else s.j(w, 0.15), s.j(0.4, 0.15)), p


def _smp_basket(s):
    p = {"shape": s.c(["rect", "round"]), "color": s.col(((0.55, 0.4, 0.22), (0.35, 0.25, 0.15), (0.75, 0.65, 0.45)))}
    p["liner"] = s.b(0.3)
    p["liner_color"] = s.col(_LINEN + _FABRIC)
    w = s.j(0.4, 0.2)
    return (w, w if p["shape"] == "round" else s.j(0.3, 0.2), s.j(0.3, 0.2)), p


def _smp_laptop(s):
    p = {"material": s.c(["metal", "plastic"], [0.6, 0.4])}
    p["color"] = s.col(((0.7, 0.7, 0.72), (0.2, 0.2, 0.22), (0.1, 0.1, 0.1)), 0.02)
    p["tilt_deg"] = s.u(8.0, 25.0, 1)
    p["base_thickness"] = s.u(0.014, 0.022)
    p["lid_thickness"] = s.u(0.005, 0.009)
    return (s.j(0.33, 0.1), s.j(0.25, 0.08), s.j(0.22, 0.08)), p


def _smp_tv(s):
    p = {"color": s.col(((0.03, 0.03, 0.035), (0.15, 0.15, 0.16)), 0.01), "stand": s.c(["center", "feet"])}
    p["panel_thickness"] = s.u(0.03, 0.06)
    p["foot_height"] = s.u(0.04, 0.1)
    w = s.j(1.2, 0.25)
    return (w, s.u(0.12, 0.25), round(w * 9 / 16 + 0.03 + p["foot_height"], 3)), p


def _smp_other(s):
    p = {"color": s.col(_PAINT + _PLASTIC)}
    return (s.j(0.4, 0.3), s.j(0.4, 0.3), s.j(0.4, 0.3)), p


_SAMPLERS: dict[str, Callable] = {
    "sofa": lambda s: _smp_upholstered(s, True),
    "armchair": lambda s: _smp_upholstered(s, False),
    "chair": _smp_chair,
    "stool": _smp_stool,
    "dining_table": _smp_dining_table,
    "coffee_table": _smp_coffee_table,
    "side_table": _smp_side_table,
    "desk": _smp_desk,
    "bed": _smp_bed,
    "nightstand": _smp_nightstand,
    "wardrobe": _smp_wardrobe,
    "bookshelf": _smp_bookshelf,
    "cabinet": _smp_cabinet,
    "tv_stand": _smp_tv_stand,
    "tv": _smp_tv,
    "kitchen_counter": _smp_kitchen_counter,
    "fridge": _smp_fridge,
    "stove": _smp_stove,
    "toilet": _smp_toilet,
    "bathtub": _smp_bathtub,
    "washbasin": _smp_washbasin,
    "floor_lamp": _smp_floor_lamp,
    "table_lamp": _smp_table_lamp,
    "plant": lambda s: _smp_plant(s, False),
    "cushion": _smp_cushion,
    "book": _smp_book,
    "vase": _smp_vase,
    "bowl": _smp_bowl,
    "picture": _smp_picture,
    "mirror": _smp_mirror,
    "bin": _smp_bin,
    "shoe_rack": _smp_shoe_rack,
    "bench": _smp_bench,
    "laptop": _smp_laptop,
    "ceiling_light": _smp_ceiling_light,
    "small_plant": lambda s: _smp_plant(s, True),
    "basket": _smp_basket,
    "other": _smp_other,
}


# ----------------------------------------------------------------------------------------------
# public API


def known_classes() -> list[str]:
    """Classes with a mesh generator (every non-structure class of scenes/classes.yaml)."""
    return list(_GENERATORS)


def _check_cls(cls: str) -> None:
    if cls not in _GENERATORS:
        raise UnknownClassError(f"unknown object class {cls!r}: no mesh generator")


def _check_size(size) -> tuple[float, float, float]:
    try:
        w, d, h = (float(v) for v in size)
    except (TypeError, ValueError) as e:
        raise ValueError(f"size must be three numbers (w, d, h), got {size!r}") from e
    if not all(math.isfinite(v) and v > 0 for v in (w, d, h)):
        raise ValueError(f"size must be positive and finite, got {size!r}")
    return w, d, h


def _build(cls: str, size, params) -> tuple[list[Part], list[Surface]]:
    _check_cls(cls)
    w, d, h = _check_size(size)
    b = _Builder()
    _GENERATORS[cls](b, w, d, h, dict(params or {}))
    return _finish(b, w, d, h)


def sample_params(cls: str, rng: np.random.Generator) -> tuple[tuple[float, float, float], dict]:
    """Realistic size (w, d, h) in metres and style params (plain YAML-able values) for one instance."""
    _check_cls(cls)
    size, params = _SAMPLERS[cls](_S(rng))
    return tuple(float(v) for v in size), params


def make_parts(cls: str, size, params: dict) -> list[Part]:
    """Named, material-tagged parts of one object; their union fills [-w/2,w/2]x[-d/2,d/2]x[0,h] exactly."""
    return _build(cls, size, params)[0]


def make_mesh(cls: str, size, params: dict) -> trimesh.Trimesh:
    """All parts of make_parts concatenated into one mesh."""
    return _cat([p.mesh for p in make_parts(cls, size, params)])


def support_surfaces(cls: str, size, params: dict) -> list[Surface]:
    """Rectangles in the object's local frame where small objects can be placed ([] for none)."""
    _check_cls(cls)
    if cls in _NO_SURFACES:
        _check_size(size)
        return []
    return _build(cls, size, params)[1]
