"""Where reloc's shipped files live: inside the package (``importlib.resources``), so an installed
wheel finds them as a checkout does.

- ``reloc/models/``: the learned detector the experiments use by default
  (``detector_v2_160x120.onnx``, :data:`SHIPPED_MODEL`) and its model card (``detector_v2_160x120.md``);
  the first model, ``detector_160x120.onnx``, stays beside it, loadable by path.
- ``reloc/specs/``: the shipped experiment and check specs; ``reloc experiment demo_experiment`` is
  ``reloc experiment reloc/specs/demo_experiment.yaml`` (:func:`experiment_spec`, :func:`check_spec`).

An experiment spec's ``render`` names the render job whose tours it reads: a file relative to the
spec, or the name of a render job spec synth ships (``render: demo``: ``render_jobs/demo.yaml``;
:func:`render_spec_of`). That folder is found as package data; no code of synth is imported.
"""

from __future__ import annotations

from pathlib import Path

from vrformats.errors import SceneFormatError, UnknownNameError
from vrformats.shipped import is_bare_name, package_dir, resolve_spec, shipped_file, shipped_folder, shipped_names

PACKAGE_DIR = package_dir("reloc")
MODELS_DIR = PACKAGE_DIR / "models"
SPECS_DIR = PACKAGE_DIR / "specs"  # experiment and check specs
SHIPPED_MODEL = MODELS_DIR / "detector_v2_160x120.onnx"  # the learned detector's default model
MODEL_CARD = SHIPPED_MODEL.with_suffix(".md")


def shipped_model() -> Path:
    return SHIPPED_MODEL


def experiment_specs() -> list[str]:
    return shipped_names(SPECS_DIR, "render")


def check_specs() -> list[str]:
    return shipped_names(SPECS_DIR, "checks")


def experiment_spec(arg) -> Path:
    """``reloc experiment``'s argument: a file, or the name of a shipped experiment spec."""
    return resolve_spec(arg, SPECS_DIR, "experiment spec", "render")


def check_spec(arg) -> Path:
    """``reloc check``'s argument: a file, or the name of a shipped check spec."""
    return resolve_spec(arg, SPECS_DIR, "check spec", "checks")


def synth_specs_dir() -> Path:
    """synth's shipped render job specs (``render_jobs/``), located like package data: the package
    is found, not run (``importlib.util.find_spec`` imports nothing)."""
    import importlib.util

    spec = importlib.util.find_spec("synth")
    if spec is None or not spec.submodule_search_locations:
        raise UnknownNameError("the synth package is not installed: give render: as a file")
    return shipped_folder(Path(list(spec.submodule_search_locations)[0]), "render_jobs")


def render_spec_of(spec_file, value) -> Path:
    """An experiment spec's ``render``: a file relative to ``spec_file`` (resolved), else the bare
    name of a render job spec synth ships. A SceneFormatError names the spec file and the key."""
    src = Path(spec_file)
    rel = (src.parent / str(value)).resolve()
    if rel.is_file() or not is_bare_name(value):
        return rel
    try:
        return shipped_file(str(value), synth_specs_dir(), "render job spec", "designs").resolve()
    except UnknownNameError as e:
        raise SceneFormatError(src, "render", f"{rel} not found; {e}") from None
