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

Mesh assets (ReplicaCAD) are drawn with their own glTF materials: ``material == "gltf"`` means
"use ``mesh.visual``" (see :class:`RenderPart`), one part per glTF primitive (``synth.mesh.gltf``):

* ``"replicacad:<glb>"`` objects: one part per primitive, placed by ``pose @ diag(scale)``.
* ``"replicacad-urdf:<urdf>"`` objects (articulated, ``synth.mesh.urdf``): one part per primitive of
  every link visual, placed by ``pose @ diag(scale) @ visual.matrix @ diag(visual.scale)``, in the
  instance's ``params["joint_state"]``.
* A stage with an ``asset``: its primitives placed by the stage pose. When the stage has derived
  structure (``walls`` or ``rooms``), every triangle gets the id that
  ``synth.mesh.stage_structure.face_ids`` gives it (wall ``WALL_ID_BASE+k``, floor ``FLOOR_ID_BASE+k``,
  ceiling ``CEILING_ID_BASE+k``) and each primitive is split into one part per id (UVs kept), so
  walls, floors and ceilings are separate instances in both renderers. Triangles it leaves
  unclassified (0: door and window frames, skirting, fittings) take the id of the NEAREST WALL
  (distance from the triangle's centroid to the wall's centre line, in plan): instance 0 keeps
  meaning "nothing", and every stage pixel has depth and an id in both renderers (the Blender
  geometry pass drops instance-0 pixels). Without walls (rooms only) they take the floor of the
  nearest room below half the storey height, its ceiling above. No procedural wall, floor or
  ceiling boxes are drawn for such a stage: its walls and rooms only describe the mesh. A stage
  without derived structure (older imports) is drawn as before: all of it instance
  ``WALL_ID_BASE``, semantic "wall".
