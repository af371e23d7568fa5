"""Interpenetration of mesh objects from the collision shapes their dataset gives them.

No Blender here. Boxes overlap where the objects do not: a chair tucked under a table, a book inside
a wall cabinet, a stool beside a sofa's armrest. ReplicaCAD says what a physics engine may treat as
solid: a rigid object's ``collision_asset`` (``objects/convex/*_cv_decomp.glb``: one convex piece
per mesh, as habitat-sim's Bullet loader takes it with ``join_collision_meshes: false``) and an
articulated object's URDF ``<collision>`` elements (boxes, or meshes taken as their convex hull);
a rigid object without a collision asset collides, as in habitat-sim, with its render meshes (the
convex hull of each).
The dataset's scenes were settled by that physics, so two objects whose collision shapes overlap by
more than ``PENETRATION_TOL`` truly interpenetrate.

Overlap depth of two convex pieces: the radius of the largest ball inside both (their intersection's
Chebyshev centre, one linear programme over the pieces' face planes, ``scipy.optimize.linprog``).
Two objects interpenetrate when some pair of their pieces holds a ball of radius
``PENETRATION_TOL``; bullet's contact margin (a few mm) and the settling of a physics step stay
below it.

Shapes are in the object's local Z-up frame, scaled (``ObjectInstance.scale``); ``world_pieces``
places them. An object without collision data (procedural objects, a dataset without collision
assets) has none here, and the checks fall back to its box.
"""

from __future__ import annotations

import functools
import logging
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np

from vrformats.fields import inside_root

from ..scene import geometry as geo
from ..scene.geometry import Y_UP_TO_Z_UP
from ..scene.model import GLB_ASSET_PREFIX, URDF_ASSET_PREFIX
from .roots import dataset_root, owning_root

log = logging.getLogger(__name__)

PENETRATION_TOL = 0.01  # m: a ball of this radius fits inside both shapes -> interpenetration
# Contact. Bullet grows every convex collision shape by its margin (btCollisionMargin.h:
# CONVEX_DISTANCE_MARGIN 0.04 m), and habitat-sim gives objects and stages a ``margin`` attribute
# ("collision shape inflation margin"): ReplicaCAD's stage config sets 0.01, one object config
# (picture_04) 0.01, the others none. So a settled object rests up to the sum of the two margins
# away from what holds it (a rug 3.6-4.5 cm above the floor, a shoe box 2 cm above a bin's lid).
DEFAULT_MARGIN = 0.04  # m: an object's margin when its config sets none
CONTACT_SLACK = 0.005  # m: added to the sum of margins (solver slop)
CONTACT_GAP = 0.02  # m: the contact distance when neither object has a margin (procedural objects)
_C = Y_UP_TO_Z_UP


@functools.lru_cache(maxsize=512)
def _glb_pieces(path: str) -> tuple[np.ndarray, ...]:
    """Vertices of each mesh of a GLB (our Z-up frame, node transforms applied): one convex piece each."""
    import trimesh

    scene = trimesh.load(path, force="scene", process=False)
    out = []
    for node in scene.graph.nodes_geometry:
        T, gname = scene.graph[node]
        g = scene.geometry[gname]
        v = np.asarray(g.vertices, float) @ T[:3, :3].T + T[:3, 3]
        if len(v) >= 4:
            out.append(v @ _C.T)
    return tuple(out)


def _box_vertices(size, T) -> np.ndarray:
    h = np.asarray(size, float) / 2.0
    signs = np.array([[sx, sy, sz] for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)], float)
    return (signs * h) @ T[:3, :3].T + T[:3, 3]


@functools.lru_cache(maxsize=64)
def _urdf_collision_elements(path: str) -> tuple:
    """(link, origin 4x4 habitat frame, ("box", size) | ("mesh", glb path, scale)) per <collision>."""
    from .urdf import origin_matrix

    root = ET.parse(path).getroot()
    out = []
    for link in root.findall("link"):
        for k, col in enumerate(link.findall("collision")):
            T = origin_matrix(Path(path), col, f"link[{link.get('name')}].collision[{k}]")
            geom = col.find("geometry")
            if geom is None:
                continue
            box, mesh = geom.find("box"), geom.find("mesh")
            if box is not None and box.get("size"):
                out.append((link.get("name"), T, ("box", tuple(float(x) for x in box.get("size").replace(",", " ").split()))))
            elif mesh is not None and mesh.get("filename"):
                sc = mesh.get("scale")
                scale = tuple(float(x) for x in sc.replace(",", " ").split()) if sc else (1.0, 1.0, 1.0)
                if len(scale) == 1:
                    scale = scale * 3
                f = inside_root(path, "collision.geometry.mesh", Path(path).parent / mesh.get("filename"), owning_root(path))
                out.append((link.get("name"), T, ("mesh", str(f), scale)))
    return tuple(out)


