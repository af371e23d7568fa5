"""A small dataset shaped like ReplicaCAD, built from scratch, with its construction facts in OUR frame.

``make_fixture(root)`` writes it (deterministic bytes, well under a second);
``python tests/replicacad_fixture.py OUT_DIR`` writes it for demos. Everything below is authored
here; expected values (``OBJECT_BOXES`` ...) are written out by hand from the construction, never
read back from the files.

Frames. Ours: right-handed, Z up. Habitat/glTF: Y up, -Z forward. C = [[1,0,0],[0,0,-1],[0,1,0]]
maps habitat to ours, ``(x, y, z)_h -> (x, -z, y)``, so ours -> habitat is C^T: ``(x, y, z) ->
(x, z, -y)``. A yaw of theta about our +Z is a rotation about habitat +Y by theta, habitat quaternion
``(cos theta/2, 0, sin theta/2, 0)``. The stage is built in our frame and written with C^T applied;
object / URDF meshes are authored in habitat's frame (Y up), like ReplicaCAD's.

Layout written::

    replicaCAD.scene_dataset_config.json
    stages/frl_apartment_stage.glb                       floor (textured), walls (grey), ceiling (white)
    objects/*.glb                                        textured furniture (PBR baseColorTexture)
    urdf/kitchen_counter/kitchen_counter.urdf            links "body", "drawer" (prismatic joint)
    urdf/kitchen_counter/{kitchen_counter,drawer1}.glb   meshes, referenced relative to the URDF
    urdf/kitchen_counter/kitchen_counter.ao_config.json
    configs/stages/frl_apartment_stage.stage_config.json
    configs/objects/*.object_config.json (+ configs/objects/decor/ for the lamp)
    configs/lighting/frl_apartment_stage.lighting_config.json, frl_apartment_1.lighting_config.json
    configs/scenes/apt_0 .. apt_5.scene_instance.json

Format facts (read in these sources; "third-party" = reference only):

* Scene instance (habitat-sim docs/pages/attributesJSON.rst, the apt_0 excerpt there):
  ``stage_instance.template_name`` "stages/frl_apartment_stage", ``default_lighting``
  "lighting/frl_apartment_stage" (a lighting handle; "" = default lighting, "no_lights" = flat),
  ``object_instances[]`` {template_name "objects/<name>", motion_type STATIC|KINEMATIC|DYNAMIC,
  translation, rotation (w, x, y, z), uniform_scale, non_uniform_scale, translation_origin
  'COM'|'asset_local'}; ``articulated_object_instances[]`` {template_name (URDF handle, e.g.
  "fridge"), fixed_base, auto_clamp_joint_limits, translation, rotation, motion_type,
  uniform_scale, non_uniform_scale, mass_scale, translation_origin, initial_joint_pose (list in
  joint order, or {joint name: value}), initial_joint_velocities}; ``navmesh_instance``,
  ``semantic_scene_instance``. The SceneInstanceAttributes constructor (habitat-sim
  src/esp/metadata/attributes/SceneInstanceAttributes.cpp) defaults the scene-level
  translation_origin to asset_local and the lighting handle to NO_LIGHT_KEY; the fixture writes
  ``"translation_origin": "asset_local"`` at the top level (as the importer assumes ReplicaCAD
  does) and one instance overrides it with "COM".
* Lighting (attributesJSON.rst LightLayoutAttributes; the real file
  huggingface.co/datasets/haosulab/ReplicaCAD configs/lighting/frl_apartment_5.lighting_config.json):
  ``{"lights": {"0": {"type": "point", "position": [x, y, z] (habitat frame), "intensity": f,
  "color": [r, g, b] (linear, 0..1)}, ...}}``; intensities may be NEGATIVE (used to fake shadows);
  optional per-light "direction" (directional lights) and "position_model" ("global" | "camera"),
  which ReplicaCAD's files omit. No "positional_lighting_model" key was found in either source.
* Dataset config (the real replicaCAD.scene_dataset_config.json, seen via the code search):
  stages/objects ``{"paths": {".json": ["configs/stages" | "configs/objects"]}}``,
  ``"articulated_objects": {"paths": {".urdf": ["urdf/*/"]}}``, ``"light_setups":
  {"default_attributes": {"positive_intensity_scale": 2.5, "negative_intensity_scale": 0.1},
  "paths": {".json": ["configs/lighting"]}}``, scene_instances under "configs/scenes",
  navmesh_instances / semantic_scene_descriptor_instances (omitted here: no such files).
  NOTE: those intensity scales mean habitat multiplies positive light intensities by 2.5 and
  negative ones by 0.1 when it loads the setups.
* URDFs (haosulab/ManiSkill mani_skill/utils/scene_builder/replicacad/scene_builder.py; the file
  list in a ReplicaCAD baked-lighting converter seen via find_string):
  ``urdf/<template_name>/<template_name>.urdf``, meshes next to it (kitchen_counter/
  kitchen_counter.glb, drawer1..4.glb; fridge/body.glb ...) and referenced by bare relative file
  names. ManiSkill poses articulations exactly like rigid objects (``Pose(q=Rx(90)) *
  Pose(translation, rotation)``): the URDF and its GLBs are in habitat's Y-up frame, the instance
  translation/rotation place the base (root) link frame. ``<urdf_name>.ao_config.json`` may hold
  extra user metadata (attributesJSON.rst); its fields were not verified here.

Construction (OUR frame, metres): see the constants below. Rooms A x[0,4] y[0,3] and B
x[4.1,7.1] y[0,3]; the interior wall x[4.0,4.1] has a door y[1.0,1.9] z[0,2.1]; the north wall
has a window x[1.0,2.2] z[0.9,2.0]. In apt_0, furniture keeps out of the walkway y[1.0,1.9]
(x 0..7.1, through the door), out of the door zone x[3.4,4.7] and out of the window front
x[1.0,2.2] y[2.2,3.0].
"""

