"""Material vocabulary and colour palettes of the procedural assets (no dependencies).

``MATERIALS`` is every material a part may have (``synth.blender.materials`` has a shader for each);
the palettes are approximate linear RGB colours that the samplers pick from and the generators fall
back to when a colour parameter is missing.
"""
from __future__ import annotations

__all__ = [
    "APPLIANCE",
    "BOOK",
    "CERAMIC",
    "DARK",
    "FABRIC",
    "LEAF",
    "LEATHER",
    "LINEN",
    "MARBLE",
    "MATERIALS",
    "PAINT",
    "PLASTIC",
    "SHADE",
    "WHITE",
    "WOODS",
]

MATERIALS: tuple[str, ...] = (
    "wood_light",
    "wood_dark",
    "fabric",
    "leather",
    "metal",
    "plastic",
    "ceramic",
    "glass",
    "leaf",
    "soil",
    "paper",
    "book_cover",
    "screen",
    "lamp_shade",
    "diffuser",
    "mattress",
    "painted",
    "mirror",
    "marble",
    "canvas",
    "wicker",
)


# colour palettes (approximate linear RGB)

FABRIC = (
    (0.42, 0.42, 0.44), (0.12, 0.16, 0.30), (0.55, 0.48, 0.38), (0.20, 0.32, 0.20),
    (0.45, 0.17, 0.11), (0.72, 0.69, 0.62), (0.10, 0.10, 0.11), (0.60, 0.42, 0.12),
    (0.30, 0.12, 0.20), (0.25, 0.38, 0.45),
)
LEATHER = ((0.25, 0.12, 0.06), (0.07, 0.06, 0.06), (0.45, 0.28, 0.15), (0.60, 0.55, 0.50))
PAINT = (
    (0.85, 0.85, 0.83), (0.08, 0.08, 0.09), (0.50, 0.52, 0.50), (0.35, 0.45, 0.38),
    (0.20, 0.28, 0.40), (0.75, 0.70, 0.60),
)
CERAMIC = (
    (0.90, 0.90, 0.88), (0.15, 0.15, 0.16), (0.60, 0.35, 0.25), (0.30, 0.45, 0.55),
    (0.75, 0.65, 0.50), (0.50, 0.55, 0.45),
)
LEAF = ((0.10, 0.30, 0.08), (0.15, 0.38, 0.12), (0.08, 0.25, 0.12), (0.22, 0.40, 0.10))
BOOK = (
    (0.55, 0.08, 0.08), (0.08, 0.18, 0.45), (0.10, 0.35, 0.15), (0.85, 0.75, 0.20),
    (0.12, 0.12, 0.12), (0.80, 0.80, 0.78), (0.45, 0.20, 0.45), (0.85, 0.40, 0.10),
    (0.30, 0.55, 0.65),
)
SHADE = ((0.95, 0.92, 0.85), (0.90, 0.85, 0.75), (0.85, 0.85, 0.85), (0.80, 0.75, 0.65))
PLASTIC = ((0.90, 0.90, 0.90), (0.10, 0.10, 0.10), (0.50, 0.50, 0.52), (0.15, 0.30, 0.55))
APPLIANCE = ((0.92, 0.92, 0.92), (0.65, 0.66, 0.68), (0.12, 0.12, 0.13))
MARBLE = ((0.90, 0.89, 0.87), (0.15, 0.15, 0.16), (0.60, 0.60, 0.58))
LINEN = ((0.92, 0.92, 0.90), (0.85, 0.82, 0.75), (0.70, 0.75, 0.80))
DARK = (0.04, 0.04, 0.045)
WHITE = (0.9, 0.9, 0.88)

WOODS = ("wood_light", "wood_dark")
