"""`synth tour export`: tours in the 7-Scenes, ACE, TUM RGB-D and COLMAP layouts.

The tests build a tiny tour by hand (vrformats.frames.write_frame: random HDR RGB on every other
frame, random planar depth with holes and far surfaces, known poses), export it, and read every
export back with plain OpenCV / numpy / scipy code written here, in each tool's own convention:
poses (world-to-camera converted back here), depth quantisation, 8-bit sRGB against an sRGB
formula written here, and projections of known 3D points with the exported calibration
(COLMAP's +0.5 pixel origin and DSAC*'s W/2 principal point taken into account as documented).
No Blender.
"""

from __future__ import annotations

import os
from pathlib import Path

import cv2
import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from vrformats import camera as cam
from vrformats.errors import SceneFormatError, UserError
from synth.cli import main as synth_main
from vrformats.export import FORMATS, export_tour, read_manifest, summary_line
from conftest import make_tour

W, H = 48, 36
INTR = cam.Intrinsics.from_fov(W, H, 70.0)
FPS = 10.0
N = 6
RGB_EVERY = 2
FAR_M = 20.0  # beyond TUM's 13.1 m range, inside the millimetre formats' 65.5 m


def tour_poses(n=N, shift=0.0):
    return [cam.pose_from_ypr((1.0 + 0.1 * i + shift, 0.5 + 0.05 * i, 1.4 - 0.01 * i), yaw=0.3 + 0.07 * i,
                              pitch=-0.1 + 0.03 * i, roll=0.02 * i) for i in range(n)]


def random_tour(root: Path, n=N, rgb_every=RGB_EVERY, shift=0.0, seed=0, rgb=True):
    """A tour folder; returns {frame: (pose, depth, rgb or None)} with the values as stored (RGB half-float)."""
    rng = np.random.default_rng(seed)
    poses = tour_poses(n, shift)
    truth, frames = {}, {}
    for i, T in enumerate(poses):
        depth = rng.uniform(0.3, 12.0, (H, W)).astype(np.float32)
        depth[:5, :7] = 0.0  # no surface
        depth[-3:, -4:] = FAR_M
        col = None
        if rgb and i % rgb_every == 0:
            col = (rng.uniform(0.0, 1.0, (H, W, 3)) ** 2 * (0.5 + i)).astype(np.float16).astype(np.float32)
        inst = np.ones((H, W), np.uint32)
        frames[i] = dict(rgb=col, depth=depth, instance=inst, semantic=inst)
        truth[i] = (T, depth, col)
    make_tour(root, poses, frames, intrinsics=INTR, fps=FPS, layout="testroom", lighting="day" if rgb else None,
              path="test", renderer="test", seed=seed, settings={"rgb_every": rgb_every})
    return truth


@pytest.fixture(scope="module")
def tour(tmp_path_factory):
    root = tmp_path_factory.mktemp("tours") / "tour_a"
    return root, random_tour(root)


# ---------------------------------------------------------------------------------------------
# independent reference computations


def srgb_ref(x):
    x = np.clip(x, 0.0, 1.0)
    return np.where(x <= 0.0031308, 12.92 * x, 1.055 * np.power(x, 1 / 2.4) - 0.055)


def expected_rgb8(rgb_linear, factor):
    return np.floor(srgb_ref(rgb_linear.astype(np.float64) * factor) * 255.0 + 0.5)


def auto_factor_ref(rgb_linear):
    lum = rgb_linear.astype(np.float64) @ np.array([0.2126, 0.7152, 0.0722])
    return 0.9 / np.percentile(lum, 97)


def points_for(T_wc):
    """Two world points for camera T_wc: one on its optical axis, one off-axis."""
    R, t = T_wc[:3, :3], T_wc[:3, 3]
    return np.stack([t + R @ np.array([0.0, 0.0, 2.0]), t + R @ np.array([0.4, -0.25, 2.5])])


