"""``synth tour check``: a rendered tour on disk, checked (the reader is ``vrformats.tour.Tour``).

A tour directory, as the renderers write it (the format is ``vrformats.tour``)::

    TOUR/
      camera.json    {"width", "height", "K", "fx", "fy", "cx", "cy", "fps", + vrformats.camera.CAMERA_DOC keys}
      poses.txt      TUM, camera-to-world, OpenCV axes; frame index = round(t * fps); one line per frame
      objects.json   ground-truth boxes of the tour's layout (``vrformats.boxes``: videoreloc-boxes/1)
      meta.json      {"toolkit", "layout", "lighting" (null: geometry-only tour), "path", "renderer", "seed",
                      "settings", "frames": [first, last], "wall_time_s", ...}
      frames/NNNNNN.exr   one per frame (vrformats.frames: R, G, B half; Z; instance; semantic)
      previews/NNNNNN.png optional 8-bit sRGB previews

``check_tour``
is ``synth tour check``: completeness, readability, channels, sizes, depth values, ids against
objects.json, pose sanity and a multi-view depth consistency test between neighbouring frames
(it catches shifted or wrong poses, camera axes in the wrong convention and depth stored as ray
length instead of planar z; it does not catch a wrong focal length, which small camera motions
hardly reveal), and a brightness test: a lit tour whose RGB frames are nearly black fails (the
median over its RGB frames of each frame's 99th-percentile luminance, in linear RGB at exposure 1
as ``vrformats.tour.tonemap(rgb, 1.0)`` shows it, below ``DARK_P99_LUMINANCE``; a scene lit only
through windows it does not have, or a night preset without lamps, renders like that). The
contact sheet of one frame (``synth tour show``) is ``synth.tour.show``.

No Blender here; this module imports without bpy.
"""

from __future__ import annotations

import math
import sys
from pathlib import Path

import numpy as np

from vrformats.fields import terminal_safe
from vrformats import frames as fr
from vrformats.boxes import STRUCTURE_CLASSES, STRUCTURE_ID_MAX, STRUCTURE_ID_MIN
from vrformats.camera import Intrinsics
from vrformats.errors import UserError
from vrformats.tour import (CAMERA_FILE, FRAMES_DIR, META_FILE, OBJECTS_FILE, POSES_FILE, PREVIEWS_DIR, Tour,
                          images_from_channels, ranges_text, read_split_channels, scan_dir)

# depth consistency between neighbouring frames
CONSISTENCY_ABS_TOL_M = 0.02  # a pixel agrees within max(2 cm, 1 % of its depth)
CONSISTENCY_REL_TOL = 0.01
OCCLUSION_ABS_M = 0.05  # frame j sees something this much (or 5 %) in front: occluded, not compared
OCCLUSION_REL = 0.05
MIN_AGREEMENT = 0.9  # pairs below this are flagged ...
MIN_OVERLAP_PIXELS = 1000  # ... when they have at least this many compared pixels
PAIR_MAX_STEP = 5  # neighbours are i, i + k with k in 1..5
PAIR_MIN_MOVE_M, PAIR_MIN_TURN_DEG = 0.02, 1.0  # the camera moved ...
PAIR_GOOD_MOVE_M, PAIR_GOOD_TURN_DEG = 0.1, 5.0  # ... preferably this much ...
PAIR_MAX_MOVE_M, PAIR_MAX_TURN_DEG = 1.0, 30.0  # ... but the views still overlap
CLASS_MISMATCH_FRACTION = 0.005  # instance/semantic pairs disagreeing with objects.json on > 0.5 % of a frame
ROTATION_TOL = 1e-4
# a lit tour is nearly black when the median over its RGB frames of each frame's 99th-percentile
# luminance (Rec. 709 weights, as vrformats.tour.tonemap; linear RGB at exposure 1) is below this:
# 0.01 is sRGB 25/255 at exposure 1, i.e. the brightest 1 % of the frame is darker than a dim grey and
# auto exposure would have to scale the frame by about 90 to show it. The toolkit's renders lie far
# above (built-in apartment by day about 1.3; ReplicaCAD apt_0 with the stand-in stage: see docs/replicacad.md)
DARK_P99_LUMINANCE = 0.01
DARK_PERCENTILE = 99.0
LUMINANCE = np.array([0.2126, 0.7152, 0.0722], dtype=np.float32)  # vrformats.tour.tonemap's weights
PROBLEM_LINES_PER_KIND = 20  # text report: at most this many lines per kind of problem


