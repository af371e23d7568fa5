"""synth.sources.replicacad.importer: a tiny ReplicaCAD-shaped dataset built here, expected values worked out by hand.

These tests cover the conversion of scene instances, poses, scales and frames, so they import with
``structure=False`` (the stage stays one mesh, articulated objects are skipped); the full import
(structure from the stage mesh, URDF furniture, supports, fixtures) is tested on the
ReplicaCAD-shaped fixture in tests/synth/sources/test_replicacad_import.py.

Frames: habitat/glTF is Y up, -Z forward; ours is Z up. C maps (x, y, z) -> (x, -z, y).
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest
import trimesh
from scipy.spatial.transform import Rotation

from vrformats.errors import SceneFormatError, UnknownNameError
from synth.scene.classes import parse_class_table
from synth.sources.replicacad.importer import Y_UP_TO_Z_UP, list_scenes, load_asset_mesh, load_replicacad
from synth.scene.model import load_layout, object_box, save_layout
from meshes import box_mesh, write_glb



C = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, -1.0], [0.0, 1.0, 0.0]])  # written out by hand, not imported
S45 = math.sqrt(0.5)
SCENE = "apt_test"

CLASSES = parse_class_table(
    {
        "classes": {
            "wall": {"id": 1, "support": "floor", "movable": False, "structure": True},
            "chair": {"id": 2, "support": "floor", "movable": True},
            "dining_table": {"id": 3, "support": "floor", "movable": True},
            "floor_lamp": {"id": 4, "support": "floor", "movable": True},
            "other": {"id": 5, "support": "floor", "movable": True},
        },
        "replicacad": {"aliases": {"table": "dining_table", "lamp": "floor_lamp"}},
    },
    "<test classes>",
)


# Meshes in habitat/glTF coordinates (x, y up, z).
CHAIR = box_mesh((-0.2, 0.0, -0.25), (0.2, 0.9, 0.25))  # 0.4 x 0.9 x 0.5, standing on y = 0
TABLE = box_mesh((-0.6, 0.0, -0.4), (0.6, 0.75, 0.4))  # 1.2 x 0.75 x 0.8
LAMP = trimesh.util.concatenate([  # asymmetric, bounds off-centre: x [0.1, 0.5], y [0, 1.5], z [-0.3, -0.1]
    box_mesh((0.1, 0.0, -0.3), (0.5, 0.1, -0.1)),  # foot
    box_mesh((0.25, 0.1, -0.25), (0.35, 1.5, -0.15)),  # pole
])
GADGET = box_mesh((-0.05, 0.0, -0.05), (0.05, 0.1, 0.05))
STAGE = trimesh.util.concatenate([
    box_mesh((-3.0, 0.0, -4.0), (3.0, 0.1, 4.0)),  # floor slab
    box_mesh((-3.1, 0.0, -4.1), (3.1, 2.6, -4.0)),  # walls, 2.6 m tall
    box_mesh((-3.1, 0.0, 4.0), (3.1, 2.6, 4.1)),
    box_mesh((-3.1, 0.0, -4.0), (-3.0, 2.6, 4.0)),
    box_mesh((3.0, 0.0, -4.0), (3.1, 2.6, 4.0)),
])

# a general rotation (about a tilted axis), (w, x, y, z)
Q_TILT = tuple(np.array([0.9, 0.1, 0.3, -0.2]) / np.linalg.norm([0.9, 0.1, 0.3, -0.2]))

INSTANCES = [
    {"template_name": "objects/frl_apartment_chair_01", "motion_type": "STATIC",
     "translation": [1.0, 0.2, -3.0], "rotation": [1, 0, 0, 0]},
    {"template_name": "objects/frl_apartment_chair_01", "motion_type": "DYNAMIC",  # +90 deg about habitat +Y
     "translation": [2.0, 0.0, 1.0], "rotation": [S45, 0.0, S45, 0.0]},
    {"template_name": "frl_apartment_table_01", "motion_type": "STATIC",  # no folder prefix
     "translation": [-1.0, 0.0, 2.0], "rotation": [1, 0, 0, 0], "non_uniform_scale": [2.0, 1.0, 0.5]},
    {"template_name": "objects/frl_apartment_lamp_01", "motion_type": "DYNAMIC",
     "translation": [3.0, 0.0, -2.0], "rotation": [1, 0, 0, 0]},
    {"template_name": "objects/frl_apartment_zzgadget", "motion_type": "KINEMATIC",  # no class rule
     "translation": [0.0, 0.0, 0.0], "rotation": [1, 0, 0, 0]},
    {"template_name": "objects/frl_apartment_chair_01", "translation_origin": "COM",  # translation = COM
     "translation": [-2.0, 0.5, -1.0], "rotation": list(Q_TILT), "uniform_scale": 1.5},
]


def _write_json(path: Path, doc) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps(doc, indent=2))


def _make_dataset(root: Path, instances=None) -> Path:
    _write_json(root / "test.scene_dataset_config.json", {})  # the dataset's root holds one (habitat-sim loads it)
    write_glb(root / "stages/test_stage.glb", STAGE)
    write_glb(root / "objects/frl_apartment_chair_01.glb", CHAIR)
    write_glb(root / "objects/frl_apartment_table_01.glb", TABLE)
    write_glb(root / "objects/lamp.glb", LAMP)
    write_glb(root / "objects/gadget.glb", GADGET)
    _write_json(root / "configs/stages/test_stage.stage_config.json",
                {"render_asset": "../../stages/test_stage.glb", "up": [0, 1, 0], "front": [0, 0, -1],
                 "origin": [0, 0, 0], "scale": [1, 1, 1], "requires_lighting": True})
    _write_json(root / "configs/objects/frl_apartment_chair_01.object_config.json",
                {"render_asset": "../../objects/frl_apartment_chair_01.glb", "mass": 5.0, "up": [0, 1, 0], "front": [0, 0, -1]})
    _write_json(root / "configs/objects/frl_apartment_table_01.object_config.json",
                {"render_asset": "../../objects/frl_apartment_table_01.glb", "scale": [1, 1, 1]})
    _write_json(root / "configs/objects/lights/frl_apartment_lamp_01.object_config.json",  # in a sub-folder
                {"render_asset": "../../../objects/lamp.glb"})
    _write_json(root / "configs/objects/frl_apartment_zzgadget.object_config.json",
                {"render_asset": "../../objects/gadget.glb"})
    _write_json(root / f"configs/scenes/{SCENE}.scene_instance.json", {
        "stage_instance": {"template_name": "stages/test_stage"},
        "default_lighting": "lighting/test_stage",
        "translation_origin": "asset_local",
        "object_instances": INSTANCES if instances is None else instances,
        "articulated_object_instances": [
            {"template_name": "fridge", "fixed_base": True, "translation": [0, 0, 0], "rotation": [1, 0, 0, 0],
             "motion_type": "DYNAMIC"},
            {"template_name": "kitchen_counter", "fixed_base": True, "translation": [1, 0, 0], "rotation": [1, 0, 0, 0]},
        ],
        "navmesh_instance": "test_navmesh",
    })
    _write_json(root / "configs/scenes/other_scene.scene_instance.json",
                {"stage_instance": {"template_name": "test_stage"}, "object_instances": []})
    return root


@pytest.fixture(scope="module")
def dataset(tmp_path_factory) -> Path:
    return _make_dataset(tmp_path_factory.mktemp("replica_cad"))


@pytest.fixture(scope="module")
def layout(dataset):
    return load_replicacad(dataset, SCENE, classes=CLASSES, allow_unknown=True, structure=False)


def _scene_file(root: Path) -> Path:
    return root / f"configs/scenes/{SCENE}.scene_instance.json"


def _edit_scene(root: Path, fn) -> None:
    p = _scene_file(root)
    doc = json.loads(p.read_text())
    fn(doc)
    p.write_text(json.dumps(doc))


def test_matrix_and_list_scenes(dataset):
    assert np.array_equal(Y_UP_TO_Z_UP, C)
    assert Y_UP_TO_Z_UP @ np.array([1.0, 0.2, -3.0]) == pytest.approx([1.0, 3.0, 0.2])
    assert list_scenes(dataset) == [SCENE, "other_scene"]


def test_layout_basics(layout, dataset):
    assert layout.name == SCENE
    assert layout.meta == {"source": "replicacad", "root": str(dataset.resolve()), "scene": SCENE,
                           "skipped_articulated": ["fridge", "kitchen_counter"]}
    assert [o.id for o in layout.objects] == [1, 2, 3, 4, 5, 6]
    assert [o.cls for o in layout.objects] == ["chair", "chair", "dining_table", "floor_lamp", "other", "chair"]
    assert [o.movable for o in layout.objects] == [False, True, False, True, True, True]
    assert all(o.support == "free" for o in layout.objects)
    assert [o.asset for o in layout.objects] == [
        "replicacad:objects/frl_apartment_chair_01.glb", "replicacad:objects/frl_apartment_chair_01.glb",
        "replicacad:objects/frl_apartment_table_01.glb", "replicacad:objects/lamp.glb",
        "replicacad:objects/gadget.glb", "replicacad:objects/frl_apartment_chair_01.glb",
    ]
    assert layout.objects[0].params == {"template": "objects/frl_apartment_chair_01", "motion_type": "STATIC"}
    assert layout.objects[2].params == {"template": "frl_apartment_table_01", "motion_type": "STATIC"}
    assert layout.objects[4].params["motion_type"] == "KINEMATIC"
    assert layout.objects[5].params["motion_type"] == "UNDEFINED"  # not given in the file


def test_stage(layout, dataset):
    st = layout.stage
    assert st.asset == "replicacad:stages/test_stage.glb"
    assert st.ceiling_height == pytest.approx(2.6, abs=1e-6)  # walls span habitat y 0 .. 2.6
    assert st.floor_z == pytest.approx(0.0, abs=1e-6)
    assert st.position == (0.0, 0.0, 0.0) and st.rotation == (1.0, 0.0, 0.0, 0.0)
    assert st.rooms == [] and st.walls == [] and st.openings == []
    m = load_asset_mesh(dataset, st.asset)
    # habitat x [-3.1, 3.1], y [0, 2.6], z [-4.1, 4.1] -> ours x [-3.1, 3.1], y = -z [-4.1, 4.1], z = y [0, 2.6]
    assert m.bounds == pytest.approx(np.array([[-3.1, -4.1, 0.0], [3.1, 4.1, 2.6]]), abs=1e-6)


def test_position_identity_rotation(layout):
    o = layout.objects[0]
    assert o.position == pytest.approx((1.0, 3.0, 0.2))  # habitat (1, 0.2, -3) -> (x, -z, y)
    assert o.rotation == pytest.approx((1.0, 0.0, 0.0, 0.0))
    # chair box: habitat x [-0.2, 0.2], y [0, 0.9], z [-0.25, 0.25] -> ours x [-.2, .2], y [-.25, .25], z [0, .9]
    assert o.size == pytest.approx((0.4, 0.5, 0.9), abs=1e-6)
    assert o.box_offset == pytest.approx((0.0, 0.0, 0.45), abs=1e-6)
    b = object_box(o)
    assert b.center == pytest.approx((1.0, 3.0, 0.65), abs=1e-6)
    assert b.size == pytest.approx((0.4, 0.5, 0.9), abs=1e-6)
    assert b.yaw == pytest.approx(0.0, abs=1e-9)


def test_rotation_about_vertical_is_yaw(layout):
    # Habitat R_y(90): x -> (cos 90, 0, -sin 90) = (0, 0, -1), i.e. local +X points along habitat -Z.
    # Habitat -Z is our +Y (C (0, 0, -1) = (0, 1, 0)), so local +X points along our +Y: yaw +90 deg.
    # The quaternion (cos45, 0, sin45, 0) becomes (w, x, -z, y) = (cos45, 0, 0, sin45).
    o = layout.objects[1]
    assert o.position == pytest.approx((2.0, -1.0, 0.0), abs=1e-12)  # habitat (2, 0, 1)
    assert o.rotation == pytest.approx((S45, 0.0, 0.0, S45))
    assert o.yaw == pytest.approx(math.pi / 2)
    b = object_box(o)
    assert b.center == pytest.approx((2.0, -1.0, 0.45), abs=1e-6)
    assert b.size == pytest.approx((0.4, 0.5, 0.9), abs=1e-6)
    assert b.yaw == pytest.approx(math.pi / 2)
    # Footprint by hand: in habitat the chair's x half-width 0.2 turns into z, its z half-depth 0.25 into x:
    # x in 2 +- 0.25, z in 1 +- 0.2 -> ours x [1.75, 2.25], y = -z [-1.2, -0.8].
    c = b.corners_2d()
    assert c.min(axis=0) == pytest.approx([1.75, -1.2], abs=1e-6)
    assert c.max(axis=0) == pytest.approx([2.25, -0.8], abs=1e-6)


def test_non_uniform_scale(layout):
    o = layout.objects[2]
    # habitat scale (x 2, y 1, z 0.5) -> ours (x 2, y 0.5, z 1)
    assert o.scale == pytest.approx((2.0, 0.5, 1.0))
    # table 1.2 (x) x 0.75 (y up) x 0.8 (z) -> scaled 2.4 x 0.75 x 0.4 -> ours (2.4, 0.4, 0.75)
    assert o.size == pytest.approx((2.4, 0.4, 0.75), abs=1e-6)
    assert o.position == pytest.approx((-1.0, -2.0, 0.0), abs=1e-12)
    b = object_box(o)
    assert b.center == pytest.approx((-1.0, -2.0, 0.375), abs=1e-6)
    assert b.size == pytest.approx((2.4, 0.4, 0.75), abs=1e-6)


def test_off_centre_bounds(layout):
    o = layout.objects[3]
    # lamp: habitat x [0.1, 0.5], y [0, 1.5], z [-0.3, -0.1] -> ours x [0.1, 0.5], y [0.1, 0.3], z [0, 1.5]
    assert o.size == pytest.approx((0.4, 0.2, 1.5), abs=1e-6)
    assert o.box_offset == pytest.approx((0.3, 0.2, 0.75), abs=1e-6)
    assert o.position == pytest.approx((3.0, 2.0, 0.0), abs=1e-12)  # habitat (3, 0, -2)
    b = object_box(o)
    assert b.center == pytest.approx((3.3, 2.2, 0.75), abs=1e-6)
    assert b.size == pytest.approx((0.4, 0.2, 1.5), abs=1e-6)


def test_com_translation_origin(layout):
    # "COM": the translation places the centre of the scaled bounding box, not the GLB origin.
    o = layout.objects[5]
    b = object_box(o)
    # position and box offset are stored at 0.1 mm: the centre they imply is within 0.1 mm per axis
    assert b.center == pytest.approx((-2.0, 1.0, 0.5), abs=1e-4)  # C (-2, 0.5, -1)
    assert o.scale == pytest.approx((1.5, 1.5, 1.5))
    assert o.size == pytest.approx((0.6, 0.75, 1.35), abs=1e-6)


def _rot(q) -> np.ndarray:
    w, x, y, z = q
    return Rotation.from_quat([x, y, z, w]).as_matrix()


@pytest.mark.parametrize("index, mesh, com", [
    (0, CHAIR, None), (1, CHAIR, None), (2, TABLE, None), (3, LAMP, None), (4, GADGET, None),
    (5, CHAIR, (0.0, 0.45, 0.0)),  # chair bounding-box centre, habitat frame
])
def test_world_vertices_agree(layout, dataset, index, mesh, com):
    inst, o = INSTANCES[index], layout.objects[index]
    t = np.array(inst["translation"], float)
    s = np.array(inst.get("non_uniform_scale", [1, 1, 1]), float) * inst.get("uniform_scale", 1.0)
    origin = np.zeros(3) if com is None else np.array(com)
    world_h = t + (s * (mesh.vertices - origin)) @ _rot(inst["rotation"]).T  # habitat pose applied to v
    expected = world_h @ C.T  # C (T_h v)

    local = load_asset_mesh(dataset, o.asset).vertices
    got = (local * np.asarray(o.scale)) @ _rot(o.rotation).T + np.asarray(o.position)
    assert len(got) == len(expected)
    d = np.linalg.norm(expected[:, None, :] - got[None, :, :], axis=2)
    # layouts store positions at 0.1 mm (synth.scene.model.LENGTH_DECIMALS): at most 0.05 mm per axis
    assert d.min(axis=1).max() < 1e-4 and d.min(axis=0).max() < 1e-4


def test_one_vertex_by_hand(layout, dataset):
    # chair corner habitat (0.2, 0.9, 0.25); R_y(90) (x, y, z) = (z, y, -x) -> (0.25, 0.9, -0.2);
    # + (2, 0, 1) -> (2.25, 0.9, 0.8); C -> (2.25, -0.8, 0.9)
    o = layout.objects[1]
    local = load_asset_mesh(dataset, o.asset).vertices
    world = local @ _rot(o.rotation).T + np.asarray(o.position)
    assert np.linalg.norm(world - [2.25, -0.8, 0.9], axis=1).min() < 1e-6


def test_unknown_template(dataset):
    with pytest.raises(UnknownNameError) as e:
        load_replicacad(dataset, SCENE, classes=CLASSES, structure=False)
    assert "frl_apartment_zzgadget" in str(e.value)
    assert "chair" not in str(e.value)


def test_default_class_table(tmp_path):
    root = _make_dataset(tmp_path / "d", instances=INSTANCES[:2])
    lay = load_replicacad(root, SCENE, structure=False)
    assert [o.cls for o in lay.objects] == ["chair", "chair"]


def test_round_trip(layout, tmp_path):
    path = save_layout(layout, tmp_path / "rt.yaml")
    again = load_layout(path, classes=CLASSES)
    assert again == layout
    save_layout(again, tmp_path / "rt2.yaml")
    assert (tmp_path / "rt2.yaml").read_bytes() == path.read_bytes()


def _error(root: Path, **kw) -> str:
    with pytest.raises(SceneFormatError) as e:
        load_replicacad(root, SCENE, classes=CLASSES, allow_unknown=True, **kw, structure=False)
    return str(e.value)


def test_malformed_json(tmp_path):
    root = _make_dataset(tmp_path / "d")
    _scene_file(root).write_text('{"stage_instance": {"template_name": ')
    msg = _error(root)
    assert msg.startswith(f"{_scene_file(root)}: ") and "not valid JSON" in msg


@pytest.mark.parametrize("field, value, expect", [
    ("rotation", [1, 0, 0], "object_instances[1].rotation: expected 4 numbers"),
    ("rotation", [1, 1, 0, 0], "object_instances[1].rotation: expected a unit quaternion"),
    ("rotation", "identity", "object_instances[1].rotation: expected 4 numbers"),
    ("translation", [1, "a", 0], "object_instances[1].translation: expected 3 numbers"),
    ("translation", [1, 2], "object_instances[1].translation: expected 3 numbers"),
    ("non_uniform_scale", [1, 0, 1], "object_instances[1].non_uniform_scale: expected 3 numbers > 0"),
    ("motion_type", "FLYING", "object_instances[1].motion_type: expected one of"),
    ("template_name", "objects/frl_apartment_nothing_01", "object_instances[1].template_name: no object config"),
    ("translation_origin", "middle", "object_instances[1].translation_origin: expected"),
])
def test_bad_instance_field(tmp_path, field, value, expect):
    root = _make_dataset(tmp_path / "d")
    _edit_scene(root, lambda d: d["object_instances"][1].__setitem__(field, value))
    msg = _error(root)
    assert msg.startswith(f"{_scene_file(root)}: {expect}"), msg
    assert f"{SCENE}.scene_instance.json: object_instances[1].{field}" in msg


def test_missing_glb(tmp_path):
    root = _make_dataset(tmp_path / "d")
    (root / "objects/frl_apartment_table_01.glb").unlink()
    msg = _error(root)
    cfg = root / "configs/objects/frl_apartment_table_01.object_config.json"
    assert msg.startswith(f"{cfg}: render_asset: GLB not found")


def test_missing_stage_glb(tmp_path):
    root = _make_dataset(tmp_path / "d")
    (root / "stages/test_stage.glb").unlink()
    assert "test_stage.stage_config.json: render_asset: GLB not found" in _error(root)


def test_broken_glb(tmp_path):
    root = _make_dataset(tmp_path / "d")
    (root / "objects/lamp.glb").write_bytes(b"not a glb file at all")
    msg = _error(root)
    assert msg.startswith(f"{root / 'objects/lamp.glb'}: cannot read GLB")


def test_non_default_frame_rejected(tmp_path):
    root = _make_dataset(tmp_path / "d")
    _write_json(root / "configs/objects/frl_apartment_chair_01.object_config.json",
                {"render_asset": "../../objects/frl_apartment_chair_01.glb", "up": [0, 0, 1], "front": [0, 1, 0]})
    assert "frl_apartment_chair_01.object_config.json: up: only the default frame" in _error(root)


def test_missing_root_and_scene(tmp_path):
    with pytest.raises(SceneFormatError, match="not found"):
        load_replicacad(tmp_path / "nowhere", SCENE, classes=CLASSES, structure=False)
    with pytest.raises(SceneFormatError, match="not found"):
        list_scenes(tmp_path / "nowhere")
    root = _make_dataset(tmp_path / "d")
    with pytest.raises(SceneFormatError) as e:
        load_replicacad(root, "apt_9", classes=CLASSES, structure=False)
    assert "apt_9.scene_instance.json" in str(e.value) and SCENE in str(e.value)


def test_missing_stage_instance(tmp_path):
    root = _make_dataset(tmp_path / "d")
    _edit_scene(root, lambda d: d.pop("stage_instance"))
    assert f"{SCENE}.scene_instance.json: stage_instance: missing" in _error(root)


def test_load_asset_mesh_errors(dataset):
    with pytest.raises(UnknownNameError):
        load_asset_mesh(dataset, "proc:chair")
    with pytest.raises(SceneFormatError, match="GLB not found"):
        load_asset_mesh(dataset, "replicacad:objects/none.glb")


def test_translation_origin_defaults_to_com(tmp_path):
    # Without a top-level "translation_origin", habitat-sim reads translations as COM positions
    # (centre of the bounding box) unless an instance says "asset_local".
    root = _make_dataset(tmp_path / "d", instances=[
        dict(INSTANCES[0]),
        dict(INSTANCES[0], translation_origin="asset_local"),
    ])
    _edit_scene(root, lambda d: d.pop("translation_origin"))
    a, b = load_replicacad(root, SCENE, classes=CLASSES, structure=False).objects
    # COM: the chair's box centre lands on C (1, 0.2, -3) = (1, 3, 0.2); its origin is 0.45 lower
    assert object_box(a).center == pytest.approx((1.0, 3.0, 0.2), abs=1e-6)
    assert a.position == pytest.approx((1.0, 3.0, 0.2 - 0.45), abs=1e-6)
    # asset_local: the GLB origin lands there, the box centre 0.45 higher
    assert b.position == pytest.approx((1.0, 3.0, 0.2), abs=1e-12)
    assert object_box(b).center == pytest.approx((1.0, 3.0, 0.65), abs=1e-6)


def test_config_com_and_scene_without_objects(dataset, tmp_path):
    lay = load_replicacad(dataset, "other_scene", classes=CLASSES, structure=False)  # stage template without folder prefix
    assert lay.objects == [] and lay.meta["skipped_articulated"] == []
    assert lay.stage.ceiling_height == pytest.approx(2.6, abs=1e-6)

    root = _make_dataset(tmp_path / "d", instances=[dict(INSTANCES[3], translation_origin="COM")])
    _write_json(root / "configs/objects/lights/frl_apartment_lamp_01.object_config.json",
                {"render_asset": "../../../objects/lamp.glb", "COM": [0.3, 0.0, -0.2]})
    (o,) = load_replicacad(root, SCENE, classes=CLASSES, structure=False).objects
    # the config COM (0.3, 0, -0.2) is placed at (3, 0, -2): GLB origin at (2.7, 0, -1.8) -> ours (2.7, 1.8, 0)
    assert o.position == pytest.approx((2.7, 1.8, 0.0), abs=1e-12)
