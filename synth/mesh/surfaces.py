"""Supporting surfaces of mesh objects: where a ReplicaCAD object can hold another one.

Procedural objects have theirs in ``synth.assets.registry.support_surfaces``. A mesh object's are
the receptacles its dataset declares when it has any (``synth.sources.replicacad.receptacles``), else the
top face of its local box, when the mesh has up-facing triangles at its top covering at least
``MESH_TOP_COVERAGE`` of that face (``mesh_top_coverage``, cached per asset), ``SURFACE_MARGIN``
inside its edges, with unlimited clearance, then the horizontal levels below the top (a sofa's
seat, shelf boards: ``mesh_levels``) with the clearance up to the next level above them or to the
box top (a cushion on a seat sits inside the sofa's box; ``synth.layout.validity`` lets an object
overlap the box of what holds it); only for objects standing upright (tilt below
``UPRIGHT_TILT_DEG``) and of a class that holds things in the procedural apartment too (not
``MESH_NO_SURFACE_CLASSES``: lamps, vases, bowls, plants, cushions, "other"...). Meshes come from
``synth.mesh.mesh_assets.load_asset_mesh``; a layout without ``meta["root"]`` has no mesh
surfaces. Placement (``synth.layout.placement``) and the layout checks read them from here.
"""

from __future__ import annotations

import functools
import math

import numpy as np

from ..assets import registry as assets
from ..assets.surfaces import Surface
from ..scene import geometry as geo
from ..scene.model import MESH_ASSET_PREFIXES, ObjectInstance

# supporting surfaces of mesh objects (see the module docstring)
MESH_TOP_COVERAGE = 0.5  # fraction of the box top that up-facing top triangles must cover
MESH_TOP_TOL = 0.01  # how far below the mesh's highest point a "top" triangle may lie (m, mesh units)
MESH_UP_COS = math.cos(math.radians(10.0))  # a triangle faces up when its normal is within 10 deg of +Z
SURFACE_MARGIN = 0.02  # usable area kept inside the top's edges (m; at most 10 % of the extent)
UPRIGHT_TILT_DEG = 0.5
LEVEL_MIN_SIDE = 0.15  # a level below the top (seat, shelf board) at least this wide and deep (m)
LEVEL_MIN_RISE = 0.05  # ... and at least this high above the mesh's bottom (m)
# classes that hold nothing, as in the procedural apartment (a bowl on a lamp's shade, on a vase...)
MESH_NO_SURFACE_CLASSES = assets.NO_SURFACE_CLASSES


def mesh_top_coverage(vertices, faces) -> float:
    """Fraction of the top face of a mesh's bounding box covered by up-facing triangles at its top.

    A triangle counts when its normal is within 10 deg of +Z and all its vertices lie within
    ``MESH_TOP_TOL`` of the highest vertex; coverage is the sum of the counted triangles'
    horizontal areas over the box top's area (overlapping triangles count twice: capped at 1).
    Vertices are in a Z-up frame (``synth.sources.replicacad.importer.load_asset_mesh``)."""
    v = np.asarray(vertices, float)
    f = np.asarray(faces, int)
    if len(v) == 0 or len(f) == 0:
        return 0.0
    lo, hi = v.min(axis=0), v.max(axis=0)
    top_area = float((hi[0] - lo[0]) * (hi[1] - lo[1]))
    if top_area <= 0:
        return 0.0
    a, b, c = v[f[:, 0]], v[f[:, 1]], v[f[:, 2]]
    n = np.cross(b - a, c - a)
    norm = np.linalg.norm(n, axis=1)
    ok = norm > 0
    up = np.zeros(len(f), bool)
    up[ok] = n[ok, 2] / norm[ok] >= MESH_UP_COS
    at_top = np.minimum(np.minimum(a[:, 2], b[:, 2]), c[:, 2]) >= hi[2] - MESH_TOP_TOL
    covered = float(np.abs(n[up & at_top, 2]).sum()) / 2.0
    return min(1.0, covered / top_area)


def _asset_geometry(root: str, asset: str):
    """(vertices, faces) of a mesh asset in its Z-up local frame, unscaled; None when unknown."""
    if any(asset.startswith(p) for p in MESH_ASSET_PREFIXES):
        from .mesh_assets import load_asset_mesh

        m = load_asset_mesh(root, asset)
        return m.vertices, m.faces
    return None


@functools.lru_cache(maxsize=512)
def asset_top_coverage(root: str, asset: str) -> float:
    """``mesh_top_coverage`` of a mesh asset (0 when its mesh cannot be had); cached per asset."""
    geom = _asset_geometry(root, asset)
    return 0.0 if geom is None else mesh_top_coverage(*geom)


