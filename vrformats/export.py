"""``synth tour export``: a tour in the layouts other relocalizers already read.

It lives in ``vrformats`` (no Blender, no scene model) because both sides use it: the ``synth tour
export`` command (``synth.tour.cli``) and ``reloc experiment``'s external methods
(``reloc.experiments.external``). With ``vrformats.tour`` (the reader and the tour folder's
conventions) it is the tour's only format-side home; the tour's synth-side code is ``synth.tour``.

Other people's relocalizers (ACE, DSAC*, hloc, RGB-D SLAM systems) get our tours through four
layouts, each written the way its own loader reads it (sources below). Every export folder holds
``export.json`` (format ``synth-export/1``), written last and atomically: the export's format, role,
tour (path and content key), intrinsics in the toolkit's and in the tool's convention, depth
encoding, exposure, the exported frames by file name (``frames``: name relative to the export root
-> tour frame index) and the geometry-only frames left out (``skipped``). ``vrformats.poses`` and
``reloc eval --poses`` map the tools' pose files back to tour frames with it.

Frame files keep the tour's frame index in their names (``frame-000120.color.png`` is tour frame
120), so names do not depend on which frames are skipped; the tools list or sort files and do not
need contiguous numbers.

Layouts (``role`` "mapping" or "query")::

    7scenes    seq-01/ (mapping) or seq-02/ (query): frame-NNNNNN.color.png, .depth.png, .pose.txt
               TrainSplit.txt / TestSplit.txt ("sequence1" / "sequence2" in the role's split, the
               other split empty), intrinsics.txt (3x3 K: 7-Scenes itself has no intrinsics file)
    ace        train/ (mapping) or test/ (query): rgb/frame-NNNNNN.color.png,
               depth/frame-NNNNNN.depth.png, poses/frame-NNNNNN.pose.txt,
               calibration/frame-NNNNNN.calibration.txt (3x3 K)
    dsacstar   the ace layout, each calibration file one number: fx (DSAC*, ACE's one-number path)
    tum-rgbd   rgb/NNNNNN.png, depth/NNNNNN.png, rgb.txt, depth.txt, groundtruth.txt,
               associations.txt, intrinsics.txt
    colmap     images/frame-NNNNNN.png, sparse/{cameras,images,points3D}.txt,
               queries_with_intrinsics.txt (query role: hloc's query list)

Conventions, and where they come from:

- 7-Scenes as DSAC*, ACE and hloc read it (Microsoft RGB-D 7-Scenes; ``nianticlabs/ace``
  ``datasets/setup_7scenes.py``, ``cvg/Hierarchical-Localization``
  ``hloc/pipelines/7Scenes/create_gt_sfm.py``): ``seq-XX/frame-NNNNNN.color.png`` 8-bit sRGB,
  ``.depth.png`` uint16 millimetres, ``.pose.txt`` a 4x4 camera-to-world matrix (``np.loadtxt``);
  ``TrainSplit.txt``/``TestSplit.txt`` list ``sequenceN``, which the setup scripts map to
  ``seq-0N`` (``'seq-' + s.strip()[8:].zfill(2)``). The original dataset marks missing depth with
  65535; we write 0, which is what the readers test for (hloc: ``depth == 0 | depth > 1000 m``
  is NaN; DSAC*/ACE: ``depth == 0`` gives no target). 7-Scenes ships no intrinsics: the setup
  scripts hard-code fx = fy = 525 and the image centre, so a user must take our K
  (``intrinsics.txt`` / export.json) instead.
- ACE (``nianticlabs/ace`` ``dataset.py``, ``test_ace.py``): ``{train,test}/{rgb,depth,poses,
  calibration}``, each folder sorted on its own and matched by position (so every exported frame
  has all four files); poses are 4x4 camera-to-world; depth uint16 mm (``depth /= 1000``);
  calibration via ``np.loadtxt``: one number (focal length, principal point then the image
  centre W/2, H/2) or a 3x3 K whose fx, fy, cx, cy are used as given (``test_ace.py`` asserts
  fx == fy). ACE and DSAC* place pixel u at coordinate u (their depth-to-camera code takes
  ``depth[4::8]`` at x = 8i + 4 minus the principal point), the toolkit's convention, so K is
  written unchanged. ``test_ace.py`` writes its estimates as ``NAME qw qx qy qz tx ty tz ...``
  with NAME the rgb file's base name and the pose world-to-camera.
- DSAC* (``vislearn/dsacstar`` ``dataset.py``): the same layout, but the calibration file must be
  ONE focal length (``float(np.loadtxt(f))``: our 3x3 files do not load) and the principal
  point is assumed at W/2, H/2 ("assume image center"). The toolkit's centred camera has
  cx = (W - 1) / 2: DSAC* would put it half a pixel right of and below ours. Recorded in
  export.json (``intrinsics.dsacstar``). ``--format dsacstar`` writes that layout: the ace one
  with fx as the one number (refused when fx != fy).
- TUM RGB-D (the benchmark's file-format page; read by RGB-D SLAM systems and evo):
  ``rgb.txt``/``depth.txt`` ("timestamp filename"), 8-bit colour PNGs, 16-bit depth PNGs scaled
  by 5000 (5000 = 1 m, 0 = no data), ``groundtruth.txt`` "timestamp tx ty tz qx qy qz qw",
  camera-to-world, as our poses.txt (t = frame / fps). ``associations.txt`` is what the
  benchmark's ``associate.py`` would produce for frames with both images. Depth beyond
  65535 / 5000 = 13.1 m (65.5 m in millimetre formats) is written as 0 (invalid).
- COLMAP text model, as hloc reads it (COLMAP ``doc/format.rst``): ``cameras.txt``
  "CAMERA_ID MODEL WIDTH HEIGHT fx fy cx cy" (PINHOLE), ``images.txt``
  "IMAGE_ID QW QX QY QZ TX TY TZ CAMERA_ID NAME" world-to-camera (Hamilton quaternion; camera
  x right, y down, z forward, as ours) followed by one line of 2D points, here empty; an empty
  ``points3D.txt``. COLMAP puts the image origin at the corner of the upper-left pixel, whose
  centre is (0.5, 0.5): hloc adds 0.5 to every keypoint before handing it to COLMAP
  (``hloc/triangulation.py``: ``keypoints += 0.5  # COLMAP origin``). So COLMAP's
  cx = ours + 0.5 and cy = ours + 0.5; that is what cameras.txt holds. IMAGE_ID is the tour
  frame index + 1.

Exposure: images are ``vrformats.tour.tonemap`` of the tour's linear RGB (scale, sRGB encode,
clip), rounded to 8 bits. "auto" (the default, camera-like) scales each frame on its own;
"fixed" uses one factor for the whole tour, the median of the per-frame auto factors; a number
is that factor. export.json records every factor used.

Sensor: ``sensor`` (a ``vrformats.sensors`` preset name, file or ``Sensor``) exports the frames as that
RGB-D camera measures them (``Tour(..., sensor=, sensor_seed=)``: the same noisy frames every other
reader of the tour gets with that seed); export.json records its name, seed and parameters, and a
folder exported with another sensor or seed is refused like another exposure. ``ideal`` (the
default) exports the render as it is.

Idempotent and resumable: a frame whose files all exist is kept; a killed export resumes where
it stopped; an export whose export.json matches the request and whose files are all there
writes nothing. A folder holding another export (another tour, format, role, exposure or sensor) is an
error naming its export.json (or ``.synth-export.json``, the request written before the first
frame) and the field that differs.
"""

