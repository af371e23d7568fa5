"""Load ReplicaCAD scenes as distributed (habitat-sim scene dataset format) into a ``Layout``.

No Blender here. The dataset folder looks like this (only what is read is listed)::

    <root>/configs/scenes/<scene>.scene_instance.json     stage_instance, object_instances, ...
    <root>/configs/objects/<template>.object_config.json  render_asset (a .glb), scale, COM, up/front
    <root>/configs/stages/<template>.stage_config.json    render_asset, scale, up/front, origin
    <root>/objects/*.glb, <root>/stages/*.glb             meshes (glTF: Y up, -Z forward)

Frames
    habitat-sim (and glTF) is right-handed with +Y up and -Z forward; ours is right-handed with
    +Z up. ``Y_UP_TO_Z_UP`` (called C below) maps habitat coordinates to ours,
    ``(x, y, z) -> (x, -z, y)``; it is a proper rotation (+90 deg about X), so meshes keep their
    face winding. The conversion happens once, here: a habitat pose ``T_h`` becomes
    ``T = C T_h C^T`` and a mesh vertex ``v_h`` becomes ``C v_h`` (``load_asset_mesh``), so world
    points agree: ``C (T_h v_h) = T (C v_h)``. For a quaternion this is ``(w, x, y, z) ->
    (w, x, -z, y)``: a rotation about habitat's vertical +Y is a yaw about our +Z by the same angle.

Scale
    Instance scale is ``uniform_scale * non_uniform_scale * <object config scale>``, per axis of the
    habitat object frame. C permutes the axes (habitat x, y, z become our x, z, y, up to sign), so
    ``ObjectInstance.scale = (s_x, s_z, s_y)``: the scale to apply to the ``load_asset_mesh`` vertices
    before ``ObjectInstance.matrix()``. ``size`` and ``box_offset`` are the local bounding box of
    those scaled vertices, so ``synth.scene.object_box`` gives the world box without meshes.

Translation origin (habitat-sim semantics)
    An object instance's ``translation`` places either the GLB's own origin ("asset_local") or the
    object's centre of mass ("COM": the config's ``COM``, else the centre of the mesh's bounding
    box; both scaled). The instance's ``translation_origin`` decides; when it is absent the scene
    file's top-level ``translation_origin`` does ("asset_local" there applies to every instance
    without its own value); otherwise it is "COM". The loader folds the COM shift into
    ``ObjectInstance.position``, so the instance's local frame is always the GLB's own frame.

Templates
    A template name (``objects/frl_apartment_chair_01`` or ``frl_apartment_chair_01``) is resolved
    like habitat-sim's handle lookup, against the configs that exist: ``configs/<name>``, then
    ``configs/objects/<basename>``, then any ``configs/objects/**/<basename>.object_config.json``
    (preferring one whose path ends with the template name). Stages likewise under ``configs/stages``.
    Paths inside configs (``render_asset``) are relative to the config file's folder.

Not supported
    * Articulated objects (``articulated_object_instances``, URDF): not loaded; their template names
      are listed in ``layout.meta["skipped_articulated"]``.
    * Room structure: ``Stage.rooms``, ``walls`` and ``openings`` stay empty. Structure boxes (walls,
      floors, ceilings) are not derived from ReplicaCAD stage meshes; the stage is one mesh asset.
    * Object or stage configs with a non-default ``up``/``front`` frame, scaled stages, a stage
      ``origin`` other than zero (all rejected with ``SceneFormatError``); lighting, navmeshes,
      semantic descriptors, ``units_to_meters``, ``is_instance_visible`` and ``user_defined``
      are ignored.
"""

from __future__ import annotations

import json
import logging
import math
import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import trimesh

from formats.boxes import MAX_OBJECT_ID
from formats.errors import SceneFormatError, UnknownNameError

from .classes import ClassTable, class_table
from .scene import Layout, ObjectInstance, Stage

