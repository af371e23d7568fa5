"""Render settings shared by the renderers, the job specs and the CLIs (no bpy): the render defaults,
quality presets and devices.

``DEFAULTS`` is the one home of what a tour or a job renders with when nothing says otherwise:
``synth.tour.render.TourSpec``, ``synth.jobs.spec.JobSpec`` and its parser, and the options
of ``synth tour render`` read it."""

from __future__ import annotations

from dataclasses import dataclass

from vrformats.camera import DEFAULT_HEIGHT, DEFAULT_HFOV_DEG, DEFAULT_WIDTH
from vrformats.errors import UnknownNameError


@dataclass(frozen=True)
class RenderDefaults:
    renderer: str = "blender"  # blender | fast
    quality: str = "preview"  # a key of QUALITY
    width: int = DEFAULT_WIDTH
    height: int = DEFAULT_HEIGHT
    hfov_deg: float = DEFAULT_HFOV_DEG
    seed: int = 0  # Cycles seed
    device: str = "cpu"  # a member of DEVICES
    chunk_size: int = 50  # frames per Blender process
    previews: bool = False  # 8-bit PNG previews beside the EXR frames

    @property
    def size(self) -> str:
        return f"{self.width}x{self.height}"


DEFAULTS = RenderDefaults()


# Cycles settings per quality preset. Geometry passes (depth, ids) ignore these: they are traced with
# one sample through each pixel centre.
QUALITY = {
    # 3 samples + OpenImageDenoise (fast prefilter): under 1 s per 320x240 frame on 2 cores, close to
    # 16 samples by eye (and cleaner than 4 samples without the prefilter)
    "preview": {"samples": 3, "adaptive_threshold": 0.05, "max_bounces": 2, "diffuse_bounces": 1, "glossy_bounces": 1,
                "transmission_bounces": 2, "denoise": True, "denoise_prefilter": "FAST"},
    "standard": {"samples": 32, "adaptive_threshold": 0.02, "max_bounces": 4, "diffuse_bounces": 2, "glossy_bounces": 2,
                 "transmission_bounces": 4, "denoise": True, "denoise_prefilter": "ACCURATE"},
    "paper": {"samples": 128, "adaptive_threshold": 0.01, "max_bounces": 8, "diffuse_bounces": 4, "glossy_bounces": 4,
              "transmission_bounces": 8, "denoise": True, "denoise_prefilter": "ACCURATE"},
}
DEVICES = ("auto", "cpu", "gpu")


def quality(name: str) -> dict:
    try:
        return dict(QUALITY[name])
    except KeyError:
        raise UnknownNameError(f"unknown quality preset '{name}'; known: {', '.join(QUALITY)}") from None
