"""Rendering: the Blender camera conventions against an independent renderer, lighting design, the
tour format, geometry shared across lightings, resume, and bad input.

Blender tests use tiny images and few samples; they carry the ``blender`` marker.
"""

from __future__ import annotations

import json
import os

import numpy as np
import OpenEXR
import pytest
from scipy import ndimage

from vrformats import frames as fr
from vrformats.camera import Intrinsics, pose_from_ypr, read_tum, write_tum
from vrformats.tour import Tour
from synth.cli import main as synth_main
from synth.tour.check import check_tour
from synth.render.fast_render import FastRenderer
from synth.paths.files import load_path
from synth.scene.model import load_layout
from synth.tour.render import TourSpec, render_tour



def spread_path(tmp_path, n: int, name: str = "query") -> str:
    """A TUM file with ``n`` poses spread along a shipped camera path (varied views, few frames)."""
    poses = load_path(name).poses
    idx = np.linspace(0, len(poses) - 1, n + 2).round().astype(int)[1:-1]
    f = tmp_path / f"{name}_{n}.txt"
    write_tum(f, poses[idx])
    return str(f)


def depth_edges(depth: np.ndarray, jump: float = 0.05) -> np.ndarray:
    """Pixels next to a depth discontinuity (or to a hole), dilated by one pixel."""
    gx = np.abs(np.diff(depth, axis=1, prepend=depth[:, :1]))
    gy = np.abs(np.diff(depth, axis=0, prepend=depth[:1, :]))
    rel = np.maximum(gx, gy) > jump * np.maximum(depth, 1.0)
    return ndimage.binary_dilation(rel | (depth == 0), iterations=1)


def assert_renders_agree(a, b) -> None:
    """Blender frame ``a`` and fast-renderer frame ``b`` of one view: depth within 1 mm on 99 % of
    the pixels away from depth edges, instance and semantic ids equal on 99 %."""
    away = ~depth_edges(b.depth) & (a.depth > 0) & (b.depth > 0)
    assert away.mean() > 0.5
    close = np.abs(a.depth - b.depth)[away] < 1e-3
    assert close.mean() >= 0.99, (a.index, close.mean())
    assert (a.instance == b.instance).mean() >= 0.99
    assert (a.semantic == b.semantic).mean() >= 0.99


# ---- geometry: Blender against Open3D ----------------------------------------------------------


@pytest.mark.slow
@pytest.mark.blender
def test_blender_geometry_matches_open3d_ray_casting(tmp_path):
    path = spread_path(tmp_path, 5)
    common = dict(layout="apt_0", path=path, width=96, height=72, chunk_size=3)
    mb = render_tour(TourSpec(out=str(tmp_path / "blender"), renderer="blender", **common), progress=False)
    mf = render_tour(TourSpec(out=str(tmp_path / "fast"), renderer="fast", **common), progress=False)
    assert mb["complete"] and mf["complete"] and mb["n_frames"] == 5
    tb, tf = Tour(tmp_path / "blender"), Tour(tmp_path / "fast")
    for a, b in zip(tb, tf):
        assert a.depth.shape == (72, 96)
        assert_renders_agree(a, b)


def test_fast_renderer_against_analytic_depth():
    # looking straight down from 1.5 m at the floor of the living room: planar depth is 1.5 m everywhere
    lay = load_layout("apt_0")
    room = lay.stage.room("living")
    x, y = (room.rect[0] + room.rect[2]) / 2, (room.rect[1] + room.rect[3]) / 2
    T = pose_from_ypr((x, y, 0.2), yaw=0.0, pitch=-np.pi / 2)
    intr = Intrinsics.from_fov(64, 48, hfov_deg=20.0)
    d, inst, sem = FastRenderer(lay).render(T, intr)
    floor = inst == 2000  # living room's floor id (room 0)
    assert floor.mean() > 0.5
    assert np.allclose(d[floor], 0.2, atol=1e-5)
    # a tilted view of the same floor: planar depth of pixel row v is h / (cos(p) * (sin(p)... ) -> compare with rays
    T2 = pose_from_ypr((x, y, 1.5), yaw=0.3, pitch=-0.6)
    d2, inst2, _ = FastRenderer(lay).render(T2, intr)
    rays = intr.pixel_rays() @ T2[:3, :3].T  # world directions with camera z = 1
    t = -1.5 / rays[..., 2]  # parameter where the ray meets z = 0
    fl = inst2 == 2000
    assert fl.mean() > 0.2
    assert np.allclose(d2[fl], t[fl], atol=1e-4)


