"""FPFH-ICP, the dense geometric clip-rigid control (reloc/fpfh_icp.py).

Ground truth is independent of the code under test: depth comes from the fast ray-casting renderer
of apt_0 (``synth.render.fast_render``) along the shipped mapping and query camera paths, written as real
tour directories, and the clip frame is an arbitrary rigid transform X of the world.
"""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from reloc.baselines.fpfh_icp import FpfhConfig, PointMap, clip_frames, constraint, register_clip, run_fpfh_icp

from vrformats import camera as cam
from vrformats.errors import UserError
from conftest import make_tour
from vrformats.tour import Tour
from synth.render.fast_render import FastRenderer
from synth.paths.files import load_path
from synth.scene.model import load_layout

INTR = cam.Intrinsics.from_fov(96, 72, 75.0)
FPS = 30.0
MAP_EVERY = 30  # every 30th pose of the shipped 6000-frame mapping path: 200 frames
CLIP = range(300, 400)  # query path frames of the good clip
WALL = range(400, 420)  # frames whose depth is replaced by one flat wall
BLANK = range(420, 430)  # frames without depth
SPECK = range(430, 432)  # frames with a handful of depth pixels


def depth_tour(root, poses: dict[int, np.ndarray], depths: dict[int, np.ndarray]) -> Tour:
    """A tour of depth-only frames."""
    idx = sorted(poses)
    return Tour(make_tour(root, [poses[i] for i in idx], {i: dict(depth=depths[i]) for i in idx}, intrinsics=INTR,
                          fps=FPS, frame_ids=idx, layout="apt_0", path="test", renderer="fast"))


def random_T(rng, t_scale=5.0) -> np.ndarray:
    q = rng.normal(size=4)
    q /= np.linalg.norm(q)
    w, x, y, z = q
    R = np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
                  [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
                  [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)]])
    T = np.eye(4)
    T[:3, :3] = R
    T[:3, 3] = rng.uniform(-t_scale, t_scale, 3)
    return T


def slide(T, dx) -> np.ndarray:
    """T moved dx metres along its own x axis (sideways, same orientation)."""
    out = T.copy()
    out[:3, 3] += dx * T[:3, 0]
    return out


def rot_deg(Ra, Rb) -> float:
    return math.degrees(math.acos(np.clip((np.trace(Ra.T @ Rb) - 1) / 2, -1, 1)))


@pytest.fixture(scope="module")
def world(tmp_path_factory):
    """A mapping tour, its point map, a query tour and the arbitrary clip frame X."""
    base = tmp_path_factory.mktemp("fpfh")
    rend = FastRenderer(load_layout("apt_0"))
    mp = load_path("mapping").poses[::MAP_EVERY]
    mposes = {k: T for k, T in enumerate(mp)}
    mapping = depth_tour(base / "mapping", mposes, {k: rend.render(T, INTR)[0] for k, T in mposes.items()})
    qp = load_path("query").poses
    qposes = {i: qp[i] for i in (*CLIP, *WALL, *BLANK, *SPECK)}
    depths = {i: rend.render(qp[i], INTR)[0] for i in CLIP}
    for i in WALL:
        depths[i] = np.full((INTR.height, INTR.width), 2.0, np.float32)  # a flat wall 2 m ahead
    for i in BLANK:
        depths[i] = np.zeros((INTR.height, INTR.width), np.float32)
    for i in SPECK:
        d = np.zeros((INTR.height, INTR.width), np.float32)
        d[30:33, 40:43] = 1.5
        depths[i] = d
    query = depth_tour(base / "query", qposes, depths)
    X = random_T(np.random.default_rng(7))
    Xinv = np.linalg.inv(X)
    clips = {
        0: {i: Xinv @ qp[i] for i in CLIP},  # V_i: the true pose in the clip frame
        1: {i: Xinv @ slide(qp[WALL[0]], 0.05 * k) for k, i in enumerate(WALL)},  # one flat wall, camera sliding
        2: {i: Xinv @ qp[i] for i in SPECK},  # almost no depth
        3: {i: Xinv @ qp[i] for i in BLANK},  # no depth at all
    }
    cfg = FpfhConfig(map_stride=1)
    pmap = PointMap.build(mapping, cfg)
    return {"base": base, "mapping": mapping, "query": query, "pmap": pmap, "cfg": cfg, "X": X, "clips": clips,
            "gt": qp}


