"""Textured glTF binary (GLB) meshes for both renderers, in our Z-up frame. No Blender here.

``load_glb_parts(path)`` reads a GLB with trimesh (``force="scene"``, so every primitive keeps its
own PBR material) and returns one ``trimesh.Trimesh`` per drawn primitive: the node transforms of
the file's default scene applied, then converted from glTF's Y-up frame to ours with
``synth.scene.geometry.Y_UP_TO_Z_UP`` (C below): a vertex ``v`` becomes ``C M v`` for the node's world
matrix ``M``, a normal ``n`` becomes ``C (M^-1)^T n`` (unit length); a node with a mirroring matrix
(det < 0) gets its triangles' winding reversed, as glTF prescribes. A mesh instanced by several
nodes gives one part per node.

What each part carries
    ``mesh.visual``: a ``trimesh.visual.TextureVisuals`` with ``uv`` (trimesh's convention: origin
    at the image's lower-left, i.e. ``(u, 1 - v_gltf)``, Blender's convention too; ``None`` when the
    primitive has no TEXCOORD_0) and ``material``, a ``trimesh.visual.material.PBRMaterial``
    (``baseColorTexture``/``emissiveTexture``/``metallicRoughnessTexture``/``normalTexture`` as PIL
    images, factors, ``alphaMode``...). The material object is SHARED between the parts (and the
    copies) of one file: treat it as read-only.
    ``mesh.metadata["gltf"]``: ``{"file": <resolved path>, "material": <index of the glTF material,
    -1 for none>, "key": "<file>#<index>", "normals": <the file gave normals>, "node", "name"}``
    plus, when the primitive could be matched to the file's JSON (always, for files trimesh
    reads in order), the exact ``baseColorFactor``/``emissiveFactor`` (the latter times
    KHR_materials_emissive_strength) and ``sources`` (where each texture's encoded image lies).
    A material that cannot be matched gets a negative index (distinct per material).
    ``vertex_normals``: the file's normals when it has them (then ``metadata["gltf"]["normals"]``).
    :func:`pbr` turns a part's visual into plain values with the glTF defaults filled in (exact
    float factors read from the file's JSON: trimesh stores ``baseColorFactor`` as 8-bit).

Texture transforms (``KHR_texture_transform`` on a slot's textureInfo: ``offset``, ``rotation``,
``scale``): recorded per slot in ``metadata["gltf"]["texture_transforms"]`` and ``pbr(mesh)
["texture_transforms"]`` (``{slot: {"offset": [ox, oy], "rotation": r, "scale": [sx, sy],
"texCoord": k or None}}``); the UVs themselves stay untransformed (slots may differ). On glTF UVs
(origin top-left) the transform is ``uv' = T(offset) R(rotation) S(scale) uv`` with
``R = [[cos r, sin r], [-sin r, cos r]]``: counter-clockwise in UV space (u right, v DOWN), as the
extension's text says and as its sample model (TextureTransformTest), Babylon.js and Blender's own
glTF importer (``io_scene_gltf2``, ``texture_transform_gltf_to_blender``) implement it. The GLSL
listing in the extension's README has the transpose of R: a known erratum (KhronosGroup/glTF issue
#1563, "KHR_texture_transform has the wrong rotation matrix"). :func:`uv_transform_matrix` gives
the transform in trimesh's (= Blender's) UV convention, :func:`texture_uv` a part's UVs for one
slot with it applied, :func:`blender_mapping` the values of a Blender Mapping node doing the same,
:func:`sample_base_color` the fast renderer's texture lookup. A bad value is a
``SceneFormatError`` naming the field, e.g.
``materials[0].pbrMetallicRoughness.baseColorTexture.extensions.KHR_texture_transform.scale``.

Not supported (ignored): vertex colours (COLOR_0), texture coordinate sets other than 0 (a slot
whose ``texCoord`` -- its own or the transform's override -- is not 0 is logged once per file and
drawn with TEXCOORD_0), samplers (wrapping is REPEAT, filtering linear), occlusion maps, point and
line primitives, triangle fans, morph targets and skins (the rest pose is used). A normal map under
a rotated transform keeps the mesh's own UV tangents (as Blender's importer does).

Git LFS pointers: a GLB, an external texture or an external buffer that is a Git LFS pointer file
(a small text file starting ``version https://git-lfs.github.com/spec/v1``, what a clone of
ReplicaCAD made without ``git lfs`` holds) is a ``SceneFormatError`` naming the file ("... is a
Git LFS pointer, not the file itself (run git lfs pull)").

Textures that cannot be decoded (KTX2 / KHR_texture_basisu images, or bytes PIL cannot open):
a warning is logged once per file and the material falls back to its ``baseColorFactor`` (and to
its plain factors for the other texture slots). A texture given as an external file that does not
exist is an error (:func:`check_glb`), not a fallback.

A file whose materials make trimesh fail is read again without them (a warning; every primitive
then has glTF's default material). Loads are cached by (path, modification time, size); every
call hands out new ``Trimesh`` objects (copied arrays) that share the cached materials.
"""

