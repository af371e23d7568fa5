"""Reading habitat-sim / ReplicaCAD files: the frame conversion, typed field checks whose errors
name the file and the field, dataset paths and config lookup. Shared by ``synth.sources.replicacad.importer``
(scene instances, objects, stages), ``synth.mesh.urdf`` (articulated objects) and
``synth.sources.replicacad.habitat_lighting``; no Blender here.

Frames: habitat-sim (and glTF) is right-handed with +Y up and -Z forward; ours is right-handed with
+Z up. ``Y_UP_TO_Z_UP`` (C) maps habitat coordinates to ours, ``(x, y, z) -> (x, -z, y)``, a proper
rotation (+90 deg about X). A habitat pose ``T_h`` becomes ``C T_h C^T``, a vertex ``v_h`` becomes
``C v_h``, a quaternion ``(w, x, y, z)`` becomes ``(w, x, -z, y)`` (``convert_quat``).
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from vrformats.fields import fail, inside_root, mapping, number, numbers, string  # noqa: F401  (re-exported)
from vrformats.fields import unit_quat as quat  # noqa: F401
from vrformats.yamlfile import read_json  # noqa: F401  (re-exported: every habitat config is read with it)

from ...scene.geometry import Y_UP_TO_Z_UP  # noqa: F401  (the readers import it from here too)
from ...mesh.roots import DATASET_CONFIG_GLOB, dataset_config_path, dataset_root, owning_root  # noqa: F401  (re-exported)
from ...scene.model import GLB_ASSET_PREFIX, URDF_ASSET_PREFIX


ASSET_PREFIX = GLB_ASSET_PREFIX  # a GLB, relative to the dataset root (names: synth.scene.model)
URDF_PREFIX = URDF_ASSET_PREFIX  # an articulated object's URDF, relative to the dataset root (synth.mesh.urdf)
MOTION_TYPES = ("STATIC", "KINEMATIC", "DYNAMIC")
UNKNOWN_CLASS = "other"
MIN_EXTENT = 1e-3  # metres; flat meshes (pictures, rugs) get boxes at least this thick

_DEFAULT_UP = (0.0, 1.0, 0.0)
_DEFAULT_FRONT = (0.0, 0.0, -1.0)
_C = Y_UP_TO_Z_UP

# field checks (every error names the file and the field): vrformats.fields, re-exported for the readers


def check_frame(file, cfg: dict) -> None:
    """Accept only the glTF default frame (up +Y, front -Z), given or implied."""
    up = numbers(file, cfg["up"], "up", 3) if "up" in cfg else np.array(_DEFAULT_UP)
    front = numbers(file, cfg["front"], "front", 3) if "front" in cfg else np.array(_DEFAULT_FRONT)
    for field, vec, ref in (("up", up, _DEFAULT_UP), ("front", front, _DEFAULT_FRONT)):
        n = np.linalg.norm(vec)
        if n == 0 or not np.allclose(vec / n, ref, atol=1e-6):
            fail(file, field, f"only the default frame (up {list(_DEFAULT_UP)}, front {list(_DEFAULT_FRONT)}) "
                               f"is supported, got {cfg.get(field)!r}")


def translation_origin(file, v, field: str) -> str | None:
    """'asset_local', 'COM' or None (unknown / not given)."""
    if v is None:
        return None
    s = string(file, v, field).lower()
    if s == "asset_local":
        return "asset_local"
    if s == "com":
        return "COM"
    if s == "unknown":
        return None
    fail(file, field, f"expected 'asset_local' or 'COM', got {v!r}")


# --------------------------------------------------------------------------------------------
# dataset paths


# dataset paths: the mesh layer's (synth.mesh.roots), re-exported for the readers


class ConfigFinder:
    """Template name -> config file, the way habitat-sim matches handles against registered configs."""

    def __init__(self, root: Path, folder: str, suffix: str):
        self.root, self.folder, self.suffix = root, folder, suffix
        self._index: dict[str, list[Path]] | None = None

    def find(self, template: str) -> Path | None:
        t = template.replace("\\", "/").strip("/")
        if t.endswith(self.suffix):
            t = t[: -len(self.suffix)]
        base = t.rsplit("/", 1)[-1]
        configs = self.root / "configs"
        for cand in (configs / f"{t}{self.suffix}", configs / self.folder / f"{base}{self.suffix}"):
            if cand.is_file():
                return cand
        if self._index is None:
            self._index = {}
            for p in sorted((configs / self.folder).rglob("*" + self.suffix)):
                self._index.setdefault(p.name[: -len(self.suffix)], []).append(p)
        hits = self._index.get(base, [])
        for p in hits:
            if p.as_posix()[: -len(self.suffix)].endswith("/" + t):
                return p
        return hits[0] if hits else None


def asset_name(root: Path, glb: Path) -> str:
    return ASSET_PREFIX + Path(os.path.relpath(glb, root)).as_posix()


def render_asset(root: Path, config: Path, cfg: dict) -> Path:
    """The GLB a config's ``render_asset`` names (relative to the config's folder). SceneFormatError
    naming the config and ``render_asset`` when it does not exist, and naming the GLB when it is a
    Git LFS pointer (a clone made without ``git lfs``: "run git lfs pull")."""
    from vrformats.lfs import LFS_HINT, is_lfs_pointer

    rel = string(config, cfg.get("render_asset"), "render_asset")
    glb = inside_root(config, "render_asset", config.parent / rel, root)
    if not glb.is_file():
        fail(config, "render_asset", f"GLB not found: {glb}")
    if is_lfs_pointer(glb):
        fail(glb, None, f"cannot read GLB: {LFS_HINT} (named by {config}: render_asset)")
    return glb


# --------------------------------------------------------------------------------------------
# poses


def convert_quat(q) -> tuple[float, float, float, float]:
    """Habitat (w, x, y, z) -> ours: the rotation C R C^T, i.e. (w, x, -z, y), with w >= 0."""
    w, x, y, z = (float(v) for v in q)
    out = np.array([w, x, -z, y])
    out /= np.linalg.norm(out)
    if out[0] < 0:
        out = -out
    return tuple(float(v) + 0.0 for v in out)  # + 0.0: no negative zeros in the files


def hab_matrix(q) -> np.ndarray:
    w, x, y, z = q
    return np.array([
        [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
        [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
        [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
    ])


def vec(v) -> tuple[float, float, float]:
    return tuple(float(x) + 0.0 for x in v)
