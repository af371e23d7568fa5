"""Per-frame EXR files: linear RGB, planar depth, instance and semantic ids in one file.

Channels (all optional, but a frame has at least one group):

    R, G, B     HALF    linear scene-referred RGB (Rec.709 primaries), as rendered by Cycles
    Z           FLOAT   planar depth in metres along the camera's +z (OpenCV), 0 = no surface
    instance    UINT    instance id: 0 = nothing, objects 1..999, walls 1000+k, floors 2000+k, ceilings 3000+k
    semantic    UINT    semantic class id from scenes/classes.yaml, 0 = nothing

ZIP compression, scanline image. A frame file becomes visible only when complete: it is written
to a hidden temporary name in the same folder, then renamed.
"""

from __future__ import annotations

import contextlib
import io
import os
import threading
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import OpenEXR

from .atomic import replacing
from .errors import UserError

RGB_CHANNELS = ("R", "G", "B")
DEPTH_CHANNEL = "Z"
INSTANCE_CHANNEL = "instance"
SEMANTIC_CHANNEL = "semantic"


class FrameFileError(UserError):
    """A frame file that is missing, corrupt or lacks a channel; the message names the file."""


@dataclass
class FrameImages:
    rgb: np.ndarray | None = None  # (H, W, 3) float32, linear
    depth: np.ndarray | None = None  # (H, W) float32, metres, 0 = none
    instance: np.ndarray | None = None  # (H, W) uint32
    semantic: np.ndarray | None = None  # (H, W) uint32

    @property
    def shape(self) -> tuple[int, int]:
        for a in (self.depth, self.instance, self.semantic, self.rgb):
            if a is not None:
                return a.shape[:2]
        raise ValueError("empty frame")


def write_frame(path, rgb=None, depth=None, instance=None, semantic=None) -> Path:
    """Write one frame EXR atomically (temporary name, then rename)."""
    path = Path(path)
    ch: dict[str, np.ndarray] = {}
    shape = None
    if rgb is not None:
        rgb = np.asarray(rgb)
        if rgb.ndim != 3 or rgb.shape[2] != 3:
            raise ValueError(f"rgb must be (H, W, 3), got {rgb.shape}")
        shape = rgb.shape[:2]
        for k, name in enumerate(RGB_CHANNELS):
            ch[name] = np.ascontiguousarray(rgb[..., k], dtype=np.float16)
    for name, arr, dtype in ((DEPTH_CHANNEL, depth, np.float32), (INSTANCE_CHANNEL, instance, np.uint32), (SEMANTIC_CHANNEL, semantic, np.uint32)):
        if arr is None:
            continue
        arr = np.ascontiguousarray(arr, dtype=dtype)
        if arr.ndim != 2 or (shape is not None and arr.shape != shape):
            raise ValueError(f"{name} must be (H, W) matching the other channels, got {arr.shape}")
        shape = arr.shape
        ch[name] = arr
    if not ch:
        raise ValueError("a frame needs at least one of rgb, depth, instance, semantic")
    header = {"compression": OpenEXR.ZIP_COMPRESSION, "type": OpenEXR.scanlineimage}
    with replacing(path) as tmp, OpenEXR.File(header, ch) as f:
        f.write(str(tmp))
    return path


EXR_MAGIC = b"\x76\x2f\x31\x01"


def read_channels(path) -> dict[str, np.ndarray]:
    """All channels of an EXR file by name; a clear error for missing or corrupt files.

    OpenEXR's own messages about a damaged file (on stdout and stderr) are silenced: the error
    says what is wrong, once."""
    path = Path(path)
    if not path.exists():
        raise FrameFileError(f"{path}: frame file not found")
    try:
        with _quiet():
            # separate_channels: one array per channel (by default OpenEXR 3 merges R, G, B into "RGB")
            with OpenEXR.File(str(path), separate_channels=True) as f:
                return {name: np.array(c.pixels) for name, c in f.channels().items()}
    except Exception:  # OpenEXR raises RuntimeError / OSError variants for damaged files
        raise FrameFileError(_unreadable(path)) from None


