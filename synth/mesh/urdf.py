"""URDF models (articulated objects): links, joints, forward kinematics and the visual meshes at a joint state.

No Blender here. The mesh layer's URDF reader: it parses a URDF (``xml.etree``, no new dependency),
runs forward kinematics at a joint state and gives the link meshes (``urdf_visuals``, ``urdf_mesh``,
``urdf_geometry``) and their bounds (``local_bounds``). ReplicaCAD's kitchen counter, fridge, kitchen
cupboards, chest of drawers, cabinet and doors are *articulated objects*: the scene instance JSON lists
them under ``articulated_object_instances`` and each names a template that resolves to a URDF whose
links carry GLB visual meshes; finding those URDFs and turning each instance into ONE
``synth.scene.model.ObjectInstance`` in its joint state is the scene source's
(``synth.sources.replicacad.articulated``). The notes below are on both.

Why one static object
    A closed drawer or door is visually part of the counter or cabinet; a detector sees one piece
    of furniture, and the relocalizer's landmarks are whole objects (one class-labelled box each).
    So the links are not separate instances: their visual meshes become the render parts of one
    object (``urdf_visuals``), its box is the union of the link meshes in the default joint state
    (all joints at 0, or the instance's ``initial_joint_pose``), and it never moves
    (``movable=False``, ``support="floor"``).

Format facts (habitat-sim is the reference reader of ReplicaCAD; sources are
facebookresearch/habitat-sim at commit 57ee4941 unless noted)
    * Where URDFs live: the dataset's ``urdf/`` folder, one sub-folder per object. ManiSkill's
      ReplicaCAD builder (haosulab/ManiSkill, mani_skill/utils/scene_builder/replicacad/
      scene_builder.py) opens ``urdf/<template_name>/<template_name>.urdf``; other readers of the
      distributed dataset use e.g. ``urdf/kitchen_cupboards/kitchenCupboard_01.urdf``. habitat-sim
      registers every URDF found under the scene dataset config's ``"articulated_objects":
      {"paths": {".urdf": [...]}}`` folders and resolves a template name against those handles
      (src/esp/physics/PhysicsManager.cpp, addArticulatedObjectInstance ->
      getFullAttrNameFromStr). ``find_urdf`` does: ``<root>/<name>[.urdf]`` if the name is a path,
      then ``urdf/<base>/<base>.urdf``, then any ``<base>.urdf`` under the config's
      articulated-object paths (``<root>/*.scene_dataset_config.json``), else under ``urdf/``,
      preferring one whose path ends with the template name. (habitat-sim's last resort, a
      substring match on the handle, is not done: ``door`` would match ``door2.urdf``.)
    * An articulated template may also have a ``<name>.ao_config.json`` (searched like the URDF;
      habitat-sim src/esp/metadata/managers/AOAttributesManager.cpp): its ``urdf_filepath``
      (relative to the config's folder) names the URDF, its ``uniform_scale`` multiplies the
      instance's, its ``link_order`` ("tree_traversal" default, or "urdf_order"; an instance's
      own ``link_order`` wins) orders ``initial_joint_pose``. "urdf_order" with joint positions is
      rejected (not implemented); a ``render_asset`` (skinned mesh) is not drawn (logged).
    * Mesh file names are joined to the URDF's folder as they are; habitat-sim does not resolve
      ``package://`` (src/esp/metadata/URDFParser.cpp, validateMeshFile), so neither do we: such a
      name is an error. ``<mesh scale>`` is 3 numbers, or one number for all axes (same file,
      parseGeometry). Only mesh visuals are supported here (the renderer draws GLBs); box,
      cylinder, sphere, capsule and plane visuals are rejected with ``SceneFormatError``.
    * ``<origin rpy>`` is roll about X, pitch about Y, yaw about Z, fixed axes: R = Rz(y) Ry(p)
      Rx(r) (URDFParser.cpp parseTransform). Default joint axis (1, 0, 0).
    * Frame: a URDF's coordinates are habitat coordinates, Y up. habitat-sim loads each link's
      visual GLB with the default asset frame (no re-orientation: src/esp/physics/bullet/
      BulletPhysicsManager.cpp, attachLinkGeometry) and places the root link with the instance's
      rotation and translation, like any habitat pose; ManiSkill likewise applies the same +90 deg
      about X to URDFs as to the stage and rigid objects. So the conversion to our Z-up frame is
      the one of ``synth.sources.replicacad.importer``: ``T = C T_h C^T``, ``v = C v_h``.
    * Instance fields (src/esp/metadata/managers/SceneInstanceAttributesManager.cpp,
      createAOInstanceAttributesFromJSON): ``template_name``, ``translation``, ``rotation``
      (w, x, y, z), ``uniform_scale``, ``non_uniform_scale``, ``motion_type``,
      ``translation_origin``, ``fixed_base`` (bool), ``auto_clamp_joint_limits``,
      ``initial_joint_pose`` and ``initial_joint_velocities`` (a list, or an object whose values
      are taken in sorted-key order: core/Configuration.h, getSubconfigValsOfTypeInVector).
    * Placement: ``translation`` and ``rotation`` are the root link's pose, as they are: the
      translation origin (COM correction) is applied to rigid objects only, never to articulated
      ones (src/esp/physics/bullet/BulletArticulatedObject.cpp, resetStateFromSceneInstanceAttr;
      PhysicsManager.cpp, addObjectAndSaveAttributes). ``translation_origin`` is checked and
      otherwise ignored here.
    * Scale: the instance's ``uniform_scale`` multiplies the template's and scales the whole model
      (joint and visual origin translations, mesh scales, prismatic limits: URDFParser.cpp,
      Model::setGlobalScaling); ``non_uniform_scale`` is not used for articulated objects
      (PhysicsManager.cpp, addArticulatedObjectInstance) and is ignored here too (logged when it
      is not 1).
    * Joint positions: ``initial_joint_pose`` values go, in order, to the degrees of freedom in the
      articulated object's link order, all others start at 0 (BulletArticulatedObject.cpp,
      resetStateFromSceneInstanceAttr); values beyond the last degree of freedom are dropped with
      a warning. The default link order is "tree traversal" (ArticulatedObjectAttributes.cpp):
      depth first from the root link, a link's children in the order of their joints' names
      (the parser keeps joints in a std::map by name; URDFParser.cpp initTreeAndRoot and
      bullet/BulletURDFImporter.cpp computeParentIndices). Revolute, continuous and prismatic
      joints have one degree of freedom, fixed joints none; floating, planar and spherical joints
      are rejected. Limits are not applied (ReplicaCAD's states are within them).

Frames of this module's outputs
    ``UrdfVisual.matrix`` maps a GLB's vertices already converted to our frame (``C v``, as
    ``synth.sources.replicacad.importer.load_asset_mesh`` gives them), after ``UrdfVisual.scale``, into the
    articulated object's local Z-up frame: the root link's frame, converted. The instance pose
    (``ObjectInstance.position``/``rotation``) and scale (``ObjectInstance.scale``, uniform)
    place that frame in the world. With the link pose ``T_L`` and visual origin ``T_V`` from the
    URDF (habitat frame) and mesh scale ``s``: ``matrix = C T_L T_V C^T`` and ``scale = (s_x,
    s_z, s_y)``, because ``C (s * v_h) = (s_x, s_z, s_y) * (C v_h)``.

Joint states in the scene model
    ``ObjectInstance.params["joint_state"]`` maps every movable joint's name to its position in
    the URDF's own units (radians; metres before the instance scale). habitat-sim's prismatic
    positions are in scaled metres, so a prismatic value from the scene file is divided by
    ``uniform_scale`` (a no-op for ReplicaCAD, whose articulated objects are unscaled). Then
    scaling the whole unscaled model by ``ObjectInstance.scale`` gives habitat-sim's geometry.
"""

