"""Shader-node plumbing shared by the procedural and the glTF materials (bpy).

``Tree`` adds and links nodes; ``finish`` adds the optional emission and the material output;
:func:`emission_node` / :func:`set_emission` are how the lighting switches an emitter on (a lamp's
shade, a ceiling diffuser, a glTF emitter); :func:`clear_cache` forgets every cached material.

Emission: a material built emissive has an Emission shader node named ``"emission"``
(:data:`EMISSION_NODE`; strength 0 = off) added to its surface shader; a glTF emitter also has an RGB
node named ``"emission_light"`` (:data:`EMISSION_LIGHT_NODE`) carrying the light's colour, which
tints the texture x factor colour instead of replacing it.
"""
from __future__ import annotations

import math

from . import require_python

require_python()  # before bpy: one line, not "No module named bpy", on another Python
import bpy  # noqa: E402
import numpy as np

EMISSION_NODE = "emission"
EMISSION_LIGHT_NODE = "emission_light"  # glTF emitters: RGB node carrying the light's colour

Color = tuple[float, float, float]

# the material caches of both libraries (cleared together by clear_cache)
CACHES: list[dict] = []


def emission_node(mat: bpy.types.Material):
    """The Emission node of ``mat`` (inputs "Color" and "Strength"), or None."""
    if mat is None or mat.node_tree is None:
        return None
    return mat.node_tree.nodes.get(EMISSION_NODE)


def set_emission(mat: bpy.types.Material, strength: float, color: Color | None = None) -> None:
    """Set the strength (and optionally the linear RGB colour) of ``mat``'s "emission" node.

    Raises ValueError when ``mat`` has none (build it with ``emissive=True``)."""
    node = emission_node(mat)
    if node is None:
        raise ValueError(f"material {mat.name!r} has no {EMISSION_NODE!r} node")
    node.inputs["Strength"].default_value = float(strength)
    if color is not None:
        light = mat.node_tree.nodes.get(EMISSION_LIGHT_NODE)
        if light is not None:  # glTF emitter: the texture x factor colour stays, the light tints it
            light.outputs[0].default_value = (*norm_color(color), 1.0)
        else:
            node.inputs["Color"].default_value = (*norm_color(color), 1.0)


def clear_cache() -> None:
    """Forget cached materials and images (they stay in bpy.data); the next call builds new ones."""
    for cache in CACHES:
        cache.clear()


def norm_color(color) -> Color | None:
    if color is None:
        return None
    vals = [float(v) for v in tuple(color)[:3]]
    if len(vals) != 3 or not all(math.isfinite(v) for v in vals):
        raise ValueError(f"color must be three finite numbers, got {color!r}")
    return tuple(round(min(max(v, 0.0), 1.0), 4) for v in vals)


def is_alive(mat) -> bool:
    try:
        return bpy.data.materials.get(mat.name) == mat
    except ReferenceError:
        return False


def seeded_rng(seed: int, salt: int) -> np.random.Generator:
    return np.random.default_rng([abs(int(seed)), salt])


def seed_offset(seed: int) -> tuple[float, float, float]:
    if seed == 0:
        return (0.0, 0.0, 0.0)
    return tuple(float(v) for v in seeded_rng(seed, 1).uniform(-50.0, 50.0, size=3))


def find_socket(coll, key):
    for s in coll:
        if s.identifier == key and s.enabled:
            return s
    for s in coll:
        if s.name == key and s.enabled:
            return s
    for s in coll:
        if s.identifier == key or s.name == key:
            return s
    raise KeyError(key)



MAX_DETAIL = 2.0  # noise octaves (see Tree.noise)