from __future__ import annotations

import hashlib
import json
import math
import os
import sys
from collections.abc import Callable
import dataclasses
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from vrformats.atomic import replacing, write_json_atomic, write_text_atomic
from vrformats.camera import matrix_to_quat
from vrformats.errors import SceneFormatError, UserError, check_output_folder
from vrformats.fields import is_integer, is_number
from vrformats.tour import CAMERA_FILE, META_FILE, POSES_FILE, Tour, ranges_text, tonemap
from vrformats.yamlfile import read_json

ROLES = ("mapping", "query")
MANIFEST_FORMAT = "synth-export/1"
MANIFEST_FILE = "export.json"
REQUEST_FILE = ".synth-export.json"  # the request, written before the first frame; kept
UINT16_MAX = 65535  # depth: uint16 value = round(metres * scale), 0 = no surface (or out of range)
TIMESTAMP_DECIMALS = 6  # as vrformats.camera.write_tum


# ---------------------------------------------------------------------------------------------
# request and frame plan


def parse_exposure(value) -> str | float:
    """"auto", "fixed" or a positive finite factor (a number or its text); else a UserError."""
    if isinstance(value, str):
        v = value.strip().lower()
        if v in ("auto", "fixed"):
            return v
        try:
            value = float(v)
        except ValueError:
            raise UserError(f"--exposure {value!r}: expected auto, fixed or a positive number") from None
    if not is_number(value) or value <= 0:
        raise UserError(f"--exposure {value!r}: expected auto, fixed or a positive number")
    return float(value)


def _check_choice(value, known, option: str, what: str) -> str:
    if not isinstance(value, str) or value not in known:
        raise UserError(f"{option} {value!r}: unknown {what}; known: {', '.join(known)}")
    return value


def tour_key(root: Path) -> str:
    """Content key of a tour: sha256 of camera.json, poses.txt and meta.json (names and bytes)."""
    h = hashlib.sha256()
    for name in (CAMERA_FILE, POSES_FILE, META_FILE):
        data = (root / name).read_bytes()
        h.update(f"{name}\0{len(data)}\0".encode())
        h.update(data)
    return h.hexdigest()


@dataclass
class _Frame:
    index: int
    has_rgb: bool
    files: dict[str, str] = field(default_factory=dict)  # kind -> path relative to the export root


def _has_rgb_channels(path: Path) -> bool:
    """Whether a frame EXR carries R, G, B (header only)."""
    import OpenEXR

    from vrformats.frames import RGB_CHANNELS, FrameFileError

    try:
        with OpenEXR.File(str(path), header_only=True) as f:
            names = {c.name for c in f.header()["channels"]}
    except Exception as e:
        raise FrameFileError(f"{path}: corrupt or unreadable EXR ({e or type(e).__name__})") from None
    return all(c in names for c in RGB_CHANNELS) or "RGB" in names


# ---------------------------------------------------------------------------------------------
# encoding


def _encode_png(img: np.ndarray) -> bytes:
    import cv2

    ok, buf = cv2.imencode(".png", img, [cv2.IMWRITE_PNG_COMPRESSION, 1])
    if not ok:
        raise RuntimeError("PNG encoding failed")
    return buf.tobytes()


def rgb8(rgb_linear: np.ndarray, factor: float) -> np.ndarray:
    """8-bit sRGB of linear RGB scaled by ``factor`` (vrformats.tour.tonemap, then rounded)."""
    img, _ = tonemap(rgb_linear, factor)
    return (img * 255.0 + 0.5).astype(np.uint8)


def auto_factor(rgb_linear: np.ndarray) -> float:
    """The camera-like per-frame exposure factor of vrformats.tour.tonemap."""
    return float(tonemap(rgb_linear, None)[1])