from __future__ import annotations

import logging
import math
import xml.etree.ElementTree as ET
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import trimesh

from vrformats.errors import UnknownNameError
from vrformats.fields import fail, inside_root, number

from ..scene.geometry import Y_UP_TO_Z_UP
from ..scene.model import URDF_ASSET_PREFIX
from .roots import dataset_root, owning_root

log = logging.getLogger(__name__)

JOINT_TYPES = ("fixed", "revolute", "continuous", "prismatic")
MOVABLE_JOINT_TYPES = ("revolute", "continuous", "prismatic")
JOINT_STATE_DECIMALS = 9
_PRIMITIVES = ("box", "cylinder", "sphere", "capsule", "plane")
_C = Y_UP_TO_Z_UP


# --------------------------------------------------------------------------------------------
# public data


@dataclass
class UrdfVisual:
    """One visual mesh of one link, placed in the articulated object's local Z-up frame."""

    link: str
    glb: Path  # absolute path of the visual mesh file
    matrix: np.ndarray  # 4x4: (scaled) C v -> object local frame, Z up
    scale: np.ndarray  # (3,), applied to the C v vertices first (URDF <mesh scale>, axes permuted)


# --------------------------------------------------------------------------------------------
# parsed model


@dataclass
class _Visual:
    link: str
    index: int
    origin: np.ndarray  # 4x4, habitat frame, in the link frame
    glb: Path
    scale: np.ndarray  # (3,), GLB (habitat) axes