def project_ours(Xw, T_wc):
    """Pixel coordinates (toolkit: pixel centres at integers) with the tour's K and pose."""
    Xc = (Xw - T_wc[:3, 3]) @ T_wc[:3, :3]
    return np.stack([INTR.fx * Xc[:, 0] / Xc[:, 2] + INTR.cx, INTR.fy * Xc[:, 1] / Xc[:, 2] + INTR.cy], axis=1)


def project_cv(Xw, R_cw, t_cw, K):
    rvec, _ = cv2.Rodrigues(np.asarray(R_cw, dtype=np.float64))
    uv, _ = cv2.projectPoints(Xw.astype(np.float64), rvec, np.asarray(t_cw, dtype=np.float64), np.asarray(K, float), None)
    return uv[:, 0, :]


def read_png(path):
    img = cv2.imread(str(path), cv2.IMREAD_UNCHANGED)
    assert img is not None, path
    return img


def check_rgb(path, rgb_linear, factor):
    img = read_png(path)
    assert img.dtype == np.uint8 and img.shape == (H, W, 3)
    diff = np.abs(img[..., ::-1].astype(int) - expected_rgb8(rgb_linear, factor))
    assert diff.max() <= 1, (path, diff.max())


def check_depth(path, depth_m, scale):
    d = read_png(path)
    assert d.dtype == np.uint16 and d.shape == (H, W)
    m = d.astype(np.float64) / scale
    fits = (depth_m > 0) & (depth_m * scale <= 65535)
    assert np.all(d[~fits] == 0)
    assert np.abs(m[fits] - depth_m[fits]).max() <= 0.5 / scale + 1e-6


def mtimes(root: Path) -> dict:
    return {str(p.relative_to(root)): p.stat().st_mtime_ns for p in sorted(root.rglob("*")) if p.is_file()}


def rgb_frames():
    return [i for i in range(N) if i % RGB_EVERY == 0]


# ---------------------------------------------------------------------------------------------
# per format


def test_7scenes(tour, tmp_path):
    root, truth = tour
    out = tmp_path / "ex7"
    m = export_tour(root, "7scenes", out, role="query")
    assert m == {**read_manifest(out), "run": m["run"]}
    assert m["export_format"] == "7scenes" and m["role"] == "query"
    # split files as ACE's / DSAC*'s setup_7scenes.py read them: 'seq-' + s.strip()[8:].zfill(2)
    test_seqs = ["seq-" + s.strip()[8:].zfill(2) for s in (out / "TestSplit.txt").read_text().splitlines()]
    assert test_seqs == ["seq-02"] and (out / "TrainSplit.txt").read_text().strip() == ""
    K = np.loadtxt(out / "intrinsics.txt")
    assert np.allclose(K, INTR.K)
    colors = sorted(p.name for p in (out / "seq-02").glob("*.color.png"))
    assert colors == [f"frame-{i:06d}.color.png" for i in rgb_frames()]
    for i in rgb_frames():
        T, depth, rgb = truth[i]
        stem = out / "seq-02" / f"frame-{i:06d}"
        T_read = np.loadtxt(f"{stem}.pose.txt")
        assert T_read.shape == (4, 4) and np.abs(T_read - T).max() < 1e-6
        check_depth(f"{stem}.depth.png", depth, 1000.0)
        check_rgb(f"{stem}.color.png", rgb, m["exposure"]["factors"][str(i)])
        Xw = points_for(T)
        R_cw = T_read[:3, :3].T
        uv = project_cv(Xw, R_cw, -R_cw @ T_read[:3, 3], K)
        assert np.abs(uv - project_ours(Xw, T)).max() < 1e-6
        assert np.allclose(uv[0], [INTR.cx, INTR.cy])
        assert m["frames"][f"seq-02/frame-{i:06d}.color.png"] == i
    assert m["skipped"] == {**m["skipped"], "count": 3, "frames": [1, 3, 5]}
    assert not list((out / "seq-02").glob("frame-000001.*"))
    assert m["depth"]["scale"] == 1000.0 and m["depth"]["invalid"] == 0