from __future__ import annotations

import io
import json
import logging
import struct
import urllib.parse
from collections import OrderedDict
from pathlib import Path

import numpy as np
import trimesh
from trimesh.visual import TextureVisuals
from trimesh.visual.material import PBRMaterial

from vrformats.errors import SceneFormatError
from vrformats.fields import inside_root, listing, shown
from vrformats.yamlfile import check_shape
from vrformats.color import srgb_decode
from vrformats.lfs import LFS_HINT, LFS_POINTER_PREFIX, is_lfs_pointer  # noqa: F401 - re-exported for readers

from ..scene.geometry import Y_UP_TO_Z_UP

log = logging.getLogger(__name__)

C = Y_UP_TO_Z_UP

_GLB_MAGIC = b"glTF"
_CHUNK_JSON = 0x4E4F534A
_CHUNK_BIN = 0x004E4942
_TRIANGLE_MODES = (4, 5)  # TRIANGLES, TRIANGLE_STRIP (what trimesh turns into triangles)
_TRIMESH_MODES = (0, 1, 4, 5)  # primitives trimesh makes a geometry of, in file order

_CACHE: OrderedDict[tuple, list[trimesh.Trimesh]] = OrderedDict()
_CACHE_MAX = 128
_WARNED: set[str] = set()

__all__ = ["load_glb_parts", "glb_geometry", "check_glb", "pbr", "is_emissive", "submesh", "read_image_source",
           "clear_cache", "is_lfs_pointer", "uv_transform_matrix", "texture_uv", "blender_mapping",
           "sample_base_color", "srgb_to_linear", "TEXTURE_TRANSFORM", "LFS_HINT"]

TEXTURE_TRANSFORM = "KHR_texture_transform"


# --------------------------------------------------------------------------------------------
# the GLB container


def _read_container(path: Path) -> tuple[dict, bytes | None, int]:
    """(JSON document, BIN chunk or None, file offset of the BIN chunk's data);
    SceneFormatError(path, None, "cannot read GLB: ...")."""
    try:
        data = path.read_bytes()
    except OSError as e:
        raise SceneFormatError(path, None, f"cannot read GLB: {e.strerror or e}") from None

    def bad(msg):
        raise SceneFormatError(path, None, f"cannot read GLB: {msg}")

    if is_lfs_pointer(data):
        bad(LFS_HINT)
    if data[:4] != _GLB_MAGIC:
        bad("not a binary glTF file (no 'glTF' header)")
    if len(data) < 20:
        bad(f"truncated ({len(data)} bytes, not even a header and a chunk header)")
    version, length = struct.unpack_from("<II", data, 4)
    if version != 2:
        bad(f"glTF version {version} (only 2 is supported)")
    if length > len(data):
        bad(f"truncated ({len(data)} of {length} bytes)")
    off, doc, binary, bin_at = 12, None, None, 0
    while off + 8 <= length:
        clen, ctype = struct.unpack_from("<II", data, off)
        chunk = data[off + 8: off + 8 + clen]
        if len(chunk) != clen:
            bad("truncated chunk")
        if ctype == _CHUNK_JSON and doc is None:
            try:
                doc = json.loads(chunk.decode("utf-8"))
            except (UnicodeDecodeError, ValueError) as e:
                bad(f"malformed JSON chunk: {e}")
            except RecursionError:
                bad("JSON chunk nested too deeply")
            check_shape(path, doc)  # the bounds of every reader (vrformats.yamlfile)
        elif ctype == _CHUNK_BIN and binary is None:
            binary, bin_at = chunk, off + 8
        off += 8 + clen + (-clen % 4)
    if not isinstance(doc, dict):
        bad("no JSON chunk")
    return doc, binary, bin_at


def _external(path: Path, uri: str, field: str = "images[].uri") -> Path | None:
    """The file an external URI names (relative to the GLB's folder); None for a data: URI.
    SceneFormatError naming the GLB and ``field`` for a URI with a scheme or outside the GLB's
    dataset folder (``owning_root``; ``vrformats.fields.inside_root``)."""
    if uri.startswith("data:"):
        return None
    if "://" in uri:
        raise SceneFormatError(path, field, f"URIs with a scheme are not read: {shown(uri)}")
    from .roots import owning_root

    return inside_root(path, field, path.parent / urllib.parse.unquote(uri), owning_root(path))


def check_glb(path) -> dict:
    """Check a GLB before it is loaded; return its JSON document.

    Raises SceneFormatError naming the file for: a file that is not a readable GLB 2.0
    (field None, "cannot read GLB: ...": not a GLB, truncated, a Git LFS pointer "... (run git lfs
    pull)"), an external image or buffer whose file does not exist or is a Git LFS pointer (field
    ``images[i].uri`` / ``buffers[i].uri``, "texture not found: <file>" / "buffer not found:
    <file>" / "texture <file> is a Git LFS pointer ..."), a malformed ``KHR_texture_transform``
    (its field), and a file without any triangle primitive ("GLB has no triangles")."""
    return _check(Path(path))[0]