@dataclass
class _Joint:
    name: str
    type: str
    parent: str
    child: str
    origin: np.ndarray  # 4x4, habitat frame, parent link -> joint frame
    axis: np.ndarray  # unit (3,), joint frame
    limits: tuple[float, float] | None = None  # <limit lower upper> of a revolute or prismatic joint


@dataclass
class UrdfModel:
    """A parsed URDF: links in file order, their mesh visuals, the joint tree."""

    path: Path
    name: str
    links: list[str]
    visuals: dict[str, list[_Visual]]
    joints: dict[str, _Joint]  # by joint name
    root: str
    children: dict[str, list[_Joint]] = field(default_factory=dict)  # link -> child joints by joint name

    def movable_joints(self) -> list[str]:
        """Names of the joints with one degree of freedom, in habitat-sim's default link order
        (depth first from the root; a link's children in the order of their joints' names)."""
        out: list[str] = []
        stack = list(reversed(self.children.get(self.root, [])))
        while stack:
            j = stack.pop()  # pre-order: a joint, then its child's subtree, then its next sibling
            if j.type in MOVABLE_JOINT_TYPES:
                out.append(j.name)
            stack.extend(reversed(self.children.get(j.child, [])))
        return out


# --------------------------------------------------------------------------------------------
# URDF parsing


def _floats(file, text, field: str, n: int, positive: bool = False, allow_one: bool = False) -> np.ndarray:
    parts = str(text).replace(",", " ").split() if text is not None else []
    try:
        vals = [float(p) for p in parts]
    except ValueError:
        vals = None
    ok_len = vals is not None and (len(vals) == n or (allow_one and len(vals) == 1))
    if not ok_len or not all(math.isfinite(v) for v in vals):
        fail(file, field, f"expected {n} finite numbers{' (or one)' if allow_one else ''}, got {text!r}")
    if positive and any(v <= 0 for v in vals):
        fail(file, field, f"expected numbers > 0, got {text!r}")
    if len(vals) == 1 and n > 1:
        vals = vals * n
    return np.array(vals, dtype=float)


def _rpy_matrix(r: float, p: float, y: float) -> np.ndarray:
    """URDF fixed-axis roll-pitch-yaw: Rz(y) @ Ry(p) @ Rx(r)."""
    cr, sr, cp, sp, cy, sy = math.cos(r), math.sin(r), math.cos(p), math.sin(p), math.cos(y), math.sin(y)
    Rx = np.array([[1, 0, 0], [0, cr, -sr], [0, sr, cr]])
    Ry = np.array([[cp, 0, sp], [0, 1, 0], [-sp, 0, cp]])
    Rz = np.array([[cy, -sy, 0], [sy, cy, 0], [0, 0, 1]])
    return Rz @ Ry @ Rx


def origin_matrix(file, el, field: str) -> np.ndarray:
    T = np.eye(4)
    o = el.find("origin")
    if o is None:
        return T
    if o.get("xyz") is not None:
        T[:3, 3] = _floats(file, o.get("xyz"), f"{field}.origin.xyz", 3)
    if o.get("rpy") is not None:
        T[:3, :3] = _rpy_matrix(*_floats(file, o.get("rpy"), f"{field}.origin.rpy", 3))
    return T


