"""Mesh primitives, the part conventions and the ``Builder`` that every generator fills.

Every generator builds an object from simple primitives (boxes, cylinders, surfaces of revolution,
icospheres) in the object's local frame:

* metres; z up; origin at the centre of the bottom face of the object's bounding box;
* x = width, y = depth, z = height; the object's FRONT faces local +y (backrests, headboards, the
  back of pictures and mirrors are at -y; screens and doors face +y);
* for a size (w, d, h) the union of all parts has axis-aligned bounds exactly
  [-w/2, w/2] x [-d/2, d/2] x [0, h].  Generators lay out their parts to fill that box; a final
  per-axis affine fit (``Builder.finish``, close to the identity for every generator) removes the
  remaining millimetre slack, so the bounds hold exactly for any size.

A part is named (``Builder.add`` numbers repeated names), tagged with one of ``materials.MATERIALS``,
optionally emissive and coloured.  ``param`` reads a generator's parameter with a typed default, so a
missing or junk value falls back to it.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import trimesh

from .materials import MATERIALS
from .surfaces import Surface

INF = float("inf")
MIN_THICKNESS = 1e-4  # thinnest slab a primitive gets


@dataclass(frozen=True)
class Part:
    """One named, material-tagged mesh of an object, in the object's local frame."""

    name: str
    material: str
    mesh: trimesh.Trimesh
    emissive: bool = False
    color: tuple[float, float, float] | None = None


# ----------------------------------------------------------------------------------------------
# parameter access


def param(p: dict, key: str, default):
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


def clamp(v: float, lo: float, hi: float) -> float:
    if hi < lo:
        return lo
    return min(max(v, lo), hi)


def _col(c) -> tuple[float, float, float] | None:
    if c is None:
        return None
    return tuple(float(min(max(v, 0.0), 1.0)) for v in c[:3])


# ----------------------------------------------------------------------------------------------
# primitives (all return fresh trimesh.Trimesh objects)


def mesh_from(v, f) -> trimesh.Trimesh:
    return trimesh.Trimesh(np.asarray(v, dtype=np.float64), np.asarray(f, dtype=np.int64), process=False)


def box(x0, x1, y0, y1, z0, z1) -> trimesh.Trimesh:
    lo = np.array([min(x0, x1), min(y0, y1), min(z0, z1)], dtype=np.float64)
    hi = np.array([max(x0, x1), max(y0, y1), max(z0, z1)], dtype=np.float64)
    hi = np.maximum(hi, lo + MIN_THICKNESS)
    m = trimesh.creation.box(bounds=np.array([lo, hi]))
    return mesh_from(m.vertices, m.faces)


def cylinder(cx, cy, z0, z1, rx, ry=None, sections=32) -> trimesh.Trimesh:
    """Vertical (elliptic) cylinder."""
    ry = rx if ry is None else ry
    hgt = max(z1 - z0, MIN_THICKNESS)
    m = trimesh.creation.cylinder(radius=1.0, height=hgt, sections=sections)
    v = (m.vertices * np.array([max(rx, MIN_THICKNESS), max(ry, MIN_THICKNESS), 1.0])
         + np.array([cx, cy, z0 + hgt / 2.0]))
    return mesh_from(v, m.faces)


def rod(p0, p1, r, square=False, sections=12) -> trimesh.Trimesh:
    """Cylinder (or square bar) of radius / half-width r between points p0 and p1."""
    p0 = np.asarray(p0, dtype=np.float64)
    p1 = np.asarray(p1, dtype=np.float64)
    vec = p1 - p0
    length = float(np.linalg.norm(vec))
    if length < MIN_THICKNESS:
        vec = np.array([0.0, 0.0, 1.0])
        length = MIN_THICKNESS
    r = max(r, MIN_THICKNESS)
    if square:
        m = trimesh.creation.box(extents=[2 * r, 2 * r, length])
    else:
        m = trimesh.creation.cylinder(radius=r, height=length, sections=sections)
    tf = trimesh.geometry.align_vectors([0.0, 0.0, 1.0], vec / length)
    tf[:3, 3] = (p0 + p1) / 2.0
    v = trimesh.transform_points(m.vertices, tf)
    return mesh_from(v, m.faces)


def y_cylinder(cx, cz, y0, y1, rx, rz, sections=48, r_in=None) -> trimesh.Trimesh:
    """(Elliptic) cylinder or annulus (r_in as a fraction of the radius) whose axis runs along y."""
    y0, y1 = min(y0, y1), max(y0, y1)
    y1 = max(y1, y0 + MIN_THICKNESS)
    seg = [[0.0, y0, 0.0], [0.0, y1, 0.0]]
    if r_in is None:
        m = trimesh.creation.cylinder(radius=1.0, segment=seg, sections=sections)
    else:
        m = trimesh.creation.annulus(r_min=float(r_in), r_max=1.0, segment=seg, sections=sections)
    v = m.vertices * np.array([max(rx, MIN_THICKNESS), 1.0, max(rz, MIN_THICKNESS)]) + np.array([cx, 0.0, cz])
    return mesh_from(v, m.faces)


