"""Appearance-based per-frame baseline (reloc.baselines.appearance) and the clip-rigid protocol (reloc.frontend.clip_rigid).

The tours are a textured box room (6 x 5 x 2.6 m) ray-cast exactly at 160x120: every pixel's colour
is a multi-scale value-noise texture of the WORLD point it sees (different per wall), so appearance is
consistent across views and SIFT finds repeatable, distinctive features; depth is planar z. The
correct poses are the ones the images were rendered from. No Blender.
"""

from __future__ import annotations

import json
import math
import time

import numpy as np
import pytest

from reloc.baselines.appearance import AppearanceConfig, AppearanceMap, localize_frame, run_appearance
from reloc.frontend.clip_rigid import clip_rigid_trajectory, fit_clip_transform
from reloc.geometry import exp_so3, inv_T, make_T, pose_distance

from vrformats import camera as cam
from vrformats.errors import UserError
from conftest import make_tour
from vrformats.tour import Tour


ROOM_LO = np.array([0.0, 0.0, 0.0])
ROOM_HI = np.array([6.0, 5.0, 2.6])
INTR = cam.Intrinsics.from_fov(160, 120, 75.0)
FPS = 30.0
TINTS = np.array([[1.0, 0.8, 0.6], [0.6, 0.9, 1.0], [0.9, 1.0, 0.7], [1.0, 0.7, 0.9], [0.8, 0.8, 0.8], [0.95, 0.9, 0.8]])


def _hash01(ix, iy, seed):
    h = (ix.astype(np.int64) * 73856093) ^ (iy.astype(np.int64) * 19349663) ^ (seed * 83492791)
    h = h.astype(np.uint64) * np.uint64(0x9E3779B97F4A7C15)
    h ^= h >> np.uint64(31)
    return (h & np.uint64(0xFFFFFF)).astype(np.float64) / float(0xFFFFFF)


def _value_noise(a, b, seed):
    ia, ib = np.floor(a), np.floor(b)
    fa, fb = a - ia, b - ib
    fa, fb = fa * fa * (3 - 2 * fa), fb * fb * (3 - 2 * fb)
    c00, c10 = _hash01(ia, ib, seed), _hash01(ia + 1, ib, seed)
    c01, c11 = _hash01(ia, ib + 1, seed), _hash01(ia + 1, ib + 1, seed)
    return (c00 * (1 - fa) + c10 * fa) * (1 - fb) + (c01 * (1 - fa) + c11 * fa) * fb


def render(T, intr=INTR):
    """(linear RGB radiance, planar depth) of the textured room seen from camera-to-world pose T."""
    rays = intr.pixel_rays()
    d = rays @ T[:3, :3].T
    o = T[:3, 3]
    with np.errstate(divide="ignore", invalid="ignore"):
        t_axis = np.where(d > 0, (ROOM_HI - o) / d, np.where(d < 0, (ROOM_LO - o) / d, np.inf))
    axis = t_axis.argmin(axis=-1)
    t = t_axis.min(axis=-1)
    pos = np.take_along_axis(d, axis[..., None], axis=-1)[..., 0] > 0
    plane = 2 * axis + pos  # 0..5: x-, x+, y-, y+, floor, ceiling
    p = o + t[..., None] * d
    # the two in-plane world coordinates
    a = np.choose(axis, [p[..., 1], p[..., 0], p[..., 0]])
    b = np.choose(axis, [p[..., 2], p[..., 2], p[..., 1]])
    tex = np.zeros_like(a)
    for k, (scale, amp) in enumerate(((0.35, 0.45), (0.12, 0.35), (0.05, 0.2))):
        tex += amp * _value_noise(a / scale, b / scale, plane * 10 + k)
    albedo = 0.04 + 0.9 * tex
    rgb = albedo[..., None] * TINTS[plane]
    return rgb.astype(np.float32), t.astype(np.float32)


def night(rgb, seed=0):
    """A dim, warm, noisy version of a radiance image (auto exposure brings the level back, not the noise)."""
    rng = np.random.default_rng(seed)
    dim = rgb * np.array([0.02, 0.012, 0.006], np.float32)
    return np.clip(dim + rng.normal(0.0, 0.003, rgb.shape), 0, None).astype(np.float32)