def depth16(depth_m: np.ndarray, scale: float) -> np.ndarray:
    """uint16 depth = round(metres * scale); 0 where there is no surface or it does not fit."""
    d = np.nan_to_num(np.asarray(depth_m, dtype=np.float64), nan=0.0, posinf=0.0, neginf=0.0)
    q = np.floor(d * scale + 0.5)
    q[(d <= 0) | (q > UINT16_MAX)] = 0
    return q.astype(np.uint16)


def _matrix_text(M: np.ndarray) -> str:
    return "\n".join(" ".join(f"{v:.12f}" for v in row) for row in np.asarray(M, dtype=float)) + "\n"


def _write_bytes_atomic(path: Path, data: bytes) -> None:
    with replacing(path) as tmp:
        tmp.write_bytes(data)


def _write_text_if_changed(path: Path, text: str) -> bool:
    """Write (atomically) unless the file already holds exactly ``text``; True when written."""
    try:
        if path.read_text() == text:
            return False
    except (OSError, UnicodeDecodeError):
        pass
    write_text_atomic(path, text)
    return True


def _ts(i: int, fps: float) -> str:
    return f"{i / fps:.{TIMESTAMP_DECIMALS}f}"


# ---------------------------------------------------------------------------------------------
# the formats: one record each


@dataclass(frozen=True)
class ExportFormat:
    """One export layout: where its frame files go, the files written once per export, and what
    export.json says of it. The functions take the export's role ("mapping" or "query")."""

    name: str
    needs_rgb: bool  # an image format: frames without RGB are left out (else written without colour)
    depth: dict | None  # depth PNGs: {"unit", "scale"} (uint16 = round(metres * scale)); None: no depth
    poses: dict  # export.json "poses": where the poses are, in which convention
    frame_files: Callable[[str, int, bool], dict[str, str]]  # (role, frame, has RGB) -> {kind: path}
    frame_dirs: Callable[[str], list[str]]  # the folders holding frame files
    name_root: Callable[[str], str]  # prefix of a ``frames`` key that the tool's own frame name lacks
    whole_files: Callable[[str], list[str]]  # the files written once, after the frames
    write_whole_files: Callable[[Path, Tour, str, list[_Frame]], None]  # (out, tour, role, exported frames)
    intrinsics: Callable[[object], dict]  # (tour intrinsics) -> this format's entries of export.json "intrinsics"
    named_kinds: tuple[str, ...] = ("rgb",)  # the frame files export.json "frames" names
    focal_only: bool = False  # calibration files hold one focal length (DSAC*), not a 3x3 K
    manifest_extra: Callable[[Tour, list[_Frame]], dict] | None = None  # more export.json entries


MM_DEPTH = {"unit": "mm", "scale": 1000.0}


def _dsacstar_doc(intr, files: str) -> dict:
    """What DSAC* (the same layout as 7-Scenes / ACE, one focal length per frame) needs instead."""
    w, h = intr.width, intr.height
    return {
        "focal_length": intr.fx,
        "principal_point": [w / 2.0, h / 2.0],
        "offset_px": [w / 2.0 - intr.cx, h / 2.0 - intr.cy],
        "note": f"DSAC* reads ONE focal length per frame (float(np.loadtxt(calibration file))); {files}. DSAC* "
                "assumes the principal point at W/2, H/2, offset_px from the toolkit's (half a pixel right and "
                "down for a centred camera, cx = (W - 1) / 2)" + ("" if math.isclose(intr.fx, intr.fy) else
                                                                   "; fx != fy here, which DSAC* cannot represent"),
    }


# 7-Scenes: seq-01/ (mapping) or seq-02/ (query), split files, intrinsics.txt


def _seq(role: str) -> tuple[str, int]:
    n = 1 if role == "mapping" else 2
    return f"seq-{n:02d}", n


def _7scenes_frame_files(role: str, i: int, has_rgb: bool) -> dict[str, str]:
    seq, _ = _seq(role)
    stem = f"{seq}/frame-{i:06d}"
    return {"rgb": f"{stem}.color.png", "depth": f"{stem}.depth.png", "pose": f"{stem}.pose.txt"}


def _7scenes_write_whole_files(out: Path, tour: Tour, role: str, exported: list[_Frame]) -> None:
    _, n = _seq(role)
    own, other = ("TrainSplit.txt", "TestSplit.txt") if role == "mapping" else ("TestSplit.txt", "TrainSplit.txt")
    _write_text_if_changed(out / own, f"sequence{n}\n")
    _write_text_if_changed(out / other, "")
    _write_text_if_changed(out / "intrinsics.txt", _matrix_text(tour.K))


def _7scenes_intrinsics(intr) -> dict:
    return {
        "dsacstar": _dsacstar_doc(intr, "its setup_7scenes.py writes 525 for every frame: write fx instead"),
        "file": "intrinsics.txt (3x3 K, toolkit convention)",
        "7scenes": ("7-Scenes ships no intrinsics; its readers' setup scripts hard-code fx = fy = 525 and "
                    "the image centre: use this K"),
    }


SEVEN_SCENES = ExportFormat(
    name="7scenes", needs_rgb=True, depth=MM_DEPTH,
    poses={"files": "seq-XX/frame-NNNNNN.pose.txt", "content": "4x4 camera-to-world, OpenCV camera axes"},
    frame_files=_7scenes_frame_files,
    frame_dirs=lambda role: [_seq(role)[0]],
    name_root=lambda role: "",
    whole_files=lambda role: ["TrainSplit.txt", "TestSplit.txt", "intrinsics.txt"],
    write_whole_files=_7scenes_write_whole_files,
    intrinsics=_7scenes_intrinsics,
)


# ACE: train/ (mapping) or test/ (query), rgb/, depth/, poses/, calibration/ (per-frame 3x3 K)


