"""The Python API of ``synth``: what a notebook needs, importable as ``synth.NAME``.

Each function is the code path of a ``synth`` command (named in its docstring), taking Python
values where the command takes options; errors are the commands' one-line ``UserError``s
(``vrformats.errors``). Layouts and camera paths are given by name (``apt_0``, ``query``: the shipped
ones, or ``$SYNTH_SCENES_DIR``'s) or by file; a layout or path made in Python is saved with
:func:`save_layout` / :func:`save_path` and given by its file. docs/api.md has a worked example.
"""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

if TYPE_CHECKING:  # the types of the signatures; importing them is left to the call
    from vrformats.tour import Tour

    from .paths.model import CameraPath
    from .scene.model import Layout

__all__ = ["load_layout", "save_layout", "list_layouts", "generate_apartment", "rearrange", "plan_path", "load_path",
           "save_path", "render_tour", "read_tour", "render_job"]


def load_layout(layout: str | Path) -> Layout:
    """A layout by name (``"apt_0"``) or file (``synth scene show``). Raises ``SceneFormatError``
    naming the file and field when the file is malformed."""
    from .scene.model import load_layout as load

    return load(layout)


def save_layout(layout: Layout, file: str | Path) -> Path:
    """Write ``layout`` as a layout YAML file (atomically); returns its path, which every function
    here takes where it takes a layout name."""
    from .scene.model import save_layout as save

    return save(layout, file)


def list_layouts() -> list[str]:
    """The names of the layouts ``load_layout`` finds by name (``synth scene list``)."""
    from .scene.model import list_layouts as names

    return names()


def generate_apartment(seed: int | None = None, name: str = "apt_0") -> Layout:
    """The built-in procedural apartment (``synth scene generate``): ``seed`` None is the shipped
    ``apt_0``'s seed, so the result equals ``load_layout("apt_0")``; another seed is another apartment."""
    from .layout.apartment import DEFAULT_SEED, generate_apartment as generate

    return generate(DEFAULT_SEED if seed is None else seed, name)


def rearrange(layout: str | Path | Layout, name: str, seed: int = 0, removed: int | None = None,
              added: int | None = None, other_room: float | None = None, attempts: int = 40) -> Layout:
    """A rearranged variant of ``layout`` (``synth scene rearrange``): furniture moved, ``removed``
    objects taken out and ``added`` ones brought in (defaults: ``RearrangePlan``'s, within the paper's
    ranges), ``other_room`` the chance that a moved object changes room. Kept out of the reference's
    walkway and retried on sub-seeds until its change statistics lie in range and the plausibility
    checks pass, as the built-in variants apt_1..apt_5 are made."""
    from dataclasses import replace

    from .layout.rearrange import RearrangePlan, new_variant

    ref = layout if not isinstance(layout, (str, Path)) else load_layout(layout)
    changes = {k: v for k, v in (("removed", removed), ("added", added), ("other_room", other_room)) if v is not None}
    return new_variant(ref, name, int(seed), replace(RearrangePlan(), **changes), attempts=int(attempts))


def plan_path(kind: str, layouts: list[str | Path | Layout], frames: int | None = None, seed: int | None = None,
              name: str | None = None) -> CameraPath:
    """A camera path (``synth path plan query|mapping``): ``query``, a walk through every room clear of
    the objects of every layout given; ``mapping``, a cross-hatch tour of one layout. ``frames``
    and ``seed`` default to the shipped paths' (``synth.paths.model.DEFAULTS``)."""
    from vrformats.errors import UserError

    from .paths.model import DEFAULTS
    from .paths.shipped import plan_path as plan

    if kind not in ("query", "mapping"):
        raise UserError(f"unknown path kind {kind!r}; use query or mapping")
    lays = [x if not isinstance(x, (str, Path)) else load_layout(x) for x in layouts]
    if not lays:
        raise UserError("plan_path needs at least one layout")
    n = frames if frames is not None else (DEFAULTS.query_frames if kind == "query" else DEFAULTS.mapping_frames)
    return plan(kind, lays, int(n), DEFAULTS.seed if seed is None else int(seed), name=name)


def load_path(path: str | Path) -> CameraPath:
    """A saved camera path by name (``"query"``, ``"mapping"``) or TUM file (``synth path show``)."""
    from .paths.files import load_path as load

    return load(path)


def save_path(path: CameraPath, file: str | Path) -> Path:
    """Write a camera path (TUM poses, and its ``.yaml`` sidecar beside it); returns the TUM file."""
    from .paths.files import save_path as save

    return save(path, file)


def render_tour(layout: str | Path, path: str | Path, out: str | Path, *, lighting: str | None = None,
                renderer: str = "fast", size: tuple[int, int] = (160, 120), frames: int | None = None,
                quality: str = "preview", seed: int = 0, workers: int = 1, progress: bool = False) -> Tour:
    """Render one tour, a layout x a lighting x a camera path, into ``out`` (``synth tour render``)
    and return it read back (:func:`read_tour`).

    ``renderer="fast"`` (the default here) traces depth and instance/semantic ids with Open3D, in
    seconds; ``"blender"`` renders RGB with Cycles under ``lighting`` (a preset name: ``day``,
    ``evening``, ``night``) at ``quality``. ``frames``: the first N frames of the path. Frames
    already on disk are kept, so a killed render resumes."""
    from .render.settings import DEFAULTS
    from .tour.render import TourSpec, render_tour as render

    w, h = size
    render(TourSpec(layout=str(layout), path=str(path), out=str(out), lighting=lighting, renderer=renderer,
                    quality=quality, width=int(w), height=int(h), hfov_deg=DEFAULTS.hfov_deg, frames=frames,
                    seed=int(seed), workers=int(workers)), progress=progress)
    return read_tour(out)


def read_tour(folder: str | Path) -> Tour:
    """A rendered tour (``vrformats.tour.Tour``): its poses, intrinsics, meta and frames
    (``tour.frame(i)``: RGB, depth, instance and semantic ids). ``synth tour check`` validates one."""
    from vrformats.tour import Tour

    return Tour(folder)


def render_job(spec: str | Path, out: str | Path | None = None, workers: int = 1, resume: bool = False,
               progress: bool = False) -> dict:
    """Render every tour of a job spec (``synth render``): a shipped name (``"quickstart"``,
    ``"demo"``) or a YAML file; ``out`` defaults to the spec's. Returns the job summary
    (``job_summary.json``). With ``resume`` a killed job finishes without redoing done work."""
    from .jobs import load_spec, run_job

    return run_job(load_spec(spec), out, workers=int(workers), resume=resume, progress=progress)
