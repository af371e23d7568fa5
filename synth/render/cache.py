"""A cache of what a render chunk computes before Blender sees the scene and that depends only on its
inputs: today the structure id of every triangle of a mesh stage (``synth.render.meshes``: which
wall, floor or ceiling it belongs to), about 20 s of Python per chunk for a ReplicaCAD apartment and
the same in every chunk of a job.

Entries are ``.npy`` files (read with ``allow_pickle=False``), named by the SHA-256 of everything the
value depends on: the input files' bytes, the layout section that is read, the source of the modules
that compute it, and NumPy's version. A changed input or code is a new name, never a stale hit.
The folder is ``$SYNTH_CACHE_DIR`` if set (an empty value turns the cache off), else
``$XDG_CACHE_HOME/videoreloc-synth`` or ``~/.cache/videoreloc-synth``. Entries are written
atomically; a folder that cannot be written only costs the computation, and an entry that cannot be
read is computed again.
"""

from __future__ import annotations

import functools
import hashlib
import os
from pathlib import Path

import numpy as np

from vrformats.errors import UserError

ENV = "SYNTH_CACHE_DIR"


def cache_dir() -> Path | None:
    """The cache folder, or None when the cache is off (``SYNTH_CACHE_DIR=``)."""
    v = os.environ.get(ENV)
    if v is not None:
        return Path(v) if v.strip() else None
    base = os.environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache")
    return Path(base) / "videoreloc-synth"


@functools.lru_cache(maxsize=256)
def file_digest(path: str, size: int, mtime_ns: int) -> str:
    """SHA-256 of a file's bytes (remembered per path, size and modification time in this process)."""
    h = hashlib.sha256()
    with open(path, "rb") as f:
        for block in iter(lambda: f.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()


def digest_of_file(path) -> str:
    st = os.stat(path)
    return file_digest(str(Path(path).resolve()), st.st_size, st.st_mtime_ns)


def code_digest(*modules: str) -> str | None:
    """SHA-256 of the source files of the named modules (the code a cached value comes from), and of
    NumPy's version; None when one of them is no module file (a stand-in put in its place): then
    nothing is cached."""
    import importlib

    h = hashlib.sha256(np.__version__.encode())
    for name in modules:
        f = getattr(importlib.import_module(name), "__file__", None)
        if not f:
            return None
        h.update(_source(f))
    return h.hexdigest()


@functools.lru_cache(maxsize=64)
def _source(path: str) -> bytes:
    return Path(path).read_bytes()


def cached_array(kind: str, key: list[str | None], compute, validate=None) -> np.ndarray:
    """``compute()``'s array, read from the cache when an entry of this ``kind`` and ``key`` exists (and
    ``validate(array)`` accepts it), else computed and stored. A key with a None in it (a part that
    cannot be told, e.g. ``code_digest`` of a stand-in) is never cached."""
    d = cache_dir() if None not in key else None
    f = d / kind / (hashlib.sha256("\n".join([kind, *key]).encode()).hexdigest() + ".npy") if d is not None else None
    if f is not None and f.is_file() and not f.is_symlink():
        try:
            a = np.load(f, allow_pickle=False)
            if validate is None or validate(a):
                return a
        except (OSError, ValueError):
            pass  # unreadable: computed again and rewritten
    a = compute()
    if f is not None:
        try:
            from vrformats.atomic import replacing

            f.parent.mkdir(parents=True, exist_ok=True)
            with replacing(f) as tmp:
                with open(tmp, "wb") as out:
                    np.save(out, a, allow_pickle=False)
        except (OSError, UserError):
            pass  # a read-only or full disk, or a folder in the entry's place, only costs the computation
    return a
