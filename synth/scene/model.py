"""The scene model: plain Python data for a layout (stage + objects + light fixtures).

No Blender here. A layout is what the renderers translate and what the relocalizer's map is
derived from. Files are YAML (``scenes/layouts/NAME.yaml``), written so that a person can edit
them: one object a block, vectors on one line. ``save_layout`` followed by ``load_layout`` gives
back an equal layout, and saving that again gives the same bytes.

Frames and units: world Z up, metres; rotations are (w, x, y, z) quaternions.

Object instances
    ``position`` and ``rotation`` place the object's local frame in the world. ``size`` is the
    extent of the object's local bounding box (already scaled, metres) and ``box_offset`` the box
    centre in the local frame, so the ground-truth box follows from the pose alone, without
    loading meshes. For procedural assets the local origin is the centre of the box's bottom face
    (``box_offset = (0, 0, h/2)``) and the front faces local +Y.
    ``support`` names what holds the object: ``floor``, ``ceiling``, ``wall:<wall id>`` or
    ``object:<id>:<surface index>`` (a surface of another object, see ``synth.assets.registry``), or
    ``free`` (placed by an outside source such as ReplicaCAD: checked only to rest on something).

Ids
    Object ids are 1..999 and stable across the variants of a layout. Structure ids are derived:
    walls 1000+k, floors 2000+k, ceilings 3000+k (k = index in the stage). 0 means "nothing".
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np
import yaml

from vrformats.atomic import write_text_atomic
from vrformats.boxes import BOXES_FORMAT, CEILING_ID_BASE, FLOOR_ID_BASE, FRAME_TEXT, MAX_OBJECT_ID, STRUCT_SLAB, WALL_ID_BASE
from vrformats.errors import UnknownNameError
from vrformats import fields
from vrformats.yamlfile import read_yaml

from . import geometry as geo
from .classes import ClassTable, class_table
from ..resources import layouts_dir

FORMAT = "synth-layout/1"
GLB_ASSET_PREFIX = "replicacad:"  # a GLB mesh, relative to the layout's meta.root
URDF_ASSET_PREFIX = "replicacad-urdf:"  # an articulated object's URDF (synth.mesh.urdf), relative to meta.root
MESH_ASSET_PREFIXES = (GLB_ASSET_PREFIX, URDF_ASSET_PREFIX)

# --------------------------------------------------------------------------------------------
# stored precision
#
# Generated values carry last-bit noise that depends on the processor and its maths library
# (FMA, the SIMD variants of sin/cos/atan2 in libm, BLAS kernels): two machines can differ in
# the 16th digit. A layout therefore holds every value at a stated precision, rounded where the
# value enters the scene model (the dataclasses below round in ``__post_init__``, and the writer
# rounds again), so that every later step -- placement checks, statistics, boxes, renders -- sees
# exactly what the file holds, a regenerated layout is the same file on any machine, and
# load -> save is exact. Rounding is Python's correctly rounded ``round``, so it is the same
# everywhere; only a value within one ulp of a rounding boundary could still differ.

LENGTH_DECIMALS = 4  # metres: positions, sizes, offsets, wall and room coordinates (0.1 mm)
QUAT_DECIMALS = 9  # unit quaternion components (about 2e-9 rad)
QUAT_NORM_TOL = 1e-8  # a quaternion further than this from unit norm is normalised before rounding
SCALE_DECIMALS = 6  # dimensionless mesh scale factors
LIGHT_DECIMALS = 3  # kelvin and watts


def quantize(x, decimals: int = LENGTH_DECIMALS) -> float:
    """``x`` at the stored precision; ``-0.0`` becomes ``0.0`` so the sign of a zero never differs."""
    return round(float(x), decimals) + 0.0


def quantize_vec(v, decimals: int = LENGTH_DECIMALS) -> tuple[float, ...]:
    return tuple(quantize(x, decimals) for x in v)


def quantize_quat(q) -> geo.Quat:
    """A (w, x, y, z) quaternion rounded to ``QUAT_DECIMALS``, normalised first when it is not unit,
    in the hemisphere whose first non-zero component is positive.

    Normalising uses plain IEEE arithmetic (the same on every machine) and is skipped when the
    norm is already within ``QUAT_NORM_TOL`` of 1 -- as it is for every generated rotation and for
    every rounded one -- so quantising a quantised quaternion gives it back unchanged. A stored
    quaternion's norm differs from 1 by at most about 1e-8; every consumer normalises before use.
    """
    q = tuple(float(x) for x in q)
    n = math.sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3])
    if abs(n - 1.0) > QUAT_NORM_TOL and n > 0.0 and math.isfinite(n):
        q = tuple(x / n for x in q)
    q = tuple(quantize(x, QUAT_DECIMALS) for x in q)
    # q and -q are one rotation: keep the one whose first non-zero component is positive. A yaw of
    # pi comes out as (0, 0, 0, 1) or (0, 0, 0, -1) depending on the sign of a zero in atan2.
    lead = next((x for x in q if x != 0.0), 0.0)
    return tuple(-x + 0.0 for x in q) if lead < 0 else q  # type: ignore[return-value]

# --------------------------------------------------------------------------------------------
# data


@dataclass
class Room:
    name: str
    type: str  # living | kitchen | bedroom | bathroom | hallway | ...
    rect: tuple[float, float, float, float]  # free interior (inside wall faces): xmin, ymin, xmax, ymax
    # The free interior as a simple polygon (counter-clockwise XY vertices) when it is not the whole
    # rect (an open plan, an L-shaped room: ReplicaCAD rooms from the floor or the navmesh); ``rect``
    # is then its bounding rectangle. None: the interior is ``rect``.
    polygon: tuple[tuple[float, float], ...] | None = None

    def __post_init__(self):
        self.rect = quantize_vec(self.rect)
        if self.polygon is not None:
            self.polygon = tuple(quantize_vec(p) for p in self.polygon)
            if len(self.polygon) < 3:
                raise ValueError(f"room {self.name}: a polygon needs at least 3 vertices")

    def outline(self) -> np.ndarray:
        """The free interior's boundary, (N, 2) counter-clockwise: the polygon, else the rect's corners."""
        if self.polygon is not None:
            return np.asarray(self.polygon, float)
        x0, y0, x1, y1 = self.rect
        return np.array([(x0, y0), (x1, y0), (x1, y1), (x0, y1)], float)

    def contains(self, pts) -> np.ndarray:
        """Which XY points lie in the free interior (boundary included, to 1 mm)."""
        pts = np.atleast_2d(np.asarray(pts, float))
        x0, y0, x1, y1 = self.rect
        inside = (pts[:, 0] >= x0) & (pts[:, 0] <= x1) & (pts[:, 1] >= y0) & (pts[:, 1] <= y1)
        if self.polygon is not None and inside.any():
            from matplotlib.path import Path as MplPath

            inside[inside] = MplPath(self.outline()).contains_points(pts[inside], radius=1e-3) | \
                MplPath(self.outline()).contains_points(pts[inside], radius=-1e-3)
        return inside

    @property
    def area(self) -> float:
        if self.polygon is not None:
            q = self.outline()
            return float(abs(np.dot(q[:, 0], np.roll(q[:, 1], -1)) - np.dot(q[:, 1], np.roll(q[:, 0], -1))) / 2.0)
        return (self.rect[2] - self.rect[0]) * (self.rect[3] - self.rect[1])


@dataclass
class Wall:
    id: str
    start: tuple[float, float]  # centre line, world XY
    end: tuple[float, float]
    thickness: float
    height: float

    def __post_init__(self):
        self.start, self.end = quantize_vec(self.start), quantize_vec(self.end)
        self.thickness, self.height = quantize(self.thickness), quantize(self.height)

    @property
    def length(self) -> float:
        return math.dist(self.start, self.end)

    @property
    def direction(self) -> np.ndarray:
        d = np.subtract(self.end, self.start)
        return d / np.linalg.norm(d)


@dataclass
class Opening:
    id: str
    kind: str  # door | window
    wall: str
    offset: float  # distance of the opening's centre from the wall's start, along the wall
    width: float
    bottom: float  # sill height (0 for doors)
    height: float
    rooms: tuple[str, ...] = ()  # rooms a door connects (one room for an entrance door)

    def __post_init__(self):
        self.offset, self.width = quantize(self.offset), quantize(self.width)
        self.bottom, self.height = quantize(self.bottom), quantize(self.height)

    def center_xy(self, wall: Wall) -> np.ndarray:
        return np.asarray(wall.start) + wall.direction * self.offset


@dataclass
class Stage:
    ceiling_height: float
    rooms: list[Room] = field(default_factory=list)
    walls: list[Wall] = field(default_factory=list)
    openings: list[Opening] = field(default_factory=list)
    floor_z: float = 0.0
    asset: str | None = None  # a stage mesh (ReplicaCAD); None for procedural stages
    position: tuple[float, float, float] = (0.0, 0.0, 0.0)
    rotation: geo.Quat = (1.0, 0.0, 0.0, 0.0)

    def __post_init__(self):
        self.ceiling_height, self.floor_z = quantize(self.ceiling_height), quantize(self.floor_z)
        self.position, self.rotation = quantize_vec(self.position), quantize_quat(self.rotation)

    def wall(self, wall_id: str) -> Wall:
        for w in self.walls:
            if w.id == wall_id:
                return w
        raise UnknownNameError(f"no wall '{wall_id}' in the stage")

    def room(self, name: str) -> Room:
        for r in self.rooms:
            if r.name == name:
                return r
        raise UnknownNameError(f"no room '{name}' in the stage")

    def room_at(self, xy) -> Room | None:
        x, y = xy
        for r in self.rooms:
            if r.contains((x, y))[0]:
                return r
        return None

    @property
    def area(self) -> float:
        return sum(r.area for r in self.rooms)


@dataclass
class ObjectInstance:
    id: int
    cls: str
    asset: str  # "proc:<class>" (synth.assets.registry generator), "replicacad:<glb path relative to meta.root>" or
    #             "replicacad-urdf:<urdf path relative to meta.root>" (an articulated object in its default joint state)
    position: tuple[float, float, float]
    rotation: geo.Quat
    size: tuple[float, float, float]
    box_offset: tuple[float, float, float]
    support: str = "floor"
    movable: bool = True
    scale: tuple[float, float, float] = (1.0, 1.0, 1.0)
    params: dict[str, Any] = field(default_factory=dict)

    def __post_init__(self):
        self.position, self.rotation = quantize_vec(self.position), quantize_quat(self.rotation)
        self.size, self.box_offset = quantize_vec(self.size), quantize_vec(self.box_offset)
        self.scale = quantize_vec(self.scale, SCALE_DECIMALS)

    @property
    def yaw(self) -> float:
        return geo.quat_yaw(self.rotation)

    def matrix(self) -> np.ndarray:
        """4x4 object-to-world transform (without scale)."""
        T = np.eye(4)
        T[:3, :3] = geo.quat_to_matrix(self.rotation)
        T[:3, 3] = self.position
        return T

    def support_parent(self) -> tuple[int, int] | None:
        """(object id, surface index) when the object stands on another object."""
        if self.support.startswith("object:"):
            _, oid, idx = self.support.split(":")
            return int(oid), int(idx)
        return None


@dataclass
class LightFixture:
    id: str
    kind: str  # lamp (an object's emissive part) | ceiling | window
    position: tuple[float, float, float]
    room: str | None = None
    object: int | None = None  # instance id of the lamp / ceiling light object
    opening: str | None = None  # window opening id
    color_temperature: float = 3000.0  # kelvin
    power: float = 60.0  # watts (Blender's light power)

    def __post_init__(self):
        self.position = quantize_vec(self.position)
        self.color_temperature, self.power = quantize(self.color_temperature, LIGHT_DECIMALS), quantize(self.power, LIGHT_DECIMALS)


@dataclass
class Layout:
    name: str
    stage: Stage
    objects: list[ObjectInstance] = field(default_factory=list)
    fixtures: list[LightFixture] = field(default_factory=list)
    seed: int | None = None
    reference: str | None = None  # the layout this one was rearranged from
    meta: dict[str, Any] = field(default_factory=dict)

    def object(self, oid: int) -> ObjectInstance:
        for o in self.objects:
            if o.id == oid:
                return o
        raise UnknownNameError(f"no object with id {oid} in layout '{self.name}'")

    def by_id(self) -> dict[int, ObjectInstance]:
        return {o.id: o for o in self.objects}

    def copy(self, **changes) -> "Layout":
        """Deep copy (through the file representation, so nothing is shared)."""
        lay = layout_from_dict(layout_to_dict(self), source=f"<copy of {self.name}>", validate=False)
        return replace(lay, **changes) if changes else lay


# --------------------------------------------------------------------------------------------
# ground-truth boxes


def object_box(obj: ObjectInstance) -> geo.OrientedBox:
    """Gravity-aligned box of an object instance in the world frame.

    For yaw-only rotations this is the exact rotated local box. For tilted objects it is the
    smallest box aligned with the object's heading that holds the rotated local box.
    """
    R = geo.quat_to_matrix(obj.rotation)
    p = np.asarray(obj.position, dtype=float)
    off = np.asarray(obj.box_offset, dtype=float)
    if geo.is_yaw_only(obj.rotation):
        c = R @ off + p
        return geo.OrientedBox(obj.id, obj.cls, tuple(float(v) for v in c), tuple(float(v) for v in obj.size), obj.yaw)
    half = np.asarray(obj.size, dtype=float) / 2.0
    signs = np.array([[sx, sy, sz] for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)])
    corners = (off + signs * half) @ R.T + p
    # heading: the local axis (x or y) that stays most horizontal
    ax = R[:, 0] if np.hypot(R[0, 0], R[1, 0]) >= np.hypot(R[0, 1], R[1, 1]) else R[:, 1]
    yaw = math.atan2(ax[1], ax[0])
    Rz = geo.rot_z(yaw)
    local = corners @ Rz  # into the heading frame
    lo, hi = local.min(axis=0), local.max(axis=0)
    c = Rz @ ((lo + hi) / 2.0)
    return geo.OrientedBox(obj.id, obj.cls, tuple(float(v) for v in c), tuple(float(v) for v in hi - lo), yaw)



def structure_boxes(stage: Stage) -> list[geo.OrientedBox]:
    """Boxes of every wall segment and of the floor and ceiling of every room."""
    boxes = []
    for k, w in enumerate(stage.walls):
        mid = (np.asarray(w.start) + np.asarray(w.end)) / 2.0
        yaw = math.atan2(w.end[1] - w.start[1], w.end[0] - w.start[0])
        boxes.append(
            geo.OrientedBox(
                WALL_ID_BASE + k, "wall", (float(mid[0]), float(mid[1]), stage.floor_z + w.height / 2.0),
                (w.length, w.thickness, w.height), yaw, kind="wall",
            )
        )
    for k, r in enumerate(stage.rooms):
        cx, cy = (r.rect[0] + r.rect[2]) / 2.0, (r.rect[1] + r.rect[3]) / 2.0
        sx, sy = r.rect[2] - r.rect[0], r.rect[3] - r.rect[1]
        boxes.append(geo.OrientedBox(FLOOR_ID_BASE + k, "floor", (cx, cy, stage.floor_z - STRUCT_SLAB / 2), (sx, sy, STRUCT_SLAB), 0.0, kind="floor"))
        top = stage.floor_z + stage.ceiling_height
        boxes.append(geo.OrientedBox(CEILING_ID_BASE + k, "ceiling", (cx, cy, top + STRUCT_SLAB / 2), (sx, sy, STRUCT_SLAB), 0.0, kind="ceiling"))
    return boxes


def layout_boxes(layout: Layout, structure: bool = True) -> list[geo.OrientedBox]:
    boxes = [object_box(o) for o in layout.objects]
    if structure:
        boxes += structure_boxes(layout.stage)
    return boxes


def boxes_document(layout: Layout, classes: ClassTable | None = None) -> dict:
    """The box file the relocalizer's map reads (``synth scene export-boxes``)."""
    classes = classes or class_table()
    movable = {o.id: o.movable for o in layout.objects}
    out = []
    for b in layout_boxes(layout):
        d = b.to_dict()  # boxes are computed (rotations, atan2): stored at the layout's precision too
        d["center"], d["size"] = _vec(d["center"]), _vec(d["size"])
        d["yaw"] = quantize(d["yaw"], QUAT_DECIMALS)
        d["movable"] = bool(movable.get(b.id, False))
        out.append(d)
    used = sorted({b["class"] for b in out})
    return {
        "format": BOXES_FORMAT,
        "layout": layout.name,
        "frame": FRAME_TEXT,
        "classes": {c: classes.id_of(c) for c in used},
        "boxes": out,
    }