from __future__ import annotations

import json
import math
import sys
from pathlib import Path

import numpy as np
import trimesh
from meshes import box_mesh, write_glb
from PIL import Image
from trimesh.visual import TextureVisuals
from trimesh.visual.material import PBRMaterial

# ours -> habitat is C^T; written out here, not imported from synth
_C = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, -1.0], [0.0, 1.0, 0.0]])

SCENES = ("apt_0", "apt_1", "apt_2", "apt_3", "apt_4", "apt_5")
STAGE_TEMPLATE = "frl_apartment_stage"
LIGHTING_HANDLE = "lighting/frl_apartment_stage"

# ---------------------------------------------------------------------------------------------
# structure, OUR frame

FLOOR_Z = 0.0
CEILING_Z = 2.5
FLOOR_SLAB = ((-0.1, -0.1, -0.1), (7.2, 3.1, 0.0))
CEILING_SLAB = ((-0.1, -0.1, 2.5), (7.2, 3.1, 2.6))
WALL_BOXES = {  # full wall boxes, holes not cut (see DOOR / WINDOW)
    "south": ((-0.1, -0.1, 0.0), (7.2, 0.0, 2.5)),
    "north": ((-0.1, 3.0, 0.0), (7.2, 3.1, 2.5)),
    "west": ((-0.1, 0.0, 0.0), (0.0, 3.0, 2.5)),
    "east": ((7.1, 0.0, 0.0), (7.2, 3.0, 2.5)),
    "interior": ((4.0, 0.0, 0.0), (4.1, 3.0, 2.5)),
}
DOOR = ("interior", (4.0, 1.0, 0.0), (4.1, 1.9, 2.1))
WINDOW = ("north", (1.0, 3.0, 0.9), (2.2, 3.1, 2.0))
ROOMS = {"A": ((0.0, 0.0), (4.0, 3.0)), "B": ((4.1, 0.0), (7.1, 3.0))}  # (x, y) lo, hi
WALKWAY = ((0.0, 1.0), (7.1, 1.9))  # free of furniture in apt_0 (x, y lo, hi)
DOOR_ZONE = ((3.4, 1.0), (4.7, 1.9))
WINDOW_FRONT = ((1.0, 2.2), (2.2, 3.0))