def test_map_is_a_5cm_cloud_with_keypoint_features(world):
    pm = world["pmap"]
    assert pm.voxel == 0.05 and len(pm) > 5000
    # one point per 5 cm cell (cells centred on multiples of 5 cm)
    keys = np.floor(pm.points / pm.voxel + 0.5).astype(np.int64)
    assert len(np.unique(keys, axis=0)) >= 0.999 * len(pm)  # (float32 rounding at cell borders)
    assert np.allclose(np.linalg.norm(pm.normals, axis=1), 1.0, atol=1e-3)
    assert 0 < len(pm.keypoints) < len(pm) and pm.features.shape == (len(pm.keypoints), 33)
    # the apartment's floor is at z = 0 and its normals point up, into the room the cameras saw
    floor = (np.abs(pm.points[:, 2]) < 0.03) & (np.abs(pm.normals[:, 2]) > 0.9)
    assert floor.sum() > 500 and (pm.normals[floor, 2] > 0).mean() > 0.99


def test_registers_clip_given_in_an_arbitrary_frame(world):
    S, info = register_clip(world["pmap"], world["query"], world["clips"][0], world["cfg"])
    assert S is not None, info
    assert info["reason"] is None and info["fitness"] > 0.8 and info["rmse"] < 0.03
    X = world["X"]
    assert np.linalg.norm(S[:3, 3] - X[:3, 3]) < 0.03
    assert rot_deg(S[:3, :3], X[:3, :3]) < 1.0
    for i, V in world["clips"][0].items():  # every frame's map pose
        assert np.linalg.norm((S @ V)[:3, 3] - world["gt"][i][:3, 3]) < 0.05


def test_registration_is_deterministic(world):
    S1, i1 = register_clip(world["pmap"], world["query"], world["clips"][0], world["cfg"])
    S2, i2 = register_clip(world["pmap"], world["query"], world["clips"][0], world["cfg"])
    # the sampler is seeded; Open3D's multi-threaded ICP sums may differ in the last bits
    assert i1["ransac_iterations"] == i2["ransac_iterations"] and i1["ransac_inliers"] == i2["ransac_inliers"]
    assert np.abs(S1 - S2).max() < 1e-6


def test_flat_wall_is_degenerate_not_registered(world):
    S, info = register_clip(world["pmap"], world["query"], world["clips"][1], world["cfg"])
    assert S is None
    assert info["points"] >= world["cfg"].min_points  # plenty of points, but one plane
    assert "degenerate" in info["reason"] and info["constraint"] < 1e-3


@pytest.mark.parametrize("clip", [2, 3])
def test_clips_without_enough_depth_are_not_registered(world, clip):
    S, info = register_clip(world["pmap"], world["query"], world["clips"][clip], world["cfg"])
    assert S is None and info["reason"].startswith("too few points")
    assert info["fitness"] == 0.0 and "seconds" in info


def test_empty_clip_and_voxel_mismatch(world):
    S, info = register_clip(world["pmap"], world["query"], {}, world["cfg"])
    assert S is None and info["reason"] == "empty clip"
    S, info = register_clip(world["pmap"], world["query"], world["clips"][0], FpfhConfig(voxel=0.1))
    assert S is None and "voxel" in info["reason"]


def test_constraint_measure():
    rng = np.random.default_rng(0)
    plane = np.c_[rng.uniform(-1, 1, (500, 2)), np.zeros(500)]
    up = np.tile([0.0, 0.0, 1.0], (500, 1))
    assert constraint(plane, up) < 1e-9
    # floor and one wall: sliding along the wall is free
    wall = np.c_[rng.uniform(-1, 1, 500), np.zeros(500), rng.uniform(0, 1, 500)]
    side = np.tile([0.0, 1.0, 0.0], (500, 1))
    assert constraint(np.r_[plane, wall], np.r_[up, side]) < 1e-9
    # a corner of three planes pins everything
    wall2 = np.c_[np.zeros(500), rng.uniform(-1, 1, 500), rng.uniform(0, 1, 500)]
    front = np.tile([1.0, 0.0, 0.0], (500, 1))
    assert constraint(np.r_[plane, wall, wall2], np.r_[up, side, front]) > 0.02


def test_clip_frames_follow_the_observation_cadence():
    assert clip_frames(range(10, 22), 5) == [10, 15, 20, 21]
    assert clip_frames([3], 5) == [3]
    assert clip_frames([], 5) == []