log = logging.getLogger(__name__)

Y_UP_TO_Z_UP = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, -1.0], [0.0, 1.0, 0.0]])
"""Maps ReplicaCAD/habitat world coordinates (Y up, -Z forward) to ours (Z up): (x, y, z) -> (x, -z, y)."""

ASSET_PREFIX = "replicacad:"
SCENE_SUFFIX = ".scene_instance.json"
OBJECT_SUFFIX = ".object_config.json"
STAGE_SUFFIX = ".stage_config.json"
MOTION_TYPES = ("STATIC", "KINEMATIC", "DYNAMIC")
UNKNOWN_CLASS = "other"
MIN_EXTENT = 1e-3  # metres; flat meshes (pictures, rugs) get boxes at least this thick

_DEFAULT_UP = (0.0, 1.0, 0.0)
_DEFAULT_FRONT = (0.0, 0.0, -1.0)
_C = Y_UP_TO_Z_UP

# --------------------------------------------------------------------------------------------
# field checks: every error names the file and the field


def _fail(file, field: str | None, msg: str):
    raise SceneFormatError(file, field, msg)


def _number(file, v, field: str, positive: bool = False) -> float:
    if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(float(v)):
        _fail(file, field, f"expected a finite number, got {v!r}")
    if positive and v <= 0:
        _fail(file, field, f"must be > 0, got {v!r}")
    return float(v)


def _numbers(file, v, field: str, n: int, what: str = "", positive: bool = False) -> np.ndarray:
    ok = isinstance(v, list) and len(v) == n and all(
        not isinstance(x, bool) and isinstance(x, (int, float)) and math.isfinite(float(x)) for x in v
    )
    if not ok:
        _fail(file, field, f"expected {n} numbers{what}, got {v!r}")
    if positive and any(x <= 0 for x in v):
        _fail(file, field, f"expected {n} numbers > 0{what}, got {v!r}")
    return np.array([float(x) for x in v])


def _quat(file, v, field: str) -> np.ndarray:
    q = _numbers(file, v, field, 4, " (w, x, y, z)")
    n = float(np.linalg.norm(q))
    if abs(n - 1.0) > 1e-3:
        _fail(file, field, f"expected a unit quaternion (w, x, y, z), got {v!r} (norm {n:.4f})")
    return q / n


def _string(file, v, field: str) -> str:
    if not isinstance(v, str) or not v:
        _fail(file, field, f"expected a non-empty string, got {v!r}")
    return v


def _mapping(file, v, field: str | None) -> dict:
    if not isinstance(v, dict):
        _fail(file, field, f"expected a JSON object, got {type(v).__name__}")
    return v


def _read_json(path: Path):
    if not path.is_file():
        _fail(path, None, "file not found")
    try:
        return json.loads(path.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError) as e:
        problem = f"cannot read: {e}"
    except ValueError as e:  # json.JSONDecodeError
        problem = f"malformed JSON: {e}"
    _fail(path, None, problem)


def _check_frame(file, cfg: dict) -> None:
    """Accept only the glTF default frame (up +Y, front -Z), given or implied."""
    up = _numbers(file, cfg["up"], "up", 3) if "up" in cfg else np.array(_DEFAULT_UP)
    front = _numbers(file, cfg["front"], "front", 3) if "front" in cfg else np.array(_DEFAULT_FRONT)
    for field, vec, ref in (("up", up, _DEFAULT_UP), ("front", front, _DEFAULT_FRONT)):
        n = np.linalg.norm(vec)
        if n == 0 or not np.allclose(vec / n, ref, atol=1e-6):
            _fail(file, field, f"only the default frame (up {list(_DEFAULT_UP)}, front {list(_DEFAULT_FRONT)}) "
                               f"is supported, got {cfg.get(field)!r}")