def texroom_tour(root, poses, images):
    """A tour of the textured room; images[i] = (rgb or None, depth)."""
    frames = {i: dict(rgb=rgb, depth=depth) for i, (rgb, depth) in enumerate(images)}
    return make_tour(root, poses, frames, intrinsics=INTR, fps=FPS, layout="texroom", lighting="day", path="test",
                     renderer="test")


def mapping_poses():
    """Two stations turning in 30 degree steps (the odd frames are rendered without RGB)."""
    out = []
    for pos in ((2.2, 2.0, 1.4), (3.8, 3.0, 1.5)):
        for k in range(12):
            for half in (0.0, 0.5):  # frame with RGB, then one in between without
                out.append(cam.pose_from_ypr(pos, yaw=math.radians(30.0 * (k + half)), pitch=-0.1))
    return out


QUERY_A = cam.pose_from_ypr((2.45, 2.2, 1.35), yaw=math.radians(47.0), pitch=-0.05, roll=0.03)
QUERY_B = cam.pose_from_ypr((3.6, 2.7, 1.45), yaw=math.radians(200.0), pitch=-0.15)


@pytest.fixture(scope="module")
def tours(tmp_path_factory):
    base = tmp_path_factory.mktemp("appearance")
    mp = mapping_poses()
    imgs = []
    for j, T in enumerate(mp):
        rgb, depth = render(T)
        imgs.append((rgb if j % 2 == 0 else None, depth))
    mapping = texroom_tour(base / "mapping", mp, imgs)
    rgb_a, depth_a = render(QUERY_A)
    rgb_b, depth_b = render(QUERY_B)
    q_poses = [QUERY_A, QUERY_B, QUERY_A, QUERY_A, QUERY_B]
    q_imgs = [(rgb_a, depth_a), (None, depth_b), (np.zeros_like(rgb_a), depth_a), (night(rgb_a), depth_a),
              (rgb_b, depth_b)]
    query = texroom_tour(base / "query", q_poses, q_imgs)
    t0 = time.perf_counter()
    amap = AppearanceMap.build(Tour(mapping))
    build_s = time.perf_counter() - t0
    return {"base": base, "mapping": mapping, "query": query, "map": amap, "build_s": build_s,
            "rgb_a": rgb_a, "rgb_b": rgb_b}


def _err(T, gt):
    pos, rot = pose_distance(T, gt)
    return pos, math.degrees(rot)


# ---------------------------------------------------------------------------------------------
# appearance map and per-frame localization


def test_map_uses_rgb_keyframes_only(tours):
    amap = tours["map"]
    assert list(amap.kf_frames) == list(range(0, 48, 2))  # the frames without RGB are not keyframes
    assert len(amap.xyz) > 24 * 50
    # the world points are where the ray-cast room says: on one of the six planes
    p = amap.xyz.astype(np.float64)
    dist = np.minimum(np.abs(p - ROOM_LO), np.abs(p - ROOM_HI)).min(axis=1)
    assert np.median(dist) < 1e-3 and (dist < 0.02).mean() > 0.98
    sub = AppearanceMap.build(Tour(tours["mapping"]), stride=3, cfg=AppearanceConfig(vocab_words=64))
    assert list(sub.kf_frames) == list(range(0, 48, 6))


def test_query_between_keyframes_is_localized(tours):
    amap = tours["map"]
    t0 = time.perf_counter()
    for rgb, gt in ((tours["rgb_a"], QUERY_A), (tours["rgb_b"], QUERY_B)):
        T, info = localize_frame(amap, rgb, INTR.K)
        assert T is not None, info
        pos, rot = _err(T, gt)
        assert pos < 0.05 and rot < 1.0, (pos, rot, info)
        assert info["inliers"] >= 50 and info["reason"] is None
        assert info["keyframe"] in amap.kf_frames
    ms = (time.perf_counter() - t0) * 500
    print(f"\nappearance map: {len(amap)} keyframes, {len(amap.xyz)} points, built in {tours['build_s']:.2f} s; "
          f"localization {ms:.1f} ms/frame")


