"""The folder a mesh asset's files belong to: the root that the paths a file names (a URDF's meshes,
a GLB's textures) must stay inside (``vrformats.fields.inside_root``), and the dataset folder that
asset names (``replicacad:<glb>``, ``replicacad-urdf:<urdf>``) are relative to.

A dataset folder is marked by a scene dataset config (``*.scene_dataset_config.json``, habitat-sim's,
the one format of mesh datasets read today); a second scene source with another marker adds it here.
No Blender here.
"""

from __future__ import annotations

import functools
from pathlib import Path

from vrformats.fields import fail

DATASET_CONFIG_GLOB = "*.scene_dataset_config.json"


def owning_root(path) -> Path:
    """The dataset folder a file belongs to: its nearest ancestor holding a
    ``*.scene_dataset_config.json``, else the file's own folder. Paths a file names (a URDF's
    meshes, a GLB's textures) must stay inside it (``vrformats.fields.inside_root``)."""
    p = Path(path).resolve().parent
    return _owning(p)


@functools.lru_cache(maxsize=4096)
def _owning(folder: Path) -> Path:
    for d in (folder, *folder.parents):
        try:
            if any(d.glob(DATASET_CONFIG_GLOB)):
                return d
        except OSError:
            break
    return folder


def dataset_root(root, require_config: bool = False) -> Path:
    """The dataset folder, resolved. SceneFormatError when it is not a folder, and with
    ``require_config`` when it holds no ``*.scene_dataset_config.json`` (:func:`dataset_config_path`)."""
    p = Path(root).expanduser()
    if not p.is_dir():
        fail(p, None, "ReplicaCAD dataset folder not found")
    p = p.resolve()
    if require_config:
        dataset_config_path(p)
    return p


def dataset_config_path(root, required: bool = True) -> Path | None:
    """``<root>/*.scene_dataset_config.json``, the scene dataset config habitat-sim is pointed at
    (ReplicaCAD's is ``replicaCAD.scene_dataset_config.json``). None when there is none and not
    ``required``; SceneFormatError naming the folder when there is none (and it is required) or
    when there are several (which one habitat would load is the user's choice, not ours)."""
    r = Path(root)
    configs = sorted(r.glob(DATASET_CONFIG_GLOB))
    if not configs:
        if not required:
            return None
        fail(r, None, f"no {DATASET_CONFIG_GLOB} in the ReplicaCAD folder (the dataset's root holds "
                      "replicaCAD.scene_dataset_config.json next to configs/ and objects/)")
    if len(configs) > 1:
        fail(r, None, f"several scene dataset configs ({', '.join(c.name for c in configs)}); keep one")
    return configs[0]
