"""synth.mesh.urdf: URDFs and GLBs written here, expected positions worked out by hand.

Frames: a URDF is in habitat coordinates (Y up, like its GLBs); ours is Z up. C maps habitat
(x, y, z) to ours (x, -z, y). Every expected number below is derived in the comments.
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest

from vrformats.errors import SceneFormatError, UnknownNameError
from synth.scene import geometry as geo
from synth.scene.classes import parse_class_table
from synth.scene.model import object_box
from synth.mesh.urdf import parse_urdf, urdf_geometry, urdf_visuals
from synth.sources.replicacad.articulated import find_urdf, load_articulated_instances
from meshes import box_mesh, write_glb

CLASSES = parse_class_table(
    {
        "classes": {
            "wall": {"id": 1, "support": "floor", "movable": False, "structure": True},
            "kitchen_counter": {"id": 2, "support": "floor", "movable": False},
            "other": {"id": 3, "support": "floor", "movable": True},
        },
        "replicacad": {"aliases": {"test_counter": "kitchen_counter", "wallthing": "wall"}},
    },
    "<test classes>",
)


# GLB meshes, habitat/glTF coordinates (x, y up, z).
BODY = box_mesh((-0.75, 0.0, -0.3), (0.75, 0.45, 0.3))  # drawn with <mesh scale="1 2 1">: 1.5 wide, 0.9 tall, 0.6 deep
DRAWER = box_mesh((-0.25, -0.075, -0.275), (0.25, 0.075, 0.275))  # 0.5 x 0.15 x 0.55; turned 90 deg about Y by its visual rpy
DOOR = box_mesh((0.0, 0.0, -0.01), (0.6, 0.8, 0.01))  # a panel 0.6 wide from its hinge edge x = 0

URDF = """<?xml version="1.0"?>
<robot name="test_counter">
  <link name="body">
    <inertial><mass value="10"/></inertial>
    <visual>
      <origin xyz="0 0 0" rpy="0 0 0"/>
      <geometry><mesh filename="meshes/body.glb" scale="1 2 1"/></geometry>
    </visual>
    <collision><geometry><box size="1.5 0.9 0.6"/></geometry></collision>
  </link>
  <link name="drawer">
    <visual>
      <origin xyz="0 0 0" rpy="0 1.5707963267948966 0"/>
      <geometry><mesh filename="meshes/drawer.glb"/></geometry>
    </visual>
  </link>
  <joint name="slide" type="prismatic">
    <origin xyz="0.2 0.6 0.1" rpy="0 0 0"/>
    <parent link="body"/>
    <child link="drawer"/>
    <axis xyz="0 0 1"/>
    <limit lower="0" upper="0.4" effort="1" velocity="1"/>
  </joint>
</robot>
"""

DOOR_URDF = """<?xml version="1.0"?>
<robot name="test_door">
  <link name="frame">
    <visual><geometry><mesh filename="body.glb" scale="1 2 1"/></geometry></visual>
  </link>
  <link name="door">
    <visual><geometry><mesh filename="door.glb"/></geometry></visual>
  </link>
  <joint name="hinge" type="revolute">
    <origin xyz="0.75 0 0.3"/>
    <parent link="frame"/>
    <child link="door"/>
    <axis xyz="0 1 0"/>
  </joint>
</robot>
"""

# joint order test: root children by joint name a_hinge (-> b), m_fixed (-> c), z_slide (-> a); a's child by b_sub (-> d)
ORDER_URDF = """<?xml version="1.0"?>
<robot name="order">
  <link name="base"><visual><geometry><mesh filename="body.glb"/></geometry></visual></link>
  <link name="a"/><link name="b"/><link name="c"/><link name="d"/>
  <joint name="z_slide" type="prismatic"><parent link="base"/><child link="a"/><axis xyz="1 0 0"/></joint>
  <joint name="b_sub" type="prismatic"><parent link="a"/><child link="d"/></joint>
  <joint name="a_hinge" type="continuous"><parent link="base"/><child link="b"/></joint>
  <joint name="m_fixed" type="fixed"><parent link="base"/><child link="c"/></joint>
