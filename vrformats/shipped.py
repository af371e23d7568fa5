"""Files the packages ship, and the shipped-name lookup of the command lines' spec arguments.

The toolkit is installed unzipped (from a wheel, or editable from a checkout), so the
``importlib.resources.files`` of one of its packages is a folder on disk: :func:`package_dir`
returns it as a ``Path`` (``reloc/models``, ``reloc/specs`` lie in it); :func:`shipped_folder` finds
synth's ``scenes/`` and ``render_jobs/``, at the checkout's root or inside the installed package. :func:`resolve_spec` turns a spec argument into a file: a path that exists always wins; a bare
name (no folder, no suffix: ``synth render demo``, ``reloc check demo_checks``) is the shipped spec
of that name; an unknown name is one line that lists the shipped names (exit status 2).
"""

from __future__ import annotations

import os
from pathlib import Path

from .errors import UnknownNameError


def package_dir(package: str) -> Path:
    """The folder of an installed package (imports the package, as ``importlib.resources`` does)."""
    from importlib.resources import files

    t = files(package)
    if isinstance(t, Path):
        return t
    try:  # e.g. a namespace package's MultiplexedPath: its first folder
        return Path(os.fspath(t))
    except TypeError:
        raise RuntimeError(f"{package} is not installed as a folder ({t!r}); the toolkit reads its shipped data "
                           "from files on disk: install it unzipped (pip install, or pip install -e .)") from None


def shipped_folder(package_folder: Path, name: str) -> Path:
    """A data folder the design card puts at the top level (``scenes``, ``render_jobs``): inside the
    package when installed from a wheel (pyproject.toml's package-dir maps ``synth.NAME`` onto the root
    folder ``NAME/``), else at the root of the checkout the package lies in."""
    inside = Path(package_folder) / name
    return inside if inside.is_dir() else Path(package_folder).resolve().parent / name


def is_bare_name(arg) -> bool:
    """``demo``, not ``demo.yaml``, ``./demo`` or ``specs/demo``."""
    s = str(arg)
    return bool(s) and s not in (".", "..") and "/" not in s and "\\" not in s and Path(s).suffix == ""


def shipped_names(folder: Path, key: str | None = None) -> list[str]:
    """The names of the ``*.yaml`` specs in ``folder``; with ``key``, only those whose top level has it
    (``designs``: render jobs, ``seeds``: trainsets, ``render``: experiments, ``checks``: checks)."""
    from .yamlfile import read_yaml

    out = []
    for p in sorted(Path(folder).glob("*.yaml")):
        if key is not None:
            try:
                doc = read_yaml(p)
            except Exception:  # a broken shipped spec is reported when it is asked for, not here
                continue
            if not isinstance(doc, dict) or key not in doc:
                continue
        out.append(p.stem)
    return out


def resolve_spec(arg, folder: Path, what: str, key: str | None = None) -> Path:
    """A spec argument as a file: an existing file as given; a bare name, the shipped spec
    ``folder/NAME.yaml`` (of the kind ``key`` marks, see :func:`shipped_names`); anything else as
    given (its loader says it is not found). An unknown bare name raises ``UnknownNameError``."""
    p = Path(arg)
    if p.is_file() or not is_bare_name(arg):
        return p
    return shipped_file(str(arg), folder, what, key)


def shipped_file(name: str, folder: Path, what: str, key: str | None = None) -> Path:
    """The shipped spec ``folder/NAME.yaml`` (of the kind ``key`` marks); ``UnknownNameError`` (listing
    the names) when there is none. A shipped file that does not parse is returned all the same: its
    loader reports what is wrong with it, rather than calling it missing."""
    from .yamlfile import read_yaml

    p = Path(folder) / f"{name}.yaml"
    if p.is_file():
        if key is None:
            return p
        try:
            doc = read_yaml(p)
        except Exception:
            return p
        if isinstance(doc, dict) and key in doc:
            return p
    names = shipped_names(folder, key)
    raise UnknownNameError(f"{name}: no such file, and no shipped {what} of that name; shipped: "
                           f"{', '.join(names) or 'none'} (in {folder})")
