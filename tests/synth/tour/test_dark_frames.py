"""`synth tour check` fails a lit tour whose RGB frames are nearly black (issue 25, item 7).

A scene lit only through windows that it does not have (a stand-in stage without openings), or a
night preset without lamps, renders black; the check must say so, not a person looking at frames.
The tours here are written by hand with the format layer: a camera sliding sideways in front of a
flat wall 3 m away (planar depth 3 m on every pixel, instance id 1000 = the wall), RGB a smooth
pattern scaled to a chosen brightness. No Blender.
"""

from __future__ import annotations


import numpy as np
import pytest

from vrformats import camera as cam
from vrformats.tour import tonemap
from conftest import make_tour
from synth.cli import main as synth_main
from synth.tour.check import DARK_P99_LUMINANCE, check_tour, format_report, frame_brightness

W, H = 48, 36
INTR = cam.Intrinsics.from_fov(W, H, 70.0)
FPS = 30.0
N = 6
WALL_ID, WALL_CLASS = 1000, 1
# OpenCV camera looking along world +x: right = -y, down = -z, forward = +x
R = np.array([[0.0, 0.0, 1.0], [-1.0, 0.0, 0.0], [0.0, -1.0, 0.0]])
LUM = np.array([0.2126, 0.7152, 0.0722])


