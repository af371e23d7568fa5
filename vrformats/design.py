"""A rendered design on disk: its tours, named ``<layout>__<lighting>__<path>``, listed from their files.

A render job (``synth render SPEC``) writes into its output folder::

    OUT/design.json     {"format": "videoreloc-design/1", "job": NAME, "spec": SPEC FILE,
                         "tours": {tour name: {"layout", "lighting", "path", "n_frames"}}}
    OUT/<tour name>/    one tour each (``vrformats.tour``), whose meta.json records the same fields

``design.json`` is written before any frame is rendered, so a reader knows which tours are still
missing; each tour's ``meta.json`` is written when its frames are done. Readers of a design
(``reloc experiment``) need nothing else: ``list_tours`` reads the tours' meta.json, and
``read_design`` the planned set.
"""

from __future__ import annotations

from pathlib import Path

from .atomic import write_json_atomic
from .errors import SceneFormatError
from .yamlfile import read_json

DESIGN_FORMAT = "videoreloc-design/1"
DESIGN_FILE = "design.json"
GEOMETRY = "geometry"  # the lighting part of a geometry-only tour's name


def short_name(name: str) -> str:
    """A layout, lighting or path given as a file stands for its stem in tour names (a path in the
    name would put the tour outside the design's folder)."""
    p = Path(name)
    if "/" in name or "\\" in name or p.suffix.lower() in (".yaml", ".yml", ".json", ".txt", ".tum"):
        return p.stem
    return name


def tour_name(layout: str, lighting: str | None, path: str) -> str:
    """The folder name of a tour in a design: ``<layout>__<lighting>__<path>``."""
    return f"{short_name(layout)}__{short_name(lighting) if lighting else GEOMETRY}__{short_name(path)}"


def write_design(out, job: str, spec, tours: dict[str, dict]) -> Path:
    """``OUT/design.json``: the tours a job will render (name -> layout, lighting, path, n_frames)."""
    doc = {"format": DESIGN_FORMAT, "job": job, "spec": str(spec) if spec else None,
           "tours": {n: {k: t.get(k) for k in ("layout", "lighting", "path", "n_frames")} for n, t in sorted(tours.items())}}
    return write_json_atomic(Path(out) / DESIGN_FILE, doc, indent=1)


def read_design(root) -> dict | None:
    """The planned tours of the design in ``root`` ({name: {layout, lighting, path, n_frames}}), or
    None when ``root`` has no design.json (tours rendered one by one with ``synth tour render``)."""
    path = Path(root) / DESIGN_FILE
    if not path.is_file():
        return None
    doc = read_json(path)
    if doc.get("format") != DESIGN_FORMAT:
        raise SceneFormatError(path, "format", f"expected {DESIGN_FORMAT!r}, got {doc.get('format')!r}")
    tours = doc.get("tours")
    if not isinstance(tours, dict):
        raise SceneFormatError(path, "tours", "expected a mapping of tour name -> layout, lighting, path")
    for name, t in tours.items():
        if not isinstance(t, dict) or not isinstance(t.get("layout"), str) or not isinstance(t.get("path"), str):
            raise SceneFormatError(path, f"tours.{name}", "expected layout and path names")
    return tours


def list_tours(root) -> dict[str, dict]:
    """The tours in ``root`` that have a meta.json: {folder name: meta.json}; each meta has at least
    layout, lighting (None: geometry only) and path. A malformed meta.json is an error naming it."""
    root = Path(root)
    if not root.is_dir():
        return {}
    out = {}
    for d in sorted(p for p in root.iterdir() if p.is_dir() and not p.name.startswith(".")):
        f = d / "meta.json"
        if not f.is_file():
            continue
        meta = read_json(f)
        for k in ("layout", "path"):
            if not isinstance(meta.get(k), str):
                raise SceneFormatError(f, k, "expected a name")
        out[d.name] = meta
    return out