def _ace_split(role: str) -> str:
    return "train" if role == "mapping" else "test"


def _ace_frame_files(role: str, i: int, has_rgb: bool) -> dict[str, str]:
    split = _ace_split(role)
    stem = f"frame-{i:06d}"
    return {"rgb": f"{split}/rgb/{stem}.color.png", "depth": f"{split}/depth/{stem}.depth.png",
            "pose": f"{split}/poses/{stem}.pose.txt", "calibration": f"{split}/calibration/{stem}.calibration.txt"}


# ACE rescales images to --image_resolution px of height and multiplies K by the same factor s, which
# moves a pixel-centre principal point by (s - 1) / 2 px: exact only at the export's own height
ACE_RESIZE_NOTE = ("run train_ace.py and test_ace.py with --image_resolution {h} (this export's height): ACE scales "
                   "K with the image, exact only at its own height")


def _ace_intrinsics(intr) -> dict:
    return {
        "ace": {
            "file": "{train,test}/calibration/frame-NNNNNN.calibration.txt",
            "content": "3x3 K, toolkit convention (ACE uses fx, fy, cx, cy of a 3x3 K as given; pixel u at u)",
            "image_resolution": intr.height,
            "note": ACE_RESIZE_NOTE.format(h=intr.height),
        },
        "dsacstar": _dsacstar_doc(intr, "the 3x3 calibration files of this export do not load in DSAC*: replace "
                                        "each with fx"),
    }


ACE = ExportFormat(
    name="ace", needs_rgb=True, depth=MM_DEPTH,
    poses={"files": "{train,test}/poses/frame-NNNNNN.pose.txt",
           "content": "4x4 camera-to-world, OpenCV camera axes",
           "tool_output": "test_ace.py: 'NAME qw qx qy qz tx ty tz ...' world-to-camera, NAME = rgb base name"},
    frame_files=_ace_frame_files,
    frame_dirs=lambda role: [f"{_ace_split(role)}/{d}" for d in ("rgb", "depth", "poses", "calibration")],
    name_root=lambda role: f"{_ace_split(role)}/rgb/",
    whole_files=lambda role: [],
    write_whole_files=lambda out, tour, role, exported: None,
    intrinsics=_ace_intrinsics,
)


# TUM RGB-D: rgb/, depth/, rgb.txt, depth.txt, groundtruth.txt, associations.txt, intrinsics.txt


def _tum_frame_files(role: str, i: int, has_rgb: bool) -> dict[str, str]:
    out = {"depth": f"depth/{i:06d}.png"}
    if has_rgb:
        out = {"rgb": f"rgb/{i:06d}.png", **out}
    return out


def _tum_write_whole_files(out: Path, tour: Tour, role: str, exported: list[_Frame]) -> None:
    fps = tour.fps
    rgb = [f for f in exported if "rgb" in f.files]
    head = "# {what}\n# file: '{name}' (synth export)\n# timestamp filename\n"
    _write_text_if_changed(out / "rgb.txt", head.format(what="color images", name=tour.name)
                           + "".join(f"{_ts(f.index, fps)} {f.files['rgb']}\n" for f in rgb))
    _write_text_if_changed(out / "depth.txt", head.format(what="depth maps", name=tour.name)
                           + "".join(f"{_ts(f.index, fps)} {f.files['depth']}\n" for f in exported))
    lines = ["# ground truth trajectory", f"# file: '{tour.name}' (synth export)", "# timestamp tx ty tz qx qy qz qw"]
    for f in exported:
        T = tour.pose(f.index)
        w, x, y, z = matrix_to_quat(T[:3, :3])
        t = T[:3, 3]
        lines.append(f"{_ts(f.index, fps)} {t[0]:.9f} {t[1]:.9f} {t[2]:.9f} {x:.9f} {y:.9f} {z:.9f} {w:.9f}")
    _write_text_if_changed(out / "groundtruth.txt", "\n".join(lines) + "\n")
    _write_text_if_changed(out / "associations.txt", "".join(
        f"{_ts(f.index, fps)} {f.files['rgb']} {_ts(f.index, fps)} {f.files['depth']}\n" for f in rgb))
    _write_text_if_changed(out / "intrinsics.txt", _matrix_text(tour.K))


def _tum_manifest_extra(tour: Tour, exported: list[_Frame]) -> dict:
    return {"timestamps": {_ts(f.index, tour.fps): f.index for f in exported},
            "timestamp_rule": f"t = frame / fps (fps {tour.fps:g}), {TIMESTAMP_DECIMALS} decimals"}


TUM_RGBD = ExportFormat(
    name="tum-rgbd", needs_rgb=False, depth={"unit": "1/5000 m", "scale": 5000.0},
    poses={"files": "groundtruth.txt", "content": "timestamp tx ty tz qx qy qz qw, camera-to-world, "
                                                  "t = frame / fps"},
    frame_files=_tum_frame_files,
    frame_dirs=lambda role: ["rgb", "depth"],
    name_root=lambda role: "",
    whole_files=lambda role: ["rgb.txt", "depth.txt", "groundtruth.txt", "associations.txt", "intrinsics.txt"],
    write_whole_files=_tum_write_whole_files,
    intrinsics=lambda intr: {"file": "intrinsics.txt (3x3 K, toolkit convention)"},
    named_kinds=("rgb", "depth"),
    manifest_extra=_tum_manifest_extra,
)


# COLMAP (as hloc reads it): images/, sparse/{cameras,images,points3D}.txt, queries_with_intrinsics.txt

COLMAP_NAME_ROOT = "images/"


