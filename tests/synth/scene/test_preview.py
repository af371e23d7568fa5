"""Top-down layout previews (synth.scene.preview): files, pixel sizes, diffs, degenerate layouts."""

from __future__ import annotations

import math
from dataclasses import replace

import matplotlib.image as mpimg
import numpy as np
import pytest

from vrformats.errors import UserError
from synth.scene import geometry as geo
from synth.scene.classes import class_table
from synth.scene.preview import class_color, diff_layouts, figure_size, plot_layout
from synth.scene.model import Layout, ObjectInstance, Opening, Room, Stage, Wall



DPI = 60


def _obj(oid, cls, x, y, yaw_deg=0.0, size=(0.5, 0.5, 0.5), z=0.0, support="floor", box_offset=None):
    return ObjectInstance(
        id=oid, cls=cls, asset=f"proc:{cls}", position=(x, y, z), rotation=geo.yaw_to_quat(math.radians(yaw_deg)),
        size=size, box_offset=box_offset or (0.0, 0.0, size[2] / 2.0), support=support,
    )


def _stage() -> Stage:
    t = 0.1
    walls = [
        Wall("south", (0.0, 0.0), (7.0, 0.0), t, 2.5),
        Wall("east", (7.0, 0.0), (7.0, 3.0), t, 2.5),
        Wall("north", (7.0, 3.0), (0.0, 3.0), t, 2.5),
        Wall("west", (0.0, 3.0), (0.0, 0.0), t, 2.5),
        Wall("mid", (4.0, 0.0), (4.0, 3.0), t, 2.5),
    ]
    rooms = [Room("living", "living", (0.05, 0.05, 3.95, 2.95)), Room("kitchen", "kitchen", (4.05, 0.05, 6.95, 2.95))]
    openings = [
        Opening("door_1", "door", "mid", 1.5, 0.8, 0.0, 2.0, ("kitchen", "living")),
        Opening("window_1", "window", "south", 2.0, 1.0, 0.9, 1.2),
    ]
    return Stage(ceiling_height=2.5, rooms=rooms, walls=walls, openings=openings)


def _layout() -> Layout:
    objects = [
        _obj(1, "sofa", 1.5, 2.45, 180, (2.0, 0.9, 0.85)),
        _obj(2, "coffee_table", 1.5, 1.2, 0, (1.0, 0.6, 0.45)),
        _obj(3, "dining_table", 5.5, 1.5, 90, (1.4, 0.8, 0.75)),
        _obj(4, "chair", 4.8, 1.5, -90, (0.45, 0.5, 0.9)),
        _obj(5, "bowl", 5.5, 1.5, 0, (0.3, 0.3, 0.1), z=0.75, support="object:3:0"),
        _obj(6, "plant", 0.4, 0.4, 0, (0.4, 0.4, 1.2)),
    ]
    return Layout("two_rooms", _stage(), objects)


def _variant(ref: Layout) -> Layout:
    by = ref.by_id()
    objs = []
    for o in ref.objects:
        if o.id == 4:  # removed: the chair
            continue
        if o.id == 6:  # moved by (1.6, 1.2) -> 2.0 m
            o = replace(o, position=(2.0, 1.6, 0.0))
        if o.id == 2:  # nudged 5 cm: below the threshold
            o = replace(o, position=(1.55, 1.2, 0.0))
        if o.id == 1:  # turned in place about its box centre: not moved
            o = replace(o, rotation=geo.yaw_to_quat(math.radians(175)))
        objs.append(o)
    objs.append(_obj(7, "stool", 6.3, 2.4, 0, (0.35, 0.35, 0.65)))  # added
    assert by[4].cls == "chair"
    return Layout("two_rooms_v1", ref.stage, objs, reference=ref.name)


def _read(path):
    img = mpimg.imread(str(path))
    assert img.ndim == 3 and img.shape[2] in (3, 4)
    return img


def _has_color(img, hex_color: str, tol: float = 0.02) -> bool:
    rgb = np.array([int(hex_color[i : i + 2], 16) / 255.0 for i in (1, 3, 5)])
    return bool((np.abs(img[..., :3] - rgb).max(axis=-1) <= tol).any())


# --------------------------------------------------------------------------------------------


def test_plot_layout_writes_png_of_expected_size(tmp_path):
    lay = _layout()
    out = tmp_path / "new" / "folder" / "plan.png"
    got = plot_layout(lay, out, dpi=DPI)
    assert got == out and out.is_file() and out.stat().st_size > 1000
    assert sorted(p.name for p in out.parent.iterdir()) == ["plan.png"]  # no temporary file left
    img = _read(out)
    w, h = figure_size(lay, dpi=DPI)
    assert img.shape[:2] == (h, w)
    # a 7 m x 3 m plan: wider than tall, a few inches at most
    assert w > h and 4 * DPI < w < 25 * DPI and 2 * DPI < h < 15 * DPI
    # pixel size scales with dpi
    w2, h2 = figure_size(lay, dpi=2 * DPI)
    assert abs(w2 - 2 * w) <= 1 and abs(h2 - 2 * h) <= 1
    # objects are filled with their class colour, walls are drawn
    for cls in ("sofa", "dining_table", "plant"):
        assert _has_color(img, class_color(cls)), cls
    assert _has_color(img, "#333333")