# pieces actually meshed (non-overlapping boxes, holes cut)
WALL_PIECES = [
    WALL_BOXES["south"],
    ((-0.1, 3.0, 0.0), (1.0, 3.1, 2.5)),  # north, west of the window
    ((2.2, 3.0, 0.0), (7.2, 3.1, 2.5)),  # north, east of the window
    ((1.0, 3.0, 0.0), (2.2, 3.1, 0.9)),  # below the window
    ((1.0, 3.0, 2.0), (2.2, 3.1, 2.5)),  # above the window
    WALL_BOXES["west"],
    WALL_BOXES["east"],
    ((4.0, 0.0, 0.0), (4.1, 1.0, 2.5)),  # interior, south of the door
    ((4.0, 1.9, 0.0), (4.1, 3.0, 2.5)),  # interior, north of the door
    ((4.0, 1.0, 2.1), (4.1, 1.9, 2.5)),  # lintel
]

# ---------------------------------------------------------------------------------------------
# colours (8-bit sRGB). Each texture is 32x32 px of vertical stripes 4 px wide alternating two
# shades (a, b); 16 columns each, so the mean is exactly (a + b) / 2.

TEXTURE_SIZE = 32
STRIPE_PX = 4
_SHADES = {
    "frl_apartment_stage:floor": ((150, 100, 60), (130, 84, 46)),  # wood brown
    "frl_apartment_table_01": ((230, 120, 30), (210, 100, 20)),  # orange
    "frl_apartment_chair_01": ((40, 80, 220), (20, 60, 200)),  # blue
    "frl_apartment_sofa": ((40, 180, 60), (20, 160, 40)),  # green
    "frl_apartment_lamp_02": ((240, 220, 40), (220, 200, 20)),  # yellow
    "frl_apartment_bowl_03": ((220, 40, 200), (200, 20, 180)),  # magenta
    "frl_apartment_cushion_01": ((230, 40, 40), (210, 20, 20)),  # red
    "kitchen_counter:body": ((40, 200, 210), (20, 180, 190)),  # cyan
    "kitchen_counter:drawer": ((130, 60, 220), (110, 40, 200)),  # purple
}
TEXTURE_SRGB = {  # mean colour of each texture, by hand: (a + b) / 2
    "frl_apartment_stage:floor": (140, 92, 53),
    "frl_apartment_table_01": (220, 110, 25),
    "frl_apartment_chair_01": (30, 70, 210),
    "frl_apartment_sofa": (30, 170, 50),
    "frl_apartment_lamp_02": (230, 210, 30),
    "frl_apartment_bowl_03": (210, 30, 190),
    "frl_apartment_cushion_01": (220, 30, 30),
    "kitchen_counter:body": (30, 190, 200),
    "kitchen_counter:drawer": (120, 50, 210),
}
GLB_PATHS = {  # key of TEXTURE_SRGB -> GLB (relative to the root) carrying that texture
    "frl_apartment_stage:floor": "stages/frl_apartment_stage.glb",
    "frl_apartment_table_01": "objects/frl_apartment_table_01.glb",
    "frl_apartment_chair_01": "objects/frl_apartment_chair_01.glb",
    "frl_apartment_sofa": "objects/frl_apartment_sofa.glb",
    "frl_apartment_lamp_02": "objects/frl_apartment_lamp_02.glb",
    "frl_apartment_bowl_03": "objects/frl_apartment_bowl_03.glb",
    "frl_apartment_cushion_01": "objects/frl_apartment_cushion_01.glb",
    "kitchen_counter:body": "urdf/kitchen_counter/kitchen_counter.glb",
    "kitchen_counter:drawer": "urdf/kitchen_counter/drawer1.glb",
}
WALL_COLOR_FACTOR = (200, 200, 200, 255)  # glTF baseColorFactor, 8-bit (factor = value / 255, linear)
CEILING_COLOR_FACTOR = (255, 255, 255, 255)

# ---------------------------------------------------------------------------------------------
# object meshes, HABITAT local frame (x, y up, z); front faces habitat +z (= our -y) unless noted


def _table_parts():  # 1.2 x 0.75 x 0.8 standing on y = 0; bounds x[-0.6,0.6] y[0,0.75] z[-0.4,0.4]
    parts = [box_mesh((-0.6, 0.7, -0.4), (0.6, 0.75, 0.4))]
    for x0 in (-0.6, 0.55):
        for z0 in (-0.4, 0.35):
            parts.append(box_mesh((x0, 0.0, z0), (x0 + 0.05, 0.7, z0 + 0.05)))
    return parts


