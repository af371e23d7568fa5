"""The fast geometry renderer: Open3D ray casting of the layout's parts, no Blender.

It writes the same depth, instance and semantic images as the Blender geometry pass, from the same
parts (``synth.meshes``), with an independent camera model: for pixel (u, v) the ray leaves the
camera centre along ``R @ K^-1 [u, v, 1]``, whose camera-frame z is 1, so Open3D's hit parameter
is the planar depth itself. It is the fast mode for relocalization experiments and the independent
check of the Blender camera conventions. Parts of mesh assets carry their glTF materials
(``mesh.visual``, ``synth.gltf``); only their vertices and faces are read here.
"""

from __future__ import annotations

import numpy as np
import open3d as o3d

from formats.camera import Intrinsics

from .meshes import layout_parts
from .scene import Layout

INVALID = o3d.t.geometry.RaycastingScene.INVALID_ID


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
        for iid, ps in sorted(by_inst.items()):
            verts, faces, off = [], [], 0
            for p in ps:
                verts.append(p.world_vertices())
                faces.append(np.asarray(p.mesh.faces) + off)
                off += len(p.mesh.vertices)
            gid = self.scene.add_triangles(
                o3d.core.Tensor(np.concatenate(verts).astype(np.float32)),
                o3d.core.Tensor(np.concatenate(faces).astype(np.uint32)),
            )
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

    def render(self, T_world_cam: np.ndarray, intr: Intrinsics) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Planar depth (m, 0 = no hit), instance ids and semantic ids for one camera pose."""
        d_cam = self._cam_rays(intr)
        R, t = T_world_cam[:3, :3], T_world_cam[:3, 3]
        d = d_cam @ R.T
        rays = np.empty((len(d), 6), np.float32)
        rays[:, :3] = t
        rays[:, 3:] = d
        ans = self.scene.cast_rays(o3d.core.Tensor(rays), nthreads=self.threads)
        depth = ans["t_hit"].numpy()
        gids = ans["geometry_ids"].numpy()
        hit = gids != INVALID
        gids = np.where(hit, gids, len(self._inst) - 1)  # the last slot holds 0
        depth = np.where(hit & np.isfinite(depth), depth, 0.0).astype(np.float32)
        shape = (intr.height, intr.width)
        return depth.reshape(shape), self._inst[gids].reshape(shape), self._sem[gids].reshape(shape)
