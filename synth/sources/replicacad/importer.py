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
    those scaled vertices, so ``synth.scene.model.object_box`` gives the world box without meshes.

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

Structure, articulated objects, supports, lights (``structure=True``, the default)
    * The stage's walls, doors, windows, rooms, floor and ceiling are derived from its mesh
      (``synth.mesh.stage_structure``), so a ReplicaCAD layout has structure boxes, rooms for camera
      paths and rearrangement, and per-triangle wall/floor/ceiling instance ids in renders.
    * Articulated objects (``articulated_object_instances``, URDF) load as one static object each in
      their default joint state (``synth.mesh.urdf``; asset ``"replicacad-urdf:<urdf path>"``), ids after
      the rigid objects.
    * Supports are inferred from the boxes (``infer_supports``): floor, the top of another object, or
      ``free``.
    * Light fixtures come from the scene's ``default_lighting`` config (``synth.sources.replicacad.habitat_lighting``).
    ``structure=False`` keeps the older reading: the stage is one mesh without structure and
    articulated objects are skipped (listed in ``layout.meta["skipped_articulated"]``).

Not supported
    * Object or stage configs with a non-default ``up``/``front`` frame, scaled stages, a stage
      ``origin`` other than zero (all rejected with ``SceneFormatError``); navmeshes, semantic
      descriptors, ``units_to_meters``, ``is_instance_visible`` and ``user_defined`` are ignored.
