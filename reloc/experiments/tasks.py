"""The tasks of an experiment, run in worker processes: one map built from the mapping tour
(``run_map_task``) or one method on one query tour (``run_tour_task``), and their done markers.

A task writes its files atomically and last a done marker (``done.json`` in a run folder,
``FILE.done.json`` beside a map) holding the task's key (:mod:`reloc.experiments.fingerprint`);
a result counts only while its marker holds the current key (``is_done``). Maps are loaded once
per worker process (``_load``). The clip-rigid controls reuse VideoReloc's clip partition and
within-clip odometry (``clip_poses.npz`` of its run), as the paper's dagger rows do.
"""

from __future__ import annotations

import os
import time
from pathlib import Path

from formats.atomic import write_json_atomic, write_text_atomic
from formats.camera import write_tum
from formats.errors import SceneFormatError, UserError
from formats.yamlfile import read_json
from formats.tour import Tour

from . import tables
from .spec import open_detector

DONE = "done.json"


def is_done(d: Path, key: str) -> bool:
    try:
        return read_json(d / DONE).get("key") == key
    except (SceneFormatError, OSError, ValueError):
        return False


def mark_done(d: Path, key: str, seconds: float, extra: dict | None = None) -> None:
    write_json_atomic(d / DONE, {"key": key, "seconds": round(seconds, 2), **(extra or {})})


def _config(spec_config: dict, variant=None):
    from ..config import Config

    cfg = Config.from_dict(spec_config)
    if variant is not None:
        orient, run_level, adaptive = variant
        if not orient:
            cfg = cfg.replace("refinement.orientation_aware", False)
        if not run_level:
            cfg = cfg.replace("backend.run_level", False)
        if not adaptive:
            cfg = cfg.replace("clips.adaptive", False).replace("clips.start_frames", 100)
    return cfg


def _detector(det: dict, tour, bmap, cfg):
    """The spec's detector for one query tour, asked for the map's classes."""
    return open_detector(det, bmap.class_set, tour.class_names(), cfg.detection)


_CACHE: dict = {}


def _load(kind: str, path: str, map_config=None):
    """A map, cached per process (per file version and, for a box map, per ``Config.map``: the
    triangle index it builds depends on it)."""
    k = (kind, path, os.stat(path).st_mtime_ns, map_config)
    if k not in _CACHE:
        if kind == "boxes":
            from ..map.boxmap import BoxMap

            _CACHE[k] = BoxMap.load(path, config=map_config)
        elif kind == "appearance":
            from ..baselines.appearance import AppearanceMap

            _CACHE[k] = AppearanceMap.load(path)
        else:
            from ..baselines.fpfh_icp import PointMap

            _CACHE[k] = PointMap.load(path)
    return _CACHE[k]


def run_map_task(task: dict) -> dict:
    """Build one map (box map, FPFH point map or appearance keyframe map) from the mapping tour."""
    t0 = time.perf_counter()
    out = Path(task["file"])
    out.with_name(out.name + ".done.json").unlink(missing_ok=True)
    tour = Tour(task["tour"], sensor=task.get("sensor"), sensor_seed=task.get("sensor_seed", 0))
    if task["kind"] == "boxes":
        from ..map.build import build_map
        from ..map.document import dumps_map, map_from_tour

        if task["source"] == "ground-truth":
            doc = map_from_tour(tour.root)
        else:
            det = task["detector"]
            detector = None if det["kind"] == "oracle" else open_detector(det, None, tour.class_names())
            doc, report = build_map(tour, detector=detector, progress=False)  # the Tour: read through its sensor
            if not doc["boxes"]:
                raise UserError(report["warnings"][0] if report["warnings"] else f"{tour.root}: no boxes built")
            from ..map.scoring import errors_against_ground_truth

            write_json_atomic(tables.map_report_path(out),
                              {"build": report, "errors": errors_against_ground_truth(tour, doc)})
        write_text_atomic(out, dumps_map(doc))
    elif task["kind"] == "appearance":
        from ..baselines.appearance import AppearanceConfig, AppearanceMap

        AppearanceMap.build(tour, cfg=AppearanceConfig(**task["options"])).save(out)
    else:
        from ..baselines.fpfh_icp import FpfhConfig, PointMap

        PointMap.build(tour, cfg=FpfhConfig(**task["options"])).save(out)
    s = time.perf_counter() - t0
    write_json_atomic(out.with_name(out.name + ".done.json"),
                      {"key": task["key"], "seconds": round(s, 2), "code": task["code"]})
    return {"kind": task["kind"], "seconds": s}


def run_tour_task(task: dict) -> dict:
    """One method on one query tour; writes its trajectories into ``task['dir']`` and marks it done."""
    from ..backend.run import load_clip_poses, relocalize

    t0 = time.perf_counter()
    d = Path(task["dir"])
    d.mkdir(parents=True, exist_ok=True)
    (d / DONE).unlink(missing_ok=True)  # from here until done, this run's files are not a result
    tour = Tour(task["tour"], sensor=task.get("sensor"), sensor_seed=task["seed"])
    method = task["method"]
    extra: dict = {}
    if method in ("videoreloc", "videoreloc_oracle") or method.startswith("ablation_"):
        cfg = _config(task["config"], task.get("variant"))
        bmap = _load("boxes", task["map"], cfg.map)
        s = relocalize(tour, bmap, d, cfg=cfg, detector=_detector(task["detector"], tour, bmap, cfg), seed=task["seed"],
                       progress=False)
        extra = {"fps": s["fps"], "clips": s["clips"]}
    elif method == "fpfh_icp":
        from ..baselines.fpfh_icp import FpfhConfig, run_fpfh_icp

        s = run_fpfh_icp(tour, _load("fpfh", task["fpfh_map"]), load_clip_poses(task["clips"]), d,
                         cfg=FpfhConfig(**task["options"]), progress=False)
        extra = {k: s[k] for k in ("clips", "registered") if k in s}
    elif method == "appearance":
        from ..baselines.appearance import AppearanceConfig, run_appearance

        s = run_appearance(tour, _load("appearance", task["appearance_map"]), d,
                           clip_poses=load_clip_poses(task["clips"]), cfg=AppearanceConfig(**task["options"]),
                           clip_rigid=_config(task["config"]).clip_rigid, progress=False)
    elif method == "one_frame":
        from .localization_units import run_units

        cfg = _config(task["config"])
        bmap = _load("boxes", task["map"], cfg.map)
        lengths = tuple(task["lengths"])
        est: dict = {}
        rep = run_units(tour, bmap, lengths=lengths, detector=_detector(task["detector"], tour, bmap, cfg),
                        cfg=cfg, one_frame_stride=task["stride"], seed=task["seed"],
                        progress=False, estimates=est)
        one = est.get(1, {})
        fr = sorted(one)
        write_tum(d / "causal.txt", [one[i] for i in fr], fps=tour.fps, frames=fr,
                  header=f"one-frame object units on every {task['stride']}th frame of {tour.root}")
        for L in lengths:  # each longer unit's poses, for Table III's intervals (tables.unit_file)
            if L > 1:
                e = est.get(L, {})
                fr = sorted(e)
                write_tum(d / tables.unit_file(L), [e[i] for i in fr], fps=tour.fps, frames=fr,
                          header=f"{L}-frame clip units, each registered independently, of {tour.root}")
        write_json_atomic(d / "units.json", rep)
    else:
        raise ValueError(f"unknown method {method!r}")
    seconds = time.perf_counter() - t0
    mark_done(d, task["key"], seconds, {**extra, "code": task["code"]})
    return {"method": method, "tour": task["tour_name"], "seconds": seconds}

