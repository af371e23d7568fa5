"""Pose files of other relocalizers: read and write them in a stated convention. One place.

Every reader returns what the toolkit uses everywhere (``vrformats.camera``): tour frame index ->
4x4 **camera-to-world** pose ``T_world_cam`` in **OpenCV** camera axes (x right, y down, z forward).
A convention is always stated by the caller, never guessed from the file.

=========  =====================================================  ===============  ==============
name       one line per frame                                     direction        frame by
=========  =====================================================  ===============  ==============
tum        ``t tx ty tz qx qy qz qw``                             camera-to-world  t = frame / fps
ace        ``name qw qx qy qz tx ty tz r_err t_err inliers``      world-to-camera  file name
colmap     ``name qw qx qy qz tx ty tz``                          world-to-camera  file name
mapfree    ``name qw qx qy qz tx ty tz confidence``               world-to-camera  file name
=========  =====================================================  ===============  ==============

All four use OpenCV/COLMAP camera axes; only the direction and the field order differ. In the
world-to-camera conventions a world point maps as ``p_cam = R(q) @ p_world + t`` (so the camera
centre is ``-R(q).T @ t``), and the "world" is the frame of the map the method was given: for an
export of a tour, the tour's world frame.

Sources (read for this module):

- ace: nianticlabs/ace ``test_ace.py`` writes ``poses_<scene>_<session>.txt`` one line per test
  image: ``frame_name`` (the image's basename, ``Path(frame_path).name``), ``q_w q_x q_y q_z t_x t_y
  t_z r_err t_err inlier_count``, after ``out_pose = out_pose.inverse()`` of the camera-to-world
  estimate (the dataset's ``poses/*.txt`` are camera-to-world 4x4, ``dataset.py``); its
  ``eval_poses.py`` reads the 11 fields back and inverts them ("We saved the inverse pose").
  ``r_err`` (deg), ``t_err`` (m) are ACE's errors against the ground truth it was given and
  ``inliers`` its RANSAC inlier count: read and ignored here; ``write_poses`` writes ``-1 -1 -1``
  (not measured). A line with the 8 pose fields only is accepted too.
- colmap: cvg/Hierarchical-Localization ``hloc/localize_sfm.py`` (and ``hloc/utils/io.py``
  ``write_poses``) writes ``f"{name} {qvec} {tvec}"`` with ``qvec``/``tvec`` of pycolmap's
  ``cam_from_world`` (COLMAP's image pose, world-to-camera, quaternion ``w x y z``: newer versions
  reorder pycolmap's ``x y z w`` with ``quat[[3, 0, 1, 2]]``); ``name`` is the query's basename,
  or ``camera/basename`` with ``prepend_camera_name``. Not COLMAP's ``images.txt`` (two lines per
  image, ids): that is a model, not a results file.
- mapfree: nianticlabs/map-free-reloc ``benchmark/utils.py`` ``load_poses``: "The text file encodes
  world2cam poses with the format: imgpath qw qx qy qz tx ty tz [confidence]" and converts them to
  cam2world; submissions (``pose_<scene>.txt``, ``benchmark/mapfree.py``) carry the confidence (9
  fields), its ground-truth ``poses.txt`` does not (8 fields): both are accepted. The benchmark's
  world is the reference image's camera; here it is the tour's world frame. ``write_poses`` writes
  confidence 1.
- tum: ``vrformats.camera`` (TUM RGB-D ``t tx ty tz qx qy qz qw``, camera-to-world); here the time
  must lie within ``TUM_TIME_TOL`` (1 ms) of a frame time ``frame / fps``.

Names (ace, colmap, mapfree) are matched to tour frames through ``names``, an export manifest's
``"frames"`` (file name as the exporter wrote it -> tour frame index; ``load_names``). Names are
compared as ``/``-separated paths (``\\`` read as ``/``, ``.`` parts dropped). A name in the file
matches, in this order of rules, the first rule that finds anything deciding:

1. a manifest name equal to it;
2. manifest names it ends with, or that end with it, whole path parts only (an absolute path
   ``/data/exp/test/rgb/frame-000120.color.png`` ends with ``test/rgb/frame-000120.color.png``;
   ACE's ``frame-000120.color.png`` and hloc's ``seq-01/frame-000120.color.png`` are tails of
   ``test/rgb/...`` and ``test/seq-01/...`` names);
3. last resort: manifest names with the same basename.

A rule that finds names of two different frames is an error (ambiguous: e.g. the bare basename
``frame-000000.color.png`` when the export holds ``seq-01/`` and ``seq-02/``); names of one frame
(its colour and depth files) are fine. A name no rule matches is an error.

Errors are ``SceneFormatError(file, "line N", ...)``, one line, naming the line: wrong field count,
a non-number, a non-finite value, a quaternion whose norm is off 1 by more than ``QUAT_NORM_TOL``, a
time off the frame grid, an unknown or ambiguous name, a frame not in the tour (``frames``), a
frame given twice (both lines). ``#`` comment lines and blank lines are skipped. Names cannot hold
white space (the fields are white-space separated, as in every source above).
"""