"""

from __future__ import annotations

import logging
import math
import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from vrformats.boxes import MAX_OBJECT_ID
from vrformats.errors import UnknownNameError
from vrformats.fields import integer, nonneg_int, shown

from ...scene.classes import ClassTable, LexiconTable, class_table, lexicon_table
from .receptacles import read_receptacles, to_object_frame
from .habitat_format import ASSET_PREFIX, MIN_EXTENT, dataset_config_path, MOTION_TYPES, UNKNOWN_CLASS, URDF_PREFIX, Y_UP_TO_Z_UP, ConfigFinder, asset_name, check_frame, convert_quat, dataset_root, fail, hab_matrix, inside_root, mapping, number, numbers, quat, read_json, render_asset, string, translation_origin, vec
from ...mesh.gltf import check_glb, glb_geometry
from ...mesh.mesh_assets import load_asset_mesh
from ...scene.model import Layout, ObjectInstance, Stage

log = logging.getLogger(__name__)

__all__ = ["ASSET_PREFIX", "URDF_PREFIX", "Y_UP_TO_Z_UP", "infer_supports", "list_scenes", "load_asset_mesh", "load_replicacad"]

LIGHTING_SUFFIX = ".lighting_config.json"
SUPPORT_SNAP = 0.03  # m: an object whose bottom is this close to the floor or to a supporting surface rests on it
FLOOR_SINK = 0.05  # m: ... or this far below the floor (visual meshes sink into it: a bike's tyres, a beanbag, a door leaf)
BOX_TOP_SNAP = 0.005  # m: ... or this close to the box top of an object without surfaces (a monitor 2 cm above its stand's box is mounted on it)
SCENE_SUFFIX = ".scene_instance.json"
OBJECT_SUFFIX = ".object_config.json"
STAGE_SUFFIX = ".stage_config.json"
_C = Y_UP_TO_Z_UP

# --------------------------------------------------------------------------------------------
# dataset paths


def list_scenes(root) -> list[str]:
    """Names of the scenes in ``<root>/configs/scenes`` (``apt_0``, ``v3_sc0_staging_00``, ...)."""
    d = dataset_root(root, require_config=True) / "configs" / "scenes"
    if not d.is_dir():
        fail(d, None, "folder not found (not a ReplicaCAD dataset root?)")
    return sorted(p.name[: -len(SCENE_SUFFIX)] for p in d.glob("*" + SCENE_SUFFIX) if p.is_file())


@dataclass
class _Template:
    config: Path
    glb: Path
    asset: str
    scale: np.ndarray  # config scale, habitat object axes
    com: np.ndarray | None  # config COM, habitat object frame, unscaled
    semantic_id: int | None = None  # the config's semantic_id (the dataset's lexicon names it)
    receptacles: tuple = ()  # the config's user_defined receptacle_aabb_* (habitat object frame, unscaled)
    collision: str | None = None  # the config's collision_asset, relative to the root (synth.mesh.collision)
    margin: float | None = None  # the config's collision margin (m); None: habitat-sim's default (synth.mesh.collision)


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
    soft: bool = False  # a soft furnishing (scenes/replicacad_lexicon.yaml: soft)


def _object_template(root: Path, config: Path) -> _Template:
    cfg = mapping(config, read_json(config), None)
    glb = render_asset(root, config, cfg)
    check_glb(glb)  # a missing texture is named (images[i].uri) at import, not at render time
    scale = numbers(config, cfg["scale"], "scale", 3, positive=True) if "scale" in cfg else np.ones(3)
    com = numbers(config, cfg["COM"], "COM", 3) if "COM" in cfg else None
    check_frame(config, cfg)
    sid = None
    if "semantic_id" in cfg:
        sid = nonneg_int(config, cfg["semantic_id"], "semantic_id")
    collision = "box" if cfg.get("use_bounding_box_for_collision") is True else None
    if collision is None and isinstance(cfg.get("collision_asset"), str) and cfg["collision_asset"]:
        cpath = inside_root(config, "collision_asset", config.parent / cfg["collision_asset"], root)
        if cpath.is_file():  # optional: the checks fall back to the object's box without it
            check_glb(cpath)
            collision = Path(os.path.relpath(cpath, root)).as_posix()
    margin = number(config, cfg["margin"], "margin") if "margin" in cfg else None
    if margin is not None and margin < 0:
        fail(config, "margin", f"must be >= 0, got {cfg['margin']!r}")
    return _Template(config, glb, asset_name(root, glb), scale, com, sid, read_receptacles(config, cfg), collision, margin)


def _load_stage(root: Path, scene_path: Path, doc: dict, structure: bool = True) -> tuple[Stage, dict]:
    if "stage_instance" not in doc:
        fail(scene_path, "stage_instance", "missing (every scene needs a stage)")
    st = mapping(scene_path, doc["stage_instance"], "stage_instance")
    name = string(scene_path, st.get("template_name"), "stage_instance.template_name")
    if name.upper() == "NONE":
        fail(scene_path, "stage_instance.template_name", "scenes without a stage ('NONE') are not supported")
    config = ConfigFinder(root, "stages", STAGE_SUFFIX).find(name)
    if config is None:
        fail(scene_path, "stage_instance.template_name",
              f"no stage config for '{name}' (looked for {name.rsplit('/', 1)[-1]}{STAGE_SUFFIX} under {root / 'configs'})")
    cfg = mapping(config, read_json(config), None)
    glb = render_asset(root, config, cfg)
    check_frame(config, cfg)
    if "scale" in cfg and not np.allclose(numbers(config, cfg["scale"], "scale", 3), 1.0):
        fail(config, "scale", f"scaled stages are not supported, got {cfg['scale']!r}")
    if "origin" in cfg and not np.allclose(numbers(config, cfg["origin"], "origin", 3), 0.0):
        fail(config, "origin", f"a stage origin other than [0, 0, 0] is not supported, got {cfg['origin']!r}")
    f = "stage_instance"
    t = numbers(scene_path, st["translation"], f + ".translation", 3) if "translation" in st else np.zeros(3)
    q = quat(scene_path, st["rotation"], f + ".rotation") if "rotation" in st else np.array([1.0, 0, 0, 0])
    if "uniform_scale" in st and number(scene_path, st["uniform_scale"], f + ".uniform_scale") != 1.0:
        fail(scene_path, f + ".uniform_scale", f"scaled stages are not supported, got {st['uniform_scale']!r}")
    if "non_uniform_scale" in st and not np.allclose(numbers(scene_path, st["non_uniform_scale"], f + ".non_uniform_scale", 3), 1.0):
        fail(scene_path, f + ".non_uniform_scale", f"scaled stages are not supported, got {st['non_uniform_scale']!r}")

    position = vec(_C @ t)
    rotation = convert_quat(q)
    check_glb(glb)  # a missing texture is named (images[i].uri) at import, not at render time
    mesh = glb_geometry(glb)
    R = hab_matrix(rotation)  # same formula, our frame
    T = np.eye(4)
    T[:3, :3], T[:3, 3] = R, position
    world = mesh.copy()
    world.apply_transform(T)
    if float(np.ptp(world.vertices[:, 2])) <= 0:
        fail(glb, None, "stage mesh has no height")
    if not structure:
        z = world.vertices[:, 2]
        zmin, zmax = float(z.min()), float(z.max())
        return Stage(ceiling_height=zmax - zmin, floor_z=zmin, asset=asset_name(root, glb), position=position, rotation=rotation), {}
    from ...mesh.stage_structure import derive_structure

    stage_margin = number(config, cfg["margin"], "margin") if "margin" in cfg else None
    st = derive_structure(world, str(glb))
    stage = Stage(ceiling_height=st.ceiling_height, floor_z=st.floor_z, rooms=st.rooms, walls=st.walls, openings=st.openings,
                  asset=asset_name(root, glb), position=position, rotation=rotation)
    report = dict(st.report)
    if stage_margin is not None:
        report["margin"] = stage_margin  # the stage's collision margin (synth.mesh.collision)
    return stage, report


def _parse_instances(root: Path, scene_path: Path, doc: dict, classes: ClassTable, semantics: Semantics) -> list[_Instance]:
    raw = doc.get("object_instances", [])
    if not isinstance(raw, list):
        fail(scene_path, "object_instances", f"expected a list, got {type(raw).__name__}")
    if len(raw) > MAX_OBJECT_ID:
        fail(scene_path, "object_instances", f"{len(raw)} objects; at most {MAX_OBJECT_ID} are supported")
    scene_origin = translation_origin(scene_path, doc.get("translation_origin"), "translation_origin")
    finder = ConfigFinder(root, "objects", OBJECT_SUFFIX)
    templates: dict[Path, _Template] = {}
    out = []
    for i, inst in enumerate(raw):
        f = f"object_instances[{i}]"
        mapping(scene_path, inst, f)
        name = string(scene_path, inst.get("template_name"), f + ".template_name")
        t = numbers(scene_path, inst["translation"], f + ".translation", 3) if "translation" in inst else np.zeros(3)
        q = quat(scene_path, inst["rotation"], f + ".rotation") if "rotation" in inst else np.array([1.0, 0, 0, 0])
        scale = np.ones(3)
        if "uniform_scale" in inst:
            scale = scale * number(scene_path, inst["uniform_scale"], f + ".uniform_scale", positive=True)
        if "non_uniform_scale" in inst:
            scale = scale * numbers(scene_path, inst["non_uniform_scale"], f + ".non_uniform_scale", 3, positive=True)
        if "motion_type" in inst:
            mt = string(scene_path, inst["motion_type"], f + ".motion_type").upper()
            if mt not in MOTION_TYPES:
                fail(scene_path, f + ".motion_type", f"expected one of {', '.join(MOTION_TYPES)}, got {inst['motion_type']!r}")
        else:
            mt = "UNDEFINED"
        origin = translation_origin(scene_path, inst.get("translation_origin"), f + ".translation_origin")
        asset_local = origin == "asset_local" or (origin is None and scene_origin == "asset_local")
        config = finder.find(name)
        if config is None:
            base = name.replace("\\", "/").rsplit("/", 1)[-1]
            fail(scene_path, f + ".template_name",
                  f"no object config for '{name}' (looked for {base}{OBJECT_SUFFIX} under {root / 'configs' / 'objects'})")
        if config not in templates:
            templates[config] = _object_template(root, config)
        tmpl = templates[config]
        soft = semantics.names is not None and semantics.names.get(tmpl.semantic_id) in semantics.table.soft
        out.append(_Instance(i, name, tmpl, object_class(name, tmpl.semantic_id, tmpl.config, semantics, classes),
                             t, q, scale * tmpl.scale, mt, asset_local, soft))
    return out


@dataclass(frozen=True)
class Semantics:
    """What names an imported object's class: the dataset's lexicon (semantic id -> name, from the
    file the scene dataset config names) and the toolkit's table (``scenes/replicacad_lexicon.yaml``)."""

    names: dict[int, str] | None  # None: the dataset has no lexicon (name rules only)
    source: Path | None
    table: LexiconTable