def _pose_problem(T: np.ndarray) -> str | None:
    T = np.asarray(T, dtype=float)
    if not np.isfinite(T).all():
        return "non-finite values"
    if not np.allclose(T[3], [0.0, 0.0, 0.0, 1.0], atol=1e-9):
        return f"last row is {T[3].tolist()}, not [0, 0, 0, 1]"
    R = T[:3, :3]
    err = float(np.abs(R.T @ R - np.eye(3)).max())
    if err > ROTATION_TOL:
        return f"rotation is not orthonormal (max |R^T R - I| = {err:.2g})"
    det = float(np.linalg.det(R))
    if det < 0:
        return f"rotation is a reflection (det {det:.3f})"
    return None


def _relative_motion(Ta: np.ndarray, Tb: np.ndarray) -> tuple[float, float]:
    """(translation m, rotation deg) between two camera-to-world poses."""
    t = float(np.linalg.norm(Tb[:3, 3] - Ta[:3, 3]))
    R = Ta[:3, :3].T @ Tb[:3, :3]
    ang = math.degrees(math.acos(float(np.clip((np.trace(R) - 1.0) / 2.0, -1.0, 1.0))))
    return t, ang


def choose_pairs(poses: np.ndarray, usable, n: int, max_step: int = PAIR_MAX_STEP) -> list[tuple[int, int]]:
    """Up to ``n`` pairs (a, a + k) of positions in ``poses`` spread over the tour, k in 1..max_step.

    k is the smallest step over which the camera moved enough for a telling comparison (10 cm or
    5 deg), else the largest step over which it moved at all (2 cm or 1 deg), never so far that the
    views stop overlapping (1 m or 30 deg); a still camera gives the nearest usable neighbour. Only
    ``usable`` positions (frames with readable, valid depth and a proper pose) take part.
    """
    usable = np.asarray(usable, dtype=bool)
    N = len(poses)
    if n <= 0 or N < 2:
        return []
    pairs: list[tuple[int, int]] = []
    for anchor in np.unique(np.linspace(0, N - 2, min(n, N - 1)).round().astype(int)):
        a = int(anchor)
        while a < N - 1 and not usable[a]:
            a += 1
        if a >= N - 1:
            continue
        target = moved = nearest = None
        for b in range(a + 1, min(a + max_step, N - 1) + 1):
            if not usable[b]:
                continue
            move, turn = _relative_motion(poses[a], poses[b])
            if move > PAIR_MAX_MOVE_M or turn > PAIR_MAX_TURN_DEG:
                break
            nearest = b if nearest is None else nearest
            if move >= PAIR_MIN_MOVE_M or turn >= PAIR_MIN_TURN_DEG:
                moved = b
            if move >= PAIR_GOOD_MOVE_M or turn >= PAIR_GOOD_TURN_DEG:
                target = b
                break
        b = next((x for x in (target, moved, nearest) if x is not None), None)
        if b is not None and (a, b) not in pairs:
            pairs.append((a, b))
    return pairs


