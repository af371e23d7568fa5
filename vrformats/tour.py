"""The tour format, and its reader: a rendered tour on disk, read frame by frame.

A tour directory, as the renderers write it::

    TOUR/
      camera.json    {"width", "height", "K", "fx", "fy", "cx", "cy", "fps", + vrformats.camera.CAMERA_DOC keys}
      poses.txt      TUM, camera-to-world, OpenCV axes; frame index = round(t * fps); one line per frame
      objects.json   ground-truth boxes of the tour's layout (``vrformats.boxes``: videoreloc-boxes/1)
      meta.json      {"toolkit", "layout", "lighting" (null: geometry-only tour), "path", "renderer", "seed",
                      "settings", "frames": [first, last], "n_frames", "rgb_every", "complete", ...}
      frames/NNNNNN.exr   one per frame (vrformats.frames: R, G, B half; Z; instance; semantic)
      previews/NNNNNN.png optional 8-bit sRGB previews

``Tour`` reads the small files up front and the frames lazily, one EXR at a time.

The tour's format has two homes here, this reader with its conventions and ``vrformats.export`` (the
other methods' formats a tour is exported to), both in the format layer because reloc reads tours
and imports nothing of synth. The tour's synth-side code is ``synth.tour``: rendering a tour
(``synth tour render``, ``synth.tour.render``), the checker (``synth tour check``,
``synth.tour.check``) and the contact sheet (``synth tour show``, ``synth.tour.show``).
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path
from typing import Iterator

import numpy as np

from . import frames as fr
from .atomic import write_json_atomic
from .camera import DEFAULT_FPS, Intrinsics, camera_document, read_tum, write_tum
from .color import srgb_encode
from .errors import SceneFormatError, UserError
from .fields import is_integer, number, required, whole_number
from .yamlfile import read_json

CAMERA_FILE = "camera.json"
POSES_FILE = "poses.txt"
OBJECTS_FILE = "objects.json"
META_FILE = "meta.json"
FRAMES_DIR = "frames"
PREVIEWS_DIR = "previews"



def ranges_text(values) -> str:
    """'3, 10-19, 25' for sorted integers."""
    vals = sorted(int(v) for v in values)
    parts, start, prev = [], None, None
    for v in vals:
        if start is None:
            start = prev = v
        elif v == prev + 1:
            prev = v
        else:
            parts.append(f"{start}" if start == prev else f"{start}-{prev}")
            start = prev = v
    if start is not None:
        parts.append(f"{start}" if start == prev else f"{start}-{prev}")
    return ", ".join(parts)


def scan_dir(d: Path) -> list[os.DirEntry]:
    try:
        with os.scandir(d) as it:
            return list(it)
    except (FileNotFoundError, NotADirectoryError):
        return []


@dataclass
class Frame:
    index: int
    rgb: np.ndarray | None  # (H, W, 3) float32, linear
    depth: np.ndarray | None  # (H, W) float32, planar metres, 0 = no surface
    instance: np.ndarray | None  # (H, W) uint32
    semantic: np.ndarray | None  # (H, W) uint32
    pose: np.ndarray  # 4x4 camera-to-world, OpenCV axes
    K: np.ndarray  # 3x3

    @property
    def position(self) -> np.ndarray:
        return self.pose[:3, 3]


# ---------------------------------------------------------------------------------------------
# reading


def _read_json(path: Path, what: str) -> dict:
    return read_json(path, missing=f"{what} not found")


def read_camera(path: Path) -> tuple[Intrinsics, float, dict]:
    """A tour's ``camera.json``: (intrinsics, fps, the whole document), every field checked (a
    SceneFormatError naming the file and the field)."""
    d = _read_json(path, "camera file")
    w = whole_number(path, required(path, d, "width"), "width", positive=True)
    h = whole_number(path, required(path, d, "height"), "height", positive=True)
    fx, fy, cx, cy, fps = (number(path, required(path, d, k), k, positive=k not in ("cx", "cy"))
                           for k in ("fx", "fy", "cx", "cy", "fps"))
    intr = Intrinsics(w, h, fx, fy, cx, cy)
    if "K" in d:
        try:
            K = np.asarray(d["K"], dtype=float)
            good_shape = K.shape == (3, 3)
        except (TypeError, ValueError):
            good_shape = False
        if not good_shape:
            raise SceneFormatError(path, "K", f"expected a 3x3 matrix, got {d['K']!r}")
        if not np.allclose(K, intr.K, rtol=1e-6, atol=1e-6):
            raise SceneFormatError(path, "K", f"does not match fx, fy, cx, cy ({K.tolist()} vs {intr.K.tolist()})")
    return intr, fps, d


def _split_channels(ch: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
    """Channels by their EXR names; interleaved RGB(A) arrays (OpenEXR's default read) split into R, G, B(, A)."""
    out: dict[str, np.ndarray] = {}
    for name, a in ch.items():
        if name in ("RGB", "RGBA") and a.ndim == 3 and a.shape[2] == len(name):
            for k, c in enumerate(name):
                out[c] = a[..., k]
        else:
            out[name] = a
    return out


def images_from_channels(ch: dict[str, np.ndarray], rgb=True, depth=True, instance=True, semantic=True) -> fr.FrameImages:
    out = fr.FrameImages()
    if rgb and all(c in ch for c in fr.RGB_CHANNELS):
        out.rgb = np.stack([ch[c].astype(np.float32) for c in fr.RGB_CHANNELS], axis=-1)
    if depth and fr.DEPTH_CHANNEL in ch:
        out.depth = ch[fr.DEPTH_CHANNEL].astype(np.float32, copy=False)
    if instance and fr.INSTANCE_CHANNEL in ch:
        out.instance = ch[fr.INSTANCE_CHANNEL].astype(np.uint32, copy=False)
    if semantic and fr.SEMANTIC_CHANNEL in ch:
        out.semantic = ch[fr.SEMANTIC_CHANNEL].astype(np.uint32, copy=False)
    return out


def read_split_channels(path: Path) -> dict[str, np.ndarray]:
    """All channels of one frame file by EXR name (FrameFileError naming the file when unreadable)."""
    return _split_channels(fr.read_channels(path))


def _channel_names(path: Path) -> list[str]:
    """Channel names from the EXR header only (cheap)."""
    import OpenEXR

    try:
        with OpenEXR.File(str(path), header_only=True) as f:
            return sorted(c.name for c in f.header()["channels"])
    except Exception as e:
        raise fr.FrameFileError(f"{path}: corrupt or unreadable EXR ({e or type(e).__name__})") from None


class Tour:
    """A rendered tour directory. The small files are read here; frames are read when asked for.

    A tour whose poses.txt and frame files disagree is refused (``SceneFormatError`` naming
    poses.txt and both counts): frame files without a pose (poses.txt cut short: reading it
    would silently shorten the tour), or a meta.json ``n_frames`` other than the number of poses.
    Fewer frame files than poses is allowed: a partly rendered (or resumed) tour has them, and a
    missing frame is a ``FrameFileError`` naming its file when read. ``strict=False`` (what
    ``check_tour`` uses) accepts either, to report it.

    ``sensor`` (a ``vrformats.sensors`` preset name, file or ``Sensor``): frames are read as that RGB-D
    camera would measure them, seeded per (tour name, frame, sensor, ``sensor_seed``), so every
    reader of the same frame gets the same noise; ``ideal`` (or None) reads the render as it is.
    """

    def __init__(self, root, strict: bool = True, sensor=None, sensor_seed: int = 0):
        self.root = Path(root)
        if not self.root.is_dir():
            raise UserError(f"{self.root}: tour directory not found")
        self.camera_file = self.root / CAMERA_FILE
        self.intrinsics, self.fps, self.camera = read_camera(self.camera_file)
        poses_file = self.root / POSES_FILE
        self.frame_indices, self.poses = read_tum(poses_file, fps=self.fps)
        if len(self.frame_indices) == 0:
            raise SceneFormatError(poses_file, None, "no poses (a tour has one line per frame)")
        uniq, counts = np.unique(self.frame_indices, return_counts=True)
        if (counts > 1).any():
            dup = int(uniq[counts > 1][0])
            raise SceneFormatError(poses_file, None, f"frame {dup} appears {int(counts[counts > 1][0])} times "
                                   f"(frame = round(t * fps), fps {self.fps:g} from {CAMERA_FILE})")
        self._row = {int(i): k for k, i in enumerate(self.frame_indices)}
        self.meta = _read_json(self.root / META_FILE, "tour metadata")
        # a sensor model applied as frames are read (vrformats.sensors): one render, any camera
        self.sensor, self.sensor_seed = None, int(sensor_seed)
        if sensor is not None:
            from .sensors import Sensor, load_sensor

            s = sensor if isinstance(sensor, Sensor) else load_sensor(sensor)
            s.check_resolution(self.intrinsics.width, self.intrinsics.height, str(self.root))
            self.sensor = None if s.is_ideal else s
        self._objects: dict | None = None
        if strict:
            why = self.count_problem()
            if why:
                raise SceneFormatError(poses_file, None, why)

    # -- basics --------------------------------------------------------------------------------

    @property
    def name(self) -> str:
        return self.root.resolve().name

    @property
    def K(self) -> np.ndarray:
        return self.intrinsics.K

    @property
    def frames_dir(self) -> Path:
        return self.root / FRAMES_DIR

    def __len__(self) -> int:
        return len(self.frame_indices)

    def __repr__(self) -> str:
        return f"Tour({str(self.root)!r}, {len(self)} frames, {self.intrinsics.width}x{self.intrinsics.height})"

    def frame_path(self, index: int) -> Path:
        return self.frames_dir / fr.frame_name(int(index))

    def frame_files(self) -> list[int]:
        """Indices of the frame files on disk (``frames/NNNNNN.exr``), sorted; one directory listing."""
        return sorted(int(e.name[:-4]) for e in scan_dir(self.frames_dir)
                      if e.name.endswith(".exr") and e.name[:-4].isdigit())

    def count_problem(self, frame_files: list[int] | None = None) -> str | None:
        """Why poses.txt, the frame files and meta.json's ``n_frames`` disagree, or None.

        Frame files without a pose, or ``n_frames`` other than the number of poses, disagree;
        fewer frame files than poses (a partly rendered tour) does not."""
        present = self.frame_files() if frame_files is None else frame_files
        n = len(self.frame_indices)
        extra = sorted(set(present) - set(self._row))
        if extra:
            return (f"{n} poses for {len(present)} frame files in {FRAMES_DIR}/ ({len(extra)} frame files have no "
                    f"pose: {ranges_text(extra)}); poses.txt was cut short or belongs to another render")
        n_meta = self.disagreeing_n_frames()
        if n_meta is not None:
            return f"{n} poses, but {META_FILE} says the tour has {n_meta} frames (n_frames)"
        return None

    def disagreeing_n_frames(self) -> int | None:
        """meta.json's ``n_frames`` when it is given and differs from the number of poses, else None."""
        n_meta = self.meta.get("n_frames")
        ok = not is_integer(n_meta) or n_meta == len(self.frame_indices)
        return None if ok else n_meta

    def pose(self, index: int) -> np.ndarray:
        return self.poses[self._position(index)].copy()

    def _position(self, index: int) -> int:
        try:
            return self._row[int(index)]
        except KeyError:
            fi = self.frame_indices
            raise UserError(f"{self.root / POSES_FILE}: frame {index} is not in this tour "
                            f"({len(fi)} frames, {int(fi.min())}..{int(fi.max())})") from None

    # -- frames --------------------------------------------------------------------------------

    def frame(self, index: int, rgb: bool = True, depth: bool = True, instance: bool = True,
              semantic: bool = True) -> Frame:
        """One frame (reads its EXR); channels not asked for, or absent from the file, are None."""
        k = self._position(index)
        noisy = self.sensor is not None and (rgb or depth)
        # a sensor's depth can depend on the frame's colour (dark surfaces): read it whenever depth is asked
        img = images_from_channels(read_split_channels(self.frame_path(index)), rgb or (noisy and depth), depth,
                                   instance, semantic)
        frame_rgb, frame_depth = img.rgb, img.depth
        if noisy:
            from .sensors import Motion, apply_sensor, frame_seed

            seed = frame_seed(self.name, int(index), self.sensor.name, self.sensor_seed)
            # the camera's motion around the frame (motion blur): the neighbouring poses.txt positions,
            # dt = index difference / fps; a neighbour not strictly earlier / later in time is left out
            fi, n = self.frame_indices, len(self.frame_indices)
            dt_prev = (int(fi[k]) - int(fi[k - 1])) / self.fps if k > 0 else 0.0
            dt_next = (int(fi[k + 1]) - int(fi[k])) / self.fps if k + 1 < n else 0.0
            motion = Motion(self.poses[k], self.poses[k - 1] if dt_prev > 0 else None,
                            self.poses[k + 1] if dt_next > 0 else None,
                            dt_prev if dt_prev > 0 else 1.0 / self.fps, dt_next if dt_next > 0 else 1.0 / self.fps)
            # colour not asked for: skip the colour model (depth draws from its own stream: the same depth)
            sensor = self.sensor if rgb else self._depth_sensor()
            frame_depth, frame_rgb = apply_sensor(sensor, img.depth, img.rgb, self.intrinsics, seed, motion=motion)
        return Frame(int(index), frame_rgb if rgb else None, frame_depth, img.instance, img.semantic,
                     self.poses[k].copy(), self.K)

    def _depth_sensor(self):
        """The tour's sensor without its colour model (depth-only reads), made once."""
        if getattr(self, "_depth_only", None) is None:
            from dataclasses import replace

            from .sensors import ColorModel

            self._depth_only = replace(self.sensor, color=ColorModel())
        return self._depth_only

    def __iter__(self) -> Iterator[Frame]:
        """Frames in poses.txt order, reading one EXR at a time."""
        for i in self.frame_indices:
            yield self.frame(int(i))

    def has_rgb(self) -> bool:
        """Whether the frames carry R, G, B (a geometry-only tour has none).

        Asks the first frame file's header; without any frame file, meta.json's ``lighting``
        (null for geometry-only tours) decides.
        """
        for i in self.frame_indices:
            p = self.frame_path(int(i))
            if p.is_file():
                try:
                    names = _channel_names(p)
                except fr.FrameFileError:
                    continue
                return all(c in names for c in fr.RGB_CHANNELS)
        return self.meta.get("lighting") is not None

    @property
    def rgb_every(self) -> int:
        """RGB is rendered on frames 0, k, 2k, ... (a render job's ``rgb_every``; 1: every frame)."""
        k = (self.meta.get("settings") or {}).get("rgb_every")
        return int(k) if isinstance(k, int) and k > 0 else 1

    def objects(self) -> dict:
        """objects.json (videoreloc-boxes/1), read on first use."""
        if self._objects is None:
            path = self.root / OBJECTS_FILE
            d = _read_json(path, "ground-truth boxes")
            if not isinstance(d.get("boxes"), list):
                raise SceneFormatError(path, "boxes", "expected a list of boxes")
            if not isinstance(d.get("classes"), dict):
                raise SceneFormatError(path, "classes", "expected a mapping of class name -> semantic id")
            for k, b in enumerate(d["boxes"]):
                if not isinstance(b, dict) or not is_integer(b.get("id")):
                    raise SceneFormatError(path, f"boxes[{k}].id", f"expected an integer id, got {b!r:.80}")
            for name, v in d["classes"].items():
                if not is_integer(v):
                    raise SceneFormatError(path, f"classes.{name}", f"expected an integer id, got {v!r}")
            self._objects = d
        return self._objects

    def class_names(self) -> dict[int, str]:
        """semantic id -> class name from objects.json (empty when it cannot be read)."""
        try:
            return {int(v): k for k, v in self.objects()["classes"].items()}
        except UserError:
            return {}


# ---------------------------------------------------------------------------------------------
# check


def tonemap(rgb: np.ndarray, exposure: float | None = None) -> tuple[np.ndarray, float]:
    """Simple display transform: scale (auto: the 97th luminance percentile to 0.9), sRGB gamma, clip.

    Returns (image in [0, 1], the scale used).
    """
    rgb = np.nan_to_num(np.asarray(rgb, dtype=np.float32), nan=0.0, posinf=0.0, neginf=0.0)
    if exposure is None:
        lum = rgb @ np.array([0.2126, 0.7152, 0.0722], dtype=np.float32)
        p = float(np.percentile(lum, 97)) if lum.size else 0.0
        scale = 0.9 / p if p > 1e-8 else 1.0
    else:
        scale = float(exposure)
    return srgb_encode(rgb * scale).astype(np.float32), scale


def write_tour(root, poses, intrinsics: Intrinsics, frames: dict | None = None, *, fps: float = DEFAULT_FPS,
               frame_ids=None, meta: dict | None = None, objects: dict | None = None, hfov_deg: float | None = None,
               header: str | None = None) -> "Tour":
    """Write a tour folder in the format ``Tour`` reads, for a tool that makes tours without the
    renderers (an importer of another dataset, a test): ``frames`` (frame id -> keyword arguments of
    ``vrformats.frames.write_frame``: ``rgb``, ``depth``, ``instance``, ``semantic``), ``camera.json``
    (``vrformats.camera.camera_document``), ``poses.txt`` (camera-to-world, one pose per ``frame_ids``,
    default 0..n-1), ``meta.json`` (``meta`` over a header naming the frames, with ``layout``,
    ``lighting``, ``path`` and ``renderer`` defaulting to placeholders) and ``objects.json`` when
    ``objects`` is given. Every file is written atomically; returns the ``Tour``."""
    root = Path(root)
    poses = np.asarray(poses, dtype=float).reshape(-1, 4, 4)
    ids = list(range(len(poses))) if frame_ids is None else [int(i) for i in frame_ids]
    if len(ids) != len(poses) or not ids:
        raise ValueError(f"write_tour: {len(poses)} poses for {len(ids)} frame ids")
    for i, images in (frames or {}).items():
        fr.write_frame(root / FRAMES_DIR / fr.frame_name(int(i)), **images)
    write_json_atomic(root / CAMERA_FILE, camera_document(intrinsics, fps, hfov_deg), indent=1)
    write_tum(root / POSES_FILE, poses, fps=fps, frames=None if frame_ids is None else ids, header=header)
    if objects is not None:
        write_json_atomic(root / OBJECTS_FILE, objects, indent=1)
    head = {"layout": "unnamed", "lighting": None, "path": "unnamed", "renderer": "none", "seed": 0, "settings": {},
            "frames": [ids[0], ids[-1]], "n_frames": len(ids)}
    write_json_atomic(root / META_FILE, {**head, **(meta or {})}, indent=1)
    return Tour(root)