# --------------------------------------------------------------------------------------------
# serialisation


def _vec(v, decimals: int = LENGTH_DECIMALS) -> list[float]:
    return list(quantize_vec(v, decimals))


def layout_to_dict(layout: Layout) -> dict:
    """The file representation; every number at its stored precision (see ``quantize``)."""
    st = layout.stage
    stage: dict[str, Any] = {"ceiling_height": quantize(st.ceiling_height), "floor_z": quantize(st.floor_z)}
    if st.asset is not None:
        stage["asset"] = st.asset
        stage["position"] = _vec(st.position)
        stage["rotation"] = list(quantize_quat(st.rotation))
    stage["rooms"] = [
        {"name": r.name, "type": r.type, "rect": _vec(r.rect), **({} if r.polygon is None else {"polygon": [_vec(p) for p in r.polygon]})}
        for r in st.rooms
    ]
    stage["walls"] = [
        {"id": w.id, "start": _vec(w.start), "end": _vec(w.end), "thickness": quantize(w.thickness), "height": quantize(w.height)}
        for w in st.walls
    ]
    stage["openings"] = [
        {
            "id": o.id, "kind": o.kind, "wall": o.wall, "offset": quantize(o.offset), "width": quantize(o.width),
            "bottom": quantize(o.bottom), "height": quantize(o.height), "rooms": list(o.rooms),
        }
        for o in st.openings
    ]
    objects = []
    for o in layout.objects:
        d: dict[str, Any] = {
            "id": o.id, "class": o.cls, "asset": o.asset, "position": _vec(o.position), "rotation": list(quantize_quat(o.rotation)),
            "size": _vec(o.size), "box_offset": _vec(o.box_offset), "support": o.support, "movable": bool(o.movable),
        }
        if quantize_vec(o.scale, SCALE_DECIMALS) != (1.0, 1.0, 1.0):
            d["scale"] = _vec(o.scale, SCALE_DECIMALS)
        if o.params:
            d["params"] = o.params
        objects.append(d)
    fixtures = []
    for f in layout.fixtures:
        d = {"id": f.id, "kind": f.kind, "position": _vec(f.position)}
        for key in ("room", "object", "opening"):
            if getattr(f, key) is not None:
                d[key] = getattr(f, key)
        d["color_temperature"] = quantize(f.color_temperature, LIGHT_DECIMALS)
        d["power"] = quantize(f.power, LIGHT_DECIMALS)
        fixtures.append(d)
    doc: dict[str, Any] = {"format": FORMAT, "name": layout.name}
    if layout.seed is not None:
        doc["seed"] = layout.seed
    if layout.reference is not None:
        doc["reference"] = layout.reference
    if layout.meta:
        doc["meta"] = layout.meta
    doc.update({"stage": stage, "objects": objects, "fixtures": fixtures})
    return doc