</robot>
"""


def _ours(v_h) -> np.ndarray:
    """C v, written out: (x, y, z) -> (x, -z, y)."""
    v_h = np.asarray(v_h, float)
    return np.stack([v_h[:, 0], -v_h[:, 2], v_h[:, 1]], axis=1)


def _same_points(a, b, tol=1e-6) -> bool:
    a, b = np.asarray(a, float), np.asarray(b, float)
    if a.shape != b.shape:
        return False
    d = np.linalg.norm(a[:, None, :] - b[None, :, :], axis=2)
    return bool(d.min(axis=1).max() < tol and d.min(axis=0).max() < tol)


def _placed(vis) -> np.ndarray:
    """A visual's GLB vertices placed by the visual (the renderer's recipe), from our own copy of the mesh."""
    v = _ours({"body.glb": BODY, "drawer.glb": DRAWER, "door.glb": DOOR}[vis.glb.name].vertices)
    return (v * vis.scale) @ vis.matrix[:3, :3].T + vis.matrix[:3, 3]


# hand-derived placements in our local frame (x, y, z = up), from GLB vertices (x, y, z):
def _body_expected(v):  # habitat (x, 2y, z) -> ours (x, -z, 2y)
    return np.stack([v[:, 0], -v[:, 2], 2 * v[:, 1]], axis=1)


def _drawer_expected(v, q=0.0):
    # Ry(90 deg): (x, y, z) -> (z, y, -x); + joint origin (0.2, 0.6, 0.1) + q * (0, 0, 1)
    # habitat (z + 0.2, y + 0.6, -x + 0.1 + q) -> ours (z + 0.2, x - 0.1 - q, y + 0.6)
    return np.stack([v[:, 2] + 0.2, v[:, 0] - 0.1 - q, v[:, 1] + 0.6], axis=1)


def _counter_dir(folder: Path, urdf_text: str = URDF, name: str = "test_counter") -> Path:
    folder.mkdir(parents=True, exist_ok=True)
    write_glb(folder / "meshes" / "body.glb", BODY)
    write_glb(folder / "meshes" / "drawer.glb", DRAWER)
    p = folder / f"{name}.urdf"
    p.write_text(urdf_text)
    return p


@pytest.fixture
def counter(tmp_path) -> Path:
    return _counter_dir(tmp_path / "urdf" / "test_counter")


@pytest.fixture
def door(tmp_path) -> Path:
    d = tmp_path / "door"
    write_glb(d / "body.glb", BODY)
    write_glb(d / "door.glb", DOOR)
    (d / "door.urdf").write_text(DOOR_URDF)
    return d / "door.urdf"


# --------------------------------------------------------------------------------------------
# urdf_visuals


def test_visuals_default_state(counter):
    vis = urdf_visuals(counter)
    assert [v.link for v in vis] == ["body", "drawer"]
    assert vis[0].glb == (counter.parent / "meshes" / "body.glb").resolve()
    # <mesh scale="1 2 1"> on habitat (x, y, z) is (1, 1, 2) on ours (x, -z, y)
    np.testing.assert_allclose(vis[0].scale, [1.0, 1.0, 2.0])
    np.testing.assert_allclose(vis[1].scale, [1.0, 1.0, 1.0])
    assert _same_points(_placed(vis[0]), _body_expected(BODY.vertices))
    assert _same_points(_placed(vis[1]), _drawer_expected(DRAWER.vertices))
    # the drawer's box, by hand: x [-0.275+0.2, 0.275+0.2], y [-0.25-0.1, 0.25-0.1], z [0.6-0.075, 0.6+0.075]
    p = _placed(vis[1])
    np.testing.assert_allclose(p.min(axis=0), [-0.075, -0.35, 0.525], atol=1e-9)
    np.testing.assert_allclose(p.max(axis=0), [0.475, 0.15, 0.675], atol=1e-9)


def test_prismatic_state_moves_drawer_along_axis(counter):
    vis = urdf_visuals(counter, {"slide": 0.3})
    # the axis is habitat +Z, i.e. our -Y: the drawer moves 0.3 m towards -Y, the body stays
    assert _same_points(_placed(vis[0]), _body_expected(BODY.vertices))
    assert _same_points(_placed(vis[1]), _drawer_expected(DRAWER.vertices, q=0.3))
    d = _placed(vis[1]).mean(axis=0) - _placed(urdf_visuals(counter)[1]).mean(axis=0)
    np.testing.assert_allclose(d, [0.0, -0.3, 0.0], atol=1e-9)


def test_revolute_state_rotates_door(door):
    c0 = urdf_visuals(door)[1]
    c90 = urdf_visuals(door, {"hinge": math.pi / 2})[1]
    v = DOOR.vertices
    # q = 0: habitat (0.75 + x, y, 0.3 + z) -> ours (0.75 + x, -0.3 - z, y)
    assert _same_points(_placed(c0), np.stack([0.75 + v[:, 0], -0.3 - v[:, 2], v[:, 1]], axis=1))
    # q = 90 deg about habitat +Y: (x, y, z) -> (z, y, -x); habitat (0.75 + z, y, 0.3 - x) -> ours (0.75 + z, x - 0.3, y):
    # a yaw of +90 deg about our +Z through the hinge (0.75, -0.3)
    assert _same_points(_placed(c90), np.stack([0.75 + v[:, 2], v[:, 0] - 0.3, v[:, 1]], axis=1))
    # the free edge (x = 0.6) went from (1.35, -0.3) to (0.75, 0.3)
    tip = _placed(c90)[np.isclose(v[:, 0], 0.6)]
    np.testing.assert_allclose(tip[:, :2].mean(axis=0), [0.75, 0.3], atol=1e-9)


def test_visual_origin_roll_and_yaw(tmp_path):
    d = tmp_path / "rpy"
    write_glb(d / "drawer.glb", DRAWER)
    (d / "rpy.urdf").write_text(
        '<robot name="rpy"><link name="l"><visual>'
        '<origin xyz="0.1 0.2 0.3" rpy="1.5707963267948966 0 1.5707963267948966"/>'
        '<geometry><mesh filename="drawer.glb"/></geometry></visual></link></robot>')
    (vis,) = urdf_visuals(d / "rpy.urdf")
    v = DRAWER.vertices
    # R = Rz(90) Ry(0) Rx(90): Rx(90) (x, y, z) -> (x, -z, y), then Rz(90) (x, y, z) -> (-y, x, z): together (z, x, y)
    # habitat (z + 0.1, x + 0.2, y + 0.3) -> ours (z + 0.1, -y - 0.3, x + 0.2)
    assert _same_points(_placed(vis), np.stack([v[:, 2] + 0.1, -v[:, 1] - 0.3, v[:, 0] + 0.2], axis=1))


def test_urdf_geometry_and_asset(tmp_path, counter):
    m = urdf_geometry(tmp_path, "replicacad-urdf:urdf/test_counter/test_counter.urdf")
    # union: body x [-0.75, 0.75], y [-0.3, 0.3], z [0, 0.9]; drawer y down to -0.35
    np.testing.assert_allclose(m.bounds, [[-0.75, -0.35, 0.0], [0.75, 0.3, 0.9]], atol=1e-9)
    assert len(m.faces) == len(BODY.faces) + len(DRAWER.faces)
    m = urdf_geometry(tmp_path, "replicacad-urdf:urdf/test_counter/test_counter.urdf", {"slide": 0.3})
    np.testing.assert_allclose(m.bounds[0], [-0.75, -0.65, 0.0], atol=1e-9)
    with pytest.raises(UnknownNameError, match="ghost"):
        urdf_visuals(counter, {"ghost": 1.0})
    with pytest.raises(UnknownNameError):
        urdf_geometry(tmp_path, "replicacad:urdf/test_counter/test_counter.urdf")


def test_movable_joint_order(tmp_path):
    d = tmp_path / "order"
    write_glb(d / "body.glb", BODY)
    (d / "order.urdf").write_text(ORDER_URDF)
    # depth first from base, children in joint-name order: a_hinge, m_fixed (no dof), z_slide, then z_slide's child a: b_sub
    assert parse_urdf(d / "order.urdf").movable_joints() == ["a_hinge", "z_slide", "b_sub"]


# --------------------------------------------------------------------------------------------
# load_articulated_instances

C15, S15 = math.cos(math.radians(15)), math.sin(math.radians(15))


def _scene(tmp_path, instances) -> tuple[Path, dict]:
    sp = tmp_path / "configs" / "scenes" / "t.scene_instance.json"
    sp.parent.mkdir(parents=True, exist_ok=True)
    doc = {"stage_instance": {"template_name": "stages/x"}, "articulated_object_instances": instances}
    sp.write_text(json.dumps(doc))
    return sp, doc


def _world_vertices(obj) -> np.ndarray:
    """All link vertices in the world, by hand: local (hand formulas, times the scale) -> Rz(yaw) + position."""
    q = obj.params["joint_state"]["slide"]
    local = np.vstack([_body_expected(BODY.vertices), _drawer_expected(DRAWER.vertices, q)]) * np.asarray(obj.scale)
    return local @ geo.rot_z(obj.yaw).T + np.asarray(obj.position)


def _check_box_tight(obj, pts):
    box = object_box(obj)
    d = (pts - np.asarray(box.center)) @ geo.rot_z(box.yaw)  # into the box frame
    half = np.asarray(box.size) / 2.0
    assert np.all(np.abs(d) <= half + 1e-3)  # contains every vertex (1 mm)
    np.testing.assert_allclose(d.max(axis=0), half, atol=1e-3)  # every face touched
    np.testing.assert_allclose(d.min(axis=0), -half, atol=1e-3)


def test_load_instance_pose_box_and_params(tmp_path, counter):
    sp, doc = _scene(tmp_path, [
        # 30 deg about habitat +Y = a yaw of +30 deg about our +Z; translation (1, 0, -2) -> ours (1, 2, 0)
        {"template_name": "test_counter", "translation": [1.0, 0.0, -2.0], "rotation": [C15, 0.0, S15, 0.0],
         "fixed_base": True, "motion_type": "STATIC", "translation_origin": "COM"},
        # uniform scale 2, drawer pulled 0.3 m (habitat's scaled metres) = 0.15 m of the unscaled model
        {"template_name": "test_counter", "translation": [0.0, 0.0, 0.0], "uniform_scale": 2.0,
         "initial_joint_pose": [0.3]},
    ])
    objs = load_articulated_instances(tmp_path, sp, doc, 7, CLASSES)
    a, b = objs
    assert (a.id, b.id) == (7, 8)
    assert a.cls == "kitchen_counter" and a.asset == "replicacad-urdf:urdf/test_counter/test_counter.urdf"
    assert a.movable is False and a.support == "floor"
    assert a.params["template"] == "test_counter" and a.params["articulated"] is True
    assert a.params["links"] == ["body", "drawer"] and a.params["joint_state"] == {"slide": 0.0}
    # the translation places the root link; translation_origin COM is not applied to articulated objects
    np.testing.assert_allclose(a.position, [1.0, 2.0, 0.0], atol=1e-9)
    np.testing.assert_allclose(a.rotation, [C15, 0.0, 0.0, S15], atol=1e-8)
    assert math.isclose(a.yaw, math.radians(30), abs_tol=1e-7)
    # local box: x [-0.75, 0.75], y [-0.35, 0.3], z [0, 0.9]
    np.testing.assert_allclose(a.size, [1.5, 0.65, 0.9], atol=1e-9)
    np.testing.assert_allclose(a.box_offset, [0.0, -0.025, 0.45], atol=1e-9)
    _check_box_tight(a, _world_vertices(a))

    assert b.params["joint_state"] == {"slide": 0.15}
    np.testing.assert_allclose(b.scale, [2.0, 2.0, 2.0])
    # unscaled: drawer y [-0.35 - 0.15, 0.15 - 0.15] -> union y [-0.5, 0.3]; times 2
    np.testing.assert_allclose(b.size, [3.0, 1.6, 1.8], atol=1e-9)
    np.testing.assert_allclose(b.box_offset, [0.0, -0.2, 0.9], atol=1e-9)
    _check_box_tight(b, _world_vertices(b))


def test_initial_joint_pose_order_and_dict(tmp_path):
    d = tmp_path / "urdf" / "order"
    write_glb(d / "body.glb", BODY)
    (d / "order.urdf").write_text(ORDER_URDF)
    classes = parse_class_table({"classes": {"cabinet": {"id": 1, "support": "floor", "movable": False}},
                                 "replicacad": {"aliases": {"order": "cabinet"}}}, "<t>")
    sp, doc = _scene(tmp_path, [
        {"template_name": "order", "initial_joint_pose": [0.1, 0.2, 0.3, 0.4]},  # 4th value: no such dof, dropped
        {"template_name": "order", "initial_joint_pose": {"001": 0.2, "000": 0.1}},  # values in sorted-key order
    ])
    a, b = load_articulated_instances(tmp_path, sp, doc, 1, classes)
    assert a.params["joint_state"] == {"a_hinge": 0.1, "z_slide": 0.2, "b_sub": 0.3}
    assert b.params["joint_state"] == {"a_hinge": 0.1, "z_slide": 0.2, "b_sub": 0.0}


def test_find_urdf_layouts(tmp_path):
    # the distributed layout: urdf/<folder>/<name>.urdf with a folder name unlike the file name
    p = _counter_dir(tmp_path / "urdf" / "kitchen_cupboards", name="kitchenCupboard_01")
    assert find_urdf(tmp_path, "kitchenCupboard_01") == p
    # a dataset config naming another folder
    q = _counter_dir(tmp_path / "arts" / "x", name="fridge")
    (tmp_path / "d.scene_dataset_config.json").write_text(json.dumps({"articulated_objects": {"paths": {".urdf": ["arts/*/"]}}}))
    assert find_urdf(tmp_path, "fridge") == q
    assert find_urdf(tmp_path, "door") is None


def test_ao_config(tmp_path):
    # the config names a URDF with another file name, and scales the template by 2
    _counter_dir(tmp_path / "urdf" / "test_counter", name="model")
    cfg = tmp_path / "urdf" / "test_counter" / "test_counter.ao_config.json"
    cfg.write_text(json.dumps({"urdf_filepath": "model.urdf", "uniform_scale": 2.0}))
    sp, doc = _scene(tmp_path, [{"template_name": "test_counter", "uniform_scale": 1.5}])
    (o,) = load_articulated_instances(tmp_path, sp, doc, 1, CLASSES)
    assert o.asset == "replicacad-urdf:urdf/test_counter/model.urdf"
    # scale 2 * 1.5 = 3: local box x [-0.75, 0.75], y [-0.35, 0.3], z [0, 0.9] times 3
    np.testing.assert_allclose(o.scale, [3.0, 3.0, 3.0])
    np.testing.assert_allclose(o.size, [4.5, 1.95, 2.7], atol=1e-9)
    np.testing.assert_allclose(o.box_offset, [0.0, -0.075, 1.35], atol=1e-9)
    # a link order other than the default is refused when joint positions depend on it
    cfg.write_text(json.dumps({"urdf_filepath": "model.urdf", "link_order": "urdf_order"}))
    sp, doc = _scene(tmp_path, [{"template_name": "test_counter", "initial_joint_pose": [0.1]}])
    with pytest.raises(SceneFormatError) as e:
        load_articulated_instances(tmp_path, sp, doc, 1, CLASSES)
    _err(e, sp, "articulated_object_instances[0].initial_joint_pose")
    for bad, field in (({"urdf_filepath": "nope.urdf"}, "urdf_filepath"), ({"uniform_scale": -1}, "uniform_scale")):
        cfg.write_text(json.dumps(bad))
        with pytest.raises(SceneFormatError) as e:
            load_articulated_instances(tmp_path, sp, doc, 1, CLASSES)
        _err(e, cfg, field)


def test_unknown_and_structure_classes(tmp_path, counter):
    _counter_dir(tmp_path / "urdf" / "zzthing", name="zzthing")
    _counter_dir(tmp_path / "urdf" / "wallthing", name="wallthing")
    sp, doc = _scene(tmp_path, [{"template_name": "zzthing"}, {"template_name": "test_counter"}])
    with pytest.raises(UnknownNameError, match="zzthing"):
        load_articulated_instances(tmp_path, sp, doc, 1, CLASSES)
    objs = load_articulated_instances(tmp_path, sp, doc, 1, CLASSES, allow_unknown=True)
    assert [o.cls for o in objs] == ["other", "kitchen_counter"]
    sp, doc = _scene(tmp_path, [{"template_name": "wallthing"}])
    with pytest.raises(UnknownNameError, match="structure"):
        load_articulated_instances(tmp_path, sp, doc, 1, CLASSES)


# --------------------------------------------------------------------------------------------
# bad input: SceneFormatError, one line, naming the file and the field


def _err(exc_info, file, field):
    msg = str(exc_info.value)
    assert "\n" not in msg
    assert str(file) in msg, msg
    if field:
        assert f": {field}: " in msg, msg


def test_missing_urdf(tmp_path, counter):
    sp, doc = _scene(tmp_path, [{"template_name": "test_counter"}, {"template_name": "no_such_thing"}])
    with pytest.raises(SceneFormatError) as e:
        load_articulated_instances(tmp_path, sp, doc, 1, CLASSES)
    _err(e, sp, "articulated_object_instances[1].template_name")


@pytest.mark.parametrize("field,value", [
    ("translation", [1.0, 2.0]),
    ("rotation", [1.0, 0.0, 0.0]),
    ("uniform_scale", 0.0),
    ("initial_joint_pose", ["a"]),
    ("initial_joint_pose", 0.3),
    ("fixed_base", "yes"),
    ("motion_type", "FLYING"),
    ("translation_origin", "middle"),
])
def test_bad_instance_fields(tmp_path, counter, field, value):
    sp, doc = _scene(tmp_path, [{"template_name": "test_counter", field: value}])
    with pytest.raises(SceneFormatError) as e:
        load_articulated_instances(tmp_path, sp, doc, 1, CLASSES)
    _err(e, sp, f"articulated_object_instances[0].{field}")


@pytest.mark.parametrize("old,new,field", [
    ('filename="meshes/body.glb"', 'filename="meshes/missing.glb"', "link[body].visual[0].mesh"),
    ('filename="meshes/body.glb"', 'filename="package://counter/meshes/body.glb"', "link[body].visual[0].mesh"),
    ('filename="meshes/body.glb"', 'filename="meshes/body.obj"', "link[body].visual[0].mesh"),
    ('<mesh filename="meshes/body.glb" scale="1 2 1"/>', '<box size="1.5 0.9 0.6"/>', "link[body].visual[0].geometry"),
    ('<child link="drawer"/>', '<child link="ghost"/>', "joint[slide].child"),
    ('<parent link="body"/>', '<parent link="ghost"/>', "joint[slide].parent"),
    ('type="prismatic"', 'type="floating"', "joint[slide].type"),
    ('<origin xyz="0.2 0.6 0.1" rpy="0 0 0"/>', '<origin xyz="0.2 abc 0.1"/>', "joint[slide].origin.xyz"),
    ('rpy="0 1.5707963267948966 0"', 'rpy="0 1.57"', "link[drawer].visual[0].origin.rpy"),
    ('scale="1 2 1"', 'scale="1 0 1"', "link[body].visual[0].mesh.scale"),
    ('<axis xyz="0 0 1"/>', '<axis xyz="0 0 0"/>', "joint[slide].axis.xyz"),
    ('<parent link="body"/>', '<parent link="drawer"/>', "joint[slide].child"),  # a link its own parent
    ('</robot>', '<joint name="back" type="fixed"><parent link="drawer"/><child link="body"/></joint></robot>', "robot"),
    ('</robot>', '<link name="loose"/></robot>', "robot"),  # several roots
    ('</robot>', '<link name="loose"/><link name="c2"/>'
                 '<joint name="j1" type="fixed"><parent link="c2"/><child link="loose"/></joint>'
                 '<joint name="j2" type="fixed"><parent link="loose"/><child link="c2"/></joint></robot>', "robot"),
])
def test_bad_urdf(tmp_path, old, new, field):
    assert old in URDF
    p = _counter_dir(tmp_path / "urdf" / "test_counter", URDF.replace(old, new, 1))
    with pytest.raises(SceneFormatError) as e:
        urdf_visuals(p)
    _err(e, p.resolve(), field)
    # and through the scene loader too
    sp, doc = _scene(tmp_path, [{"template_name": "test_counter"}])
    with pytest.raises(SceneFormatError) as e:
        load_articulated_instances(tmp_path, sp, doc, 1, CLASSES)
    _err(e, p.resolve(), field)


def test_cycle_messages(tmp_path):
    p = _counter_dir(tmp_path / "c", URDF.replace(
        "</robot>", '<joint name="back" type="fixed"><parent link="drawer"/><child link="body"/></joint></robot>'))
    with pytest.raises(SceneFormatError, match="cycle"):
        urdf_visuals(p)
    p = _counter_dir(tmp_path / "r", URDF.replace("</robot>", '<link name="loose"/></robot>'))
    with pytest.raises(SceneFormatError, match="several root links"):
        urdf_visuals(p)


def test_malformed_xml(tmp_path):
    p = _counter_dir(tmp_path / "urdf" / "test_counter", URDF[: URDF.index("<joint")])
    with pytest.raises(SceneFormatError, match="malformed XML") as e:
        urdf_visuals(p)
    _err(e, p.resolve(), None)