def test_night_degrades(tours):
    amap = tours["map"]
    _, day = localize_frame(amap, tours["rgb_a"], INTR.K)
    Tn, dark = localize_frame(amap, night(tours["rgb_a"]), INTR.K)
    print(f"\nday: {day['inliers']} inliers / {day['matches']} matches; night: {dark['inliers']} / {dark['matches']}")
    assert dark["inliers"] < 0.7 * day["inliers"]
    assert dark["matches"] < day["matches"]
    if Tn is not None:  # when it still localizes, it is not a wild guess
        assert _err(Tn, QUERY_A)[0] < 0.5


def test_black_and_missing_images_give_none_with_a_reason(tours):
    amap = tours["map"]
    T, info = localize_frame(amap, np.zeros((120, 160, 3), np.float32), INTR.K)
    assert T is None and "feature" in info["reason"]
    T, info = localize_frame(amap, None, INTR.K)
    assert T is None and info["reason"] == "no RGB"
    flat = np.full((120, 160, 3), 0.3, np.float32)
    T, info = localize_frame(amap, flat, INTR.K)
    assert T is None and info["reason"]


def test_save_load_round_trip_and_bad_files(tours, tmp_path):
    amap = tours["map"]
    path = amap.save(tmp_path / "maps" / "app.npz")
    assert AppearanceMap.nbytes(path) == path.stat().st_size > 1000
    assert not [p for p in path.parent.iterdir() if p.name != "app.npz"]  # no temporary left behind
    back = AppearanceMap.load(path)
    assert back.cfg == amap.cfg and len(back) == len(amap)
    T1, i1 = localize_frame(amap, tours["rgb_a"], INTR.K)
    T2, i2 = localize_frame(back, tours["rgb_a"], INTR.K)
    assert np.allclose(T1, T2, atol=1e-9) and i1["inliers"] == i2["inliers"]
    bad = tmp_path / "corrupt.npz"
    bad.write_bytes(b"PK\x03\x04 this is not a zip archive")
    with pytest.raises(UserError, match="corrupt.npz"):
        AppearanceMap.load(bad)
    other = tmp_path / "other.npz"
    np.savez(other, a=np.zeros(3))
    with pytest.raises(UserError, match="other.npz: not an appearance map"):
        AppearanceMap.load(other)
    with pytest.raises(UserError, match="nothere.npz: appearance map not found"):
        AppearanceMap.load(tmp_path / "nothere.npz")


def test_run_appearance_writes_causal_and_clip_rigid(tours, tmp_path):
    amap = tours["map"]
    qt = Tour(tours["query"])
    gt = {int(i): qt.pose(int(i)) for i in qt.frame_indices}
    # one clip over all five frames; its odometry is the truth seen from an arbitrary clip frame
    S_true = make_T(exp_so3([0.1, -0.2, 1.0]), [1.0, -2.0, 0.3])
    clips = {7: {i: inv_T(S_true) @ gt[i] for i in gt}}
    out = tmp_path / "run"
    summary = run_appearance(qt, amap, out, clip_poses=clips, progress=False)
    assert summary["frames"] == 5 and summary["frames_rgb"] == 4  # frame 1 has no RGB: skipped
    assert summary["ms_per_frame"] > 0 and summary["clips_fitted"] == 1 and summary["clips_fallback"] == 0
    frames, poses = cam.read_tum(out / "causal.txt", fps=FPS)
    assert 0 in frames and 4 in frames and 1 not in frames and 2 not in frames
    for i, T in zip(frames, poses):
        if i in (0, 4):
            assert _err(T, gt[int(i)])[0] < 0.05
    rows = {r["frame"]: r for r in json.loads((out / "frames.json").read_text())}
    assert set(rows) == {0, 2, 3, 4} and rows[2]["reason"] and not rows[2]["localized"]
    cf, cp = cam.read_tum(out / "closure.txt", fps=FPS)
    assert list(cf) == [0, 1, 2, 3, 4]  # every frame of the clip, the one without RGB included
    for i, T in zip(cf, cp):  # S averages the supporting frames (the night frame's coarser estimate may be one)
        pos, rot = _err(T, gt[int(i)])
        assert pos < 0.1 and rot < 2.0
    run = json.loads((out / "run.json").read_text())
    assert run["localized"] == summary["localized"] and run["clips"] == 1
    # without clips: causal only, and no stale closure.txt
    summary = run_appearance(qt, amap, out, progress=False)
    assert "clips" not in summary and not (out / "closure.txt").exists() and (out / "causal.txt").exists()


