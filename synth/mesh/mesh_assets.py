"""Meshes of mesh assets (``replicacad:<glb>``, ``replicacad-urdf:<urdf>``) in an object's local frame.

The one place that turns an ``ObjectInstance.asset`` of an imported layout into triangles for
geometry (boxes, supporting surfaces, checks); the renderers take the textured primitives from
``synth.mesh.gltf`` and ``synth.mesh.urdf`` directly. Paths are relative to the dataset root
(``layout.meta["root"]``). No Blender here.
"""

from __future__ import annotations

from pathlib import Path

import trimesh

from vrformats.errors import UnknownNameError

from vrformats.fields import fail, inside_root

from ..scene.model import GLB_ASSET_PREFIX as ASSET_PREFIX
from ..scene.model import URDF_ASSET_PREFIX as URDF_PREFIX
from .roots import dataset_root


def asset_file(root, asset: str) -> Path:
    """The file a mesh asset names (a GLB or a URDF), checked to exist."""
    r = dataset_root(root)
    for prefix, what in ((URDF_PREFIX, "URDF"), (ASSET_PREFIX, "GLB")):
        if isinstance(asset, str) and asset.startswith(prefix) and len(asset) > len(prefix):
            path = inside_root(asset, None, r / asset[len(prefix):], r)
            if not path.is_file():
                fail(path, None, f"{what} not found (asset {asset!r})")
            return path
    raise UnknownNameError(f"not a ReplicaCAD asset name: {asset!r} (expected '{ASSET_PREFIX}<relative glb path>' "
                           f"or '{URDF_PREFIX}<relative urdf path>')")


def load_asset_mesh(root, asset: str, joint_state: dict | None = None) -> trimesh.Trimesh:
    """Mesh of ``"replicacad:<glb path relative to root>"`` in our Z-up local frame, unscaled.

    Vertices are ``Y_UP_TO_Z_UP @ v`` for the GLB's vertices ``v`` (node transforms applied). Place it
    with ``ObjectInstance.scale`` (per axis, first) and then ``ObjectInstance.matrix()``; for the
    stage with ``Stage.position``/``Stage.rotation``. Returns a new mesh on every call.
    ``"replicacad-urdf:<urdf path>"`` gives all link meshes of an articulated object at
    ``joint_state`` (an object's ``params["joint_state"]``; None: every joint at 0), see ``synth.mesh.urdf``.
    """
    path = asset_file(root, asset)
    if asset.startswith(URDF_PREFIX):
        from .urdf import urdf_geometry

        return urdf_geometry(dataset_root(root), asset, joint_state)
    from .gltf import glb_geometry

    return glb_geometry(path)