def _warp_compare(depth_i, T_i, depth_j, T_j, intr: Intrinsics, rays: np.ndarray) -> dict:
    """Back-project frame i's depth to the world, project it into frame j and compare with j's depth.

    Returns counts: ``compared`` (lands inside j on a surface, not occluded), ``agree``,
    ``occluded``, and the absolute differences of the compared pixels.
    """
    H, W = depth_i.shape
    d = depth_i.reshape(-1).astype(np.float64)
    valid = np.isfinite(d) & (d > 0)
    p_cam = rays.reshape(-1, 3)[valid] * d[valid, None]
    # camera i -> world -> camera j
    R_ji = T_j[:3, :3].T @ T_i[:3, :3]
    t_ji = T_j[:3, :3].T @ (T_i[:3, 3] - T_j[:3, 3])
    q = p_cam @ R_ji.T + t_ji
    z = q[:, 2]
    front = z > 1e-6
    q, z = q[front], z[front]
    u = intr.fx * q[:, 0] / z + intr.cx
    v = intr.fy * q[:, 1] / z + intr.cy
    inside = (u >= 0) & (u <= W - 1) & (v >= 0) & (v <= H - 1)
    u, v, z = u[inside], v[inside], z[inside]
    u0 = np.minimum(np.floor(u).astype(np.int64), W - 2) if W > 1 else np.zeros(len(u), np.int64)
    v0 = np.minimum(np.floor(v).astype(np.int64), H - 2) if H > 1 else np.zeros(len(v), np.int64)
    du, dv = u - u0, v - v0
    dj = depth_j.astype(np.float64)
    u1, v1 = np.minimum(u0 + 1, W - 1), np.minimum(v0 + 1, H - 1)
    nb = np.stack([dj[v0, u0], dj[v0, u1], dj[v1, u0], dj[v1, u1]], axis=1)  # 2x2 neighbours
    nb_ok = np.isfinite(nb) & (nb > 0)
    # bilinear interpolation of inverse depth (exact on planes) where all four neighbours hit
    all_ok = nb_ok.all(axis=1)
    with np.errstate(divide="ignore", invalid="ignore"):
        inv = np.where(nb_ok, 1.0 / np.where(nb_ok, nb, 1.0), 0.0)
        wts = np.stack([(1 - du) * (1 - dv), du * (1 - dv), (1 - du) * dv, du * dv], axis=1)
        interp = np.where(all_ok, 1.0 / np.maximum((inv * wts).sum(axis=1), 1e-12), np.nan)
    cand = np.concatenate([nb, interp[:, None]], axis=1)
    cand_ok = np.concatenate([nb_ok, all_ok[:, None]], axis=1)
    any_ok = cand_ok.any(axis=1)
    diff = np.where(cand_ok, cand - z[:, None], np.inf)
    best = np.take_along_axis(diff, np.abs(diff).argmin(axis=1)[:, None], axis=1)[:, 0]
    best, zz = best[any_ok], z[any_ok]
    occluded = best < -np.maximum(OCCLUSION_ABS_M, OCCLUSION_REL * zz)
    cmp_diff = np.abs(best[~occluded])
    tol = np.maximum(CONSISTENCY_ABS_TOL_M, CONSISTENCY_REL_TOL * zz[~occluded])
    return {
        "in_view": int(any_ok.sum()),
        "occluded": int(occluded.sum()),
        "compared": int(len(cmp_diff)),
        "agree": int((cmp_diff <= tol).sum()),
        "abs_diff": cmp_diff,
    }


def depth_consistency(depth_i, T_i, depth_j, T_j, intr: Intrinsics, rays: np.ndarray | None = None) -> dict:
    """Agreement of two depth maps of the same static scene, warped both ways (i -> j and j -> i).

    A pixel agrees when the warped depth is within max(2 cm, 1 % of depth) of what the other
    frame sees there; pixels where the other frame sees something clearly in front are occluded
    and not compared. Checking both directions makes a wrong pose show up whichever way it errs.
    """
    rays = intr.pixel_rays() if rays is None else rays
    a = _warp_compare(depth_i, T_i, depth_j, T_j, intr, rays)
    b = _warp_compare(depth_j, T_j, depth_i, T_i, intr, rays)
    compared = a["compared"] + b["compared"]
    in_view = a["in_view"] + b["in_view"]
    diffs = np.concatenate([a["abs_diff"], b["abs_diff"]])
    return {
        "compared_pixels": compared,
        "agreement": round((a["agree"] + b["agree"]) / compared, 4) if compared else None,
        "median_abs_diff_m": round(float(np.median(diffs)), 4) if compared else None,
        "occluded_fraction": round((a["occluded"] + b["occluded"]) / in_view, 4) if in_view else None,
    }


