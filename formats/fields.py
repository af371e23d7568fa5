"""Typed field checks for the files the toolkit reads: one set, shared by both halves.

Every check takes ``(file, value, field)`` and either returns the value in its checked type or raises
``SceneFormatError(file, field, message)``, whose text reads ``FILE: FIELD: message`` (one line,
``formats.errors``). ``field`` is a dotted path into the document (``designs[0].path.frames``) or
None for the whole file. Booleans are never numbers (``True`` is not 1), and a YAML ``"no"`` is not
``False``: a boolean field takes only ``true``/``false``.
"""

from __future__ import annotations

import math
from typing import NoReturn

import numpy as np

from .errors import SceneFormatError


def fail(file, field: str | None, msg: str) -> NoReturn:
    raise SceneFormatError(file, field, msg)


def _is_number(v) -> bool:
    return not isinstance(v, bool) and isinstance(v, (int, float)) and math.isfinite(float(v))


def number(file, v, field: str, positive: bool = False, lo: float | None = None) -> float:
    """A finite number (int or float); ``positive``: > 0; ``lo``: >= lo."""
    if not _is_number(v):
        fail(file, field, f"expected a finite number, got {v!r}")
    if positive and v <= 0:
        fail(file, field, f"must be > 0, got {v!r}")
    if lo is not None and v < lo:
        fail(file, field, f"must be >= {lo}, got {v!r}")
    return float(v)


def integer(file, v, field: str, lo: int | None = None) -> int:
    """An integer (not a bool, not 2.0); ``lo``: >= lo."""
    if isinstance(v, bool) or not isinstance(v, int):
        fail(file, field, f"expected an integer, got {v!r}")
    if lo is not None and v < lo:
        fail(file, field, f"expected an integer >= {lo}, got {v!r}")
    return v


def positive_int(file, v, field: str) -> int:
    if isinstance(v, bool) or not isinstance(v, int) or v <= 0:
        fail(file, field, f"expected a positive integer, got {v!r}")
    return v


def numbers(file, v, field: str, n: int, what: str = "", positive: bool = False) -> np.ndarray:
    """A list of exactly ``n`` finite numbers (``what`` names them in the message: " (w, x, y, z)")."""
    if not (isinstance(v, list) and len(v) == n and all(_is_number(x) for x in v)):
        fail(file, field, f"expected {n} numbers{what}, got {v!r}")
    if positive and any(x <= 0 for x in v):
        fail(file, field, f"expected {n} numbers > 0{what}, got {v!r}")
    return np.array([float(x) for x in v])


def unit_quat(file, v, field: str) -> np.ndarray:
    """A unit quaternion (w, x, y, z) within 1e-3 of norm 1, returned normalised."""
    q = numbers(file, v, field, 4, " (w, x, y, z)")
    n = float(np.linalg.norm(q))
    if abs(n - 1.0) > 1e-3:
        fail(file, field, f"expected a unit quaternion (w, x, y, z), got {v!r} (norm {n:.4f})")
    return q / n


def string(file, v, field: str) -> str:
    if not isinstance(v, str) or not v:
        fail(file, field, f"expected a non-empty string, got {v!r}")
    return v


def text(file, v, field: str) -> str:
    """Free text (a description); may be empty, but must be text."""
    if not isinstance(v, str):
        fail(file, field, f"expected text, got {v!r}")
    return v


def names(file, v, field: str) -> list[str]:
    """A non-empty list of non-empty strings; a single string is a list of one."""
    if isinstance(v, str):
        v = [v]
    if not isinstance(v, list) or not v or not all(isinstance(x, str) and x for x in v):
        fail(file, field, f"expected a non-empty list of names, got {v!r}")
    return list(v)


def boolean(file, v, field: str) -> bool:
    if not isinstance(v, bool):
        fail(file, field, f"expected true or false, got {v!r}")
    return v


def mapping(file, v, field: str | None) -> dict:
    if not isinstance(v, dict):
        fail(file, field, f"expected a JSON object, got {type(v).__name__}")
    return v


def listing(file, v, field: str) -> list:
    if not isinstance(v, list):
        fail(file, field, f"expected a list, got {type(v).__name__}")
    return v


# a frame's size: at most 8192 px a side and 16.8 million pixels (4096 x 4096); a frame of that size
# holds about 400 MB in memory while it is rendered and written (RGB, depth, instance and class ids)
MAX_SIDE = 8192
MAX_PIXELS = 4096 * 4096
BYTES_PER_PIXEL = 24


def frame_size(file, v, field: str) -> tuple[int, int]:
    """``[width, height]`` in pixels, within the bounds above (checked before anything is written)."""
    if not isinstance(v, list) or len(v) != 2:
        fail(file, field, f"expected [width, height], got {v!r}")
    w, h = (positive_int(file, x, field) for x in v)
    if max(w, h) > MAX_SIDE or w * h > MAX_PIXELS:
        fail(file, field, f"{w}x{h} is too large: at most {MAX_SIDE} px a side and {MAX_PIXELS:,} pixels "
                          f"(a frame would need about {w * h * BYTES_PER_PIXEL / 2**30:.1f} GiB)")
    return w, h


def out_folder(file, v, field: str = "out") -> str:
    """A spec's output folder: a non-empty string; a relative one may not climb out of the working
    folder it is resolved against (``../..``): give an absolute path, or ``--out`` on the command line."""
    import os

    s = string(file, v, field)
    if not os.path.isabs(s):
        norm = os.path.normpath(s)
        if norm == ".." or norm.startswith(".." + os.sep):
            fail(file, field, f"{s!r} leaves the working folder; give an absolute path in the spec, or --out")
    return s
