"""Procedural Cycles materials: shader nodes only, no image textures.

One entry point, :func:`get_material`, builds (and caches) a material for every name of
``synth.assets.materials.MATERIALS`` and of :data:`STAGE_MATERIALS` (the apartment shell).

Design rules

* Patterns are driven by the ``Object`` output of a Texture Coordinate node, so they are sized in
  metres (meshes are built in their object's local frame, objects are never scaled) and travel with
  the object when it is rearranged.  Planks are about 0.15 m x 1.2 m, tiles 0.4 m, etc.
* Every material carries some believable, low-contrast texture (wood grain and planks, tiles and
  grout, paint mottling, fabric weave, marble veins, colourful abstract art on canvases ...) so that
  feature matchers have something to hold on to, without looking like noise.
* ``color`` (linear RGB, 0..1) defines or tints the base colour; ``None`` gives a default per material.
* ``seed`` varies the pattern: the art of ``canvas`` (palette and layout), the accent of
  ``book_cover`` and a texture-space offset for the other materials.
* Trees are small (at most about 10 nodes) because render time matters (Cycles on CPU).

Emission (for the lighting code)

A material is *emissive* when ``emissive=True`` is passed, and always for ``lamp_shade`` and
``diffuser``.  Its tree then has an Emission shader node named ``"emission"`` (see
:data:`EMISSION_NODE`), added to the surface shader:

* ``mat.node_tree.nodes["emission"].inputs["Strength"].default_value``: 0 by default (light off);
* ``mat.node_tree.nodes["emission"].inputs["Color"].default_value``: RGBA, defaults to ``color``
  (white when ``color`` is None).

Use ``key`` (e.g. the fixture id) to get a material of one's own whose strength can be changed alone;
:func:`emission_node` returns that node (``None`` for non-emissive materials), :func:`set_emission`
sets strength and colour.

Glass: a Principled BSDF with Transmission Weight 1 (cheap, no volume); depth and instance passes
still see glass surfaces, as with any other mesh.

The emission API (:func:`emission_node`, :func:`set_emission`) and the node-tree helpers are in
``synth.blender.shading``; glTF PBR materials are ``synth.blender.gltf_materials``.
"""
from __future__ import annotations

import colorsys
import math

from . import require_python

require_python()  # before bpy: one line, not "No module named bpy", on another Python
import bpy  # noqa: E402

from ..assets.materials import MATERIALS
from .shading import CACHES, Color, Tree, find_socket, finish, is_alive, norm_color, seeded_rng

__all__ = [
    "STAGE_MATERIALS",
    "ALL_MATERIALS",
    "EMISSIVE_MATERIALS",
    "get_material",
]

STAGE_MATERIALS: tuple[str, ...] = ("floor_wood", "floor_tile", "wall_paint", "ceiling_paint", "door_frame")
ALL_MATERIALS: tuple[str, ...] = tuple(MATERIALS) + STAGE_MATERIALS
EMISSIVE_MATERIALS: tuple[str, ...] = ("lamp_shade", "diffuser")  # always get an "emission" node

_CACHE: dict[tuple, bpy.types.Material] = {}
CACHES.append(_CACHE)


# ----------------------------------------------------------------------------------------------
# public API


def get_material(name: str, color: Color | None = None, emissive: bool = False, key: str | None = None,
                 seed: int = 0) -> bpy.types.Material:
    """The Cycles material ``name`` (one of :data:`ALL_MATERIALS`), built once per argument tuple.

    ``color``: linear RGB in 0..1 (defines/tints the base colour; ``None``: the material's default).
    ``emissive``: add the Emission node named ``"emission"`` (strength 0); always on for
    ``lamp_shade`` and ``diffuser``.  ``key``: any string making the material unique (per lamp).
    ``seed``: varies the pattern (the art of a canvas).  Raises ValueError for an unknown name."""
    if name not in _BUILDERS:
        raise ValueError(f"unknown material {name!r}; known: {', '.join(ALL_MATERIALS)}")
    col = norm_color(color)
    emissive = bool(emissive) or name in EMISSIVE_MATERIALS
    seed = int(seed)
    ck = (name, col, emissive, None if key is None else str(key), seed)
    mat = _CACHE.get(ck)
    if mat is not None and is_alive(mat):
        return mat
    mat = _build(name, col, emissive, ck[3], seed)
    _CACHE[ck] = mat
    return mat