from __future__ import annotations

import math
from pathlib import Path, PurePosixPath

import numpy as np

from .atomic import write_text_atomic
from .camera import matrix_to_quat, quat_to_matrix
from .errors import SceneFormatError, UserError
from .fields import is_integer
from .yamlfile import read_json

CONVENTIONS = ("tum", "ace", "colmap", "mapfree")
NAMED = ("ace", "colmap", "mapfree")
MANIFEST = "export.json"  # synth tour export's manifest; its "frames": file name -> tour frame index

TUM_TIME_TOL = 1e-3  # s: a TUM time further than this from frame / fps is not a frame time
QUAT_NORM_TOL = 1e-3

# accepted field counts and the line each count means (first: what write_poses writes)
_LAYOUT = {
    "tum": {8: "t tx ty tz qx qy qz qw"},
    "ace": {11: "name qw qx qy qz tx ty tz r_err t_err inliers", 8: "name qw qx qy qz tx ty tz"},
    "colmap": {8: "name qw qx qy qz tx ty tz"},
    "mapfree": {9: "name qw qx qy qz tx ty tz confidence", 8: "name qw qx qy qz tx ty tz"},
}
DIRECTION = {"tum": "camera-to-world", "ace": "world-to-camera", "colmap": "world-to-camera",
             "mapfree": "world-to-camera"}


def check_convention(convention, where: str | None = None) -> str:
    """The convention's name (lower case), or a UserError naming it (after ``where``, e.g. the
    option or spec field that gave it) and the known ones."""
    c = str(convention).strip().lower()
    if c not in CONVENTIONS:
        at = f"{where}: " if where else ""
        raise UserError(f"{at}unknown pose convention {convention!r} (known: {', '.join(CONVENTIONS)})")
    return c


def load_names(path) -> dict[str, int]:
    """An export's ``"frames"`` (file name -> tour frame index) from its folder (``export.json`` in
    it) or from a JSON file ``{"frames": {name: index, ...}}`` (a manifest, or one written by hand)."""
    p = Path(path)
    f = p / MANIFEST if p.is_dir() else p
    data = read_json(f, missing="not found (an export folder holding export.json, or a JSON file "
                                "{\"frames\": {file name: frame index}})", expect_object=False)
    if not isinstance(data, dict) or "frames" not in data:
        raise SceneFormatError(f, "frames", "missing: expected an export manifest {\"frames\": {file name: frame "
                               "index}} (the names a pose file uses)")
    frames = data["frames"]
    if not isinstance(frames, dict):
        raise SceneFormatError(f, "frames", f"expected a mapping file name -> frame index, got {type(frames).__name__}")
    for k, v in frames.items():
        if not is_integer(v) or v < 0:
            raise SceneFormatError(f, f"frames[{k!r}]", f"expected a frame index (integer >= 0), got {v!r}")
    return dict(frames)


def frame_names(names: dict[str, int]) -> dict[int, str]:
    """Frame index -> one file name (the first the manifest lists for it): ``write_poses``' ``names``."""
    out: dict[int, str] = {}
    for k, i in names.items():
        out.setdefault(int(i), k)
    return out


def _parts(name: str) -> tuple[str, ...]:
    return tuple(p for p in PurePosixPath(name.replace("\\", "/")).parts if p not in (".", ""))


