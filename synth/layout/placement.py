"""Valid placements of object instances in a layout: the engine behind apt_0 and its variants.

A placement is valid when the object's box
  - lies inside one room's free interior (floor and wall objects) or on a supporting surface of
    another object (surface objects: footprint inside the surface rectangle, height within its
    clearance),
  - interpenetrates no other object's box, except its own support parent,
  - keeps every door's clearance zone free (floor-level objects), covers no opening (wall objects),
  - stands in front of no window when it is taller than the window's sill.
The same rules are what ``synth.layout.validity`` verifies, so a layout produced here checks clean.

Procedural and mesh objects
    Every placement primitive takes an optional ``template``: ``None`` places a procedural
    instance (``proc:<class>``, local origin at the bottom centre of its box); an existing
    ``ObjectInstance`` with a mesh asset (``replicacad:``, ``replicacad-urdf:``) places a copy of it
    -- same asset, scale, local box and parameters -- so that its world box has the requested
    footprint centre, bottom height and heading (``placed_copy``). ``size`` is then the template's
    world box size (``object_box(template).size``). A tilted template keeps its tilt: the copy is
    the template turned about the vertical.

Supporting surfaces
    Procedural objects: ``synth.assets.registry.support_surfaces``; mesh objects:
    ``synth.mesh.surfaces.mesh_surfaces`` (their box top and the levels below it).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from vrformats.camera import wrap_angle

from ..assets import registry as assets
from ..mesh.surfaces import mesh_surfaces
from ..scene import geometry as geo
from ..scene.classes import class_table
from ..scene.fixtures import OPEN_TOP_TOLERANCE, is_light_source
from ..scene.model import Layout, ObjectInstance, Room, Stage, Wall, object_box
from ..scene.openings import door_zone, opening_box

GAP = 0.01  # distance kept from walls and between touching objects (m)
WALL_TOL = 0.03  # how far a wall object may float off its wall face (m)
CEILING_GAP = 0.05  # free space kept under the ceiling above anything standing (m)

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
            y = wrap_angle(y + math.radians(self.rng.uniform(-jitter_deg, jitter_deg)))
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
        return self.floor_at(oid, cls, size, params, xy, wrap_angle(yaw + dyaw), ignore, template)

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
        yaw = wrap_angle(pyaw + dyaw)
        box = self._box(oid, cls, size, xy, z, yaw)
        if box.zmax > self.ceiling_z - CEILING_GAP or self.in_keepout(box) or self.collides(box, ignore | {parent.id}):
            return None
        if is_light_source(cls) and not parent.asset.startswith("proc:") and not self.open_top(parent, box):
            return None  # a lamp inside a cupboard lights nothing (procedural furniture has no doors: all open)
        return self._make(oid, cls, size, params, (xy[0], xy[1], z), yaw, f"object:{parent.id}:{k}", template)

    def open_top(self, parent: ObjectInstance, box: geo.OrientedBox) -> bool:
        """True when ``box`` stands on ``parent``'s top, open to the room: nothing of the parent is
        above it. Receptacles inside a mesh piece of furniture (a closed cupboard's shelf, a drawer,
        but also an open bookshelf's middle board: a receptacle does not say whether doors close it)
        are not. Procedural furniture has no doors, so the rule is applied to mesh parents only."""
        top = self.boxes[parent.id].zmax if parent.id in self.boxes else object_box(parent).zmax
        return box.zmin >= top - OPEN_TOP_TOLERANCE

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