def check_tour(root, consistency_pairs: int = 8, progress: bool | None = None) -> dict:
    """Check a rendered tour (``synth tour check``); returns a JSON-serialisable report.

    Unusable input (no directory, no or bad camera.json / poses.txt / meta.json) raises
    ``UserError``; everything else is reported: ``ok`` is True when ``problems`` is empty, and
    ``problems`` has one readable line per problem. Frames are read one at a time.
    """
    tour = Tour(root, strict=False)
    N = len(tour)
    rep: dict = {
        "tour": str(tour.root),
        "ok": False,
        "problems": [],
        "problem_counts": {},
        "problem_total": 0,
        "frames_expected": N,
        "frames_found": 0,
        "frame_files": 0,
        "missing": [],
        "extra_frames": [],
        "unreadable": [],
        "stray_temp_files": [],
        "channels": [],
        "missing_channels": [],
        "shape_mismatch": [],
        "bad_depth": [],
        "bad_rgb": [],
        "unknown_ids": [],
        "class_mismatch": [],
        "bad_poses": [],
        "consistency": {},
        "brightness": {},
        "errors": [],
        "warnings": [],
    }
    present = _check_files(tour, rep)
    known = _check_objects(tour, rep)
    _check_poses(tour, rep)
    frame_channels, depth_ok, rgb_p99 = _check_frames(tour, rep, present, known, progress)
    _check_channels(tour, rep, frame_channels)
    rep["consistency"] = _consistency(tour, depth_ok, consistency_pairs)
    rep["brightness"] = _brightness(rgb_p99)  # a lit tour must not be black
    meta_count_bad = _summary_lines(tour, rep)
    rep["problem_counts"] = _problem_counts(rep, meta_count_bad)
    rep["problem_total"] = sum(rep["problem_counts"].values())
    rep["ok"] = not rep["problems"]
    return rep


def _check_files(tour: Tour, rep: dict) -> set[int]:
    """Files on disk: frames present, missing and extra; stray temporaries; failed-render leftovers."""
    expected = {int(i) for i in tour.frame_indices}
    present: set[int] = set()
    for d in (tour.root, tour.frames_dir, tour.root / PREVIEWS_DIR):
        for e in scan_dir(d):
            if e.name.startswith(".") and e.name.endswith(".tmp"):
                rep["stray_temp_files"].append(str(Path(e.path).relative_to(tour.root)))
            elif d == tour.root and e.name.startswith(".jobs_") and e.is_dir():
                rep["warnings"].append(f"{e.name}/: render jobs and logs left by a failed render (see synth.tour.render)")
            elif d == tour.frames_dir and e.name.endswith(".exr") and e.name[:-4].isdigit():
                present.add(int(e.name[:-4]))
    rep["stray_temp_files"].sort()
    if not tour.frames_dir.is_dir():
        rep["errors"].append(f"{tour.frames_dir}: frames folder not found")
    rep["missing"] = sorted(expected - present)
    rep["extra_frames"] = sorted(present - expected)
    rep["frames_found"] = len(expected & present)
    rep["frame_files"] = len(present)

    meta_frames = tour.meta.get("frames")
    fi = tour.frame_indices
    if isinstance(meta_frames, list) and len(meta_frames) == 2 and list(meta_frames) != [int(fi.min()), int(fi.max())]:
        rep["warnings"].append(f"{META_FILE}: frames is {meta_frames}, poses.txt spans [{int(fi.min())}, {int(fi.max())}]")
    return present


def _check_objects(tour: Tour, rep: dict):
    """objects.json: the known instance and semantic ids, instance -> class id; None when unreadable."""
    inst_to_sem: dict[int, int] = {}
    try:
        objs = tour.objects()
        classes = {k: int(v) for k, v in objs["classes"].items()}
        known_inst = {int(b["id"]) for b in objs["boxes"]}
        known_sem = set(classes.values()) | {0}
        for b in objs["boxes"]:
            if b.get("class") in classes:
                inst_to_sem[int(b["id"])] = classes[b["class"]]
        inst_to_sem[0] = 0
    except UserError as e:
        rep["errors"].append(str(e))
        return None
    return known_inst, known_sem, inst_to_sem, classes


