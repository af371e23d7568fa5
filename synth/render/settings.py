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
DENOISE_PREFILTERS = ("NONE", "FAST", "ACCURATE")  # OpenImageDenoise's prefilter of the albedo and normal passes


def quality(name: str) -> dict:
    try:
        return dict(QUALITY[name])
    except KeyError:
        raise UnknownNameError(f"unknown quality preset '{name}'; known: {', '.join(QUALITY)}") from None


def cycles_overrides(file, v, field: str = "cycles") -> dict | None:
    """A spec's ``cycles:`` mapping (settings of the quality preset replaced for this job, e.g.
    ``{denoise_prefilter: ACCURATE}``), checked key by key; None when absent. The one home of that
    validator: job specs, tours and the stability benchmark's render perturbations use it."""
    from vrformats import fields

    if v is None:
        return None
    d = fields.mapping(file, v, field, allowed=tuple(QUALITY["preview"]), what="a mapping of Cycles settings")
    out: dict = {}
    for k, x in d.items():
        f = f"{field}.{k}" if field else str(k)
        if k == "samples":
            out[k] = fields.positive_int(file, x, f)
        elif k == "adaptive_threshold":
            out[k] = fields.number(file, x, f, lo=0.0, hi=1.0)
        elif k.endswith("bounces"):
            out[k] = fields.integer(file, x, f, lo=0, hi=1024)
        elif k == "denoise":
            out[k] = fields.boolean(file, x, f)
        elif x not in DENOISE_PREFILTERS:  # denoise_prefilter
            fields.fail(file, f, f"expected one of {', '.join(DENOISE_PREFILTERS)}, got {fields.shown(x)}")
        else:
            out[k] = x
    return out or None


def resolve_quality(name: str, overrides: dict | None = None) -> dict:
    """The Cycles settings a render uses: preset ``name`` with ``overrides`` (checked by
    ``cycles_overrides``) applied."""
    return {**quality(name), **(overrides or {})}