def mesh_levels(vertices, faces) -> list[tuple[float, float, float, float, float]]:
    """Horizontal support levels *below* a mesh's top: seats, shelf boards, a counter's step.

    Up-facing triangles (normal within 10 deg of +Z) are grouped by height (1 cm steps, a gap of
    more than 1 cm starts a new level). A level counts when its triangles cover at least
    ``MESH_TOP_COVERAGE`` of their own bounding rectangle, that rectangle is at least
    ``LEVEL_MIN_SIDE`` on each side, it lies at least ``LEVEL_MIN_RISE`` above the mesh's bottom and
    more than ``MESH_TOP_TOL`` below its top (the top is ``mesh_top_coverage``'s), and at most half of
    it is hidden under higher triangles (not a board inside a closed body); the level's rectangle is
    then the open part of it (``_open_part``: a seat without the strip under the backrest). Returns
    (z, xmin, xmax, ymin, ymax) per level, highest first, in the mesh's unscaled frame."""
    v = np.asarray(vertices, float)
    f = np.asarray(faces, int)
    if len(v) == 0 or len(f) == 0:
        return []
    lo, hi = v.min(axis=0), v.max(axis=0)
    a, b, c = v[f[:, 0]], v[f[:, 1]], v[f[:, 2]]
    n = np.cross(b - a, c - a)
    norm = np.linalg.norm(n, axis=1)
    up = np.zeros(len(f), bool)
    ok = norm > 0
    up[ok] = n[ok, 2] / norm[ok] >= MESH_UP_COS
    z = (a[:, 2] + b[:, 2] + c[:, 2]) / 3.0
    sel = up & (z >= lo[2] + LEVEL_MIN_RISE) & (z < hi[2] - MESH_TOP_TOL)
    if not sel.any():
        return []
    idx = np.nonzero(sel)[0]
    idx = idx[np.argsort(z[idx], kind="stable")]
    zs = z[idx]
    breaks = np.nonzero(np.diff(zs) > 0.01)[0] + 1
    out = []
    for group in np.split(idx, breaks):
        pts = np.concatenate([a[group], b[group], c[group]])
        x0, y0 = pts[:, 0].min(), pts[:, 1].min()
        x1, y1 = pts[:, 0].max(), pts[:, 1].max()
        if min(x1 - x0, y1 - y0) < LEVEL_MIN_SIDE:
            continue
        area = float(np.abs(n[group, 2]).sum()) / 2.0
        if area < MESH_TOP_COVERAGE * (x1 - x0) * (y1 - y0):
            continue
        hidden, (x0, x1, y0, y1) = _open_part(a, b, c, float(np.median(z[group])), (x0, x1, y0, y1))
        if hidden > 0.5:
            continue  # inside the mesh (a closed drawer's top under the counter top): nothing can be put there
        out.append((round(float(np.median(z[group])), 4), float(x0), float(x1), float(y0), float(y1)))
    return sorted(out, key=lambda t: -t[0])


LEVEL_GRID = 9  # cells per side of the grid that tells the open part of a level from the part under something


def _open_part(a, b, c, z: float, rect) -> tuple[float, tuple[float, float, float, float]]:
    """Which part of a level at height ``z`` over ``rect`` is open from above: the fraction of a
    ``LEVEL_GRID`` x ``LEVEL_GRID`` grid of cell centres that some non-vertical triangle higher than
    ``z`` + 1 cm covers in plan view, and the bounding rectangle of the open cells (a sofa's seat
    without the strip under its backrest)."""
    x0, x1, y0, y1 = rect
    dx, dy = (x1 - x0) / LEVEL_GRID, (y1 - y0) / LEVEL_GRID
    gx, gy = np.meshgrid(x0 + (np.arange(LEVEL_GRID) + 0.5) * dx, y0 + (np.arange(LEVEL_GRID) + 0.5) * dy)
    p = np.stack([gx.ravel(), gy.ravel()], axis=1)
    zc = (a[:, 2] + b[:, 2] + c[:, 2]) / 3.0
    A, B, C = a[:, :2], b[:, :2], c[:, :2]
    det = (B[:, 0] - A[:, 0]) * (C[:, 1] - A[:, 1]) - (C[:, 0] - A[:, 0]) * (B[:, 1] - A[:, 1])
    keep = (zc > z + 0.01) & (np.abs(det) > 1e-12)
    covered = np.zeros(len(p), bool)
    if keep.any():
        A, B, C, det = A[keep], B[keep], C[keep], det[keep]
        for i, q in enumerate(p):
            u = ((B[:, 0] - q[0]) * (C[:, 1] - q[1]) - (C[:, 0] - q[0]) * (B[:, 1] - q[1])) / det
            v = ((C[:, 0] - q[0]) * (A[:, 1] - q[1]) - (A[:, 0] - q[0]) * (C[:, 1] - q[1])) / det
            covered[i] = bool(((u >= 0) & (v >= 0) & (u + v <= 1)).any())
    free = p[~covered]
    if len(free) == 0:
        return 1.0, rect
    return float(covered.mean()), (float(max(x0, free[:, 0].min() - dx / 2)), float(min(x1, free[:, 0].max() + dx / 2)),
                                   float(max(y0, free[:, 1].min() - dy / 2)), float(min(y1, free[:, 1].max() + dy / 2)))