def test_point_map_round_trip_and_errors(world, tmp_path):
    pm = world["pmap"]
    path = pm.save(tmp_path / "m.npz")
    assert path.stat().st_size > 0 and not list(tmp_path.glob(".*tmp*"))
    back = PointMap.load(path)
    for k in ("points", "normals", "keypoints", "features"):
        assert np.array_equal(getattr(back, k), getattr(pm, k)), k
    assert back.voxel == pm.voxel and back.source == str(path)
    assert back.meta["config"]["map_stride"] == 1

    with pytest.raises(UserError, match="m_missing.npz"):
        PointMap.load(tmp_path / "m_missing.npz")
    bad = tmp_path / "garbage.npz"
    bad.write_bytes(b"not a zip file at all")
    with pytest.raises(UserError, match="garbage.npz"):
        PointMap.load(bad)
    cut = tmp_path / "cut.npz"
    cut.write_bytes(path.read_bytes()[: path.stat().st_size // 2])
    with pytest.raises(UserError, match="cut.npz"):
        PointMap.load(cut)
    other = tmp_path / "other.npz"
    np.savez(other, points=np.zeros((3, 3)))
    with pytest.raises(UserError, match="other.npz.*missing"):
        PointMap.load(other)


def test_run_writes_closure_for_registered_clips_only(world, tmp_path):
    out = tmp_path / "run"
    s = run_fpfh_icp(world["query"], world["pmap"], world["clips"], out, world["cfg"], progress=False)
    assert s["clips"] == 4 and s["registered"] == 1 and s["closure_frames"] == len(CLIP)
    frames, poses = cam.read_tum(out / "closure.txt", fps=FPS)
    assert frames.tolist() == list(CLIP)
    for i, T in zip(frames, poses):
        assert np.linalg.norm(T[:3, 3] - world["gt"][i][:3, 3]) < 0.05
        assert rot_deg(T[:3, :3], world["gt"][i][:3, :3]) < 1.0
    rows = json.loads((out / "clips.json").read_text())
    assert [r["clip"] for r in rows] == [0, 1, 2, 3]
    assert [r["registered"] for r in rows] == [True, False, False, False]
    assert rows[0]["reason"] is None and all(r["reason"] for r in rows[1:])
    assert all(r["seconds"] >= 0 and r["frames"] > 0 for r in rows)
    run = json.loads((out / "run.json").read_text())
    assert run["clips"] == 4 and run["registered"] == 1 and run["seconds_per_clip"] > 0
    assert run["not_registered"] == {"degenerate geometry": 1, "too few points": 2}


def test_run_with_no_registered_clip_writes_an_empty_closure(world, tmp_path):
    out = tmp_path / "run"
    s = run_fpfh_icp(world["query"], world["pmap"], {3: world["clips"][3]}, out, world["cfg"], progress=False)
    assert s["registered"] == 0
    frames, _ = cam.read_tum(out / "closure.txt", fps=FPS)
    assert len(frames) == 0


def test_command_line(world, tmp_path, capsys):
    from reloc.baselines.fpfh_icp import main

    assert main(["map", "--tour", str(world["mapping"].root), "--out", str(tmp_path / "m.npz"), "--stride", "4",
                 "--quiet"]) == 0
    assert PointMap.load(tmp_path / "m.npz").meta["frames"] == 50
    run = tmp_path / "vr"  # a 'reloc run' directory's clip partition and odometry
    run.mkdir()
    V = world["clips"][0]
    fr = sorted(V)
    np.savez(run / "clip_poses.npz", frames=np.array(fr), clip=np.zeros(len(fr), np.int64),
             V=np.stack([V[i] for i in fr]))
    world["pmap"].save(tmp_path / "full.npz")
    assert main(["run", "--map", str(tmp_path / "full.npz"), "--tour", str(world["query"].root), "--clips", str(run),
                 "--out", str(tmp_path / "out"), "--quiet"]) == 0
    assert "1/1 clips registered" in capsys.readouterr().out
    s = json.loads((tmp_path / "out" / "run.json").read_text())
    assert s["map_bytes"] == (tmp_path / "full.npz").stat().st_size and s["closure_frames"] == len(CLIP)
    assert main(["run", "--map", str(tmp_path / "nope.npz"), "--tour", str(world["query"].root), "--clips", str(run),
                 "--out", str(tmp_path / "out2"), "--quiet"]) == 2
    assert "nope.npz" in capsys.readouterr().err
