"""Renderable geometry of a layout: the one source both renderers draw from.

``layout_parts`` turns a layout into parts, each a mesh in its own local frame plus the matrix
placing it in the world, with the instance id, semantic id, material name and (for emitting parts)
the light fixture it belongs to. The Blender renderer builds one Blender object per part (so
procedural textures move with the object); the fast Open3D renderer ray-casts the same parts in
world coordinates. Because both read these parts, their depth and instance images must agree.

Procedural stages are built here: walls as boxes with door and window holes cut out, a floor slab
(top at ``floor_z``) and a ceiling slab per room, and a floor slab under every door opening.
Windows and doors are open holes (no glass, no door leaves): daylight comes in through them, and
rays that leave the flat hit nothing (depth 0, instance 0).
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass

import numpy as np
import trimesh

from formats.boxes import CEILING_ID_BASE, FLOOR_ID_BASE, STRUCT_SLAB, WALL_ID_BASE

from . import assets
from . import geometry as geo
from .classes import class_table
from .scene import Layout, ObjectInstance, Stage

ROOM_FLOOR_MATERIAL = {"bathroom": "floor_tile", "kitchen": "floor_tile"}  # others: floor_wood


@dataclass
class RenderPart:
    name: str  # unique within the layout, e.g. "obj12/seat", "W3/2", "floor/living"
    instance_id: int
    semantic_id: int
    material: str
    mesh: trimesh.Trimesh  # in the part's local frame
    matrix: np.ndarray  # 4x4 local-to-world (scale included)
    color: tuple[float, float, float] | None = None
    emissive: bool = False
    fixture: str | None = None  # light fixture id of an emitting part
    seed: int = 0  # material variation (e.g. which abstract painting a canvas shows)

    def world_vertices(self) -> np.ndarray:
        v = np.asarray(self.mesh.vertices, dtype=np.float64)
        return v @ self.matrix[:3, :3].T + self.matrix[:3, 3]


def _box_mesh(lo, hi) -> trimesh.Trimesh:
    lo, hi = np.asarray(lo, float), np.asarray(hi, float)
    m = trimesh.creation.box(extents=hi - lo)
    m.apply_translation((lo + hi) / 2.0)
    return m


def _pose_matrix(position, rotation, scale=(1.0, 1.0, 1.0)) -> np.ndarray:
    T = np.eye(4)
    T[:3, :3] = geo.quat_to_matrix(rotation) @ np.diag(scale)
    T[:3, 3] = position
    return T


def wall_pieces(stage: Stage, wall_index: int) -> list[tuple[np.ndarray, np.ndarray]]:
    """Boxes (lo, hi) in the wall's frame (x along the wall from its start, y across, z up) that
    make up the wall with its openings cut out."""
    w = stage.walls[wall_index]
    L, t, H = w.length, w.thickness, w.height
    holes = sorted(
        (max(0.0, o.offset - o.width / 2), min(L, o.offset + o.width / 2), o.bottom, min(H, o.bottom + o.height))
        for o in stage.openings
        if o.wall == w.id
    )
    pieces = []
    x = 0.0
    for a, b, z0, z1 in holes:
        if a > x + 1e-6:
            pieces.append(((x, -t / 2, 0.0), (a, t / 2, H)))
        if z0 > 1e-6:
            pieces.append(((a, -t / 2, 0.0), (b, t / 2, z0)))
        if z1 < H - 1e-6:
            pieces.append(((a, -t / 2, z1), (b, t / 2, H)))
        x = max(x, b)
    if x < L - 1e-6:
        pieces.append(((x, -t / 2, 0.0), (L, t / 2, H)))
    return [(np.array(lo), np.array(hi)) for lo, hi in pieces]


def stage_parts(layout: Layout) -> list[RenderPart]:
    st = layout.stage
    ct = class_table()
    parts: list[RenderPart] = []
    if st.asset is not None:  # a stage mesh (ReplicaCAD): one part, labelled as wall
        from .replicacad import load_asset_mesh

        mesh = load_asset_mesh(layout.meta.get("root", ""), st.asset)
        parts.append(RenderPart("stage", WALL_ID_BASE, ct.id_of("wall"), "wall_paint", mesh, _pose_matrix(st.position, st.rotation)))
    z0 = st.floor_z
    for k, w in enumerate(st.walls):
        yaw = math.atan2(w.end[1] - w.start[1], w.end[0] - w.start[0])
        T = np.eye(4)
        T[:3, :3] = geo.rot_z(yaw)
        T[:3, 3] = (w.start[0], w.start[1], z0)
        for j, (lo, hi) in enumerate(wall_pieces(st, k)):
            parts.append(RenderPart(f"{w.id}/{j}", WALL_ID_BASE + k, ct.id_of("wall"), "wall_paint", _box_mesh(lo, hi), T, seed=k))
    room_index = {r.name: k for k, r in enumerate(st.rooms)}
    for k, r in enumerate(st.rooms):
        xmin, ymin, xmax, ymax = r.rect
        mat = ROOM_FLOOR_MATERIAL.get(r.type, "floor_wood")
        parts.append(RenderPart(f"floor/{r.name}", FLOOR_ID_BASE + k, ct.id_of("floor"), mat,
                                _box_mesh((xmin, ymin, z0 - STRUCT_SLAB), (xmax, ymax, z0)), np.eye(4), seed=k))
        top = z0 + st.ceiling_height
        parts.append(RenderPart(f"ceiling/{r.name}", CEILING_ID_BASE + k, ct.id_of("ceiling"), "ceiling_paint",
                                _box_mesh((xmin, ymin, top), (xmax, ymax, top + STRUCT_SLAB)), np.eye(4), seed=k))
    # thresholds: the floor inside each door opening belongs to the first room the door opens to
    for op in st.openings:
        if op.kind != "door" or not op.rooms:
            continue
        wi = next(i for i, w in enumerate(st.walls) if w.id == op.wall)
        w = st.walls[wi]
        yaw = math.atan2(w.end[1] - w.start[1], w.end[0] - w.start[0])
        T = np.eye(4)
        T[:3, :3] = geo.rot_z(yaw)
        T[:3, 3] = (w.start[0], w.start[1], z0)
        k = room_index.get(op.rooms[0], 0)
        r = st.rooms[k]
        lo = (op.offset - op.width / 2, -w.thickness / 2, -STRUCT_SLAB)
        hi = (op.offset + op.width / 2, w.thickness / 2, 0.0)
        parts.append(RenderPart(f"threshold/{op.id}", FLOOR_ID_BASE + k, ct.id_of("floor"),
                                ROOM_FLOOR_MATERIAL.get(r.type, "floor_wood"), _box_mesh(lo, hi), T, seed=k))
    return parts


@functools.lru_cache(maxsize=512)
def _proc_parts(cls: str, size: tuple, params_key: str) -> tuple:
    import json

    return tuple(assets.make_parts(cls, size, json.loads(params_key)))


def object_parts(layout: Layout, obj: ObjectInstance) -> list[RenderPart]:
    import json

    sem = class_table().id_of(obj.cls)
    fixture = next((f.id for f in layout.fixtures if f.object == obj.id), None)
    if obj.asset.startswith("proc:"):
        pieces = _proc_parts(obj.asset[5:], tuple(obj.size), json.dumps(obj.params, sort_keys=True))
        T = _pose_matrix(obj.position, obj.rotation, obj.scale)
        seed = int(obj.params.get("art_seed", obj.id)) if isinstance(obj.params.get("art_seed", obj.id), int) else obj.id
        return [
            RenderPart(f"obj{obj.id}/{p.name}", obj.id, sem, p.material, p.mesh, T, p.color, p.emissive,
                       fixture if p.emissive else None, seed)
            for p in pieces
        ]
    from .replicacad import load_asset_mesh

    mesh = load_asset_mesh(layout.meta.get("root", ""), obj.asset)
    T = _pose_matrix(obj.position, obj.rotation, obj.scale)
    return [RenderPart(f"obj{obj.id}/mesh", obj.id, sem, "painted", mesh, T, seed=obj.id)]


def layout_parts(layout: Layout) -> list[RenderPart]:
    """Every renderable part of the layout: stage first, then objects in id order."""
    parts = stage_parts(layout)
    for o in sorted(layout.objects, key=lambda o: o.id):
        parts.extend(object_parts(layout, o))
    return parts


def instance_classes(layout: Layout) -> dict[int, int]:
    """instance id -> semantic id, for every object and structure element of the layout."""
    ct = class_table()
    out = {o.id: ct.id_of(o.cls) for o in layout.objects}
    st = layout.stage
    out.update({WALL_ID_BASE + k: ct.id_of("wall") for k in range(max(len(st.walls), 1 if st.asset else 0))})
    out.update({FLOOR_ID_BASE + k: ct.id_of("floor") for k in range(len(st.rooms))})
    out.update({CEILING_ID_BASE + k: ct.id_of("ceiling") for k in range(len(st.rooms))})
    return out