* Emission: a primitive whose glTF material has a non-zero ``emissiveFactor`` is an emitting part
  (``emissive=True``). It belongs to its object's own light fixture if the object has one, else to
  the nearest fixture (``layout.fixtures``, kinds other than "window") within
  ``EMITTER_FIXTURE_RADIUS`` of the part's bounding-box centre; the lighting then switches it
  (``synth.scene.lighting.resolve_lighting``'s ``emission[fixture]``). An emitter with no fixture that
  near has ``fixture=None`` and stays OFF in every lighting preset.
"""

from __future__ import annotations

import json

import functools
import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import trimesh

from vrformats.boxes import CEILING_ID_BASE, FLOOR_ID_BASE, STRUCT_SLAB, WALL_ID_BASE
from vrformats.errors import SceneFormatError, UnknownNameError
from vrformats.fields import is_number

from ..assets import registry as assets
from ..scene import geometry as geo
from ..scene.classes import class_table
from ..scene.model import GLB_ASSET_PREFIX, URDF_ASSET_PREFIX, Layout, ObjectInstance, Stage

ROOM_FLOOR_MATERIAL = {"bathroom": "floor_tile", "kitchen": "floor_tile"}  # others: floor_wood
GLTF_MATERIAL = "gltf"  # RenderPart.material: draw the mesh's own glTF material (mesh.visual)
EMITTER_FIXTURE_RADIUS = 1.5  # m: an emissive glTF part belongs to a light fixture at most this far away
GLB_PREFIX = GLB_ASSET_PREFIX
URDF_PREFIX = URDF_ASSET_PREFIX


@dataclass
class RenderPart:
    """One mesh of the layout, in its own local frame, with what the renderers need.

    ``material`` names a procedural material (``synth.blender.materials``), or is ``"gltf"``
    (:data:`GLTF_MATERIAL`): then ``mesh.visual`` is a ``trimesh.visual.TextureVisuals`` (UVs and a
    ``PBRMaterial``) and ``mesh.metadata["gltf"]`` identifies the glTF file and material
    (``synth.mesh.gltf``); ``color`` and ``seed`` are unused. The fast renderer reads only vertices
    and faces."""

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


FINISH_MATERIALS = {"floor_material": ("floor_wood", "floor_tile")}


def stage_finishes(layout: Layout) -> dict:
    """The layout's ``meta.finishes`` (training layouts, ``synth.trainset.appearance``): optional
    ``wall_color``, ``ceiling_color``, ``floor_color`` (linear RGB in [0, 1]) and ``floor_material``
    (floor_wood | floor_tile) for a procedural stage; {} when absent. A bad value is a
    SceneFormatError naming the layout and the key."""
    fin = (layout.meta or {}).get("finishes")
    if fin is None:
        return {}
    where = f"layout {layout.name}"
    if not isinstance(fin, dict):
        raise SceneFormatError(where, "meta.finishes", "expected a mapping")
    out = {}
    for key, val in fin.items():
        if key in FINISH_MATERIALS:
            if val not in FINISH_MATERIALS[key]:
                raise SceneFormatError(where, f"meta.finishes.{key}", f"expected one of {', '.join(FINISH_MATERIALS[key])}, got {val!r}")
            out[key] = val
        elif key in ("wall_color", "ceiling_color", "floor_color"):
            ok = isinstance(val, (list, tuple)) and len(val) == 3 and all(
                is_number(v) and 0.0 <= v <= 1.0 for v in val)
            if not ok:
                raise SceneFormatError(where, f"meta.finishes.{key}", f"expected three numbers in [0, 1], got {val!r}")
            out[key] = tuple(float(v) for v in val)
        else:
            raise SceneFormatError(where, f"meta.finishes.{key}",
                                   "unknown key; allowed: ceiling_color, floor_color, floor_material, wall_color")
    return out


def stage_parts(layout: Layout) -> list[RenderPart]:
    st = layout.stage
    ct = class_table()
    parts: list[RenderPart] = []
    if st.asset is not None:  # a stage mesh (ReplicaCAD): its own triangles only, no boxes
        return _mesh_stage_parts(layout)
    fin = stage_finishes(layout)
    wall_c, ceil_c, floor_c = fin.get("wall_color"), fin.get("ceiling_color"), fin.get("floor_color")

    def floor_mat(room_type: str) -> str:
        return fin.get("floor_material") or ROOM_FLOOR_MATERIAL.get(room_type, "floor_wood")
    z0 = st.floor_z
    for k, w in enumerate(st.walls):
        yaw = math.atan2(w.end[1] - w.start[1], w.end[0] - w.start[0])
        T = np.eye(4)
        T[:3, :3] = geo.rot_z(yaw)
        T[:3, 3] = (w.start[0], w.start[1], z0)
        for j, (lo, hi) in enumerate(wall_pieces(st, k)):
            parts.append(RenderPart(f"{w.id}/{j}", WALL_ID_BASE + k, ct.id_of("wall"), "wall_paint", _box_mesh(lo, hi), T,
                                    color=wall_c, seed=k))
    room_index = {r.name: k for k, r in enumerate(st.rooms)}
    for k, r in enumerate(st.rooms):
        xmin, ymin, xmax, ymax = r.rect
        parts.append(RenderPart(f"floor/{r.name}", FLOOR_ID_BASE + k, ct.id_of("floor"), floor_mat(r.type),
                                _box_mesh((xmin, ymin, z0 - STRUCT_SLAB), (xmax, ymax, z0)), np.eye(4),
                                color=floor_c, seed=k))
        top = z0 + st.ceiling_height
        parts.append(RenderPart(f"ceiling/{r.name}", CEILING_ID_BASE + k, ct.id_of("ceiling"), "ceiling_paint",
                                _box_mesh((xmin, ymin, top), (xmax, ymax, top + STRUCT_SLAB)), np.eye(4),
                                color=ceil_c, seed=k))
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
                                floor_mat(r.type), _box_mesh(lo, hi), T, color=floor_c, seed=k))
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
    T = _pose_matrix(obj.position, obj.rotation, obj.scale)
    from ..mesh.gltf import load_glb_parts

    if obj.asset.startswith(GLB_PREFIX) and len(obj.asset) > len(GLB_PREFIX):
        prims = load_glb_parts(_asset_file(layout, obj.asset, GLB_PREFIX, "GLB"))
        return [_gltf_part(layout, f"obj{obj.id}/{j}", obj.id, sem, m, T, fixture) for j, m in enumerate(prims)]
    if obj.asset.startswith(URDF_PREFIX) and len(obj.asset) > len(URDF_PREFIX):
        from ..mesh.urdf import urdf_visuals

        path = _asset_file(layout, obj.asset, URDF_PREFIX, "URDF")
        state = obj.params.get("joint_state")
        visuals = urdf_visuals(path, state) if state else urdf_visuals(path)
        parts = []
        for i, vis in enumerate(visuals):
            Tv = T @ np.asarray(vis.matrix, dtype=np.float64) @ np.diag([*np.asarray(vis.scale, dtype=np.float64), 1.0])
            parts.extend(_gltf_part(layout, f"obj{obj.id}/{i}.{j}", obj.id, sem, m, Tv, fixture)
                         for j, m in enumerate(load_glb_parts(vis.glb)))
        return parts
    raise UnknownNameError(f"object {obj.id}: unknown asset {obj.asset!r} (expected 'proc:<class>', "
                           f"'{GLB_PREFIX}<glb path>' or '{URDF_PREFIX}<urdf path>')")


# --------------------------------------------------------------------------------------------
# mesh assets (glTF)


def _asset_file(layout: Layout, asset: str, prefix: str, what: str) -> Path:
    """The file of a mesh asset, relative to ``layout.meta["root"]``."""
    root = layout.meta.get("root")
    if not root:
        raise SceneFormatError(f"<layout {layout.name}>", "meta.root", f"no dataset folder for mesh asset {asset!r}")
    path = Path(root).expanduser() / asset[len(prefix):]
    if not path.is_file():
        raise SceneFormatError(path, None, f"{what} not found (asset {asset!r})")
    return path


def _emitter_fixture(layout: Layout, own: str | None, center: np.ndarray) -> str | None:
    if own is not None:
        return own
    best = None
    for f in layout.fixtures:
        if f.kind == "window":
            continue
        d = float(np.linalg.norm(np.asarray(f.position, dtype=np.float64) - center))
        if d <= EMITTER_FIXTURE_RADIUS and (best is None or d < best[0]):
            best = (d, f.id)
    return None if best is None else best[1]


def _gltf_part(layout: Layout, name: str, iid: int, sid: int, mesh: trimesh.Trimesh, T: np.ndarray,
               own_fixture: str | None = None) -> RenderPart:
    from ..mesh.gltf import is_emissive

    emissive = is_emissive(mesh)
    fixture = None
    if emissive:
        c = np.asarray(mesh.bounds, dtype=np.float64).mean(axis=0)
        fixture = _emitter_fixture(layout, own_fixture, T[:3, :3] @ c + T[:3, 3])
    return RenderPart(name, iid, sid, GLTF_MATERIAL, mesh, T, None, emissive, fixture, 0)


def _triangle_frames(mesh: trimesh.Trimesh, T: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """World centroids and unit normals (zero for degenerate triangles) of a part's triangles."""
    v = np.asarray(mesh.vertices, dtype=np.float64) @ T[:3, :3].T + T[:3, 3]
    tri = v[np.asarray(mesh.faces)]
    n = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    ln = np.linalg.norm(n, axis=1, keepdims=True)
    return tri.mean(axis=1), np.divide(n, ln, out=np.zeros_like(n), where=ln > 0)


def nearest_structure_ids(stage: Stage, points: np.ndarray) -> np.ndarray:
    """Structure id for stage triangles that ``face_ids`` leaves unclassified: the nearest wall
    (plan distance to its centre line); without walls the nearest room's floor (below half the
    storey height) or ceiling (above)."""
    p = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    out = np.zeros(len(p), np.int64)
    if len(p) == 0:
        return out
    if stage.walls:
        a = np.array([w.start for w in stage.walls], dtype=np.float64)
        d = np.array([w.end for w in stage.walls], dtype=np.float64) - a
        L2 = np.maximum((d * d).sum(axis=1), 1e-12)
        for s in range(0, len(p), 4096):
            q = p[s:s + 4096, None, :2] - a[None]
            t = np.clip((q * d[None]).sum(-1) / L2, 0.0, 1.0)
            dist = np.linalg.norm(q - t[..., None] * d[None], axis=-1)
            out[s:s + 4096] = WALL_ID_BASE + np.argmin(dist, axis=1)
        return out
    rect = np.array([r.rect for r in stage.rooms], dtype=np.float64)
    dx = np.maximum(np.maximum(rect[None, :, 0] - p[:, None, 0], p[:, None, 0] - rect[None, :, 2]), 0.0)
    dy = np.maximum(np.maximum(rect[None, :, 1] - p[:, None, 1], p[:, None, 1] - rect[None, :, 3]), 0.0)
    k = np.argmin(np.hypot(dx, dy), axis=1)
    up = p[:, 2] > stage.floor_z + stage.ceiling_height / 2.0
    return np.where(up, CEILING_ID_BASE, FLOOR_ID_BASE) + k


STAGE_MAX_EDGE = 0.25  # m: floor and ceiling triangles longer than this are split before they get room ids


def _refine_horizontal(m, T: np.ndarray, max_edge: float | None = None):
    """The stage primitive ``m`` with its horizontal triangles (floor, ceiling) split at edge midpoints
    until no edge is longer than ``max_edge`` in the world (UVs and normals interpolated).

    ``face_ids`` labels whole triangles by their centroid: one floor quad spanning two rooms would
    otherwise give all of it to one room's floor. After splitting, a room boundary is off by at
    most ``max_edge`` -- and room boundaries lie under walls, where the floor is not seen."""
    import trimesh

    from ..mesh.gltf import make_part

    max_edge = STAGE_MAX_EDGE if max_edge is None else max_edge
    meta = m.metadata["gltf"]
    v, f = np.asarray(m.vertices, dtype=np.float64), np.asarray(m.faces, dtype=np.int64)
    attrs = {}
    if m.visual.uv is not None:
        attrs["uv"] = np.asarray(m.visual.uv, dtype=np.float64)
    if meta.get("normals"):
        attrs["normals"] = np.asarray(m.vertex_normals, dtype=np.float64)
    changed = False
    for _ in range(16):
        w = v @ T[:3, :3].T + T[:3, 3]
        tri = w[f]
        n = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
        horizontal = np.abs(n[:, 2]) > 0.9 * np.linalg.norm(n, axis=1)
        longest = np.max(np.linalg.norm(tri - np.roll(tri, 1, axis=1), axis=2), axis=1)
        sel = np.flatnonzero(horizontal & (longest > max_edge))
        if len(sel) == 0:
            break
        v, f, attrs = trimesh.remesh.subdivide(v, f, face_index=sel, vertex_attributes=attrs or None) if attrs else \
            (*trimesh.remesh.subdivide(v, f, face_index=sel), {})
        changed = True
    if not changed:
        return m
    normals = attrs.get("normals")
    if normals is not None:
        normals = normals / np.maximum(np.linalg.norm(normals, axis=1, keepdims=True), 1e-12)
    return make_part(v, f, attrs.get("uv"), m.visual.material, normals, meta)


def _mesh_stage_parts(layout: Layout) -> list[RenderPart]:
    from ..mesh.gltf import load_glb_parts, submesh

    st = layout.stage
    ct = class_table()
    sem = {WALL_ID_BASE: ct.id_of("wall"), FLOOR_ID_BASE: ct.id_of("floor"), CEILING_ID_BASE: ct.id_of("ceiling")}
    prims = load_glb_parts(_asset_file(layout, st.asset, GLB_PREFIX, "GLB"))
    T = _pose_matrix(st.position, st.rotation)
    if not st.walls and not st.rooms:  # no derived structure: all of it one wall instance, as before
        return [_gltf_part(layout, f"stage/{j}", WALL_ID_BASE, sem[WALL_ID_BASE], m, T) for j, m in enumerate(prims)]
    from ..mesh.stage_structure import face_ids

    prims = [_refine_horizontal(m, T) for m in prims]
    frames = [_triangle_frames(m, T) for m in prims]
    centroids = np.concatenate([c for c, _ in frames])
    normals = np.concatenate([n for _, n in frames])

    def compute() -> np.ndarray:
        ids = np.asarray(face_ids(st, centroids, normals), dtype=np.int64).reshape(-1)
        if len(ids) != len(centroids):
            raise ValueError(f"face_ids gave {len(ids)} ids for {len(centroids)} stage triangles")
        free = ids == 0
        if free.any():
            ids[free] = nearest_structure_ids(st, centroids[free])
        return ids

    # the same in every chunk of a job, and about 20 s for a ReplicaCAD apartment: cached (synth.render.cache)
    from ..scene.model import layout_to_dict
    from .cache import cached_array, code_digest, digest_of_file

    key = [digest_of_file(_asset_file(layout, st.asset, GLB_PREFIX, "GLB")),
           json.dumps(layout_to_dict(layout)["stage"], sort_keys=True, default=str),
           code_digest("synth.mesh.stage_structure", "synth.render.meshes", "synth.mesh.gltf", "synth.scene.model")]
    ids = np.array(cached_array("stage_face_ids", key, compute,
                                validate=lambda a: a.dtype == np.int64 and a.shape == (len(centroids),)))
    parts: list[RenderPart] = []
    off = 0
    for j, m in enumerate(prims):
        mine = ids[off: off + len(m.faces)]
        off += len(m.faces)
        uniq = np.unique(mine)  # once per primitive (not once per id: 7 s of sorting for a ReplicaCAD stage)
        for iid in uniq:
            base = int(iid) // 1000 * 1000
            if base not in sem:
                raise ValueError(f"face_ids gave {int(iid)}, not a wall, floor or ceiling id")
            sub = m if len(uniq) == 1 else submesh(m, np.flatnonzero(mine == iid))
            parts.append(_gltf_part(layout, f"stage/{j}/{int(iid)}", int(iid), sem[base], sub, T))
    return parts


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