def _check(path: Path) -> tuple[dict, bytes | None, int]:
    doc, binary, bin_at = _read_container(path)
    for i, img in enumerate(listing(path, doc.get("images", []), "images")):
        if isinstance(img, dict) and isinstance(img.get("uri"), str):
            f = _external(path, img["uri"], f"images[{i}].uri")
            if f is not None and not f.is_file():
                raise SceneFormatError(path, f"images[{i}].uri", f"texture not found: {f}")
            if f is not None and is_lfs_pointer(f):
                raise SceneFormatError(path, f"images[{i}].uri", f"texture {f} {LFS_HINT}")
    for i, buf in enumerate(listing(path, doc.get("buffers", []), "buffers")):
        if isinstance(buf, dict) and isinstance(buf.get("uri"), str):
            f = _external(path, buf["uri"], f"buffers[{i}].uri")
            if f is not None and not f.is_file():
                raise SceneFormatError(path, f"buffers[{i}].uri", f"buffer not found: {f}")
            if f is not None and is_lfs_pointer(f):
                raise SceneFormatError(path, f"buffers[{i}].uri", f"buffer {f} {LFS_HINT}")
    for i in range(len(listing(path, doc.get("materials", []), "materials"))):
        _texture_transforms(path, doc, i)  # a malformed transform is named now, not at render time
    if not any(isinstance(p, dict) and p.get("mode", 4) in _TRIANGLE_MODES
               for m in listing(path, doc.get("meshes", []), "meshes") if isinstance(m, dict) for p in m.get("primitives", [])):
        raise SceneFormatError(path, None, "GLB has no triangles")
    return doc, binary, bin_at


def _image_bytes(path: Path, doc: dict, binary: bytes | None, index: int) -> bytes | None:
    try:
        img = doc["images"][index]
        if "bufferView" in img:
            bv = doc["bufferViews"][img["bufferView"]]
            if bv.get("buffer", 0) != 0 or binary is None:
                return None
            start = bv.get("byteOffset", 0)
            return binary[start: start + bv["byteLength"]]
        uri = img["uri"]
        if uri.startswith("data:"):
            import base64

            return base64.b64decode(uri.split("base64,", 1)[1])
        return _external(path, uri).read_bytes()
    except (KeyError, IndexError, TypeError, ValueError, OSError):
        return None


def _undecodable_textures(path: Path, doc: dict, binary: bytes | None) -> list[str]:
    """Textures used by materials that trimesh/PIL cannot decode (KTX2, basisu, unknown bytes)."""
    import PIL.Image

    bad = []
    textures = doc.get("textures", []) or []
    images = doc.get("images", []) or []
    used = set()
    for mat in doc.get("materials", []) or []:
        if not isinstance(mat, dict):
            continue
        slots = dict(mat.get("pbrMetallicRoughness", {}) or {})
        slots.update({k: mat[k] for k in ("emissiveTexture", "normalTexture") if k in mat})
        for k, v in slots.items():
            if k.endswith("Texture") and isinstance(v, dict) and isinstance(v.get("index"), int):
                used.add(v["index"])
    for t in sorted(used):
        tex = textures[t] if t < len(textures) and isinstance(textures[t], dict) else {}
        src = tex.get("source")
        if src is None:
            webp = (tex.get("extensions") or {}).get("EXT_texture_webp", {})
            src = webp.get("source") if isinstance(webp, dict) else None
        if not isinstance(src, int) or src >= len(images):
            bad.append(f"textures[{t}] (no image source trimesh can read: {', '.join(tex.get('extensions', {})) or 'none'})")
            continue
        img = images[src] if isinstance(images[src], dict) else {}
        if img.get("mimeType") == "image/ktx2" or str(img.get("uri", "")).lower().endswith((".ktx2", ".basis")):
            bad.append(f"images[{src}] (KTX2/basis)")
            continue
        blob = _image_bytes(path, doc, binary, src)
        try:
            PIL.Image.open(io.BytesIO(blob or b"")).size  # header only: cheap
        except Exception:  # noqa: BLE001 - PIL raises many types
            bad.append(f"images[{src}] (cannot be decoded)")
    return bad


# --------------------------------------------------------------------------------------------
# loading


class _Resolver(trimesh.resolvers.FilePathResolver):
    """External files of a GLB: URIs percent-decoded, relative to the GLB's folder (``..`` allowed)."""

    def get(self, name: str) -> bytes:
        return (Path(self.parent) / urllib.parse.unquote(name.strip())).read_bytes()


def _primitive_table(doc: dict) -> list[tuple[int, int, dict]]:
    """(mesh index, primitive index, primitive) of every primitive trimesh makes a geometry of, in
    the order trimesh adds them to ``scene.geometry``."""
    out = []
    for mi, m in enumerate(doc.get("meshes", []) or []):
        for pi, p in enumerate(m.get("primitives", []) or []):
            if p.get("mode", 4) in _TRIMESH_MODES:
                out.append((mi, pi, p))
    return out