def _colmap_params(intr) -> str:
    """PINHOLE fx fy cx cy in COLMAP's convention (image origin at the upper-left pixel's corner)."""
    return " ".join(f"{v:.15g}" for v in (intr.fx, intr.fy, intr.cx + 0.5, intr.cy + 0.5))


def _colmap_write_whole_files(out: Path, tour: Tour, role: str, exported: list[_Frame]) -> None:
    intr = tour.intrinsics
    cam = f"1 PINHOLE {intr.width} {intr.height} {_colmap_params(intr)}"
    _write_text_if_changed(out / "sparse/cameras.txt", "# Camera list with one line of data per camera:\n"
                           "#   CAMERA_ID, MODEL, WIDTH, HEIGHT, PARAMS[]\n# Number of cameras: 1\n" + cam + "\n")
    lines = ["# Image list with two lines of data per image:", "#   IMAGE_ID, QW, QX, QY, QZ, TX, TY, TZ, CAMERA_ID, NAME",
             "#   POINTS2D[] as (X, Y, POINT3D_ID)", f"# Number of images: {len(exported)}, mean observations per image: 0"]
    root = COLMAP_NAME_ROOT
    for f in exported:
        T = tour.pose(f.index)
        R = T[:3, :3].T
        t = -R @ T[:3, 3]
        w, x, y, z = matrix_to_quat(R)
        name = f.files["rgb"][len(root):]
        lines.append(f"{f.index + 1} {w:.12f} {x:.12f} {y:.12f} {z:.12f} {t[0]:.12f} {t[1]:.12f} {t[2]:.12f} 1 {name}")
        lines.append("")
    _write_text_if_changed(out / "sparse/images.txt", "\n".join(lines) + "\n")
    _write_text_if_changed(out / "sparse/points3D.txt", "# 3D point list with one line of data per point:\n"
                           "#   POINT3D_ID, X, Y, Z, R, G, B, ERROR, TRACK[] as (IMAGE_ID, POINT2D_IDX)\n"
                           "# Number of points: 0, mean track length: 0\n")
    if role == "query":
        params = _colmap_params(intr)
        _write_text_if_changed(out / "queries_with_intrinsics.txt", "".join(
            f"{f.files['rgb'][len(root):]} PINHOLE {intr.width} {intr.height} {params}\n" for f in exported))


def _colmap_intrinsics(intr) -> dict:
    return {
        "colmap": {
            "model": "PINHOLE", "fx": intr.fx, "fy": intr.fy, "cx": intr.cx + 0.5, "cy": intr.cy + 0.5,
            "file": "sparse/cameras.txt",
            "note": "COLMAP's image origin is the upper-left pixel's corner (its centre is at 0.5, 0.5; hloc adds "
                    "0.5 to keypoints for COLMAP): COLMAP cx, cy = toolkit cx, cy + 0.5",
        },
    }


COLMAP = ExportFormat(
    name="colmap", needs_rgb=True, depth=None,
    poses={"files": "sparse/images.txt", "content": "IMAGE_ID QW QX QY QZ TX TY TZ CAMERA_ID NAME, "
                                                    "world-to-camera; IMAGE_ID = frame + 1"},
    frame_files=lambda role, i, has_rgb: {"rgb": f"images/frame-{i:06d}.png"},
    frame_dirs=lambda role: ["images"],
    name_root=lambda role: COLMAP_NAME_ROOT,
    whole_files=lambda role: ["sparse/cameras.txt", "sparse/images.txt", "sparse/points3D.txt"]
                             + (["queries_with_intrinsics.txt"] if role == "query" else []),
    write_whole_files=_colmap_write_whole_files,
    intrinsics=_colmap_intrinsics,
)

def _dsacstar_intrinsics(intr) -> dict:
    return {"dsacstar": {**_dsacstar_doc(intr, "this export writes fx in every calibration file"),
                         "file": "{train,test}/calibration/frame-NNNNNN.calibration.txt (one number: fx)",
                         "image_resolution": intr.height, "resize_note": ACE_RESIZE_NOTE.format(h=intr.height)}}


# DSAC* (and ACE's one-number calibration path, which its RGB-D initialisation uses): the ACE layout,
# each calibration file one focal length; the principal point is then the image centre (W/2, H/2)
DSACSTAR = dataclasses.replace(ACE, name="dsacstar", focal_only=True, intrinsics=_dsacstar_intrinsics)

FORMATS: dict[str, ExportFormat] = {f.name: f for f in (SEVEN_SCENES, ACE, DSACSTAR, TUM_RGBD, COLMAP)}


# ---------------------------------------------------------------------------------------------
# manifest


def _intrinsics_doc(tour: Tour, layout: ExportFormat) -> dict:
    intr = tour.intrinsics
    w, h = intr.width, intr.height
    doc = {
        "width": w, "height": h, "fx": intr.fx, "fy": intr.fy, "cx": intr.cx, "cy": intr.cy,
        "K": intr.K.tolist(),
        "pixel_centers": "toolkit (= OpenCV, ACE): pixel (u, v) is centred at integer (u, v); a centred camera "
                         "has cx = (width - 1) / 2",
    }
    doc.update(layout.intrinsics(intr))
    return doc


def _depth_doc(enc: dict | None) -> dict | None:
    if enc is None:
        return None
    return {"dtype": "uint16 PNG", "unit": enc["unit"], "scale": enc["scale"],
            "meaning": "planar z along the camera's +z axis (not ray length): metres = value / scale",
            "invalid": 0, "max_m": UINT16_MAX / enc["scale"],
            "out_of_range": f"surfaces farther than {UINT16_MAX / enc['scale']:g} m are written as 0 (invalid)"}


