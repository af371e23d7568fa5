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
# one sample through each pixel centre. Picked on the quality-versus-time curve of ``synth bench
# quality`` (docs/rendering.md#quality-against-time: PSNR against a 2x2048-sample, 16-bounce
# reference, 160x120, built-in apartment by day and night, ReplicaCAD apt_0 by night): bounces buy
# more than samples (at 16 samples, 4 bounces lose 2.6-5.5 dB to 8), and past 64 samples a doubling
# buys under 1.2 dB.
QUALITY = {
    # 3 samples, 2 bounces + OpenImageDenoise (fast prefilter): the demo's; 22-28 dB, well below
    # paper quality (its 2 bounces), under 1 s per 160x120 frame on 2 cores
    "preview": {"samples": 3, "adaptive_threshold": 0.05, "max_bounces": 2, "diffuse_bounces": 1, "glossy_bounces": 1,
                "transmission_bounces": 2, "denoise": True, "denoise_prefilter": "FAST"},
    # the paper preset at 16 samples: 32-37 dB, faster than the 32-sample, 4-bounce standard it replaces
    # (28-32 dB) in every view measured
    "standard": {"samples": 16, "adaptive_threshold": 0.01, "max_bounces": 8, "diffuse_bounces": 4, "glossy_bounces": 4,
                 "transmission_bounces": 8, "denoise": True, "denoise_prefilter": "ACCURATE"},
    # paper quality, >= 35 dB: 64 samples is the fewest that reach it in every view measured (35.0 dB in
    # the built-in apartment by day, the hardest view; 128 samples gave 36.2 there at twice the time)
    "paper": {"samples": 64, "adaptive_threshold": 0.01, "max_bounces": 8, "diffuse_bounces": 4, "glossy_bounces": 4,
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
