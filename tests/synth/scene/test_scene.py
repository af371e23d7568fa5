"""Scene model: file round trips, ground-truth boxes against hand-computed values, bad input."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
import yaml

from vrformats.camera import wrap_angle
from vrformats.errors import SceneFormatError, UnknownNameError
from synth.scene import geometry as geo
from synth.cli import main as synth_main
from synth.scene.model import (
    FLOOR_ID_BASE,
    WALL_ID_BASE,
    Layout,
    ObjectInstance,
    Room,
    Stage,
    Wall,
    boxes_document,
    layout_from_dict,
    layout_to_dict,
    load_layout,
    object_box,
    save_layout,
    structure_boxes,
)


def small_layout() -> Layout:
    stage = Stage(
        ceiling_height=2.5,
        rooms=[Room("a", "living", (0.1, 0.1, 3.95, 2.9))],
        walls=[Wall("W0", (0.0, 0.0), (4.0, 0.0), 0.2, 2.5), Wall("W1", (4.0, 0.0), (4.0, 3.0), 0.1, 2.5)],
    )
    objs = [
        ObjectInstance(1, "coffee_table", "proc:coffee_table", (1.0, 2.0, 0.0), geo.yaw_to_quat(math.pi / 2),
                       (2.0, 1.0, 0.5), (0.0, 0.0, 0.25), params={"legs": "square", "n": 4}),
        ObjectInstance(2, "bowl", "proc:bowl", (1.0, 2.0, 0.5), geo.yaw_to_quat(0.3), (0.2, 0.2, 0.08), (0.0, 0.0, 0.04),
                       support="object:1:0"),
    ]
    return Layout("tiny", stage, objs, seed=3, meta={"note": "test"})


def test_round_trip_exact(tmp_path):
    lay = small_layout()
    p = save_layout(lay, tmp_path / "tiny.yaml")
    back = load_layout(p)
    assert layout_to_dict(back) == layout_to_dict(lay)
    p2 = save_layout(back, tmp_path / "tiny2.yaml")
    assert p.read_bytes() == p2.read_bytes()
    # human-editable: YAML with one block per object, vectors inline
    text = p.read_text()
    assert "position: [1.0, 2.0, 0.0]" in text


def test_builtin_layout_round_trips(tmp_path):
    lay = load_layout("apt_0")
    p = save_layout(lay, tmp_path / "apt_0.yaml")
    from synth.resources import layouts_dir

    assert p.read_bytes() == (layouts_dir() / "apt_0.yaml").read_bytes()


def test_yaw_deg_shorthand_is_accepted():
    doc = layout_to_dict(small_layout())
    del doc["objects"][0]["rotation"]
    doc["objects"][0]["yaw_deg"] = 90.0
    lay = layout_from_dict(doc)
    assert lay.objects[0].yaw == pytest.approx(math.pi / 2)


def test_object_box_yaw_only_against_hand_values():
    b = object_box(small_layout().objects[0])
    assert b.center == pytest.approx((1.0, 2.0, 0.25))
    assert b.size == pytest.approx((2.0, 1.0, 0.5))
    assert b.yaw == pytest.approx(math.pi / 2)
    # rotated by 90 deg the 2 m side runs along world y: footprint x in [0.5, 1.5], y in [1, 3]
    c = b.corners_2d()
    assert c[:, 0].min() == pytest.approx(0.5) and c[:, 0].max() == pytest.approx(1.5)
    assert c[:, 1].min() == pytest.approx(1.0) and c[:, 1].max() == pytest.approx(3.0)


def test_object_box_tilted_object():
    # a box lying on its side: 90 deg about +x maps local y -> world z and local z -> world -y
    q = (math.cos(math.pi / 4), math.sin(math.pi / 4), 0.0, 0.0)
    o = ObjectInstance(5, "book", "proc:book", (0.0, 0.0, 1.0), q, (0.3, 0.2, 0.04), (0.0, 0.0, 0.02))
    b = object_box(o)
    # local box x in [-.15,.15], y in [-.1,.1], z in [0,.04] -> world x same, y = -z in [-.04, 0], z = 1 + y in [.9, 1.1]
    assert b.yaw == pytest.approx(0.0, abs=1e-9)
    assert b.size == pytest.approx((0.3, 0.04, 0.2))
    assert b.center == pytest.approx((0.0, -0.02, 1.0))


def test_structure_boxes_against_hand_values():
    lay = small_layout()
    boxes = {b.id: b for b in structure_boxes(lay.stage)}
    w0 = boxes[WALL_ID_BASE]
    assert (w0.cls, w0.kind) == ("wall", "wall")
    assert w0.center == pytest.approx((2.0, 0.0, 1.25)) and w0.size == pytest.approx((4.0, 0.2, 2.5)) and w0.yaw == 0.0
    w1 = boxes[WALL_ID_BASE + 1]
    assert w1.center == pytest.approx((4.0, 1.5, 1.25)) and w1.yaw == pytest.approx(math.pi / 2)
    fl = boxes[FLOOR_ID_BASE]
    assert fl.cls == "floor" and fl.zmax == pytest.approx(0.0)
    assert fl.size[:2] == pytest.approx((3.85, 2.8))


def test_export_boxes_cli(tmp_path, capsys):
    out = tmp_path / "boxes.json"
    assert synth_main(["scene", "export-boxes", "apt_0", "--out", str(out)]) == 0
    doc = json.loads(out.read_text())
    lay = load_layout("apt_0")
    assert doc["format"] == "videoreloc-boxes/1"
    n_struct = len(lay.stage.walls) + 2 * len(lay.stage.rooms)
    assert len(doc["boxes"]) == len(lay.objects) + n_struct
    ids = [b["id"] for b in doc["boxes"]]
    assert len(set(ids)) == len(ids)
    # every box of an object equals object_box of that object
    by_id = {b["id"]: b for b in doc["boxes"]}
    for o in lay.objects:
        assert by_id[o.id]["center"] == pytest.approx(list(object_box(o).center))
        assert by_id[o.id]["class"] == o.cls
    assert set(doc["classes"]) >= {"wall", "floor", "ceiling", "chair"}


def test_boxes_document_size_is_small():
    doc = boxes_document(load_layout("apt_0"))
    assert len(json.dumps(doc)) < 150_000


# ---- bad input --------------------------------------------------------------------------------


def _write(tmp_path, doc, name="bad.yaml"):
    p = tmp_path / name
    p.write_text(yaml.safe_dump(doc))
    return p


@pytest.mark.parametrize(
    "mutate, field",
    [
        (lambda d: d["objects"][0].update(position=[1, "abc", 0]), "objects[0].position[1]"),
        (lambda d: d["objects"][0].update(position=[1, 2]), "objects[0].position"),
        (lambda d: d["objects"][1].update(rotation=[1, 1, 1, 1]), "objects[1].rotation"),
        (lambda d: d["objects"][0].update(size=[1, 0, 1]), "objects[0].size[1]"),
        (lambda d: d["objects"][1].update(id=1), "objects[1].id"),
        (lambda d: d["objects"][0].update(colour="red"), "objects[0]"),
        (lambda d: d["objects"][1].update(support="object:77:0"), "objects[1].support"),
        (lambda d: d["objects"][1].update(support="shelf"), "objects[1].support"),
        (lambda d: d["stage"]["walls"][0].update(thickness=-1), "stage.walls[0].thickness"),
        (lambda d: d["stage"]["rooms"][0].update(rect=[3, 0, 1, 1]), "stage.rooms[0].rect"),
        (lambda d: d["stage"].pop("ceiling_height"), "stage"),
        (lambda d: d.update(format="other/2"), "format"),
    ],
)
def test_malformed_field_names_file_and_field(tmp_path, mutate, field):
    doc = layout_to_dict(small_layout())
    mutate(doc)
    p = _write(tmp_path, doc)
    with pytest.raises(SceneFormatError) as e:
        load_layout(p)
    assert str(e.value).startswith(f"{p}: {field}")


def test_unknown_class_is_named(tmp_path):
    doc = layout_to_dict(small_layout())
    doc["objects"][0]["class"] = "sofaa"
    with pytest.raises(SceneFormatError, match="unknown object class 'sofaa'"):
        load_layout(_write(tmp_path, doc))


def test_unknown_asset_is_named(tmp_path):
    doc = layout_to_dict(small_layout())
    doc["objects"][0]["asset"] = "proc:sofaa"
    with pytest.raises(SceneFormatError, match="objects\\[0\\].asset: unknown procedural asset 'sofaa'"):
        load_layout(_write(tmp_path, doc))
    doc["objects"][0]["asset"] = "http://example/sofa.glb"
    with pytest.raises(SceneFormatError, match="objects\\[0\\].asset: expected"):
        load_layout(_write(tmp_path, doc))


def test_malformed_yaml_and_missing_file_exit_2(tmp_path, capsys):
    p = tmp_path / "broken.yaml"
    p.write_text("name: x\nstage: [unclosed\n")
    assert synth_main(["scene", "check", str(p)]) == 2
    err = capsys.readouterr().err
    assert err.startswith("synth: error: ") and str(p) in err and "malformed YAML" in err
    assert len(err.strip().splitlines()) == 1
    assert synth_main(["scene", "show", str(tmp_path / "nope.yaml")]) == 2
    assert "file not found" in capsys.readouterr().err
    assert synth_main(["scene", "show", "apt_99"]) == 2
    err = capsys.readouterr().err
    assert "unknown layout 'apt_99'" in err and "apt_0" in err


def test_unknown_class_lookup_names_it():
    from synth.scene.classes import class_table

    with pytest.raises(UnknownNameError, match="'lamp_post'"):
        class_table().get("lamp_post")


def test_geometry_quaternion_round_trip():
    rng = np.random.default_rng(0)
    for _ in range(50):
        q = rng.normal(size=4)
        q /= np.linalg.norm(q)
        if q[0] < 0:
            q = -q
        R = geo.quat_to_matrix(q)
        assert np.allclose(R @ R.T, np.eye(3), atol=1e-12)
        assert np.allclose(geo.matrix_to_quat(R), q, atol=1e-9)


def test_wrap_angle_range_is_minus_pi_exclusive_to_pi_inclusive():
    """vrformats.camera.wrap_angle, the one wrap (layout yaws): (-pi, pi], so half a turn is always
    +pi whichever way it was reached, and the old scalar code's values are kept bit for bit."""
    pi = math.pi
    assert wrap_angle(pi) == pi and wrap_angle(-pi) == pi
    assert wrap_angle(3 * pi) == pi and wrap_angle(-3 * pi) == pi
    assert wrap_angle(0.0) == 0.0 and wrap_angle(2 * pi) == 0.0
    assert isinstance(wrap_angle(1.0), float) and isinstance(wrap_angle(np.float64(1.0)), float)
    a = np.array([pi, -pi, 3 * pi, -3 * pi, 0.0, 2 * pi, 1.0, -1.0, 7.5, -7.5])
    got = wrap_angle(a)
    assert isinstance(got, np.ndarray) and got.shape == a.shape
    assert got[:4].tolist() == [pi] * 4 and ((got > -pi) & (got <= pi)).all()
    assert np.allclose(np.cos(got), np.cos(a)) and np.allclose(np.sin(got), np.sin(a))

    def old(x):  # the layout code's scalar wrap before it moved here
        x = math.fmod(x + pi, 2 * pi)
        if x <= 0:
            x += 2 * pi
        return x - pi

    rng = np.random.default_rng(0)
    xs = list(rng.uniform(-20, 20, 2000)) + [pi, -pi, 3 * pi, -3 * pi, 1e-300, -1e-300]
    assert [wrap_angle(float(x)) for x in xs] == [old(float(x)) for x in xs]
    assert wrap_angle(np.array(xs)).tolist() == [old(float(x)) for x in xs]
    assert wrap_angle(np.array(xs).reshape(-1, 2)).shape == (len(xs) // 2, 2)


def test_boxes_overlap_is_symmetric_and_respects_touching():
    a = geo.OrientedBox(1, "x", (0, 0, 0.5), (1, 1, 1), 0.0)
    b = geo.OrientedBox(2, "x", (1.0, 0, 0.5), (1, 1, 1), 0.0)  # touching faces
    # along (1,1)/sqrt2: a reaches 0.707, c starts at 0.7*sqrt2 - 0.5 = 0.49: overlap; at (0.9, 0.9) it starts at 0.77: apart
    c = geo.OrientedBox(3, "x", (0.7, 0.7, 0.5), (1, 1, 1), math.pi / 4)
    assert not geo.boxes_overlap(a, geo.OrientedBox(5, "x", (0.9, 0.9, 0.5), (1, 1, 1), math.pi / 4))
    assert not geo.boxes_overlap(a, b) and not geo.boxes_overlap(b, a)
    assert geo.boxes_overlap(a, c) and geo.boxes_overlap(c, a)
    d = geo.OrientedBox(4, "x", (0, 0, 1.5), (1, 1, 1), 0.3)  # stacked on top
    assert not geo.boxes_overlap(a, d)