def _chair_parts():  # bounds x[-0.225,0.225] y[0,0.9] z[-0.225,0.225]; backrest at -z (our +y)
    parts = [box_mesh((-0.225, 0.42, -0.225), (0.225, 0.47, 0.225)),  # seat
             box_mesh((-0.225, 0.47, -0.225), (0.225, 0.9, -0.185))]  # backrest
    for x0 in (-0.225, 0.185):
        for z0 in (-0.225, 0.185):
            parts.append(box_mesh((x0, 0.0, z0), (x0 + 0.04, 0.42, z0 + 0.04)))
    return parts


def _sofa_parts():  # centred: bounds x[-0.9,0.9] y[-0.4,0.4] z[-0.425,0.425]; seat top at y = 0
    return [box_mesh((-0.9, -0.4, -0.425), (0.9, 0.0, 0.425)),  # base
            box_mesh((-0.9, 0.0, -0.425), (0.9, 0.4, -0.225)),  # backrest (our +y)
            box_mesh((-0.9, 0.0, -0.225), (-0.75, 0.15, 0.425)),  # armrests
            box_mesh((0.75, 0.0, -0.225), (0.9, 0.15, 0.425))]


def _lamp_parts():  # bounds x[-0.2,0.2] y[0,1.65] z[-0.2,0.2]
    return [box_mesh((-0.15, 0.0, -0.15), (0.15, 0.03, 0.15)),  # foot
            box_mesh((-0.015, 0.03, -0.015), (0.015, 1.35, 0.015)),  # pole
            box_mesh((-0.2, 1.35, -0.2), (0.2, 1.65, 0.2))]  # shade


def _bowl_parts():  # bounds x[-0.1,0.1] y[0,0.08] z[-0.1,0.1]
    t = 0.015
    return [box_mesh((-0.1, 0.0, -0.1), (0.1, t, 0.1)),
            box_mesh((-0.1, t, -0.1), (0.1, 0.08, -0.1 + t)),
            box_mesh((-0.1, t, 0.1 - t), (0.1, 0.08, 0.1)),
            box_mesh((-0.1, t, -0.1 + t), (-0.1 + t, 0.08, 0.1 - t)),
            box_mesh((0.1 - t, t, -0.1 + t), (0.1, 0.08, 0.1 - t))]


def _cushion_parts():  # centred: bounds x[-0.2,0.2] y[-0.06,0.06] z[-0.2,0.2]
    return [box_mesh((-0.2, -0.06, -0.2), (0.2, 0.06, 0.2))]


def _counter_parts():  # URDF link "body", link frame: x[-0.75,0.75] y[0,0.9] z[-0.3,0.3], front +z
    return [box_mesh((-0.75, 0.0, -0.3), (0.75, 0.9, 0.3))]


def _drawer_parts():  # URDF link "drawer", link frame: centred 0.5 x 0.15 x 0.55
    return [box_mesh((-0.25, -0.075, -0.275), (0.25, 0.075, 0.275))]


# URDF joint (habitat frame, relative to the body link): the closed drawer spans body-frame
# x[-0.25,0.25] y[0.65,0.80] z[-0.23,0.32] (front 2 cm proud of the body's front face z = 0.3)
DRAWER_JOINT_ORIGIN_H = (0.0, 0.725, 0.045)
DRAWER_JOINT_AXIS_H = (0.0, 0.0, 1.0)
DRAWER_LIMITS = (0.0, 0.35)
URDF_JOINT = {"name": "drawer_slide", "type": "prismatic", "parent": "body", "child": "drawer",
              "origin_h": DRAWER_JOINT_ORIGIN_H, "axis_h": DRAWER_JOINT_AXIS_H, "limits": DRAWER_LIMITS}

# ---------------------------------------------------------------------------------------------
# configs: template -> (glb name, parts, config extras)

_OBJECTS = {
    "frl_apartment_table_01": ("configs/objects", _table_parts,
                               {"mass": 20.0, "COM": [0.0, 0.5, 0.0]}),
    "frl_apartment_chair_01": ("configs/objects", _chair_parts,
                               {"mass": 5.0, "scale": [1.0, 1.0, 1.0]}),
    "frl_apartment_sofa": ("configs/objects", _sofa_parts,
                           {"mass": 40.0, "COM": [0.0, -0.1, 0.05]}),
    "frl_apartment_lamp_02": ("configs/objects/decor", _lamp_parts, {"mass": 4.0}),
    "frl_apartment_bowl_03": ("configs/objects", _bowl_parts,
                              {"mass": 0.3, "COM": [0.0, 0.03, 0.0], "use_bounding_box_for_collision": True}),
    "frl_apartment_cushion_01": ("configs/objects", _cushion_parts,
                                 {"mass": 0.5, "use_bounding_box_for_collision": True}),
}