def object_pieces(obj, root) -> list[np.ndarray]:
    """Convex collision pieces of an object (vertex arrays, local Z-up frame, scaled); [] when the
    object has no collision data."""
    if root is None:
        return []
    col = obj.params.get("collision")
    scale = np.asarray(obj.scale, float)
    if col == "box":  # use_bounding_box_for_collision: the render mesh's box
        T = np.eye(4)
        T[:3, 3] = obj.box_offset
        return [_box_vertices(obj.size, T)]
    if isinstance(col, str) and col:
        path = dataset_root(root) / col
        if not path.is_file():
            return []
        return [v * scale for v in _glb_pieces(str(path))]
    if obj.asset.startswith(GLB_ASSET_PREFIX):  # no collision asset: habitat-sim collides with the render meshes' hulls
        path = dataset_root(root) / obj.asset[len(GLB_ASSET_PREFIX):]
        return [v * scale for v in _glb_pieces(str(path))] if path.is_file() else []
    if obj.params.get("articulated") and obj.asset.startswith(URDF_ASSET_PREFIX):
        from .urdf import link_poses, parse_urdf, urdf_path

        upath = urdf_path(root, obj.asset)
        model = parse_urdf(upath)
        poses = link_poses(model, obj.params.get("joint_state") or None)
        out = []
        for link, T, geom in _urdf_collision_elements(str(upath)):
            M = poses.get(link, np.eye(4)) @ T  # habitat frame, root-link relative
            if geom[0] == "box":
                v = _box_vertices(geom[1], M)
            else:
                if not Path(geom[1]).is_file():
                    continue
                pieces = [p @ _C for p in _glb_pieces(geom[1])]  # back to the habitat frame
                if not pieces:
                    continue
                v = np.concatenate(pieces) * np.asarray(geom[2], float)
                v = v @ M[:3, :3].T + M[:3, 3]
            out.append((v @ _C.T) * scale)
        return out
    return []


def margin(obj) -> float:
    """An object's collision margin: its config's (``params["margin"]``), else ``DEFAULT_MARGIN`` for an
    object with dataset collision data; 0 for procedural objects (their boxes are exact)."""
    if "margin" in obj.params:
        return float(obj.params["margin"])
    return DEFAULT_MARGIN if ("collision" in obj.params or obj.params.get("articulated")
                              or obj.asset.startswith(GLB_ASSET_PREFIX)) else 0.0


def contact_gap(a_margin: float, b_margin: float) -> float:
    """How far apart two settled shapes may be and still touch (see ``DEFAULT_MARGIN``)."""
    m = a_margin + b_margin
    return m + CONTACT_SLACK if m > 0 else CONTACT_GAP


def world_pieces(obj, root) -> list[np.ndarray]:
    """``object_pieces`` placed in the world."""
    R = geo.quat_to_matrix(obj.rotation)
    p = np.asarray(obj.position, float)
    return [v @ R.T + p for v in object_pieces(obj, root)]


def _halfspaces(v: np.ndarray):
    from scipy.spatial import ConvexHull, QhullError

    try:
        h = ConvexHull(v)
    except (QhullError, ValueError):  # flat piece: thicken it by a hair so it still has a volume
        jitter = np.array([[0, 0, 0], [1e-4, 0, 0], [0, 1e-4, 0], [0, 0, 1e-4]])
        h = ConvexHull(np.concatenate([v + j for j in jitter]))
    return h.equations  # n . x + d <= 0 inside, |n| = 1


def overlap_depth(va: np.ndarray, vb: np.ndarray) -> float:
    """Radius of the largest ball inside both convex hulls (0 when they are disjoint)."""
    lo, hi = np.maximum(va.min(0), vb.min(0)), np.minimum(va.max(0), vb.max(0))
    if np.any(hi <= lo):
        return 0.0
    from scipy.optimize import linprog

    E = np.concatenate([_halfspaces(va), _halfspaces(vb)])
    A = np.hstack([E[:, :3], np.ones((len(E), 1))])  # n.x + r <= -d
    res = linprog(c=[0, 0, 0, -1.0], A_ub=A, b_ub=-E[:, 3], bounds=[(None, None)] * 3 + [(0, None)], method="highs")
    return float(res.x[3]) if res.status == 0 else 0.0


