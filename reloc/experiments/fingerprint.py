"""What a result depends on, as short keys: the code that computes it and its inputs.

``code_fingerprint``: a hash of the sources that can compute a result (every module of ``reloc``
and the project modules it imports, found by reading the import statements) and of the numeric
libraries' versions. ``key_of``, ``file_key``, ``ground_truth_key``: keys of settings and input
files. A done-marker holds the key of everything its result depends on
(:mod:`reloc.experiments.tasks`), so a change of any of them recomputes the result.
"""

from __future__ import annotations

import ast
import functools
import hashlib
import json
from pathlib import Path

# ---------------------------------------------------------------------------------------------
# the code a result depends on

# The project's top-level packages (pyproject.toml's tool.setuptools.packages.find). A new one must
# be added here for the fingerprint to follow imports into it (tests check this list).
PROJECT_PACKAGES = ("vrformats", "reloc", "synth")
# Distributions whose version changes numbers: the numeric and image libraries reloc computes with.
LIBRARIES = ("numpy", "scipy", "open3d", "opencv-python-headless", "opencv-python", "OpenEXR", "onnxruntime")
SOURCE_ROOT = Path(__file__).resolve().parents[2]  # the folder holding the project's packages


def _module_file(root: Path, name: str) -> Path | None:
    """The source file of module ``name`` under ``root`` (a package's ``__init__.py``), or None."""
    p = root.joinpath(*name.split("."))
    for f in (p.with_suffix(".py"), p / "__init__.py"):
        if f.is_file():
            return f
    return None


def _imported_names(path: Path, module: str) -> set[str]:
    """Every module name an import statement of ``path`` may load, function-level ones included
    (``from a import b`` gives a and a.b: b may be a module)."""
    package = module if path.name == "__init__.py" else module.rpartition(".")[0]
    names: set[str] = set()
    for node in ast.walk(ast.parse(path.read_bytes(), filename=str(path))):
        if isinstance(node, ast.Import):
            names.update(a.name for a in node.names)
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                parts = package.split(".")
                base = ".".join(parts[: len(parts) - node.level + 1] + ([node.module] if node.module else []))
            else:
                base = node.module or ""
            names.add(base)
            names.update(f"{base}.{a.name}" for a in node.names)
    return names


def code_files(root: Path | None = None) -> list[Path]:
    """The sources whose code can compute a result: every module of the ``reloc`` package, and every
    module of the project's other packages (``PROJECT_PACKAGES``: vrformats, synth) that reloc imports, directly
    or through other such modules, with the ``__init__.py`` of each package on the way; found by
    reading the import statements. Sorted by path relative to ``root`` (default ``SOURCE_ROOT``)."""
    root = Path(root or SOURCE_ROOT)
    todo = sorted((root / "reloc").rglob("*.py"))
    seen = set(todo)
    while todo:
        f = todo.pop()
        module = ".".join(f.relative_to(root).with_suffix("").parts)
        for name in _imported_names(f, module.removesuffix(".__init__")):
            parts = name.split(".")
            if parts[0] not in PROJECT_PACKAGES:
                continue
            for k in range(1, len(parts) + 1):  # importing a.b.c runs a and a.b first
                g = _module_file(root, ".".join(parts[:k]))
                if g is not None and g not in seen:
                    seen.add(g)
                    todo.append(g)
    return sorted(seen, key=lambda f: f.relative_to(root).as_posix())


def library_versions() -> dict[str, str]:
    """Python's and each of ``LIBRARIES``' versions (``vrformats.environment.library_versions``)."""
    from vrformats.environment import library_versions as versions

    return versions(LIBRARIES)


def source_fingerprint(root: Path | None = None, versions: dict | None = None) -> str:
    """sha256 over ``code_files(root)`` (relative path and bytes of each) and the library versions."""
    root = Path(root or SOURCE_ROOT)
    h = hashlib.sha256()
    for f in code_files(root):
        data = f.read_bytes()
        h.update(f"{f.relative_to(root).as_posix()}\0{len(data)}\0".encode())
        h.update(data)
    h.update(json.dumps(library_versions() if versions is None else versions, sort_keys=True).encode())
    return h.hexdigest()[:16]


@functools.lru_cache(maxsize=1)
def code_fingerprint() -> str:
    """The fingerprint of the code this process computes with; part of every done-key, so that a
    change of reloc, of the synth modules it imports or of a numeric library recomputes the results
    (once per process: a few tens of files parsed and hashed)."""
    return source_fingerprint()


# ---------------------------------------------------------------------------------------------
# the inputs a result depends on


def key_of(*parts) -> str:
    """A short key of settings and input keys (JSON, sorted keys; what a done marker holds)."""
    return hashlib.sha1(json.dumps(parts, sort_keys=True, default=str).encode()).hexdigest()[:16]


def file_key(path, missing: str | None = None) -> str:
    """What a result depends on in a file: its content (a rebuilt identical map changes nothing).
    A path that is no file gives ``missing`` when that is given (else the OSError)."""
    if missing is not None and not Path(path).is_file():
        return missing
    h = hashlib.sha1()
    with open(path, "rb") as f:
        for block in iter(lambda: f.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()[:16]


def ground_truth_key(tour_dir) -> str:
    """What a ground-truth map depends on: the content of the tour's objects.json."""
    return "ground-truth:" + file_key(Path(tour_dir) / "objects.json")

