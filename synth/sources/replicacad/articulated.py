"""ReplicaCAD articulated objects in a scene instance: one static ``ObjectInstance`` per articulated object.

The URDF reader (parsing, forward kinematics, link meshes) is the mesh layer's ``synth.mesh.urdf``,
whose docstring gives the format facts; here is what is habitat's: finding a template's URDF and
``*.ao_config.json`` in the dataset, the ``articulated_object_instances`` of a scene instance, the
receptacles of an articulated object and the doors that stand open. No Blender here.
"""

from __future__ import annotations

import json
import logging
import os
from pathlib import Path

import numpy as np

from vrformats.boxes import MAX_OBJECT_ID
from vrformats.errors import UnknownNameError
from vrformats.fields import boolean, fail, is_number

from . import habitat_format as hf
from ...mesh.urdf import JOINT_STATE_DECIMALS, link_poses, local_bounds, parse_urdf, urdf_path
from ...scene.classes import ClassTable
from .receptacles import to_object_frame
from ...scene.model import URDF_ASSET_PREFIX, ObjectInstance

log = logging.getLogger(__name__)

# Doors. ReplicaCAD's door leaves (urdf/doors/*) are closed at joint zero, which walls a camera path
# off from the rooms behind them. An articulated object of this class whose instance states no
# ``initial_joint_pose`` is loaded with each revolute joint at the limit farthest from zero: open as
# far as the URDF allows (door2: -2.0 rad, about 115 deg). Its box is then where the open leaf is,
# so paths and checks treat it as any other object. Fridges, cupboards and drawers stay closed.
DOOR_CLASS = "door"
AO_CONFIG_SUFFIX = ".ao_config.json"
LINK_ORDERS = ("unspecified", "tree_traversal", "urdf_order")
_C = hf.Y_UP_TO_Z_UP


# --------------------------------------------------------------------------------------------
# finding URDFs


def _dataset_urdf_dirs(root: Path) -> list[Path]:
    """Folders named by ``articulated_objects.paths`` of the dataset config(s) in ``root``."""
    dirs: list[Path] = []
    for cfg_path in sorted(root.glob("*.scene_dataset_config.json")):
        try:
            cfg = json.loads(cfg_path.read_text(encoding="utf-8"))
            paths = cfg["articulated_objects"]["paths"]
            globs = [g for key, vals in paths.items() for g in vals] if isinstance(paths, dict) else []
        except (OSError, ValueError, KeyError, TypeError, AttributeError):
            continue
        for g in globs:
            if not isinstance(g, str):
                continue
            g = g.replace("\\", "/").rstrip("/")
            if Path(g).is_absolute() or ".." in Path(g).parts:
                continue  # outside the dataset (ReplicaCAD's own names ../hab_fetch_1.0/robots, another dataset): not searched
            for hit in sorted(cfg_path.parent.glob(g)) if any(c in g for c in "*?[") else [cfg_path.parent / g]:
                if not hit.resolve().is_relative_to(Path(root).resolve()):
                    continue  # a link out of the dataset
                if hit.is_dir():
                    dirs.append(hit)
                elif hit.is_file() and hit.suffix == ".urdf":
                    dirs.append(hit.parent)
    return dirs


def _search(r: Path, t: str, suffix: str) -> Path | None:
    base = t.rsplit("/", 1)[-1]
    cands = [r / f"{t}{suffix}"] if "/" in t else []
    cands.append(r / "urdf" / base / f"{base}{suffix}")
    for c in cands:
        if c.is_file():
            return c
    dirs = _dataset_urdf_dirs(r) or [r / "urdf"]
    hits: list[Path] = []
    for d in dirs:
        if d.is_dir():
            hits.extend(p for p in sorted(d.rglob(f"{base}{suffix}")) if p.is_file() and p not in hits)
    for p in hits:
        if p.as_posix()[: -len(suffix)].endswith("/" + t):
            return p
    return hits[0] if hits else None