# ---------------------------------------------------------------------------------------------
# scene content, OUR frame. An entry: template, position (of the asset origin, ours), yaw (deg,
# about +Z), motion type, extra JSON fields. "COM" entries are converted to a COM translation.

_SOFA_COM_H = (0.0, -0.1, 0.05)
_CUSHION_NUS = [1.25, 1.0, 0.75]
_LAMP_SCALE = 1.2
_CHAIR2_YAW = -110.0

APT0_OBJECTS = [
    # 0 table, room A south strip
    ("frl_apartment_table_01", (1.6, 0.5, 0.0), 0.0, "STATIC", {}),
    # 1 chair west of the table, facing +x: 90 deg about habitat +Y
    ("frl_apartment_chair_01", (0.6, 0.5, 0.0), 90.0, "DYNAMIC", {}),
    # 2 chair east of the table, a general yaw
    ("frl_apartment_chair_01", (2.75, 0.5, 0.0), _CHAIR2_YAW, "DYNAMIC", {}),
    # 3 sofa, room B against the north wall, translation given at its COM
    ("frl_apartment_sofa", (5.9, 2.525, 0.4), 0.0, "STATIC", {"translation_origin": "COM"}),
    # 4 cushion lying on the sofa seat (seat top z = 0.4), non-uniform scale
    ("frl_apartment_cushion_01", (5.5, 2.55, 0.46), 0.0, "DYNAMIC", {"non_uniform_scale": _CUSHION_NUS}),
    # 5 floor lamp, room A north-west corner, uniform scale
    ("frl_apartment_lamp_02", (0.4, 2.6, 0.0), 0.0, "STATIC", {"uniform_scale": _LAMP_SCALE}),
    # 6 bowl on the table top (z = 0.75)
    ("frl_apartment_bowl_03", (1.6, 0.5, 0.75), 0.0, "DYNAMIC", {}),
]

_h2 = 0.225 * (abs(math.cos(math.radians(_CHAIR2_YAW))) + abs(math.sin(math.radians(_CHAIR2_YAW))))
OBJECT_BOXES = {  # apt_0, instance index -> world AABB (ours), by hand from the construction above
    0: ((1.0, 0.1, 0.0), (2.2, 0.9, 0.75)),
    1: ((0.375, 0.275, 0.0), (0.825, 0.725, 0.9)),
    2: ((2.75 - _h2, 0.5 - _h2, 0.0), (2.75 + _h2, 0.5 + _h2, 0.9)),
    3: ((5.0, 2.1, 0.0), (6.8, 2.95, 0.8)),
    4: ((5.25, 2.4, 0.4), (5.75, 2.7, 0.52)),
    5: ((0.16, 2.36, 0.0), (0.64, 2.84, 1.98)),
    6: ((1.5, 0.4, 0.75), (1.7, 0.6, 0.83)),
}
OBJECT_CLASSES = {0: "dining_table", 1: "chair", 2: "chair", 3: "sofa", 4: "cushion", 5: "floor_lamp", 6: "bowl"}

# the kitchen counter: base link at (5.95, 0.31, 0) ours, yawed 180 deg (front, habitat +z, faces
# our +y, into room B); 1 cm clear of the south wall
COUNTER_TEMPLATE = "kitchen_counter"
COUNTER_POSITION = (5.95, 0.31, 0.0)
COUNTER_YAW = 180.0
URDF_LINK_BOXES = {  # apt_0, drawer closed (joint 0)
    "body": ((5.2, 0.01, 0.0), (6.7, 0.61, 0.9)),
    "drawer": ((5.7, 0.08, 0.65), (6.2, 0.63, 0.8)),
}
COUNTER_BOX = ((5.2, 0.01, 0.0), (6.7, 0.63, 0.9))  # apt_0, union of the link boxes (drawer closed)