def _axis_rotation(axis: np.ndarray, angle: float) -> np.ndarray:
    """Rotation matrix by ``angle`` about the unit ``axis`` (Rodrigues)."""
    x, y, z = axis
    c, s = math.cos(angle), math.sin(angle)
    K = np.array([[0, -z, y], [z, 0, -x], [-y, x, 0]])
    return np.eye(3) + s * K + (1 - c) * (K @ K)


def _parse_visual(file: Path, link: str, index: int, vis) -> _Visual:
    field = f"link[{link}].visual[{index}]"
    origin = origin_matrix(file, vis, field)
    geom = vis.find("geometry")
    shapes = list(geom) if geom is not None else []
    if len(shapes) != 1:
        fail(file, f"{field}.geometry", f"expected exactly one shape element, got {len(shapes)}")
    shape = shapes[0]
    if shape.tag in _PRIMITIVES:
        fail(file, f"{field}.geometry", f"primitive visual '{shape.tag}' is not supported (only <mesh> visuals with a .glb file)")
    if shape.tag != "mesh":
        fail(file, f"{field}.geometry", f"unknown shape <{shape.tag}> (expected <mesh>)")
    fn = shape.get("filename")
    if not fn:
        fail(file, f"{field}.mesh", "missing filename")
    if "://" in fn:
        fail(file, f"{field}.mesh", f"URIs such as {fn!r} are not resolved (habitat-sim neither); use a path relative to the URDF")
    glb = inside_root(file, f"{field}.mesh", file.parent / fn, owning_root(file))
    if glb.suffix.lower() != ".glb":
        fail(file, f"{field}.mesh", f"only .glb meshes are supported, got {fn!r}")
    if not glb.is_file():
        fail(file, f"{field}.mesh", f"mesh file not found: {glb}")
    scale = np.ones(3)
    if shape.get("scale") is not None:
        scale = _floats(file, shape.get("scale"), f"{field}.mesh.scale", 3, positive=True, allow_one=True)
    return _Visual(link, index, origin, glb, scale)


def _parse(path: Path) -> UrdfModel:
    try:
        tree = ET.parse(str(path))
    except ET.ParseError as e:
        fail(path, None, f"malformed XML: {e}")
    except OSError as e:
        fail(path, None, f"cannot read: {e}")
    robot = tree.getroot()
    if robot.tag != "robot":
        fail(path, None, f"expected a <robot> root element, got <{robot.tag}>")
    name = robot.get("name", path.stem)

    links: list[str] = []
    visuals: dict[str, list[_Visual]] = {}
    for k, el in enumerate(robot.findall("link")):
        ln = el.get("name")
        if not ln:
            fail(path, f"link #{k}", "missing name")
        if ln in visuals:
            fail(path, f"link[{ln}]", "duplicate link name")
        links.append(ln)
        visuals[ln] = [_parse_visual(path, ln, i, v) for i, v in enumerate(el.findall("visual"))]
    if not links:
        fail(path, "robot", "no <link> elements")

    joints: dict[str, _Joint] = {}
    parent_of: dict[str, str] = {}
    for k, el in enumerate(robot.findall("joint")):
        jn = el.get("name")
        if not jn:
            fail(path, f"joint #{k}", "missing name")
        f = f"joint[{jn}]"
        if jn in joints:
            fail(path, f, "duplicate joint name")
        jt = el.get("type")
        if jt not in JOINT_TYPES:
            fail(path, f + ".type", f"unsupported joint type {jt!r} (expected one of {', '.join(JOINT_TYPES)})")
        ends = {}
        for end in ("parent", "child"):
            e = el.find(end)
            ref = e.get("link") if e is not None else None
            if not ref:
                fail(path, f"{f}.{end}", "missing <" + end + " link=...>")
            if ref not in visuals:
                fail(path, f"{f}.{end}", f"unknown link {ref!r}")
            ends[end] = ref
        if ends["child"] == ends["parent"]:
            fail(path, f + ".child", f"link {ends['child']!r} is its own parent")
        if ends["child"] in parent_of:
            fail(path, f + ".child", f"link {ends['child']!r} already has parent joint {parent_of[ends['child']]!r}")
        parent_of[ends["child"]] = jn
        axis = np.array([1.0, 0.0, 0.0])
        ax = el.find("axis")
        if ax is not None and ax.get("xyz") is not None:
            axis = _floats(path, ax.get("xyz"), f + ".axis.xyz", 3)
            n = float(np.linalg.norm(axis))
            if n < 1e-9:
                fail(path, f + ".axis.xyz", f"zero axis {ax.get('xyz')!r}")
            axis = axis / n
        limits = None
        lim = el.find("limit")
        if lim is not None and lim.get("lower") is not None and lim.get("upper") is not None:
            lo_hi = (_floats(path, lim.get("lower"), f + ".limit.lower", 1)[0], _floats(path, lim.get("upper"), f + ".limit.upper", 1)[0])
            if lo_hi[0] > lo_hi[1]:
                fail(path, f + ".limit", f"lower {lo_hi[0]} > upper {lo_hi[1]}")
            limits = (float(lo_hi[0]), float(lo_hi[1]))
        joints[jn] = _Joint(jn, jt, ends["parent"], ends["child"], origin_matrix(path, el, f), axis, limits)

    roots = [ln for ln in links if ln not in parent_of]
    if not roots:
        fail(path, "robot", "the joints form a cycle (no root link)")
    if len(roots) > 1:
        fail(path, "robot", f"several root links ({', '.join(roots)}): every link but one needs a parent joint")
    children: dict[str, list[_Joint]] = {}
    for j in sorted(joints.values(), key=lambda j: j.name):
        children.setdefault(j.parent, []).append(j)
    seen = {roots[0]}
    stack = [roots[0]]
    while stack:
        for j in children.get(stack.pop(), []):
            if j.child not in seen:
                seen.add(j.child)
                stack.append(j.child)
    unreached = [ln for ln in links if ln not in seen]
    if unreached:
        fail(path, "robot", f"the joints form a cycle: links {', '.join(unreached)} are not reached from root link {roots[0]!r}")
    return UrdfModel(path, name, links, visuals, joints, roots[0], children)