def _request(fmt: str, role: str, exposure, key: str, sensor: dict | None = None) -> dict:
    return {"export_format": fmt, "role": role, "tour_key": key, "exposure": exposure, "sensor": sensor}


def sensor_record(sensor, seed: int) -> dict | None:
    """What export.json says of the sensor the frames were read through (None: the ideal sensor):
    name, seed and every parameter (so that an edited sensor file is another export)."""
    if sensor is None:
        return None
    import dataclasses

    from .sensors import load_sensor

    s = load_sensor(sensor)
    if s.is_ideal:
        return None
    params = {"depth": dataclasses.asdict(s.depth), "color": dataclasses.asdict(s.color)}
    return {"name": s.name, "seed": int(seed), "params": json.loads(json.dumps(params, default=str))}


def _request_of(doc: dict) -> dict:
    """The request fields of a manifest or request file."""
    exp = doc.get("exposure")
    return {"export_format": doc.get("export_format"), "role": doc.get("role"),
            "tour_key": (doc.get("tour") or {}).get("key") if isinstance(doc.get("tour"), dict) else doc.get("tour_key"),
            "exposure": exp.get("requested") if isinstance(exp, dict) else exp, "sensor": doc.get("sensor")}


def _compare(path: Path, have: dict, want: dict, tour_path: str | None) -> None:
    for fld, label in (("export_format", "export_format"), ("role", "role"), ("tour_key", "tour.key"),
                       ("exposure", "exposure.requested"), ("sensor", "sensor")):
        a, b = have.get(fld), want.get(fld)
        same = (a == b) if not (isinstance(a, (int, float)) and isinstance(b, (int, float))) else float(a) == float(b)
        if not same:
            what = {"export_format": "format", "role": "role", "tour_key": "tour", "exposure": "exposure",
                    "sensor": "sensor"}[fld]
            extra = f" (tour {tour_path})" if fld == "tour_key" and tour_path else ""
            if fld == "sensor":
                a, b = _sensor_text(a), _sensor_text(b)
            raise SceneFormatError(path, label, f"this folder holds another export: {what} {a!r}{extra}, asked for "
                                   f"{b!r}; export into another --out folder (or delete this one)")


def _sensor_text(rec) -> str:
    if not isinstance(rec, dict):
        return "ideal"
    return f"{rec.get('name')} (seed {rec.get('seed')})"


def read_manifest(out_dir) -> dict:
    """OUT/export.json, checked (SceneFormatError naming the file and the field)."""
    path = Path(out_dir) / MANIFEST_FILE
    doc = read_json(path, missing="not found (not a finished synth export)")
    if doc.get("format") != MANIFEST_FORMAT:
        raise SceneFormatError(path, "format", f"expected {MANIFEST_FORMAT!r}, got {doc.get('format')!r}")
    if not isinstance(doc.get("export_format"), str) or doc["export_format"] not in FORMATS:
        raise SceneFormatError(path, "export_format", f"expected one of {', '.join(FORMATS)}, got "
                               f"{doc.get('export_format')!r}")
    if doc.get("role") not in ROLES:
        raise SceneFormatError(path, "role", f"expected one of {', '.join(ROLES)}, got {doc.get('role')!r}")
    tour = doc.get("tour")
    if not isinstance(tour, dict) or not isinstance(tour.get("key"), str) or not isinstance(tour.get("path"), str):
        raise SceneFormatError(path, "tour", "expected {path, key, ...}")
    if not is_number(tour.get("fps")) or tour["fps"] <= 0:
        raise SceneFormatError(path, "tour.fps", f"expected a positive number, got {tour.get('fps')!r}")
    frames = doc.get("frames")
    if not isinstance(frames, dict):
        raise SceneFormatError(path, "frames", "expected a mapping of file name -> frame index")
    for name, i in frames.items():
        if not is_integer(i) or i < 0:
            raise SceneFormatError(path, f"frames.{name}", f"expected a frame index, got {i!r}")
    exp = doc.get("exposure")
    if not isinstance(exp, dict) or exp.get("mode") not in ("auto", "fixed"):
        raise SceneFormatError(path, "exposure.mode", "expected 'auto' or 'fixed'")
    if exp["mode"] == "fixed" and not (is_number(exp.get("factor")) and exp["factor"] > 0):
        raise SceneFormatError(path, "exposure.factor", f"expected a positive number, got {exp.get('factor')!r}")
    if exp["mode"] == "auto" and not isinstance(exp.get("factors"), dict):
        raise SceneFormatError(path, "exposure.factors", "expected a mapping of frame index -> factor")
    sk = doc.get("skipped")
    if not isinstance(sk, dict) or not isinstance(sk.get("count"), int) or not isinstance(sk.get("frames"), list):
        raise SceneFormatError(path, "skipped", "expected {count, frames}")
    return doc


# ---------------------------------------------------------------------------------------------
# export


def _open_tour(tour_dir, sensor=None, sensor_seed: int = 0) -> tuple[Tour, list[_Frame]]:
    tour = Tour(tour_dir, sensor=sensor, sensor_seed=sensor_seed)
    present = set(tour.frame_files())
    missing = [int(i) for i in tour.frame_indices if int(i) not in present]
    if missing:
        raise UserError(f"{tour.frames_dir}: {len(missing)} of {len(tour)} frame files missing ({ranges_text(missing)}); "
                        f"the tour is not completely rendered")
    frames = [_Frame(int(i), _has_rgb_channels(tour.frame_path(int(i)))) for i in tour.frame_indices]
    return tour, frames