def _template_name(template: str) -> str:
    t = template.replace("\\", "/").strip("/")
    for suffix in (AO_CONFIG_SUFFIX, ".urdf"):
        if t.endswith(suffix):
            t = t[: -len(suffix)]
    return t


def find_ao_config(root, template: str) -> Path | None:
    """The ``<name>.ao_config.json`` of an articulated template (searched like the URDF), or None."""
    return _search(Path(root), _template_name(template), AO_CONFIG_SUFFIX)


def find_urdf(root, template: str) -> Path | None:
    """The URDF file of an articulated template name (see the module docstring), or None.

    An ``<name>.ao_config.json`` found for the template names it (``urdf_filepath``, relative to
    the config's folder); otherwise the URDF is searched by name."""
    cfg = find_ao_config(root, template)
    if cfg is not None:
        try:
            rel = json.loads(cfg.read_text(encoding="utf-8")).get("urdf_filepath")
        except (OSError, ValueError, AttributeError):
            rel = None
        if isinstance(rel, str) and rel:
            p = hf.inside_root(cfg, "urdf_filepath", cfg.parent / rel, root)
            return p if p.is_file() else None
    return _search(Path(root), _template_name(template), ".urdf")


def _ao_config(cfg_path: Path | None) -> dict:
    """The checked fields of an ao_config that change geometry: urdf_filepath, uniform_scale, link_order."""
    if cfg_path is None:
        return {}
    cfg = hf.mapping(cfg_path, hf.read_json(cfg_path), None)
    out = {}
    if "urdf_filepath" in cfg:
        rel = hf.string(cfg_path, cfg["urdf_filepath"], "urdf_filepath")
        p = hf.inside_root(cfg_path, "urdf_filepath", cfg_path.parent / rel, hf.owning_root(cfg_path))
        if not p.is_file():
            fail(cfg_path, "urdf_filepath", f"URDF not found: {p}")
        out["urdf"] = p
    if "uniform_scale" in cfg:
        out["scale"] = hf.number(cfg_path, cfg["uniform_scale"], "uniform_scale", positive=True)
    if "link_order" in cfg:
        out["link_order"] = hf.string(cfg_path, cfg["link_order"], "link_order").lower()
    if cfg.get("render_asset"):
        log.warning("%s: render_asset %r (a skinned mesh) is not drawn; the link meshes are", cfg_path, cfg["render_asset"])
    from .receptacles import read_receptacles

    out["receptacles"] = read_receptacles(cfg_path, cfg, articulated=True)
    return out


# --------------------------------------------------------------------------------------------
# scene instances


def _joint_pose(scene_path: Path, v, field: str) -> list[float]:
    """``initial_joint_pose`` as habitat-sim reads it: a list, or an object's values in sorted-key order."""
    if isinstance(v, dict):
        items = [v[k] for k in sorted(v)]
    elif isinstance(v, list):
        items = v
    else:
        fail(scene_path, field, f"expected a list of numbers or an object of numbers, got {type(v).__name__}")
    out = []
    for x in items:
        if not is_number(x):
            fail(scene_path, field, f"expected finite numbers, got {v!r}")
        out.append(float(x))
    return out


