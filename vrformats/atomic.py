"""Atomic file writes, one implementation for synth and reloc: a reader never sees a half-written file.

A file is written under a hidden temporary name in its own folder (``.NAME.PID.tmp``: the process
id keeps two writers of the same file apart), then renamed into place; on failure the temporary
file is removed. ``synth tour check`` reports stray ``.*.tmp`` files left by a killed process.

Links: no file the toolkit creates or overwrites is reached through a symbolic link it did not make
(a job folder may come from someone else). Atomic writes replace a link at the target instead of
following it, and make their temporary file exclusively; locks, logs and job files open with
``O_NOFOLLOW`` (``open_nofollow``) and refuse a link in one line.
"""

from __future__ import annotations

import errno
import json
import os
from contextlib import contextmanager
from pathlib import Path

from .errors import UserError


def refuse_link(path, err: OSError | None = None) -> None:
    """Raise the toolkit's one-line refusal for a write that would go through a symbolic link (or
    into a folder) that the toolkit did not make: a shared or downloaded folder must not make a run
    overwrite another file the user can write."""
    path = Path(path)
    if os.path.islink(path):
        raise UserError(f"{path}: is a symbolic link; the toolkit does not write through links it did not make "
                        "(remove it, or use another output folder)")
    if path.is_dir():
        raise UserError(f"{path}: is a folder where a file should be written (remove it, or use another output folder)")
    if err is not None:
        raise UserError(f"{path}: cannot write ({err.strerror or err})") from None


def open_nofollow(path, flags: int = os.O_WRONLY | os.O_CREAT | os.O_TRUNC, mode: int = 0o644) -> int:
    """``os.open`` that refuses a symbolic link as the last component (``O_NOFOLLOW``) with one line
    (``refuse_link``); the file descriptor is close-on-exec. The one home of that rule: locks,
    temporary files, logs and job files all open through it (or ``nofollow_opener``)."""
    try:
        return os.open(path, flags | os.O_NOFOLLOW | os.O_CLOEXEC, mode)
    except OSError as e:
        if e.errno in (errno.ELOOP, errno.EISDIR, errno.EEXIST) or os.path.islink(path):
            refuse_link(path, e)
        raise


def nofollow_opener(path, flags: int) -> int:
    """``open(path, "w", opener=nofollow_opener)``: the builtin ``open`` through ``open_nofollow``."""
    return open_nofollow(path, flags)


def write_nofollow(path, data: bytes | str) -> Path:
    """Write a file in place (not atomically: a job file, a log), refusing a symbolic link there."""
    path = Path(path)
    mode = "wb" if isinstance(data, bytes) else "w"
    with open(path, mode, opener=nofollow_opener) as f:
        f.write(data)
    return path


def temp_name(path) -> Path:
    """The hidden temporary name ``path`` is written under before it is renamed into place."""
    path = Path(path)
    return path.with_name(f".{path.name}.{os.getpid()}.tmp")


@contextmanager
def replacing(path):
    """``with replacing(path) as tmp:`` write ``tmp``; on success it becomes ``path``, else it is removed."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    if path.is_dir() and not path.is_symlink():
        refuse_link(path)
    tmp = temp_name(path)
    # the temporary name is predictable: whatever stands there (a stale file, a planted link) is
    # removed, and the file is made here, exclusively, so the writer opens our own regular file
    if os.path.lexists(tmp):
        if tmp.is_dir() and not tmp.is_symlink():
            refuse_link(tmp)
        tmp.unlink()
    os.close(open_nofollow(tmp, os.O_WRONLY | os.O_CREAT | os.O_EXCL))
    try:
        yield tmp
        os.replace(tmp, path)  # a link at ``path`` itself is replaced, never followed
    except OSError as e:
        if e.filename is None:  # a write that failed (full disk, size limit) names no file: name the target
            raise OSError(e.errno, e.strerror, str(path)) from e
        raise
    finally:
        if os.path.lexists(tmp):
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