# ----------------------------------------------------------------------------------------------
# helpers


def _scale(c: Color, k: float) -> Color:
    return tuple(min(max(v * k, 0.0), 1.0) for v in c)


def _lerp(a: Color, b: Color, t: float) -> Color:
    return tuple(x + (y - x) * t for x, y in zip(a, b))


def _lum(c: Color) -> float:
    return 0.2126 * c[0] + 0.7152 * c[1] + 0.0722 * c[2]


# ----------------------------------------------------------------------------------------------
# builders: each takes (tree, color or None, seed) and returns the surface shader socket


def _wood_colors(base: Color) -> tuple[Color, Color, Color]:
    """(dark late-wood, mid, light early-wood) tones around a base colour."""
    return _scale(base, 0.62), base, _scale(base, 1.22)


def _wood(t: Tree, color, seed, default):
    base = color or default
    dark, mid, light = _wood_colors(base)
    # growth rings around the object's x axis; coordinates squeezed along x so the distortion is
    # long and gentle: on faces the rings read as long grain lines along x, ~1-2 cm apart
    vec = t.coords(seed, scale=(0.12, 1.0, 1.0))
    wave = t.add("ShaderNodeTexWave", wave_type="RINGS", rings_direction="X", wave_profile="SIN",
                 inputs={"Vector": vec, "Scale": 16.0, "Distortion": 9.0, "Detail": 2.0, "Detail Scale": 0.3,
                         "Detail Roughness": 0.55})
    # fine pores / streaks along x
    gmap = t.add("ShaderNodeMapping", inputs={"Vector": vec, "Scale": (25.0, 150.0, 150.0)})
    grain = t.noise(gmap.outputs["Vector"], 1.0, detail=3.0, roughness=0.6)
    col = t.ramp(wave.outputs["Fac"], [(0.0, light), (0.5, mid), (1.0, dark)])
    col = t.mix(grain.outputs["Fac"], col, (0.8, 0.8, 0.8), blend="MULTIPLY")
    nrm = t.bump(wave.outputs["Fac"], 0.05, 0.001)
    return t.bsdf(Base_Color=col, Roughness=0.45, Normal=nrm, Specular_IOR_Level=0.45)


def _wood_light(t, c, s):
    return _wood(t, c, s, (0.46, 0.29, 0.15))


def _wood_dark(t, c, s):
    return _wood(t, c, s, (0.13, 0.065, 0.03))


def _floor_wood(t: Tree, color, seed):
    base = color or (0.40, 0.24, 0.12)
    dark, mid, light = _scale(base, 0.72), base, _scale(base, 1.15)
    tc = t.add("ShaderNodeTexCoord")
    vec = tc.outputs["Object"]
    # planks 1.2 m x 0.15 m; brick colour = random per-plank value in 0.1..1, gaps (mortar) = 0
    brick = t.add("ShaderNodeTexBrick", offset=0.5, offset_frequency=2, squash=1.0, squash_frequency=2,
                  inputs={"Vector": vec, "Color1": (0.1, 0.1, 0.1), "Color2": (1.0, 1.0, 1.0), "Mortar": (0, 0, 0),
                          "Scale": 1.0, "Mortar Size": 0.0015, "Mortar Smooth": 0.3, "Bias": 0.0,
                          "Brick Width": 1.2, "Row Height": 0.15})
    # per-plank shift of the grain pattern (the random value moves its coordinates by up to 1 m)
    shift = t.add("ShaderNodeMapping", inputs={"Vector": vec, "Location": brick.outputs["Color"],
                                               "Scale": (0.12, 1.0, 1.0)})
    wave = t.add("ShaderNodeTexWave", wave_type="RINGS", rings_direction="X", wave_profile="SIN",
                 inputs={"Vector": shift.outputs["Vector"], "Scale": 7.0, "Distortion": 12.0, "Detail": 2.0,
                         "Detail Scale": 0.25, "Detail Roughness": 0.6,
                         "Phase Offset": float(seeded_rng(seed, 2).uniform(0, 6.28)) if seed else 0.0})
    col = t.ramp(wave.outputs["Fac"], [(0.0, light), (0.5, mid), (1.0, dark)])
    tint = t.ramp(brick.outputs["Color"], [(0.0, (0.25, 0.25, 0.25)), (0.1, (0.78, 0.78, 0.78)),
                                           (1.0, (1.12, 1.12, 1.12))])
    col = t.mix(1.0, col, tint, blend="MULTIPLY")
    nrm = t.bump(brick.outputs["Fac"], 0.35, 0.002)
    return t.bsdf(Base_Color=col, Roughness=0.35, Normal=nrm, Specular_IOR_Level=0.5)