class _Names:
    """Match a pose file's names to manifest names (the module docstring's three rules)."""

    def __init__(self, names: dict[str, int]):
        self.exact: dict[str, dict[int, str]] = {}
        self.tails: dict[str, dict[int, str]] = {}  # every whole-part tail of every name
        for key, i in names.items():
            parts = _parts(str(key))
            if not parts:
                continue
            self.exact.setdefault("/".join(parts), {}).setdefault(int(i), key)
            for k in range(len(parts)):
                self.tails.setdefault("/".join(parts[k:]), {}).setdefault(int(i), key)
        self.n = len(names)
        self.example = next(iter(names), None)

    def match(self, name: str) -> tuple[int | None, str]:
        """(frame, "") or (None, why)."""
        parts = _parts(name)
        if not parts:
            return None, "empty name"
        whole = "/".join(parts)
        rules = [self.exact.get(whole, {})]
        found: dict[int, str] = dict(self.tails.get(whole, {}))  # manifest names that end with it
        for k in range(1, len(parts)):  # manifest names it ends with
            for i, key in self.exact.get("/".join(parts[k:]), {}).items():
                found.setdefault(i, key)
        rules.append(found)
        rules.append(self.tails.get(parts[-1], {}))  # same basename
        for cand in rules:
            if len(cand) == 1:
                return next(iter(cand)), ""
            if len(cand) > 1:
                (i, a), (j, b) = sorted(cand.items())[:2]
                return None, (f"{name!r} is ambiguous: it matches {a!r} (frame {i}) and {b!r} (frame {j}) of the "
                              f"export's names (give the longer path)")
        return None, (f"{name!r} is not a file of the export (none of its {self.n} names matches, e.g. "
                      f"{self.example!r})")


def _numbers(path: Path, ln: int, tokens: list[str]) -> list[float]:
    try:
        v = [float(x) for x in tokens]
    except ValueError:
        bad = next(x for x in tokens if not _is_float(x))
        raise SceneFormatError(path, f"line {ln}", f"not a number: {bad!r}") from None
    if not all(math.isfinite(x) for x in v):
        raise SceneFormatError(path, f"line {ln}", f"non-finite value in {' '.join(tokens)!r}")
    return v


def _is_float(x: str) -> bool:
    try:
        float(x)
        return True
    except ValueError:
        return False


def _pose(path: Path, ln: int, q_wxyz, t, world_to_camera: bool) -> np.ndarray:
    q = np.asarray(q_wxyz, dtype=float)
    n = float(np.linalg.norm(q))
    if abs(n - 1.0) > QUAT_NORM_TOL:
        raise SceneFormatError(path, f"line {ln}", f"quaternion is not unit length (norm {n:.6f})")
    R = quat_to_matrix(q)
    t = np.asarray(t, dtype=float)
    T = np.eye(4)
    if world_to_camera:  # p_cam = R p_world + t  ->  p_world = R^T p_cam - R^T t
        T[:3, :3] = R.T
        T[:3, 3] = -R.T @ t
    else:
        T[:3, :3] = R
        T[:3, 3] = t
    return T