def _expected_faces(doc: dict, prim: dict) -> int | None:
    try:
        if prim.get("mode", 4) != 4:
            return None
        acc = doc["accessors"][prim["indices"] if "indices" in prim else prim["attributes"]["POSITION"]]
        return int(acc["count"]) // 3
    except (KeyError, IndexError, TypeError, ValueError):
        return None


_SLOTS = {"baseColorTexture": ("pbrMetallicRoughness", "baseColorTexture"),
          "metallicRoughnessTexture": ("pbrMetallicRoughness", "metallicRoughnessTexture"),
          "emissiveTexture": (None, "emissiveTexture"), "normalTexture": (None, "normalTexture")}
_SUFFIX = {"image/png": ".png", "image/jpeg": ".jpg", "image/webp": ".webp"}


def _image_sources(path: Path, doc: dict, bin_at: int, index: int) -> dict:
    """Where the encoded image of each texture slot of glTF material ``index`` lies: ``{slot:
    {"file", "offset", "length", "suffix"}}`` (slots with a plain PNG/JPEG/WebP image only)."""
    out = {}
    try:
        mat = doc["materials"][index]
    except (KeyError, IndexError, TypeError):
        return out
    for slot, (group, key) in _SLOTS.items():
        try:
            ref = (mat.get(group, {}) if group else mat)[key]
            src = doc["textures"][ref["index"]]["source"]
            img = doc["images"][src]
            if "bufferView" in img:
                bv = doc["bufferViews"][img["bufferView"]]
                suffix = _SUFFIX.get(img.get("mimeType", ""))
                if bv.get("buffer", 0) != 0 or suffix is None or bin_at == 0:
                    continue
                out[slot] = {"file": str(path.resolve()), "offset": bin_at + int(bv.get("byteOffset", 0)),
                             "length": int(bv["byteLength"]), "suffix": suffix}
            elif isinstance(img.get("uri"), str) and not img["uri"].startswith("data:"):
                f = _external(path, img["uri"])
                suffix = f.suffix.lower()
                if suffix in (".png", ".jpg", ".jpeg", ".webp"):
                    out[slot] = {"file": str(f.resolve()), "offset": 0, "length": -1, "suffix": suffix}
        except (KeyError, IndexError, TypeError, ValueError, AttributeError):
            continue
    return out


def read_image_source(source: dict) -> bytes:
    """The encoded bytes of an image source (``pbr(mesh)["sources"][slot]``)."""
    with open(source["file"], "rb") as f:
        f.seek(source["offset"])
        return f.read() if source["length"] < 0 else f.read(source["length"])


def _exact_material(doc: dict, index: int) -> dict:
    """Float factors of glTF material ``index`` as written in the file (glTF defaults filled in)."""
    try:
        mat = doc["materials"][index]
    except (KeyError, IndexError, TypeError):
        return {}
    pmr = mat.get("pbrMetallicRoughness", {}) or {}
    out = {"baseColorFactor": [float(x) for x in pmr.get("baseColorFactor", [1.0, 1.0, 1.0, 1.0])]}
    strength = ((mat.get("extensions") or {}).get("KHR_materials_emissive_strength") or {}).get("emissiveStrength", 1.0)
    out["emissiveFactor"] = [float(x) * float(strength) for x in mat.get("emissiveFactor", [0.0, 0.0, 0.0])]
    return out


def _slot_infos(mat) -> dict:
    """``{slot: textureInfo}`` of a glTF material's texture slots that are JSON objects."""
    out = {}
    if not isinstance(mat, dict):
        return out
    for slot, (group, key) in _SLOTS.items():
        holder = mat.get(group) if group else mat
        info = holder.get(key) if isinstance(holder, dict) else None
        if isinstance(info, dict):
            out[slot] = info
    return out


def _material(doc: dict, index: int):
    """glTF material ``index`` of ``doc``, or None when there is no such material."""
    try:
        return doc["materials"][index]
    except (KeyError, IndexError, TypeError):
        return None


def _texture_transforms(path: Path, doc: dict, index: int) -> dict:
    """``{slot: {"offset", "rotation", "scale", "texCoord"}}``: the ``KHR_texture_transform`` of each
    texture slot of glTF material ``index`` that has one, glTF defaults filled in (``texCoord`` None
    when the extension does not override the slot's). SceneFormatError naming the field for bad values."""
    from vrformats.fields import integer, mapping, number, numbers

    mat = _material(doc, index)
    if mat is None:
        return {}
    out = {}
    for slot, info in _slot_infos(mat).items():
        ext = info.get("extensions")
        if not isinstance(ext, dict) or TEXTURE_TRANSFORM not in ext:
            continue
        group, key = _SLOTS[slot]
        field = f"materials[{index}].{group + '.' if group else ''}{key}.extensions.{TEXTURE_TRANSFORM}"
        t = mapping(path, ext[TEXTURE_TRANSFORM], field)
        offset = numbers(path, t["offset"], field + ".offset", 2) if "offset" in t else np.zeros(2)
        rotation = number(path, t["rotation"], field + ".rotation") if "rotation" in t else 0.0
        scale = numbers(path, t["scale"], field + ".scale", 2) if "scale" in t else np.ones(2)
        tc = t.get("texCoord")
        if tc is not None:
            integer(path, tc, field + ".texCoord", lo=0)
        out[slot] = {"offset": [float(x) for x in offset], "rotation": float(rotation),
                     "scale": [float(x) for x in scale], "texCoord": tc}
    return out