def _floor_tile(t: Tree, color, seed):
    base = color or (0.62, 0.60, 0.56)
    vec = t.coords(seed)
    mottle = t.noise(vec, 6.0, detail=6.0, roughness=0.6, distortion=0.4)
    c1 = t.ramp(mottle.outputs["Fac"], [(0.3, _scale(base, 0.8)), (0.5, base), (0.7, _scale(base, 1.12))])
    # 0.4 m square tiles, 4 mm grout; per-tile shade between Color1 and Color2
    brick = t.add("ShaderNodeTexBrick", offset=0.0, offset_frequency=2, squash=1.0, squash_frequency=2,
                  inputs={"Vector": vec, "Color1": c1, "Color2": _scale(base, 0.88),
                          "Mortar": _scale(base, 0.42), "Scale": 1.0, "Mortar Size": 0.004,
                          "Mortar Smooth": 0.2, "Bias": -0.4, "Brick Width": 0.4, "Row Height": 0.4})
    rough = t.add("ShaderNodeMapRange", inputs={"Value": brick.outputs["Fac"], "To Min": 0.12, "To Max": 0.85})
    nrm = t.bump(brick.outputs["Fac"], 0.5, 0.002)
    return t.bsdf(Base_Color=brick.outputs["Color"], Roughness=rough.outputs["Result"], Normal=nrm)


def _paint(t: Tree, base: Color, seed, low=0.06, rough=0.75, low_scale=0.9):
    vec = t.coords(seed)
    lo = t.noise(vec, low_scale, detail=3.0, roughness=0.55)
    col = t.ramp(lo.outputs["Fac"], [(0.3, _scale(base, 1.0 - low)), (0.7, _scale(base, 1.0 + low))])
    hi = t.noise(vec, 220.0, detail=0.0, roughness=0.5)
    r = t.add("ShaderNodeMapRange", inputs={"Value": hi.outputs["Fac"], "To Min": rough - 0.12, "To Max": rough + 0.12})
    # no bump: millimetre relief is sub-pixel here, and a bump node evaluates its input three times
    return t.bsdf(Base_Color=col, Roughness=r.outputs["Result"])


def _wall_paint(t, c, s):
    return _paint(t, c or (0.74, 0.72, 0.68), s, low=0.07, rough=0.8, low_scale=0.7)


def _ceiling_paint(t, c, s):
    return _paint(t, c or (0.84, 0.84, 0.82), s, low=0.04, rough=0.85, low_scale=0.5)


def _painted(t, c, s):
    return _paint(t, c or (0.70, 0.70, 0.68), s, low=0.05, rough=0.38, low_scale=2.5)


def _door_frame(t: Tree, color, seed):
    """Door and window frames: smooth semi-gloss paint (faint mottling and orange peel)."""
    return _paint(t, color or (0.80, 0.79, 0.76), seed, low=0.04, rough=0.3, low_scale=3.0)