# lights, OUR frame: two near the ceiling of rooms A and B, one just above the lamp's shade
# (shade top z = 1.65 * 1.2 = 1.98)
LIGHTS = {"0": (2.0, 1.5, 2.3), "1": (5.6, 1.5, 2.3), "2": (0.4, 2.6, 2.1)}
LIGHT_INTENSITY = {"0": 1.2, "1": 1.2, "2": 0.8}
LIGHT_COLOR = {"0": (1.0, 1.0, 0.95), "1": (1.0, 1.0, 0.95), "2": (1.0, 0.85, 0.6)}
# frl_apartment_1 (used by apt_3): dimmer, warmer, one negative "shadow" light like ReplicaCAD's
LIGHTS_1 = {"0": ((2.0, 1.5, 2.3), 0.9, (1.0, 0.9, 0.8)),
            "1": ((5.6, 1.5, 2.3), 0.9, (1.0, 0.9, 0.8)),
            "2": ((1.6, 0.5, 0.9), -0.3, (1.0, 1.0, 1.0))}


def _variant(k: int):
    """(objects, counter dict, lighting handle) of apt_k, as edits of apt_0 (all OUR frame)."""
    objs = [list(o) for o in APT0_OBJECTS]
    counter = {"position": COUNTER_POSITION, "yaw": COUNTER_YAW, "joint": None}
    lighting = LIGHTING_HANDLE
    if k == 1:  # chair 2 squared to the table, bowl removed, cushion moved along the seat
        objs[2][1], objs[2][2] = (2.7, 0.5, 0.0), -90.0
        objs[4][1] = (6.2, 2.55, 0.46)
        del objs[6]
    elif k == 2:  # lamp moved east of the window and turned; drawer open
        objs[5][1], objs[5][2] = (2.7, 2.6, 0.0), 30.0
        counter["joint"] = [0.3]
    elif k == 3:  # table turned round, a second bowl added, other lighting
        objs[0][2] = 180.0
        objs.append(["frl_apartment_bowl_03", (1.9, 0.4, 0.75), 45.0, "DYNAMIC", {}])
        lighting = "lighting/frl_apartment_1"
    elif k == 4:  # chair 1 removed, sofa and counter shifted
        objs[3][1] = (6.0, 2.525, 0.4)
        objs[4][1] = (5.6, 2.55, 0.46)
        del objs[1]
        counter["position"] = (5.4, 0.31, 0.0)
    elif k == 5:  # a second cushion, the lamp moved and turned 45 deg
        objs.append(["frl_apartment_cushion_01", (6.1, 2.5, 0.46), 20.0, "DYNAMIC", {"non_uniform_scale": _CUSHION_NUS}])
        objs[5][1], objs[5][2] = (0.5, 2.5, 0.0), 45.0
    return objs, counter, lighting


# ---------------------------------------------------------------------------------------------
# writing


def _to_h(v) -> list[float]:
    """Our-frame point -> habitat (C^T v), no negative zeros, rounded off float noise."""
    return [round(float(x), 12) + 0.0 for x in _C.T @ np.asarray(v, float)]


def _yaw_quat_h(deg: float) -> list[float]:
    """Yaw about our +Z = rotation about habitat +Y: (w, x, y, z) = (cos t/2, 0, sin t/2, 0)."""
    t = math.radians(deg)
    return [round(math.cos(t / 2), 15) + 0.0, 0.0, round(math.sin(t / 2), 15) + 0.0, 0.0]


def _texture(key: str) -> Image.Image:
    a, b = _SHADES[key]
    px = np.zeros((TEXTURE_SIZE, TEXTURE_SIZE, 3), np.uint8)
    for col in range(TEXTURE_SIZE):
        px[:, col] = a if (col // STRIPE_PX) % 2 == 0 else b
    return Image.fromarray(px, "RGB")


def _unshared(mesh: trimesh.Trimesh) -> trimesh.Trimesh:
    """Three vertices of its own per face (so each face can get planar UVs)."""
    v = mesh.vertices[mesh.faces].reshape(-1, 3)
    return trimesh.Trimesh(v, np.arange(len(v)).reshape(-1, 3), process=False)


def _planar_uv(mesh: trimesh.Trimesh, tile: float) -> np.ndarray:
    """Per-vertex UVs: each face projected along its dominant normal axis, one texture per `tile` m."""
    axis = np.argmax(np.abs(mesh.face_normals), axis=1)
    uv = np.zeros((len(mesh.vertices), 2))
    for f, a in enumerate(axis):
        keep = [i for i in range(3) if i != a]
        idx = mesh.faces[f]
        uv[idx] = mesh.vertices[idx][:, keep] / tile
    return uv


def _textured(parts, key: str, tile: float = 0.25) -> trimesh.Trimesh:
    mesh = _unshared(trimesh.util.concatenate(parts))
    mat = PBRMaterial(name=key.replace(":", "_"), baseColorTexture=_texture(key),
                      metallicFactor=0.0, roughnessFactor=0.8)
    mesh.visual = TextureVisuals(uv=_planar_uv(mesh, tile), material=mat)
    return mesh


def _plain(parts, name: str, factor) -> trimesh.Trimesh:
    mesh = trimesh.util.concatenate(parts)
    mesh.visual = TextureVisuals(material=PBRMaterial(name=name, baseColorFactor=list(factor),
                                                      metallicFactor=0.0, roughnessFactor=0.9))
    return mesh


def _write_json(path: Path, doc) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps(doc, indent=2) + "\n", encoding="utf-8")