def _other_texcoord_sets(doc: dict, index: int, transforms: dict) -> dict:
    """``{slot: set}`` of the slots of material ``index`` that sample a texture coordinate set other
    than 0 (the transform's ``texCoord`` overrides the slot's own)."""
    mat = _material(doc, index)
    if mat is None:
        return {}
    out = {}
    for slot, info in _slot_infos(mat).items():
        tc = (transforms.get(slot) or {}).get("texCoord")
        tc = info.get("texCoord", 0) if tc is None else tc
        if tc not in (0, None):
            out[slot] = tc
    return out


def _load(path: Path) -> list[trimesh.Trimesh]:
    doc, binary, bin_at = _check(path)
    bad = _undecodable_textures(path, doc, binary)
    if bad and str(path) not in _WARNED:
        _WARNED.add(str(path))
        log.warning("%s: texture(s) cannot be decoded, using the materials' factors instead (baseColorFactor "
                    "for the base colour): %s", path, "; ".join(bad))
    scene, err = None, None
    for kwargs in ({}, {"skip_materials": True}):  # materials that break trimesh: geometry, default material
        try:
            scene = trimesh.load(str(path), file_type="glb", force="scene", process=False,
                                 resolver=_Resolver(path.parent), **kwargs)
            break
        except Exception as e:  # noqa: BLE001 - trimesh raises many types for broken files
            err = e
    if scene is None:
        raise SceneFormatError(path, None, f"cannot read GLB: {err}") from None
    if err is not None:
        log.warning("%s: materials cannot be read (%s); drawn with glTF's default material", path, err)

    # geometry name -> glTF primitive (trimesh adds them in file order); verified by face counts
    names = list(scene.geometry)
    table = _primitive_table(doc)
    prim_of: dict[str, dict] = {}
    if len(table) == len(names):
        ok = True
        for name, (_, _, p) in zip(names, table):
            g = scene.geometry[name]
            n = _expected_faces(doc, p)
            if n is not None and (not isinstance(g, trimesh.Trimesh) or len(g.faces) != n):
                ok = False
                break
        if ok:
            prim_of = {name: p for name, (_, _, p) in zip(names, table)}

    # material identity: the glTF index when known, else order of first appearance (negative)
    mat_index: dict[int, int] = {}
    exact: dict[int, dict] = {}
    for name in names:
        g = scene.geometry[name]
        m = getattr(getattr(g, "visual", None), "material", None)
        if m is None or id(m) in mat_index:
            continue
        p = prim_of.get(name)
        if p is not None and isinstance(p.get("material"), int):
            mat_index[id(m)] = p["material"]
            exact[id(m)] = _exact_material(doc, p["material"])
            exact[id(m)]["sources"] = _image_sources(path, doc, bin_at, p["material"])
            tt = _texture_transforms(path, doc, p["material"])
            exact[id(m)]["texture_transforms"] = tt
            sets = _other_texcoord_sets(doc, p["material"], tt)
            if sets and f"{path}#texCoord" not in _WARNED:
                _WARNED.add(f"{path}#texCoord")
                log.warning("%s: materials[%d] samples texture coordinate set(s) other than 0 (%s); only "
                            "TEXCOORD_0 is read, so those textures are drawn with it", path, p["material"],
                            ", ".join(f"{k}: {v}" for k, v in sets.items()))
        else:
            mat_index[id(m)] = -2 - len(mat_index)
    default_mat = None

    resolved = str(path.resolve())
    parts = []
    for node in scene.graph.nodes_geometry:
        M, gname = scene.graph[node]
        g = scene.geometry.get(gname)
        if not isinstance(g, trimesh.Trimesh) or len(g.faces) == 0:
            continue
        A = np.eye(4)
        A[:3, :3] = C
        W = A @ np.asarray(M, dtype=np.float64)
        v = np.asarray(g.vertices, dtype=np.float64) @ W[:3, :3].T + W[:3, 3]
        f = np.asarray(g.faces, dtype=np.int64)
        if np.linalg.det(W[:3, :3]) < 0:
            f = f[:, ::-1]
        p = prim_of.get(gname)
        has_normals = ("NORMAL" in p.get("attributes", {})) if p is not None else ("vertex_normals" in g._cache)
        normals = None
        if has_normals:
            N = np.linalg.inv(W[:3, :3]).T
            normals = np.asarray(g.vertex_normals, dtype=np.float64) @ N.T
            ln = np.linalg.norm(normals, axis=1, keepdims=True)
            normals = np.divide(normals, ln, out=np.zeros_like(normals), where=ln > 0)
        vis = g.visual
        mat = getattr(vis, "material", None)
        if isinstance(vis, TextureVisuals) and isinstance(mat, PBRMaterial):
            uv = None if vis.uv is None else np.asarray(vis.uv, dtype=np.float64)
            index = mat_index[id(mat)]
        else:  # no material: glTF's default material (white, metallic 1, roughness 1)
            if default_mat is None:
                default_mat = PBRMaterial(name="gltf_default", baseColorFactor=[1.0, 1.0, 1.0, 1.0],
                                          metallicFactor=1.0, roughnessFactor=1.0)
            mat, uv, index = default_mat, None, -1
        meta = {"file": resolved, "material": index, "key": f"{resolved}#{index}", "normals": normals is not None,
                "name": str(gname), "node": str(node)}
        if index >= 0:
            meta.update({k: v for k, v in exact.get(id(mat), {}).items()})
        parts.append(make_part(v, f, uv, mat, normals, meta))
    if not parts:
        raise SceneFormatError(path, None, "GLB has no triangles")
    return parts


