"""What the methods share: the spec's detector opened (``open_detector``, ``ORACLE``), VideoReloc's
configuration of a task (``config_of``, with an ablation variant), maps loaded once per worker
process (``load_map``) and the names of the files a run or a map leaves (``unit_file``,
``map_report_path``). Imports nothing of the experiment's other modules, which import it."""

from __future__ import annotations

import os
from pathlib import Path

from . import registry

ORACLE = {"kind": "oracle", "model": None, "corruption": {}}  # a spec's detector: the rendered labels


def open_detector(det: dict, vocabulary, classes=None, cfg=None):
    """The detector a spec's ``detector`` names (``spec._detector_spec``'s dict)."""
    from ...detection.factory import DetectorSpec, build_detector
    from ...detection.learned import Perturbation
    from ...detection.oracle import Corruption

    spec = DetectorSpec(kind=det["kind"], corruption=Corruption(**det.get("corruption", {})), model=det.get("model"),
                        class_map=det.get("class_map"), perturbation=Perturbation(**det.get("perturbation", {})))
    return build_detector(spec, classes or {}, vocabulary=vocabulary, config=cfg)


def config_of(spec_config: dict, variant=None):
    """VideoReloc's ``Config`` of a task: the spec's overrides and, for an ablation run, its
    ``variant`` (orientation-aware, run-level, adaptive; False turns the component off)."""
    from ...config import Config

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


def detector_for(det: dict, tour, bmap, cfg):
    """The spec's detector for one query tour, asked for the map's classes."""
    return open_detector(det, bmap.class_set, tour.class_names(), cfg.detection)


_CACHE: dict = {}


def load_map(kind: str, path: str, map_config=None):
    """A map of a registered kind (``registry.MapKind``), cached per process (per file version and,
    for a box map, per ``Config.map``: the triangle index it builds depends on it)."""
    k = (kind, path, os.stat(path).st_mtime_ns, map_config)
    if k not in _CACHE:
        mk = registry.map_kind(kind)
        _CACHE[k] = registry.map_kind(mk.builds_as or kind).load(path, map_config)
    return _CACHE[k]


def unit_file(length: int) -> str:
    """The trajectory of a localization unit's poses in a ``one_frame`` run folder (Table III):
    ``causal.txt`` for the one-frame unit, ``unit_L.txt`` for L-frame clips."""
    return "causal.txt" if int(length) == 1 else f"unit_{int(length)}.txt"


def map_report_path(map_file) -> Path:
    """Where an experiment keeps a built map's report (build counts, errors against the ground
    truth): ``videoreloc_map.json`` -> ``videoreloc_map.report.json``."""
    p = Path(map_file)
    return p.with_name(p.stem + ".report.json")
