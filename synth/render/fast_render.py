"""The fast geometry renderer: Open3D ray casting of the layout's parts, no Blender.

It writes the same depth, instance and semantic images as the Blender geometry pass, from the same
parts (``synth.render.meshes``), with an independent camera model: for pixel (u, v) the ray leaves the
camera centre along ``R @ K^-1 [u, v, 1]``, whose camera-frame z is 1, so Open3D's hit parameter
is the planar depth itself. It is the fast mode for relocalization experiments and the independent
check of the Blender camera conventions. Parts of mesh assets carry their glTF materials
(``mesh.visual``, ``synth.mesh.gltf``); ``render`` reads only their vertices and faces.

``render_base_color`` gives the unlit base colour (albedo, linear RGB) seen at each pixel: for a
glTF part its base colour texture looked up at the hit point's UV with the slot's
``KHR_texture_transform`` applied, times ``baseColorFactor`` (``synth.mesh.gltf.sample_base_color``);
for a procedural part its flat ``color`` (``PROCEDURAL_ALBEDO`` when it has none). It is a check of
what texture each surface shows, not a shaded image.
"""

from __future__ import annotations

import numpy as np

from vrformats.camera import Intrinsics
from vrformats.native import import_open3d

from .meshes import layout_parts
from ..scene.model import Layout

o3d = import_open3d()  # a missing libGL is one line naming its package

INVALID = o3d.t.geometry.RaycastingScene.INVALID_ID
PROCEDURAL_ALBEDO = (0.7, 0.7, 0.7)  # base colour of a procedural part without a colour of its own


class FastRenderer:
    """Ray-casting scene of one layout; ``render(pose, K)`` -> (depth, instance, semantic)."""

    def __init__(self, layout: Layout, threads: int = 0):
        self.threads = threads
        parts = layout_parts(layout)
        # one Open3D geometry per instance: fewer geometries, faster build and lookup
        by_inst: dict[int, list] = {}
        sem_of: dict[int, int] = {}
        for p in parts:
            by_inst.setdefault(p.instance_id, []).append(p)
            sem_of[p.instance_id] = p.semantic_id
        self.scene = o3d.t.geometry.RaycastingScene(nthreads=threads)
        ids, inst, sem = [], [], []
        self._parts: dict[int, tuple[np.ndarray, list]] = {}  # geometry id -> (first face of each part, parts)
        for iid, ps in sorted(by_inst.items()):
            verts, faces, off, first, nf = [], [], 0, [], 0
            for p in ps:
                verts.append(p.world_vertices())
                faces.append(np.asarray(p.mesh.faces) + off)
                off += len(p.mesh.vertices)
                first.append(nf)
                nf += len(p.mesh.faces)
            gid = self.scene.add_triangles(
                o3d.core.Tensor(np.concatenate(verts).astype(np.float32)),
                o3d.core.Tensor(np.concatenate(faces).astype(np.uint32)),
            )
            self._parts[gid] = (np.asarray(first, np.int64), ps)
            ids.append(gid)
            inst.append(iid)
            sem.append(sem_of[iid])
        n = max(ids) + 1 if ids else 1
        self._inst = np.zeros(n + 1, np.uint32)
        self._sem = np.zeros(n + 1, np.uint32)
        self._inst[ids] = inst
        self._sem[ids] = sem
        self._rays_cache: tuple[Intrinsics, np.ndarray] | None = None

    def _cam_rays(self, intr: Intrinsics) -> np.ndarray:
        if self._rays_cache is None or self._rays_cache[0] != intr:
            self._rays_cache = (intr, intr.pixel_rays().reshape(-1, 3))
        return self._rays_cache[1]

    def _cast(self, T_world_cam: np.ndarray, intr: Intrinsics) -> dict:
        d_cam = self._cam_rays(intr)
        R, t = T_world_cam[:3, :3], T_world_cam[:3, 3]
        d = d_cam @ R.T
        rays = np.empty((len(d), 6), np.float32)
        rays[:, :3] = t
        rays[:, 3:] = d
        return self.scene.cast_rays(o3d.core.Tensor(rays), nthreads=self.threads)

    def render_base_color(self, T_world_cam: np.ndarray, intr: Intrinsics) -> np.ndarray:
        """Unlit base colour (linear RGB, float32, H x W x 3; 0 where nothing is hit) for one camera
        pose: textures sampled at the hit points with their texture transforms (module docstring)."""
        from ..mesh.gltf import sample_base_color
        from .meshes import GLTF_MATERIAL

        ans = self._cast(T_world_cam, intr)
        gids = ans["geometry_ids"].numpy().astype(np.int64)
        prims = ans["primitive_ids"].numpy().astype(np.int64)
        buv = ans["primitive_uvs"].numpy().astype(np.float64)  # hit = (1 - a - b) v0 + a v1 + b v2
        hit = (gids != INVALID) & np.isfinite(ans["t_hit"].numpy())
        out = np.zeros((len(gids), 3), np.float32)
        bary = np.column_stack([1.0 - buv[:, 0] - buv[:, 1], buv[:, 0], buv[:, 1]])
        for gid in np.unique(gids[hit]):
            first, ps = self._parts[int(gid)]
            sel = np.flatnonzero(hit & (gids == gid))
            k = np.searchsorted(first, prims[sel], side="right") - 1
            for j in np.unique(k):
                px = sel[k == j]
                p = ps[int(j)]
                if p.material == GLTF_MATERIAL:
                    out[px] = sample_base_color(p.mesh, prims[px] - first[j], bary[px])
                else:
                    out[px] = p.color if p.color is not None else PROCEDURAL_ALBEDO
        return out.reshape(intr.height, intr.width, 3)

    def render(self, T_world_cam: np.ndarray, intr: Intrinsics) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Planar depth (m, 0 = no hit), instance ids and semantic ids for one camera pose."""
        ans = self._cast(T_world_cam, intr)
        depth = ans["t_hit"].numpy()
        gids = ans["geometry_ids"].numpy()
        hit = gids != INVALID
        gids = np.where(hit, gids, len(self._inst) - 1)  # the last slot holds 0
        depth = np.where(hit & np.isfinite(depth), depth, 0.0).astype(np.float32)
        shape = (intr.height, intr.width)
        return depth.reshape(shape), self._inst[gids].reshape(shape), self._sem[gids].reshape(shape)