def test_ace(tour, tmp_path):
    root, truth = tour
    out = tmp_path / "ace"
    m = export_tour(root, "ace", out, role="mapping")
    split = out / "train"
    assert not (out / "test").exists()
    # ACE sorts each folder on its own and pairs files by position
    lists = {d: sorted((split / d).iterdir()) for d in ("rgb", "depth", "poses", "calibration")}
    assert {len(v) for v in lists.values()} == {len(rgb_frames())}
    for k, i in enumerate(rgb_frames()):
        T, depth, rgb = truth[i]
        assert all(lists[d][k].name.startswith(f"frame-{i:06d}.") for d in lists)
        T_read = np.loadtxt(lists["poses"][k])
        assert np.abs(T_read - T).max() < 1e-6
        check_depth(lists["depth"][k], depth, 1000.0)
        check_rgb(lists["rgb"][k], rgb, m["exposure"]["factors"][str(i)])
        K = np.loadtxt(lists["calibration"][k])
        assert K.shape == (3, 3)
        # ACE: fx, fy, cx, cy of the 3x3 K as given, pixel u at coordinate u (as ours)
        Xw = points_for(T)
        R_cw = T_read[:3, :3].T
        t_cw = -R_cw @ T_read[:3, 3]
        assert np.abs(project_cv(Xw, R_cw, t_cw, K) - project_ours(Xw, T)).max() < 1e-6
        # DSAC*: one focal length, principal point at W/2, H/2: off by the documented offset
        K_dsac = np.array([[K[0, 0], 0, W / 2], [0, K[0, 0], H / 2], [0, 0, 1]])
        off = project_cv(Xw, R_cw, t_cw, K_dsac) - project_ours(Xw, T)
        assert np.allclose(off, m["intrinsics"]["dsacstar"]["offset_px"], atol=1e-6)
        assert np.allclose(off, 0.5, atol=1e-6)
        assert m["frames"][f"train/rgb/frame-{i:06d}.color.png"] == i
    assert m["name_root"] == "train/rgb/"
    assert m["skipped"]["frames"] == [1, 3, 5]


def test_dsacstar(tour, tmp_path):
    """--format dsacstar: the ACE layout with one number per calibration file, read as DSAC*'s and ACE's
    dataset.py read it (``np.loadtxt``, size 1: the focal length, principal point at W/2, H/2)."""
    root, truth = tour
    out = tmp_path / "dsac"
    m = export_tour(root, "dsacstar", out, role="query")
    cal = sorted((out / "test" / "calibration").iterdir())
    assert len(cal) == len(rgb_frames())
    for f in cal:
        k = np.loadtxt(f)
        assert k.size == 1 and float(k) == INTR.fx
    assert m["export_format"] == "dsacstar" and "one number" in m["intrinsics"]["dsacstar"]["file"]
    assert m["frames"][f"test/rgb/frame-{rgb_frames()[0]:06d}.color.png"] == rgb_frames()[0]


