"""Appearance randomisation for detector training data: a layout's colours and materials redrawn.

A detector trained on the procedural assets' default palettes learns the palette (a brown leather
sofa, white walls) as much as the shape. ``randomize_appearance`` returns a copy of a layout in
which, per object with probability ``strength``, every colour parameter (``color``, ``*_color``) is
drawn anew and every material parameter (``material``, ``*_material``) is swapped within its
family (hard surfaces, soft furnishings); the room finishes (wall, ceiling and floor colours, the
floor's material) are drawn with the same probability per layout and stored in the layout's
``meta.finishes``, which ``synth.render.meshes.stage_parts`` reads (``FINISH_KEYS``). Geometry,
classes and ids are unchanged, so labels are unchanged. Seeded: same layout and seed, same result.

Only training layouts are randomised (``synth trainset``'s ``appearance`` key); the experiment
layouts keep their own look.
"""

from __future__ import annotations

import colorsys
import copy

import numpy as np

from ..assets.materials import MATERIALS
from ..scene.model import Layout

# material families that a part may move within (others, like glass, screens or leaves, stay)
HARD = ("wood_light", "wood_dark", "metal", "plastic", "painted", "marble", "ceramic")
SOFT = ("fabric", "leather")
FAMILIES = (HARD, SOFT)
FLOORS = ("floor_wood", "floor_tile")
FINISH_KEYS = ("wall_color", "ceiling_color", "floor_color", "floor_material")
assert all(m in MATERIALS for fam in FAMILIES for m in fam)


def random_color(rng: np.random.Generator, value=(0.03, 0.85), saturation=(0.0, 0.75)) -> list[float]:
    """A linear-RGB colour: uniform hue, saturation and value in the given ranges (value is drawn in
    display space, then linearised, so dark and light colours are about equally likely)."""
    h, s = float(rng.uniform(0, 1)), float(rng.uniform(*saturation))
    v = float(rng.uniform(*value))
    return [round(float(c) ** 2.2, 4) for c in colorsys.hsv_to_rgb(h, s, v)]


def _family(material: str):
    return next((fam for fam in FAMILIES if material in fam), None)


def randomize_appearance(layout: Layout, seed: int, strength: float = 0.5) -> Layout:
    """A copy of ``layout`` with colours and materials redrawn (see the module docstring)."""
    if not 0.0 <= strength <= 1.0:
        raise ValueError(f"appearance strength must lie in [0, 1], got {strength}")
    rng = np.random.default_rng([int(seed), 23])
    out = copy.deepcopy(layout)
    for obj in out.objects:
        if not obj.params or rng.uniform() >= strength:
            continue
        for key in sorted(obj.params):
            val = obj.params[key]
            if (key == "color" or key.endswith("_color")) and isinstance(val, (list, tuple)) and len(val) == 3:
                obj.params[key] = random_color(rng)
            elif (key == "material" or key.endswith("_material")) and isinstance(val, str) and _family(val):
                fam = _family(val)
                obj.params[key] = fam[int(rng.integers(len(fam)))]
    if out.stage.asset is None and rng.uniform() < strength:
        out.meta = dict(out.meta)
        out.meta["finishes"] = {
            "wall_color": random_color(rng, value=(0.35, 0.95), saturation=(0.0, 0.5)),
            "ceiling_color": random_color(rng, value=(0.6, 0.95), saturation=(0.0, 0.15)),
            "floor_color": random_color(rng, value=(0.15, 0.8), saturation=(0.0, 0.6)),
            "floor_material": FLOORS[int(rng.integers(len(FLOORS)))],
        }
    return out