def _check_poses(tour: Tour, rep: dict) -> None:
    for i, T in zip(tour.frame_indices, tour.poses):
        why = _pose_problem(T)
        if why:
            rep["bad_poses"].append({"frame": int(i), "why": why})


def _check_frames(tour: Tour, rep: dict, present: set[int], known, progress):
    """Every frame, one at a time: readable, the camera's size, valid depth and RGB, known ids.
    Returns the channels of each frame, which frames have valid depth, and each RGB frame's brightness."""
    from tqdm import tqdm

    H, W = tour.intrinsics.height, tour.intrinsics.width
    frame_channels: dict[int, frozenset] = {}
    depth_ok = np.zeros(len(tour), dtype=bool)
    rgb_p99: dict[int, float] = {}  # frame -> 99th-percentile linear luminance
    if progress is None:
        progress = sys.stderr.isatty()
    for k, idx in enumerate(tqdm(tour.frame_indices, desc=terminal_safe(f"checking {tour.name}"), unit="frame", disable=not progress)):
        idx = int(idx)
        if idx not in present:
            continue
        path = tour.frame_path(idx)
        try:
            ch = read_split_channels(path)
        except fr.FrameFileError as e:
            rep["unreadable"].append({"frame": idx, "file": str(path), "error": str(e)})
            continue
        names = frozenset(ch)
        frame_channels[idx] = names
        shapes = {tuple(a.shape[:2]) for a in ch.values()}
        if shapes != {(H, W)}:
            rep["shape_mismatch"].append({"frame": idx, "shape": [list(s) for s in sorted(shapes)], "expected": [H, W]})
            continue
        img = images_from_channels(ch)
        del ch
        why = _depth_problem(img.depth)
        if why is True:
            depth_ok[k] = True
        elif why is not None:
            rep["bad_depth"].append({"frame": idx, **why})
        if img.rgb is not None:
            nonfinite = int((~np.isfinite(img.rgb)).sum())
            if nonfinite:
                rep["bad_rgb"].append({"frame": idx, "why": f"{nonfinite} NaN/inf values"})
            rgb_p99[idx] = frame_brightness(img.rgb)
        if known is not None:
            _check_ids(rep, idx, img, known)
        del img
    return frame_channels, depth_ok, rgb_p99


def _depth_problem(d):
    """None without depth, True for valid depth, else {"why": text, "kinds": [...]}."""
    if d is None:
        return None
    why = []
    nonfinite = int((~np.isfinite(d)).sum())
    if nonfinite:
        why.append(f"{nonfinite} NaN/inf pixels")
    neg = int((d < 0).sum())
    if neg:
        why.append(f"{neg} negative pixels")
    kinds = (["nonfinite"] if nonfinite else []) + (["negative"] if neg else [])
    if not (d > 0).any():
        why.append("all zero (no surface hit)")
        kinds.append("all_zero")
    return {"why": "; ".join(why), "kinds": kinds} if why else True


def _check_ids(rep: dict, idx: int, img, known) -> None:
    """A frame's instance and semantic ids against objects.json."""
    known_inst, known_sem, inst_to_sem, classes = known
    entry: dict = {}
    if img.instance is not None:
        ids = np.unique(img.instance)
        bad = [int(x) for x in ids if x != 0 and int(x) not in known_inst and not STRUCTURE_ID_MIN <= x <= STRUCTURE_ID_MAX]
        if bad:
            entry["instance"] = bad
    if img.semantic is not None:
        bad = [int(x) for x in np.unique(img.semantic) if int(x) not in known_sem]
        if bad:
            entry["semantic"] = bad
    if entry:
        rep["unknown_ids"].append({"frame": idx, **entry})
    if img.instance is not None and img.semantic is not None:
        mm = _class_mismatch(img.instance, img.semantic, inst_to_sem, classes)
        if mm is not None:
            rep["class_mismatch"].append({"frame": idx, **mm})