def _fabric(t: Tree, color, seed, default=(0.42, 0.42, 0.44), sheen=0.6, rough=0.9):
    base = color or default
    vec = t.coords(seed)
    mottle = t.noise(vec, 9.0, detail=4.0, roughness=0.6, distortion=0.3)
    col = t.ramp(mottle.outputs["Fac"], [(0.3, _scale(base, 0.88)), (0.7, _scale(base, 1.1))])
    # twill: fine diagonal ribs (~4 mm) in colour, a thread-scale weave in the bump
    twill = t.add("ShaderNodeTexWave", wave_type="BANDS", bands_direction="DIAGONAL", wave_profile="SIN",
                  inputs={"Vector": vec, "Scale": 75.0, "Distortion": 0.4, "Detail": 1.0})
    col = t.mix(twill.outputs["Fac"], col, (0.88, 0.88, 0.88), blend="MULTIPLY")
    weave = t.add("ShaderNodeTexMagic", turbulence_depth=1, inputs={"Vector": vec, "Scale": 160.0, "Distortion": 1.0})
    nrm = t.bump(weave.outputs["Fac"], 0.2, 0.001)
    return t.bsdf(Base_Color=col, Roughness=rough, Normal=nrm, Sheen_Weight=sheen, Sheen_Roughness=0.4,
                  Specular_IOR_Level=0.3)


def _leather(t: Tree, color, seed):
    base = color or (0.25, 0.12, 0.06)
    vec = t.coords(seed)
    lo = t.noise(vec, 3.0, detail=3.0, roughness=0.6, distortion=0.5)
    col = t.ramp(lo.outputs["Fac"], [(0.3, _scale(base, 0.7)), (0.7, _scale(base, 1.3))])
    pores = t.add("ShaderNodeTexVoronoi", feature="F1", distance="EUCLIDEAN",
                  inputs={"Vector": vec, "Scale": 250.0, "Randomness": 1.0})
    r = t.add("ShaderNodeMapRange", inputs={"Value": lo.outputs["Fac"], "To Min": 0.25, "To Max": 0.45})
    nrm = t.bump(pores.outputs["Distance"], 0.25, 0.001)
    return t.bsdf(Base_Color=col, Roughness=r.outputs["Result"], Normal=nrm, Specular_IOR_Level=0.6,
                  Coat_Weight=0.25, Coat_Roughness=0.25)


def _metal(t: Tree, color, seed):
    base = color or (0.72, 0.72, 0.74)
    bright = max(base) > 0.25
    vec = t.coords(seed)
    # brushed along x: noise squeezed across the brushing direction
    bm = t.add("ShaderNodeMapping", inputs={"Vector": vec, "Scale": (4.0, 400.0, 400.0)})
    brush = t.noise(bm.outputs["Vector"], 1.0, detail=3.0, roughness=0.6)
    smudge = t.noise(vec, 4.0, detail=3.0, roughness=0.6)
    col = t.mix(brush.outputs["Fac"], _scale(base, 0.85), _scale(base, 1.1))
    r = t.add("ShaderNodeMapRange", inputs={"Value": smudge.outputs["Fac"], "From Min": 0.3, "From Max": 0.7,
                                            "To Min": 0.18 if bright else 0.3, "To Max": 0.4 if bright else 0.5})
    nrm = t.bump(brush.outputs["Fac"], 0.08, 0.0005)
    return t.bsdf(Base_Color=col, Metallic=1.0 if bright else 0.6, Roughness=r.outputs["Result"], Normal=nrm,
                  Anisotropic=0.5)


def _plastic(t: Tree, color, seed):
    base = color or (0.8, 0.8, 0.8)
    vec = t.coords(seed)
    lo = t.noise(vec, 3.0, detail=3.0, roughness=0.5)
    col = t.ramp(lo.outputs["Fac"], [(0.3, _scale(base, 0.93)), (0.7, _scale(base, 1.06))])
    r = t.add("ShaderNodeMapRange", inputs={"Value": lo.outputs["Fac"], "To Min": 0.22, "To Max": 0.4})
    return t.bsdf(Base_Color=col, Roughness=r.outputs["Result"], Specular_IOR_Level=0.5)