def pattern() -> np.ndarray:
    """Linear RGB in [0.2, 1] (a warm gradient with a checker), 99th-percentile luminance about 0.9."""
    v, u = np.mgrid[0:H, 0:W].astype(np.float32)
    check = ((u // 6 + v // 6) % 2)[..., None]
    base = np.stack([0.9 - 0.3 * v / H, 0.8 - 0.2 * u / W, 0.6 + 0.0 * u], axis=-1)
    return (base * (0.35 + 0.65 * check)).astype(np.float32)


def wall_tour(root, levels, lighting="night"):
    """A tour whose frame k has RGB = pattern() * levels[k] (None: no RGB, geometry only); returns root."""
    poses, frames = [], {}
    for k, level in enumerate(levels):
        T = np.eye(4)
        T[:3, :3] = R
        T[:3, 3] = [0.0, 0.15 * k, 1.5]
        poses.append(T)
        frames[k] = dict(rgb=None if level is None else pattern() * np.float32(level),
                         depth=np.full((H, W), 3.0, np.float32), instance=np.full((H, W), WALL_ID, np.uint32),
                         semantic=np.full((H, W), WALL_CLASS, np.uint32))
    objects = {"format": "videoreloc-boxes/1", "layout": "flatwall", "frame": "world: right-handed, Z up, metres",
               "classes": {"wall": WALL_CLASS},
               "boxes": [{"id": WALL_ID, "class": "wall", "kind": "wall", "center": [3.1, 0.0, 1.3],
                          "size": [0.2, 20.0, 2.6], "yaw": 0.0, "movable": False}]}
    lit = any(x is not None for x in levels)
    return make_tour(root, poses, frames, intrinsics=INTR, fps=FPS, objects=objects, layout="flatwall",
                     lighting=lighting if lit else None, path="slide", renderer="test")


def dark_lines(rep):
    return [p for p in rep["problems"] if "nearly black" in p]


def test_normally_lit_tour_passes_with_its_brightness_reported(tmp_path):
    rep = check_tour(wall_tour(tmp_path / "flatwall__day__slide", [1.0] * N, lighting="day"), progress=False)
    assert rep["ok"], rep["problems"]
    b = rep["brightness"]
    assert b["rgb_frames"] == N and not b["dark"] and b["threshold"] == DARK_P99_LUMINANCE
    # the pattern's 99th-percentile luminance, from the pattern itself (frames are stored as half floats)
    want = float(np.percentile(pattern().reshape(-1, 3) @ LUM, 99))
    assert b["median_p99_luminance"] == pytest.approx(want, rel=2e-3)
    assert "brightness: 99th-percentile luminance" in format_report(rep)


def test_nearly_black_tour_fails_with_one_line_naming_tour_and_lighting(tmp_path, capsys):
    # 1/400 of the normal level: the brightest pixels at about 0.002 linear, 12/255 at exposure 1
    root = wall_tour(tmp_path / "apt_0__night__query", [1.0 / 400] * N, lighting="night")
    rep = check_tour(root, progress=False)
    assert not rep["ok"]
    lines = dark_lines(rep)
    assert len(lines) == 1 and lines == rep["problems"]  # the only problem: the tour is otherwise sound
    assert "apt_0__night__query" in lines[0] and "lighting night" in lines[0] and "\n" not in lines[0]
    assert rep["brightness"]["dark"] and rep["brightness"]["median_p99_luminance"] < DARK_P99_LUMINANCE
    assert rep["problem_counts"] == {"nearly black tours": 1}
    # the command: exit 1, the line printed
    assert synth_main(["tour", "check", str(root)]) == 1
    out = capsys.readouterr().out
    assert "nearly black" in out and "apt_0__night__query" in out and "PROBLEMS FOUND (1)" in out


def test_dark_threshold_is_in_the_readers_exposure_convention():
    # the threshold is linear luminance at exposure 1: tonemap(x, 1.0) shows it as sRGB 25/255 ...
    grey = np.full((4, 4, 3), DARK_P99_LUMINANCE, np.float32)
    img, scale = tonemap(grey, 1.0)
    assert scale == 1.0 and round(float(img[0, 0, 0]) * 255) == 25
    assert frame_brightness(grey) == pytest.approx(DARK_P99_LUMINANCE, rel=1e-6)
    # ... and auto exposure (97th percentile to 0.9) would have to scale such a frame by about 90
    assert tonemap(grey)[1] == pytest.approx(0.9 / DARK_P99_LUMINANCE, rel=1e-5)
    # the 99th percentile: a lamp on under 1 % of the pixels does not make a black frame lit
    spot = np.zeros((100, 100, 3), np.float32)
    spot.reshape(-1, 3)[:50] = 5.0
    assert frame_brightness(spot) == 0.0
    spot.reshape(-1, 3)[:200] = 5.0
    assert frame_brightness(spot) == pytest.approx(5.0)


@pytest.mark.parametrize("scale, dark", [(2.0, False), (0.5, True)])
def test_dark_tour_decided_by_the_threshold(tmp_path, scale, dark):
    """Levels chosen so the tour's median 99th-percentile luminance is the threshold x scale."""
    p99 = float(np.percentile(pattern().reshape(-1, 3) @ LUM, 99))
    rep = check_tour(wall_tour(tmp_path / "t", [DARK_P99_LUMINANCE * scale / p99] * N), progress=False)
    assert rep["brightness"]["dark"] is dark and rep["ok"] is (not dark)
    assert rep["brightness"]["median_p99_luminance"] == pytest.approx(DARK_P99_LUMINANCE * scale, rel=5e-3)


def test_median_over_frames_some_dark_frames_pass_most_fail(tmp_path):
    # a camera facing a dark corner now and then is fine ...
    rep = check_tour(wall_tour(tmp_path / "a", [1.0, 0.001, 1.0, 1.0, 0.001, 1.0]), progress=False)
    assert rep["ok"], rep["problems"]
    assert rep["brightness"]["min_p99_luminance"] < DARK_P99_LUMINANCE
    # ... a tour dark on most of its frames is not
    rep = check_tour(wall_tour(tmp_path / "b", [0.001, 0.001, 1.0, 0.001, 0.001, 1.0]), progress=False)
    assert not rep["ok"] and len(dark_lines(rep)) == 1


def test_geometry_only_tour_has_no_brightness_test(tmp_path):
    rep = check_tour(wall_tour(tmp_path / "g", [None] * N), progress=False)
    assert rep["ok"], rep["problems"]
    assert rep["brightness"] == {"rgb_frames": 0} and "brightness" not in format_report(rep)