def test_tum_rgbd(tour, tmp_path):
    root, truth = tour
    out = tmp_path / "tum"
    m = export_tour(root, "tum-rgbd", out)

    def listing(name):
        rows = [ln.split() for ln in (out / name).read_text().splitlines() if ln and not ln.startswith("#")]
        return {float(r[0]): r[1] for r in rows}

    rgb_list, depth_list = listing("rgb.txt"), listing("depth.txt")
    assert sorted(rgb_list) == pytest.approx([i / FPS for i in rgb_frames()])
    assert sorted(depth_list) == pytest.approx([i / FPS for i in range(N)])
    gt = np.array([[float(v) for v in ln.split()] for ln in (out / "groundtruth.txt").read_text().splitlines()
                   if ln and not ln.startswith("#")])
    assert len(gt) == N
    K = np.loadtxt(out / "intrinsics.txt")
    for row in gt:
        i = int(round(row[0] * FPS))
        T, depth, rgb = truth[i]
        T_read = np.eye(4)
        T_read[:3, :3] = Rotation.from_quat(row[4:8]).as_matrix()  # qx qy qz qw, camera-to-world
        T_read[:3, 3] = row[1:4]
        assert np.abs(T_read - T).max() < 1e-6
        check_depth(out / depth_list[row[0]], depth, 5000.0)
        assert m["timestamps"][f"{row[0]:.6f}"] == i
        if rgb is not None:
            check_rgb(out / rgb_list[row[0]], rgb, m["exposure"]["factors"][str(i)])
        Xw = points_for(T)
        R_cw = T_read[:3, :3].T
        assert np.abs(project_cv(Xw, R_cw, -R_cw @ T_read[:3, 3], K) - project_ours(Xw, T)).max() < 1e-6
    d = read_png(out / depth_list[0.0])
    assert np.all(d[-3:, -4:] == 0)  # 20 m does not fit TUM's 5000 scale
    assert m["depth"]["scale"] == 5000.0
    assocs = [ln.split() for ln in (out / "associations.txt").read_text().splitlines()]
    assert [float(a[0]) for a in assocs] == pytest.approx([i / FPS for i in rgb_frames()])
    assert m["skipped"]["frames"] == [1, 3, 5]
    assert m["frames"]["depth/000001.png"] == 1 and "rgb/000001.png" not in m["frames"]


def test_colmap(tour, tmp_path):
    root, truth = tour
    out = tmp_path / "colmap"
    m = export_tour(root, "colmap", out, role="query")
    cams = [ln.split() for ln in (out / "sparse/cameras.txt").read_text().splitlines() if ln and ln[0] != "#"]
    assert len(cams) == 1 and cams[0][1] == "PINHOLE" and cams[0][2:4] == [str(W), str(H)]
    fx, fy, cx_c, cy_c = map(float, cams[0][4:8])
    K_colmap = np.array([[fx, 0, cx_c], [0, fy, cy_c], [0, 0, 1]])
    assert (cx_c, cy_c) == pytest.approx((INTR.cx + 0.5, INTR.cy + 0.5))
    # images.txt as COLMAP / hloc's read_images_text read it: an image line, then its 2D points line
    lines = (out / "sparse/images.txt").read_text().splitlines()
    images, k = {}, 0
    while k < len(lines):
        ln = lines[k].strip()
        k += 1
        if ln and ln[0] != "#":
            e = ln.split()
            images[e[9]] = (int(e[0]), np.array(e[1:5], float), np.array(e[5:8], float), int(e[8]))
            assert lines[k].strip() == ""
            k += 1
    assert sorted(images) == [f"frame-{i:06d}.png" for i in rgb_frames()]
    assert not [ln for ln in (out / "sparse/points3D.txt").read_text().splitlines() if ln and ln[0] != "#"]
    for i in rgb_frames():
        T, _, rgb = truth[i]
        name = f"frame-{i:06d}.png"
        image_id, q, t_cw, cam_id = images[name]
        assert image_id == i + 1 and cam_id == 1
        R_cw = Rotation.from_quat([q[1], q[2], q[3], q[0]]).as_matrix()  # COLMAP: QW QX QY QZ, world-to-camera
        T_read = np.eye(4)
        T_read[:3, :3] = R_cw.T
        T_read[:3, 3] = -R_cw.T @ t_cw
        assert np.abs(T_read - T).max() < 1e-6
        Xw = points_for(T)
        uv_colmap = project_cv(Xw, R_cw, t_cw, K_colmap)  # image origin at the pixel corner
        assert np.abs(uv_colmap - 0.5 - project_ours(Xw, T)).max() < 1e-6
        check_rgb(out / "images" / name, rgb, m["exposure"]["factors"][str(i)])
        assert m["frames"][f"images/{name}"] == i
    queries = [ln.split() for ln in (out / "queries_with_intrinsics.txt").read_text().splitlines()]
    assert [q[0] for q in queries] == [f"frame-{i:06d}.png" for i in rgb_frames()]
    assert queries[0][1:4] == ["PINHOLE", str(W), str(H)] and float(queries[0][6]) == pytest.approx(INTR.cx + 0.5)
    assert m["intrinsics"]["colmap"]["cx"] == pytest.approx(INTR.cx + 0.5)
    assert m["depth"] is None and m["skipped"]["count"] == 3