def _stage_meshes() -> list[tuple[str, trimesh.Trimesh]]:
    """Floor, walls, ceiling built in OUR frame, then moved to habitat's (C^T)."""
    T = np.eye(4)
    T[:3, :3] = _C.T
    floor = _textured([box_mesh(*FLOOR_SLAB)], "frl_apartment_stage:floor", tile=0.5)  # UVs planar in ours
    walls = _plain([box_mesh(*b) for b in WALL_PIECES], "walls", WALL_COLOR_FACTOR)
    ceiling = _plain([box_mesh(*CEILING_SLAB)], "ceiling", CEILING_COLOR_FACTOR)
    out = []
    for name, m in (("floor", floor), ("walls", walls), ("ceiling", ceiling)):
        m.apply_transform(T)
        out.append((name, m))
    return out


def _object_entry(template, pos, yaw, motion, extra) -> dict:
    pos = np.asarray(pos, float)
    e = {"template_name": f"objects/{template}", "motion_type": motion}
    e.update({k: v for k, v in extra.items() if k != "translation_origin"})
    if extra.get("translation_origin") == "COM":
        # translation is the world COM: asset origin + R S COM (ours: C COM_h; only yaw, scale 1 here)
        com = _C @ np.asarray(_SOFA_COM_H if template == "frl_apartment_sofa" else (0, 0, 0), float)
        t = math.radians(yaw)
        R = np.array([[math.cos(t), -math.sin(t), 0], [math.sin(t), math.cos(t), 0], [0, 0, 1]])
        pos = pos + R @ com
        e["translation_origin"] = "COM"
    e["translation"] = _to_h(pos)
    e["rotation"] = _yaw_quat_h(yaw)
    return e


def _scene_doc(k: int) -> dict:
    objs, counter, lighting = _variant(k)
    ao = {"template_name": COUNTER_TEMPLATE, "translation_origin": "asset_local", "fixed_base": True,
          "auto_clamp_joint_limits": True, "translation": _to_h(counter["position"]),
          "rotation": _yaw_quat_h(counter["yaw"]), "motion_type": "DYNAMIC"}
    if counter["joint"] is not None:
        ao["initial_joint_pose"] = counter["joint"]
    return {
        "stage_instance": {"template_name": f"stages/{STAGE_TEMPLATE}"},
        "default_lighting": lighting,
        "translation_origin": "asset_local",
        "object_instances": [_object_entry(*o) for o in objs],
        "articulated_object_instances": [ao],
    }


def _lighting_doc(lights) -> dict:
    return {"lights": {k: {"type": "point", "position": _to_h(p), "intensity": i, "color": list(c)}
                       for k, (p, i, c) in lights.items()}}