def load_articulated_instances(root, scene_path, doc: dict, first_id: int, classes: ClassTable,
                               allow_unknown: bool = False, lexicon=None) -> list[ObjectInstance]:
    """One ObjectInstance per entry of ``doc["articulated_object_instances"]``, ids ``first_id``,
    ``first_id + 1``, ... in file order.

    asset ``"replicacad-urdf:<urdf path relative to root>"``; class from
    ``classes.replicacad_class(template)`` (``UnknownNameError`` naming every template without a
    rule, unless ``allow_unknown`` maps them to ``"other"``); ``movable=False``,
    ``support="floor"``; pose from the habitat root-link pose (``position = C t``, rotation
    ``C R C^T``); ``scale`` the uniform scale; ``size``/``box_offset`` the local bounding box of
    the union of the link meshes at the initial joint state (scaled); ``params`` ``{"template",
    "articulated": True, "links", "joint_state", "motion_type", "fixed_base"}``. Bad fields
    raise ``SceneFormatError`` naming the scene file (or URDF) and the field.
    """
    r = hf.dataset_root(root)
    scene_path = Path(scene_path)
    raw = doc.get("articulated_object_instances", []) if isinstance(doc, dict) else []
    if not isinstance(raw, list):
        fail(scene_path, "articulated_object_instances", f"expected a list, got {type(raw).__name__}")
    if raw and first_id + len(raw) - 1 > MAX_OBJECT_ID:
        fail(scene_path, "articulated_object_instances",
              f"ids {first_id}..{first_id + len(raw) - 1} exceed the maximum object id {MAX_OBJECT_ID}")
    parsed = []
    for i, inst in enumerate(raw):
        f = f"articulated_object_instances[{i}]"
        hf.mapping(scene_path, inst, f)
        name = hf.string(scene_path, inst.get("template_name"), f + ".template_name")
        t = hf.numbers(scene_path, inst["translation"], f + ".translation", 3) if "translation" in inst else np.zeros(3)
        q = hf.quat(scene_path, inst["rotation"], f + ".rotation") if "rotation" in inst else np.array([1.0, 0, 0, 0])
        s = hf.number(scene_path, inst["uniform_scale"], f + ".uniform_scale", positive=True) if "uniform_scale" in inst else 1.0
        if "non_uniform_scale" in inst:
            nus = hf.numbers(scene_path, inst["non_uniform_scale"], f + ".non_uniform_scale", 3, positive=True)
            if not np.allclose(nus, 1.0):
                log.warning("%s: %s.non_uniform_scale %s ignored (habitat-sim does not scale articulated objects "
                            "non-uniformly)", scene_path, f, list(nus))
        mt = "UNDEFINED"
        if "motion_type" in inst:
            mt = hf.string(scene_path, inst["motion_type"], f + ".motion_type").upper()
            if mt not in hf.MOTION_TYPES:
                fail(scene_path, f + ".motion_type", f"expected one of {', '.join(hf.MOTION_TYPES)}, got {inst['motion_type']!r}")
        fixed = boolean(scene_path, inst.get("fixed_base", False), f + ".fixed_base")
        hf.translation_origin(scene_path, inst.get("translation_origin"), f + ".translation_origin")  # checked, unused
        pose = _joint_pose(scene_path, inst["initial_joint_pose"], f + ".initial_joint_pose") if "initial_joint_pose" in inst else []
        order = None
        if "link_order" in inst:
            order = hf.string(scene_path, inst["link_order"], f + ".link_order").lower()
            if order not in LINK_ORDERS:
                fail(scene_path, f + ".link_order", f"expected one of {', '.join(LINK_ORDERS)}, got {inst['link_order']!r}")
        cfg_path = find_ao_config(r, name)
        cfg = _ao_config(cfg_path)
        urdf = cfg.get("urdf") or _search(r, _template_name(name), ".urdf")
        if urdf is None:
            base = _template_name(name).rsplit("/", 1)[-1]
            fail(scene_path, f + ".template_name",
                  f"no URDF for articulated template '{name}' (looked for {base}.urdf and {base}{AO_CONFIG_SUFFIX} "
                  f"under {r / 'urdf'})")
        s = s * cfg.get("scale", 1.0)  # habitat-sim: template scale times instance scale
        if order in (None, "unspecified"):
            order = cfg.get("link_order", "tree_traversal")
        if order == "urdf_order" and pose:
            fail(scene_path, f + ".initial_joint_pose",
                  "joint positions in link_order 'urdf_order' are not supported (only the default 'tree_traversal')")
        parsed.append((i, f, name, t, q, s, mt, fixed, pose, urdf, cfg.get("receptacles", ()), cfg_path))

    def class_of(name):  # the lexicon table's template rules, then the class table's name rules
        cls = lexicon.class_of(name, None)[0] if lexicon is not None else None
        return cls if cls is not None else classes.replicacad_class(name)

    unknown = sorted({p[2] for p in parsed if class_of(p[2]) is None})
    if unknown and not allow_unknown:
        raise UnknownNameError(
            f"{scene_path}: no class rule for ReplicaCAD articulated template(s) {', '.join(unknown)}; add aliases "
            f"under replicacad.aliases in {classes.source} or pass allow_unknown=True to load them as '{hf.UNKNOWN_CLASS}'"
        )
    if unknown:
        classes.get(hf.UNKNOWN_CLASS)
    out = []
    for i, f, name, t, q, s, mt, fixed, pose, urdf, recs, cfg_path in parsed:
        cls = class_of(name) or hf.UNKNOWN_CLASS
        if classes.get(cls).structure:
            raise UnknownNameError(f"{scene_path}: articulated template '{name}' maps to structure class '{cls}'")
        model = parse_urdf(urdf)
        dofs = model.movable_joints()
        if len(pose) > len(dofs):
            log.warning("%s: %s.initial_joint_pose has %d values, %s has %d movable joints: extra values ignored",
                        scene_path, f, len(pose), urdf, len(dofs))
        state = {}
        for k, jn in enumerate(dofs):
            v = pose[k] if k < len(pose) else 0.0
            if model.joints[jn].type == "prismatic":
                v = v / s  # habitat-sim: scaled metres; ours: metres of the unscaled model
            if cls == DOOR_CLASS and k >= len(pose) and model.joints[jn].type == "revolute" and model.joints[jn].limits:
                v = max(model.joints[jn].limits, key=abs)  # a door without a stated pose stands open (DOOR_CLASS)
            state[jn] = round(v, JOINT_STATE_DECIMALS) + 0.0
        lo, hi = local_bounds(model, state)
        lo, hi = s * lo, s * hi
        extra = {}
        if recs:
            poses = link_poses(model, state)
            for rec in recs:
                if rec["link"] is not None and rec["link"] not in poses:
                    fail(cfg_path, f"user_defined.{rec['name']}.parent_link", f"no link {rec['link']!r} in {urdf}")
            extra["receptacles"] = to_object_frame(recs, (s, s, s), lambda ln: poses[ln])
        out.append(ObjectInstance(
            id=first_id + i,
            cls=cls,
            asset=URDF_ASSET_PREFIX + Path(os.path.relpath(urdf, r)).as_posix(),
            position=hf.vec(_C @ t),
            rotation=hf.convert_quat(q),
            size=hf.vec(np.maximum(hi - lo, hf.MIN_EXTENT)),
            box_offset=hf.vec((lo + hi) / 2.0),
            support="floor",
            movable=False,
            scale=(s, s, s),
            params={"template": name, "articulated": True, "links": list(model.links), "joint_state": state,
                    "motion_type": mt, "fixed_base": fixed, **extra},
        ))
    return out


def with_joint_state(obj: ObjectInstance, root, state: dict[str, float]) -> ObjectInstance:
    """A copy of an articulated object at another joint state: its local box recomputed (scaled)."""
    model = parse_urdf(urdf_path(root, obj.asset))
    lo, hi = local_bounds(model, state)
    s = np.asarray(obj.scale, float)
    lo, hi = s * lo, s * hi
    params = {**obj.params, "joint_state": {k: round(float(v), JOINT_STATE_DECIMALS) + 0.0 for k, v in state.items()}}
    return ObjectInstance(obj.id, obj.cls, obj.asset, obj.position, obj.rotation, hf.vec(np.maximum(hi - lo, hf.MIN_EXTENT)),
                          hf.vec((lo + hi) / 2.0), obj.support, obj.movable, obj.scale, params)