# ---------------------------------------------------------------------------------------------
# exposure


def test_auto_exposure_factors_are_the_frames_own(tour, tmp_path):
    root, truth = tour
    m = export_tour(root, "colmap", tmp_path / "c")
    for i in rgb_frames():
        assert m["exposure"]["factors"][str(i)] == pytest.approx(auto_factor_ref(truth[i][2]), rel=1e-5)
    assert m["exposure"]["mode"] == "auto"


def test_fixed_and_numeric_exposure(tour, tmp_path):
    root, truth = tour
    m = export_tour(root, "ace", tmp_path / "fixed", exposure="fixed")
    median = float(np.median([auto_factor_ref(truth[i][2]) for i in rgb_frames()]))
    assert m["exposure"]["mode"] == "fixed" and m["exposure"]["factor"] == pytest.approx(median, rel=1e-5)
    for i in rgb_frames():
        check_rgb(tmp_path / "fixed" / "test" / "rgb" / f"frame-{i:06d}.color.png", truth[i][2], m["exposure"]["factor"])
    m = export_tour(root, "ace", tmp_path / "num", exposure="0.5")
    assert m["exposure"] == {**m["exposure"], "mode": "fixed", "factor": 0.5}
    for i in rgb_frames():
        check_rgb(tmp_path / "num" / "test" / "rgb" / f"frame-{i:06d}.color.png", truth[i][2], 0.5)


# ---------------------------------------------------------------------------------------------
# idempotence, resume, conflicts


@pytest.mark.parametrize("fmt", FORMATS)
def test_second_export_writes_nothing(tour, tmp_path, fmt):
    root, _ = tour
    out = tmp_path / fmt
    first = export_tour(root, fmt, out, exposure="fixed")
    before = mtimes(out)
    again = export_tour(root, fmt, out, exposure="fixed")
    assert again["run"] == {"written": 0, "kept": first["n_exported"]}
    assert mtimes(out) == before
    assert {k: v for k, v in again.items() if k != "run"} == read_manifest(out)


@pytest.mark.parametrize("fmt", FORMATS)
def test_killed_export_resumes(tour, tmp_path, fmt):
    root, _ = tour
    out = tmp_path / fmt
    first = export_tour(root, fmt, out)
    manifest = read_manifest(out)
    victim = next(n for n, i in first["frames"].items() if i == 2)
    original = (out / victim).read_bytes()
    keep = next(n for n, i in first["frames"].items() if i == 0)
    kept_mtime = (out / keep).stat().st_mtime_ns
    (out / MANIFEST_NAME).unlink()
    (out / victim).unlink()
    stray = (out / victim).parent / f".{Path(victim).name}.999.tmp"
    stray.write_bytes(b"half")
    again = export_tour(root, fmt, out)
    assert again["run"]["written"] == 1 and again["run"]["kept"] == first["n_exported"] - 1
    assert (out / victim).read_bytes() == original
    assert (out / keep).stat().st_mtime_ns == kept_mtime
    assert not stray.exists()
    assert read_manifest(out) == manifest


MANIFEST_NAME = "export.json"