def make_part(v, f, uv, material, normals, meta) -> trimesh.Trimesh:
    m = trimesh.Trimesh(vertices=v, faces=f, process=False, validate=False)
    m.visual = TextureVisuals(uv=uv, material=material)
    if normals is not None:
        m.vertex_normals = normals
    m.metadata["gltf"] = dict(meta)
    return m


def _copy(m: trimesh.Trimesh) -> trimesh.Trimesh:
    """A copy with its own arrays, sharing the (read-only) material."""
    meta = m.metadata["gltf"]
    uv = None if m.visual.uv is None else np.array(m.visual.uv)
    normals = np.array(m.vertex_normals) if meta["normals"] else None
    return make_part(np.array(m.vertices), np.array(m.faces), uv, m.visual.material, normals, meta)


def _cached(path: Path) -> list[trimesh.Trimesh]:
    path = Path(path)
    try:
        st = path.stat()
    except OSError:
        raise SceneFormatError(path, None, "GLB not found") from None
    key = (str(path.resolve()), st.st_mtime_ns, st.st_size)
    parts = _CACHE.get(key)
    if parts is None:
        parts = _load(path)
        while len(_CACHE) >= _CACHE_MAX:
            _CACHE.popitem(last=False)
        _CACHE[key] = parts
    else:
        _CACHE.move_to_end(key)
    return parts


def load_glb_parts(path) -> list[trimesh.Trimesh]:
    """One Trimesh per drawn primitive of the GLB, in our Z-up frame, node transforms applied,
    each with its glTF material (see the module docstring). New objects on every call."""
    return [_copy(m) for m in _cached(Path(path))]


def glb_geometry(path) -> trimesh.Trimesh:
    """All triangles of the GLB concatenated, Z-up, node transforms applied, without materials
    (plain vertices and faces; a new object on every call)."""
    parts = _cached(Path(path))
    verts, faces, off = [], [], 0
    for m in parts:
        verts.append(np.asarray(m.vertices))
        faces.append(np.asarray(m.faces) + off)
        off += len(m.vertices)
    return trimesh.Trimesh(vertices=np.concatenate(verts), faces=np.concatenate(faces), process=False)


def submesh(mesh: trimesh.Trimesh, faces) -> trimesh.Trimesh:
    """The part of a ``load_glb_parts`` mesh made of the triangles ``faces`` (indices): only the
    vertices they use, with their UVs and normals, the same (shared) material and metadata."""
    faces = np.asarray(faces, dtype=np.int64)
    f = np.asarray(mesh.faces)[faces]
    used, inverse = np.unique(f.ravel(), return_inverse=True)
    meta = mesh.metadata["gltf"]
    uv = None if mesh.visual.uv is None else np.asarray(mesh.visual.uv)[used]
    normals = np.asarray(mesh.vertex_normals)[used] if meta["normals"] else None
    return make_part(np.asarray(mesh.vertices)[used], inverse.reshape(-1, 3), uv, mesh.visual.material, normals, meta)


def clear_cache() -> None:
    _CACHE.clear()
    _IMAGE_ARRAYS.clear()


# --------------------------------------------------------------------------------------------
# material values for the renderers


def _factor(v, n: int, default) -> list[float]:
    if v is None:
        return list(default)
    a = np.asarray(v, dtype=np.float64).ravel()
    if a.dtype.kind in "iu":
        a = a / 255.0  # trimesh keeps baseColorFactor as 8-bit RGBA
    out = list(a[:n]) + list(default[len(a[:n]):])
    return [float(x) for x in out[:n]]


