"""FPFH-ICP, a clip-rigid control: FPFH + RANSAC + ICP of each of VideoReloc's clips against a 5 cm
point map of the mapping tour (``fpfh_icp.closure``; settings: the spec's ``fpfh_icp``)."""

from __future__ import annotations

from .common import load_map
from .registry import MapKind, Method, Row, register, register_map


def _options():
    from ...baselines.fpfh_icp import FpfhConfig

    return FpfhConfig


def build_point_map(task: dict, tour, out) -> None:
    from ...baselines.fpfh_icp import FpfhConfig, PointMap

    PointMap.build(tour, cfg=FpfhConfig(**task["options"])).save(out)


def load_point_map(path, map_config=None):
    from ...baselines.fpfh_icp import PointMap

    return PointMap.load(path)


def run_fpfh_icp(task: dict, tour, d) -> dict:
    from ...backend.run import load_clip_poses
    from ...baselines.fpfh_icp import FpfhConfig, run_fpfh_icp as run

    s = run(tour, load_map("fpfh", task["fpfh_map"]), load_clip_poses(task["clips"]), d,
            cfg=FpfhConfig(**task["options"]), progress=False)
    return {k: s[k] for k in ("clips", "registered") if k in s}


register_map(MapKind("fpfh", "fpfh_map.npz", build=build_point_map, load=load_point_map,
                     options=lambda spec: spec.fpfh_icp))

register(Method(
    "fpfh_icp", "FPFH-ICP", rows=(Row("closure", "FPFH-ICP", dagger=True, order=30),),
    run=run_fpfh_icp, primary="closure", maps=("fpfh",), uses="fpfh",
    task_args=lambda spec, files: {"fpfh_map": str(files["fpfh"]), "options": spec.fpfh_icp},
    clips_from="videoreloc", options_key="fpfh_icp", options_class=_options, default=True,
))