def layout_from_dict(doc, source: str = "<memory>", classes: ClassTable | None = None, validate: bool = True) -> Layout:
    """Build a Layout from its file representation, validating every field."""
    fields.mapping(source, doc, "(top level)", {"format", "name", "seed", "reference", "meta", "stage", "objects", "fixtures"}, {"name", "stage"}, what="a mapping")
    fmt = doc.get("format", FORMAT)
    if fmt != FORMAT:
        fields.fail(source, "format", f"expected '{FORMAT}', got {fmt!r}")
    name = fields.name_text(source, doc["name"])
    seed = None if doc.get("seed") is None else fields.integer(source, doc["seed"], "seed")
    reference = None if doc.get("reference") is None else fields.string(source, doc["reference"], "reference")
    meta = fields.mapping(source, doc.get("meta") or {}, "meta", what="a mapping")

    s = fields.mapping(source, doc["stage"], "stage", {"ceiling_height", "floor_z", "asset", "position", "rotation", "rooms", "walls", "openings"}, {"ceiling_height"}, what="a mapping")
    rooms = []
    for i, r in enumerate(fields.listing(source, s.get("rooms"), "stage.rooms", none_is_empty=True)):
        f = f"stage.rooms[{i}]"
        fields.mapping(source, r, f, {"name", "type", "rect", "polygon"}, {"name", "type", "rect"}, what="a mapping")
        rect = fields.vector(source, r["rect"], f + ".rect", 4)
        if rect[2] <= rect[0] or rect[3] <= rect[1]:
            fields.fail(source, f + ".rect", f"expected xmin < xmax and ymin < ymax, got {list(rect)}")
        polygon = None
        if r.get("polygon") is not None:
            pts = fields.listing(source, r["polygon"], f + ".polygon", none_is_empty=True)
            if len(pts) < 3:
                fields.fail(source, f + ".polygon", f"expected at least 3 vertices, got {len(pts)}")
            polygon = tuple(tuple(fields.vector(source, p, f"{f}.polygon[{k}]", 2)) for k, p in enumerate(pts))
            q = np.asarray(polygon)
            if q[:, 0].min() < rect[0] - 1e-3 or q[:, 0].max() > rect[2] + 1e-3 or q[:, 1].min() < rect[1] - 1e-3 or q[:, 1].max() > rect[3] + 1e-3:
                fields.fail(source, f + ".polygon", "extends outside the room's rect")
        rooms.append(Room(fields.string(source, r["name"], f + ".name"), fields.string(source, r["type"], f + ".type"), rect, polygon))
    walls = []
    for i, w in enumerate(fields.listing(source, s.get("walls"), "stage.walls", none_is_empty=True)):
        f = f"stage.walls[{i}]"
        fields.mapping(source, w, f, {"id", "start", "end", "thickness", "height"}, {"id", "start", "end", "thickness", "height"}, what="a mapping")
        wall = Wall(fields.string(source, w["id"], f + ".id"), fields.vector(source, w["start"], f + ".start", 2), fields.vector(source, w["end"], f + ".end", 2),
                    fields.number(source, w["thickness"], f + ".thickness", positive=True), fields.number(source, w["height"], f + ".height", positive=True))
        if wall.length <= 0:
            fields.fail(source, f, "wall has zero length")
        walls.append(wall)
    wall_ids = {w.id for w in walls}
    room_names = {r.name for r in rooms}
    openings = []
    for i, o in enumerate(fields.listing(source, s.get("openings"), "stage.openings", none_is_empty=True)):
        f = f"stage.openings[{i}]"
        fields.mapping(source, o, f, {"id", "kind", "wall", "offset", "width", "bottom", "height", "rooms"}, {"id", "kind", "wall", "offset", "width", "height"}, what="a mapping")
        kind = fields.string(source, o["kind"], f + ".kind")
        if kind not in ("door", "window"):
            fields.fail(source, f + ".kind", f"expected 'door' or 'window', got {kind!r}")
        wid = fields.string(source, o["wall"], f + ".wall")
        if wid not in wall_ids:
            fields.fail(source, f + ".wall", f"no wall '{wid}' in stage.walls")
        orooms = tuple(fields.string(source, x, f + ".rooms") for x in fields.listing(source, o.get("rooms"), f + ".rooms", none_is_empty=True))
        for rn in orooms:
            if rn not in room_names:
                fields.fail(source, f + ".rooms", f"no room '{rn}' in stage.rooms")
        openings.append(Opening(fields.string(source, o["id"], f + ".id"), kind, wid, fields.number(source, o["offset"], f + ".offset"),
                                fields.number(source, o["width"], f + ".width", positive=True), fields.number(source, o.get("bottom", 0.0), f + ".bottom", lo=0),
                                fields.number(source, o["height"], f + ".height", positive=True), orooms))
    stage = Stage(
        ceiling_height=fields.number(source, s["ceiling_height"], "stage.ceiling_height", positive=True),
        rooms=rooms, walls=walls, openings=openings,
        floor_z=fields.number(source, s.get("floor_z", 0.0), "stage.floor_z"),
        asset=None if s.get("asset") is None else fields.string(source, s["asset"], "stage.asset"),
        position=fields.vector(source, s.get("position", [0, 0, 0]), "stage.position", 3),
        rotation=_quat(source, s.get("rotation", [1, 0, 0, 0]), "stage.rotation"),
    )

    classes = classes or class_table()
    objects = []
    seen: set[int] = set()
    for i, o in enumerate(fields.listing(source, doc.get("objects"), "objects", none_is_empty=True)):
        f = f"objects[{i}]"
        fields.mapping(source, o, f, {"id", "class", "asset", "position", "rotation", "yaw_deg", "size", "box_offset", "support", "movable", "scale", "params"},
                  {"id", "class", "asset", "position", "size"}, what="a mapping")
        oid = fields.integer(source, o["id"], f + ".id")
        if not 1 <= oid <= MAX_OBJECT_ID:
            fields.fail(source, f + ".id", f"object ids must be 1..{MAX_OBJECT_ID}, got {oid}")
        if oid in seen:
            fields.fail(source, f + ".id", f"duplicate object id {oid}")
        seen.add(oid)
        cls = fields.string(source, o["class"], f + ".class")
        if cls not in classes or classes.get(cls).structure:
            fields.fail(source, f + ".class", f"unknown object class '{cls}' (see {classes.source})")
        if "rotation" in o and "yaw_deg" in o:
            fields.fail(source, f, "give either rotation (w, x, y, z) or yaw_deg, not both")
        if "yaw_deg" in o:
            rot = geo.yaw_to_quat(math.radians(fields.number(source, o["yaw_deg"], f + ".yaw_deg")))
        else:
            rot = _quat(source, o.get("rotation", [1, 0, 0, 0]), f + ".rotation")
        size = fields.vector(source, o["size"], f + ".size", 3, positive=True)
        support = fields.string(source, o.get("support", classes.get(cls).support if classes.get(cls).support != "surface" else "floor"), f + ".support")
        _check_support(source, support, f + ".support", wall_ids)
        params = fields.mapping(source, o.get("params") or {}, f + ".params", what="a mapping")
        movable = fields.boolean(source, o.get("movable", classes.get(cls).movable), f + ".movable")
        asset = fields.string(source, o["asset"], f + ".asset")
        if asset.startswith("proc:"):
            gen = asset[5:]
            if gen not in classes or classes.get(gen).structure:
                fields.fail(source, f + ".asset", f"unknown procedural asset '{gen}' (generators exist for the object classes of {classes.source})")
        elif not any(asset.startswith(pre) and len(asset) > len(pre) for pre in MESH_ASSET_PREFIXES):
            fields.fail(source, f + ".asset", f"expected 'proc:<class>', 'replicacad:<glb path>' or 'replicacad-urdf:<urdf path>', got {asset!r}")
        objects.append(ObjectInstance(
            id=oid, cls=cls, asset=asset, position=fields.vector(source, o["position"], f + ".position", 3), rotation=rot, size=size,
            box_offset=fields.vector(source, o.get("box_offset", [0.0, 0.0, size[2] / 2.0]), f + ".box_offset", 3),
            support=support, movable=movable, scale=fields.vector(source, o.get("scale", [1, 1, 1]), f + ".scale", 3, positive=True), params=params,
        ))
    for i, o in enumerate(objects):
        par = o.support_parent()
        if par and par[0] not in seen:
            fields.fail(source, f"objects[{i}].support", f"object {o.id} stands on object {par[0]}, which is not in the layout")
        if par and par[0] == o.id:
            fields.fail(source, f"objects[{i}].support", f"object {o.id} cannot stand on itself")

    fixtures = []
    fids: set[str] = set()
    for i, x in enumerate(fields.listing(source, doc.get("fixtures"), "fixtures", none_is_empty=True)):
        f = f"fixtures[{i}]"
        fields.mapping(source, x, f, {"id", "kind", "position", "room", "object", "opening", "color_temperature", "power"}, {"id", "kind", "position"}, what="a mapping")
        fid = fields.string(source, x["id"], f + ".id")
        if fid in fids:
            fields.fail(source, f + ".id", f"duplicate fixture id '{fid}'")
        fids.add(fid)
        kind = fields.string(source, x["kind"], f + ".kind")
        if kind not in ("lamp", "ceiling", "window"):
            fields.fail(source, f + ".kind", f"expected lamp, ceiling or window, got {kind!r}")
        obj = None if x.get("object") is None else fields.integer(source, x["object"], f + ".object")
        if obj is not None and obj not in seen:
            fields.fail(source, f + ".object", f"no object with id {obj}")
        opening = None if x.get("opening") is None else fields.string(source, x["opening"], f + ".opening")
        if opening is not None and opening not in {o.id for o in openings}:
            fields.fail(source, f + ".opening", f"no opening '{opening}' in stage.openings")
        fixtures.append(LightFixture(
            id=fid, kind=kind, position=fields.vector(source, x["position"], f + ".position", 3),
            room=None if x.get("room") is None else fields.string(source, x["room"], f + ".room"), object=obj, opening=opening,
            color_temperature=fields.number(source, x.get("color_temperature", 3000.0), f + ".color_temperature", positive=True),
            power=fields.number(source, x.get("power", 60.0), f + ".power", lo=0),
        ))
    return Layout(name=name, stage=stage, objects=objects, fixtures=fixtures, seed=seed, reference=reference, meta=dict(meta))


