"""The Python API of ``reloc``: what a notebook needs, importable as ``reloc.NAME``.

Each function runs the code path of a ``reloc`` command (named in its docstring), taking Python
values where the command takes options; errors are the commands' one-line ``UserError``s
(``vrformats.errors``). A tour is a folder or a ``vrformats.tour.Tour`` (``synth.read_tour``); a map
is a file or a :class:`reloc.map.boxmap.BoxMap`. docs/api.md has a worked example.
"""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:  # the types of the signatures; importing them is left to the call
    from vrformats.tour import Tour

    from .config import Config
    from .map.boxmap import BoxMap

__all__ = ["read_tour", "ground_truth_map", "build_map", "load_map", "relocalize", "evaluate", "run_experiment",
           "check"]

DETECTORS = ("oracle", "learned", "onnx")  # reloc.detection.factory's kinds


def read_tour(tour: str | Path | Tour, sensor: str | None = None) -> Tour:
    """A rendered tour, optionally read through a sensor model (``sensor``: a preset such as
    ``"structured_light"`` or a file; docs/sensors.md). A ``Tour`` is returned as it is."""
    from vrformats.tour import Tour

    return tour if isinstance(tour, Tour) else Tour(tour, sensor=sensor)


def _detector(kind: str, tour: Tour, model: str | Path | None, vocabulary=None, config: Config | None = None):
    from vrformats.errors import UserError

    from .detection.factory import DetectorSpec, build_detector

    if kind not in DETECTORS:
        raise UserError(f"unknown detector {kind!r}; use one of {', '.join(DETECTORS)}")
    spec = DetectorSpec(kind=kind, model=str(model) if model else None)
    return build_detector(spec, tour.class_names(), vocabulary=vocabulary, config=config.detection if config else None)


def ground_truth_map(tour: str | Path | Tour, out: str | Path | None = None) -> BoxMap:
    """The map of the boxes a tour's layout holds (``reloc map ground-truth``), written to ``out``
    when given."""
    from vrformats.atomic import write_text_atomic

    from .map.boxmap import BoxMap
    from .map.document import dumps_map, map_from_tour

    t = read_tour(tour)
    doc = map_from_tour(t.root)
    if out is not None:
        write_text_atomic(out, dumps_map(doc))
    return BoxMap(doc, source=str(out or t.root))


def build_map(tour: str | Path | Tour, detector: str = "oracle", model: str | Path | None = None,
              out: str | Path | None = None, stride: int | None = None, voxel: float | None = None,
              progress: bool = False) -> BoxMap:
    """A box map built from a mapping tour (``reloc map build``): detections fused over the tour's
    depth into class-labelled boxes. ``detector``: ``"oracle"`` (the rendered labels), ``"learned"``
    (the shipped model, or ``model``) or ``"onnx"`` (your YOLO-style ``model``). Written to ``out``
    when given. A tour from which no box can be built is a UserError."""
    from vrformats.atomic import write_text_atomic
    from vrformats.errors import UserError, check_output_file

    from .map.boxmap import BoxMap
    from .map.build import build_map as build
    from .map.document import dumps_map

    if out is not None:
        check_output_file(out)
    t = read_tour(tour)
    det = None if detector == "oracle" and model is None else _detector(detector, t, model)
    doc, report = build(t, detector=det, stride=stride, voxel=voxel, progress=progress)
    if not doc["boxes"]:
        raise UserError(report["warnings"][0] if report["warnings"] else f"{t.root}: no boxes built")
    m = BoxMap(doc, source=str(out or t.root))
    if out is not None:
        write_text_atomic(out, dumps_map(doc))
    m.report = report
    return m


def load_map(file: str | Path, config: Config | None = None) -> BoxMap:
    """A map file (``videoreloc-boxes/1``), validated as ``reloc map show`` reads it; a malformed one
    is a UserError naming the file and the field."""
    from .map.boxmap import BoxMap

    return BoxMap.load(file, config=config.map if config else None)


def relocalize(tour: str | Path | Tour, map: str | Path | BoxMap, out: str | Path, detector: str = "oracle",
               model: str | Path | None = None, config: Config | None = None, poses: str = "odometry",
               frames: int | None = None, seed: int = 0, progress: bool = False) -> dict[str, Any]:
    """VideoReloc on one tour against a map (``reloc run``): writes ``out/causal.txt`` and
    ``out/closure.txt`` (TUM, camera-to-world), the clips and ``summary.json``; returns the summary.
    ``detector`` as in :func:`build_map`; ``config``: a ``reloc.config.Config`` (the paper's
    thresholds by default); ``poses``: ``"odometry"`` (RGB-D odometry) or ``"gt"``."""
    from .backend.run import relocalize as run
    from .config import Config

    cfg = config or Config()
    t = read_tour(tour)
    bmap = map if not isinstance(map, (str, Path)) else load_map(map, cfg)
    det = _detector(detector, t, model, vocabulary=bmap.class_set, config=cfg)
    return run(t, bmap, out, cfg=cfg, detector=det, poses=poses, frames=frames, seed=seed, progress=progress)


def evaluate(run: str | Path, tour: str | Path | Tour) -> dict[str, Any]:
    """Recall at 1 m/10 deg and 0.25 m/5 deg, median errors and coverage of every trajectory of a
    ``relocalize`` output against the tour's ground truth (``reloc eval``): ``{"closure": {...},
    "causal": {...}, "frames": N, ...}``, fractions."""
    from .experiments.cli import evaluate_run

    return evaluate_run(run, read_tour(tour))


def run_experiment(spec: str | Path, tours: str | Path | None = None, out: str | Path | None = None,
                   workers: int | None = None, progress: bool = False, plots: bool = True) -> dict[str, Any]:
    """Methods x tours over a rendered design (``reloc experiment``): maps, runs, the paper's tables
    with intervals, plots and ``report.html`` in ``out`` (default: the spec's). ``spec``: a shipped
    name (``"quickstart_experiment"``) or a file; ``tours``: the rendered job folder. Resumes what is
    done. Returns ``results.json``'s content."""
    from .experiments.runner import run_experiment as run
    from .experiments.spec import load_experiment

    s = load_experiment(spec)
    if tours is not None:
        s.tours_root = Path(tours)
    r = run(s, out=Path(out) if out else None, workers=workers, progress=progress, plots=plots)
    r.pop("_ran", None)
    return r


def check(checks: str | Path, results: str | Path, junit: str | Path | None = None) -> list[dict[str, Any]]:
    """Pass/fail robustness checks on experiment results (``reloc check``): one row per check with
    ``passed``, ``value``, ``against`` and the ``interval`` that decided; ``junit``: also write them
    as JUnit XML for a CI server."""
    from vrformats.atomic import write_text_atomic

    from .experiments.checks import junit_xml, run_checks

    rows = run_checks(checks, results)
    if junit is not None:
        write_text_atomic(junit, junit_xml(rows, Path(checks).stem, results))
    return rows
