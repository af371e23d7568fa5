"""Render settings shared by the renderers and the CLI (no bpy): quality presets and devices."""

from __future__ import annotations

from formats.errors import UnknownNameError



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