def _folder_state(out: Path, want: dict, tour_path: str) -> dict | None:
    """The matching manifest (None: none yet); errors for a folder holding something else."""
    if out.exists() and not out.is_dir():
        raise UserError(f"cannot write to output folder {out}: it is a file")
    man_path, req_path = out / MANIFEST_FILE, out / REQUEST_FILE
    manifest = None
    if man_path.exists():
        manifest = read_manifest(out)
        _compare(man_path, _request_of(manifest), want, manifest["tour"].get("path"))
    if req_path.exists():
        try:
            req = read_json(req_path, expect_object=False)
            if not isinstance(req, dict):
                raise ValueError
        except (SceneFormatError, ValueError, OSError, UnicodeDecodeError):
            raise SceneFormatError(req_path, None, "unreadable export request (delete the folder and export again)") from None
        _compare(req_path, _request_of(req), want, req.get("tour_path"))
    elif manifest is None and out.is_dir() and any(out.iterdir()):
        raise UserError(f"{out}: the folder is not empty and holds no export ({MANIFEST_FILE}); "
                        f"export into an empty or new folder")
    return manifest


def _clean_strays(out: Path, dirs: list[str]) -> None:
    """Remove temporary files a killed export left (tools that list a folder would read them)."""
    for d in [""] + dirs:
        folder = out / d if d else out
        if not folder.is_dir():
            continue
        for e in os.scandir(folder):
            if e.is_file() and e.name.startswith(".") and e.name.endswith(".tmp"):
                try:
                    os.unlink(e.path)
                except OSError:
                    pass


def export_tour(tour_dir, fmt: str, out_dir, role: str = "query", exposure: str | float = "auto",
                progress: bool = False, sensor=None, sensor_seed: int = 0) -> dict:
    """Export one tour; role "mapping" (ACE: train/, 7scenes: the train split) or "query" (ACE: test/,
    7scenes: the test split).

    Returns the manifest (also written last, atomically, as OUT/export.json), plus a ``run`` entry
    that is not written: {"written": frames written now, "kept": frames already there}.
    Idempotent: exporting the same tour with the same settings into the same folder again does
    nothing (frames already written are kept; a killed export resumes), while a folder holding a
    DIFFERENT export (another tour, format, role, exposure or sensor) is an error naming OUT/export.json
    and the field that differs. Bad input raises a UserError before anything is written. ``sensor``,
    ``sensor_seed``: read the frames through that RGB-D camera model (``vrformats.sensors``).
    """
    fmt = _check_choice(fmt, FORMATS, "--format", "export format")
    layout = FORMATS[fmt]
    if layout.focal_only:
        intr = Tour(tour_dir).intrinsics
        if not math.isclose(intr.fx, intr.fy, rel_tol=1e-9):
            raise UserError(f"{tour_dir}: fx {intr.fx} != fy {intr.fy}: the {fmt} format holds one focal length; "
                            "export --format ace (a 3x3 K) instead")
    role = _check_choice(role, ROLES, "--role", "role")
    exp_req = parse_exposure(exposure)
    sensor_doc = sensor_record(sensor, sensor_seed)
    tour, frames = _open_tour(tour_dir, sensor, sensor_seed)
    out = Path(out_dir)
    check_output_folder(out)
    tour_path = str(tour.root.resolve())
    key = tour_key(tour.root)
    want = _request(fmt, role, exp_req, key, sensor_doc)
    manifest = _folder_state(out, want, tour_path)

    for f in frames:
        f.files = layout.frame_files(role, f.index, f.has_rgb) if f.has_rgb or not layout.needs_rgb else {}
    exported = [f for f in frames if f.files]
    skipped = [f.index for f in frames if not f.has_rgb]
    if not exported:
        raise UserError(f"{tour.root}: no frame has RGB (a geometry-only tour); the {fmt} format needs images "
                        f"(tum-rgbd exports depth alone)")

    if manifest is not None and all((out / p).is_file() for f in exported for p in f.files.values()) \
            and all((out / p).is_file() for p in layout.whole_files(role)):
        return {**manifest, "run": {"written": 0, "kept": len(exported)}}

    # the request first (a killed export is recognised and resumed by it), then the frames, then the manifest
    out.mkdir(parents=True, exist_ok=True)
    req_path = out / REQUEST_FILE
    request = {**want, "tour_path": tour_path, "format": MANIFEST_FORMAT + " request"}
    if not req_path.exists():
        write_json_atomic(req_path, request)
    _clean_strays(out, layout.frame_dirs(role))

    from tqdm import tqdm

    rgb_frames = [f for f in exported if f.has_rgb]
    known = {}
    if manifest is not None and manifest["exposure"]["mode"] == "auto":
        known = {int(k): float(v) for k, v in manifest["exposure"]["factors"].items()}
    fixed_factor: float | None = None
    if isinstance(exp_req, float):
        fixed_factor = exp_req
    elif exp_req == "fixed":
        fixed_factor = _fixed_factor(tour, rgb_frames, out, manifest, progress)

    factors: dict[int, float] = {}
    written = kept = 0
    bar = tqdm(exported, desc=f"export {fmt}", unit="frame", disable=not progress, file=sys.stderr, dynamic_ncols=True)
    for f in bar:
        done = all((out / p).is_file() for p in f.files.values())
        if done:
            kept += 1
            if f.has_rgb and fixed_factor is None:
                factors[f.index] = known[f.index] if f.index in known else \
                    auto_factor(tour.frame(f.index, depth=False, instance=False, semantic=False).rgb)
            continue
        fr = tour.frame(f.index, rgb="rgb" in f.files, depth="depth" in f.files, instance=False, semantic=False)
        if "rgb" in f.files:
            if fr.rgb is None:
                raise UserError(f"{tour.frame_path(f.index)}: R, G, B channels unreadable")
            factor = fixed_factor if fixed_factor is not None else auto_factor(fr.rgb)
            if fixed_factor is None:
                factors[f.index] = factor
            img = rgb8(fr.rgb, factor)
            _write_bytes_atomic(out / f.files["rgb"], _encode_png(np.ascontiguousarray(img[..., ::-1])))
        if "depth" in f.files:
            if fr.depth is None:
                raise UserError(f"{tour.frame_path(f.index)}: no depth channel (Z)")
            _write_bytes_atomic(out / f.files["depth"], _encode_png(depth16(fr.depth, layout.depth["scale"])))
        if "calibration" in f.files:
            write_text_atomic(out / f.files["calibration"], f"{tour.intrinsics.fx!r}\n" if layout.focal_only
                              else _matrix_text(tour.K))
        if "pose" in f.files:  # last: a frame is complete when all its files exist
            write_text_atomic(out / f.files["pose"], _matrix_text(fr.pose))
        written += 1
    bar.close()

    layout.write_whole_files(out, tour, role, exported)
    manifest = _manifest(tour, tour_path, key, layout, role, exp_req, fixed_factor, factors, exported, skipped)
    manifest["sensor"] = sensor_doc
    write_json_atomic(out / MANIFEST_FILE, manifest)
    return {**manifest, "run": {"written": written, "kept": kept}}