# ---- tour format --------------------------------------------------------------------------------


def test_tour_format_fast(tmp_path):
    path = spread_path(tmp_path, 3)
    out = tmp_path / "t"
    assert synth_main(["tour", "render", "apt_2", path, "--out", str(out), "--renderer", "fast", "--size", "80x60", "--quiet"]) == 0
    cam = json.loads((out / "camera.json").read_text())
    assert (cam["width"], cam["height"]) == (80, 60)
    assert cam["cx"] == pytest.approx(39.5) and cam["cy"] == pytest.approx(29.5) and cam["fx"] == pytest.approx(cam["fy"])
    assert "planar" in cam["depth"] and "OpenCV" in cam["camera_axes"]
    ids, poses = read_tum(out / "poses.txt")
    assert list(ids) == [0, 1, 2]
    _, src = read_tum(path)
    assert np.allclose(poses, src, atol=1e-6)
    objs = json.loads((out / "objects.json").read_text())
    assert objs["layout"] == "apt_2"
    meta = json.loads((out / "meta.json").read_text())
    assert meta["renderer"] == "fast" and meta["lighting"] is None and meta["complete"]
    assert {"numpy", "open3d", "synth"} <= set(meta["toolkit"])
    with OpenEXR.File(str(out / "frames" / "000000.exr"), separate_channels=True) as f:
        types = {k: v.pixels.dtype for k, v in f.channels().items()}
    assert types == {"Z": np.float32, "instance": np.uint32, "semantic": np.uint32}
    assert check_tour(out)["ok"]


def test_resume_renders_only_missing_frames(tmp_path):
    path = spread_path(tmp_path, 4)
    spec = TourSpec(layout="apt_0", path=path, out=str(tmp_path / "t"), renderer="fast", width=48, height=36)
    render_tour(spec, progress=False)
    frames = sorted((tmp_path / "t" / "frames").glob("*.exr"))
    assert len(frames) == 4
    before = {f.name: f.stat().st_mtime_ns for f in frames}
    frames[2].unlink()
    meta = render_tour(spec, progress=False)
    assert meta["geometry_frames_rendered_now"] == 1 and meta["complete"]
    after = {f.name: f.stat().st_mtime_ns for f in (tmp_path / "t" / "frames").glob("*.exr")}
    assert set(after) == set(before)
    assert all(after[n] == before[n] for n in before if n != frames[2].name)


def test_frame_write_is_atomic(tmp_path, monkeypatch):
    target = tmp_path / "frames" / "000007.exr"

    class Boom(RuntimeError):
        pass

    real = OpenEXR.File

    def failing_file(*a, **k):
        f = real(*a, **k)

        class W:
            def __enter__(self):
                return self

            def __exit__(self, *e):
                return False

            def write(self, name):
                with open(name, "wb") as h:  # half a file under the temporary name, then a crash
                    h.write(b"v/1\x01partial")
                raise Boom("killed mid-write")

        return W() if a and isinstance(a[0], dict) else f

    monkeypatch.setattr(OpenEXR, "File", failing_file)
    with pytest.raises(Boom):
        fr.write_frame(target, depth=np.ones((4, 5), np.float32))
    assert not target.exists()
    assert not list(target.parent.glob(".*"))  # no half-written temporary file left either


def test_corrupt_exr_is_named(tmp_path):
    bad = tmp_path / "000001.exr"
    bad.write_bytes(b"\x76\x2f\x31\x01" + os.urandom(300))
    with pytest.raises(fr.FrameFileError, match=str(bad)):
        fr.read_frame(bad)


# ---- bad input: one clear line, exit 2, nothing written ----------------------------------------