def _check_channels(tour: Tour, rep: dict, frame_channels: dict) -> None:
    """Channels every frame should have: depth, ids and (for lit tours) RGB."""
    expect_rgb = (tour.meta.get("lighting") is not None) if "lighting" in tour.meta else None
    rep["channels"] = sorted(set().union(*frame_channels.values()))
    want = {fr.DEPTH_CHANNEL, fr.INSTANCE_CHANNEL, fr.SEMANTIC_CHANNEL}
    if expect_rgb is None:
        expect_rgb = any(set(fr.RGB_CHANNELS) <= c for c in frame_channels.values())
    every = tour.rgb_every
    for idx, names in sorted(frame_channels.items()):
        lack = sorted(want - names)
        if expect_rgb and idx % every == 0:
            lack = sorted((want | set(fr.RGB_CHANNELS)) - names)
        if lack:
            rep["missing_channels"].append({"frame": idx, "missing": lack})
    if expect_rgb is False and any(set(fr.RGB_CHANNELS) <= c for c in frame_channels.values()):
        rep["warnings"].append(f"{META_FILE}: lighting is null (geometry-only) but frames have R, G, B")


def _summary_lines(tour: Tour, rep: dict) -> bool:
    """One readable line per problem (capped per kind) into rep["problems"]; returns whether
    meta.json's frame count disagrees with poses.txt."""
    problems: list[str] = rep["problems"]
    N = len(tour)
    H, W = tour.intrinsics.height, tour.intrinsics.width
    def capped(kind_lines: list[str]) -> None:
        problems.extend(kind_lines[:PROBLEM_LINES_PER_KIND])
        if len(kind_lines) > PROBLEM_LINES_PER_KIND:
            problems.append(f"... and {len(kind_lines) - PROBLEM_LINES_PER_KIND} more like the above")

    problems.extend(rep["errors"])
    if rep["missing"]:
        problems.append(f"missing frames ({len(rep['missing'])} of {N}, no EXR in {FRAMES_DIR}/): {ranges_text(rep['missing'])}")
    if rep["extra_frames"]:
        problems.append(f"frames not in {POSES_FILE} ({len(rep['extra_frames'])}): {ranges_text(rep['extra_frames'])}")
    n_meta = tour.disagreeing_n_frames()
    meta_count_bad = n_meta is not None
    if meta_count_bad:
        problems.append(f"{POSES_FILE} has {N} poses, but {META_FILE} says the tour has {n_meta} frames (n_frames)")
    capped([f"unreadable frame {u['frame']}: {u['error']}" for u in rep["unreadable"]])
    capped([f"stray temporary file (interrupted write?): {p}" for p in rep["stray_temp_files"]])
    capped([f"frame {m['frame']}: missing channel(s) {', '.join(m['missing'])}" for m in rep["missing_channels"]])
    capped([f"frame {s['frame']}: size {' / '.join('x'.join(map(str, sh[::-1])) for sh in s['shape'])}, "
            f"{CAMERA_FILE} says {W}x{H}" for s in rep["shape_mismatch"]])
    capped([f"frame {b['frame']}: bad depth: {b['why']}" for b in rep["bad_depth"]])
    capped([f"frame {b['frame']}: bad RGB: {b['why']}" for b in rep["bad_rgb"]])
    lines = []
    for u in rep["unknown_ids"]:
        what = []
        if "instance" in u:
            what.append(f"instance ids {u['instance']} (not in {OBJECTS_FILE}, not structure {STRUCTURE_ID_MIN}-{STRUCTURE_ID_MAX})")
        if "semantic" in u:
            what.append(f"semantic ids {u['semantic']} (not in {OBJECTS_FILE} classes)")
        lines.append(f"frame {u['frame']}: unknown " + "; ".join(what))
    capped(lines)
    capped([f"frame {m['frame']}: instance/semantic disagree with {OBJECTS_FILE} on {m['fraction']:.1%} of pixels "
            f"(instance, semantic, expected): {m['pairs']}" for m in rep["class_mismatch"]])
    capped([f"frame {b['frame']}: bad pose: {b['why']}" for b in rep["bad_poses"]])
    br = rep["brightness"]
    if br.get("dark"):
        light = tour.meta.get("lighting")
        problems.append(f"tour {tour.name} ({f'lighting {light}' if light is not None else 'lighting unknown'}) is nearly black: "
                        f"median 99th-percentile luminance {br['median_p99_luminance']:.3g} over its {br['rgb_frames']} RGB "
                        f"frames (linear, exposure 1), below {DARK_P99_LUMINANCE:g} (no light reaches the camera: "
                        "windows or lamps missing?)")
    capped([f"frames {p['frames'][0]} -> {p['frames'][1]}: depth inconsistent with poses: "
            f"{p['agreement']:.1%} of {p['compared_pixels']} pixels agree (need {MIN_AGREEMENT:.0%}), "
            f"median |diff| {p['median_abs_diff_m'] * 100:.1f} cm" for p in rep["consistency"]["pairs"] if p["flagged"]])
    return meta_count_bad


