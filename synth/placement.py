"""Valid placements of object instances in a layout: the engine behind apt_0 and its variants.

A placement is valid when the object's box
  - lies inside one room's free interior (floor and wall objects) or on a supporting surface of
    another object (surface objects: footprint inside the surface rectangle, height within its
    clearance),
  - interpenetrates no other object's box, except its own support parent,
  - keeps every door's clearance zone free (floor-level objects), covers no opening (wall objects),
  - stands in front of no window when it is taller than the window's sill.
The same rules are what ``synth.checks`` verifies, so a layout produced here checks clean.

Procedural and mesh objects
    Every placement primitive takes an optional ``template``: ``None`` places a procedural
    instance (``proc:<class>``, local origin at the bottom centre of its box); an existing
    ``ObjectInstance`` with a mesh asset (``replicacad:``, ``replicacad-urdf:``) places a copy of it
    -- same asset, scale, local box and parameters -- so that its world box has the requested
    footprint centre, bottom height and heading (``placed_copy``). ``size`` is then the template's
    world box size (``object_box(template).size``). A tilted template keeps its tilt: the copy is
    the template turned about the vertical.

Supporting surfaces
    Procedural objects: ``synth.assets.support_surfaces``. Mesh objects: the top face of the
    object's local box, when the mesh has up-facing triangles at its top covering at least
    ``MESH_TOP_COVERAGE`` of that face (``mesh_top_coverage``, cached per asset), ``SURFACE_MARGIN``
    inside its edges, with unlimited clearance, then the horizontal levels below the top (a sofa's
    seat, shelf boards: ``mesh_levels``) with the clearance up to the next level above them or to
    the box top (a cushion on a seat sits inside the sofa's box; ``synth.checks`` lets an object
    overlap the box of what holds it); only for objects standing upright (tilt below
    ``UPRIGHT_TILT_DEG``) and of a class that holds things in the procedural apartment too
    (not ``MESH_NO_SURFACE_CLASSES``: lamps, vases, bowls, plants, cushions, "other"...). Meshes come from ``synth.replicacad.load_asset_mesh`` (``replicacad:``) or
    ``synth.urdf.urdf_geometry`` (``replicacad-urdf:``, when that module exists); a layout without
    ``meta["root"]`` has no mesh surfaces.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass

import numpy as np

from . import assets
from . import geometry as geo
from .classes import class_table
from .scene import MESH_ASSET_PREFIXES, Layout, ObjectInstance, Opening, Room, Stage, Wall, object_box

GAP = 0.01  # distance kept from walls and between touching objects (m)
DOOR_CLEARANCE = 0.9  # depth of the free zone on each side of a door (m)
DOOR_ZONE_HEIGHT = 2.0
WALL_TOL = 0.03  # how far a wall object may float off its wall face (m)
CEILING_GAP = 0.05  # free space kept under the ceiling above anything standing (m)

# supporting surfaces of mesh objects (see the module docstring)
MESH_TOP_COVERAGE = 0.5  # fraction of the box top that up-facing top triangles must cover
MESH_TOP_TOL = 0.01  # how far below the mesh's highest point a "top" triangle may lie (m, mesh units)
MESH_UP_COS = math.cos(math.radians(10.0))  # a triangle faces up when its normal is within 10 deg of +Z
SURFACE_MARGIN = 0.02  # usable area kept inside the top's edges (m; at most 10 % of the extent)
UPRIGHT_TILT_DEG = 0.5
LEVEL_MIN_SIDE = 0.15  # a level below the top (seat, shelf board) at least this wide and deep (m)
LEVEL_MIN_RISE = 0.05  # ... and at least this high above the mesh's bottom (m)
# classes that hold nothing, as in the procedural apartment (a bowl on a lamp's shade, on a vase...)
MESH_NO_SURFACE_CLASSES = assets._NO_SURFACES

SIDES = ("S", "N", "W", "E")
# yaw that makes an object's front (+Y) face into the room from each side's wall
SIDE_YAW = {"S": 0.0, "N": math.pi, "W": -math.pi / 2, "E": math.pi / 2}


def proc_instance(oid: int, cls: str, size, params, position, yaw: float, support: str) -> ObjectInstance:
    info = class_table().get(cls)
    return ObjectInstance(
        id=oid, cls=cls, asset=f"proc:{cls}", position=tuple(float(v) for v in position), rotation=geo.yaw_to_quat(yaw),
        size=tuple(float(v) for v in size), box_offset=(0.0, 0.0, float(size[2]) / 2.0), support=support,
        movable=info.movable, params=params,
    )


def placed_copy(template: ObjectInstance, oid: int, xy, z: float, yaw: float, support: str) -> ObjectInstance:
    """A copy of the mesh object ``template`` whose world box has its footprint centre at ``xy``,
    its bottom at ``z`` and heading ``yaw``: the template turned about +Z by ``yaw - box yaw`` and
    moved. Asset, class, local box, scale, mobility and parameters are the template's."""
    ob = object_box(template)
    R = geo.rot_z(yaw - ob.yaw) @ geo.quat_to_matrix(template.rotation)
    centre = np.array([float(xy[0]), float(xy[1]), float(z) + ob.size[2] / 2.0])
    pos = centre - R @ np.asarray(template.box_offset, float)
    return ObjectInstance(
        id=oid, cls=template.cls, asset=template.asset, position=tuple(float(v) for v in pos),
        rotation=geo.matrix_to_quat(R), size=template.size, box_offset=template.box_offset, support=support,
        movable=template.movable, scale=template.scale, params=dict(template.params),
    )