def _translation_origin(file, v, field: str) -> str | None:
    """'asset_local', 'COM' or None (unknown / not given)."""
    if v is None:
        return None
    s = _string(file, v, field).lower()
    if s == "asset_local":
        return "asset_local"
    if s == "com":
        return "COM"
    if s == "unknown":
        return None
    _fail(file, field, f"expected 'asset_local' or 'COM', got {v!r}")


# --------------------------------------------------------------------------------------------
# dataset paths


def _root(root) -> Path:
    p = Path(root).expanduser()
    if not p.is_dir():
        _fail(p, None, "ReplicaCAD dataset folder not found")
    return p.resolve()


def list_scenes(root) -> list[str]:
    """Names of the scenes in ``<root>/configs/scenes`` (``apt_0``, ``v3_sc0_staging_00``, ...)."""
    d = _root(root) / "configs" / "scenes"
    if not d.is_dir():
        _fail(d, None, "folder not found (not a ReplicaCAD dataset root?)")
    return sorted(p.name[: -len(SCENE_SUFFIX)] for p in d.glob("*" + SCENE_SUFFIX) if p.is_file())


class _ConfigFinder:
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


def _asset_name(root: Path, glb: Path) -> str:
    return ASSET_PREFIX + Path(os.path.relpath(glb, root)).as_posix()


def _render_asset(root: Path, config: Path, cfg: dict) -> Path:
    rel = _string(config, cfg.get("render_asset"), "render_asset")
    glb = Path(os.path.normpath(config.parent / rel))
    if not glb.is_file():
        _fail(config, "render_asset", f"GLB not found: {glb}")
    return glb


# --------------------------------------------------------------------------------------------
# meshes

_MESH_CACHE: dict[tuple[str, int, int], trimesh.Trimesh] = {}
_MESH_CACHE_MAX = 64


def _read_glb(path: Path) -> trimesh.Trimesh:
    """All triangles of a GLB (node transforms applied), in the file's own Y-up frame."""
    mesh = None
    err: Exception | None = None
    for kwargs in ({}, {"skip_materials": True}):  # textures that fail to decode: geometry only
        try:
            mesh = trimesh.load(str(path), file_type="glb", force="mesh", process=False, **kwargs)
            break
        except Exception as e:  # noqa: BLE001 - trimesh raises many types for broken files
            err = e
    if mesh is None:
        _fail(path, None, f"cannot read GLB: {err}")
    if not isinstance(mesh, trimesh.Trimesh) or len(mesh.faces) == 0:
        _fail(path, None, "GLB has no triangles")
    return mesh


def _converted_mesh(path: Path) -> trimesh.Trimesh:
    """The GLB's mesh with vertices ``C v`` (cached by path, size and modification time)."""
    st = path.stat()
    key = (str(path.resolve()), st.st_mtime_ns, st.st_size)
    mesh = _MESH_CACHE.get(key)
    if mesh is None:
        mesh = _read_glb(path)
        T = np.eye(4)
        T[:3, :3] = _C
        mesh.apply_transform(T)
        if len(_MESH_CACHE) >= _MESH_CACHE_MAX:
            _MESH_CACHE.pop(next(iter(_MESH_CACHE)))
        _MESH_CACHE[key] = mesh
    return mesh


def load_asset_mesh(root, asset: str) -> trimesh.Trimesh:
    """Mesh of ``"replicacad:<glb path relative to root>"`` in our Z-up local frame, unscaled.

    Vertices are ``Y_UP_TO_Z_UP @ v`` for the GLB's vertices ``v`` (node transforms applied). Place it
    with ``ObjectInstance.scale`` (per axis, first) and then ``ObjectInstance.matrix()``; for the
    stage with ``Stage.position``/``Stage.rotation``. Returns a new copy on every call.
    """
    r = _root(root)
    if not isinstance(asset, str) or not asset.startswith(ASSET_PREFIX) or len(asset) == len(ASSET_PREFIX):
        raise UnknownNameError(f"not a ReplicaCAD asset name: {asset!r} (expected '{ASSET_PREFIX}<relative glb path>')")
    path = r / asset[len(ASSET_PREFIX):]
    if not path.is_file():
        _fail(path, None, f"GLB not found (asset {asset!r})")
    return _converted_mesh(path).copy()


