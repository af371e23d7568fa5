"""Pose files of other relocalizers (vrformats.poses) and ``reloc eval --poses CONVENTION``.

The same camera-to-world poses, written in every convention (by ``write_poses`` and, independently,
by plain text code here that follows each tool's documented convention: world-to-camera inverted
with numpy, quaternions from scipy), read back equal and evaluate identically; a seeded error of
known size gives the predicted recall; bad input is one line, exit 2, nothing written.
"""

from __future__ import annotations

import json

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from vrformats.camera import Intrinsics, write_tum
from vrformats.errors import SceneFormatError, UserError
from vrformats.poses import CONVENTIONS, frame_names, load_names, read_poses, write_poses
from vrformats.tour import Tour, write_tour
from reloc.cli import main as reloc_main
from cli_errors import one_line_error

N, FPS = 40, 30.0


def _rot(axis, deg) -> np.ndarray:
    a = np.asarray(axis, dtype=float)
    return Rotation.from_rotvec(np.radians(deg) * a / np.linalg.norm(a)).as_matrix()


@pytest.fixture(scope="module")
def tour(tmp_path_factory) -> Tour:
    """A tour written by hand (camera.json, poses.txt, meta.json): random rotations, among them
    exactly and nearly 180 degrees and the identity."""
    root = tmp_path_factory.mktemp("poses") / "tour"
    root.mkdir()
    rng = np.random.default_rng(17)
    poses = []
    for i in range(N):
        T = np.eye(4)
        T[:3, :3] = Rotation.random(random_state=rng).as_matrix()
        T[:3, 3] = rng.uniform(-5, 5, 3)
        poses.append(T)
    poses[1][:3, :3] = _rot([1, 0, 0], 180.0)
    poses[2][:3, :3] = _rot([0.3, -0.5, 0.8], 179.99)
    poses[3][:3, :3] = _rot([0, 1, 1], 180.0)
    poses[4][:3, :3] = np.eye(3)
    t = write_tour(root, poses, Intrinsics.from_fov(64, 48), fps=FPS)
    assert len(t) == N
    return t


def _gt(tour) -> dict[int, np.ndarray]:
    return {int(i): T for i, T in zip(tour.frame_indices, tour.poses)}


# export manifests as synth tour export writes them ("frames": file name -> tour frame index)
def _ace_manifest(n=N) -> dict:
    return {"format": "ace", "frames": {f"test/rgb/frame-{i:06d}.color.png": i for i in range(n)}}