def read_semantics(root: Path, scene_path: Path, doc: dict, classes: ClassTable) -> Semantics:
    """The lexicon of a scene as habitat-sim finds it: the scene's ``semantic_scene_instance``, else the
    scene dataset config's ``scene_instances.default_attributes.semantic_scene_instance``, is a key of
    the config's ``semantic_scene_descriptor_instances``, whose value is the lexicon's path relative to
    the root. A dataset without a config or without that entry has no lexicon."""
    table = lexicon_table(classes=classes)
    cfg_path = dataset_config_path(root, required=False)
    if cfg_path is None:
        return Semantics(None, None, table)
    cfg = mapping(cfg_path, read_json(cfg_path), None)
    descs = cfg.get("semantic_scene_descriptor_instances")
    if descs is None:
        return Semantics(None, None, table)
    descs = mapping(cfg_path, descs, "semantic_scene_descriptor_instances")
    key = doc.get("semantic_scene_instance")
    field = "semantic_scene_instance"
    where = scene_path
    if key is None:
        si = cfg.get("scene_instances") or {}
        key = ((si.get("default_attributes") or {}) if isinstance(si, dict) else {}).get("semantic_scene_instance")
        field, where = "scene_instances.default_attributes.semantic_scene_instance", cfg_path
    if key is None:
        return Semantics(None, None, table)
    key = string(where, key, field)
    if key not in descs:
        fail(where, field, f"names '{key}', which semantic_scene_descriptor_instances in {cfg_path.name} lacks")
    rel = string(cfg_path, descs[key], f"semantic_scene_descriptor_instances.{key}")
    lex = inside_root(cfg_path, f"semantic_scene_descriptor_instances.{key}", root / rel, root)
    if not lex.is_file():
        fail(cfg_path, f"semantic_scene_descriptor_instances.{key}", f"lexicon not found: {lex}")
    doc_l = mapping(lex, read_json(lex), None)
    raw = doc_l.get("classes")
    if not isinstance(raw, list):
        fail(lex, "classes", "expected a list of {name, id}")
    names: dict[int, str] = {}
    for k, c in enumerate(raw):
        c = mapping(lex, c, f"classes[{k}]")
        cid, nm = c.get("id"), c.get("name")
        integer(lex, cid, f"classes[{k}].id")
        nm = string(lex, nm, f"classes[{k}].name")
        if cid in names:  # which name would habitat use? not ours to guess: a basket must not import as a bed
            first = next(j for j, c2 in enumerate(raw) if isinstance(c2, dict) and c2.get("id") == cid)
            fail(lex, f"classes[{k}].id", f"id {cid} ({shown(nm)}) is already classes[{first}] ({shown(names[cid])})")
        names[cid] = nm
    missing = sorted(set(names.values()) - set(table.lexicon))
    if missing:
        fail(lex, "classes", f"lexicon name(s) {', '.join(missing)} have no class in {table.source}")
    return Semantics(names, lex, table)