def pbr(mesh: trimesh.Trimesh) -> dict:
    """The glTF material of a part as plain values, glTF defaults filled in:

    ``key`` (``"<file>#<material index>"``), ``base_color`` (linear RGBA factor), ``base_color_texture``
    (PIL image or None, sRGB), ``metallic``, ``roughness`` (factors), ``metallic_roughness_texture``
    (PIL or None; roughness in G, metallic in B, linear), ``emissive`` (linear RGB factor),
    ``emissive_texture`` (PIL or None, sRGB), ``normal_texture`` (PIL or None), ``sources``
    (``{"baseColorTexture" | "metallicRoughnessTexture" | "emissiveTexture" | "normalTexture":
    where the texture's encoded PNG/JPEG/WebP bytes lie in the file}``, for slots that have a
    decodable texture; read them with :func:`read_image_source`), ``texture_transforms`` (``{slot:
    {"offset", "rotation", "scale", "texCoord"}}``: the ``KHR_texture_transform`` of the slots that
    have a texture and one; see the module docstring), ``alpha_mode`` ("OPAQUE", "MASK" or "BLEND"),
    ``alpha_cutoff``, ``has_uv``."""
    meta = mesh.metadata.get("gltf", {})
    vis = mesh.visual
    m = getattr(vis, "material", None)
    if not isinstance(m, PBRMaterial):
        m = PBRMaterial()
    base = meta.get("baseColorFactor") or _factor(m.baseColorFactor, 4, (1.0, 1.0, 1.0, 1.0))
    emissive = meta.get("emissiveFactor") or _factor(m.emissiveFactor, 3, (0.0, 0.0, 0.0))
    mode = (m.alphaMode or "OPAQUE").upper()
    return {
        "key": meta.get("key", f"mem:{id(m)}"),
        "base_color": [float(x) for x in base],
        "base_color_texture": m.baseColorTexture,
        "metallic": 1.0 if m.metallicFactor is None else float(m.metallicFactor),
        "roughness": 1.0 if m.roughnessFactor is None else float(m.roughnessFactor),
        "metallic_roughness_texture": m.metallicRoughnessTexture,
        "emissive": [float(x) for x in emissive],
        "emissive_texture": m.emissiveTexture,
        "normal_texture": m.normalTexture,
        "sources": {k: v for k, v in meta.get("sources", {}).items() if getattr(m, k, None) is not None},
        "texture_transforms": {k: dict(v) for k, v in meta.get("texture_transforms", {}).items()
                               if getattr(m, k, None) is not None},
        "alpha_mode": mode if mode in ("OPAQUE", "MASK", "BLEND") else "OPAQUE",
        "alpha_cutoff": 0.5 if m.alphaCutoff is None else float(m.alphaCutoff),
        "has_uv": getattr(vis, "uv", None) is not None,
    }


def is_emissive(mesh: trimesh.Trimesh) -> bool:
    """The part's glTF material emits light (an emissive factor above zero)."""
    return max(pbr(mesh)["emissive"]) > 0.0


# --------------------------------------------------------------------------------------------
# texture transforms (KHR_texture_transform) and the texture lookup of the fast renderer

_FLIP_V = np.array([[1.0, 0.0, 0.0], [0.0, -1.0, 1.0], [0.0, 0.0, 1.0]])  # glTF UV <-> trimesh UV: (u, 1 - v)


def uv_transform_matrix(transform: dict | None, convention: str = "trimesh") -> np.ndarray:
    """3x3 homogeneous matrix of a texture transform (``pbr(mesh)["texture_transforms"][slot]``;
    None: identity) acting on column vectors ``(u, v, 1)``.

    ``convention="gltf"``: glTF UVs (origin top-left, v down), ``T(offset) R(rotation) S(scale)``
    with ``R = [[cos, sin], [-sin, cos]]`` (see the module docstring for the erratum of the
    extension's GLSL listing). ``"trimesh"`` (the default): the same transform on trimesh's / Blender's
    UVs (origin bottom-left, ``(u, 1 - v_gltf)``), i.e. ``F M F`` with ``F: (u, v) -> (u, 1 - v)``."""
    if transform is None:
        return np.eye(3)
    ox, oy = (float(x) for x in transform.get("offset", (0.0, 0.0)))
    sx, sy = (float(x) for x in transform.get("scale", (1.0, 1.0)))
    r = float(transform.get("rotation", 0.0))
    c, s = np.cos(r), np.sin(r)
    T = np.array([[1.0, 0.0, ox], [0.0, 1.0, oy], [0.0, 0.0, 1.0]])
    R = np.array([[c, s, 0.0], [-s, c, 0.0], [0.0, 0.0, 1.0]])
    S = np.diag([sx, sy, 1.0])
    M = T @ R @ S
    if convention == "gltf":
        return M
    if convention != "trimesh":
        raise ValueError(f"convention must be 'gltf' or 'trimesh', got {convention!r}")
    return _FLIP_V @ M @ _FLIP_V