class Tree:
    """Tiny node-graph builder: nodes laid out left to right, inputs given as values or sockets."""

    def __init__(self, mat: bpy.types.Material):
        mat.use_nodes = True
        self.nt = mat.node_tree
        self.nt.nodes.clear()
        self.n = 0

    def add(self, type_: str, name: str | None = None, inputs: dict | None = None, **props):
        node = self.nt.nodes.new(type_)
        if name:
            node.name = name
            node.label = name
        for k, v in props.items():
            setattr(node, k, v)
        for k, v in (inputs or {}).items():
            self.set(node, k, v)
        node.location = (200.0 * self.n - 1800.0, 300.0 * (self.n % 2))
        self.n += 1
        return node

    def set(self, node, key, value):
        sock = find_socket(node.inputs, key)
        if isinstance(value, bpy.types.NodeSocket):
            self.nt.links.new(value, sock)
        elif isinstance(value, (tuple, list)):
            n = len(sock.default_value)
            v = list(value)[:n]
            if len(v) < n:
                v += [1.0] * (n - len(v))
            sock.default_value = v
        else:
            sock.default_value = value

    # common nodes -------------------------------------------------------------------------------
    def coords(self, seed=0, scale=(1.0, 1.0, 1.0), rotation=(0.0, 0.0, 0.0), mapping=True):
        """Object-space coordinates (metres), offset by the seed, optionally scaled / rotated."""
        tc = self.add("ShaderNodeTexCoord")
        if not mapping:
            return tc.outputs["Object"]
        m = self.add("ShaderNodeMapping", inputs={"Vector": tc.outputs["Object"], "Location": seed_offset(seed),
                                                  "Scale": scale, "Rotation": rotation})
        return m.outputs["Vector"]

    def noise(self, vec, scale, detail=2.0, roughness=0.5, distortion=0.0, **kw):
        # octaves beyond MAX_DETAIL are sub-pixel at 640x480 from a few metres but cost CPU time
        return self.add("ShaderNodeTexNoise", inputs={"Vector": vec, "Scale": scale, "Detail": min(detail, MAX_DETAIL),
                                                      "Roughness": roughness, "Distortion": distortion}, **kw)

    def ramp(self, fac, stops, interpolation="LINEAR"):
        node = self.add("ShaderNodeValToRGB", inputs={"Fac": fac})
        cr = node.color_ramp
        cr.interpolation = interpolation
        stops = sorted(stops, key=lambda s: s[0])
        els = cr.elements
        while len(els) > 1:
            els.remove(els[-1])
        els[0].position = stops[0][0]
        els[0].color = (*stops[0][1][:3], 1.0)
        for pos, col in stops[1:]:
            e = els.new(pos)
            e.color = (*col[:3], 1.0)
        return node.outputs["Color"]

    def mix(self, fac, a, b, blend="MIX"):
        node = self.add("ShaderNodeMix", data_type="RGBA", blend_type=blend,
                        inputs={"Factor_Float": fac, "A_Color": a, "B_Color": b})
        return find_socket(node.outputs, "Result_Color")

    def mixf(self, fac, a, b):
        node = self.add("ShaderNodeMix", data_type="FLOAT", inputs={"Factor_Float": fac, "A_Float": a, "B_Float": b})
        return find_socket(node.outputs, "Result_Float")

    def bump(self, height, strength, distance=0.01):
        node = self.add("ShaderNodeBump", inputs={"Height": height, "Strength": strength, "Distance": distance})
        return node.outputs["Normal"]

    def bsdf(self, **inputs):
        node = self.add("ShaderNodeBsdfPrincipled",
                        inputs={k.replace("_", " "): v for k, v in inputs.items()})
        return node.outputs["BSDF"]


def finish(t: Tree, surface, emissive: bool, emit_color: Color):
    if emissive:
        em = t.add("ShaderNodeEmission", name=EMISSION_NODE, inputs={"Color": emit_color, "Strength": 0.0})
        add = t.add("ShaderNodeAddShader")
        t.nt.links.new(surface, add.inputs[0])
        t.nt.links.new(em.outputs["Emission"], add.inputs[1])
        surface = add.outputs["Shader"]
    out = t.add("ShaderNodeOutputMaterial", name="output", target="ALL")
    t.nt.links.new(surface, out.inputs["Surface"])
    out.is_active_output = True


