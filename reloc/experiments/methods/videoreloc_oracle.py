"""VideoReloc on oracle detections: the rendered labels on the queries and a box map built from the
oracle's (or the ground-truth map with ``map: ground-truth``). The upper bound beside the spec's
detector, ``VideoReloc (oracle detections)``: the gap a real detector leaves is a reported figure."""

from __future__ import annotations

from .common import ORACLE
from .registry import MapKind, Method, Row, register, register_map
from .videoreloc import run_videoreloc

register_map(MapKind("boxes_oracle", "videoreloc_oracle_map.json", builds_as="boxes", detector=lambda spec: ORACLE,
                     spec_map=True))

register(Method(
    "videoreloc_oracle", "VideoReloc (oracle detections)",
    # the upper bound: the same relocalizer on the rendered labels (map and queries), beside the
    # detector the experiment uses
    rows=(Row("causal", "VideoReloc (oracle detections), causal", order=70),
          Row("closure", "VideoReloc (oracle detections), with clip closure", order=80)),
    run=run_videoreloc, primary="closure", maps=("boxes_oracle",), uses="boxes_oracle",
    task_args=lambda spec, files: {"map": str(files["boxes_oracle"]), "detector": ORACLE, "model": None},
    clips=True, oracle_of="videoreloc", default=True,
))