def revolve(profile, cx=0.0, cy=0.0, z0=0.0, sx=1.0, sy=1.0, sz=1.0, sections=48) -> trimesh.Trimesh:
    """Surface of revolution of a (r, z) profile (counter-clockwise, closed or ending on the axis),
    scaled by (sx, sy, sz) and moved to (cx, cy, z0)."""
    m = trimesh.creation.revolve(np.asarray(profile, dtype=np.float64), sections=sections)
    v = m.vertices * np.array([sx, sy, sz]) + np.array([cx, cy, z0])
    return mesh_from(v, m.faces)


def ellipsoid(center, radii, subdiv=2) -> trimesh.Trimesh:
    m = trimesh.creation.icosphere(subdivisions=subdiv, radius=1.0)
    v = (m.vertices * np.maximum(np.asarray(radii, dtype=np.float64), MIN_THICKNESS)
         + np.asarray(center, dtype=np.float64))
    return mesh_from(v, m.faces)


_SOFT_CACHE: dict[tuple[float, int], tuple[np.ndarray, np.ndarray]] = {}


def soft_box(x0, x1, y0, y1, z0, z1, e=0.3, subdiv=3) -> trimesh.Trimesh:
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
    hi = np.maximum(hi, lo + MIN_THICKNESS)
    return mesh_from((v + 1.0) / 2.0 * (hi - lo) + lo, f.copy())


def transform(m: trimesh.Trimesh, tf) -> trimesh.Trimesh:
    return mesh_from(trimesh.transform_points(m.vertices, np.asarray(tf)), m.faces)


def rotation(angle, axis, point=(0.0, 0.0, 0.0)):
    return trimesh.transformations.rotation_matrix(angle, axis, point)


def concat(meshes) -> trimesh.Trimesh:
    meshes = [m for m in meshes if m is not None and len(m.faces)]
    verts, faces, off = [], [], 0
    for m in meshes:
        verts.append(np.asarray(m.vertices, dtype=np.float64))
        faces.append(np.asarray(m.faces, dtype=np.int64) + off)
        off += len(m.vertices)
    if not verts:
        return mesh_from(np.zeros((0, 3)), np.zeros((0, 3), dtype=np.int64))
    return mesh_from(np.vstack(verts), np.vstack(faces))


def fit_meshes(meshes, lo, hi):
    """Affinely map the union of ``meshes`` (per axis) onto the box [lo, hi]."""
    lo = np.asarray(lo, dtype=np.float64)
    hi = np.asarray(hi, dtype=np.float64)
    allv = np.vstack([m.vertices for m in meshes])
    blo, bhi = allv.min(axis=0), allv.max(axis=0)
    s = (hi - lo) / np.maximum(bhi - blo, 1e-12)
    return [mesh_from((m.vertices - blo) * s + lo, m.faces) for m in meshes]


# ----------------------------------------------------------------------------------------------
# builder


class Builder:
    """Collects the parts (``add``) and supporting surfaces (``surf``) a generator lays out; ``finish``
    fits them to the object's box."""

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

    def finish(self, w, d, h) -> tuple[list[Part], list[Surface]]:
        """The parts and surfaces fitted exactly to [-w/2, w/2] x [-d/2, d/2] x [0, h] (per-axis affine map)."""
        lo = np.array([-w / 2.0, -d / 2.0, 0.0])
        hi = np.array([w / 2.0, d / 2.0, h])
        meshes = [p[2] for p in self.parts]
        allv = np.vstack([m.vertices for m in meshes])
        blo, bhi = allv.min(axis=0), allv.max(axis=0)
        s = (hi - lo) / np.maximum(bhi - blo, 1e-12)
        parts = []
        for name, mat, m, em, col in self.parts:
            v = np.clip((m.vertices - blo) * s + lo, lo, hi)
            parts.append(Part(name=name, material=mat, mesh=mesh_from(v, m.faces), emissive=em, color=col))
        surfs = []
        for z, x0, x1, y0, y1, cl in self.surfaces:
            z2 = float(np.clip((z - blo[2]) * s[2], 0.0, h))
            xa = float(np.clip((x0 - blo[0]) * s[0] + lo[0], lo[0], hi[0]))
            xb = float(np.clip((x1 - blo[0]) * s[0] + lo[0], lo[0], hi[0]))
            ya = float(np.clip((y0 - blo[1]) * s[1] + lo[1], lo[1], hi[1]))
            yb = float(np.clip((y1 - blo[1]) * s[1] + lo[1], lo[1], hi[1]))
            c2 = float(cl * s[2]) if math.isfinite(cl) else INF
            if xb - xa > 1e-3 and yb - ya > 1e-3:
                surfs.append(Surface(z=z2, xmin=xa, xmax=xb, ymin=ya, ymax=yb, clearance=c2))
        return parts, surfs