# --------------------------------------------------------------------------------------------
# poses


def _convert_quat(q) -> tuple[float, float, float, float]:
    """Habitat (w, x, y, z) -> ours: the rotation C R C^T, i.e. (w, x, -z, y), with w >= 0."""
    w, x, y, z = (float(v) for v in q)
    out = np.array([w, x, -z, y])
    out /= np.linalg.norm(out)
    if out[0] < 0:
        out = -out
    return tuple(float(v) + 0.0 for v in out)  # + 0.0: no negative zeros in the files


def _hab_matrix(q) -> np.ndarray:
    w, x, y, z = q
    return np.array([
        [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
        [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
        [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
    ])


def _vec(v) -> tuple[float, float, float]:
    return tuple(float(x) + 0.0 for x in v)


@dataclass
class _Template:
    config: Path
    glb: Path
    asset: str
    scale: np.ndarray  # config scale, habitat object axes
    com: np.ndarray | None  # config COM, habitat object frame, unscaled


@dataclass
class _Instance:
    index: int
    template_name: str
    template: _Template
    cls: str | None
    translation: np.ndarray
    rotation: np.ndarray
    scale: np.ndarray  # habitat object axes, all factors
    motion_type: str
    asset_local: bool


def _object_template(root: Path, config: Path) -> _Template:
    cfg = _mapping(config, _read_json(config), None)
    glb = _render_asset(root, config, cfg)
    scale = _numbers(config, cfg["scale"], "scale", 3, positive=True) if "scale" in cfg else np.ones(3)
    com = _numbers(config, cfg["COM"], "COM", 3) if "COM" in cfg else None
    _check_frame(config, cfg)
    return _Template(config, glb, _asset_name(root, glb), scale, com)


def _load_stage(root: Path, scene_path: Path, doc: dict) -> Stage:
    if "stage_instance" not in doc:
        _fail(scene_path, "stage_instance", "missing (every scene needs a stage)")
    st = _mapping(scene_path, doc["stage_instance"], "stage_instance")
    name = _string(scene_path, st.get("template_name"), "stage_instance.template_name")
    if name.upper() == "NONE":
        _fail(scene_path, "stage_instance.template_name", "scenes without a stage ('NONE') are not supported")
    config = _ConfigFinder(root, "stages", STAGE_SUFFIX).find(name)
    if config is None:
        _fail(scene_path, "stage_instance.template_name",
              f"no stage config for '{name}' (looked for {name.rsplit('/', 1)[-1]}{STAGE_SUFFIX} under {root / 'configs'})")
    cfg = _mapping(config, _read_json(config), None)
    glb = _render_asset(root, config, cfg)
    _check_frame(config, cfg)
    if "scale" in cfg and not np.allclose(_numbers(config, cfg["scale"], "scale", 3), 1.0):
        _fail(config, "scale", f"scaled stages are not supported, got {cfg['scale']!r}")
    if "origin" in cfg and not np.allclose(_numbers(config, cfg["origin"], "origin", 3), 0.0):
        _fail(config, "origin", f"a stage origin other than [0, 0, 0] is not supported, got {cfg['origin']!r}")
    f = "stage_instance"
    t = _numbers(scene_path, st["translation"], f + ".translation", 3) if "translation" in st else np.zeros(3)
    q = _quat(scene_path, st["rotation"], f + ".rotation") if "rotation" in st else np.array([1.0, 0, 0, 0])
    if "uniform_scale" in st and _number(scene_path, st["uniform_scale"], f + ".uniform_scale") != 1.0:
        _fail(scene_path, f + ".uniform_scale", f"scaled stages are not supported, got {st['uniform_scale']!r}")
    if "non_uniform_scale" in st and not np.allclose(_numbers(scene_path, st["non_uniform_scale"], f + ".non_uniform_scale", 3), 1.0):
        _fail(scene_path, f + ".non_uniform_scale", f"scaled stages are not supported, got {st['non_uniform_scale']!r}")

    position = _vec(_C @ t)
    rotation = _convert_quat(q)
    mesh = _converted_mesh(glb)
    R = _hab_matrix(rotation)  # same formula, our frame
    z = mesh.vertices @ R[2] + position[2]
    zmin, zmax = float(z.min()), float(z.max())
    if zmax - zmin <= 0:
        _fail(glb, None, "stage mesh has no height")
    return Stage(ceiling_height=zmax - zmin, floor_z=zmin, asset=_asset_name(root, glb), position=position, rotation=rotation)


def _parse_instances(root: Path, scene_path: Path, doc: dict, classes: ClassTable) -> list[_Instance]:
    raw = doc.get("object_instances", [])
    if not isinstance(raw, list):
        _fail(scene_path, "object_instances", f"expected a list, got {type(raw).__name__}")
    if len(raw) > MAX_OBJECT_ID:
        _fail(scene_path, "object_instances", f"{len(raw)} objects; at most {MAX_OBJECT_ID} are supported")
    scene_origin = _translation_origin(scene_path, doc.get("translation_origin"), "translation_origin")
    finder = _ConfigFinder(root, "objects", OBJECT_SUFFIX)
    templates: dict[Path, _Template] = {}
    out = []
    for i, inst in enumerate(raw):
        f = f"object_instances[{i}]"
        _mapping(scene_path, inst, f)
        name = _string(scene_path, inst.get("template_name"), f + ".template_name")
        t = _numbers(scene_path, inst["translation"], f + ".translation", 3) if "translation" in inst else np.zeros(3)
        q = _quat(scene_path, inst["rotation"], f + ".rotation") if "rotation" in inst else np.array([1.0, 0, 0, 0])
        scale = np.ones(3)
        if "uniform_scale" in inst:
            scale = scale * _number(scene_path, inst["uniform_scale"], f + ".uniform_scale", positive=True)
        if "non_uniform_scale" in inst:
            scale = scale * _numbers(scene_path, inst["non_uniform_scale"], f + ".non_uniform_scale", 3, positive=True)
        if "motion_type" in inst:
            mt = _string(scene_path, inst["motion_type"], f + ".motion_type").upper()
            if mt not in MOTION_TYPES:
                _fail(scene_path, f + ".motion_type", f"expected one of {', '.join(MOTION_TYPES)}, got {inst['motion_type']!r}")
        else:
            mt = "UNDEFINED"
        origin = _translation_origin(scene_path, inst.get("translation_origin"), f + ".translation_origin")
        asset_local = origin == "asset_local" or (origin is None and scene_origin == "asset_local")
        config = finder.find(name)
        if config is None:
            base = name.replace("\\", "/").rsplit("/", 1)[-1]
            _fail(scene_path, f + ".template_name",
                  f"no object config for '{name}' (looked for {base}{OBJECT_SUFFIX} under {root / 'configs' / 'objects'})")
        if config not in templates:
            templates[config] = _object_template(root, config)
        tmpl = templates[config]
        out.append(_Instance(i, name, tmpl, classes.replicacad_class(name), t, q, scale * tmpl.scale, mt, asset_local))
    return out


def _articulated_names(scene_path: Path, doc: dict) -> list[str]:
    raw = doc.get("articulated_object_instances", [])
    if not isinstance(raw, list):
        _fail(scene_path, "articulated_object_instances", f"expected a list, got {type(raw).__name__}")
    names = []
    for i, a in enumerate(raw):
        f = f"articulated_object_instances[{i}]"
        _mapping(scene_path, a, f)
        names.append(_string(scene_path, a.get("template_name"), f + ".template_name"))
    return names


def _object(inst: _Instance, oid: int, cls: str) -> ObjectInstance:
    mesh = _converted_mesh(inst.template.glb)  # vertices C v, unscaled
    S_h = inst.scale
    R_h = _hab_matrix(inst.rotation)
    if inst.asset_local:
        origin_h = np.zeros(3)
    elif inst.template.com is not None:
        origin_h = inst.template.com
    else:
        origin_h = _C.T @ mesh.bounds.mean(axis=0)  # bounding-box centre, back in the habitat frame
    position = _C @ (inst.translation - R_h @ (S_h * origin_h))
    scale = np.abs(_C) @ S_h  # (s_x, s_z, s_y)
    lo, hi = scale * mesh.bounds[0], scale * mesh.bounds[1]
    return ObjectInstance(
        id=oid,
        cls=cls,
        asset=inst.template.asset,
        position=_vec(position),
        rotation=_convert_quat(inst.rotation),
        size=_vec(np.maximum(hi - lo, MIN_EXTENT)),
        box_offset=_vec((lo + hi) / 2.0),
        support="free",  # ReplicaCAD places objects by physics: no support relation is recorded
        movable=inst.motion_type != "STATIC",
        scale=_vec(scale),
        params={"template": inst.template_name, "motion_type": inst.motion_type},
    )


def load_replicacad(root, scene: str, classes: ClassTable | None = None, allow_unknown: bool = False) -> Layout:
    """Read ``<root>/configs/scenes/<scene>.scene_instance.json`` into a Layout (see the module docstring).

    Object ids are 1.. in file order of ``object_instances``; classes come from
    ``ClassTable.replicacad_class``. Templates without a class rule raise ``UnknownNameError``
    naming all of them, unless ``allow_unknown`` maps them to class ``"other"``. Bad files or
    fields raise ``SceneFormatError`` naming the file and the field.
    """
    r = _root(root)
    classes = classes or class_table()
    scene_path = r / "configs" / "scenes" / f"{scene}{SCENE_SUFFIX}"
    if not isinstance(scene, str) or not scene or not scene_path.is_file():
        known = ", ".join(list_scenes(r)) if (r / "configs" / "scenes").is_dir() else "none"
        _fail(scene_path, None, f"scene {scene!r} not found; scenes in {r}: {known or 'none'}")
    doc = _mapping(scene_path, _read_json(scene_path), "(top level)")

    instances = _parse_instances(r, scene_path, doc, classes)
    skipped = _articulated_names(scene_path, doc)
    unknown = sorted({inst.template_name for inst in instances if inst.cls is None})
    if unknown and not allow_unknown:
        raise UnknownNameError(
            f"{scene_path}: no class rule for ReplicaCAD template(s) {', '.join(unknown)}; add aliases under "
            f"replicacad.aliases in {classes.source} or pass allow_unknown=True to load them as '{UNKNOWN_CLASS}'"
        )
    if unknown:
        classes.get(UNKNOWN_CLASS)  # UnknownNameError if the table has no fallback class
    for inst in instances:
        if inst.cls is not None and classes.get(inst.cls).structure:
            raise UnknownNameError(f"{scene_path}: template '{inst.template_name}' maps to structure class '{inst.cls}'")

    stage = _load_stage(r, scene_path, doc)
    objects = [_object(inst, k + 1, inst.cls or UNKNOWN_CLASS) for k, inst in enumerate(instances)]
    if skipped:
        log.info("%s: skipped %d articulated object(s) (URDF, not supported): %s", scene_path, len(skipped), ", ".join(skipped))
    meta = {"source": "replicacad", "root": str(r), "scene": scene, "skipped_articulated": skipped}
    return Layout(name=scene, stage=stage, objects=objects, meta=meta)
