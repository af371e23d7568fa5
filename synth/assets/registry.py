"""The one table of procedural object classes, and the public entry points that use it.

``REGISTRY`` maps each class name (``scenes/classes.yaml``: every class but the structure ones and
those only imported datasets have) to its ``AssetClass``: the generator that lays out its parts, the
sampler that draws a realistic size and style, and whether things may be placed on it. Generators
and samplers live side by side in the family modules (``seating``, ``tables``, ``storage``,
``kitchen``, ``beds``, ``bathroom``, ``lighting``, ``plants``, ``decor``, ``electronics``).

Public API: ``REGISTRY``, ``AssetClass``, ``NO_SURFACE_CLASSES``, ``known_classes``, ``sample_params``,
``make_parts``, ``make_mesh``, ``support_surfaces``, ``UnknownClassError``; ``Part`` and ``Surface``
(from ``primitives`` and ``surfaces``) are what they return. No bpy, no network, deterministic.
"""
from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
import trimesh

from vrformats.errors import UnknownNameError

from . import bathroom, beds, decor, electronics, kitchen, lighting, plants, seating, storage, tables
from .primitives import Builder, Part, concat
from .sampling import ParamSampler
from .surfaces import Surface

__all__ = [
    "NO_SURFACE_CLASSES",
    "REGISTRY",
    "AssetClass",
    "Part",
    "Surface",
    "UnknownClassError",
    "known_classes",
    "make_mesh",
    "make_parts",
    "sample_params",
    "support_surfaces",
]

Size = tuple[float, float, float]


class UnknownClassError(UnknownNameError, ValueError):
    """An object class without a mesh generator (a ValueError, and a UserError for the CLIs)."""


@dataclass(frozen=True)
class AssetClass:
    """How one object class is made.

    ``generate(builder, w, d, h, params)`` adds the parts and supporting surfaces of an instance of
    size (w, d, h); ``sample(sampler)`` draws a size and params for one instance; ``holds_objects``
    is False for classes whose surfaces are not meant for placing things on (lamps, vases, a TV...)."""

    generate: Callable[[Builder, float, float, float, dict], None]
    sample: Callable[[ParamSampler], tuple[Size, dict]]
    holds_objects: bool = True


# in the order of known_classes()
REGISTRY: dict[str, AssetClass] = {
    "sofa": AssetClass(seating.generate_sofa, seating.sample_sofa),
    "armchair": AssetClass(seating.generate_armchair, seating.sample_armchair),
    "chair": AssetClass(seating.generate_chair, seating.sample_chair),
    "stool": AssetClass(seating.generate_stool, seating.sample_stool),
    "dining_table": AssetClass(tables.generate_dining_table, tables.sample_dining_table),
    "coffee_table": AssetClass(tables.generate_coffee_table, tables.sample_coffee_table),
    "side_table": AssetClass(tables.generate_side_table, tables.sample_side_table),
    "desk": AssetClass(tables.generate_desk, tables.sample_desk),
    "bed": AssetClass(beds.generate_bed, beds.sample_bed),
    "nightstand": AssetClass(storage.generate_nightstand, storage.sample_nightstand),
    "wardrobe": AssetClass(storage.generate_wardrobe, storage.sample_wardrobe),
    "bookshelf": AssetClass(storage.generate_bookshelf, storage.sample_bookshelf),
    "cabinet": AssetClass(storage.generate_cabinet, storage.sample_cabinet),
    "tv_stand": AssetClass(storage.generate_tv_stand, storage.sample_tv_stand),
    "tv": AssetClass(electronics.generate_tv, electronics.sample_tv, holds_objects=False),
    "kitchen_counter": AssetClass(kitchen.generate_kitchen_counter, kitchen.sample_kitchen_counter),
    "fridge": AssetClass(kitchen.generate_fridge, kitchen.sample_fridge),
    "stove": AssetClass(kitchen.generate_stove, kitchen.sample_stove, holds_objects=False),
    "toilet": AssetClass(bathroom.generate_toilet, bathroom.sample_toilet),
    "bathtub": AssetClass(bathroom.generate_bathtub, bathroom.sample_bathtub, holds_objects=False),
    "washbasin": AssetClass(bathroom.generate_washbasin, bathroom.sample_washbasin, holds_objects=False),
    "floor_lamp": AssetClass(lighting.generate_floor_lamp, lighting.sample_floor_lamp, holds_objects=False),
    "table_lamp": AssetClass(lighting.generate_table_lamp, lighting.sample_table_lamp, holds_objects=False),
    "plant": AssetClass(plants.generate_plant, plants.sample_plant, holds_objects=False),
    "cushion": AssetClass(decor.generate_cushion, decor.sample_cushion, holds_objects=False),
    "book": AssetClass(decor.generate_book, decor.sample_book, holds_objects=False),
    "vase": AssetClass(decor.generate_vase, decor.sample_vase, holds_objects=False),
    "bowl": AssetClass(decor.generate_bowl, decor.sample_bowl, holds_objects=False),
    "picture": AssetClass(decor.generate_picture, decor.sample_picture, holds_objects=False),
    "mirror": AssetClass(decor.generate_mirror, decor.sample_mirror, holds_objects=False),
    "bin": AssetClass(decor.generate_bin, decor.sample_bin, holds_objects=False),
    "shoe_rack": AssetClass(storage.generate_shoe_rack, storage.sample_shoe_rack),
    "bench": AssetClass(seating.generate_bench, seating.sample_bench),
    "laptop": AssetClass(electronics.generate_laptop, electronics.sample_laptop, holds_objects=False),
    "ceiling_light": AssetClass(lighting.generate_ceiling_light, lighting.sample_ceiling_light, holds_objects=False),
    "small_plant": AssetClass(plants.generate_small_plant, plants.sample_small_plant, holds_objects=False),
    "basket": AssetClass(decor.generate_basket, decor.sample_basket, holds_objects=False),
    "other": AssetClass(decor.generate_other, decor.sample_other, holds_objects=False),
}

