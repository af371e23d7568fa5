"""Tour directories: reading (lazy), `synth tour check` and `synth tour show`.

The tests build their own tours: a closed box room (floor, ceiling, four walls) with one box-shaped
"sofa" in it, rendered exactly by ray casting (planar depth from camera.Intrinsics.pixel_rays and
the pose), so every frame's depth, ids and poses agree to float precision. No Blender.
"""

from __future__ import annotations

import json
import shutil

import matplotlib.image as mpimg
import numpy as np
import pytest

import vrformats.frames as frames_mod
from vrformats import camera as cam
from vrformats.errors import SceneFormatError, UserError
from vrformats.frames import FrameFileError, write_frame
from conftest import make_tour
from vrformats.tour import Tour, tonemap
from synth.cli import main as synth_main
from synth.tour.check import check_tour, choose_pairs, depth_consistency, format_report
from synth.tour.show import contact_sheet, id_colors

ROOM_LO = np.array([0.0, 0.0, 0.0])
ROOM_HI = np.array([6.0, 5.0, 2.6])
SOFA_ID, SOFA_CENTER, SOFA_SIZE = 1, np.array([4.0, 2.5, 0.4]), np.array([1.6, 0.8, 0.8])
CLASSES = {"wall": 1, "floor": 2, "ceiling": 3, "sofa": 4}
INTR = cam.Intrinsics.from_fov(96, 72, 75.0)
FPS = 30.0
N_FRAMES = 8


def tour_poses(n=N_FRAMES):
    return [
        cam.pose_from_ypr((1.2 + 0.12 * i, 1.0 + 0.15 * i, 1.4 + 0.02 * i), yaw=0.35 + 0.06 * i,
                          pitch=-0.2 + 0.02 * i, roll=0.03 * i)
        for i in range(n)
    ]


def render(T, intr=INTR):
    """Exact planar depth, instance, semantic and a patterned RGB of the room seen from pose T."""
    rays = intr.pixel_rays()
    d = rays @ T[:3, :3].T  # world directions; the ray parameter is the planar depth (camera z = 1)
    o = T[:3, 3]
    with np.errstate(divide="ignore", invalid="ignore"):
        t_axis = np.where(d > 0, (ROOM_HI - o) / d, np.where(d < 0, (ROOM_LO - o) / d, np.inf))
        axis = t_axis.argmin(axis=-1)
        t = t_axis.min(axis=-1)
        pos = np.take_along_axis(d, axis[..., None], axis=-1)[..., 0] > 0
        inst = np.choose(axis, [np.where(pos, 1001, 1000), np.where(pos, 1003, 1002), np.where(pos, 3000, 2000)])
        sem = np.choose(axis, [CLASSES["wall"], CLASSES["wall"], np.where(pos, CLASSES["ceiling"], CLASSES["floor"])])
        lo, hi = SOFA_CENTER - SOFA_SIZE / 2, SOFA_CENTER + SOFA_SIZE / 2
        t1, t2 = (lo - o) / d, (hi - o) / d
        tn = np.nanmax(np.minimum(t1, t2), axis=-1)
        tf = np.nanmin(np.maximum(t1, t2), axis=-1)
    box = (tn <= tf) & (tn > 0) & (tn < t)
    t = np.where(box, tn, t)
    inst = np.where(box, SOFA_ID, inst).astype(np.uint32)
    sem = np.where(box, CLASSES["sofa"], sem).astype(np.uint32)
    p = o + t[..., None] * d
    checker = (np.floor(p * 2.0).sum(axis=-1) % 2)[..., None]
    base = id_colors(inst, salt=3)
    rgb = (base * (0.25 + 0.5 * checker) * (0.6 + 0.4 * p[..., 2:3] / ROOM_HI[2])).astype(np.float32)
    return t.astype(np.float32), inst, sem, rgb