def texture_uv(mesh: trimesh.Trimesh, slot: str = "baseColorTexture") -> np.ndarray | None:
    """The part's UVs (trimesh convention) with the texture transform of ``slot`` applied: the
    coordinates at which that slot's image is sampled (an affine map, so transforming the vertices'
    UVs and interpolating is exact). None when the part has no UVs."""
    uv = getattr(mesh.visual, "uv", None)
    if uv is None:
        return None
    uv = np.asarray(uv, dtype=np.float64)
    t = mesh.metadata.get("gltf", {}).get("texture_transforms", {}).get(slot)
    if t is None:
        return uv.copy()
    M = uv_transform_matrix(t)
    return uv @ M[:2, :2].T + M[:2, 2]


def blender_mapping(transform: dict) -> dict:
    """Inputs of a Blender Mapping node (``vector_type`` "POINT": ``out = Location + Rz(Rotation)
    (Scale * in)``, Rz counter-clockwise) placed between the UV map and an Image Texture node, that
    apply a texture transform on Blender's UVs: ``{"location": (x, y, 0), "rotation": (0, 0, r),
    "scale": (sx, sy, 1)}``. The same values as Blender's own glTF importer
    (``texture_transform_gltf_to_blender``); equal to :func:`uv_transform_matrix` (tested)."""
    ox, oy = (float(x) for x in transform.get("offset", (0.0, 0.0)))
    sx, sy = (float(x) for x in transform.get("scale", (1.0, 1.0)))
    r = float(transform.get("rotation", 0.0))
    return {"location": (ox + sy * np.sin(r), 1.0 - oy - sy * np.cos(r), 0.0), "rotation": (0.0, 0.0, r),
            "scale": (sx, sy, 1.0)}


srgb_to_linear = srgb_decode  # sRGB-encoded values in 0..1 to linear: the one curve, vrformats.color


_IMAGE_ARRAYS: OrderedDict[int, tuple] = OrderedDict()  # id(PIL image) -> (PIL image, linear RGB float32 array)


def _linear_rgb(pil) -> np.ndarray:
    hit = _IMAGE_ARRAYS.get(id(pil))
    if hit is not None and hit[0] is pil:
        _IMAGE_ARRAYS.move_to_end(id(pil))
        return hit[1]
    a = np.asarray(pil.convert("RGB"), dtype=np.uint8)
    lut = srgb_to_linear(np.arange(256) / 255.0).astype(np.float32)
    arr = lut[a]
    while len(_IMAGE_ARRAYS) >= 32:
        _IMAGE_ARRAYS.popitem(last=False)
    _IMAGE_ARRAYS[id(pil)] = (pil, arr)
    return arr


def _bilinear_repeat(img: np.ndarray, uv: np.ndarray) -> np.ndarray:
    """Bilinear lookup with REPEAT wrapping of an image (rows from the top) at trimesh-convention UVs
    (origin bottom-left; texel centres at half-integers, as in OpenGL and Cycles)."""
    h, w = img.shape[:2]
    x = uv[:, 0] * w - 0.5
    y = (1.0 - uv[:, 1]) * h - 0.5
    x0, y0 = np.floor(x), np.floor(y)
    fx, fy = (x - x0)[:, None], (y - y0)[:, None]
    x0, y0 = x0.astype(np.int64), y0.astype(np.int64)
    x1, y1 = (x0 + 1) % w, (y0 + 1) % h
    x0, y0 = x0 % w, y0 % h
    top = img[y0, x0] * (1 - fx) + img[y0, x1] * fx
    bot = img[y1, x0] * (1 - fx) + img[y1, x1] * fx
    return top * (1 - fy) + bot * fy


def sample_base_color(mesh: trimesh.Trimesh, faces, bary) -> np.ndarray:
    """Linear RGB base colour of a ``load_glb_parts`` part at points on its triangles: ``faces``
    (N triangle indices) and ``bary`` (N x 3 barycentric weights of the triangle's three corners).
    The base colour texture (sRGB, decoded to linear) sampled bilinearly with REPEAT wrapping at
    the UVs with the slot's ``KHR_texture_transform`` applied, times ``baseColorFactor``; the factor
    alone without a decodable texture or UVs. Unlit albedo, not shading."""
    params = pbr(mesh)
    factor = np.asarray(params["base_color"][:3], dtype=np.float64)
    faces = np.asarray(faces, dtype=np.int64)
    n = len(faces)
    tex = params["base_color_texture"]
    uv = texture_uv(mesh, "baseColorTexture") if tex is not None else None
    if uv is None or n == 0:
        return np.tile(factor, (n, 1))
    try:
        img = _linear_rgb(tex)
    except Exception:  # noqa: BLE001 - undecodable: the factor alone (as in Blender)
        return np.tile(factor, (n, 1))
    corners = np.asarray(mesh.faces, dtype=np.int64)[faces]  # N x 3
    b = np.asarray(bary, dtype=np.float64)
    at = np.einsum("nk,nkj->nj", b, uv[corners])
    return _bilinear_repeat(img, at) * factor