# classes whose surfaces are not meant for placing things on
NO_SURFACE_CLASSES: frozenset[str] = frozenset(cls for cls, a in REGISTRY.items() if not a.holds_objects)


def known_classes() -> list[str]:
    """Classes with a mesh generator (every non-structure class of scenes/classes.yaml)."""
    return list(REGISTRY)


def _check_cls(cls: str) -> None:
    if cls not in REGISTRY:
        raise UnknownClassError(f"unknown object class {cls!r}: no mesh generator")


def _check_size(size) -> Size:
    try:
        w, d, h = (float(v) for v in size)
    except (TypeError, ValueError) as e:
        raise ValueError(f"size must be three numbers (w, d, h), got {size!r}") from e
    if not all(math.isfinite(v) and v > 0 for v in (w, d, h)):
        raise ValueError(f"size must be positive and finite, got {size!r}")
    return w, d, h


def _build(cls: str, size, params) -> tuple[list[Part], list[Surface]]:
    _check_cls(cls)
    w, d, h = _check_size(size)
    b = Builder()
    REGISTRY[cls].generate(b, w, d, h, dict(params or {}))
    return b.finish(w, d, h)


def sample_params(cls: str, rng: np.random.Generator) -> tuple[Size, dict]:
    """Realistic size (w, d, h) in metres and style params (plain YAML-able values) for one instance."""
    _check_cls(cls)
    size, params = REGISTRY[cls].sample(ParamSampler(rng))
    return tuple(float(v) for v in size), params


def make_parts(cls: str, size, params: dict) -> list[Part]:
    """Named, material-tagged parts of one object; their union fills [-w/2,w/2]x[-d/2,d/2]x[0,h] exactly."""
    return _build(cls, size, params)[0]


def make_mesh(cls: str, size, params: dict) -> trimesh.Trimesh:
    """All parts of make_parts concatenated into one mesh."""
    return concat([p.mesh for p in make_parts(cls, size, params)])


def support_surfaces(cls: str, size, params: dict) -> list[Surface]:
    """Rectangles in the object's local frame where small objects can be placed ([] for none)."""
    _check_cls(cls)
    if cls in NO_SURFACE_CLASSES:
        _check_size(size)
        return []
    return _build(cls, size, params)[1]