def _problem_counts(rep: dict, meta_count_bad: bool) -> dict:
    """How many problems of each kind (the text lines are capped per kind); kinds with none left out."""
    br = rep["brightness"]
    depth_kinds = {"all_zero": "frames with all-zero depth", "nonfinite": "frames with NaN/inf depth",
                   "negative": "frames with negative depth"}
    counts = {
        "errors reading the tour's files": len(rep["errors"]),
        "missing frames": len(rep["missing"]),
        f"frame files without a pose in {POSES_FILE}": len(rep["extra_frames"]),
        f"{META_FILE} frame count disagreeing with {POSES_FILE}": int(meta_count_bad),
        "unreadable frames": len(rep["unreadable"]),
        "stray temporary files": len(rep["stray_temp_files"]),
        "frames missing channels": len(rep["missing_channels"]),
        "frames of the wrong size": len(rep["shape_mismatch"]),
        **{label: sum(k in b["kinds"] for b in rep["bad_depth"]) for k, label in depth_kinds.items()},
        "frames with NaN/inf RGB": len(rep["bad_rgb"]),
        f"frames with ids unknown to {OBJECTS_FILE}": len(rep["unknown_ids"]),
        f"frames whose instance/semantic ids disagree with {OBJECTS_FILE}": len(rep["class_mismatch"]),
        "bad poses": len(rep["bad_poses"]),
        "nearly black tours": int(bool(br.get("dark"))),
        "frame pairs with depth inconsistent with the poses": len(rep["consistency"]["flagged"]),
    }
    return {k: v for k, v in counts.items() if v}


def frame_brightness(rgb) -> float:
    """The 99th-percentile luminance of linear RGB (exposure 1, ``vrformats.tour.tonemap``'s weights)."""
    rgb = np.nan_to_num(np.asarray(rgb, dtype=np.float32), nan=0.0, posinf=0.0, neginf=0.0)
    lum = rgb.reshape(-1, 3) @ LUMINANCE
    return float(np.percentile(lum, DARK_PERCENTILE)) if lum.size else 0.0


def _brightness(rgb_p99: dict[int, float]) -> dict:
    """The brightness summary of the tour's RGB frames; ``dark`` when the median is below the threshold."""
    if not rgb_p99:
        return {"rgb_frames": 0}
    v = np.array(list(rgb_p99.values()))
    med = float(np.median(v))
    return {"rgb_frames": len(v), "median_p99_luminance": round(med, 6), "min_p99_luminance": round(float(v.min()), 6),
            "max_p99_luminance": round(float(v.max()), 6), "threshold": DARK_P99_LUMINANCE,
            "dark": bool(med < DARK_P99_LUMINANCE)}


def _class_mismatch(instance, semantic, inst_to_sem: dict[int, int], classes: dict[str, int]) -> dict | None:
    """Pixels whose (instance, semantic) pair contradicts objects.json, if more than a sliver of the frame."""
    key = (instance.astype(np.uint64) << np.uint64(32)) | semantic.astype(np.uint64)
    pairs, counts = np.unique(key, return_counts=True)
    bad_px, bad_pairs = 0, []
    for p, c in zip(pairs, counts):
        inst, sem = int(p >> np.uint64(32)), int(p & np.uint64(0xFFFFFFFF))
        exp = inst_to_sem.get(inst)
        if exp is None and STRUCTURE_ID_MIN <= inst <= STRUCTURE_ID_MAX:
            for base, cls in STRUCTURE_CLASSES:
                if base <= inst < base + 1000:
                    exp = classes.get(cls)
        if exp is not None and exp != sem:
            bad_px += int(c)
            bad_pairs.append((int(c), [inst, sem, exp]))
    frac = bad_px / instance.size
    if frac <= CLASS_MISMATCH_FRACTION:
        return None
    bad_pairs.sort(key=lambda x: -x[0])
    return {"pixels": bad_px, "fraction": round(frac, 4), "pairs": [p for _, p in bad_pairs[:5]]}