def _ceramic(t: Tree, color, seed):
    base = color or (0.9, 0.9, 0.88)
    vec = t.coords(seed)
    lo = t.noise(vec, 7.0, detail=4.0, roughness=0.55, distortion=0.4)
    col = t.ramp(lo.outputs["Fac"], [(0.3, _scale(base, 0.88)), (0.7, _scale(base, 1.08))])
    speck = t.add("ShaderNodeTexVoronoi", feature="F1", inputs={"Vector": vec, "Scale": 60.0})
    col = t.mix(t.ramp(speck.outputs["Distance"], [(0.0, (1, 1, 1)), (0.06, (0, 0, 0))], "CONSTANT"), col,
                _scale(base, 0.6))
    return t.bsdf(Base_Color=col, Roughness=0.08, Specular_IOR_Level=0.6, Coat_Weight=0.6, Coat_Roughness=0.03)


def _glass(t: Tree, color, seed):
    base = color or (0.92, 0.96, 0.95)
    return t.bsdf(Base_Color=base, Roughness=0.02, IOR=1.45, Transmission_Weight=1.0)


def _mirror(t: Tree, color, seed):
    base = color or (0.92, 0.92, 0.92)
    return t.bsdf(Base_Color=base, Metallic=1.0, Roughness=0.01)


def _screen(t: Tree, color, seed):
    base = color or (0.02, 0.02, 0.025)
    base = _scale(base, 1.0) if max(base) < 0.1 else _scale(base, 0.1 / max(base))
    return t.bsdf(Base_Color=base, Roughness=0.06, Specular_IOR_Level=0.6, Coat_Weight=0.5, Coat_Roughness=0.02)


def _leaf(t: Tree, color, seed):
    base = color or (0.10, 0.30, 0.08)
    vec = t.coords(seed)
    lo = t.noise(vec, 12.0, detail=3.0, roughness=0.6, distortion=0.6)
    col = t.ramp(lo.outputs["Fac"], [(0.25, _scale(base, 0.75)), (0.5, base),
                                     (0.75, _lerp(base, (0.55, 0.6, 0.2), 0.2))])
    veins = t.add("ShaderNodeTexVoronoi", feature="DISTANCE_TO_EDGE", inputs={"Vector": vec, "Scale": 25.0})
    nrm = t.bump(veins.outputs["Distance"], 0.3, 0.002)
    return t.bsdf(Base_Color=col, Roughness=0.45, Normal=nrm, Subsurface_Weight=0.0, Sheen_Weight=0.2)


def _soil(t: Tree, color, seed):
    base = color or (0.07, 0.045, 0.028)
    vec = t.coords(seed)
    lo = t.noise(vec, 30.0, detail=8.0, roughness=0.7, distortion=0.3)
    col = t.ramp(lo.outputs["Fac"], [(0.3, _scale(base, 0.5)), (0.5, base), (0.7, _scale(base, 1.8))])
    clumps = t.add("ShaderNodeTexVoronoi", feature="F1", inputs={"Vector": vec, "Scale": 90.0})
    nrm = t.bump(clumps.outputs["Distance"], 0.6, 0.004)
    return t.bsdf(Base_Color=col, Roughness=0.95, Normal=nrm, Specular_IOR_Level=0.2)


def _paper(t: Tree, color, seed):
    base = color or (0.86, 0.85, 0.81)
    vec = t.coords(seed)
    fib = t.noise(vec, 120.0, detail=4.0, roughness=0.6)
    col = t.mix(fib.outputs["Fac"], _scale(base, 0.95), _scale(base, 1.03))
    lines = t.add("ShaderNodeTexWave", wave_type="BANDS", bands_direction="Z", wave_profile="SAW",
                  inputs={"Vector": vec, "Scale": 50.0})
    blocks = t.noise(vec, 8.0, detail=1.0)
    mask = t.mix(blocks.outputs["Fac"], (0, 0, 0),
                 t.ramp(lines.outputs["Fac"], [(0.0, (0.0, 0.0, 0.0)), (0.75, (0.12, 0.12, 0.12))], "CONSTANT"))
    col = t.mix(mask, col, _scale(base, 0.4))
    return t.bsdf(Base_Color=col, Roughness=0.75, Specular_IOR_Level=0.3)