def mesh_top_coverage(vertices, faces) -> float:
    """Fraction of the top face of a mesh's bounding box covered by up-facing triangles at its top.

    A triangle counts when its normal is within 10 deg of +Z and all its vertices lie within
    ``MESH_TOP_TOL`` of the highest vertex; coverage is the sum of the counted triangles'
    horizontal areas over the box top's area (overlapping triangles count twice: capped at 1).
    Vertices are in a Z-up frame (``synth.replicacad.load_asset_mesh``)."""
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
    (``params["receptacles"]``: ReplicaCAD's ``receptacle_aabb_*``, ``synth.receptacles``), in their
    file order; else surface 0 is its local box top when the mesh covers it, then the levels below
    it (``mesh_levels``: a sofa's seat, shelf boards), highest first; [] for classes that hold
    nothing and tilted objects."""
    if obj.params.get("receptacles"):
        from .receptacles import surfaces as receptacle_surfaces

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


def door_zone(stage: Stage, op: Opening) -> geo.OrientedBox:
    """The box in front of and behind a door that must stay free so the door stays passable."""
    w = stage.wall(op.wall)
    c = op.center_xy(w)
    yaw = math.atan2(w.direction[1], w.direction[0])
    depth = 2 * DOOR_CLEARANCE + w.thickness
    return geo.OrientedBox(0, "door_zone", (float(c[0]), float(c[1]), stage.floor_z + DOOR_ZONE_HEIGHT / 2),
                           (op.width, depth, DOOR_ZONE_HEIGHT), yaw, kind="zone")


def opening_box(stage: Stage, op: Opening, depth_extra: float = 0.0) -> geo.OrientedBox:
    """The volume of an opening inside its wall (optionally deeper than the wall)."""
    w = stage.wall(op.wall)
    c = op.center_xy(w)
    yaw = math.atan2(w.direction[1], w.direction[0])
    return geo.OrientedBox(0, op.kind, (float(c[0]), float(c[1]), stage.floor_z + op.bottom + op.height / 2),
                           (op.width, w.thickness + 2 * depth_extra, op.height), yaw, kind="zone")


def side_of_wall(room: Room, wall: Wall, tol: float = 0.02) -> str | None:
    """Which side of ``room`` the wall bounds, if its face is the room's edge and they overlap."""
    xmin, ymin, xmax, ymax = room.rect
    (x0, y0), (x1, y1) = wall.start, wall.end
    t = wall.thickness / 2
    if abs(y0 - y1) < 1e-9:  # horizontal
        lo, hi = min(x0, x1), max(x0, x1)
        if min(hi, xmax) - max(lo, xmin) <= 0.1:
            return None
        if abs(y0 + t - ymin) < tol:
            return "S"
        if abs(y0 - t - ymax) < tol:
            return "N"
    elif abs(x0 - x1) < 1e-9:
        lo, hi = min(y0, y1), max(y0, y1)
        if min(hi, ymax) - max(lo, ymin) <= 0.1:
            return None
        if abs(x0 + t - xmin) < tol:
            return "W"
        if abs(x0 - t - xmax) < tol:
            return "E"
    return None


def wall_at(stage: Stage, room: Room, side: str, along: float) -> Wall | None:
    """The wall segment on ``side`` of ``room`` that covers the coordinate ``along``."""
    for w in stage.walls:
        if side_of_wall(room, w) != side:
            continue
        if side in ("S", "N"):
            lo, hi = sorted((w.start[0], w.end[0]))
        else:
            lo, hi = sorted((w.start[1], w.end[1]))
        if lo - 1e-6 <= along <= hi + 1e-6:
            return w
    return None


def wall_side_interval(stage: Stage, room: Room, w: Wall, side: str) -> tuple[float, float]:
    """Interval of the room side covered by the wall, in the side's along-coordinate."""
    xmin, ymin, xmax, ymax = room.rect
    if side in ("S", "N"):
        lo, hi = sorted((w.start[0], w.end[0]))
        return max(lo, xmin), min(hi, xmax)
    lo, hi = sorted((w.start[1], w.end[1]))
    return max(lo, ymin), min(hi, ymax)


def along_to_xy(room: Room, side: str, along: float, depth: float, gap: float = GAP) -> tuple[float, float]:
    """Centre of a footprint of ``depth`` (its local y extent) with its back against ``side``."""
    xmin, ymin, xmax, ymax = room.rect
    if side == "S":
        return along, ymin + depth / 2 + gap
    if side == "N":
        return along, ymax - depth / 2 - gap
    if side == "W":
        return xmin + depth / 2 + gap, along
    return xmax - depth / 2 - gap, along


def side_range(room: Room, side: str) -> tuple[float, float]:
    xmin, ymin, xmax, ymax = room.rect
    return (xmin, xmax) if side in ("S", "N") else (ymin, ymax)


@dataclass
class Placed:
    obj: ObjectInstance
    box: geo.OrientedBox


def distance_to_box_2d(points: np.ndarray, box: geo.OrientedBox) -> np.ndarray:
    """Horizontal distance from each point (N, 2) to the box's footprint (0 inside)."""
    c, s = math.cos(box.yaw), math.sin(box.yaw)
    d = np.asarray(points, float) - np.asarray(box.center[:2])
    local = np.stack([d[:, 0] * c + d[:, 1] * s, -d[:, 0] * s + d[:, 1] * c], axis=1)
    out = np.maximum(np.abs(local) - np.array([box.size[0] / 2, box.size[1] / 2]), 0.0)
    return np.hypot(out[:, 0], out[:, 1])


def footprint_in_polygon(corners: np.ndarray, room: Room) -> bool:
    """Whether a convex footprint (corners (4, 2)) lies inside ``room``'s polygon: every corner inside
    (``Room.contains``) and no edge of the polygon crossing or touching the footprint's sides (a thin
    wall that reaches into the room between two corners)."""
    c = np.asarray(corners, float)
    if not room.contains(c).all():
        return False
    q = room.outline()
    a, b = q, np.roll(q, -1, axis=0)  # polygon edges a -> b
    p, r = c, np.roll(c, -1, axis=0)  # footprint sides p -> r

    def orient(o, u, v):  # sign of the turn o -> u -> v, broadcast (footprint sides x polygon edges)
        return np.sign((u[..., 0] - o[..., 0]) * (v[..., 1] - o[..., 1]) - (u[..., 1] - o[..., 1]) * (v[..., 0] - o[..., 0]))

    P, R = p[:, None, :], r[:, None, :]
    A, B = a[None, :, :], b[None, :, :]
    d1, d2 = orient(P, R, A), orient(P, R, B)
    d3, d4 = orient(A, B, P), orient(A, B, R)
    return not bool(((d1 * d2 <= 0) & (d3 * d4 <= 0) & ~((d1 == 0) & (d2 == 0))).any())


class Placer:
    """Keeps the boxes of a layout and answers whether a new placement is valid.

    ``keepout`` (points (N, 2), radius) reserves a walkway: no object except ceiling-mounted ones
    may come closer than the radius to any of the points (horizontally). New objects get ids above
    every object's and above ``used_ids``.
    """

    def __init__(self, layout: Layout, rng: np.random.Generator, keepout: tuple[np.ndarray, float] | None = None,
                 used_ids: int = 0):
        self.keepout = keepout
        self.used_ids = used_ids  # ids up to this one are taken even when no object holds them (removed ones)
        self.layout = layout
        self.stage = layout.stage
        self.rng = rng
        self.classes = class_table()
        self.boxes: dict[int, geo.OrientedBox] = {o.id: object_box(o) for o in layout.objects}
        self.door_zones = [door_zone(self.stage, op) for op in self.stage.openings if op.kind == "door"]
        self.opening_boxes = [opening_box(self.stage, op, depth_extra=0.05) for op in self.stage.openings]
        # windows, extended into the rooms: tall furniture must not stand in front of them
        self.window_fronts = [
            (op, opening_box(self.stage, op, depth_extra=0.7)) for op in self.stage.openings if op.kind == "window"
        ]
        self._surfaces: dict[int, list[assets.Surface]] = {}
        self.ceiling_z = self.stage.floor_z + self.stage.ceiling_height

    # ---- bookkeeping --------------------------------------------------------------------
    def next_id(self) -> int:
        return max([o.id for o in self.layout.objects] + [self.used_ids]) + 1

    def add(self, obj: ObjectInstance) -> ObjectInstance:
        self.layout.objects.append(obj)
        self.boxes[obj.id] = object_box(obj)
        return obj

    def remove(self, oid: int) -> None:
        self.layout.objects = [o for o in self.layout.objects if o.id != oid]
        self.boxes.pop(oid, None)
        self._surfaces.pop(oid, None)

    def children(self, oid: int) -> list[ObjectInstance]:
        """Objects standing (directly or indirectly) on object ``oid``."""
        out, frontier = [], [oid]
        while frontier:
            pid = frontier.pop()
            for o in self.layout.objects:
                par = o.support_parent()
                if par and par[0] == pid:
                    out.append(o)
                    frontier.append(o.id)
        return out

    def surfaces(self, obj: ObjectInstance) -> list[assets.Surface]:
        if obj.id not in self._surfaces:
            if obj.asset.startswith("proc:"):
                self._surfaces[obj.id] = assets.support_surfaces(obj.cls, obj.size, obj.params)
            else:
                self._surfaces[obj.id] = mesh_surfaces(obj, self.layout.meta.get("root"))
        return self._surfaces[obj.id]

    # ---- validity -----------------------------------------------------------------------
    def collides(self, box: geo.OrientedBox, ignore: set[int] = frozenset()) -> bool:
        for oid, b in self.boxes.items():
            if oid in ignore or oid == box.id:
                continue
            if geo.boxes_overlap(box, b):
                return True
        return False

    def in_door_zone(self, box: geo.OrientedBox) -> bool:
        return any(geo.boxes_overlap(box, z, tol=0.0) for z in self.door_zones)

    def blocks_window(self, box: geo.OrientedBox) -> bool:
        for op, front in self.window_fronts:
            if box.zmax > self.stage.floor_z + op.bottom + 0.02 and geo.boxes_overlap(box, front, tol=0.0):
                return True
        return False

    def covers_opening(self, box: geo.OrientedBox) -> bool:
        return any(geo.boxes_overlap(box, z, tol=0.0) for z in self.opening_boxes)

    def room_of(self, box: geo.OrientedBox) -> Room | None:
        """The room whose free interior holds the box's footprint: inside its rect and, for a room
        with a polygon (an open plan), inside the polygon (``footprint_in_polygon``)."""
        poly = box.corners_2d()
        for r in self.stage.rooms:
            if geo.polygon_inside_rect(poly, r.rect) and (r.polygon is None or footprint_in_polygon(poly, r)):
                return r
        return None

    def in_keepout(self, box: geo.OrientedBox) -> bool:
        if self.keepout is None:
            return False
        pts, r = self.keepout
        return bool((distance_to_box_2d(pts, box) < r).any())

    def valid_floor(self, box: geo.OrientedBox, ignore: set[int] = frozenset()) -> bool:
        return (
            box.zmax <= self.ceiling_z - CEILING_GAP
            and not self.in_keepout(box)
            and self.room_of(box) is not None
            and not self.in_door_zone(box)
            and not self.blocks_window(box)
            and not self.collides(box, ignore)
        )

    # ---- placement primitives -------------------------------------------------------------
    def _box(self, oid, cls, size, xy, z, yaw) -> geo.OrientedBox:
        return geo.OrientedBox(oid, cls, (float(xy[0]), float(xy[1]), float(z + size[2] / 2)), tuple(size), yaw)

    def sample(self, cls: str) -> tuple[tuple[float, float, float], dict]:
        return assets.sample_params(cls, self.rng)

    @staticmethod
    def _make(oid, cls, size, params, position, yaw: float, support: str, template: ObjectInstance | None) -> ObjectInstance:
        """A procedural instance (``template`` None) or a placed copy of the mesh object ``template``
        with its box bottom centre at ``position``."""
        if template is None:
            return proc_instance(oid, cls, size, params, position, yaw, support)
        return placed_copy(template, oid, position[:2], position[2], yaw, support)

    def floor_at(self, oid, cls, size, params, xy, yaw, ignore=frozenset(), template=None) -> ObjectInstance | None:
        box = self._box(oid, cls, size, xy, self.stage.floor_z, yaw)
        if not self.valid_floor(box, ignore):
            return None
        return self._make(oid, cls, size, params, (xy[0], xy[1], self.stage.floor_z), yaw, "floor", template)

    def against_wall(self, oid, cls, size, params, room: Room, side: str | None = None, along: float | None = None,
                     tries: int = 60, ignore=frozenset(), template=None) -> ObjectInstance | None:
        """Back against a wall of ``room`` (a random side and position unless given)."""
        for _ in range(tries):
            s = side or SIDES[self.rng.integers(4)]
            lo, hi = side_range(room, s)
            w = size[0]
            if hi - lo < w + 2 * GAP:
                continue
            a = along if along is not None else self.rng.uniform(lo + w / 2 + GAP, hi - w / 2 - GAP)
            a = float(np.clip(a, lo + w / 2 + GAP, hi - w / 2 - GAP))
            if wall_at(self.stage, room, s, a) is None:
                continue
            xy = along_to_xy(room, s, a, size[1])
            obj = self.floor_at(oid, cls, size, params, xy, SIDE_YAW[s], ignore, template)
            if obj is not None:
                return obj
            if along is not None and side is not None:
                along = None  # the requested spot is taken: fall back to random positions on that side
        return None

    def free_spot(self, oid, cls, size, params, room: Room, tries: int = 80, yaw: float | None = None,
                  jitter_deg: float = 0.0, margin: float = 0.05, ignore=frozenset(), template=None) -> ObjectInstance | None:
        """Anywhere on the floor of ``room``; yaw a multiple of 90 deg plus jitter unless given."""
        xmin, ymin, xmax, ymax = room.rect
        for _ in range(tries):
            y = yaw if yaw is not None else self.rng.integers(4) * math.pi / 2
            y = geo.wrap_angle(y + math.radians(self.rng.uniform(-jitter_deg, jitter_deg)))
            if xmax - xmin < 2 * margin or ymax - ymin < 2 * margin:
                return None
            xy = (self.rng.uniform(xmin + margin, xmax - margin), self.rng.uniform(ymin + margin, ymax - margin))
            obj = self.floor_at(oid, cls, size, params, xy, y, ignore, template)
            if obj is not None:
                return obj
        return None

    def corner(self, oid, cls, size, params, room: Room, tries: int = 8, ignore=frozenset(), template=None) -> ObjectInstance | None:
        xmin, ymin, xmax, ymax = room.rect
        corners = [(xmin, ymin), (xmax, ymin), (xmax, ymax), (xmin, ymax)]
        order = self.rng.permutation(4)
        for k in order[:tries]:
            cx, cy = corners[k]
            sx = 1 if cx == xmin else -1
            sy = 1 if cy == ymin else -1
            xy = (cx + sx * (size[0] / 2 + 0.05), cy + sy * (size[1] / 2 + 0.05))
            obj = self.floor_at(oid, cls, size, params, xy, 0.0, ignore, template)
            if obj is not None:
                return obj
        return None

    def relative(self, oid, cls, size, params, parent: ObjectInstance, dxy, dyaw: float, ignore=frozenset(),
                 template=None) -> ObjectInstance | None:
        """On the floor at offset ``dxy`` in the parent's frame, yaw = parent's + ``dyaw``."""
        yaw = parent.yaw
        c, s = math.cos(yaw), math.sin(yaw)
        xy = (parent.position[0] + c * dxy[0] - s * dxy[1], parent.position[1] + s * dxy[0] + c * dxy[1])
        return self.floor_at(oid, cls, size, params, xy, geo.wrap_angle(yaw + dyaw), ignore, template)

    def on_surface(self, oid, cls, size, params, parents: list[ObjectInstance], tries: int = 40,
                   yaw_mode: str = "aligned", ignore=frozenset(), template=None) -> ObjectInstance | None:
        """On a supporting surface of one of ``parents``.

        ``yaw_mode``: ``aligned`` (parent's yaw, front to the parent's front), ``any90`` (a multiple
        of 90 deg), ``free`` (any yaw).
        """
        cands = [(p, k, s) for p in parents for k, s in enumerate(self.surfaces(p)) if s.clearance >= size[2] + 0.01]
        if not cands:
            return None
        for _ in range(tries):
            p, k, s = cands[self.rng.integers(len(cands))]
            if yaw_mode == "aligned":
                dyaw = 0.0
            elif yaw_mode == "any90":
                dyaw = self.rng.integers(4) * math.pi / 2
            else:
                dyaw = self.rng.uniform(-math.pi, math.pi)
            # local footprint half-extents in the parent's frame
            c, sn = abs(math.cos(dyaw)), abs(math.sin(dyaw))
            hx = 0.5 * (c * size[0] + sn * size[1])
            hy = 0.5 * (sn * size[0] + c * size[1])
            if s.xmax - s.xmin < 2 * hx or s.ymax - s.ymin < 2 * hy:
                continue
            lx = self.rng.uniform(s.xmin + hx, s.xmax - hx)
            ly = self.rng.uniform(s.ymin + hy, s.ymax - hy)
            obj = self.at_surface_point(oid, cls, size, params, p, k, (lx, ly), dyaw, ignore, template)
            if obj is not None:
                return obj
        return None

    def at_surface_point(self, oid, cls, size, params, parent: ObjectInstance, k: int, lxy, dyaw: float,
                         ignore=frozenset(), template=None) -> ObjectInstance | None:
        s = self.surfaces(parent)[k]
        pyaw = parent.yaw
        c, sn = math.cos(pyaw), math.sin(pyaw)
        xy = (parent.position[0] + c * lxy[0] - sn * lxy[1], parent.position[1] + sn * lxy[0] + c * lxy[1])
        z = parent.position[2] + s.z
        yaw = geo.wrap_angle(pyaw + dyaw)
        box = self._box(oid, cls, size, xy, z, yaw)
        if box.zmax > self.ceiling_z - CEILING_GAP or self.in_keepout(box) or self.collides(box, ignore | {parent.id}):
            return None
        return self._make(oid, cls, size, params, (xy[0], xy[1], z), yaw, f"object:{parent.id}:{k}", template)

    def on_wall(self, oid, cls, size, params, room: Room, z_center: float | None = None, tries: int = 60,
                side: str | None = None, along: float | None = None, ignore=frozenset(), template=None) -> ObjectInstance | None:
        """Hung on a wall of ``room`` (pictures, mirrors), back against the wall face."""
        for _ in range(tries):
            s = side or SIDES[self.rng.integers(4)]
            lo, hi = side_range(room, s)
            if hi - lo < size[0] + 0.2:
                continue
            a = along if along is not None else self.rng.uniform(lo + size[0] / 2 + 0.1, hi - size[0] / 2 - 0.1)
            w = wall_at(self.stage, room, s, a)
            if w is None:
                continue
            wlo, whi = wall_side_interval(self.stage, room, w, s)
            if a - size[0] / 2 < wlo or a + size[0] / 2 > whi:
                continue
            zc = z_center if z_center is not None else self.rng.uniform(1.35, 1.65)
            z0 = self.stage.floor_z + zc - size[2] / 2
            xy = along_to_xy(room, s, a, size[1], gap=0.002)
            box = self._box(oid, cls, size, xy, z0, SIDE_YAW[s])
            if self.covers_opening(box) or self.in_door_zone(box) or self.in_keepout(box) or self.collides(box, ignore):
                continue
            return self._make(oid, cls, size, params, (xy[0], xy[1], z0), SIDE_YAW[s], f"wall:{w.id}", template)
        return None

    def on_ceiling(self, oid, cls, size, params, room: Room, template=None) -> ObjectInstance | None:
        xmin, ymin, xmax, ymax = room.rect
        xy = ((xmin + xmax) / 2, (ymin + ymax) / 2)
        z0 = self.stage.floor_z + self.stage.ceiling_height - size[2]
        box = self._box(oid, cls, size, xy, z0, 0.0)
        if self.collides(box):
            return None
        return self._make(oid, cls, size, params, (xy[0], xy[1], z0), 0.0, "ceiling", template)