def test_plot_layout_without_labels_and_other_formats(tmp_path):
    lay = _layout()
    plot_layout(lay, tmp_path / "a.png", labels=False, title="custom title", dpi=DPI)
    assert _read(tmp_path / "a.png").shape[:2] == figure_size(lay, dpi=DPI)[::-1]
    plot_layout(lay, tmp_path / "a.svg", dpi=DPI)
    assert b"<svg" in (tmp_path / "a.svg").read_bytes()[:2000]
    plot_layout(lay, tmp_path / "a.pdf", dpi=DPI)
    assert (tmp_path / "a.pdf").read_bytes().startswith(b"%PDF")
    with pytest.raises(UserError):
        plot_layout(lay, tmp_path / "a.notaformat", dpi=DPI)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a.pdf", "a.png", "a.svg"]


def test_diff_layouts_by_hand():
    ref = _layout()
    var = _variant(ref)
    d = diff_layouts(ref, var)
    assert set(d) == {"moved", "added", "removed"}
    assert d["added"] == [7]
    assert d["removed"] == [4]
    assert [m[0] for m in d["moved"]] == [6]
    oid, a, b, dist = d["moved"][0]
    assert a == pytest.approx((0.4, 0.4, 0.6)) and b == pytest.approx((2.0, 1.6, 0.6))
    assert dist == pytest.approx(2.0)  # 3-4-5 triangle: (1.6, 1.2)
    # a lower threshold also lists the 5 cm nudge of the coffee table
    d2 = diff_layouts(ref, var, moved_threshold=0.01)
    assert [(m[0], round(m[3], 6)) for m in d2["moved"]] == [(2, 0.05), (6, 2.0)]
    # identical layouts: nothing
    assert diff_layouts(ref, ref) == {"moved": [], "added": [], "removed": []}


def test_diff_uses_box_centres():
    # turning an object about its origin moves its box when the box is off-centre
    a = Layout("a", Stage(2.5), [_obj(1, "desk", 0.0, 0.0, 0, (1.2, 0.6, 0.75), box_offset=(0.2, 0.0, 0.375))])
    b = Layout("b", Stage(2.5), [_obj(1, "desk", 0.0, 0.0, 180, (1.2, 0.6, 0.75), box_offset=(0.2, 0.0, 0.375))])
    (oid, p, q, dist), = diff_layouts(a, b)["moved"]
    assert oid == 1 and p == pytest.approx((0.2, 0.0, 0.375)) and q == pytest.approx((-0.2, 0.0, 0.375), abs=1e-9)
    assert dist == pytest.approx(0.4)


def test_plot_diff(tmp_path):
    ref = _layout()
    var = _variant(ref)
    out = plot_layout(var, tmp_path / "diff.png", ref=ref, dpi=DPI)
    img = _read(out)
    assert img.shape[:2] == figure_size(var, ref=ref, dpi=DPI)[::-1]
    # added objects are outlined green, removed ones red, moves drawn in purple
    assert _has_color(img, "#1a9850", tol=0.05)
    assert _has_color(img, "#d73027", tol=0.05)
    assert _has_color(img, "#5e3c99", tol=0.05)
    # the stool (added) is drawn in the variant, the chair (removed) is not filled
    assert _has_color(img, class_color("stool"))
    assert not _has_color(img, class_color("chair"), tol=0.005)


def test_plot_without_rooms_or_walls(tmp_path):
    tilted = geo.matrix_to_quat(geo.rot_z(0.4) @ np.array([[1.0, 0, 0], [0, 0, -1], [0, 1, 0]]))
    objs = [
        _obj(1, "sofa", -2.0, 1.0, 30, (2.0, 0.9, 0.8)),
        _obj(2, "chair", 1.0, -1.5, 200, (0.45, 0.5, 0.9)),
        replace(_obj(3, "book", 0.5, 0.5, 0, (0.2, 0.15, 0.04)), rotation=tilted),
        _obj(4, "ceiling_light", 0.0, 0.0, 0, (0.4, 0.4, 0.1), z=2.5, support="ceiling"),
    ]
    lay = Layout("replicacad_like", Stage(2.7, asset="replicacad:stages/frl_apartment_stage.glb"), objs)
    out = plot_layout(lay, tmp_path / "rc.png", dpi=DPI)
    img = _read(out)
    assert img.shape[:2] == figure_size(lay, dpi=DPI)[::-1]
    assert _has_color(img, class_color("sofa"))


def test_plot_empty_layouts(tmp_path):
    empty = Layout("empty", Stage(2.5))
    img = _read(plot_layout(empty, tmp_path / "empty.png", dpi=DPI))
    assert img.shape[:2] == figure_size(empty, dpi=DPI)[::-1]
    # an empty variant of a furnished reference: everything removed
    ref = _layout()
    gone = Layout("gone", ref.stage, [])
    assert diff_layouts(ref, gone)["removed"] == [1, 2, 3, 4, 5, 6]
    img = _read(plot_layout(gone, tmp_path / "gone.png", ref=ref, dpi=DPI))
    assert _has_color(img, "#d73027", tol=0.05)


def test_class_colors_stable_and_distinct():
    names = class_table().object_classes()
    colors = [class_color(c) for c in names]
    assert len(set(colors)) == len(names)
    assert class_color("sofa") == class_color("sofa")
    assert class_color("not_a_class_xyz") == class_color("not_a_class_xyz")