def penetration(a_pieces: list[np.ndarray], b_pieces: list[np.ndarray], stop_at: float = PENETRATION_TOL) -> float:
    """Deepest overlap (ball radius, m) of any piece of one object with any piece of the other; stops
    early once ``stop_at`` is reached."""
    best = 0.0
    boxes_b = [(v.min(0), v.max(0)) for v in b_pieces]
    for va in a_pieces:
        la, ha = va.min(0), va.max(0)
        for vb, (lb, hb) in zip(b_pieces, boxes_b):
            if np.any(np.minimum(ha, hb) - np.maximum(la, lb) <= 2 * best):
                continue
            best = max(best, overlap_depth(va, vb))
            if best >= stop_at:
                return best
    return best


def touching(a_pieces: list[np.ndarray], b_pieces: list[np.ndarray], gap: float = CONTACT_GAP) -> bool:
    """Whether some piece of one object comes within about ``gap`` of some piece of the other: the
    pieces' face planes pushed out by ``gap / 2`` leave a common point (a slight superset of the
    Minkowski test, exact for boxes meeting face to face)."""
    from scipy.optimize import linprog

    for va in a_pieces:
        la, ha = va.min(0) - gap, va.max(0) + gap
        Ea = None
        for vb in b_pieces:
            if np.any(np.minimum(ha, vb.max(0)) < np.maximum(la, vb.min(0))):
                continue
            Ea = _halfspaces(va) if Ea is None else Ea
            E = np.concatenate([Ea, _halfspaces(vb)])
            res = linprog(c=[0, 0, 0], A_ub=E[:, :3], b_ub=-E[:, 3] + gap / 2, bounds=[(None, None)] * 3, method="highs")
            if res.status == 0:
                return True
    return False


@functools.lru_cache(maxsize=8)
def _stage_scene(root: str, asset: str, position: tuple, rotation: tuple):
    """Open3D ray-casting scene of a stage mesh in the world; None when the mesh cannot be read (the
    checks then go without it, saying so once)."""
    from vrformats.native import import_open3d

    o3d = import_open3d()

    from vrformats.errors import SceneFormatError, UnknownNameError

    from .mesh_assets import load_asset_mesh

    try:
        m = load_asset_mesh(root, asset)
    except (SceneFormatError, UnknownNameError) as e:
        log.warning("stage mesh not used by the checks: %s", e)
        return None
    R = geo.quat_to_matrix(rotation)
    v = np.asarray(m.vertices, float) @ R.T + np.asarray(position, float)
    scene = o3d.t.geometry.RaycastingScene()
    scene.add_triangles(o3d.core.Tensor(v.astype(np.float32)), o3d.core.Tensor(np.asarray(m.faces, np.uint32)))
    return scene


def stage_distance(layout, pieces: list[np.ndarray]) -> float:
    """Smallest distance (m) from an object's collision pieces (their vertices) to the stage mesh of
    an imported layout: how near it comes to the floor, a wall or anything built into the stage (a
    shelf, a hook); inf without a stage mesh."""
    from vrformats.native import import_open3d

    o3d = import_open3d()

    st, root = layout.stage, layout.meta.get("root")
    if st.asset is None or root is None or not pieces:
        return float("inf")
    scene = _stage_scene(str(root), st.asset, tuple(st.position), tuple(st.rotation))
    if scene is None:
        return float("inf")
    pts = np.concatenate(pieces).astype(np.float32)
    d = scene.compute_distance(o3d.core.Tensor(pts)).numpy()
    return float(d.min()) if len(d) else float("inf")


def stage_drop(layout, point) -> float:
    """How far below ``point`` the stage mesh is (a ray straight down; inf without a stage mesh or a hit)."""
    from vrformats.native import import_open3d

    o3d = import_open3d()

    st, root = layout.stage, layout.meta.get("root")
    if st.asset is None or root is None:
        return float("inf")
    scene = _stage_scene(str(root), st.asset, tuple(st.position), tuple(st.rotation))
    if scene is None:
        return float("inf")
    ray = np.array([[point[0], point[1], point[2], 0.0, 0.0, -1.0]], np.float32)
    t = float(scene.cast_rays(o3d.core.Tensor(ray))["t_hit"].numpy()[0])
    return t if np.isfinite(t) else float("inf")