_CACHE: dict[tuple[str, int, int], UrdfModel] = {}


def parse_urdf(path) -> UrdfModel:
    """The parsed URDF at ``path`` (cached by path, size and modification time).

    Bad files raise ``SceneFormatError`` naming the URDF and the element, e.g.
    ``link[body].visual[0].mesh`` or ``joint[slide].type``.
    """
    p = Path(path)
    if not p.is_file():
        fail(p, None, "URDF file not found")
    st = p.stat()
    key = (str(p.resolve()), st.st_mtime_ns, st.st_size)
    model = _CACHE.get(key)
    if model is None:
        model = _parse(p.resolve())
        if len(_CACHE) >= 64:
            _CACHE.pop(next(iter(_CACHE)))
        _CACHE[key] = model
    return model


# --------------------------------------------------------------------------------------------
# kinematics


def _check_state(model: UrdfModel, joint_state) -> dict[str, float]:
    if joint_state is None:
        return {}
    if not isinstance(joint_state, dict):
        fail(model.path, "joint_state", f"expected a mapping joint name -> position, got {type(joint_state).__name__}")
    unknown = sorted(str(k) for k in joint_state if k not in model.joints)
    if unknown:
        raise UnknownNameError(f"{model.path}: no joint(s) {', '.join(unknown)}; joints: {', '.join(model.joints) or 'none'}")
    out = {}
    for k, v in joint_state.items():
        if model.joints[k].type not in MOVABLE_JOINT_TYPES:
            fail(model.path, f"joint_state.{k}", f"joint {k!r} is {model.joints[k].type}: it has no position")
        out[k] = number(model.path, v, f"joint_state.{k}")
    return out


def link_poses(model: UrdfModel, joint_state: dict[str, float] | None = None) -> dict[str, np.ndarray]:
    """4x4 pose of every link in the root link's frame, habitat (Y-up) coordinates.

    ``T_child = T_parent @ joint.origin @ motion(q)``; motion is a translation by ``q * axis``
    (prismatic) or a rotation by ``q`` about ``axis`` (revolute, continuous); missing joints are 0.
    """
    q = _check_state(model, joint_state)
    poses = {model.root: np.eye(4)}
    stack = [model.root]
    while stack:
        parent = stack.pop()
        for j in model.children.get(parent, []):
            M = np.eye(4)
            v = q.get(j.name, 0.0)
            if j.type == "prismatic":
                M[:3, 3] = v * j.axis
            elif j.type in ("revolute", "continuous"):
                M[:3, :3] = _axis_rotation(j.axis, v)
            poses[j.child] = poses[parent] @ j.origin @ M
            stack.append(j.child)
    return poses