def _fixed_factor(tour: Tour, rgb_frames: list[_Frame], out: Path, manifest: dict | None, progress: bool) -> float:
    """One factor for the tour: the median of its frames' auto factors (reused from a previous run when known)."""
    if manifest is not None and manifest["exposure"].get("mode") == "fixed":
        return float(manifest["exposure"]["factor"])
    req_path = out / REQUEST_FILE
    try:
        req = read_json(req_path, expect_object=False)
        if is_number(req.get("fixed_factor")):
            return float(req["fixed_factor"])
    except (SceneFormatError, OSError, ValueError, AttributeError):
        pass
    from tqdm import tqdm

    vals = [auto_factor(tour.frame(f.index, depth=False, instance=False, semantic=False).rgb)
            for f in tqdm(rgb_frames, desc="exposure", unit="frame", disable=not progress, file=sys.stderr)]
    factor = float(np.median(vals))
    try:
        req = read_json(req_path, expect_object=False)
        write_json_atomic(req_path, {**req, "fixed_factor": factor})
    except (SceneFormatError, OSError, ValueError):
        pass
    return factor


def _manifest(tour: Tour, tour_path: str, key: str, layout: ExportFormat, role: str, exp_req, fixed_factor, factors,
              exported: list[_Frame], skipped: list[int]) -> dict:
    if fixed_factor is None:
        exposure = {"mode": "auto", "requested": exp_req, "factors": {str(i): factors[i] for i in sorted(factors)}}
    else:
        exposure = {"mode": "fixed", "requested": exp_req, "factor": fixed_factor}
        if exp_req == "fixed":
            exposure["rule"] = "median of the per-frame auto factors of the tour's RGB frames"
    exposure["transform"] = ("8-bit sRGB = round(255 * srgb_encode(clip(linear RGB * factor, 0, 1))) "
                             "(vrformats.tour.tonemap); auto factor = 0.9 / 97th percentile of the frame's luminance")
    frames: dict[str, int] = {}
    for f in exported:
        for kind in layout.named_kinds:
            if kind in f.files:
                frames[f.files[kind]] = f.index
    doc = {
        "format": MANIFEST_FORMAT,
        "export_format": layout.name,
        "role": role,
        "tour": {"path": tour_path, "key": key, "key_of": f"sha256 of {CAMERA_FILE}, {POSES_FILE}, {META_FILE}",
                 "name": tour.name, "n_frames": len(tour), "fps": tour.fps,
                 "layout": tour.meta.get("layout"), "lighting": tour.meta.get("lighting")},
        "intrinsics": _intrinsics_doc(tour, layout),
        "poses": dict(layout.poses),
        "depth": _depth_doc(layout.depth),
        "exposure": exposure,
        "frames": frames,
        "name_root": layout.name_root(role),
        "names": "frames maps each exported file (path relative to the export root) to its tour frame index; the "
                 "tool's own name for a frame (in its pose files) is the key without name_root",
        "skipped": {"count": len(skipped), "frames": skipped,
                    "reason": ("geometry-only frames (no RGB): left out" if layout.needs_rgb else
                               "geometry-only frames (no RGB): depth and pose written, no colour image")},
        "n_exported": len(exported),
    }
    if layout.manifest_extra is not None:
        doc.update(layout.manifest_extra(tour, exported))
    return doc


def summary_line(manifest: dict, out_dir) -> str:
    """One line for the CLI: frames written, skipped geometry-only frames, exposure, out."""
    run = manifest.get("run") or {}
    n = manifest.get("n_exported", 0)
    exp = manifest["exposure"]
    exp_text = "auto (per frame)" if exp["mode"] == "auto" else f"fixed x{exp['factor']:.4g}"
    sk = manifest["skipped"]["count"]
    layout = FORMATS.get(manifest["export_format"])
    sk_text = (f"{sk} geometry-only frames skipped" if layout is not None and layout.needs_rgb
               else f"{sk} geometry-only frames without colour")
    done = (f"{run.get('written', n)} written, {run.get('kept', 0)} already there" if run.get("kept")
            else f"{run.get('written', n)} written")
    sensor = manifest.get("sensor")
    sensor_text = f"; sensor {_sensor_text(sensor)}" if sensor else ""
    return (f"exported {n} frames of {manifest['tour']['name']} as {manifest['export_format']} ({manifest['role']}; "
            f"{done}); {sk_text}; exposure {exp_text}{sensor_text}; out {out_dir}")