def _book_cover(t: Tree, color, seed):
    base = color or (0.45, 0.09, 0.09)
    rng = seeded_rng(seed, 3)
    accent = (0.8, 0.62, 0.22) if _lum(base) < 0.35 else (0.05, 0.05, 0.06)
    if rng.random() < 0.35:
        accent = (0.85, 0.84, 0.80) if _lum(base) < 0.35 else _scale(base, 0.35)
    vec = t.coords(seed)
    # title / ornament bands across the spine (horizontal, a few cm apart)
    bands = t.add("ShaderNodeTexWave", wave_type="BANDS", bands_direction="Z", wave_profile="SAW",
                  inputs={"Vector": vec, "Scale": float(rng.uniform(2.5, 4.5)),
                          "Phase Offset": float(rng.uniform(0, 6.28))})
    b = t.ramp(bands.outputs["Fac"], [(0.0, (0, 0, 0)), (0.82, (1, 1, 1)), (0.9, (0, 0, 0))], "CONSTANT")
    wear = t.noise(vec, 25.0, detail=4.0, roughness=0.6)
    col = t.mix(wear.outputs["Fac"], _scale(base, 1.12), _scale(base, 0.82))
    col = t.mix(b, col, accent)
    return t.bsdf(Base_Color=col, Roughness=0.45, Specular_IOR_Level=0.4)


def _lamp_shade(t: Tree, color, seed):
    base = color or (0.9, 0.87, 0.80)
    vec = t.coords(seed)
    weave = t.add("ShaderNodeTexWave", wave_type="BANDS", bands_direction="Z", wave_profile="SIN",
                  inputs={"Vector": vec, "Scale": 60.0, "Distortion": 1.0, "Detail": 1.0})
    col = t.mix(weave.outputs["Fac"], _scale(base, 0.9), base)
    surf = t.bsdf(Base_Color=col, Roughness=0.9, Sheen_Weight=0.3, Specular_IOR_Level=0.3)
    trans = t.add("ShaderNodeBsdfTranslucent", inputs={"Color": col})
    mix = t.add("ShaderNodeMixShader", inputs={"Fac": 0.45})
    t.nt.links.new(surf, mix.inputs[1])
    t.nt.links.new(trans.outputs["BSDF"], mix.inputs[2])
    return mix.outputs["Shader"]


def _diffuser(t: Tree, color, seed):
    base = color or (0.92, 0.92, 0.92)
    surf = t.bsdf(Base_Color=base, Roughness=0.4, Specular_IOR_Level=0.4)
    trans = t.add("ShaderNodeBsdfTranslucent", inputs={"Color": base})
    mix = t.add("ShaderNodeMixShader", inputs={"Fac": 0.4})
    t.nt.links.new(surf, mix.inputs[1])
    t.nt.links.new(trans.outputs["BSDF"], mix.inputs[2])
    return mix.outputs["Shader"]


def _mattress(t: Tree, color, seed):
    base = color or (0.86, 0.86, 0.83)
    # quilting: diamonds of soft stitch lines (brick texture without offset, turned 45 degrees)
    vec = t.coords(seed, rotation=(0.0, 0.0, math.pi / 4))
    quilt = t.add("ShaderNodeTexBrick", offset=0.0, offset_frequency=2, squash=1.0, squash_frequency=2,
                  inputs={"Vector": vec, "Color1": base, "Color2": _scale(base, 0.97), "Mortar": _scale(base, 0.88),
                          "Scale": 1.0, "Mortar Size": 0.012, "Mortar Smooth": 1.0, "Bias": 0.0,
                          "Brick Width": 0.16, "Row Height": 0.16})
    mottle = t.noise(vec, 8.0, detail=3.0)
    col = t.mix(mottle.outputs["Fac"], quilt.outputs["Color"], (0.92, 0.92, 0.92), blend="MULTIPLY")
    nrm = t.bump(quilt.outputs["Fac"], 0.5, 0.015)
    return t.bsdf(Base_Color=col, Roughness=0.85, Normal=nrm, Sheen_Weight=0.5)