def test_sift_variant_works(tours):
    cfg = AppearanceConfig(feature="sift", vocab_words=64)
    amap = AppearanceMap.build(Tour(tours["mapping"]), cfg=cfg)
    T, info = localize_frame(amap, tours["rgb_a"], INTR.K)
    assert T is not None, info
    pos, rot = _err(T, QUERY_A)
    assert pos < 0.05 and rot < 1.0
    with pytest.raises(UserError, match="feature"):
        AppearanceMap.build(Tour(tours["mapping"]), cfg=AppearanceConfig(feature="surf"))


# ---------------------------------------------------------------------------------------------
# clip-rigid protocol


def _clip(rng, n=40):
    """Odometry of a wandering clip: frame -> V_i."""
    V, p, yaw = {}, np.zeros(3), 0.0
    for i in range(n):
        yaw += rng.normal(0, 0.1)
        p = p + np.array([math.cos(yaw), math.sin(yaw), 0.0]) * 0.1
        V[100 + i] = make_T(exp_so3([0.0, 0.0, yaw]) @ exp_so3(rng.normal(0, 0.05, 3)), p)
    return V


def _noisy(T, rng, pos=0.02, rot_deg=0.5):
    return make_T(exp_so3(rng.normal(0, math.radians(rot_deg), 3)) @ T[:3, :3], T[:3, 3] + rng.normal(0, pos, 3))


def _random_pose(rng):
    return make_T(exp_so3(rng.normal(0, 1.5, 3)), rng.uniform(-5, 5, 3))


def test_fit_recovers_transform_with_outliers():
    rng = np.random.default_rng(1)
    V = _clip(rng)
    S = make_T(exp_so3([0.05, -0.03, 2.0]), [3.0, 1.0, 0.2])
    est = {}
    for k, (i, Vi) in enumerate(V.items()):
        if k % 5 == 4:
            continue  # no estimate for this frame
        est[i] = _random_pose(rng) if rng.random() < 0.3 else _noisy(S @ Vi, rng)
    n_out = sum(pose_distance(T, S @ V[i])[0] > 0.3 for i, T in est.items())
    assert n_out >= 6
    S_hat, support = fit_clip_transform(est, V)
    assert S_hat is not None
    assert support == len(est) - n_out
    for Vi in V.values():  # the fitted transform places every frame of the clip
        pos, rot = pose_distance(S_hat @ Vi, S @ Vi)
        assert pos < 0.05 and math.degrees(rot) < 1.0


def test_no_consensus_keeps_frame_estimates():
    rng = np.random.default_rng(2)
    V = _clip(rng, 20)
    est = {i: _random_pose(rng) for i in list(V)[::2]}
    S_hat, support = fit_clip_transform(est, V)
    assert S_hat is None and support == 1
    V2 = _clip(rng, 10)
    V2 = {i + 1000: v for i, v in V2.items()}
    S2 = make_T(exp_so3([0.0, 0.0, -1.0]), [1.0, 2.0, 0.0])
    est.update({i: _noisy(S2 @ v, rng) for i, v in list(V2.items())[:3]})
    est[5] = _random_pose(rng)  # a frame that is in no clip
    traj, stats = clip_rigid_trajectory(est, {1: V, 2: V2})
    assert stats["clips"] == 2 and stats["clips_fitted"] == 1 and stats["clips_fallback"] == 1
    for i in V:  # clip 1: exactly its frame estimates, nothing invented for the others
        if i in est:
            assert np.array_equal(traj[i], est[i])
        else:
            assert i not in traj
    assert set(V2) <= set(traj)  # clip 2: every frame covered
    for i, v in V2.items():
        assert pose_distance(traj[i], S2 @ v)[0] < 0.05
    assert np.array_equal(traj[5], est[5])
    # too little support for a consensus
    assert fit_clip_transform({}, V2) == (None, 0)
    one = {next(iter(V2)): S2 @ next(iter(V2.values()))}
    assert fit_clip_transform(one, V2) == (None, 1)
