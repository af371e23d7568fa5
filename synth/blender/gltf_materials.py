"""glTF PBR materials for mesh assets (ReplicaCAD): a Principled BSDF per glTF material.

:func:`get_gltf_material` builds a Principled BSDF from a part's glTF PBR material
(``synth.mesh.gltf.pbr``), once per (glTF file, material index) and emission key:

* base colour = ``baseColorTexture`` (sRGB image, UV map "UVMap", linear filtering, repeat)
  x ``baseColorFactor``; alpha = texture alpha x factor alpha for ``alphaMode`` BLEND, the same
  thresholded at ``alphaCutoff`` for MASK, 1 for OPAQUE (depth and ids ignore alpha: a transparent
  primitive is a surface in the geometry pass and in the fast renderer);
* metallic / roughness = factors x ``metallicRoughnessTexture`` B / G (non-colour data);
* ``normalTexture``: a tangent-space Normal Map node on "UVMap" (strength 1: trimesh does not keep
  the glTF ``scale``);
* emission (``emissiveFactor`` > 0): an Emission node named ``"emission"`` (strength 0 = off, set by
  the lighting like the lamp shades') whose colour is ``emissiveTexture`` (sRGB) x
  ``emissiveFactor`` x the colour of an RGB node named ``"emission_light"`` (the light's colour,
  white by default; :func:`set_emission` and the scene builder set it);
* ``KHR_texture_transform`` of a slot (``params["texture_transforms"]``): a UV Map node ("UVMap")
  and a Mapping node (POINT, values from ``synth.mesh.gltf.blender_mapping``, as Blender's own glTF
  importer sets them) feed that slot's Image Texture node;
* occlusion maps, vertex colours and samplers are ignored; IOR 1.5 (glTF's).

PIL images become Blender images once per process (saved as PNG to a temporary file, loaded,
packed, the file removed). An image that PIL cannot decode is logged once and left out (the
factor alone then gives the colour).
"""

from __future__ import annotations

import logging
import os
import tempfile
from pathlib import Path

from . import require_python

require_python()  # before bpy: one line, not "No module named bpy", on another Python
import bpy  # noqa: E402

from .shading import CACHES, EMISSION_LIGHT_NODE, Tree, finish, is_alive

__all__ = ["get_gltf_material"]

log = logging.getLogger(__name__)
_GLTF_CACHE: dict[tuple, bpy.types.Material] = {}
_IMAGES: dict[tuple, tuple] = {}  # (id(PIL image), colour space) -> (PIL image, bpy image or None)
_BAD_IMAGES: set[int] = set()
CACHES.extend([_GLTF_CACHE, _IMAGES])


def _load_packed(suffix: str, write) -> bpy.types.Image:
    """A Blender image packed into the .blend from a temporary file that ``write(path)`` fills
    (Blender loads images from files only); the file is removed again."""
    fd, path = tempfile.mkstemp(prefix="synth_gltf_", suffix=suffix)
    os.close(fd)
    try:
        write(path)
        img = bpy.data.images.load(path)
        img.pack()
    finally:
        os.remove(path)
    return img


def _bpy_image(pil, colorspace: str, label: str, source: dict | None = None):
    """A packed Blender image (once per image and colour space), or None.

    With ``source`` (``synth.mesh.gltf.pbr(...)["sources"][slot]``) the file's own encoded bytes are
    loaded as they are (no re-encoding); otherwise the PIL image is saved as PNG first."""
    if pil is None:
        return None
    if source is not None:
        ck = ("src", source["file"], source["offset"], colorspace)
        hit = _IMAGES.get(ck)
        if hit is not None:
            try:
                if bpy.data.images.get(hit[1].name) == hit[1]:
                    return hit[1]
            except ReferenceError:
                pass
        try:
            from ..mesh.gltf import read_image_source

            blob = read_image_source(source)
            img = _load_packed(source["suffix"], lambda path: Path(path).write_bytes(blob))
            img.name = label
            img.colorspace_settings.name = colorspace
            _IMAGES[ck] = (None, img)
            return img
        except (OSError, RuntimeError) as e:  # fall back to the decoded PIL image
            log.warning("texture %s: cannot load the file's image bytes (%s); re-encoding it", label, e)
    ck = (id(pil), colorspace)
    hit = _IMAGES.get(ck)
    if hit is not None and hit[0] is pil:
        img = hit[1]
        try:
            if img is None or bpy.data.images.get(img.name) == img:
                return img
        except ReferenceError:
            pass
    img = None
    try:
        mode = "RGBA" if (pil.mode in ("RGBA", "LA", "PA") or "transparency" in pil.info) else "RGB"
        im = pil.convert(mode)
        img = _load_packed(".png", lambda path: im.save(path, format="PNG", compress_level=1))
        img.name = label
        img.colorspace_settings.name = colorspace
    except Exception as e:  # noqa: BLE001 - PIL raises many types for undecodable data
        if id(pil) not in _BAD_IMAGES:
            _BAD_IMAGES.add(id(pil))
            log.warning("texture %s cannot be decoded (%s); using the material's factor instead", label, e)
        img = None
    _IMAGES[ck] = (pil, img)
    return img