def _unreadable(path: Path) -> str:
    """Why an EXR file that exists could not be read, for a user (OpenEXR's reasons are internal)."""
    try:
        with open(path, "rb") as f:
            head = f.read(len(EXR_MAGIC))
    except OSError as e:
        return f"{path}: cannot read frame file ({e.strerror or e})"
    if head != EXR_MAGIC:
        return f"{path}: unreadable EXR (not an EXR file{', it is empty' if not head else ''})"
    return f"{path}: unreadable EXR (truncated or damaged)"


_QUIET_LOCK = threading.Lock()


@contextlib.contextmanager
def _quiet():
    """Silence OpenEXR meanwhile: its C core writes to file descriptor 2, its Python binding
    prints to ``sys.stdout``; both go nowhere, descriptors 1 and 2 included.

    About 15 us a call, against 0.5-1 ms for reading even a 160x120 frame; C stdio buffers are
    flushed on both sides so nothing of ours is lost and nothing of theirs leaks out later.
    Output of other threads in the meantime is lost too. One thread at a time (``_QUIET_LOCK``):
    two overlapping redirections could restore each other's sink for good."""
    sink = io.StringIO()
    with _QUIET_LOCK, contextlib.redirect_stdout(sink), contextlib.redirect_stderr(sink):
        fds: list[int] = []
        try:
            for fd in (1, 2):
                fds.append(os.dup(fd))
            fds.append(os.open(os.devnull, os.O_WRONLY))
        except OSError:  # no stdout/stderr (a daemon): nothing to protect
            for fd in fds:
                os.close(fd)
            yield
            return
        _flush_c_stdio()
        try:
            os.dup2(fds[2], 1)
            os.dup2(fds[2], 2)
            yield
        finally:
            _flush_c_stdio()
            os.dup2(fds[0], 1)
            os.dup2(fds[1], 2)
            for fd in fds:
                os.close(fd)


_LIBC = None  # the C library, for fflush; False where it cannot be loaded


def _flush_c_stdio() -> None:
    global _LIBC
    if _LIBC is None:
        import ctypes

        try:
            _LIBC = ctypes.CDLL(None)
        except OSError:
            _LIBC = False
    if _LIBC:
        _LIBC.fflush(None)


def read_frame(path, rgb: bool = True, depth: bool = True, instance: bool = True, semantic: bool = True,
               require: tuple[str, ...] = ()) -> FrameImages:
    """Read a frame EXR. Channels absent from the file come back as None unless named in ``require``
    (any of "rgb", "depth", "instance", "semantic"), which makes their absence an error."""
    ch = read_channels(path)
    out = FrameImages()
    if rgb and all(c in ch for c in RGB_CHANNELS):
        out.rgb = np.stack([ch[c].astype(np.float32) for c in RGB_CHANNELS], axis=-1)
    if depth and DEPTH_CHANNEL in ch:
        out.depth = ch[DEPTH_CHANNEL].astype(np.float32, copy=False)
    if instance and INSTANCE_CHANNEL in ch:
        out.instance = ch[INSTANCE_CHANNEL].astype(np.uint32, copy=False)
    if semantic and SEMANTIC_CHANNEL in ch:
        out.semantic = ch[SEMANTIC_CHANNEL].astype(np.uint32, copy=False)
    for what in require:
        if getattr(out, what) is None:
            names = {"rgb": "R, G, B", "depth": DEPTH_CHANNEL, "instance": INSTANCE_CHANNEL, "semantic": SEMANTIC_CHANNEL}[what]
            raise FrameFileError(f"{path}: missing channel(s) {names} ({what}); it has {sorted(ch)}")
    return out


def frame_name(index: int) -> str:
    return f"{index:06d}.exr"
