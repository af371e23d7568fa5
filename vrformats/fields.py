"""Typed field checks for the files the toolkit reads: one set, shared by both halves.

Every check takes ``(file, value, field)`` and either returns the value in its checked type or raises
``SceneFormatError(file, field, message)``, whose text reads ``FILE: FIELD: message`` (one line,
``vrformats.errors``). ``field`` is a dotted path into the document (``designs[0].path.frames``) or
None for the whole file. Booleans are never numbers (``True`` is not 1), and a YAML ``"no"`` is not
``False``: a boolean field takes only ``true``/``false``.
"""

from __future__ import annotations

import math
import os
import re
import reprlib
from pathlib import Path
from typing import NoReturn

import numpy as np

from .errors import SceneFormatError


def fail(file, field: str | None, msg: str) -> NoReturn:
    raise SceneFormatError(file, field, msg)


_SHOWN = reprlib.Repr()
_SHOWN.maxstring, _SHOWN.maxother, _SHOWN.maxlevel = 80, 80, 3
_SHOWN.maxlist = _SHOWN.maxtuple = _SHOWN.maxdict = _SHOWN.maxset = 6


def shown(v) -> str:
    """A bounded excerpt of a value for an error message (at most ~80 characters a string, 6 items a
    list, 3 levels deep): a YAML alias bomb or a 100k-character name is never repr()'d whole."""
    try:
        return _SHOWN.repr(v)
    except Exception:  # a hostile __repr__ cannot be one here (YAML and JSON give plain types), but be safe
        return f"<{type(v).__name__}>"


ALLOW_OUTSIDE_ENV = "SYNTH_ALLOW_OUTSIDE_ROOT"


def inside_root(file, field: str | None, path, root, what: str = "the dataset folder") -> Path:
    """``path`` (normalised), refused in one line naming ``file`` and ``field`` when it resolves
    (links followed) outside ``root``: a dataset or spec cannot make the toolkit read other files of
    the user's. ``SYNTH_ALLOW_OUTSIDE_ROOT=1`` in the environment allows such paths on purpose. The
    one home of that rule; checked before the file is opened or even tested for existence."""
    p = Path(os.path.normpath(path))
    if os.environ.get(ALLOW_OUTSIDE_ENV) == "1":
        return p
    try:
        rp, rr = p.resolve(), Path(root).resolve()
    except (OSError, RuntimeError) as e:  # a link loop
        fail(file, field, f"cannot resolve {shown(str(path))}: {e}")
    if rp != rr and rr not in rp.parents:
        fail(file, field, f"{shown(str(path))} lies outside {what} {rr}; set {ALLOW_OUTSIDE_ENV}=1 to allow "
                          "paths outside it on purpose")
    return p


MAX_NAME = 120  # characters of a name (a spec's, a preset's, a check's): names are printed on every progress refresh
# control characters (C0, DEL, C1) and the bidirectional overrides and isolates (Trojan Source)
_UNSAFE = re.compile("[\x00-\x1f\x7f-\x9f\u061c\u200e\u200f\u202a-\u202e\u2066-\u2069]")


def terminal_safe(text) -> str:
    """``text`` with control and bidi characters escaped (``\\x1b``, ``\\u202e``): what a file says can
    be printed without driving the terminal (colours, cursor moves, a reversed line). The one home of
    that rule: error lines (``vrformats.cli``) and progress bars go through it."""
    t = str(text)
    return _UNSAFE.sub(lambda m: m.group(0).encode("unicode_escape").decode("ascii"), t) if _UNSAFE.search(t) else t


def clean_name(name: str, file, field: str | None) -> str:
    """A name a user gave: text of at most ``MAX_NAME`` characters without control or bidi characters."""
    if len(name) > MAX_NAME:
        fail(file, field, f"a name of {len(name)} characters; at most {MAX_NAME}")
    if _UNSAFE.search(name):
        fail(file, field, f"{terminal_safe(shown(name))} holds control or bidirectional characters")
    return name


def name_text(file, v, field: str = "name") -> str:
    """A spec's or preset's ``name``: non-empty text, ``clean_name``'s rules."""
    return clean_name(string(file, v, field), file, field)


def is_number(v) -> bool:
    """A finite int or float; never a bool (``True`` is not 1). The one number test of the toolkit."""
    return not isinstance(v, bool) and isinstance(v, (int, float)) and math.isfinite(float(v))


def is_integer(v) -> bool:
    """An int, never a bool (``True`` is not 1) and never a float (2.0 is not an integer here)."""
    return isinstance(v, int) and not isinstance(v, bool)


def number(file, v, field: str, positive: bool = False, lo: float | None = None, hi: float | None = None) -> float:
    """A finite number (int or float); ``positive``: > 0; ``lo``: >= lo; ``hi``: <= hi."""
    if not is_number(v):
        fail(file, field, f"expected a finite number, got {shown(v)}")
    if positive and v <= 0:
        fail(file, field, f"must be > 0, got {shown(v)}")
    if lo is not None and v < lo:
        fail(file, field, f"must be >= {lo}, got {shown(v)}")
    if hi is not None and v > hi:
        fail(file, field, f"must be <= {hi}, got {shown(v)}")
    return float(v)