def object_class(template_name: str, semantic_id: int | None, config: Path | None, semantics: Semantics,
                 classes: ClassTable) -> str | None:
    """An imported object's class (scenes/replicacad_lexicon.yaml says the order): a template override,
    else the lexicon name of its ``semantic_id``, else the name rules of the class table; None when
    nothing maps it. A semantic id that the dataset's lexicon lacks is an error naming the config."""
    name = None
    if semantic_id is not None and semantics.names is not None:
        name = semantics.names.get(semantic_id)
        if name is None and semantics.table.class_of(template_name, None)[0] is None:
            fail(config, "semantic_id", f"{semantic_id} is not in the dataset's lexicon {semantics.source}")
    cls, _ = semantics.table.class_of(template_name, name)
    return cls if cls is not None else classes.replicacad_class(template_name)


def _articulated_names(scene_path: Path, doc: dict) -> list[str]:
    raw = doc.get("articulated_object_instances", [])
    if not isinstance(raw, list):
        fail(scene_path, "articulated_object_instances", f"expected a list, got {type(raw).__name__}")
    names = []
    for i, a in enumerate(raw):
        f = f"articulated_object_instances[{i}]"
        mapping(scene_path, a, f)
        names.append(string(scene_path, a.get("template_name"), f + ".template_name"))
    return names