def _seven_manifest(n=N) -> dict:  # two sequences: basenames repeat
    f = {f"seq-01/frame-{i:06d}.color.png": i for i in range(n // 2)}
    f |= {f"seq-02/frame-{i - n // 2:06d}.color.png": i for i in range(n // 2, n)}
    return {"format": "7scenes", "frames": f}


# --- independent writers: each tool's documented line, formatted here --------------------------


def _quat_wxyz(R, flip: bool) -> np.ndarray:
    x, y, z, w = Rotation.from_matrix(R).as_quat()
    q = np.array([w, x, y, z])
    return -q if flip else q  # q and -q are the same rotation: files may hold either


def _indep_named(poses: dict, name_of, tail: str, flip_every=2) -> str:
    """``name qw qx qy qz tx ty tz`` + ``tail``: world-to-camera (the inverse of each pose)."""
    lines = ["# written by the test", ""]
    for k, (i, T) in enumerate(sorted(poses.items())):
        Tcw = np.linalg.inv(T)
        q = _quat_wxyz(Tcw[:3, :3], flip=k % flip_every == 1)
        nums = " ".join(repr(float(v)) for v in (*q, *Tcw[:3, 3]))
        lines.append(f"{name_of(i)} {nums}{tail}")
    return "\n".join(lines) + "\n"


def _indep_tum(poses: dict, decimals=4) -> str:
    """TUM ``t tx ty tz qx qy qz qw``, camera-to-world; times printed with few decimals."""
    lines = []
    for k, (i, T) in enumerate(sorted(poses.items())):
        w, x, y, z = _quat_wxyz(T[:3, :3], flip=k % 3 == 1)
        lines.append(f"{i / FPS:.{decimals}f} " + " ".join(repr(float(v)) for v in (*T[:3, 3], x, y, z, w)))
    return "\n".join(lines) + "\n"


INDEPENDENT = {
    # ACE test_ace.py: the image's basename, 11 fields (r_err t_err inliers of its own eval)
    "ace": (lambda i: f"frame-{i:06d}.color.png", " 0.5 0.02 1234"),
    # hloc with prepend_camera_name: camera/basename, a tail of the manifest's test/rgb/... name
    "colmap": (lambda i: f"rgb/frame-{i:06d}.color.png", ""),
    # map-free submission: a longer path that ends with the manifest's name, and a confidence
    "mapfree": (lambda i: f"/data/exports/apt/test/rgb/frame-{i:06d}.color.png", " 0.75"),
}


def _write_indep(path, conv, poses) -> None:
    if conv == "tum":
        path.write_text(_indep_tum(poses))
    else:
        name_of, tail = INDEPENDENT[conv]
        path.write_text(_indep_named(poses, name_of, tail))


def _assert_same(a: dict, b: dict, tol=1e-6) -> None:
    assert sorted(a) == sorted(b)
    for i in a:
        np.testing.assert_allclose(a[i], b[i], atol=tol, rtol=0, err_msg=f"frame {i}")


# ---------------------------------------------------------------------------------------------
# 1. conventions: written by write_poses and by independent code, read back equal


@pytest.mark.parametrize("conv", CONVENTIONS)
def test_write_then_read_is_identity(tour, tmp_path, conv):
    gt = _gt(tour)
    man = _ace_manifest()
    p = write_poses(tmp_path / f"{conv}.txt", conv, gt, names=frame_names(man["frames"]), fps=FPS)
    back = read_poses(p, conv, names=man["frames"], fps=FPS, frames=set(gt))
    _assert_same(back, gt)
    assert list(back) == sorted(gt)  # file order


@pytest.mark.parametrize("conv", CONVENTIONS)
def test_independently_written_files_read_back_equal(tour, tmp_path, conv):
    gt = _gt(tour)
    p = tmp_path / f"{conv}.txt"
    _write_indep(p, conv, gt)
    if conv != "tum":  # some lines hold the negative-w quaternion
        ws = [float(ln.split()[1]) for ln in p.read_text().splitlines() if ln and not ln.startswith("#")]
        assert min(ws) < 0 < max(ws)
    back = read_poses(p, conv, names=_ace_manifest()["frames"], fps=FPS, frames=set(gt))
    _assert_same(back, gt)


def test_named_conventions_are_world_to_camera(tmp_path):
    """A camera at (1, 2, 3) looking down world +x: the file's translation is -R^T c, not c."""
    T = np.eye(4)
    T[:3, :3] = np.array([[0, 0, 1], [-1, 0, 0], [0, -1, 0]], dtype=float)  # OpenCV z -> world +x
    T[:3, 3] = [1, 2, 3]
    p = write_poses(tmp_path / "c.txt", "colmap", {5: T}, names={5: "a.png"})
    f = [float(v) for v in p.read_text().split()[1:]]
    np.testing.assert_allclose(f[4:7], -T[:3, :3].T @ T[:3, 3], atol=1e-9)
    p = write_poses(tmp_path / "t.txt", "tum", {5: T}, fps=10.0)
    f = [float(v) for v in p.read_text().split()]
    assert f[0] == pytest.approx(0.5) and f[1:4] == pytest.approx([1, 2, 3])


def test_ace_line_layout(tmp_path):
    p = write_poses(tmp_path / "poses_scene_.txt", "ace", {0: np.eye(4)}, names={0: "frame-000000.color.png"})
    assert p.read_text().split() == ["frame-000000.color.png", "1", "0", "0", "0", "0", "0", "0", "-1", "-1", "-1"]
    p = write_poses(tmp_path / "m.txt", "mapfree", {0: np.eye(4)}, names={0: "seq1/frame_00000.jpg"})
    assert p.read_text().split()[-1] == "1" and len(p.read_text().split()) == 9


# ---------------------------------------------------------------------------------------------
# 2. name matching rules


def test_name_matching_rules(tmp_path):
    names = _seven_manifest(8)["frames"]  # seq-01/frame-000000..3, seq-02/frame-000000..3 -> 0..7
    T = np.eye(4)
    cases = {
        "seq-02/frame-000001.color.png": 5,              # equal
        "/abs/export/seq-02/frame-000001.color.png": 5,  # ends with a manifest name
        "x\\seq-01\\frame-000002.color.png": 2,          # backslashes read as /
        "./seq-01/frame-000003.color.png": 3,
    }
    for name, want in cases.items():
        p = write_poses(tmp_path / "a.txt", "colmap", {0: T}, names={0: name})
        assert list(read_poses(p, "colmap", names=names)) == [want], name
    # a tail of a manifest name
    p = write_poses(tmp_path / "b.txt", "colmap", {0: T}, names={0: "frame-000001.color.png"})
    two = {"test/rgb/frame-000001.color.png": 1, "test/rgb/frame-000002.color.png": 2}
    assert list(read_poses(p, "colmap", names=two)) == [1]
    # last resort: the basename, when exactly one manifest name has it
    p = write_poses(tmp_path / "c.txt", "colmap", {0: T}, names={0: "elsewhere/frame-000001.color.png"})
    assert list(read_poses(p, "colmap", names={"test/rgb/frame-000001.color.png": 1})) == [1]
    # two names of one frame (colour and depth) are not ambiguous
    p = write_poses(tmp_path / "d.txt", "colmap", {0: T}, names={0: "000004.png"})
    assert list(read_poses(p, "colmap", names={"rgb/000004.png": 4, "depth/000004.png": 4})) == [4]


@pytest.mark.parametrize("name, message", [
    ("frame-000001.color.png", "ambiguous"),                # seq-01 and seq-02 both have it
    ("seq-03/frame-000001.color.png", "ambiguous"),         # basename rule finds two frames
    ("frame-000999.color.png", "not a file of the export"),
])
def test_unmatched_or_ambiguous_names_are_errors(tmp_path, name, message):
    p = write_poses(tmp_path / "a.txt", "colmap", {0: np.eye(4)}, names={0: name})
    with pytest.raises(SceneFormatError) as e:
        read_poses(p, "colmap", names=_seven_manifest(8)["frames"])
    assert "line 1" in str(e.value) and message in str(e.value) and name in str(e.value)


def test_load_names(tmp_path):
    (tmp_path / "exp").mkdir()
    (tmp_path / "exp" / "export.json").write_text(json.dumps(_ace_manifest(3)))
    assert load_names(tmp_path / "exp") == _ace_manifest(3)["frames"]
    assert load_names(tmp_path / "exp" / "export.json") == _ace_manifest(3)["frames"]
    (tmp_path / "bad.json").write_text(json.dumps({"frames": {"a.png": -1}}))
    with pytest.raises(SceneFormatError, match="a.png"):
        load_names(tmp_path / "bad.json")


def test_api_needs_what_the_convention_needs(tmp_path):
    p = write_poses(tmp_path / "a.txt", "tum", {0: np.eye(4)}, fps=FPS)
    with pytest.raises(UserError, match="fps"):
        read_poses(p, "tum")
    with pytest.raises(UserError, match="names"):
        read_poses(p, "ace", fps=FPS)
    with pytest.raises(UserError, match="'kitti'.*tum, ace, colmap, mapfree"):
        read_poses(p, "kitti", fps=FPS)
    assert list(read_poses(p, "TUM", fps=FPS)) == [0]


# ---------------------------------------------------------------------------------------------
# 3. reloc eval --poses: the same numbers in every convention; a seeded error gives the predicted recall


def _seeded(tour) -> dict[int, np.ndarray]:
    """Frames 0-9 exact; 10-19 moved 0.5 m; 20-29 moved 0.3 m and turned 20 deg; 30-39 missing.
    Predicted: recall 1 m/10 deg = 20/40, 0.25 m/5 deg = 10/40, coverage 30/40, median position
    error 0.3 m (10 x 0, 10 x 0.3, 10 x 0.5), median rotation error 0 deg."""
    rng = np.random.default_rng(3)
    est = {}
    for i, T in _gt(tour).items():
        if i >= 30:
            continue
        E = T.copy()
        d = rng.normal(size=3)
        d /= np.linalg.norm(d)
        if 10 <= i < 20:
            E[:3, 3] += 0.5 * d
        elif 20 <= i < 30:
            E[:3, 3] += 0.3 * d
            E[:3, :3] = E[:3, :3] @ _rot(rng.normal(size=3), 20.0)
        est[i] = E
    return est


def _eval_json(capsys, args) -> dict:
    assert reloc_main(["eval", *map(str, args), "--json"]) == 0
    return json.loads(capsys.readouterr().out)


def test_eval_poses_same_numbers_in_every_convention(tour, tmp_path, capsys):
    est = _seeded(tour)
    exp = tmp_path / "export"
    exp.mkdir()
    (exp / "export.json").write_text(json.dumps(_ace_manifest()))
    files = {}
    for conv in CONVENTIONS:
        files[f"{conv}_tool"] = (conv, write_poses(tmp_path / f"{conv}_tool.txt", conv, est,
                                                    names=frame_names(_ace_manifest()["frames"]), fps=FPS))
        _write_indep(tmp_path / f"{conv}_indep.txt", conv, est)
        files[f"{conv}_indep"] = (conv, tmp_path / f"{conv}_indep.txt")
    results = {}
    for label, (conv, f) in files.items():
        names = ["--names", exp] if conv != "tum" else []
        rep = _eval_json(capsys, [f, "--gt", tour.root, "--poses", conv, *names])
        assert rep["frames"] == N and rep["convention"] == conv
        results[label] = rep[f.name]
    for label, r in results.items():
        assert r["recall_1m_10deg"] == 0.5, label
        assert r["recall_25cm_5deg"] == 0.25, label
        assert r["coverage"] == 0.75, label
        assert r["median_pos_m"] == pytest.approx(0.3, abs=1e-6), label
        assert r["median_rot_deg"] == pytest.approx(0.0, abs=1e-3), label
    # the table labels the output by the file's name
    assert reloc_main(["eval", str(files["ace_indep"][1]), "--gt", str(tour.root), "--poses", "ace",
                       "--names", str(exp / "export.json")]) == 0
    out = capsys.readouterr().out
    assert "| ace_indep.txt | 50.0 | 25.0 | 0.300 |" in out and "(ace poses)" in out


def test_eval_poses_every_pose_half_a_metre_off(tour, tmp_path, capsys):
    """Every pose 0.5 m off: all within 1 m/10 deg, none within 0.25 m/5 deg."""
    est = {i: T.copy() for i, T in _gt(tour).items()}
    for T in est.values():
        T[:3, 3] += [0.0, 0.3, 0.4]
    f = write_poses(tmp_path / "off.txt", "mapfree", est, names=frame_names(_seven_manifest()["frames"]))
    (tmp_path / "m.json").write_text(json.dumps(_seven_manifest()))
    rep = _eval_json(capsys, [f, "--gt", tour.root, "--poses", "mapfree", "--names", tmp_path / "m.json",
                              "--save", tmp_path / "rep.json"])
    r = rep["off.txt"]
    assert (r["recall_1m_10deg"], r["recall_25cm_5deg"], r["coverage"]) == (1.0, 0.0, 1.0)
    assert r["median_pos_m"] == pytest.approx(0.5, abs=1e-6)
    assert json.loads((tmp_path / "rep.json").read_text()) == rep


def test_eval_of_a_run_folder_is_unchanged(tour, tmp_path, capsys):
    run = tmp_path / "run"
    for name in ("causal", "closure"):
        write_tum(run / f"{name}.txt", tour.poses, fps=FPS, frames=tour.frame_indices)
    rep = _eval_json(capsys, [run, "--gt", tour.root])
    assert rep["causal"]["recall_1m_10deg"] == 1.0 and "convention" not in rep


# ---------------------------------------------------------------------------------------------
# 4. bad input: one line naming the file and field, exit 2, nothing written


def _bad_line(tmp_path, conv, line_no: int, text: str | None, est=None):
    """A valid file of the tour's first 8 poses in ``conv`` with line ``line_no`` replaced by ``text``
    (None: inserted duplicate of line 2 at ``line_no``)."""
    est = est if est is not None else {i: np.eye(4) for i in range(8)}
    f = write_poses(tmp_path / f"in_{conv}.txt", conv, est, names=frame_names(_ace_manifest()["frames"]), fps=FPS)
    lines = f.read_text().splitlines()
    if text is None:
        lines.insert(line_no - 1, lines[1])
    else:
        lines[line_no - 1] = text
    f.write_text("\n".join(lines) + "\n")
    return f


def _run_bad(capsys, tmp_path, args, *names) -> str:
    out = tmp_path / "out"
    out.mkdir(exist_ok=True)
    assert reloc_main(["eval", *map(str, args), "--save", str(out / "rep.json")]) == 2
    line = one_line_error(capsys, *names, prog=("reloc",))
    assert sorted(p.name for p in out.iterdir()) == []
    return line


@pytest.mark.parametrize("conv, text, message", [
    ("colmap", "frame-000003.color.png 1 0 0 0 0 0", "expected 8 fields"),
    ("ace", "frame-000003.color.png 1 0 0 0 0 0 0 -1 -1", "expected 11 fields"),
    ("mapfree", "frame-000003.color.png 1 0 0 0 0 0 0 1 2", "got 10 fields"),
    ("tum", "0.1 0 0 0 0 0 0", "expected 8 fields"),
    ("colmap", "frame-000003.color.png 1 0 0 0 0 zero 0", "not a number: 'zero'"),
    ("ace", "frame-000003.color.png 1 0 0 nan 0 0 0 -1 -1 -1", "non-finite"),
    ("colmap", "frame-000003.color.png 0.9 0 0 0 0 0 0", "not unit length (norm 0.900000)"),
    ("tum", "0.1 0 0 0 0 0 0 1.002", "not unit length"),
    ("tum", "0.115 0 0 0 0 0 0 1", "not a frame time"),         # 3.45 frames at 30 fps
    ("tum", "99 0 0 0 0 0 0 1", "frame 2970 (t = 99) is not in the tour (40 frames, 0..39)"),
    ("tum", "-0.0333 0 0 0 0 0 0 1", "frame -1"),
    ("colmap", "frame-000999.color.png 1 0 0 0 0 0 0", "'frame-000999.color.png' is not a file of the export"),
])
def test_eval_rejects_malformed_lines(tour, tmp_path, capsys, conv, text, message):
    f = _bad_line(tmp_path, conv, 4, text)
    (tmp_path / "m.json").write_text(json.dumps(_ace_manifest()))
    names = ["--names", tmp_path / "m.json"] if conv != "tum" else []
    _run_bad(capsys, tmp_path, [f, "--gt", tour.root, "--poses", conv, *names], f, "line 4", message)


def test_eval_rejects_a_named_frame_not_in_the_tour(tour, tmp_path, capsys):
    man = _ace_manifest() | {"frames": _ace_manifest()["frames"] | {"test/rgb/frame-000500.color.png": 500}}
    (tmp_path / "m.json").write_text(json.dumps(man))
    f = write_poses(tmp_path / "p.txt", "ace", {0: np.eye(4), 500: np.eye(4)}, names=frame_names(man["frames"]))
    _run_bad(capsys, tmp_path, [f, "--gt", tour.root, "--poses", "ace", "--names", tmp_path / "m.json"],
             f, "line 2", "frame 500", "not in the tour")


@pytest.mark.parametrize("conv", CONVENTIONS)
def test_eval_rejects_duplicate_frames_naming_both_lines(tour, tmp_path, capsys, conv):
    f = _bad_line(tmp_path, conv, 6, None)  # line 2's frame again on line 6
    (tmp_path / "m.json").write_text(json.dumps(_ace_manifest()))
    names = ["--names", tmp_path / "m.json"] if conv != "tum" else []
    _run_bad(capsys, tmp_path, [f, "--gt", tour.root, "--poses", conv, *names],
             f, "line 6", "frame 1", "already given on line 2")


def test_eval_rejects_an_unknown_convention(tour, tmp_path, capsys):
    f = write_poses(tmp_path / "p.txt", "tum", {0: np.eye(4)}, fps=FPS)
    _run_bad(capsys, tmp_path, [f, "--gt", tour.root, "--poses", "kitti"],
             "--poses", "'kitti'", "tum, ace, colmap, mapfree")


@pytest.mark.parametrize("conv", ["ace", "colmap", "mapfree"])
def test_eval_named_convention_needs_names(tour, tmp_path, capsys, conv):
    f = write_poses(tmp_path / "p.txt", conv, {0: np.eye(4)}, names={0: "a.png"})
    _run_bad(capsys, tmp_path, [f, "--gt", tour.root, "--poses", conv], f, "--names", conv)


@pytest.mark.parametrize("content, field", [
    ({"format": "ace"}, "frames"),
    ({"frames": ["a.png"]}, "frames"),
    ({"frames": {"a.png": "zero"}}, "frames['a.png']"),
])
def test_eval_names_file_without_frames(tour, tmp_path, capsys, content, field):
    f = write_poses(tmp_path / "p.txt", "ace", {0: np.eye(4)}, names={0: "a.png"})
    (tmp_path / "m.json").write_text(json.dumps(content))
    _run_bad(capsys, tmp_path, [f, "--gt", tour.root, "--poses", "ace", "--names", tmp_path / "m.json"],
             tmp_path / "m.json", field)


def test_eval_names_missing_or_not_json(tour, tmp_path, capsys):
    f = write_poses(tmp_path / "p.txt", "ace", {0: np.eye(4)}, names={0: "a.png"})
    (tmp_path / "empty_export").mkdir()
    _run_bad(capsys, tmp_path, [f, "--gt", tour.root, "--poses", "ace", "--names", tmp_path / "empty_export"],
             tmp_path / "empty_export" / "export.json", "not found")
    (tmp_path / "m.json").write_text("{\n  \"frames\": {,\n}")
    _run_bad(capsys, tmp_path, [f, "--gt", tour.root, "--poses", "ace", "--names", tmp_path / "m.json"],
             tmp_path / "m.json", "line 2", "not valid JSON")


def test_eval_pose_file_missing_or_a_folder(tour, tmp_path, capsys):
    _run_bad(capsys, tmp_path, [tmp_path / "nope.txt", "--gt", tour.root, "--poses", "tum"],
             tmp_path / "nope.txt", "not found")
    (tmp_path / "dir").mkdir()
    _run_bad(capsys, tmp_path, [tmp_path / "dir", "--gt", tour.root, "--poses", "tum"], tmp_path / "dir", "folder")


def test_eval_names_without_poses(tour, tmp_path, capsys):
    _run_bad(capsys, tmp_path, [tmp_path, "--gt", tour.root, "--names", tmp_path / "m.json"], "--names", "--poses")
