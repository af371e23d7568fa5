"""VideoReloc (paper Sec. IV-A) in an experiment: the box map built from the mapping tour with the
spec's detector (or its ground truth, ``map: ground-truth``), and the relocalizer on every query
tour with the same detector: rows ``videoreloc.causal`` and ``videoreloc.closure``. Its runs'
clips are what the clip-rigid controls reuse, and its variants make Table IV (``ablation``)."""

from __future__ import annotations

from vrformats.atomic import write_json_atomic, write_text_atomic
from vrformats.errors import UserError

from .common import config_of, detector_for, load_map, map_report_path, open_detector
from .registry import MapKind, Method, Row, register, register_map


def build_box_map(task: dict, tour, out) -> None:
    """The box map from the mapping tour (read through its sensor): its ground truth, or built with
    the task's detector (the oracle: the rendered labels), with a report of its errors beside it."""
    from ...map.build import build_map
    from ...map.document import dumps_map, map_from_tour

    if task["source"] == "ground-truth":
        doc = map_from_tour(tour.root)
    else:
        det = task["detector"]
        detector = None if det["kind"] == "oracle" else open_detector(det, None, tour.class_names())
        doc, report = build_map(tour, detector=detector, progress=False)  # the Tour: read through its sensor
        if not doc["boxes"]:
            raise UserError(report["warnings"][0] if report["warnings"] else f"{tour.root}: no boxes built")
        from ...map.scoring import errors_against_ground_truth

        write_json_atomic(map_report_path(out), {"build": report, "errors": errors_against_ground_truth(tour, doc)})
    write_text_atomic(out, dumps_map(doc))


def load_box_map(path, map_config):
    from ...map.boxmap import BoxMap

    return BoxMap.load(path, config=map_config)


def run_videoreloc(task: dict, tour, d) -> dict:
    """VideoReloc on one query tour (an ablation run: with its ``variant`` of the configuration)."""
    from ...backend.run import relocalize

    cfg = config_of(task["config"], task.get("variant"))
    bmap = load_map("boxes", task["map"], cfg.map)
    s = relocalize(tour, bmap, d, cfg=cfg, detector=detector_for(task["detector"], tour, bmap, cfg), seed=task["seed"],
                   progress=False)
    return {"fps": s["fps"], "clips": s["clips"]}


register_map(MapKind("boxes", "videoreloc_map.json", build=build_box_map, load=load_box_map,
                     detector=lambda spec: spec.detector, spec_map=True, always=True))

register(Method(
    "videoreloc", "VideoReloc",
    rows=(Row("causal", "VideoReloc, causal", order=50), Row("closure", "VideoReloc, with clip closure", order=60)),
    run=run_videoreloc, primary="closure", maps=("boxes",), uses="boxes", clips=True, tables=("ablation",),
    default=True,
))