def _object(inst: _Instance, oid: int, cls: str) -> ObjectInstance:
    mesh = glb_geometry(inst.template.glb)  # vertices C v, unscaled
    S_h = inst.scale
    R_h = hab_matrix(inst.rotation)
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
        position=vec(position),
        rotation=convert_quat(inst.rotation),
        size=vec(np.maximum(hi - lo, MIN_EXTENT)),
        box_offset=vec((lo + hi) / 2.0),
        support="free",  # ReplicaCAD places objects by physics: no support relation is recorded
        movable=inst.motion_type != "STATIC",
        scale=vec(scale),
        params={"template": inst.template_name, "motion_type": inst.motion_type,
                **({"receptacles": to_object_frame(inst.template.receptacles, scale)} if inst.template.receptacles else {}),
                **({"collision": inst.template.collision} if inst.template.collision else {}),
                **({"margin": inst.template.margin} if inst.template.margin is not None else {}),
                **({"soft": True} if inst.soft else {})},
    )


def _lighting_config(root: Path, scene_path: Path, doc: dict) -> Path | None:
    """The scene's ``default_lighting`` config file, or None when it names none ("", "default", "no_lights")."""
    name = doc.get("default_lighting")
    if name is None:
        return None
    name = string(scene_path, name, "default_lighting") if name != "" else ""
    if name.lower() in ("", "default", "no_lights", "none"):
        return None
    config = ConfigFinder(root, "lighting", LIGHTING_SUFFIX).find(name)
    if config is None:
        fail(scene_path, "default_lighting",
              f"no lighting config for '{name}' (looked for {name.rsplit('/', 1)[-1]}{LIGHTING_SUFFIX} under {root / 'configs'})")
    return config


def infer_supports(objects: list[ObjectInstance], floor_z: float, root=None) -> list[ObjectInstance]:
    """What each object rests on, from the boxes and the supporting surfaces of the meshes
    (ReplicaCAD records no support relation).

    An object whose box bottom lies within ``SUPPORT_SNAP`` of the floor stands on the floor; else one
    whose bottom lies within it of a supporting surface of another object (``synth.layout.placement.
    mesh_surfaces``: the box top, a seat, a shelf board), with its footprint centre on that surface,
    stands on it (``object:<id>:<surface>``; the highest such surface); else one whose bottom meets
    the top of another object's box that its footprint overlaps stands on that object (surface 0;
    objects of classes that hold nothing); else it stays ``free`` (hanging, leaning, or placed by
    physics in a way boxes do not explain). A supported object is moved vertically onto its support
    (physics leaves gaps of a few millimetres; the shift is recorded in ``params.snapped_m``), so the
    layout checks, which allow 3 mm, hold. Objects are processed bottom-up so that a stack snaps in
    order.
    """
    from ...scene import geometry as geo
    from ...mesh.surfaces import mesh_surfaces
    from ...scene.model import object_box

    by_z = sorted(objects, key=lambda o: (object_box(o).zmin, o.id))
    placed: dict[int, ObjectInstance] = {}
    for o in by_z:
        box = object_box(o)
        support, target = "free", None
        centre = np.asarray(box.center[:2], float)
        if -FLOOR_SINK <= box.zmin - floor_z <= SUPPORT_SNAP:
            support, target = "floor", floor_z
        else:
            best = None
            for p in placed.values():
                pb = object_box(p)
                if pb.zmin >= box.zmin:
                    continue
                local = geo.rot_z(p.yaw)[:2, :2].T @ (centre - np.asarray(p.position[:2], float))
                surfs = mesh_surfaces(p, root) if root is not None else []
                for k, srf in enumerate(surfs):
                    zs = p.position[2] + srf.z
                    if zs - SUPPORT_SNAP <= box.zmin <= zs + srf.band + SUPPORT_SNAP and srf.xmin <= local[0] <= srf.xmax \
                            and srf.ymin <= local[1] <= srf.ymax:
                        # resting in a receptacle's band needs no snap; below a surface or above the band it does
                        z_to = min(max(box.zmin, zs), zs + srf.band)
                        if best is None or zs > best[3]:
                            best = (p.id, k, z_to, zs)
                # an object without supporting surfaces holds what rests on its box top (checked the
                # same way by synth.layout.validity); one with surfaces holds things on them only: the index
                # names one of its surfaces, never its box top
                if (best is None or best[0] != p.id) and not surfs:
                    if abs(pb.zmax - box.zmin) <= BOX_TOP_SNAP and geo.polygons_overlap_2d(pb.corners_2d(), box.corners_2d()):
                        if best is None or pb.zmax > best[3]:
                            best = (p.id, 0, pb.zmax, pb.zmax)
            if best is not None:
                support, target = f"object:{best[0]}:{best[1]}", best[2]
        params = dict(o.params)
        pos = o.position
        if target is not None and box.zmin != target:
            dz = target - box.zmin
            pos = (pos[0], pos[1], pos[2] + dz)
            if abs(dz) >= 5e-5:
                params["snapped_m"] = round(dz, 4)
        placed[o.id] = ObjectInstance(o.id, o.cls, o.asset, pos, o.rotation, o.size, o.box_offset, support, o.movable, o.scale, params)
    return [placed[o.id] for o in objects]