def integer(file, v, field: str, lo: int | None = None, hi: int | None = None) -> int:
    """An integer (not a bool, not 2.0); ``lo``: >= lo; ``hi``: <= hi."""
    if not is_integer(v):
        fail(file, field, f"expected an integer, got {shown(v)}")
    if lo is not None and v < lo:
        fail(file, field, f"expected an integer >= {lo}, got {shown(v)}")
    if hi is not None and v > hi:
        fail(file, field, f"expected an integer <= {hi}, got {shown(v)}")
    return v


def positive_int(file, v, field: str) -> int:
    if not is_integer(v) or v <= 0:
        fail(file, field, f"expected a positive integer, got {shown(v)}")
    return v


def nonneg_int(file, v, field: str) -> int:
    """An integer >= 0 (a seed, a count, a retry budget)."""
    if not is_integer(v) or v < 0:
        fail(file, field, f"expected a non-negative integer, got {shown(v)}")
    return v


def whole_number(file, v, field: str, positive: bool = False) -> int:
    """A finite number that is whole (640 or 640.0, as JSON writers may give it), as an int."""
    x = number(file, v, field, positive=positive)
    if x != int(x):
        fail(file, field, f"expected an integer, got {shown(v)}")
    return int(x)


def required(file, d: dict, key: str, field: str | None = None):
    """``d[key]``, or a one-line error naming the field (``field``, default ``key``) when it is missing."""
    if key not in d:
        fail(file, field or key, "missing")
    return d[key]


def vector(file, v, field: str, n: int, positive: bool = False) -> tuple[float, ...]:
    """A list of exactly ``n`` finite numbers as a tuple of floats; an element that is not one is
    named by its index (``position[2]``), ``positive``: each > 0."""
    if not isinstance(v, (list, tuple)) or len(v) != n:
        fail(file, field, f"expected a list of {n} numbers, got {shown(v)}")
    return tuple(number(file, x, f"{field}[{i}]", positive=positive) for i, x in enumerate(v))


def numbers(file, v, field: str, n: int, what: str = "", positive: bool = False) -> np.ndarray:
    """A list of exactly ``n`` finite numbers (``what`` names them in the message: " (w, x, y, z)")."""
    if not (isinstance(v, list) and len(v) == n and all(is_number(x) for x in v)):
        fail(file, field, f"expected {n} numbers{what}, got {shown(v)}")
    if positive and any(x <= 0 for x in v):
        fail(file, field, f"expected {n} numbers > 0{what}, got {shown(v)}")
    return np.array([float(x) for x in v])


def unit_quat(file, v, field: str) -> np.ndarray:
    """A unit quaternion (w, x, y, z) within 1e-3 of norm 1, returned normalised."""
    q = numbers(file, v, field, 4, " (w, x, y, z)")
    n = float(np.linalg.norm(q))
    if abs(n - 1.0) > 1e-3:
        fail(file, field, f"expected a unit quaternion (w, x, y, z), got {shown(v)} (norm {n:.4f})")
    return q / n


def string(file, v, field: str) -> str:
    if not isinstance(v, str) or not v:
        fail(file, field, f"expected a non-empty string, got {shown(v)}")
    return v


def text(file, v, field: str) -> str:
    """Free text (a description); may be empty, but must be text."""
    if not isinstance(v, str):
        fail(file, field, f"expected text, got {shown(v)}")
    return v


def names(file, v, field: str) -> list[str]:
    """A non-empty list of non-empty strings; a single string is a list of one."""
    if isinstance(v, str):
        v = [v]
    if not isinstance(v, list) or not v or not all(isinstance(x, str) and x for x in v):
        fail(file, field, f"expected a non-empty list of names, got {shown(v)}")
    return list(v)


def boolean(file, v, field: str) -> bool:
    """``true`` or ``false``; not 1, not "yes"."""
    if not isinstance(v, bool):
        fail(file, field, f"expected true or false, got {shown(v)}")
    return v


def mapping(file, v, field: str | None, allowed=None, required=(), what: str = "a JSON object") -> dict:
    """A mapping (``what`` names it in the message: a YAML file says "a mapping"); ``allowed``: the
    keys it may have (others are refused, naming them), ``required``: the keys it must have."""
    if not isinstance(v, dict):
        fail(file, field, f"expected {what}, got {type(v).__name__}")
    if allowed is not None:
        unknown = set(v) - set(allowed)
        if unknown:
            fail(file, field, f"unknown key(s) {sorted(map(str, unknown))}; allowed: {sorted(allowed)}")
    missing = set(required) - set(v)
    if missing:
        fail(file, field, f"missing key(s) {sorted(missing)}")
    return v


def listing(file, v, field: str, none_is_empty: bool = False) -> list:
    """A list; ``none_is_empty``: a missing (None) value is an empty list."""
    if v is None and none_is_empty:
        return []
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
        fail(file, field, f"expected [width, height], got {shown(v)}")
    w, h = (positive_int(file, x, field) for x in v)
    problem = size_problem(w, h)
    if problem:
        fail(file, field, problem)
    return w, h


def size_problem(w: int, h: int) -> str | None:
    """Why a ``w`` x ``h`` frame is too large to render (the bounds above), or None."""
    if max(w, h) > MAX_SIDE or w * h > MAX_PIXELS:
        return (f"{w}x{h} is too large: at most {MAX_SIDE} px a side and {MAX_PIXELS:,} pixels "
                f"(a frame would need about {w * h * BYTES_PER_PIXEL / 2**30:.1f} GiB)")
    return None


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