def _marble(t: Tree, color, seed):
    base = color or (0.86, 0.85, 0.83)
    vein = (0.12, 0.12, 0.13) if _lum(base) > 0.3 else (0.75, 0.74, 0.72)
    vec = t.coords(seed)
    w = t.add("ShaderNodeTexWave", wave_type="BANDS", bands_direction="DIAGONAL", wave_profile="SIN",
              inputs={"Vector": vec, "Scale": 1.2, "Distortion": 14.0, "Detail": 2.0, "Detail Scale": 0.8,
                      "Detail Roughness": 0.65})
    cloud = t.noise(vec, 4.0, detail=5.0, roughness=0.6)
    col = t.ramp(w.outputs["Fac"], [(0.0, _lerp(base, vein, 0.85)), (0.06, _lerp(base, vein, 0.35)),
                                    (0.15, base), (1.0, _scale(base, 1.04))])
    col = t.mix(cloud.outputs["Fac"], col, (0.9, 0.9, 0.9), blend="MULTIPLY")
    return t.bsdf(Base_Color=col, Roughness=0.12, Specular_IOR_Level=0.6, Coat_Weight=0.3, Coat_Roughness=0.05)


def _art_palette(color, seed, n=5) -> list[Color]:
    rng = seeded_rng(seed, 4)
    h0 = rng.random()
    cols = []
    for i in range(n):
        h = (h0 + rng.choice([0.0, 0.08, 0.33, 0.5, 0.6]) + rng.normal(0, 0.04)) % 1.0
        s = rng.uniform(0.45, 0.95)
        v = rng.uniform(0.25, 0.95)
        r, g, b = colorsys.hsv_to_rgb(h, s, v)
        cols.append((r ** 2.2, g ** 2.2, b ** 2.2))  # sRGB-ish -> linear
    if rng.random() < 0.6:  # a neutral for contrast
        cols[int(rng.integers(n))] = (0.8, 0.78, 0.74) if rng.random() < 0.6 else (0.03, 0.03, 0.035)
    if color is not None:
        cols[int(rng.integers(n))] = color
    return cols


_ART_STYLES = ("fields", "mosaic", "stripes", "rings")


def _canvas(t: Tree, color, seed):
    """Colourful abstract art: a seeded palette (``color`` is one of its colours) painted as flat
    colour fields, a mosaic, bands or rings; the seed picks style, palette and composition."""
    rng = seeded_rng(seed, 5)
    pal = _art_palette(color, seed)
    style = _ART_STYLES[int(rng.integers(len(_ART_STYLES)))]
    vec = t.coords(seed, rotation=(float(rng.uniform(-0.4, 0.4)), float(rng.uniform(-0.4, 0.4)),
                                   float(rng.uniform(0, math.pi))))
    if style == "fields":
        f = t.noise(vec, float(rng.uniform(1.5, 4.0)), detail=1.5, roughness=0.5,
                    distortion=float(rng.uniform(0.5, 1.5))).outputs["Fac"]
        interp, lo, hi = "CONSTANT", 0.3, 0.7
    elif style == "mosaic":
        warp = t.noise(vec, float(rng.uniform(1.0, 3.0)), detail=1.0)
        vm = t.add("ShaderNodeMix", data_type="VECTOR", clamp_factor=True,
                   inputs={"Factor_Float": float(rng.uniform(0.05, 0.2)), "A_Vector": vec,
                           "B_Vector": warp.outputs["Color"]})
        f = t.add("ShaderNodeTexVoronoi", feature="F1",
                  inputs={"Vector": find_socket(vm.outputs, "Result_Vector"), "Scale": float(rng.uniform(4.0, 9.0))}
                  ).outputs["Color"]
        interp, lo, hi = "CONSTANT", 0.1, 0.9
    elif style == "stripes":
        f = t.add("ShaderNodeTexWave", wave_type="BANDS", bands_direction=str(rng.choice(["X", "Z", "DIAGONAL"])),
                  wave_profile=str(rng.choice(["SIN", "TRI"])),
                  inputs={"Vector": vec, "Scale": float(rng.uniform(1.5, 4.0)),
                          "Distortion": float(rng.uniform(1.0, 6.0)), "Detail": 2.0, "Detail Scale": 1.0}
                  ).outputs["Fac"]
        interp, lo, hi = str(rng.choice(["CONSTANT", "LINEAR"])), 0.1, 0.9
    else:
        f = t.add("ShaderNodeTexWave", wave_type="RINGS", rings_direction="SPHERICAL", wave_profile="SAW",
                  inputs={"Vector": vec, "Scale": float(rng.uniform(0.8, 2.0)),
                          "Distortion": float(rng.uniform(0.5, 4.0)), "Detail": 2.0}).outputs["Fac"]
        interp, lo, hi = "CONSTANT", 0.1, 0.9
    stops = sorted(rng.uniform(lo, hi, len(pal) - 1))
    col = t.ramp(f, [(0.0, pal[0])] + list(zip(stops, pal[1:])), interp)
    # canvas texture: faint brush strokes
    brush = t.noise(vec, 40.0, detail=2.0, roughness=0.6)
    col = t.mix(brush.outputs["Fac"], col, (0.88, 0.88, 0.88), blend="MULTIPLY")
    return t.bsdf(Base_Color=col, Roughness=0.6, Specular_IOR_Level=0.4)