def scene_objects(root, scene_path, doc: dict, allow_unknown: bool = True) -> list[ObjectInstance]:
    """The objects of a scene as ``load_replicacad`` reads them (rigid objects, then articulated ones
    from their URDFs, doors opened), without its stage, supports or lights: for tools that build a
    stage around them (``tools/replicacad_standin.py``). Door leaves collide only with these objects."""
    r = dataset_root(root, require_config=True)
    classes = class_table()
    semantics = read_semantics(r, Path(scene_path), doc, classes)
    instances = _parse_instances(r, Path(scene_path), doc, classes, semantics)
    objects = [_object(inst, k + 1, inst.cls or UNKNOWN_CLASS) for k, inst in enumerate(instances)]
    from .articulated import load_articulated_instances

    objects += load_articulated_instances(r, Path(scene_path), doc, len(objects) + 1, classes, allow_unknown=allow_unknown,
                                          lexicon=semantics.table)
    return open_doors(objects, r)


def load_replicacad(root, scene: str, classes: ClassTable | None = None, allow_unknown: bool = False,
                    structure: bool = True) -> Layout:
    """Read ``<root>/configs/scenes/<scene>.scene_instance.json`` into a Layout (see the module docstring).

    Object ids are 1.. in file order of ``object_instances``, then the articulated objects
    (``articulated_object_instances``, one static object each: ``synth.mesh.urdf``); classes come from
    ``ClassTable.replicacad_class``. Templates without a class rule raise ``UnknownNameError``
    naming all of them, unless ``allow_unknown`` maps them to class ``"other"``. Bad files or
    fields raise ``SceneFormatError`` naming the file and the field.

    With ``structure`` (the default) the stage's walls, openings, rooms, floor and ceiling are
    derived from its mesh (``synth.mesh.stage_structure``), supports are inferred (``infer_supports``) and
    light fixtures come from the scene's lighting config (``synth.sources.replicacad.habitat_lighting``); without it
    the stage is one mesh with no structure, as before (for datasets whose stage the derivation
    cannot read).
    """
    r = dataset_root(root, require_config=True)
    classes = classes or class_table()
    scene_path = r / "configs" / "scenes" / f"{scene}{SCENE_SUFFIX}"
    if not isinstance(scene, str) or not scene or not scene_path.is_file():
        known = ", ".join(list_scenes(r)) if (r / "configs" / "scenes").is_dir() else "none"
        fail(scene_path, None, f"scene {scene!r} not found; scenes in {r}: {known or 'none'}")
    doc = mapping(scene_path, read_json(scene_path), "(top level)")

    semantics = read_semantics(r, scene_path, doc, classes)
    instances = _parse_instances(r, scene_path, doc, classes, semantics)
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
    lighting = _lighting_config(r, scene_path, doc) if structure else None

    stage, report = _load_stage(r, scene_path, doc, structure)
    objects = [_object(inst, k + 1, inst.cls or UNKNOWN_CLASS) for k, inst in enumerate(instances)]
    meta = {"source": "replicacad", "root": str(r), "scene": scene}
    if structure:
        from .articulated import load_articulated_instances

        objects += load_articulated_instances(r, scene_path, doc, len(objects) + 1, classes, allow_unknown=allow_unknown,
                                              lexicon=semantics.table)
        if len(objects) > MAX_OBJECT_ID:
            fail(scene_path, "articulated_object_instances", f"{len(objects)} objects in all; at most {MAX_OBJECT_ID} are supported")
        objects = infer_supports(open_doors(objects, r), stage.floor_z, r)
        meta["structure"] = report
    else:
        skipped = _articulated_names(scene_path, doc)
        meta["skipped_articulated"] = skipped
        if skipped:
            log.info("%s: skipped %d articulated object(s): %s", scene_path, len(skipped), ", ".join(skipped))
    layout = Layout(name=scene, stage=stage, objects=objects, meta=meta)
    if structure:
        from .habitat_lighting import fixtures_for_imported, read_lighting_config

        lights = read_lighting_config(lighting, dataset_config=dataset_config_path(r)) if lighting is not None else []
        layout.fixtures = fixtures_for_imported(layout, lights)
        meta["lighting_config"] = None if lighting is None else Path(os.path.relpath(lighting, r)).as_posix()
    return layout