_URDF = """<?xml version="1.0" ?>
<robot name="kitchen_counter">
  <link name="body">
    <inertial>
      <origin xyz="0 0.45 0" rpy="0 0 0"/>
      <mass value="60.0"/>
      <inertia ixx="5.85" ixy="0" ixz="0" iyy="13.05" iyz="0" izz="15.3"/>
    </inertial>
    <visual>
      <origin xyz="0 0 0" rpy="0 0 0"/>
      <geometry>
        <mesh filename="kitchen_counter.glb" scale="1 1 1"/>
      </geometry>
    </visual>
    <collision>
      <origin xyz="0 0.45 0" rpy="0 0 0"/>
      <geometry>
        <box size="1.5 0.9 0.6"/>
      </geometry>
    </collision>
  </link>
  <link name="drawer">
    <inertial>
      <origin xyz="0 0 0" rpy="0 0 0"/>
      <mass value="2.0"/>
      <inertia ixx="0.054" ixy="0" ixz="0" iyy="0.092" iyz="0" izz="0.046"/>
    </inertial>
    <visual>
      <origin xyz="0 0 0" rpy="0 0 0"/>
      <geometry>
        <mesh filename="drawer1.glb" scale="1 1 1"/>
      </geometry>
    </visual>
    <collision>
      <origin xyz="0 0 0" rpy="0 0 0"/>
      <geometry>
        <box size="0.5 0.15 0.55"/>
      </geometry>
    </collision>
  </link>
  <joint name="drawer_slide" type="prismatic">
    <parent link="body"/>
    <child link="drawer"/>
    <origin xyz="0 0.725 0.045" rpy="0 0 0"/>
    <axis xyz="0 0 1"/>
    <limit lower="0" upper="0.35" effort="100" velocity="1"/>
  </joint>
</robot>
"""


def make_fixture(root: Path) -> Path:
    """Write the ReplicaCAD-shaped dataset under ``root`` (created if needed); returns ``root``."""
    root = Path(root)
    root.mkdir(parents=True, exist_ok=True)
    _write_json(root / "replicaCAD.scene_dataset_config.json", {
        "stages": {"paths": {".json": ["configs/stages"]}},
        "objects": {"paths": {".json": ["configs/objects"]}},
        "articulated_objects": {"paths": {".urdf": ["urdf/*/"]}},
        "light_setups": {"default_attributes": {"positive_intensity_scale": 2.5, "negative_intensity_scale": 0.1},
                         "paths": {".json": ["configs/lighting"]}},
        "scene_instances": {"paths": {".json": ["configs/scenes"]}},
    })
    # stage
    write_glb(root / f"stages/{STAGE_TEMPLATE}.glb", _stage_meshes())
    _write_json(root / f"configs/stages/{STAGE_TEMPLATE}.stage_config.json", {
        "render_asset": f"../../stages/{STAGE_TEMPLATE}.glb", "up": [0, 1, 0], "front": [0, 0, -1],
        "origin": [0, 0, 0], "requires_lighting": True})
    # objects
    for template, (folder, parts, extra) in _OBJECTS.items():
        write_glb(root / f"objects/{template}.glb", [(template, _textured(parts(), template))])
        depth = folder.count("/") + 1
        cfg = {"render_asset": "../" * depth + f"objects/{template}.glb", "up": [0, 1, 0], "front": [0, 0, -1],
               "requires_lighting": True}
        cfg.update(extra)
        _write_json(root / folder / f"{template}.object_config.json", cfg)
    # articulated object
    udir = root / "urdf" / COUNTER_TEMPLATE
    write_glb(udir / "kitchen_counter.glb", [("kitchen_counter", _textured(_counter_parts(), "kitchen_counter:body"))])
    write_glb(udir / "drawer1.glb", [("drawer1", _textured(_drawer_parts(), "kitchen_counter:drawer", tile=0.1))])
    udir.mkdir(parents=True, exist_ok=True)
    (udir / "kitchen_counter.urdf").write_text(_URDF, encoding="utf-8")
    _write_json(udir / "kitchen_counter.ao_config.json", {"urdf_filepath": "kitchen_counter.urdf"})
    # lighting
    _write_json(root / "configs/lighting/frl_apartment_stage.lighting_config.json",
                _lighting_doc({k: (LIGHTS[k], LIGHT_INTENSITY[k], LIGHT_COLOR[k]) for k in LIGHTS}))
    _write_json(root / "configs/lighting/frl_apartment_1.lighting_config.json", _lighting_doc(LIGHTS_1))
    # scenes
    for k, name in enumerate(SCENES):
        _write_json(root / f"configs/scenes/{name}.scene_instance.json", _scene_doc(k))
    return root


if __name__ == "__main__":
    if len(sys.argv) != 2:
        sys.exit("usage: python tests/replicacad_fixture.py OUT_DIR")
    print(make_fixture(Path(sys.argv[1])))