@pytest.mark.parametrize(
    "args, message",
    [
        (["apt_9", "query"], "unknown layout 'apt_9'"),
        (["apt_0", "nowhere"], "unknown camera path 'nowhere'"),
        (["apt_0", "query", "--lighting", "dusk"], "unknown lighting preset 'dusk'"),
        (["apt_0", "query", "--quality", "ultra"], "unknown quality preset 'ultra'"),
        (["apt_0", "query", "--frames", "0"], "--frames must be positive"),
        (["apt_0", "query", "--frames", "999999"], "exceeds"),
        (["apt_0", "query", "--size", "640by480"], "--size must look like"),
        (["apt_0", "query", "--size", "99999x99999"], "--size: 99999x99999 is too large: at most 8192 px a side"),
        (["apt_0", "query", "--renderer", "fast", "--lighting", "day"], "fast renderer makes geometry only"),
    ],
)
def test_bad_tour_input(tmp_path, capsys, args, message):
    out = tmp_path / "never"
    assert synth_main(["tour", "render", *args, "--out", str(out), "--quiet"]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("synth: error:") and message in err and len(err.splitlines()) == 1
    assert not out.exists()


def test_unwritable_output_folder(tmp_path, capsys):
    blocker = tmp_path / "a_file"
    blocker.write_text("not a folder")
    assert synth_main(["tour", "render", "apt_0", "query", "--out", str(blocker / "tour"), "--renderer", "fast", "--quiet"]) == 2
    err = capsys.readouterr().err
    assert "cannot write to output folder" in err and str(blocker) in err


# ---- lighting and sharing geometry across lightings (Blender) -----------------------------------


def luminance(rgb):
    return 0.2126 * rgb[..., 0] + 0.7152 * rgb[..., 1] + 0.0722 * rgb[..., 2]


@pytest.mark.blender
@pytest.mark.slow
def test_lighting_presets_follow_the_paper_design(tmp_path):
    """Night/day mean luminance < 0.35 and evening's mean R/B >= 1.2 x day's, on a tour of apt_0;
    the depth and ids of every lighting are the very same files' content (rendered once)."""
    path = spread_path(tmp_path, 4)
    stats = {}
    metas = {}
    for light in ("day", "evening", "night"):
        out = tmp_path / light
        metas[light] = render_tour(TourSpec(layout="apt_0", path=path, out=str(out), lighting=light, width=64, height=48,
                                            quality="preview", chunk_size=4), progress=False)
        rgb = np.stack([f.rgb for f in Tour(out)])
        stats[light] = (luminance(rgb).mean(), rgb[..., 0].mean() / rgb[..., 2].mean())
    assert stats["night"][0] / stats["day"][0] < 0.35, stats
    assert stats["evening"][1] >= 1.2 * stats["day"][1], stats
    # geometry rendered once (by the first lighting) and shared
    assert metas["day"]["geometry_frames_rendered_now"] == 4
    assert metas["evening"]["geometry_frames_rendered_now"] == 0 and metas["night"]["geometry_frames_rendered_now"] == 0
    for a, b in zip(Tour(tmp_path / "day"), Tour(tmp_path / "night")):
        assert np.array_equal(a.depth, b.depth) and np.array_equal(a.instance, b.instance)
        assert not np.array_equal(a.rgb, b.rgb)
    assert metas["day"]["blender"].startswith("4.5")


@pytest.mark.blender
def test_a_blender_chunk_leaves_no_scratch_folder(tmp_path, monkeypatch):
    """The Blender worker renders each frame into a scratch folder (synth_render_*) and removes it when
    its chunk ends: a render leaves nothing in the temporary folder."""
    scratch = tmp_path / "tmp"
    scratch.mkdir()
    monkeypatch.setenv("TMPDIR", str(scratch))  # the worker processes inherit it
    spec = TourSpec(layout="apt_0", path=spread_path(tmp_path, 2), out=str(tmp_path / "t"), renderer="blender",
                    width=16, height=12)
    assert render_tour(spec, progress=False)["complete"]
    assert sorted((tmp_path / "t" / "frames").glob("*.exr")) and list(scratch.iterdir()) == []
