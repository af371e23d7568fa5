"""The tasks of an experiment, run in worker processes: one map built from the mapping tour
(``run_map_task``) or one method on one query tour (``run_tour_task``), and their done markers.

A task writes its files atomically and last a done marker (``done.json`` in a run folder,
``FILE.done.json`` beside a map) holding the task's key (:mod:`reloc.experiments.fingerprint`);
a result counts only while its marker holds the current key (``is_done``). Maps are loaded once
per worker process (``methods.common.load_map``). What a map or a method does is its registered
``MapKind`` or ``Method`` (:mod:`reloc.experiments.methods`). The clip-rigid controls reuse
VideoReloc's clip partition and within-clip odometry (``clip_poses.npz`` of its run), as the
paper's dagger rows do.
"""

from __future__ import annotations

import importlib
import time
from pathlib import Path

from vrformats.atomic import write_json_atomic
from vrformats.errors import SceneFormatError
from vrformats.yamlfile import read_json
from vrformats.tour import Tour

from . import methods

DONE = "done.json"


def is_done(d: Path, key: str) -> bool:
    try:
        return read_json(d / DONE).get("key") == key
    except (SceneFormatError, OSError, ValueError):
        return False


def mark_done(d: Path, key: str, seconds: float, extra: dict | None = None) -> None:
    write_json_atomic(d / DONE, {"key": key, "seconds": round(seconds, 2), **(extra or {})})




def run_map_task(task: dict) -> dict:
    """Build one map of a registered kind (box map, FPFH point map, appearance keyframe map, ...) from
    the mapping tour (``methods.MapKind.build``)."""
    t0 = time.perf_counter()
    out = Path(task["file"])
    out.with_name(out.name + ".done.json").unlink(missing_ok=True)
    tour = Tour(task["tour"], sensor=task.get("sensor"), sensor_seed=task.get("sensor_seed", 0))
    _method_module(task)
    methods.map_kind(task["kind"]).build(task, tour, out)
    s = time.perf_counter() - t0
    write_json_atomic(out.with_name(out.name + ".done.json"),
                      {"key": task["key"], "seconds": round(s, 2), "code": task["code"]})
    return {"kind": task["kind"], "seconds": s}


def _method_module(task: dict) -> None:
    """The module that registered the task's method or map kind, imported in this (worker) process:
    a method from outside reloc.experiments.methods registers itself there (imported once)."""
    if task.get("module"):
        importlib.import_module(task["module"])


def run_tour_task(task: dict) -> dict:
    """One method on one query tour (``methods.Method.run``); writes its trajectories into
    ``task['dir']`` and marks it done."""
    t0 = time.perf_counter()
    d = Path(task["dir"])
    d.mkdir(parents=True, exist_ok=True)
    (d / DONE).unlink(missing_ok=True)  # from here until done, this run's files are not a result
    tour = Tour(task["tour"], sensor=task.get("sensor"), sensor_seed=task["seed"])
    method = task["method"]
    _method_module(task)
    try:  # an ablation run runs as the method whose variant it is (runs_as: videoreloc)
        m = methods.get(task.get("runs_as", method))
    except KeyError:
        raise ValueError(f"unknown method {method!r}") from None
    extra = m.run(task, tour, d) or {}
    seconds = time.perf_counter() - t0
    mark_done(d, task["key"], seconds, {**extra, "code": task["code"]})
    return {"method": method, "tour": task["tour_name"], "seconds": seconds}