def _quat(source: str, v, field: str) -> geo.Quat:
    """A rotation (w, x, y, z) of norm 1 within 1e-3 (``vrformats.fields.unit_quat``), kept as written."""
    q = fields.vector(source, v, field, 4)
    fields.unit_quat(source, list(q), field)
    return q


def _check_support(source: str, support: str, field: str, wall_ids: set[str]) -> None:
    if support in ("floor", "ceiling", "free"):
        return
    parts = support.split(":")
    if parts[0] == "wall" and len(parts) == 2:
        if parts[1] not in wall_ids:
            fields.fail(source, field, f"no wall '{parts[1]}' in stage.walls")
        return
    if parts[0] == "object" and len(parts) == 3 and parts[1].isdigit() and parts[2].isdigit():
        return
    fields.fail(source, field, f"expected floor, ceiling, free, wall:<id> or object:<id>:<surface>, got {support!r}")


class _Dumper(yaml.SafeDumper):
    pass


def _represent_list(dumper, data):
    flow = all(isinstance(x, (int, float, str, bool)) or x is None for x in data) and len(data) <= 8
    return dumper.represent_sequence("tag:yaml.org,2002:seq", data, flow_style=flow)


_Dumper.add_representer(list, _represent_list)
_Dumper.add_representer(tuple, _represent_list)


def dump_yaml(doc) -> str:
    return yaml.dump(doc, Dumper=_Dumper, sort_keys=False, default_flow_style=False, width=120, allow_unicode=True)


def save_layout(layout: Layout, path: str | Path) -> Path:
    """Write the layout as YAML (atomically: temporary file, then rename)."""
    return write_text_atomic(path, dump_yaml(layout_to_dict(layout)))


def resolve_layout_path(name_or_path: str | Path) -> Path:
    """A built-in layout name (``apt_0``) or a path to a layout file."""
    p = Path(name_or_path)
    if p.suffix in (".yaml", ".yml", ".json") or p.exists():
        return p
    cand = layouts_dir() / f"{name_or_path}.yaml"
    if cand.exists():
        return cand
    known = ", ".join(list_layouts()) or "none"
    raise UnknownNameError(f"unknown layout '{name_or_path}' (no {cand}); known layouts: {known}")


def load_layout(name_or_path: str | Path, classes: ClassTable | None = None) -> Layout:
    path = resolve_layout_path(name_or_path)
    return layout_from_dict(read_yaml(path), source=str(path), classes=classes)


def list_layouts() -> list[str]:
    d = layouts_dir()
    return sorted(p.stem for p in d.glob("*.yaml")) if d.exists() else []