def objects_doc():
    boxes = [{"id": SOFA_ID, "class": "sofa", "kind": "object", "center": SOFA_CENTER.tolist(),
              "size": SOFA_SIZE.tolist(), "yaw": 0.0, "movable": True}]
    cx, cy = (ROOM_LO + ROOM_HI)[:2] / 2
    for k, (c, s) in enumerate([((0.0, cy), (0.2, 5.0)), ((6.0, cy), (0.2, 5.0)), ((cx, 0.0), (6.0, 0.2)), ((cx, 5.0), (6.0, 0.2))]):
        boxes.append({"id": 1000 + k, "class": "wall", "kind": "wall", "center": [c[0], c[1], 1.3],
                      "size": [s[0], s[1], 2.6], "yaw": 0.0, "movable": False})
    boxes.append({"id": 2000, "class": "floor", "kind": "floor", "center": [cx, cy, -0.05], "size": [6.0, 5.0, 0.1], "yaw": 0.0, "movable": False})
    boxes.append({"id": 3000, "class": "ceiling", "kind": "ceiling", "center": [cx, cy, 2.65], "size": [6.0, 5.0, 0.1], "yaw": 0.0, "movable": False})
    return {"format": "videoreloc-boxes/1", "layout": "testroom", "frame": "world: right-handed, Z up, metres",
            "classes": CLASSES, "boxes": boxes}


def room_tour(root, rgb=True, n=N_FRAMES):
    """Write a complete tour directory; returns the poses and the images written."""
    poses = tour_poses(n)
    truth, frames = [], {}
    for i, T in enumerate(poses):
        depth, inst, sem, col = render(T)
        frames[i] = dict(rgb=col if rgb else None, depth=depth, instance=inst, semantic=sem)
        truth.append((depth, inst, sem, col))
    make_tour(root, poses, frames, intrinsics=INTR, fps=FPS, objects=objects_doc(), layout="testroom",
              lighting="day" if rgb else None, path="test", renderer="test")
    return poses, truth


@pytest.fixture
def tour_dir(tmp_path):
    root = tmp_path / "tour_a"
    poses, truth = room_tour(root)
    return root, poses, truth


def _rewrite(root, index, **changes):
    """Rewrite one frame with some channels replaced."""
    f = Tour(root).frame(index)
    ch = {"rgb": f.rgb, "depth": f.depth, "instance": f.instance, "semantic": f.semantic, **changes}
    write_frame(root / "frames" / f"{index:06d}.exr", **ch)


# ---------------------------------------------------------------------------------------------
# reading


def test_tour_reads_lazily_and_round_trips(tour_dir, monkeypatch):
    root, poses, truth = tour_dir
    calls = []
    real = frames_mod.read_channels
    monkeypatch.setattr(frames_mod, "read_channels", lambda p: calls.append(str(p)) or real(p))

    tour = Tour(root)
    assert calls == []  # no frame read up front
    assert len(tour) == N_FRAMES and tour.frame_indices.tolist() == list(range(N_FRAMES))
    assert tour.intrinsics == INTR and tour.fps == FPS
    np.testing.assert_allclose(tour.K, INTR.K)
    np.testing.assert_allclose(tour.poses, np.asarray(poses), atol=2e-6)
    assert tour.meta["layout"] == "testroom" and tour.has_rgb()

    it = iter(tour)
    f0 = next(it)
    assert len(calls) == 1 and calls[0].endswith("000000.exr")
    f1 = next(it)
    assert len(calls) == 2 and f1.index == 1
    depth, inst, sem, col = truth[0]
    np.testing.assert_array_equal(f0.depth, depth)
    np.testing.assert_array_equal(f0.instance, inst)
    np.testing.assert_array_equal(f0.semantic, sem)
    assert f0.rgb is not None and f0.rgb.dtype == np.float32 and f0.rgb.shape == (72, 96, 3)
    np.testing.assert_allclose(f0.rgb, col, rtol=1e-3, atol=1e-4)  # half floats
    assert f0.depth.dtype == np.float32 and f0.instance.dtype == np.uint32
    np.testing.assert_allclose(f0.pose, poses[0], atol=2e-6)
    np.testing.assert_allclose(f0.K, INTR.K)

    f5 = tour.frame(5)
    np.testing.assert_array_equal(f5.depth, truth[5][0])
    # the planar-depth convention: back-projecting the depth lands on the room's surfaces
    p = (INTR.pixel_rays() * f5.depth[..., None]) @ f5.pose[:3, :3].T + f5.pose[:3, 3]
    on_face = np.isclose(p, ROOM_LO, atol=1e-4) | np.isclose(p, ROOM_HI, atol=1e-4)
    assert on_face.any(axis=-1)[f5.instance != SOFA_ID].all()

    with pytest.raises(UserError, match="frame 99 is not in this tour"):
        tour.frame(99)
    assert sum(1 for _ in tour) == N_FRAMES


