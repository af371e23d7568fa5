"""Where synth's shipped data lives: the design card's top-level folders ``scenes/`` and
``render_jobs/``, which the wheel ships inside the package as ``synth/scenes`` and
``synth/render_jobs`` (pyproject.toml's package-dir), so an installed wheel finds them as a checkout does.

- ``scenes/``: the layouts (``layouts/``), lighting presets (``lighting/``), camera paths
  (``paths/``), the class table (``classes.yaml``) and the ReplicaCAD lexicon
  (``replicacad_lexicon.yaml``). ``SYNTH_SCENES_DIR`` overrides the whole folder (a user's own
  scenes, or the scratch folder a Ray task materialises).
- ``render_jobs/``: the shipped render job and trainset specs; ``synth render demo`` is
  ``synth render render_jobs/demo.yaml`` (:func:`render_spec`, :func:`trainset_spec`).

``REPO_ROOT`` is the folder above the package: a source checkout when run from one
(:func:`checkout_root`), used only for the git commit and the Ray working_dir, never for data.
"""

from __future__ import annotations

import os
from pathlib import Path

from vrformats.shipped import package_dir, resolve_spec, shipped_folder, shipped_names

PACKAGE_DIR = package_dir("synth")
REPO_ROOT = PACKAGE_DIR.resolve().parent  # a checkout, or site-packages when installed
DATA_DIR = shipped_folder(PACKAGE_DIR, "scenes")  # the shipped scenes
SPECS_DIR = shipped_folder(PACKAGE_DIR, "render_jobs")  # the shipped render job and trainset specs


def checkout_root() -> Path | None:
    """The source checkout the running toolkit comes from, or None when it is installed (a wheel)."""
    root = REPO_ROOT
    return root if (root / "pyproject.toml").is_file() and (root / "synth" / "resources.py").is_file() else None


def scenes_dir() -> Path:
    """The scenes folder: ``$SYNTH_SCENES_DIR``, else the shipped ``scenes/``."""
    env = os.environ.get("SYNTH_SCENES_DIR")
    return Path(env) if env else DATA_DIR


def generated_dir(sub: str) -> Path:
    """Where ``synth scene generate`` / ``synth path generate`` write by default: the scenes folder's
    ``sub`` (``layouts``, ``paths``) when it is yours to rewrite (``$SYNTH_SCENES_DIR``, or a source
    checkout), else ``./scenes/SUB`` in the working folder: an installed package's files are not."""
    if os.environ.get("SYNTH_SCENES_DIR") or checkout_root() is not None:
        return scenes_dir() / sub
    return Path.cwd() / "scenes" / sub


def layouts_dir() -> Path:
    return scenes_dir() / "layouts"


def lighting_dir() -> Path:
    return scenes_dir() / "lighting"


def paths_dir() -> Path:
    return scenes_dir() / "paths"


def classes_file() -> Path:
    return scenes_dir() / "classes.yaml"


def replicacad_lexicon_file() -> Path:
    return scenes_dir() / "replicacad_lexicon.yaml"


def render_specs() -> list[str]:
    """Names of the shipped render job specs (``synth render NAME``)."""
    return shipped_names(SPECS_DIR, "designs")


def render_spec(arg) -> Path:
    """``synth render``'s argument: a file, or the name of a shipped render job spec."""
    return resolve_spec(arg, SPECS_DIR, "render job spec", "designs")


def trainset_spec(arg) -> Path:
    """``synth trainset render``'s argument: a file, or the name of a shipped trainset spec."""
    return resolve_spec(arg, SPECS_DIR, "trainset spec", "views")  # every trainset spec has views; render specs never