def urdf_visuals(urdf_path, joint_state: dict[str, float] | None = None) -> list[UrdfVisual]:
    """Every link's visual meshes, placed in the object's local Z-up frame at ``joint_state``.

    Links in file order, visuals in file order. ``joint_state`` maps movable joint names to
    positions (radians, or metres of the unscaled model); missing joints are at 0. A vertex
    ``v`` of ``visual.glb`` converted to our frame (``C v``) lands at
    ``visual.matrix @ [visual.scale * (C v), 1]`` in the object's local frame.
    """
    model = parse_urdf(urdf_path)
    poses = link_poses(model, joint_state)
    out = []
    for ln in model.links:
        for vis in model.visuals[ln]:
            T4 = np.eye(4)
            T4[:3, :3] = _C
            M = T4 @ poses[ln] @ vis.origin @ T4.T
            out.append(UrdfVisual(ln, vis.glb, M, np.abs(_C) @ vis.scale))
    return out


def _glb_mesh(path: Path) -> trimesh.Trimesh:
    """The GLB's triangles with vertices ``C v`` (``synth.mesh.gltf.glb_geometry``: Z up, node transforms applied)."""
    from .gltf import glb_geometry

    return glb_geometry(path)


def urdf_mesh(urdf_path, joint_state: dict[str, float] | None = None) -> trimesh.Trimesh:
    """All link meshes of a URDF in the object's local Z-up frame (unscaled by the instance)."""
    pieces = []
    for vis in urdf_visuals(urdf_path, joint_state):
        m = _glb_mesh(vis.glb)
        v = (np.asarray(m.vertices, dtype=float) * vis.scale) @ vis.matrix[:3, :3].T + vis.matrix[:3, 3]
        # rotations and positive scales only: the winding is kept
        pieces.append(trimesh.Trimesh(vertices=v, faces=np.asarray(m.faces), process=False))
    if not pieces:
        fail(Path(urdf_path), None, "URDF has no visual meshes")
    return trimesh.util.concatenate(pieces) if len(pieces) > 1 else pieces[0]


def urdf_path(root, asset: str) -> Path:
    """The URDF file of an asset name ``"replicacad-urdf:<urdf path relative to root>"``."""
    r = dataset_root(root)
    if not isinstance(asset, str) or not asset.startswith(URDF_ASSET_PREFIX) or len(asset) == len(URDF_ASSET_PREFIX):
        raise UnknownNameError(f"not a ReplicaCAD URDF asset name: {asset!r} (expected '{URDF_ASSET_PREFIX}<relative urdf path>')")
    p = inside_root(asset, None, r / asset[len(URDF_ASSET_PREFIX):], r)
    if not p.is_file():
        fail(p, None, f"URDF not found (asset {asset!r})")
    return p


def urdf_geometry(root, asset: str, joint_state: dict[str, float] | None = None) -> trimesh.Trimesh:
    """All link meshes of ``"replicacad-urdf:<path>"`` in the object's local Z-up frame.

    Place it with ``ObjectInstance.scale`` then ``ObjectInstance.matrix()``; pass the instance's
    ``params["joint_state"]`` (default: all joints at 0). Returns a new mesh on every call.
    """
    return urdf_mesh(urdf_path(root, asset), joint_state)


def local_bounds(model: UrdfModel, state: dict[str, float]) -> tuple[np.ndarray, np.ndarray]:
    """Axis-aligned bounds of all link meshes in the object's local frame (unscaled)."""
    lo = np.full(3, np.inf)
    hi = np.full(3, -np.inf)
    for vis in urdf_visuals(model.path, state):
        m = _glb_mesh(vis.glb)
        v = (np.asarray(m.vertices, dtype=float) * vis.scale) @ vis.matrix[:3, :3].T + vis.matrix[:3, 3]
        lo = np.minimum(lo, v.min(axis=0))
        hi = np.maximum(hi, v.max(axis=0))
    if not np.all(np.isfinite(lo)):
        fail(model.path, None, "URDF has no visual meshes (nothing to render or box)")
    return lo, hi