def test_objects_are_read_lazily(tour_dir):
    root, _, _ = tour_dir
    (root / "objects.json").unlink()
    tour = Tour(root)  # fine without objects.json ...
    with pytest.raises(SceneFormatError, match="objects.json"):
        tour.objects()  # ... until it is needed
    rep = check_tour(root)
    assert not rep["ok"] and any("objects.json" in p for p in rep["problems"])


def test_geometry_only_tour(tmp_path):
    root = tmp_path / "geo"
    room_tour(root, rgb=False, n=4)
    tour = Tour(root)
    assert not tour.has_rgb()
    f = tour.frame(1)
    assert f.rgb is None and f.depth is not None
    rep = check_tour(root)
    assert rep["ok"], rep["problems"]
    assert rep["channels"] == ["Z", "instance", "semantic"]
    out = contact_sheet(tour, 1, tmp_path / "geo.png")
    assert mpimg.imread(out).shape[2] in (3, 4)


@pytest.mark.parametrize(
    "edit, match",
    [
        (lambda r: (r / "camera.json").unlink(), r"camera\.json: camera file not found"),
        (lambda r: (r / "camera.json").write_text("{not json"), r"camera\.json: line 1: not valid JSON"),
        (lambda r: _edit_json(r / "camera.json", fx="abc"), r"camera\.json: fx: expected a finite number"),
        (lambda r: _edit_json(r / "camera.json", fps=None), r"camera\.json: fps: expected a finite number"),
        (lambda r: _edit_json(r / "camera.json", K=[[1, 0, 0], [0, 1, 0], [0, 0, 1]]), r"camera\.json: K: does not match"),
        (lambda r: (r / "poses.txt").unlink(), r"poses\.txt: trajectory file not found"),
        (lambda r: (r / "poses.txt").write_text("0 1 2 3 0 0 0\n"), r"poses\.txt: line 1: expected 8 numbers"),
        (lambda r: (r / "meta.json").unlink(), r"meta\.json: tour metadata not found"),
    ],
)
def test_unusable_tour_is_a_user_error(tour_dir, capsys, edit, match):
    root, _, _ = tour_dir
    edit(root)
    with pytest.raises(UserError, match=match):
        Tour(root)
    assert synth_main(["tour", "check", str(root)]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and err.startswith("synth: error: ")


def _edit_json(path, **changes):
    d = json.loads(path.read_text())
    d.update(changes)
    path.write_text(json.dumps(d))


def test_missing_directory_exit_2(tmp_path, capsys):
    assert synth_main(["tour", "check", str(tmp_path / "nope")]) == 2
    assert "tour directory not found" in capsys.readouterr().err
    assert synth_main(["tour", "show", str(tmp_path / "nope"), "--out", str(tmp_path / "x.png")]) == 2



def test_old_dataset_names_warn_and_do_the_same(tour_dir, capsys):
    """`synth dataset check|show` are the old names of `synth tour check|show`: one line on stderr, then the same."""
    root, _, _ = tour_dir
    sheet = root.parent / "old_name.png"
    for argv in (["check", str(root)], ["check", str(root), "--json"],
                 ["show", str(root), "--frame", "2", "--out", str(sheet)], ["check", str(root.parent / "nope")]):
        new_rc = synth_main(["tour", *argv])
        new = capsys.readouterr()
        old_rc = synth_main(["dataset", *argv])
        old = capsys.readouterr()
        assert old_rc == new_rc and old.out == new.out
        first, _, rest = old.err.partition("\n")
        assert first == f"synth dataset {argv[0]} is an old name: use synth tour {argv[0]}; it will be removed"
        assert rest == new.err and "old name" not in new.err


# ---------------------------------------------------------------------------------------------
# check


def test_check_clean_tour(tour_dir, capsys, monkeypatch):
    root, _, _ = tour_dir
    calls = []
    real = frames_mod.read_channels
    monkeypatch.setattr(frames_mod, "read_channels", lambda p: calls.append(str(p)) or real(p))
    rep = check_tour(root, consistency_pairs=8)
    assert rep["ok"], rep["problems"]
    assert rep["frames_expected"] == rep["frames_found"] == N_FRAMES
    assert rep["missing"] == rep["unreadable"] == rep["stray_temp_files"] == []
    assert rep["channels"] == ["B", "G", "R", "Z", "instance", "semantic"]
    assert rep["unknown_ids"] == rep["bad_depth"] == rep["bad_poses"] == rep["class_mismatch"] == []
    pairs = rep["consistency"]["pairs"]
    assert len(pairs) == N_FRAMES - 1  # every neighbouring pair of this short tour
    for p in pairs:
        assert p["agreement"] > 0.99 and p["compared_pixels"] > 3000 and not p["flagged"]
        assert p["median_abs_diff_m"] < 0.005 and p["baseline_m"] > 0.02
    assert len(calls) <= N_FRAMES + 2 * len(pairs)  # each frame once, plus the depth of the pairs
    json.dumps(rep)  # JSON-serialisable

    assert synth_main(["tour", "check", str(root)]) == 0
    out = capsys.readouterr().out
    assert "8/8 frames" in out and "OK" in out
    assert synth_main(["tour", "check", str(root), "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["ok"] is True


def test_perturbed_pose_fails_consistency(tour_dir, capsys):
    root, poses, _ = tour_dir
    bad = [T.copy() for T in poses]
    bad[3][:3, 3] += [0.3, 0.0, 0.0]  # 0.3 m, roughly along the view direction
    cam.write_tum(root / "poses.txt", bad, fps=FPS)
    rep = check_tour(root)
    assert not rep["ok"]
    flagged = rep["consistency"]["flagged"]
    assert [2, 3] in flagged and [3, 4] in flagged
    assert all(3 in f for f in flagged)  # only pairs with the moved pose
    for p in rep["consistency"]["pairs"]:
        if 3 not in p["frames"]:
            assert p["agreement"] > 0.99
    assert synth_main(["tour", "check", str(root)]) == 1
    out = capsys.readouterr().out
    assert "frames 2 -> 3: depth inconsistent with poses" in out and "PROBLEMS FOUND" in out


def test_ray_length_depth_fails_consistency(tmp_path):
    """Depth written as ray length instead of planar z is caught by the consistency test."""
    root = tmp_path / "raylen"
    room_tour(root, n=4)
    norm = np.linalg.norm(INTR.pixel_rays(), axis=-1).astype(np.float32)
    for i in range(4):
        _rewrite(root, i, depth=Tour(root).frame(i).depth * norm)
    rep = check_tour(root)
    assert rep["consistency"]["flagged"], rep["consistency"]


def test_missing_frame(tour_dir, capsys):
    root, _, _ = tour_dir
    (root / "frames" / "000005.exr").unlink()
    rep = check_tour(root)
    assert not rep["ok"] and rep["missing"] == [5] and rep["frames_found"] == N_FRAMES - 1
    assert all(5 not in p["frames"] for p in rep["consistency"]["pairs"])
    assert any("missing frames" in p and "5" in p for p in rep["problems"])
    assert synth_main(["tour", "check", str(root)]) == 1
    assert "missing frames (1 of 8, no EXR in frames/): 5" in capsys.readouterr().out
    with pytest.raises(FrameFileError, match="000005.exr"):
        Tour(root).frame(5)


def test_corrupt_frame(tour_dir):
    root, _, _ = tour_dir
    p = root / "frames" / "000004.exr"
    data = p.read_bytes()
    p.write_bytes(data[: len(data) // 2])
    rep = check_tour(root)
    assert not rep["ok"]
    assert [u["frame"] for u in rep["unreadable"]] == [4]
    assert "000004.exr" in rep["unreadable"][0]["file"] and "000004.exr" in rep["unreadable"][0]["error"]
    assert any(pr.startswith("unreadable frame 4:") for pr in rep["problems"])
    with pytest.raises(FrameFileError, match="000004.exr"):
        Tour(root).frame(4)
    # garbage, not just truncated
    p.write_bytes(b"not an exr at all")
    rep = check_tour(root)
    assert [u["frame"] for u in rep["unreadable"]] == [4]


def test_stray_temp_file(tour_dir):
    root, _, _ = tour_dir
    (root / "frames" / ".000003.exr.tmp").write_bytes(b"partial")
    rep = check_tour(root)
    assert not rep["ok"] and rep["stray_temp_files"] == ["frames/.000003.exr.tmp"]
    assert rep["missing"] == []  # the real frame is still there
    assert any(".000003.exr.tmp" in p for p in rep["problems"])
    # the job folder a failed Blender render leaves behind: a warning, not a problem
    (root / "frames" / ".000003.exr.tmp").unlink()
    (root / ".jobs_abc").mkdir()
    rep = check_tour(root)
    assert rep["ok"] and any(".jobs_abc" in w for w in rep["warnings"])
    assert ".jobs_abc" in format_report(rep)


def test_bad_depth(tour_dir):
    root, _, truth = tour_dir
    _rewrite(root, 2, depth=np.zeros((72, 96), np.float32))
    d = truth[6][0].copy()
    d[0, :3] = [np.nan, np.inf, -1.0]
    _rewrite(root, 6, depth=d)
    rep = check_tour(root)
    assert not rep["ok"]
    bad = {b["frame"]: b["why"] for b in rep["bad_depth"]}
    assert set(bad) == {2, 6}
    assert "all zero" in bad[2] and "NaN/inf" in bad[6] and "negative" in bad[6]
    assert all(2 not in p["frames"] and 6 not in p["frames"] for p in rep["consistency"]["pairs"])


def test_unknown_ids_and_class_mismatch(tour_dir):
    root, _, truth = tour_dir
    inst, sem = truth[1][1].copy(), truth[1][2].copy()
    inst[:10, :10] = 77  # not in objects.json, not structure
    inst[10:12, :10] = 1005  # a structure id: allowed
    sem[:10, :10] = 99  # no such class
    _rewrite(root, 1, instance=inst, semantic=sem)
    rep = check_tour(root)
    assert not rep["ok"]
    assert rep["unknown_ids"] == [{"frame": 1, "instance": [77], "semantic": [99]}]
    assert any("frame 1: unknown instance ids [77]" in p for p in rep["problems"])

    # the semantic id of a known instance contradicts objects.json
    _rewrite(root, 1, instance=truth[1][1], semantic=np.where(truth[1][1] == 2000, CLASSES["sofa"], truth[1][2]).astype(np.uint32))
    rep = check_tour(root)
    assert [m["frame"] for m in rep["class_mismatch"]] == [1]
    assert rep["class_mismatch"][0]["pairs"][0] == [2000, CLASSES["sofa"], CLASSES["floor"]]


def test_shape_and_channel_problems(tour_dir):
    root, _, truth = tour_dir
    write_frame(root / "frames" / "000002.exr", depth=np.ones((36, 48), np.float32),
                instance=np.ones((36, 48), np.uint32), semantic=np.ones((36, 48), np.uint32))
    write_frame(root / "frames" / "000003.exr", rgb=truth[3][3], depth=truth[3][0], instance=truth[3][1])
    rep = check_tour(root)
    assert [s["frame"] for s in rep["shape_mismatch"]] == [2]
    assert rep["shape_mismatch"][0]["shape"] == [[36, 48]]
    assert rep["missing_channels"] == [{"frame": 2, "missing": ["B", "G", "R"]}, {"frame": 3, "missing": ["semantic"]}]
    assert any("frame 2: size 48x36, camera.json says 96x72" in p for p in rep["problems"])


def test_bad_pose_rotation_is_flagged():
    from synth.tour.check import _pose_problem

    T = cam.pose_from_ypr((1, 2, 1.5), 0.3)
    assert _pose_problem(T) is None
    S = T.copy()
    S[:3, :3] *= 1.1
    assert "not orthonormal" in _pose_problem(S)
    M = T.copy()
    M[:3, 0] *= -1
    assert "reflection" in _pose_problem(M)
    N = T.copy()
    N[0, 3] = np.nan
    assert "non-finite" in _pose_problem(N)


def test_non_unit_quaternion_is_unusable(tour_dir):
    root, _, _ = tour_dir
    lines = (root / "poses.txt").read_text().splitlines()
    parts = lines[2].split()
    parts[-1] = str(float(parts[-1]) * 1.5)
    lines[2] = " ".join(parts)
    (root / "poses.txt").write_text("\n".join(lines) + "\n")
    with pytest.raises(SceneFormatError, match=r"poses\.txt: line 3: quaternion is not unit length"):
        check_tour(root)


def test_choose_pairs_skips_still_frames_and_unusable():
    moving = tour_poses(10)
    still = [moving[0]] * 3 + moving[1:]  # the camera waits for two frames at the start
    usable = np.ones(len(still), bool)
    pairs = choose_pairs(np.asarray(still), usable, 1)
    assert pairs == [(0, 3)]  # 0 -> 1 and 0 -> 2 did not move
    usable[5] = False
    pairs = choose_pairs(np.asarray(moving), usable[:10], 20)
    assert all(5 not in p for p in pairs) and (4, 6) in pairs
    assert choose_pairs(np.asarray(moving[:1]), [True], 8) == []


def test_depth_consistency_handles_occlusion():
    """A camera that sees the sofa hide part of the wall: occluded pixels are not disagreements."""
    Ta = cam.look_at((1.0, 2.5, 1.0), (6.0, 2.5, 0.6))
    Tb = cam.look_at((1.0, 1.3, 1.0), (6.0, 2.9, 0.6))  # 1.2 m sideways: the sofa hides different wall pixels
    da, db = render(Ta)[0], render(Tb)[0]
    res = depth_consistency(da, Ta, db, Tb, INTR)
    assert res["agreement"] > 0.99 and res["occluded_fraction"] > 0.01


# ---------------------------------------------------------------------------------------------
# show


def test_show_writes_contact_sheet(tour_dir, capsys):
    root, _, _ = tour_dir
    out = root.parent / "sheets" / "f3.png"
    assert synth_main(["tour", "show", str(root), "--frame", "3", "--out", str(out)]) == 0
    assert str(out) in capsys.readouterr().out
    img = mpimg.imread(out)
    assert img.shape[0] > 500 and img.shape[1] > 800
    assert img[..., :3].std() > 0.1  # not blank
    assert not list(out.parent.glob(".*"))  # no temporary file left
    # default frame: the first
    assert synth_main(["tour", "show", str(root), "--out", str(out)]) == 0
    # a frame that is not in the tour
    assert synth_main(["tour", "show", str(root), "--frame", "42", "--out", str(out)]) == 2
    assert "frame 42 is not in this tour" in capsys.readouterr().err


def test_tonemap_and_id_colors():
    rgb = np.full((4, 4, 3), 0.5, np.float32)
    img, scale = tonemap(rgb)
    assert img.max() <= 1.0 and scale == pytest.approx(1.8)
    img, scale = tonemap(rgb * 100, exposure=1.0)
    assert scale == 1.0 and np.allclose(img, 1.0)
    c = id_colors(np.array([0, 1, 2, 1, 1000]))
    assert (c[0] == 0).all() and np.allclose(c[1], c[3]) and not np.allclose(c[1], c[2])
    np.testing.assert_array_equal(id_colors(np.array([5])), id_colors(np.array([5])))  # stable


def test_format_report_mentions_every_problem(tour_dir):
    root, _, _ = tour_dir
    (root / "frames" / "000001.exr").unlink()
    (root / "frames" / ".000002.exr.tmp").write_bytes(b"")
    rep = check_tour(root)
    text = format_report(rep)
    assert len(rep["problems"]) == 2
    for p in rep["problems"]:
        assert p in text
    assert "PROBLEMS FOUND (2)" in text


def test_copy_of_tour_is_independent(tour_dir, tmp_path):
    """A tour is self-contained: it can be moved and still reads (no absolute paths inside)."""
    root, _, _ = tour_dir
    moved = tmp_path / "elsewhere" / "tour_b"
    shutil.copytree(root, moved)
    shutil.rmtree(root)
    rep = check_tour(moved)
    assert rep["ok"], rep["problems"]