@pytest.mark.parametrize("change, field", [
    ({"fmt": "ace"}, "export_format"),
    ({"role": "mapping"}, "role"),
    ({"exposure": "fixed"}, "exposure"),
    ({"exposure": 2.0}, "exposure"),
    ({"tour": "other"}, "tour.key"),
    ({"sensor": "tof"}, "sensor"),
])
def test_different_export_into_same_folder_fails(tour, tmp_path, change, field):
    root, _ = tour
    out = tmp_path / "ex"
    export_tour(root, "7scenes", out)
    before = mtimes(out)
    other = tmp_path / "tour_b"
    if change.get("tour"):
        random_tour(other, shift=0.5, seed=1)
    args = {"fmt": "7scenes", "role": "query", "exposure": "auto", **change}
    with pytest.raises(SceneFormatError) as e:
        export_tour(other if change.get("tour") else root, args["fmt"], out, role=args["role"], exposure=args["exposure"],
                    sensor=args.get("sensor"))
    assert str(out / "export.json") in str(e.value) and field in str(e.value)
    assert "\n" not in str(e.value)
    assert mtimes(out) == before


def test_export_through_a_sensor_holds_what_every_reader_of_that_sensor_gets(tour, tmp_path):
    """An export read through a sensor holds the frames Tour(sensor=, sensor_seed=) gives every other
    method (the experiment's external methods see the same noisy frames), and says so in export.json."""
    from vrformats.export import depth16
    from vrformats.tour import Tour

    root, truth = tour
    # the fixture's depth is random per pixel (all edges and grazing): a sensor with axial noise alone
    sensor = tmp_path / "noisy.yaml"
    sensor.write_text("name: axial\ndepth: {sigma_a: 0.01}\ncolor: {electrons_per_ms: 50.0, full_well_e: 1000.0}\n")
    clean, noisy, other_seed = tmp_path / "clean", tmp_path / "noisy", tmp_path / "seed4"
    export_tour(root, "ace", clean)
    m = export_tour(root, "ace", noisy, sensor=sensor, sensor_seed=3)
    export_tour(root, "ace", other_seed, sensor=sensor, sensor_seed=4)
    assert m["sensor"]["name"] == "axial" and m["sensor"]["seed"] == 3
    assert m["sensor"]["params"]["depth"]["sigma_a"] == 0.01
    assert read_manifest(clean).get("sensor") is None
    reader = Tour(root, sensor=sensor, sensor_seed=3)
    for name, i in read_manifest(noisy)["frames"].items():
        dname = name.replace("rgb/", "depth/").replace(".color.png", ".depth.png")
        want = depth16(reader.frame(i).depth, 1000.0)
        np.testing.assert_array_equal(read_png(noisy / dname), want)
        assert not np.array_equal(read_png(noisy / dname), read_png(clean / dname))
        assert not np.array_equal(read_png(noisy / dname), read_png(other_seed / dname))
    for name in read_manifest(noisy)["frames"]:  # colour too: the sensor's noise, not the render's
        if name.startswith("test/rgb/"):
            assert not np.array_equal(read_png(noisy / name), read_png(clean / name))
    assert "sensor axial (seed 3)" in summary_line(m, noisy)


def test_killed_export_then_different_request_fails(tour, tmp_path):
    root, _ = tour
    out = tmp_path / "ex"
    export_tour(root, "tum-rgbd", out)
    (out / "export.json").unlink()  # killed before the manifest
    with pytest.raises(SceneFormatError, match=r"\.synth-export\.json: role"):
        export_tour(root, "tum-rgbd", out, role="mapping")


def test_non_empty_folder_without_export_is_refused(tour, tmp_path):
    root, _ = tour
    out = tmp_path / "mine"
    out.mkdir()
    (out / "notes.txt").write_text("keep me")
    with pytest.raises(UserError, match="not empty"):
        export_tour(root, "colmap", out)
    assert sorted(p.name for p in out.iterdir()) == ["notes.txt"]


def test_geometry_only_tour(tmp_path):
    root = tmp_path / "geo"
    truth = random_tour(root, rgb=False)
    with pytest.raises(UserError, match="geometry-only"):
        export_tour(root, "colmap", tmp_path / "c")
    assert not (tmp_path / "c").exists()
    m = export_tour(root, "tum-rgbd", tmp_path / "t")
    assert m["skipped"]["count"] == N and not (tmp_path / "t" / "rgb").exists()
    check_depth(tmp_path / "t" / "depth" / "000003.png", truth[3][1], 5000.0)