def _wicker(t: Tree, color, seed):
    base = color or (0.55, 0.40, 0.22)
    # rotate 45 deg about z so both x- and y-facing sides show the weave
    vec = t.coords(seed, rotation=(0.0, 0.0, math.pi / 4))
    weft = t.add("ShaderNodeTexWave", wave_type="BANDS", bands_direction="Z", wave_profile="SIN",
                 inputs={"Vector": vec, "Scale": 20.0, "Distortion": 0.3, "Detail": 1.0})
    warp = t.add("ShaderNodeTexWave", wave_type="BANDS", bands_direction="X", wave_profile="SIN",
                 inputs={"Vector": vec, "Scale": 20.0, "Distortion": 0.3, "Detail": 1.0})
    check = t.add("ShaderNodeTexChecker", inputs={"Vector": vec, "Scale": 32.0})
    h = t.mixf(check.outputs["Fac"], weft.outputs["Fac"], warp.outputs["Fac"])
    col = t.ramp(h, [(0.0, _scale(base, 0.35)), (0.35, _scale(base, 0.85)), (1.0, _scale(base, 1.2))])
    nrm = t.bump(h, 0.6, 0.004)
    return t.bsdf(Base_Color=col, Roughness=0.7, Normal=nrm)


_BUILDERS = {
    "wood_light": _wood_light,
    "wood_dark": _wood_dark,
    "fabric": _fabric,
    "leather": _leather,
    "metal": _metal,
    "plastic": _plastic,
    "ceramic": _ceramic,
    "glass": _glass,
    "leaf": _leaf,
    "soil": _soil,
    "paper": _paper,
    "book_cover": _book_cover,
    "screen": _screen,
    "lamp_shade": _lamp_shade,
    "diffuser": _diffuser,
    "mattress": _mattress,
    "painted": _painted,
    "mirror": _mirror,
    "marble": _marble,
    "canvas": _canvas,
    "wicker": _wicker,
    "floor_wood": _floor_wood,
    "floor_tile": _floor_tile,
    "wall_paint": _wall_paint,
    "ceiling_paint": _ceiling_paint,
    "door_frame": _door_frame,
}
assert set(_BUILDERS) == set(ALL_MATERIALS), "every material name needs a builder"


def _default_emit_color(name: str, col: Color | None) -> Color:
    return col if col is not None else (1.0, 1.0, 1.0)


def _build(name: str, col: Color | None, emissive: bool, key: str | None, seed: int) -> bpy.types.Material:
    label = name if key is None else f"{name}@{key}"
    mat = bpy.data.materials.new(label)
    t = Tree(mat)
    surface = _BUILDERS[name](t, col, seed)
    finish(t, surface, emissive, _default_emit_color(name, col))
    base = col or (0.7, 0.7, 0.7)
    mat.diffuse_color = (*base, 1.0)  # viewport / solid mode only
    mat["synth_material"] = name
    return mat