def _consistency(tour: Tour, depth_ok: np.ndarray, n_pairs: int) -> dict:
    intr = tour.intrinsics
    rays = intr.pixel_rays()
    pose_ok = np.array([_pose_problem(T) is None for T in tour.poses])
    pairs = choose_pairs(tour.poses, depth_ok & pose_ok, n_pairs)
    out = []
    for a, b in pairs:
        ia, ib = int(tour.frame_indices[a]), int(tour.frame_indices[b])
        try:
            da = tour.frame(ia, rgb=False, instance=False, semantic=False).depth
            db = tour.frame(ib, rgb=False, instance=False, semantic=False).depth
        except UserError:
            continue  # reported by the frame pass
        res = depth_consistency(da, tour.poses[a], db, tour.poses[b], intr, rays)
        move, turn = _relative_motion(tour.poses[a], tour.poses[b])
        flagged = bool(res["compared_pixels"] >= MIN_OVERLAP_PIXELS and res["agreement"] < MIN_AGREEMENT)
        out.append({"frames": [ia, ib], "baseline_m": round(move, 4), "rotation_deg": round(turn, 3), **res,
                    "flagged": flagged})
    agreements = [p["agreement"] for p in out if p["agreement"] is not None]
    return {
        "tolerance": f"max({CONSISTENCY_ABS_TOL_M * 100:g} cm, {CONSISTENCY_REL_TOL:.0%} of depth)",
        "min_agreement": MIN_AGREEMENT,
        "pairs": out,
        "flagged": [p["frames"] for p in out if p["flagged"]],
        "worst_agreement": min(agreements) if agreements else None,
    }


def format_report(rep: dict) -> str:
    """The text form of a check report: a summary, then one line per problem."""
    n, files, found = rep["frames_expected"], rep.get("frame_files", rep["frames_found"]), rep["frames_found"]
    count = f"{found}/{n} frames" if files == found == n else f"{n} poses for {files} frame files"
    lines = [f"{rep['tour']}: {count}, channels {' '.join(rep['channels']) or '-'}"]
    c = rep.get("consistency") or {}
    pairs = c.get("pairs") or []
    if pairs:
        ag = [p["agreement"] for p in pairs if p["agreement"] is not None]
        med = [p["median_abs_diff_m"] for p in pairs if p["median_abs_diff_m"] is not None]
        lines.append(f"  depth consistency: {len(pairs)} frame pairs, agreement within {c['tolerance']}: "
                     f"worst {min(ag):.1%}" + (f", median |diff| up to {max(med) * 100:.1f} cm" if med else "")
                     if ag else f"  depth consistency: {len(pairs)} frame pairs without overlap")
    else:
        lines.append("  depth consistency: no usable frame pairs")
    b = rep.get("brightness") or {}
    if b.get("rgb_frames"):
        lines.append(f"  brightness: 99th-percentile luminance (linear, exposure 1) median {b['median_p99_luminance']:.3g} "
                     f"over {b['rgb_frames']} RGB frames (min {b['min_p99_luminance']:.3g}, max {b['max_p99_luminance']:.3g}; "
                     f"nearly black below {b['threshold']:g})")
    for w in rep.get("warnings", []):
        lines.append(f"  warning: {w}")
    for p in rep["problems"]:
        lines.append(f"  {p}")
    if rep["ok"]:
        lines.append("  OK")
    else:
        counts = rep.get("problem_counts") or {}
        total = rep.get("problem_total", len(rep["problems"]))
        lines.append(f"  PROBLEMS FOUND ({total}): " + ", ".join(f"{v} {k}" for k, v in counts.items())
                     if counts else f"  PROBLEMS FOUND ({len(rep['problems'])})")
    return "\n".join(lines)