DOOR_STEP = math.radians(5.0)  # how far a door swings back per try when its open leaf would hit something


def open_doors(objects: list[ObjectInstance], root) -> list[ObjectInstance]:
    """Doors (``DOOR_CLASS``) opened by ``load_articulated_instances`` swing back towards closed, in
    ``DOOR_STEP`` steps, until their leaf's collision shape interpenetrates no other object
    (``synth.mesh.collision``): a door opens until it meets the bin behind it. The angle taken is recorded
    in ``params["door_opening"]`` ("limit", "stopped" or "closed": no open angle was free)."""
    from ...mesh.collision import PENETRATION_TOL, penetration, world_pieces
    from ...scene.model import object_box
    from .articulated import DOOR_CLASS, with_joint_state

    others = [o for o in objects if o.cls != DOOR_CLASS]
    out = []
    for o in objects:
        if o.cls != DOOR_CLASS or not o.params.get("articulated") or "door_opening" in o.params:
            out.append(o)
            continue
        state = dict(o.params.get("joint_state") or {})
        moving = {k: v for k, v in state.items() if v != 0.0}
        if not moving:
            out.append(o)
            continue
        steps = int(max(abs(v) for v in moving.values()) / DOOR_STEP) + 1
        chosen, how = None, "closed"
        for k in range(steps + 1):
            f = max(0.0, 1.0 - k * DOOR_STEP / max(abs(v) for v in moving.values()))
            cand = with_joint_state(o, root, {**state, **{j: v * f for j, v in moving.items()}})
            box = object_box(cand)
            mine = world_pieces(cand, root)
            hit = False
            for p in others:
                pb = object_box(p)
                if np.any(np.abs(np.asarray(pb.center) - np.asarray(box.center)) > (np.asarray(pb.size) + np.asarray(box.size)) / 2.0 * 1.5):
                    continue
                if penetration(mine, world_pieces(p, root)) >= PENETRATION_TOL:
                    hit = True
                    break
            if not hit:
                chosen, how = cand, "limit" if k == 0 else "stopped"
                break
        if chosen is None:
            chosen = with_joint_state(o, root, {**state, **{j: 0.0 for j in moving}})
        chosen.params["door_opening"] = how
        out.append(chosen)
    return out
