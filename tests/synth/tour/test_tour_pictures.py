"""Pictures of tours and designs: synth tour show --strip / --video, and synth tour check|show on a
render job's folder. Tours written here with the format's own writer (tests.conftest.make_tour):
12 frames of 32x24, RGB on every 3rd, a depth ramp and two instances whose boundary moves a pixel
a frame."""

from __future__ import annotations

import json

import numpy as np
import pytest
from PIL import Image

from synth.cli import main as synth_main
from tests.cli_errors import one_line_error
from tests.conftest import make_tour
from vrformats.camera import Intrinsics

W, H, N = 32, 24, 12
INTR = Intrinsics.from_fov(W, H, 75.0)


def _tour(root, lighting="day", rgb_every=3, layout="apt_t"):
    frames = {}
    for i in range(N):
        depth = np.tile(np.linspace(1.0, 4.0, W, dtype=np.float32), (H, 1))
        inst = np.zeros((H, W), np.uint16)
        inst[:, : 8 + i] = 7  # the boundary moves a pixel a frame: every frame differs
        inst[:, 8 + i:] = 9
        ch = dict(depth=depth, instance=inst, semantic=inst)
        if lighting and i % rgb_every == 0:
            ch["rgb"] = np.full((H, W, 3), 0.2 + 0.05 * i, np.float32)
        frames[i] = ch
    poses = [np.eye(4) for _ in range(N)]
    for i, T in enumerate(poses):
        T[0, 3] = 0.1 * i
    return make_tour(root, poses, frames, intrinsics=INTR, layout=layout, lighting=lighting, path="query",
                     settings={"rgb_every": rgb_every if lighting else None})


def test_a_strip_shows_rgb_frames_along_the_tour(tmp_path, capsys):
    t = _tour(tmp_path / "apt_t__day__query")
    assert synth_main(["tour", "show", str(t), "--strip", "3", "--out", str(tmp_path / "s.png")]) == 0
    img = Image.open(tmp_path / "s.png")
    # three rows of (2x upscaled) RGB | depth | ids with captions, frames 0, 6 and 9 (RGB every 3rd)
    assert img.width >= 3 * 2 * W and img.height >= 3 * 2 * H
    a = np.asarray(img.convert("RGB"))
    assert a.std() > 10  # not blank
    # jpg works too; a bad suffix is one line
    assert synth_main(["tour", "show", str(t), "--strip", "--out", str(tmp_path / "s.jpg")]) == 0
    assert Image.open(tmp_path / "s.jpg").format == "JPEG"
    capsys.readouterr()
    assert synth_main(["tour", "show", str(t), "--strip", "--out", str(tmp_path / "s.bmp")]) == 2
    one_line_error(capsys, "s.bmp", ".png")


def test_a_video_has_one_frame_per_rgb_frame_and_geometry_tours_show_grey(tmp_path, capsys):
    t = _tour(tmp_path / "apt_t__day__query")
    assert synth_main(["tour", "show", str(t), "--video", "--out", str(tmp_path / "v.gif")]) == 0
    assert "(4 frames)" in capsys.readouterr().out  # frames 0, 3, 6, 9
    gif = Image.open(tmp_path / "v.gif")
    assert gif.n_frames == 4 and gif.size[0] >= 3 * W and gif.size[1] == H
    assert synth_main(["tour", "show", str(t), "--video", "--every", "1", "--out", str(tmp_path / "all.gif")]) == 0
    assert Image.open(tmp_path / "all.gif").n_frames == N
    g = _tour(tmp_path / "apt_t__geometry__query", lighting=None)
    assert synth_main(["tour", "show", str(g), "--video", "--out", str(tmp_path / "g.gif")]) == 0
    first = np.asarray(Image.open(tmp_path / "g.gif").convert("RGB"))
    rgb_panel = first[:, :W]
    assert np.ptp(rgb_panel) <= 2 and 55 <= rgb_panel.mean() <= 75  # the grey "no RGB" panel (0.25)
    capsys.readouterr()
    assert synth_main(["tour", "show", str(t), "--video", "--fps", "0", "--out", str(tmp_path / "x.gif")]) == 2
    one_line_error(capsys, "--fps")


def test_a_render_jobs_folder_is_summarised_and_drawn(tmp_path, capsys):
    job = tmp_path / "job"
    for layout in ("apt_t", "apt_u"):
        for lighting in ("day", "night"):
            _tour(job / f"{layout}__{lighting}__query", lighting=lighting, layout=layout)
    assert synth_main(["tour", "check", str(job), "--json"]) == 0
    s = json.loads(capsys.readouterr().out)
    assert len(s["tours"]) == 4 and s["frames"] == 4 * N and s["rgb_frames"] == 4 * 4
    assert s["layouts"] == ["apt_t", "apt_u"] and s["lightings"] == ["day", "night"]
    assert synth_main(["tour", "check", str(job)]) == 0
    assert "4 tours (4 complete), 48 frames (16 with RGB)" in capsys.readouterr().out
    assert synth_main(["tour", "show", str(job), "--out", str(tmp_path / "m.png")]) == 0
    m = Image.open(tmp_path / "m.png")
    assert m.width > 2 * 3 * W and m.height > 2 * H  # 2 rows (layouts) x 2 columns (lightings)
    capsys.readouterr()
    assert synth_main(["tour", "show", str(job), "--path", "mapping", "--out", str(tmp_path / "m2.png")]) == 2
    one_line_error(capsys, "--path mapping", "query")
    (job / "apt_u__day__query" / "meta.json").unlink()  # a tour not finished: the summary says so, exit 1
    (job / "design.json").write_text(json.dumps({"format": "videoreloc-design/1", "tours": {
        n: {"layout": n.split("__")[0], "lighting": n.split("__")[1], "path": "query", "n_frames": N}
        for n in ("apt_t__day__query", "apt_t__night__query", "apt_u__day__query", "apt_u__night__query")}}))
    assert synth_main(["tour", "check", str(job)]) == 1
    assert "3 complete" in capsys.readouterr().out


def test_previews_of_geometry_frames_and_of_a_fast_render(tmp_path):
    """--previews wrote nothing for the fast renderer: now every frame without an RGB preview gets
    depth | ids, and a preview already there (the Blender worker's) is kept."""
    from synth.tour.show import write_previews

    t = _tour(tmp_path / "apt_t__day__query")
    (t / "previews").mkdir()
    Image.new("RGB", (W, H), "red").save(t / "previews" / "000000.png")
    assert write_previews(t) == N - 1 and write_previews(t) == 0
    assert np.asarray(Image.open(t / "previews" / "000000.png"))[0, 0].tolist() == [255, 0, 0]
    p = Image.open(t / "previews" / "000005.png")
    assert p.size[1] == H and 2 * W <= p.size[0] <= 2 * W + 8
    out = tmp_path / "fast"
    assert synth_main(["tour", "render", "apt_0", "query", "--renderer", "fast", "--frames", "2", "--size", "32x24",
                       "--previews", "--quiet", "--out", str(out)]) == 0
    assert sorted(f.name for f in (out / "previews").iterdir()) == ["000000.png", "000001.png"]