# ---------------------------------------------------------------------------------------------
# command line


def test_cli_summary(tour, tmp_path, capsys):
    root, _ = tour
    out = tmp_path / "cli"
    assert synth_main(["tour", "export", str(root), "--format", "7scenes", "--out", str(out),
                       "--role", "mapping", "--exposure", "fixed"]) == 0
    line = capsys.readouterr().out.strip()
    assert "\n" not in line
    assert "3 frames" in line and "3 geometry-only frames skipped" in line and "fixed" in line and str(out) in line
    assert read_manifest(out)["role"] == "mapping" and (out / "seq-01").is_dir()



def test_cli_old_name_warns_and_exports_the_same(tour, tmp_path, capsys):
    """`synth dataset export` is the old name of `synth tour export`: one line on stderr, then the same export."""
    root, _ = tour
    argv = [str(root), "--format", "ace", "--role", "query"]
    assert synth_main(["tour", "export", *argv, "--out", str(tmp_path / "new")]) == 0
    new = capsys.readouterr()
    assert synth_main(["dataset", "export", *argv, "--out", str(tmp_path / "old")]) == 0
    old = capsys.readouterr()
    assert old.out == new.out.replace(str(tmp_path / "new"), str(tmp_path / "old"))
    assert old.err == "synth dataset export is an old name: use synth tour export; it will be removed\n" + new.err
    assert sorted(p.relative_to(tmp_path / "old") for p in (tmp_path / "old").rglob("*")) == \
        sorted(p.relative_to(tmp_path / "new") for p in (tmp_path / "new").rglob("*"))


