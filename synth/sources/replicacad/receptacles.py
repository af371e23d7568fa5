"""ReplicaCAD receptacles: the surfaces things stand on, as the dataset itself declares them.

No Blender here. Object configs (``*.object_config.json``) and articulated-object configs
(``*.ao_config.json``) carry ``user_defined`` entries named ``receptacle_aabb_*``::

    "receptacle_aabb_Tbl2_Top1_frl_apartment_table_02": {
        "name": ..., "parent_object": ..., "parent_link": "drawer1_top",   # articulated objects only
        "position": [x, y, z],    # centre, habitat object (or link) frame, unscaled
        "scale": [hx, hy, hz]     # half extents (habitat-lab reads it as Range3D.from_center(position, scale))
    }

habitat-lab (``habitat/datasets/rearrange/samplers/receptacle.py``, ``AABBReceptacle``,
``parse_receptacles_from_user_config``) samples object positions inside this box and lets them
settle: its bottom face is the supporting surface (a table top, a shelf board, a drawer's floor) and
an object resting on the receptacle has its bottom within the box's height. Some configs give
negative half extents (the kitchen counter's drawers): the sign carries no meaning, its magnitude
is taken.

Frames. A receptacle's box is converted once, here, to the owning object's local Z-up frame (the
frame of ``ObjectInstance.position``/``rotation``, scaled by ``ObjectInstance.scale``): centre
``s * (C c)``, half extents ``s * |C| |h|`` with ``C`` = ``synth.sources.replicacad.habitat_format.Y_UP_TO_Z_UP``;
for an articulated object the link's pose at the object's joint state comes first. Receptacles are
stored on the object (``params["receptacles"]``) so that a layout file keeps them and the checks,
the importer's support inference and the placement engine read one list; the mesh layer's
``synth.mesh.surfaces.receptacle_surfaces`` turns them into ``synth.assets.surfaces.Surface``
(bottom face, with ``band`` = the box height).
"""

from __future__ import annotations

import numpy as np

from . import habitat_format as hf

PREFIX = "receptacle_aabb_"
MIN_HALF = 1e-4  # m: a degenerate receptacle box is an error


def read_receptacles(path, cfg: dict, articulated: bool = False) -> tuple[dict, ...]:
    """The ``receptacle_aabb_*`` entries of a config's ``user_defined`` block, checked, in file order:
    ``{"name", "center" (3), "half" (3), "link" (articulated only, or None)}`` in the habitat
    object (link) frame, unscaled. Other ``user_defined`` entries are ignored."""
    ud = cfg.get("user_defined")
    if ud is None:
        return ()
    ud = hf.mapping(path, ud, "user_defined")
    out = []
    for key, v in ud.items():
        if not (isinstance(key, str) and key.startswith(PREFIX)):
            continue
        f = f"user_defined.{key}"
        v = hf.mapping(path, v, f)
        center = hf.numbers(path, v.get("position"), f + ".position", 3)
        half = np.abs(hf.numbers(path, v.get("scale"), f + ".scale", 3))
        if (half < MIN_HALF).any():
            hf.fail(path, f + ".scale", f"half extents must be non-zero, got {v.get('scale')!r}")
        link = None
        if articulated and "parent_link" in v:
            link = hf.string(path, v["parent_link"], f + ".parent_link")
        out.append({"name": key, "center": [float(x) for x in center], "half": [float(x) for x in half], "link": link})
    return tuple(out)


def to_object_frame(recs, scale, link_pose=None) -> list[dict]:
    """Receptacles in the owning object's local Z-up frame, scaled: ``{"name", "center", "half"}``
    with ``center``/``half`` in metres (rounded to 0.1 mm). ``scale``: ``ObjectInstance.scale`` (our
    axes); ``link_pose(name) -> 4x4`` (habitat frame, unscaled, root-link relative) for articulated
    objects, whose receptacles name a link."""
    C = hf.Y_UP_TO_Z_UP
    s = np.asarray(scale, float)
    out = []
    for r in recs:
        c = np.asarray(r["center"], float)
        h = np.asarray(r["half"], float)
        if r.get("link") is not None and link_pose is not None:
            T = link_pose(r["link"])
            R = T[:3, :3]
            c = R @ c + T[:3, 3]
            h = np.abs(R) @ h  # the axis-aligned box around the rotated one
        out.append({"name": r["name"], "center": [round(float(x), 4) for x in s * (C @ c)],
                    "half": [round(float(x), 4) for x in s * (np.abs(C) @ h)]})
    return out