@functools.lru_cache(maxsize=512)
def asset_levels(root: str, asset: str) -> tuple:
    """``mesh_levels`` of a mesh asset (() when its mesh cannot be had); cached per asset."""
    geom = _asset_geometry(root, asset)
    return () if geom is None else tuple(mesh_levels(*geom))


def mesh_surfaces(obj: ObjectInstance, root) -> list[assets.Surface]:
    """The supporting surfaces of a mesh object (see the module docstring), in the object's local
    frame (origin at ``obj.position``, scaled): the receptacles its dataset declares, when it has any
    (``params["receptacles"]``: ReplicaCAD's ``receptacle_aabb_*``, ``synth.sources.replicacad.receptacles``), in their
    file order; else surface 0 is its local box top when the mesh covers it, then the levels below
    it (``mesh_levels``: a sofa's seat, shelf boards), highest first; [] for classes that hold
    nothing and tilted objects."""
    if obj.params.get("receptacles"):
        return receptacle_surfaces(obj)
    if root is None or obj.asset.startswith("proc:") or obj.cls in MESH_NO_SURFACE_CLASSES:
        return []
    R = geo.quat_to_matrix(obj.rotation)
    if R[2, 2] < math.cos(math.radians(UPRIGHT_TILT_DEG)):
        return []
    off, size = obj.box_offset, obj.size
    out = []
    if asset_top_coverage(str(root), obj.asset) >= MESH_TOP_COVERAGE:
        mx, my = min(SURFACE_MARGIN, 0.1 * size[0]), min(SURFACE_MARGIN, 0.1 * size[1])
        out.append(assets.Surface(z=off[2] + size[2] / 2.0, xmin=off[0] - size[0] / 2.0 + mx, xmax=off[0] + size[0] / 2.0 - mx,
                                  ymin=off[1] - size[1] / 2.0 + my, ymax=off[1] + size[1] / 2.0 - my, clearance=math.inf))
    sx, sy, sz = obj.scale
    levels = [(z * sz, x0 * sx, x1 * sx, y0 * sy, y1 * sy) for z, x0, x1, y0, y1 in asset_levels(str(root), obj.asset)]
    top = off[2] + size[2] / 2.0
    for k, (z, x0, x1, y0, y1) in enumerate(levels):
        # clearance: up to the next level above that overlaps this one, else up to the box top
        above = [lz for lz, a0, a1, b0, b1 in levels[:k] if a0 < x1 - 0.01 and a1 > x0 + 0.01 and b0 < y1 - 0.01 and b1 > y0 + 0.01]
        clearance = max((min(above) if above else top) - z, 0.0)
        mx, my = min(SURFACE_MARGIN, 0.1 * (x1 - x0)), min(SURFACE_MARGIN, 0.1 * (y1 - y0))
        out.append(assets.Surface(z=z, xmin=x0 + mx, xmax=x1 - mx, ymin=y0 + my, ymax=y1 - my, clearance=clearance))
    return out


def receptacle_surfaces(obj) -> list:
    """``synth.assets.surfaces.Surface`` per receptacle of ``obj`` (``params["receptacles"]``), in the frame
    the checks use for supporting surfaces: origin at ``obj.position``, turned by ``obj.yaw`` only.
    A tilted object's receptacle (an articulated object whose root frame is rolled, a mesh authored
    on its side) becomes the level box around it in that frame. Each surface is the box's bottom
    face, ``band`` = its height (a resting object's bottom lies anywhere in it), and the clearance
    up to the next receptacle above that overlaps it in plan (else unlimited)."""
    recs = obj.params.get("receptacles") or []
    M = geo.rot_z(obj.yaw).T @ geo.quat_to_matrix(obj.rotation)
    boxes = [(M @ np.asarray(r["center"], float), np.abs(M) @ np.asarray(r["half"], float)) for r in recs]
    out = []
    for k, (c, h) in enumerate(boxes):
        z0 = c[2] - h[2]
        above = [c2[2] - h2[2] for j, (c2, h2) in enumerate(boxes)
                 if j != k and c2[2] - h2[2] > z0 + 0.02 and abs(c2[0] - c[0]) < h2[0] + h[0] and abs(c2[1] - c[1]) < h2[1] + h[1]]
        clearance = (min(above) - z0) if above else math.inf
        out.append(Surface(z=float(z0), xmin=float(c[0] - h[0]), xmax=float(c[0] + h[0]), ymin=float(c[1] - h[1]),
                           ymax=float(c[1] + h[1]), clearance=float(clearance), band=float(2 * h[2])))
    return out