@pytest.mark.parametrize("argv, match", [
    (["--format", "kitti"], ["kitti", "7scenes", "ace", "dsacstar", "tum-rgbd", "colmap"]),
    (["--format", "ace", "--role", "train"], ["train", "mapping", "query"]),
    (["--format", "ace", "--exposure", "bright"], ["--exposure", "bright"]),
    (["--format", "ace", "--exposure", "-1"], ["--exposure"]),
])
def test_cli_bad_options_exit_2(tour, tmp_path, capsys, argv, match):
    root, _ = tour
    out = tmp_path / "bad"
    assert synth_main(["tour", "export", str(root), "--out", str(out), *argv]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and all(s in err for s in match)
    assert not out.exists()


def test_cli_not_a_tour_exit_2(tmp_path, capsys):
    (tmp_path / "empty").mkdir()
    out = tmp_path / "o"
    assert synth_main(["tour", "export", str(tmp_path / "empty"), "--format", "ace", "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "camera.json" in err
    assert not out.exists()


def test_cli_unwritable_folder_exit_2(tour, tmp_path, capsys):
    root, _ = tour
    (tmp_path / "afile").write_text("x")
    out = tmp_path / "afile" / "sub"
    assert synth_main(["tour", "export", str(root), "--format", "ace", "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "cannot write" in err


def test_cli_different_export_exit_2(tour, tmp_path, capsys):
    root, _ = tour
    out = tmp_path / "o"
    export_tour(root, "ace", out)
    assert synth_main(["tour", "export", str(root), "--format", "colmap", "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "export.json" in err and "export_format" in err


def test_incomplete_tour_is_refused(tmp_path):
    root = tmp_path / "partial"
    random_tour(root)
    os.unlink(root / "frames" / "000004.exr")
    with pytest.raises(UserError, match="frame files missing"):
        export_tour(root, "ace", tmp_path / "o")
    assert not (tmp_path / "o").exists()


def test_progress_bar_goes_to_stderr(tour, tmp_path, capsys):
    root, _ = tour
    export_tour(root, "tum-rgbd", tmp_path / "p", progress=True)
    cap = capsys.readouterr()
    assert "export tum-rgbd" in cap.err and cap.out == ""


FAKE_TEST_ACE = '''#!/usr/bin/env python3
"""A stand-in for nianticlabs/ace test_ace.py: the same arguments, and its pose file written where the
real one writes it (the network's folder, poses_<scene name>_<session>.txt; one line per test image:
NAME qw qx qy qz tx ty tz r_err t_err inliers, world-to-camera), here with the ground-truth poses."""
import argparse, math, os
from pathlib import Path

p = argparse.ArgumentParser()
p.add_argument("scene", type=Path)
p.add_argument("network", type=Path)
p.add_argument("--session", default="")
p.add_argument("--image_resolution", type=int, default=480)
a = p.parse_args()
rgb = sorted((a.scene / "test" / "rgb").iterdir())
poses = sorted((a.scene / "test" / "poses").iterdir())
assert len(rgb) == len(poses)
with open(a.network.parent / f"poses_{a.scene.name}_{a.session}.txt", "w") as out:
    for img, pf in zip(rgb, poses):
        T = [[float(v) for v in ln.split()] for ln in pf.read_text().splitlines() if ln.strip()]
        R = [[T[j][i] for j in range(3)] for i in range(3)]  # world-to-camera: R^T, -R^T t
        t = [-sum(R[i][k] * T[k][3] for k in range(3)) for i in range(3)]
        w = math.sqrt(max(0.0, 1 + R[0][0] + R[1][1] + R[2][2])) / 2
        x = math.copysign(math.sqrt(max(0.0, 1 + R[0][0] - R[1][1] - R[2][2])) / 2, R[2][1] - R[1][2])
        y = math.copysign(math.sqrt(max(0.0, 1 - R[0][0] + R[1][1] - R[2][2])) / 2, R[0][2] - R[2][0])
        z = math.copysign(math.sqrt(max(0.0, 1 - R[0][0] - R[1][1] + R[2][2])) / 2, R[1][0] - R[0][1])
        out.write(f"{img.name} {w} {x} {y} {z} {t[0]} {t[1]} {t[2]} 0.0 0.0 1000\\n")
'''


def test_the_documented_ace_wrapper_runs(tour, tmp_path):
    """docs/external_relocalizers.md's run_ace.sh, run as written against a fake test_ace.py that writes
    its pose file where the real one does; the file it copies scores every exported frame right."""
    import json
    import os
    import re
    import subprocess

    from reloc.cli import main as reloc_main

    doc = (Path(__file__).resolve().parents[2] / "docs" / "external_relocalizers.md").read_text()
    script = re.search(r"```bash\n(#!/usr/bin/env bash\n# run_ace\.sh.*?)```", doc, re.S).group(1)
    home = tmp_path / "home"
    (home / "ace").mkdir(parents=True)
    fake = home / "ace" / "test_ace.py"
    fake.write_text(FAKE_TEST_ACE)
    fake.chmod(0o755)
    root, _ = tour
    query = tmp_path / "exports" / "tour_a_query"
    export_tour(root, "ace", query, role="query")
    mp, out = tmp_path / "map", tmp_path / "out"
    mp.mkdir()
    out.mkdir()
    (mp / "ace.pt").write_bytes(b"head weights")
    (tmp_path / "run_ace.sh").write_text(script)
    r = subprocess.run(["bash", str(tmp_path / "run_ace.sh"), str(query), str(mp), str(out)], capture_output=True,
                       text=True, env={**os.environ, "HOME": str(home)}, timeout=60)
    assert r.returncode == 0, r.stderr
    assert (out / "poses.txt").is_file()
    save = tmp_path / "eval.json"
    assert reloc_main(["eval", str(out / "poses.txt"), "--poses", "ace", "--names", str(query), "--gt", str(root),
                       "--save", str(save)]) == 0
    res = json.loads(save.read_text())
    got = res["poses.txt"]
    assert res["frames"] == len(rgb_frames()) and got["recall_1m_10deg"] == 1.0 and got["median_pos_m"] < 1e-6
