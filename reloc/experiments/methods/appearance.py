"""The appearance baseline: ORB (or SIFT) + retrieval + PnP-RANSAC per frame against a keyframe map
of the mapping tour (``appearance.causal``; only frames with RGB are localized and evaluated) and
its clip-rigid variant on VideoReloc's clips (``appearance.closure``; settings: the spec's
``appearance``)."""

from __future__ import annotations

from .common import config_of, load_map
from .registry import MapKind, Method, Row, register, register_map


def _options():
    from ...baselines.appearance import AppearanceConfig

    return AppearanceConfig


def build_keyframe_map(task: dict, tour, out) -> None:
    from ...baselines.appearance import AppearanceConfig, AppearanceMap

    AppearanceMap.build(tour, cfg=AppearanceConfig(**task["options"])).save(out)


def load_keyframe_map(path, map_config=None):
    from ...baselines.appearance import AppearanceMap

    return AppearanceMap.load(path)


def run_appearance(task: dict, tour, d) -> dict:
    from ...backend.run import load_clip_poses
    from ...baselines.appearance import AppearanceConfig, run_appearance as run

    run(tour, load_map("appearance", task["appearance_map"]), d, clip_poses=load_clip_poses(task["clips"]),
        cfg=AppearanceConfig(**task["options"]), clip_rigid=config_of(task["config"]).clip_rigid, progress=False)
    return {}


def evaluated_frames(mode: str, frames: list, rgb_every: int, stride: int) -> list:
    """Per frame: the frames with RGB (the others have no image to match); clip-rigid: every frame."""
    return [i for i in frames if i % rgb_every == 0] if mode == "causal" else frames


def label_fields(spec) -> dict:
    from ...baselines.appearance import AppearanceConfig

    return {"feature": str(spec.appearance.get("feature", AppearanceConfig().feature)).upper()}


register_map(MapKind("appearance", "appearance_map.npz", build=build_keyframe_map, load=load_keyframe_map,
                     options=lambda spec: spec.appearance))

register(Method(
    "appearance", "Appearance ({feature} + PnP)",
    rows=(Row("causal", "Appearance ({feature} + PnP), per frame", order=10),
          Row("closure", "Appearance ({feature} + PnP)", dagger=True, order=40)),
    run=run_appearance, primary="causal", maps=("appearance",), uses="appearance",
    task_args=lambda spec, files: {"appearance_map": str(files["appearance"]), "options": spec.appearance},
    clips_from="videoreloc", frames=evaluated_frames, options_key="appearance", options_class=_options,
    label_fields=label_fields, default=True,
))