def read_poses(path, convention: str, names: dict[str, int] | None = None, fps: float | None = None,
               frames: set[int] | None = None) -> dict[int, np.ndarray]:
    """Tour frame index -> 4x4 camera-to-world (OpenCV axes) from a pose file written in ``convention``.

    Named conventions (ace, colmap, mapfree) need ``names`` (an export manifest's ``"frames"``: file
    name -> frame index; matched by the module docstring's rules: equal, whole-part tail either way,
    last resort the basename; a rule finding two frames is an error); tum needs ``fps`` (frame =
    round(t * fps); a time further than ``TUM_TIME_TOL`` from that frame's is an error naming the
    line). ``frames``: the tour's frame indices; a frame named in the file but absent from the tour
    is an error naming it and the line. Malformed lines (field count, non-numbers, non-unit
    quaternion beyond ``QUAT_NORM_TOL``), unknown names and frames given twice (both lines named)
    are ``SceneFormatError(path, "line N", ...)``; an unknown convention is a UserError naming the
    known ones. Comment (``#``) and blank lines are skipped. Poses come in file order."""
    conv = check_convention(convention)
    path = Path(path)
    named = conv in NAMED
    if named and names is None:
        raise UserError(f"{path}: {conv} pose files name frames by file name: the export's names are needed "
                        f"(its {MANIFEST} \"frames\")")
    if not named and (fps is None or not fps > 0):
        raise UserError(f"{path}: tum pose files give frames by time: the tour's fps is needed (got {fps!r})")
    if path.is_dir():
        raise UserError(f"{path}: is a folder, not a pose file")
    if not path.is_file():
        raise SceneFormatError(path, None, "pose file not found")
    try:
        text = path.read_text()
    except (OSError, UnicodeDecodeError) as e:
        raise SceneFormatError(path, None, f"cannot read ({e})") from None
    matcher = _Names(names) if named else None
    layout = _LAYOUT[conv]
    expected = " or ".join(f"{n} fields '{d}'" for n, d in layout.items())
    tour = None if frames is None else {int(i) for i in frames}
    out: dict[int, np.ndarray] = {}
    first: dict[int, int] = {}
    for ln, line in enumerate(text.splitlines(), start=1):
        s = line.strip()
        if not s or s.startswith("#"):
            continue
        tok = s.split()
        if len(tok) not in layout:
            raise SceneFormatError(path, f"line {ln}", f"{conv}: expected {expected}, got {len(tok)} fields")
        if named:
            v = _numbers(path, ln, tok[1:])
            T = _pose(path, ln, v[0:4], v[4:7], world_to_camera=True)
            k, why = matcher.match(tok[0])
            if k is None:
                raise SceneFormatError(path, f"line {ln}", why)
            what = f"{tok[0]!r}"
        else:
            v = _numbers(path, ln, tok)
            T = _pose(path, ln, (v[7], v[4], v[5], v[6]), v[1:4], world_to_camera=False)
            k = int(round(v[0] * fps))
            if abs(v[0] - k / fps) > TUM_TIME_TOL:
                raise SceneFormatError(path, f"line {ln}", f"t = {tok[0]} is not a frame time: the nearest frame {k} "
                                       f"is at {k / fps:.6f} s, {abs(v[0] - k / fps) * 1e3:.2f} ms away (t = frame / "
                                       f"fps, {fps:g} fps, tolerance {TUM_TIME_TOL * 1e3:g} ms)")
            what = f"t = {tok[0]}"
        if k < 0 or (tour is not None and k not in tour):
            span = f"{len(tour)} frames, {min(tour)}..{max(tour)}" if tour else "no frames"
            raise SceneFormatError(path, f"line {ln}", f"frame {k} ({what}) is not in the tour ({span})"
                                   if tour is not None else f"frame {k} ({what}) is negative")
        if k in first:
            raise SceneFormatError(path, f"line {ln}", f"frame {k} ({what}) already given on line {first[k]}")
        first[k] = ln
        out[k] = T
    return out


def _g(x: float) -> str:
    return f"{float(x):.12g}"


def write_poses(path, convention: str, poses: dict[int, np.ndarray], names: dict[int, str] | None = None,
                fps: float | None = None) -> Path:
    """Camera-to-world poses (frame index -> 4x4, OpenCV axes) into a pose file in ``convention``,
    atomically, in frame order: the inverse of ``read_poses`` (for tests, tools and external-method
    examples). Named conventions need ``names`` (frame index -> file name; ``frame_names`` of a
    manifest), tum needs ``fps``. Quaternions are written with w >= 0; ace's r_err, t_err, inliers
    as -1 (not measured), mapfree's confidence as 1."""
    conv = check_convention(convention)
    named = conv in NAMED
    if named and names is None:
        raise UserError(f"{path}: {conv} pose files name frames by file name: names are needed")
    if not named and (fps is None or not fps > 0):
        raise UserError(f"{path}: tum pose files give frames by time: fps is needed (got {fps!r})")
    lines = []
    for i in sorted(int(k) for k in poses):
        T = np.asarray(poses[i], dtype=float)
        if named:
            if i not in names:
                raise UserError(f"{path}: no file name for frame {i}")
            name = str(names[i])
            if not name or any(c.isspace() for c in name):
                raise UserError(f"{path}: file name {name!r} of frame {i} is empty or holds white space")
            R = T[:3, :3].T  # world-to-camera
            t = -R @ T[:3, 3]
            w, x, y, z = matrix_to_quat(R)
            fields = [name] + [_g(c) for c in (w, x, y, z, *t)]
            fields += {"ace": ["-1", "-1", "-1"], "colmap": [], "mapfree": ["1"]}[conv]
        else:
            w, x, y, z = matrix_to_quat(T[:3, :3])
            fields = [f"{i / fps:.6f}"] + [_g(c) for c in (*T[:3, 3], x, y, z, w)]
        lines.append(" ".join(fields))
    return write_text_atomic(path, "".join(ln + "\n" for ln in lines))
