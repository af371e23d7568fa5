"""Mesh helpers for the tests that write their own assets (GLB objects, stages, URDF links)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import trimesh


def box_mesh(lo, hi) -> trimesh.Trimesh:
    """An axis-aligned box from corner ``lo`` to corner ``hi`` (12 triangles, shared vertices)."""
    lo, hi = np.asarray(lo, float), np.asarray(hi, float)
    b = trimesh.creation.box(extents=hi - lo)
    b.apply_translation((lo + hi) / 2.0)
    return b


def write_glb(path: Path, meshes) -> Path:
    """A binary glTF of one mesh, a list of meshes (nodes ``n0``, ``n1``, ...) or a list of
    ``(name, mesh)`` pairs (each node and geometry named), as trimesh exports it."""
    if isinstance(meshes, trimesh.Trimesh):
        meshes = [meshes]
    scene = trimesh.Scene()
    for k, m in enumerate(meshes):
        name, mesh = m if isinstance(m, tuple) else (f"n{k}", m)
        scene.add_geometry(mesh, node_name=name, geom_name=name if isinstance(m, tuple) else f"g{k}")
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_bytes(trimesh.exchange.gltf.export_glb(scene))
    return path