def get_gltf_material(params: dict, emissive: bool = False, key: str | None = None) -> bpy.types.Material:
    """The Cycles material of a glTF PBR material (``params`` = ``synth.mesh.gltf.pbr(mesh)``).

    Built once per (``params["key"]``, emissive, ``key``); ``key`` (the light fixture) gives an
    emitter a material of its own. The "emission" node exists when ``emissive`` is true (and the
    material has an emissive factor); its strength starts at 0."""
    emissive = bool(emissive) and max(params["emissive"]) > 0.0
    ck = (params["key"], emissive, None if key is None else str(key))
    mat = _GLTF_CACHE.get(ck)
    if mat is not None and is_alive(mat):
        return mat
    mat = _build_gltf(params, emissive, ck[2])
    _GLTF_CACHE[ck] = mat
    return mat


def _build_gltf(params: dict, emissive: bool, key: str | None) -> bpy.types.Material:
    name = "gltf:" + os.path.basename(params["key"])
    mat = bpy.data.materials.new(name if key is None else f"{name}@{key}")
    t = Tree(mat)
    uv = params.get("has_uv", False)
    label = os.path.basename(params["key"])

    sources = params.get("sources", {})
    transforms = params.get("texture_transforms", {})

    def tex(pil, colorspace, what):
        img = _bpy_image(pil, colorspace, f"{label}:{what}", sources.get(what + "Texture")) if uv else None
        if img is None:
            return None
        node = t.add("ShaderNodeTexImage", image=img, interpolation="Linear", extension="REPEAT")
        tt = transforms.get(what + "Texture")
        if tt is not None:  # KHR_texture_transform: UV map -> Mapping -> this image
            from ..mesh.gltf import blender_mapping

            m = blender_mapping(tt)
            uvmap = t.add("ShaderNodeUVMap", uv_map="UVMap")
            mapping = t.add("ShaderNodeMapping", name=f"uv_transform:{what}", vector_type="POINT",
                            inputs={"Vector": uvmap.outputs["UV"], "Location": m["location"],
                                    "Rotation": m["rotation"], "Scale": m["scale"]})
            t.nt.links.new(mapping.outputs["Vector"], node.inputs["Vector"])
        return node

    bc = params["base_color"]
    base_tex = tex(params["base_color_texture"], "sRGB", "baseColor")
    color = bc[:3]
    if base_tex is not None:
        color = base_tex.outputs["Color"]
        if any(abs(c - 1.0) > 1e-6 for c in bc[:3]):
            color = t.mix(1.0, color, tuple(bc[:3]), blend="MULTIPLY")
    mode = params["alpha_mode"]
    alpha = 1.0
    if mode in ("BLEND", "MASK"):
        alpha = bc[3]
        if base_tex is not None:
            alpha = t.add("ShaderNodeMath", operation="MULTIPLY",
                          inputs={"Value": base_tex.outputs["Alpha"], "Value_001": bc[3]}).outputs[0] if bc[3] != 1.0 else base_tex.outputs["Alpha"]
        if mode == "MASK":
            if isinstance(alpha, float):
                alpha = 1.0 if alpha >= params["alpha_cutoff"] else 0.0
            else:
                alpha = t.add("ShaderNodeMath", operation="GREATER_THAN",
                              inputs={"Value": alpha, "Value_001": params["alpha_cutoff"] - 1e-6}).outputs[0]
    metallic, roughness = params["metallic"], params["roughness"]
    mr_tex = tex(params["metallic_roughness_texture"], "Non-Color", "metallicRoughness")
    if mr_tex is not None:
        sep = t.add("ShaderNodeSeparateColor", inputs={"Color": mr_tex.outputs["Color"]})
        roughness = t.add("ShaderNodeMath", operation="MULTIPLY", inputs={"Value": sep.outputs["Green"], "Value_001": roughness}).outputs[0]
        metallic = t.add("ShaderNodeMath", operation="MULTIPLY", inputs={"Value": sep.outputs["Blue"], "Value_001": metallic}).outputs[0]
    normal = None
    n_tex = tex(params["normal_texture"], "Non-Color", "normal")
    if n_tex is not None:
        normal = t.add("ShaderNodeNormalMap", space="TANGENT", uv_map="UVMap",
                       inputs={"Color": n_tex.outputs["Color"], "Strength": 1.0}).outputs["Normal"]
    inputs = {"Base_Color": color, "Metallic": metallic, "Roughness": roughness, "Alpha": alpha, "IOR": 1.5}
    if normal is not None:
        inputs["Normal"] = normal
    surface = t.bsdf(**inputs)
    if emissive:
        ef = params["emissive"]
        em_tex = tex(params["emissive_texture"], "sRGB", "emissive")
        ecol = tuple(ef)
        if em_tex is not None:
            ecol = t.mix(1.0, em_tex.outputs["Color"], tuple(ef), blend="MULTIPLY")
        light = t.add("ShaderNodeRGB", name=EMISSION_LIGHT_NODE)
        light.outputs[0].default_value = (1.0, 1.0, 1.0, 1.0)
        ecol = t.mix(1.0, ecol, light.outputs[0], blend="MULTIPLY")
    finish(t, surface, emissive, ecol if emissive else None)
    mat.diffuse_color = (*[min(max(c, 0.0), 1.0) for c in bc[:3]], 1.0)
    mat["synth_material"] = "gltf"
    mat["gltf_key"] = params["key"]
    return mat


