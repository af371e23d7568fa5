"""Atomic file writes, one implementation for synth and reloc: a reader never sees a half-written file.

A file is written under a hidden temporary name in its own folder (``.NAME.PID.tmp``: the process
id keeps two writers of the same file apart), then renamed into place; on failure the temporary
file is removed. ``synth dataset check`` reports stray ``.*.tmp`` files left by a killed process.
"""

from __future__ import annotations

import json
import os
from contextlib import contextmanager
from pathlib import Path

from .errors import UserError


def temp_name(path) -> Path:
    """The hidden temporary name ``path`` is written under before it is renamed into place."""
    path = Path(path)
    return path.with_name(f".{path.name}.{os.getpid()}.tmp")


@contextmanager
def replacing(path):
    """``with replacing(path) as tmp:`` write ``tmp``; on success it becomes ``path``, else it is removed."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = temp_name(path)
    try:
        yield tmp
        os.replace(tmp, path)
    except OSError as e:
        if e.filename is None:  # a write that failed (full disk, size limit) names no file: name the target
            raise OSError(e.errno, e.strerror, str(path)) from e
        raise
    finally:
        if tmp.exists():
            tmp.unlink()


def write_text_atomic(path, text: str) -> Path:
    with replacing(path) as tmp:
        tmp.write_text(text)
    return Path(path)


def write_bytes_atomic(path, data: bytes) -> Path:
    with replacing(path) as tmp:
        tmp.write_bytes(data)
    return Path(path)


def write_json_atomic(path, data, indent: int | None = 2) -> Path:
    return write_text_atomic(path, json.dumps(data, indent=indent) + "\n")


def save_npz_atomic(path, compressed: bool = True, **arrays) -> Path:
    """numpy .npz, atomically: the archive ``np.savez`` writes (one ``NAME.npy`` per array, read by
    ``np.load``), but closed in order when a write fails (a full disk), so that the error is the
    only message (numpy's own writer leaves its zip file to a destructor that fails again)."""
    import zipfile

    import numpy as np
    from numpy.lib import format as npy

    comp = zipfile.ZIP_DEFLATED if compressed else zipfile.ZIP_STORED
    with replacing(path) as tmp, open(tmp, "wb") as f, zipfile.ZipFile(f, "w", compression=comp, allowZip64=True) as z:
        for name, value in arrays.items():
            with z.open(f"{name}.npy", "w", force_zip64=True) as fid:
                npy.write_array(fid, np.asanyarray(value), allow_pickle=False)
    return Path(path)


def save_figure(fig, out_path, dpi: float) -> Path:
    """Write a matplotlib figure atomically (temporary name next to the target, then rename).

    The format follows the extension (no extension: png); an unsupported one is a UserError.
    Metadata that changes on every run (dates, software) is left out, so reruns give equal files.
    """
    out = Path(out_path)
    fmt = out.suffix.lower().lstrip(".") or "png"
    supported = fig.canvas.get_supported_filetypes()
    if fmt not in supported:
        raise UserError(f"{out}: cannot write '.{fmt}' plots; use one of: {', '.join(sorted(supported))}")
    meta = {"png": {"Software": None}, "pdf": {"CreationDate": None, "Producer": None}, "svg": {"Date": None}}.get(fmt)
    with replacing(out) as tmp:
        fig.savefig(tmp, format=fmt, dpi=dpi, facecolor="white", metadata=meta)
    return out
