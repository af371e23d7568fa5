"""A render job's folder on an fsspec file system: ``synth render SPEC --out URI --backend ray``.

``--out`` (or the spec's ``out``) names the job folder. A plain path, or ``file://PATH`` with the
local backend, is a folder on this machine as before. A URI (``file://``, ``memory://``, and in
principle any fsspec scheme whose package is installed: ``s3://`` with s3fs, ``gs://`` with gcsfs...)
with the Ray backend puts the job folder on that file system: the driver, which receives every
frame's bytes from the nodes (``synth.jobs.ray_backend``, "frames come home"), writes them there, and
writes the job's own files there too.

- **Staging**: the driver keeps the job's small files (each tour's ``camera.json``, ``poses.txt``,
  ``objects.json``, ``meta.json``; ``design.json``, ``job_state.json``, ``job_summary.json``, the
  chunks' job files and logs under ``.work/``) in a local temporary folder and copies each one up
  when it is written. Frames never touch the driver's disk: they go from the task's bytes to the
  storage. ``Storage`` maps a path in the staging folder to the same relative path in the storage.
- **Atomic writes**: on a file system with a rename (``file://``: fsspec's local file system) a file
  is written under the hidden temporary name ``.NAME.PID.tmp`` (``vrformats.atomic.temp_name``) and
  renamed into place. Elsewhere a file is written with one put (``pipe_file``): ``memory://``
  stores the bytes when the write is complete, and object stores make an object visible only once
  it has been uploaded whole; that is atomic enough, and a rename there would be a copy.
- **Resume**: which frames exist is read from the storage (one listing per frames folder, kept up
  to date by the driver's own writes), and the job state from its ``job_state.json``.
"""

from __future__ import annotations

import posixpath
import re
from pathlib import Path

from vrformats.atomic import write_bytes_atomic
from vrformats.errors import UserError, check_output_folder
from vrformats import frames as fr

_SCHEME = re.compile(r"^([A-Za-z][A-Za-z0-9+.-]*)://")


def is_uri(text) -> bool:
    """``scheme://...`` (a plain path, even ``C:/x`` or ``./a://b``, is not)."""
    return isinstance(text, str) and bool(_SCHEME.match(text))


def scheme(uri: str) -> str:
    m = _SCHEME.match(uri)
    return m.group(1).lower() if m else ""


def local_path(uri: str) -> Path | None:
    """The path of a ``file://`` URI, else None."""
    if scheme(uri) != "file":
        return None
    from fsspec.implementations.local import LocalFileSystem

    return Path(LocalFileSystem._strip_protocol(uri))


class Storage:
    """A job folder at ``uri``; paths are given as paths in the local staging folder (``bind``)."""

    def __init__(self, uri: str, option: str = "--out"):
        try:
            import fsspec
        except ImportError:
            raise UserError(f"{option} {uri}: a storage URI needs fsspec: pip install fsspec") from None
        s = scheme(uri)
        try:
            fs, root = fsspec.core.url_to_fs(uri)
        except ValueError as e:
            raise UserError(f"{option} {uri}: unknown storage scheme '{s}://' ({e}); use a path, file:// or memory://, "
                            "or another scheme fsspec knows") from None
        except ImportError as e:
            raise UserError(f"{option} {uri}: the {s}:// storage needs a package fsspec does not have here ({e})") from None
        self.uri = uri.rstrip("/")
        self.option = option
        self.fs = fs
        self.root = root.rstrip("/") or "/"
        protocols = fs.protocol if isinstance(fs.protocol, (tuple, list)) else (fs.protocol,)
        self.renames = "file" in protocols or "local" in protocols  # a rename that replaces atomically
        self.staging: Path | None = None
        self._listed: dict[str, set[str]] = {}
        self._dirs: set[str] = set()

    # -- paths

    def bind(self, staging: Path) -> "Storage":
        self.staging = Path(staging)
        return self

    def rel(self, path) -> str:
        """The path relative to the job folder of a path in the staging folder (or already relative)."""
        p = Path(path)
        if p.is_absolute():
            if self.staging is None:
                raise ValueError("Storage.bind(staging) first")
            p = p.relative_to(self.staging)
        return p.as_posix()

    def rpath(self, path) -> str:
        rel = self.rel(path)
        return self.root if rel in ("", ".") else posixpath.join(self.root, rel)

    def url(self, path) -> str:
        rel = self.rel(path)
        return self.uri if rel in ("", ".") else f"{self.uri}/{rel}"

    # -- checks

    def check_writable(self) -> None:
        """A local storage folder can be made (``vrformats.errors.check_output_folder``; writes nothing)."""
        if self.renames:
            try:
                check_output_folder(self.root)
            except UserError as e:
                raise UserError(f"{self.option} {self.uri}: {e}") from None

    # -- reading

    def exists(self, path) -> bool:
        return self.fs.exists(self.rpath(path))

    def read_bytes(self, path) -> bytes:
        try:
            return self.fs.cat_file(self.rpath(path))
        except FileNotFoundError:
            raise FileNotFoundError(f"{self.url(path)}: no such file") from None

    def read_text(self, path) -> str:
        return self.read_bytes(path).decode("utf-8")

    def names(self, folder) -> set[str]:
        """The file names in a folder (listed once, then kept up to date by ``write_bytes``)."""
        r = self.rpath(folder)
        if r not in self._listed:
            try:
                self._listed[r] = {posixpath.basename(p.rstrip("/")) for p in self.fs.ls(r, detail=False)}
            except FileNotFoundError:
                self._listed[r] = set()
        return self._listed[r]

    def missing(self, folder, frames) -> list[int]:
        have = self.names(folder)
        return [i for i in frames if fr.frame_name(i) not in have]

    # -- writing

    def write_bytes(self, path, data: bytes) -> None:
        """Write a file atomically: a temporary name then a rename where the file system renames, one put
        elsewhere."""
        r = self.rpath(path)
        parent, name = posixpath.split(r)
        try:
            if self.renames:
                if parent not in self._dirs:
                    self.fs.makedirs(parent, exist_ok=True)
                    self._dirs.add(parent)
                write_bytes_atomic(r, data)  # this machine's files: never through a planted link (vrformats.atomic)
            else:
                self.fs.pipe_file(r, data)
        except OSError as e:
            raise UserError(f"{self.url(path)}: cannot write ({e.strerror or e})") from None
        if parent in self._listed:
            self._listed[parent].add(name)

    def write_text(self, path, text: str) -> None:
        self.write_bytes(path, text.encode("utf-8"))

    def copy(self, src, dst) -> None:
        """Copy a file within the storage (read, then an atomic write)."""
        self.write_bytes(dst, self.read_bytes(src))

    def push_tree(self, folder, skip=(".work",)) -> int:
        """Copy every file under a staging folder up (the job's small files); returns how many."""
        n = 0
        base = Path(folder)
        for p in sorted(base.rglob("*")):
            rel = p.relative_to(base)
            if p.is_file() and not (rel.parts and rel.parts[0] in skip) and not p.name.startswith("."):
                self.write_bytes(p, p.read_bytes())
                n += 1
        return n

    def remove_tree(self, path) -> None:
        r = self.rpath(path)
        if self.fs.exists(r):
            self.fs.rm(r, recursive=True)
        for k in [k for k in self._listed if k == r or k.startswith(r + "/")]:
            del self._listed[k]
        self._dirs = {d for d in self._dirs if not (d == r or d.startswith(r + "/"))}
