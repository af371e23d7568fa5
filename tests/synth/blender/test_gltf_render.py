"""ReplicaCAD meshes with their own glTF materials, in both renderers (synth.mesh.gltf, synth.render.meshes,
synth.blender).

A tiny dataset is built here with trimesh: a box whose baseColorTexture has four coloured
quadrants (its UVs all fall in the red one, so a flipped or swapped UV shows up as another colour),
a box with only a baseColorFactor, an emissive "bulb", and a floor + two walls stage (open above,
so daylight reaches in). Expected values come from the construction (the texture's colour,
linearised by the sRGB formula written out here) and from independent renderers: Open3D ray
casting for depth and ids, and Blender's own glTF importer (io_scene_gltf2) for colour.

Blender runs in subprocesses (render_tour's worker, and one script per module); renders are
80x60 with few samples; those tests carry the ``blender`` marker.
"""

from __future__ import annotations

import json
import os
import struct
import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np
import pytest
from tests.synth.render.test_render import assert_renders_agree, depth_edges  # Blender against the fast renderer, one place
import trimesh
from PIL import Image
from scipy import ndimage
from trimesh.visual import TextureVisuals
from trimesh.visual.material import PBRMaterial

from vrformats.boxes import CEILING_ID_BASE, FLOOR_ID_BASE, WALL_ID_BASE
from vrformats.camera import Intrinsics, pose_from_ypr, write_tum
from vrformats.errors import SceneFormatError
from vrformats.tour import Tour
from synth.scene.classes import class_table
from synth.scene.model import LightFixture, Room, Wall, load_layout, save_layout
from meshes import write_glb

REPO = Path(__file__).resolve().parents[3]
C = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, -1.0], [0.0, 1.0, 0.0]])  # habitat (Y up) -> ours (Z up), by hand
SCENE = "gltf_test"

RED, GREEN, BLUE, YELLOW = (230, 40, 30), (30, 200, 60), (40, 60, 220), (240, 220, 40)  # sRGB 8-bit
PLAIN_FACTOR = (0.05, 0.2, 0.8)  # linear baseColorFactor of the untextured box
BULB_EMISSION = (1.0, 0.8, 0.6)
W, H, HFOV = 80, 60, 70.0


def srgb_to_linear(c) -> np.ndarray:
    c = np.asarray(c, dtype=np.float64) / 255.0
    return np.where(c <= 0.04045, c / 12.92, ((c + 0.055) / 1.055) ** 2.4)


def chroma(rgb) -> np.ndarray:
    rgb = np.asarray(rgb, dtype=np.float64)
    return rgb / rgb.sum()


# ---- the dataset ---------------------------------------------------------------------------------


def quadrant_texture() -> Image.Image:
    """16 x 16: red top-left, green top-right, blue bottom-left, yellow bottom-right (image rows
    from the top, as glTF's UV origin)."""
    a = np.zeros((16, 16, 3), np.uint8)
    a[:8, :8], a[:8, 8:], a[8:, :8], a[8:, 8:] = RED, GREEN, BLUE, YELLOW
    return Image.fromarray(a, "RGB")


def unshared_box(lo, hi) -> trimesh.Trimesh:
    """A box with its own 3 vertices per triangle (so every face can have its own UVs)."""
    lo, hi = np.asarray(lo, float), np.asarray(hi, float)
    b = trimesh.creation.box(extents=hi - lo)
    b.apply_translation((lo + hi) / 2.0)
    return trimesh.Trimesh(b.vertices[b.faces].reshape(-1, 3), np.arange(3 * len(b.faces)).reshape(-1, 3), process=False)


def textured_box() -> trimesh.Trimesh:
    """0.5 m cube standing on habitat y = 0; glTF UVs (origin top-left) in [0.1, 0.4]^2: the red quadrant."""
    m = unshared_box((-0.25, 0.0, -0.25), (0.25, 0.5, 0.25))
    uv_gltf = np.random.default_rng(1).uniform(0.1, 0.4, (len(m.vertices), 2))
    uv = np.column_stack([uv_gltf[:, 0], 1.0 - uv_gltf[:, 1]])  # trimesh keeps UVs with the origin bottom-left
    mat = PBRMaterial(name="textured", baseColorTexture=quadrant_texture(), baseColorFactor=[1.0, 1.0, 1.0, 1.0],
                      metallicFactor=0.0, roughnessFactor=0.6)
    m.visual = TextureVisuals(uv=uv, material=mat)
    return m


def plain_box(size=0.4, factor=PLAIN_FACTOR, emissive=None, name="plain") -> trimesh.Trimesh:
    m = unshared_box((-size / 2, 0.0, -size / 2), (size / 2, size, size / 2))
    kw = {} if emissive is None else {"emissiveFactor": list(emissive)}
    m.visual = TextureVisuals(material=PBRMaterial(name=name, baseColorFactor=[*factor, 1.0], metallicFactor=0.0,
                                                   roughnessFactor=0.5, **kw))
    return m


def stage_meshes() -> list[trimesh.Trimesh]:
    """Floor (top at 0) 6 x 6 m and two walls (north y = 3, west x = -3), 2.5 m, built in OUR frame and
    written in habitat's (v_h = C^T v): no ceiling, so the sky and sun reach in."""
    pieces = [((-3.0, -3.0, -0.1), (3.0, 3.0, 0.0), (0.45, 0.4, 0.35)),  # floor
              ((-3.0, 2.9, 0.0), (3.0, 3.0, 2.5), (0.8, 0.8, 0.8)),  # north wall
              ((-3.0, -3.0, 0.0), (-2.9, 2.9, 2.5), (0.8, 0.8, 0.8))]  # west wall
    out = []
    for k, (lo, hi, col) in enumerate(pieces):
        m = unshared_box(lo, hi)
        m.vertices = m.vertices @ C  # rows: v_h = C^T v
        m.visual = TextureVisuals(material=PBRMaterial(name=f"stage{k}", baseColorFactor=[*col, 1.0],
                                                       metallicFactor=0.0, roughnessFactor=0.9))
        out.append(m)
    return out


def write_json(path: Path, doc) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps(doc, indent=1))


# object instances (habitat frame): translation = the GLB origin (asset_local)
INSTANCES = [
    ("tex_box", (-0.5, 0.0, -0.5)),  # ours: (-0.5, 0.5, 0)
    ("plain_box", (0.6, 0.0, -0.6)),  # ours: (0.6, 0.6, 0)
    ("bulb", (1.5, 1.5, -2.0)),  # ours: (1.5, 2.0, 1.5): next to the fixture added below
    ("bulb", (-2.0, 0.0, 1.5)),  # ours: (-2.0, -1.5, 0): no fixture near
]
FIXTURE_POS = (1.5, 2.0, 2.1)  # 0.6 m above the first bulb's box centre


def make_dataset(root: Path) -> Path:
    write_json(root / "test.scene_dataset_config.json", {})  # the dataset's root holds one (habitat-sim loads it)
    write_glb(root / "stages/stage.glb", stage_meshes())
    write_glb(root / "objects/tex_box.glb", [textured_box()])
    write_glb(root / "objects/plain_box.glb", [plain_box()])
    write_glb(root / "objects/bulb.glb", [plain_box(0.1, (0.9, 0.9, 0.9), BULB_EMISSION, "bulb")])
    write_json(root / "configs/stages/stage.stage_config.json", {"render_asset": "../../stages/stage.glb"})
    for name in ("tex_box", "plain_box", "bulb"):
        write_json(root / f"configs/objects/{name}.object_config.json", {"render_asset": f"../../objects/{name}.glb"})
    write_json(root / f"configs/scenes/{SCENE}.scene_instance.json", {
        "stage_instance": {"template_name": "stages/stage"},
        "translation_origin": "asset_local",
        "object_instances": [{"template_name": f"objects/{n}", "translation": list(t), "rotation": [1, 0, 0, 0],
                              "motion_type": "STATIC"} for n, t in INSTANCES],
    })
    return root


def load_test_layout(root: Path, fixture: bool = True):
    from synth.sources.replicacad.importer import load_replicacad

    lay = load_replicacad(root, SCENE, allow_unknown=True, structure=False)
    if fixture:
        lay.fixtures = [LightFixture("C0", "ceiling", FIXTURE_POS, object=None)]
    return lay


def glb_chunks(path: Path) -> tuple[dict, bytes]:
    """(JSON, BIN) of a GLB, read here by hand (independent of synth.mesh.gltf)."""
    data = path.read_bytes()
    n = struct.unpack_from("<I", data, 12)[0]
    doc = json.loads(data[20:20 + n])
    off = 20 + n
    m = struct.unpack_from("<I", data, off)[0]
    return doc, data[off + 8: off + 8 + m]


def write_glb_chunks(path: Path, doc: dict, binary: bytes) -> None:
    js = json.dumps(doc).encode()
    js += b" " * (-len(js) % 4)
    binary = binary + b"\0" * (-len(binary) % 4)
    body = struct.pack("<II", len(js), 0x4E4F534A) + js + struct.pack("<II", len(binary), 0x004E4942) + binary
    path.write_bytes(b"glTF" + struct.pack("<II", 2, 12 + len(body)) + body)


def accessor(doc: dict, binary: bytes, index: int) -> np.ndarray:
    acc = doc["accessors"][index]
    bv = doc["bufferViews"][acc["bufferView"]]
    width = {"SCALAR": 1, "VEC2": 2, "VEC3": 3, "VEC4": 4}[acc["type"]]
    dtype = {5126: np.float32, 5125: np.uint32, 5123: np.uint16}[acc["componentType"]]
    start = bv.get("byteOffset", 0) + acc.get("byteOffset", 0)
    return np.frombuffer(binary, dtype=dtype, count=acc["count"] * width, offset=start).reshape(acc["count"], width)


CAMERA = dict(position=(0.0, -1.6, 1.1), yaw=np.pi / 2, pitch=-0.35)


def camera_poses() -> np.ndarray:
    return np.stack([pose_from_ypr(CAMERA["position"], yaw=CAMERA["yaw"], pitch=CAMERA["pitch"]),
                     pose_from_ypr((1.2, -1.2, 1.4), yaw=2.0, pitch=-0.45)])


@pytest.fixture(scope="module")
def dataset(tmp_path_factory) -> Path:
    return make_dataset(tmp_path_factory.mktemp("gltf_dataset"))


@pytest.fixture(scope="module")
def layout(dataset):
    return load_test_layout(dataset)


# ---- synth.mesh.gltf: frames, UVs, materials, node transforms ----------------------------------------


def test_the_fixture_glb_holds_what_the_test_says(dataset):
    doc, binary = glb_chunks(dataset / "objects/tex_box.glb")
    prim = doc["meshes"][0]["primitives"][0]
    uv = accessor(doc, binary, prim["attributes"]["TEXCOORD_0"])
    assert uv.min() >= 0.1 - 1e-6 and uv.max() <= 0.4 + 1e-6  # glTF UVs (origin top-left): red quadrant only
    assert doc["materials"][prim["material"]]["pbrMetallicRoughness"]["baseColorTexture"]["index"] == 0


def test_load_glb_parts_converts_to_z_up_and_keeps_uvs_and_material(dataset):
    from synth.mesh.gltf import glb_geometry, load_glb_parts, pbr

    path = dataset / "objects/tex_box.glb"
    doc, binary = glb_chunks(path)
    prim = doc["meshes"][0]["primitives"][0]
    v_h = accessor(doc, binary, prim["attributes"]["POSITION"]).astype(float)
    uv_gltf = accessor(doc, binary, prim["attributes"]["TEXCOORD_0"]).astype(float)
    faces = accessor(doc, binary, prim["indices"]).reshape(-1, 3)

    (part,) = load_glb_parts(path)
    assert np.allclose(part.vertices, v_h @ C.T, atol=1e-6)  # v = C v_h
    assert np.array_equal(part.faces, faces)
    assert np.allclose(part.visual.uv, np.column_stack([uv_gltf[:, 0], 1.0 - uv_gltf[:, 1]]), atol=1e-6)
    assert part.bounds[0] == pytest.approx([-0.25, -0.25, 0.0]) and part.bounds[1] == pytest.approx([0.25, 0.25, 0.5])
    p = pbr(part)
    assert p["base_color"] == pytest.approx([1.0, 1.0, 1.0, 1.0])
    assert p["metallic"] == 0.0 and p["roughness"] == pytest.approx(0.6) and p["alpha_mode"] == "OPAQUE"
    tex = np.asarray(p["base_color_texture"].convert("RGB"))
    assert tuple(tex[0, 0]) == RED and tuple(tex[0, 15]) == GREEN and tuple(tex[15, 0]) == BLUE
    assert max(p["emissive"]) == 0.0 and p["has_uv"]

    # hand-outs are copies: changing one does not change the next
    part.vertices[:] = 0.0
    part.visual.uv[:] = 0.0
    (again,) = load_glb_parts(path)
    assert np.allclose(again.vertices, v_h @ C.T, atol=1e-6) and again.visual.uv.max() > 0.5

    g = glb_geometry(dataset / "stages/stage.glb")
    assert len(g.faces) == 36 and not hasattr(g.visual, "material")
    assert g.bounds[0] == pytest.approx([-3.0, -3.0, -0.1]) and g.bounds[1] == pytest.approx([3.0, 3.0, 2.5])

    (plain,) = load_glb_parts(dataset / "objects/plain_box.glb")
    doc, _ = glb_chunks(dataset / "objects/plain_box.glb")
    written = doc["materials"][0]["pbrMetallicRoughness"]["baseColorFactor"]
    assert pbr(plain)["base_color"] == pytest.approx(written, abs=1e-7)  # the file's floats, not 8-bit
    assert pbr(plain)["base_color_texture"] is None


def test_node_transforms_instancing_and_normals(tmp_path):
    from synth.mesh.gltf import load_glb_parts

    box = plain_box(0.2, (0.5, 0.5, 0.5))
    ang = 0.7
    M = trimesh.transformations.rotation_matrix(ang, [0, 1, 0])  # about habitat's up axis
    M[:3, 3] = (1.0, 2.0, 3.0)
    mirror = np.diag([-1.0, 1.0, 1.0, 1.0])
    sc = trimesh.Scene()
    sc.add_geometry(box, node_name="a", geom_name="box", transform=M)
    sc.add_geometry(box, node_name="b", geom_name="box", transform=mirror)  # the same mesh, a second node
    path = tmp_path / "nodes.glb"
    path.write_bytes(trimesh.exchange.gltf.export_glb(sc, include_normals=True))
    doc, binary = glb_chunks(path)
    a = next(n for n in doc["nodes"] if n.get("name") == "a")
    b = next(n for n in doc["nodes"] if n.get("name") == "b")
    b["mesh"] = a["mesh"]  # true instancing: two nodes, one mesh (the other mesh is left unused)
    write_glb_chunks(path, doc, binary)
    parts = load_glb_parts(path)
    assert len(parts) == 2
    v_h = np.asarray(box.vertices)
    n_h = np.asarray(box.vertex_normals)
    want = {"a": (v_h @ M[:3, :3].T + M[:3, 3]) @ C.T, "b": (v_h @ mirror[:3, :3].T) @ C.T}
    got = {p.metadata["gltf"]["node"]: p for p in parts}
    for node, p in got.items():
        assert np.allclose(p.vertices, want[node], atol=1e-6), node
        assert p.metadata["gltf"]["normals"]
    assert np.allclose(got["a"].vertex_normals, n_h @ M[:3, :3].T @ C.T, atol=1e-6)
    # the mirrored instance: winding reversed, so the right-hand normals still point outwards
    m = got["b"]
    c = m.vertices.mean(axis=0)
    tri = m.vertices[m.faces]
    fn = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    assert np.all(np.einsum("ij,ij->i", fn, tri.mean(axis=1) - c) > 0)


def test_undecodable_texture_warns_once_and_falls_back_to_the_factor(tmp_path, caplog):
    from synth.mesh import gltf

    src = tmp_path / "src.glb"
    write_glb(src, [textured_box()])
    doc, binary = glb_chunks(src)
    doc["images"][0]["mimeType"] = "image/ktx2"
    doc["materials"][0]["pbrMetallicRoughness"]["baseColorFactor"] = [0.5, 0.25, 0.125, 1.0]
    bad = tmp_path / "ktx2.glb"
    write_glb_chunks(bad, doc, binary)
    with caplog.at_level("WARNING", logger="synth.mesh.gltf"):
        (p,) = gltf.load_glb_parts(bad)
        gltf.clear_cache()
        gltf.load_glb_parts(bad)
    msgs = [r.getMessage() for r in caplog.records if "cannot be decoded" in r.getMessage()]
    assert len(msgs) == 1 and str(bad) in msgs[0] and "images[0]" in msgs[0]
    params = gltf.pbr(p)
    assert params["base_color_texture"] is None and params["base_color"] == pytest.approx([0.5, 0.25, 0.125, 1.0])


# ---- bad input -------------------------------------------------------------------------------------


def external_texture_glb(tmp_path: Path, uri: str) -> Path:
    """The textured box with its image moved out of the GLB to ``uri`` (next to it)."""
    src = tmp_path / "src.glb"
    write_glb(src, [textured_box()])
    doc, binary = glb_chunks(src)
    img = doc["images"][0]
    bv = doc["bufferViews"][img["bufferView"]]
    png = binary[bv.get("byteOffset", 0): bv.get("byteOffset", 0) + bv["byteLength"]]
    doc["images"][0] = {"uri": uri}  # the buffer view stays (unused): harmless
    path = tmp_path / "objects" / "ext.glb"
    path.parent.mkdir(parents=True, exist_ok=True)
    write_glb_chunks(path, doc, binary)
    return path, png


def test_missing_external_texture_names_the_glb_and_the_field(tmp_path):
    from synth.mesh.gltf import check_glb, load_glb_parts, pbr

    path, png = external_texture_glb(tmp_path, "textures/red%20box.png")
    for fn in (check_glb, load_glb_parts):
        with pytest.raises(SceneFormatError) as e:
            fn(path)
        assert e.value.file == str(path) and e.value.field == "images[0].uri"
        assert "texture not found" in str(e.value) and "red box.png" in str(e.value)
        assert len(str(e.value).splitlines()) == 1
    # once the file is there (percent-decoded, relative to the GLB), the texture is used
    (path.parent / "textures").mkdir()
    (path.parent / "textures" / "red box.png").write_bytes(png)
    (p,) = load_glb_parts(path)
    assert tuple(np.asarray(pbr(p)["base_color_texture"].convert("RGB"))[0, 0]) == RED


def test_missing_texture_is_reported_when_the_scene_loads(tmp_path):
    root = make_dataset(tmp_path / "ds")
    path, _ = external_texture_glb(tmp_path / "tmp", "gone.png")
    (root / "objects/tex_box.glb").write_bytes(path.read_bytes())
    from synth.sources.replicacad.importer import load_replicacad

    with pytest.raises(SceneFormatError) as e:
        load_replicacad(root, SCENE, allow_unknown=True, structure=False)
    assert e.value.file == str(root / "objects/tex_box.glb") and e.value.field == "images[0].uri"


def test_broken_and_empty_glbs(tmp_path):
    from synth.mesh.gltf import check_glb, load_glb_parts

    junk = tmp_path / "junk.glb"
    junk.write_bytes(b"not a glb at all, just some bytes")
    for fn in (check_glb, load_glb_parts):
        with pytest.raises(SceneFormatError, match="cannot read GLB") as e:
            fn(junk)
        assert e.value.file == str(junk) and e.value.field is None
    empty = tmp_path / "empty.glb"
    write_glb_chunks(empty, {"asset": {"version": "2.0"}, "meshes": []}, b"")
    with pytest.raises(SceneFormatError, match="GLB has no triangles"):
        load_glb_parts(empty)


# ---- synth.render.meshes: parts of ReplicaCAD objects, articulated objects and the stage ------------------


def world_bounds(parts) -> tuple[np.ndarray, np.ndarray]:
    v = np.concatenate([p.world_vertices() for p in parts])
    return v.min(axis=0), v.max(axis=0)


def test_object_parts_are_textured_and_placed(layout):
    from synth.render.meshes import GLTF_MATERIAL, layout_parts

    parts = layout_parts(layout)
    by_obj = {}
    for p in parts:
        by_obj.setdefault(p.instance_id, []).append(p)
    other = class_table().id_of("other")
    assert all(p.material == GLTF_MATERIAL for p in parts)
    (tex,) = by_obj[1]
    assert tex.semantic_id == other and tex.mesh.visual.uv is not None
    lo, hi = world_bounds(by_obj[1])  # habitat translation (-0.5, 0, -0.5) -> ours (-0.5, 0.5, 0)
    assert lo == pytest.approx([-0.75, 0.25, 0.0]) and hi == pytest.approx([-0.25, 0.75, 0.5])
    lo, hi = world_bounds(by_obj[2])
    assert lo == pytest.approx([0.4, 0.4, 0.0]) and hi == pytest.approx([0.8, 0.8, 0.4])
    # stage without derived structure: every triangle instance WALL_ID_BASE, semantic wall
    assert {p.instance_id for p in parts if p.name.startswith("stage")} == {WALL_ID_BASE}
    assert {p.semantic_id for p in by_obj[WALL_ID_BASE]} == {class_table().id_of("wall")}


def test_emitters_follow_the_nearest_fixture(layout):
    from synth.render.meshes import layout_parts

    parts = {p.instance_id: p for p in layout_parts(layout) if p.instance_id in (1, 2, 3, 4)}
    assert parts[3].emissive and parts[3].fixture == "C0"  # 0.55 m from its box centre
    assert parts[4].emissive and parts[4].fixture is None  # nothing within 1.5 m: stays off
    assert not parts[1].emissive and not parts[2].emissive
    far = layout.copy()
    far.fixtures = [LightFixture("C0", "ceiling", (1.5, 2.0, 3.1))]  # 1.55 m away: too far
    assert {p.instance_id: p.fixture for p in layout_parts(far)}[3] is None
    own = layout.copy()
    own.fixtures = [LightFixture("C0", "ceiling", FIXTURE_POS), LightFixture("L9", "lamp", (-2.0, -1.5, 2.5), object=4)]
    assert {p.instance_id: p.fixture for p in layout_parts(own)}[4] == "L9"  # its object's own fixture


def test_fast_renderer_draws_textured_parts(layout):
    from synth.render.fast_render import FastRenderer

    intr = Intrinsics.from_fov(64, 48, 30.0)
    T = pose_from_ypr((-0.5, 0.5, 3.0), yaw=0.0, pitch=-np.pi / 2)  # straight down onto the textured box
    depth, inst, sem = FastRenderer(layout).render(T, intr)
    assert (inst == 1).mean() > 0.1
    assert np.allclose(depth[inst == 1], 2.5, atol=1e-5)  # its top at z = 0.5
    assert np.allclose(depth[inst == WALL_ID_BASE], 3.0, atol=1e-5)  # the floor (top z = 0) around it


URDF = """<?xml version="1.0"?>
<robot name="cabinet">
  <link name="body">
    <visual><origin xyz="0 0 0" rpy="0 0 0"/><geometry><mesh filename="body.glb"/></geometry></visual>
  </link>
  <link name="drawer">
    <visual><origin xyz="0 0.1 0" rpy="0 0 0"/><geometry><mesh filename="drawer.glb" scale="2 1 1"/></geometry></visual>
  </link>
  <joint name="slide" type="prismatic">
    <parent link="body"/><child link="drawer"/>
    <origin xyz="0 0.6 0" rpy="0 0 0"/><axis xyz="0 0 1"/>
  </joint>
</robot>
"""


def test_articulated_object_parts(tmp_path, layout):
    from synth.render.meshes import layout_parts
    from synth.scene.model import ObjectInstance

    root = Path(layout.meta["root"])
    d = root / "urdf" / "cabinet"
    d.mkdir(parents=True, exist_ok=True)
    write_glb(d / "body.glb", [textured_box()])  # habitat: x, z in [-0.25, 0.25], y in [0, 0.5]
    write_glb(d / "drawer.glb", [plain_box(0.2, (0.3, 0.3, 0.3))])  # x, z in [-0.1, 0.1], y in [0, 0.2]
    (d / "cabinet.urdf").write_text(URDF)
    lay = layout.copy()
    lay.objects = [ObjectInstance(7, "other", "replicacad-urdf:urdf/cabinet/cabinet.urdf", (2.0, -1.0, 0.0),
                                  (1.0, 0.0, 0.0, 0.0), (0.5, 0.5, 0.8), (0.0, 0.0, 0.4), "floor", False,
                                  params={"joint_state": {"slide": 0.15}})]
    parts = [p for p in layout_parts(lay) if p.instance_id == 7]
    assert len(parts) == 2 and all(p.material == "gltf" for p in parts)
    body, drawer = parts
    lo, hi = world_bounds([body])
    assert lo == pytest.approx([1.75, -1.25, 0.0]) and hi == pytest.approx([2.25, -0.75, 0.5])
    # drawer: link at habitat y 0.6 + 0.15 along habitat z (= ours -y), visual 0.1 higher, x scaled by 2
    lo, hi = world_bounds([drawer])
    assert lo == pytest.approx([1.8, -1.25, 0.7]) and hi == pytest.approx([2.2, -1.05, 0.9])
    assert drawer.mesh.visual.uv is None and body.mesh.visual.uv is not None


def hand_structure(layout):
    """Walls and a room for the test stage, written by hand: north wall (k = 0) along y = 2.95, west
    wall (k = 1) along x = -2.95; one room."""
    lay = layout.copy()
    st = lay.stage
    st.walls = [Wall("N", (-3.0, 2.95), (3.0, 2.95), 0.1, 2.5), Wall("Wst", (-2.95, -3.0), (-2.95, 2.9), 0.1, 2.5)]
    st.rooms = [Room("living", "living", (-2.9, -3.0, 3.0, 2.9))]
    return lay


def test_stage_is_split_per_triangle_into_walls_and_floors(layout, monkeypatch):
    """The split follows face_ids triangle by triangle (a stand-in face_ids that classifies by the
    triangle's normal and height, and leaves the wall tops unclassified)."""
    import types

    from synth.render.meshes import instance_classes, layout_parts

    calls = []

    def face_ids(stage, centroids, normals):
        calls.append(len(centroids))
        ids = np.zeros(len(centroids), np.int64)
        up = normals[:, 2] > 0.9
        ids[up & (centroids[:, 2] < 0.05)] = FLOOR_ID_BASE  # floor top
        ids[~up & (centroids[:, 2] < 0.0)] = FLOOR_ID_BASE  # floor sides and bottom
        side = np.abs(normals[:, 2]) < 0.1
        ids[side & (centroids[:, 1] > 2.85) & (centroids[:, 0] > -2.92) & (centroids[:, 2] > 0.0)] = WALL_ID_BASE
        return ids  # left at 0: wall tops (z = 2.5), the north wall's west end, all of the west wall

    monkeypatch.setitem(sys.modules, "synth.mesh.stage_structure", types.SimpleNamespace(face_ids=face_ids))
    import synth.render.meshes

    monkeypatch.setattr(synth.render.meshes, "STAGE_MAX_EDGE", 100.0)  # no splitting of big floor triangles here (next test)
    lay = hand_structure(layout)
    parts = [p for p in layout_parts(lay) if p.name.startswith("stage")]
    assert calls == [36]  # one call with every stage triangle
    ids = {p.instance_id for p in parts}
    assert ids == {WALL_ID_BASE, WALL_ID_BASE + 1, FLOOR_ID_BASE}  # no 0, no procedural boxes
    ct = class_table()
    for p in parts:
        want = {WALL_ID_BASE: "wall", FLOOR_ID_BASE: "floor"}[p.instance_id // 1000 * 1000]
        assert p.semantic_id == ct.id_of(want) and p.material == "gltf"
    # the west wall's triangles (unclassified) went to the nearest wall: the west wall itself
    lo, hi = world_bounds([p for p in parts if p.instance_id == WALL_ID_BASE + 1])
    assert hi[0] == pytest.approx(-2.9) and lo[1] == pytest.approx(-3.0)
    assert sum(len(p.mesh.faces) for p in parts) == 36
    # the north wall's top (unclassified) is nearest to the north wall
    north = [p for p in parts if p.instance_id == WALL_ID_BASE]
    assert sum(len(p.mesh.faces) for p in north) == 12
    cls = instance_classes(lay)
    assert cls[WALL_ID_BASE] == ct.id_of("wall") and cls[FLOOR_ID_BASE] == ct.id_of("floor")
    assert cls[CEILING_ID_BASE] == ct.id_of("ceiling")


def test_stage_split_keeps_uvs(tmp_path):
    """Splitting a textured primitive keeps each triangle's UVs."""
    from synth.mesh.gltf import load_glb_parts, submesh

    path = tmp_path / "t.glb"
    write_glb(path, [textured_box()])
    (m,) = load_glb_parts(path)
    pick = np.array([1, 4, 7, 8])
    s = submesh(m, pick)
    assert len(s.faces) == 4
    assert np.allclose(s.vertices[s.faces], m.vertices[m.faces[pick]])
    assert np.allclose(s.visual.uv[s.faces], m.visual.uv[m.faces[pick]])
    assert s.visual.material is m.visual.material


# ---- Blender: texture colour, Blender's own glTF importer, geometry against Open3D -------------------

SCRIPT = textwrap.dedent(r'''
    import json, sys, time
    from dataclasses import replace
    import numpy as np
    import bpy
    from mathutils import Matrix
    from vrformats.camera import Intrinsics
    from synth.scene.model import load_layout
    from synth.render.meshes import layout_parts
    from synth.scene.lighting import load_lighting, resolve_lighting
    from synth.render.settings import quality
    from synth.blender import scene_builder as sb
    from synth.blender.gltf_materials import get_gltf_material
    from synth.blender.shading import set_emission
    from synth.blender.worker import read_blender_exr
    from synth.mesh.gltf import load_glb_parts, pbr

    args = json.loads(sys.argv[1])
    out = args["out"]
    lay = load_layout(args["layout"])
    intr = Intrinsics.from_dict(args["intrinsics"])
    T_cam = np.array(args["pose"])
    q = quality("preview")
    res = {"timing": {"gltf": [], "painted": []}}

    def build(mode):
        t0 = time.time()
        scene = sb.reset_scene()
        parts = layout_parts(lay)
        if mode == "painted":  # the old look: every mesh part plain "painted", no textures
            parts = [replace(p, material="painted", emissive=False, fixture=None) for p in parts]
        emitters = sb.add_parts(scene, parts, with_materials=True)
        if mode == "importer":  # objects 1 and 2 replaced by Blender's own import of their GLBs
            res["removed"] = sorted(ob.name for ob in bpy.data.objects if ob.name.split("/")[0] in ("obj1", "obj2"))
            for ob in list(bpy.data.objects):
                if ob.name.split("/")[0] in ("obj1", "obj2"):
                    bpy.data.objects.remove(ob)
            res["imported"] = {}
            for oid, glb in args["glbs"].items():
                before = set(bpy.data.objects)
                bpy.ops.import_scene.gltf(filepath=glb)
                T = Matrix(np.asarray(args["matrices"][oid]).tolist())
                new = set(bpy.data.objects) - before
                for ob in new:
                    if ob.parent is None:
                        ob.matrix_world = T @ ob.matrix_world
                bpy.context.view_layer.update()
                pts = [ob.matrix_world @ v.co for ob in new if ob.type == "MESH" for v in ob.data.vertices]
                res["imported"][oid] = {
                    "bounds": [[min(p[i] for p in pts) for i in range(3)], [max(p[i] for p in pts) for i in range(3)]],
                    "nodes": sorted({n.bl_idname for ob in new if ob.type == "MESH" for m in ob.data.materials
                                     for n in m.node_tree.nodes})}
        cam = sb.set_camera(scene, intr)
        sb.choose_device(scene, "cpu")
        sb.configure_rgb(scene, q, 0)
        sb.add_lighting(scene, resolve_lighting(load_lighting("day"), lay), emitters)
        sb.configure_output(scene, f"{out}/{mode}.exr")
        sb.place_camera(cam, T_cam)
        t1 = time.time()
        bpy.ops.render.render(write_still=True)
        t2 = time.time()
        rgb = read_blender_exr(f"{out}/{mode}.exr")["Combined"][..., :3]
        return rgb, t1 - t0, t2 - t1, emitters

    images = {}
    for i in range(3):  # alternate, so that drift in machine load hits both alike
        for mode in ("gltf", "painted"):
            rgb, tb, tr, emitters = build(mode)
            res["timing"][mode].append([tb, tr])
            images[mode] = rgb
            if mode == "gltf" and i == 0:
                def strength(name):
                    mat = bpy.data.objects[name].data.materials[0]
                    node = mat.node_tree.nodes.get("emission")
                    light = mat.node_tree.nodes.get("emission_light")
                    return None if node is None else [node.inputs["Strength"].default_value,
                                                      list(light.outputs[0].default_value)[:3]]
                res["emission"] = {"near": strength("obj3/0"), "far": strength("obj4/0"),
                                   "plain": strength("obj2/0"), "emitters": sorted(emitters)}
                res["uv_layers"] = [l.name for l in bpy.data.objects["obj1/0"].data.uv_layers]
    images["importer"], _, _, _ = build("importer")
    res["importer_materials"] = sorted(m.name for m in bpy.data.materials if not m.name.startswith("gltf:"))

    # emission, measured: a plane with the bulb's material, lit by nothing, seen head-on
    scene = sb.reset_scene()
    (bulb,) = load_glb_parts(args["bulb"])
    mat = get_gltf_material(pbr(bulb), emissive=True, key="probe")
    set_emission(mat, 5.0, (1.0, 0.5, 0.25))
    bpy.ops.mesh.primitive_plane_add(size=4.0)
    bpy.context.object.data.materials.append(mat)
    world = bpy.data.worlds.new("w"); scene.world = world; world.use_nodes = True
    world.node_tree.nodes["Background"].inputs["Strength"].default_value = 0.0
    cam = bpy.data.cameras.new("c"); cam.type = "ORTHO"; cam.ortho_scale = 1.0
    co = bpy.data.objects.new("c", cam); scene.collection.objects.link(co); scene.camera = co
    co.location = (0.0, 0.0, 3.0)
    scene.cycles.samples = 1; scene.cycles.use_denoising = False
    scene.render.resolution_x = scene.render.resolution_y = 8
    sb.configure_output(scene, f"{out}/probe.exr")
    bpy.ops.render.render(write_still=True)
    res["probe"] = read_blender_exr(f"{out}/probe.exr")["Combined"][..., :3].reshape(-1, 3).mean(0).tolist()

    # a GLB with smooth normals: they become custom normals of the Blender mesh
    from synth.render.meshes import RenderPart
    scene = sb.reset_scene()
    (sph,) = load_glb_parts(args["sphere"])
    sb.add_parts(scene, [RenderPart("sphere", 1, 1, "gltf", sph, np.eye(4))], with_materials=True)
    me = bpy.data.objects["sphere"].data
    given = np.asarray(sph.vertex_normals)
    corner = np.array([me.corner_normals[i].vector[:] for i in range(len(me.loops))])
    vidx = np.array([l.vertex_index for l in me.loops])
    flat = np.array([me.polygons[i].normal[:] for i in range(len(me.polygons))]).repeat(3, axis=0)
    res["normals"] = {"custom": bool(me.has_custom_normals), "err": float(np.abs(corner - given[vidx]).max()),
                      "flat_err": float(np.abs(flat - given[vidx]).max())}

    # a material held only in memory (no file: PIL images re-encoded), with MASK alpha, a
    # metallic-roughness and a normal texture; seen in front of a plain world colour
    import trimesh
    from PIL import Image
    from trimesh.visual import TextureVisuals
    from trimesh.visual.material import PBRMaterial
    rgba = np.zeros((4, 4, 4), np.uint8); rgba[...] = (255, 0, 0, 51)  # alpha 0.2 < cutoff 0.5
    mr = np.zeros((4, 4, 3), np.uint8); mr[..., 1] = 128; mr[..., 2] = 255
    nrm = np.zeros((4, 4, 3), np.uint8); nrm[...] = (128, 128, 255)
    box = trimesh.creation.box()
    box.visual = TextureVisuals(uv=np.full((len(box.vertices), 2), 0.5), material=PBRMaterial(
        baseColorTexture=Image.fromarray(rgba, "RGBA"), alphaMode="MASK", alphaCutoff=0.5,
        metallicRoughnessTexture=Image.fromarray(mr, "RGB"), normalTexture=Image.fromarray(nrm, "RGB"),
        metallicFactor=1.0, roughnessFactor=1.0))
    scene = sb.reset_scene()
    mat = get_gltf_material(pbr(box))
    bsdf = next(n for n in mat.node_tree.nodes if n.bl_idname == "ShaderNodeBsdfPrincipled")
    res["mask_material"] = {"linked": sorted(i.name for i in bsdf.inputs if i.is_linked),
                            "images": sorted(n.image.colorspace_settings.name for n in mat.node_tree.nodes
                                             if n.bl_idname == "ShaderNodeTexImage")}
    bpy.ops.mesh.primitive_plane_add(size=4.0)
    bpy.context.object.data.materials.append(mat)
    world = bpy.data.worlds.new("w"); scene.world = world; world.use_nodes = True
    world.node_tree.nodes["Background"].inputs["Color"].default_value = (0.2, 0.4, 0.6, 1.0)
    world.node_tree.nodes["Background"].inputs["Strength"].default_value = 1.0
    cam = bpy.data.cameras.new("c"); cam.type = "ORTHO"; cam.ortho_scale = 1.0
    co = bpy.data.objects.new("c", cam); scene.collection.objects.link(co); scene.camera = co
    co.location = (0.0, 0.0, 3.0)
    scene.cycles.samples = 4; scene.cycles.use_denoising = False
    scene.render.resolution_x = scene.render.resolution_y = 8
    sb.configure_output(scene, f"{out}/mask.exr")
    bpy.ops.render.render(write_still=True)
    res["mask_probe"] = read_blender_exr(f"{out}/mask.exr")["Combined"][..., :3].reshape(-1, 3).mean(0).tolist()

    np.savez(f"{out}/renders.npz", **images)
    with open(f"{out}/report.json", "w") as f:
        json.dump(res, f)
''')


def run_blender_script(args: dict) -> dict:
    env = dict(os.environ, PYTHONPATH=str(REPO) + os.pathsep + os.environ.get("PYTHONPATH", ""))
    r = subprocess.run([sys.executable, "-c", SCRIPT, json.dumps(args)], capture_output=True, text=True, timeout=600,
                       cwd=REPO, env=env)
    assert r.returncode == 0, r.stdout[-3000:] + r.stderr[-3000:]
    return json.loads((Path(args["out"]) / "report.json").read_text())


@pytest.fixture(scope="module")
def renders(tmp_path_factory, dataset, layout):
    """Tours of the test scene (Blender with day light, and the fast renderer), plus the script's
    renders: the pipeline, the old plain materials, Blender's glTF importer; and timings."""
    from synth.render.fast_render import FastRenderer
    from synth.render.meshes import layout_parts
    from synth.tour.render import TourSpec, render_tour

    base = tmp_path_factory.mktemp("gltf_renders")
    layout_file = save_layout(layout, base / f"{SCENE}.yaml")
    poses = camera_poses()
    path = base / "path.txt"
    write_tum(path, poses)
    common = dict(layout=str(layout_file), path=str(path), width=W, height=H, hfov_deg=HFOV, chunk_size=2,
                  check_clearance=False)
    mb = render_tour(TourSpec(out=str(base / "blender"), lighting="day", renderer="blender", **common), progress=False)
    mf = render_tour(TourSpec(out=str(base / "fast"), renderer="fast", **common), progress=False)
    assert mb["complete"] and mf["complete"]
    intr = Intrinsics.from_fov(W, H, HFOV)
    matrices = {}
    for p in layout_parts(load_layout(layout_file)):
        if p.instance_id in (1, 2):
            matrices[str(p.instance_id)] = np.asarray(p.matrix).tolist()
    out = base / "script"
    out.mkdir()
    sphere = base / "sphere.glb"  # smooth normals in the file
    ico = trimesh.creation.icosphere(subdivisions=2, radius=0.3)
    ico.visual = TextureVisuals(material=PBRMaterial(baseColorFactor=[0.5, 0.5, 0.5, 1.0]))
    sphere.write_bytes(trimesh.exchange.gltf.export_glb(trimesh.Scene(ico), include_normals=True))
    report = run_blender_script({
        "out": str(out), "layout": str(layout_file), "intrinsics": intr.to_dict(), "pose": poses[0].tolist(),
        "glbs": {"1": str(dataset / "objects/tex_box.glb"), "2": str(dataset / "objects/plain_box.glb")},
        "matrices": matrices, "bulb": str(dataset / "objects/bulb.glb"), "sphere": str(sphere)})
    images = dict(np.load(out / "renders.npz"))
    _, inst, _ = FastRenderer(load_layout(layout_file)).render(poses[0], intr)
    return {"blender": Tour(base / "blender"), "fast": Tour(base / "fast"), "report": report, "images": images,
            "inst": inst}


def mask_of(inst: np.ndarray, iid: int) -> np.ndarray:
    """Pixels of one instance, one pixel in from its outline (no anti-aliased edge pixels)."""
    return ndimage.binary_erosion(inst == iid, iterations=1)




@pytest.mark.slow
@pytest.mark.blender
def test_blender_geometry_matches_the_fast_renderer_on_the_textured_scene(renders):
    tb, tf = renders["blender"], renders["fast"]
    assert len(tb) == len(tf) == 2
    for a, b in zip(tb, tf):
        assert_renders_agree(a, b)
        assert {1, 2, WALL_ID_BASE} <= set(np.unique(b.instance).tolist())


@pytest.mark.blender
def test_textured_object_shows_its_texture_colour(renders):
    frame = next(iter(renders["blender"]))
    m = mask_of(frame.instance, 1)  # the Blender geometry pass's instance mask
    assert m.sum() >= 40
    mean = frame.rgb[m].mean(axis=0)
    want = chroma(srgb_to_linear(RED))
    got = chroma(mean)
    # tolerance: the glossy dielectric's specular reflection (F0 = 4 %, neutral) of the bright sky and
    # sun, and the blue sky's tint, pull the rendered colour towards white by a few per cent
    print(f"\ntextured box: rendered chromaticity {np.round(got, 3)}, texture {np.round(want, 3)}")
    assert np.abs(got - want).max() < 0.12, (got, want)
    painted = chroma(renders["images"]["painted"][mask_of(renders["inst"], 1)].mean(axis=0))
    assert np.abs(painted - want).max() > 0.4, painted  # the old plain material looks nothing like it
    # the untextured box: its baseColorFactor's chromaticity
    m2 = mask_of(frame.instance, 2)
    got2 = chroma(frame.rgb[m2].mean(axis=0))
    print(f"plain box: rendered chromaticity {np.round(got2, 3)}, factor {np.round(chroma(PLAIN_FACTOR), 3)}; "
          f"painted: {np.round(painted, 3)}")
    assert np.abs(got2 - chroma(PLAIN_FACTOR)).max() < 0.08, (got2, chroma(PLAIN_FACTOR))


@pytest.mark.blender
def test_blender_gltf_importer_gives_the_same_colours(renders):
    ours, theirs = renders["images"]["gltf"], renders["images"]["importer"]
    rep = renders["report"]
    assert rep["removed"] == ["obj1/0", "obj2/0"]  # our parts of objects 1 and 2 left the scene ...
    imp = rep["imported"]  # ... and the importer's meshes took their place (world bounds by hand)
    assert np.allclose(imp["1"]["bounds"], [[-0.75, 0.25, 0.0], [-0.25, 0.75, 0.5]], atol=1e-5)
    assert np.allclose(imp["2"]["bounds"], [[0.4, 0.4, 0.0], [0.8, 0.8, 0.4]], atol=1e-5)
    assert "ShaderNodeTexImage" in imp["1"]["nodes"] and "ShaderNodeTexImage" not in imp["2"]["nodes"]
    for iid in (1, 2):
        m = mask_of(renders["inst"], iid)
        a, b = ours[m].mean(axis=0), theirs[m].mean(axis=0)
        print(f"\nobject {iid}: ours {np.round(a, 4)}, Blender's glTF importer {np.round(b, 4)}")
        assert np.all(np.abs(a - b) <= 0.1 * np.maximum(b, 0.02)), (iid, a, b)
    # the pipeline render of the script is the tour's frame (same code path through the worker)
    frame = next(iter(renders["blender"]))
    m = mask_of(renders["inst"], 1)
    assert np.allclose(frame.rgb[m].mean(axis=0), ours[m].mean(axis=0), rtol=0.1)


@pytest.mark.blender
def test_gltf_emission_is_switched_by_its_fixture(renders):
    from synth.scene.lighting import CEILING_EMISSION, kelvin_to_rgb, load_lighting

    rep = renders["report"]
    em = rep["emission"]
    assert rep["uv_layers"] == ["UVMap"]
    assert em["emitters"] == ["C0"]
    strength, color = em["near"]
    assert strength == pytest.approx(CEILING_EMISSION)
    assert color == pytest.approx(kelvin_to_rgb(load_lighting("day").ceiling.color_temperature), abs=1e-6)
    assert em["far"][0] == 0.0  # no fixture within 1.5 m: off even in daylight with fills on
    assert em["plain"] is None
    # radiance of the emissive material: emissiveFactor x light colour x strength
    want = np.array(BULB_EMISSION) * np.array([1.0, 0.5, 0.25]) * 5.0
    assert rep["probe"] == pytest.approx(want.tolist(), rel=0.02)


@pytest.mark.blender
def test_file_normals_become_custom_normals(renders):
    n = renders["report"]["normals"]
    assert n["custom"] and n["err"] < 1e-3  # the file's (smooth) normals, converted to Z up
    assert n["flat_err"] > 0.05  # and not the faces' own normals


@pytest.mark.blender
def test_texture_slots_and_alpha_mask(renders):
    mm = renders["report"]["mask_material"]
    assert mm["linked"] == ["Alpha", "Base Color", "Metallic", "Normal", "Roughness"]
    assert mm["images"] == ["Non-Color", "Non-Color", "sRGB"]
    # alpha 0.2 below the 0.5 cutoff: the plane is cut away, the camera sees the world colour
    assert renders["report"]["mask_probe"] == pytest.approx([0.2, 0.4, 0.6], abs=0.01)


@pytest.mark.blender
def test_report_render_times(renders):
    t = renders["report"]["timing"]
    med = {k: (float(np.median([x[0] for x in v])), float(np.median([x[1] for x in v]))) for k, v in t.items()}
    print(f"\ntextured scene {W}x{H} preview: build {med['gltf'][0]:.3f} s, render {med['gltf'][1]:.3f} s; "
          f"plain materials: build {med['painted'][0]:.3f} s, render {med['painted'][1]:.3f} s (median of 3)")
    assert all(len(v) == 3 for v in t.values())


# ---- the ReplicaCAD-shaped fixture: derived structure, articulated object, textured stage ----------


def fixture_module():
    sys.path.insert(0, str(Path(__file__).resolve().parents[2]))
    import replicacad_fixture as F

    return F


@pytest.fixture(scope="module")
def rcad(tmp_path_factory):
    from synth.sources.replicacad.importer import load_replicacad

    F = fixture_module()
    root = F.make_fixture(tmp_path_factory.mktemp("rcad"))
    return F, root, load_replicacad(root, "apt_0")  # structure derived from the stage mesh


def fixture_poses() -> np.ndarray:
    return np.stack([pose_from_ypr((1.0, 0.5, 1.5), yaw=0.6, pitch=-0.3),  # room A: table, window, walls
                     pose_from_ypr((4.8, 1.6, 1.4), yaw=-0.4, pitch=-0.35),  # room B: counter, sofa
                     pose_from_ypr((2.0, 1.5, 1.2), yaw=3.0, pitch=0.5)])  # room A, up: ceiling, west wall


def world_points(depth: np.ndarray, T: np.ndarray, intr: Intrinsics) -> np.ndarray:
    """World points of planar depth (camera z), computed here from the pinhole model."""
    v, u = np.mgrid[0:intr.height, 0:intr.width]
    x = (u - intr.cx) / intr.fx * depth
    y = (v - intr.cy) / intr.fy * depth
    pc = np.stack([x, y, depth], axis=-1)
    return pc @ T[:3, :3].T + T[:3, 3]


def test_fixture_stage_split_matches_its_construction(rcad):
    """Every stage pixel of the fast renderer has the semantic class of the surface the fixture built
    there (floor at z = 0, ceiling at z = 2.5, the hand-made wall boxes), and a wall pixel lies in
    the derived box of the wall whose id it carries."""
    from synth.render.fast_render import FastRenderer
    from synth.render.meshes import layout_parts
    from synth.scene.model import structure_boxes

    F, root, lay = rcad
    assert lay.stage.walls and lay.stage.rooms
    parts = layout_parts(lay)
    assert all(p.material == "gltf" for p in parts)
    assert not any(p.name.startswith(("floor/", "ceiling/", "threshold/")) for p in parts)  # no procedural boxes
    assert {p.instance_id for p in parts if p.name.startswith("stage")} >= {WALL_ID_BASE, FLOOR_ID_BASE, CEILING_ID_BASE}
    ct = class_table()
    sem = {k: ct.id_of(k) for k in ("wall", "floor", "ceiling")}
    boxes = {b.id: b for b in structure_boxes(lay.stage)}
    intr = Intrinsics.from_fov(64, 48, 75.0)
    renderer = FastRenderer(lay)
    agree = {"floor": [], "ceiling": [], "wall": []}
    for T in fixture_poses():
        depth, inst, sems = renderer.render(T, intr)
        P = world_points(depth, T, intr)
        ok = ~depth_edges(depth) & (inst >= WALL_ID_BASE)
        assert ok.sum() > 500
        on_floor = np.abs(P[..., 2] - F.FLOOR_Z) < 2e-3
        on_ceiling = np.abs(P[..., 2] - F.CEILING_Z) < 2e-3
        in_wall = np.zeros(depth.shape, bool)
        for lo, hi in F.WALL_BOXES.values():
            in_wall |= np.all((P >= np.asarray(lo) - 2e-3) & (P <= np.asarray(hi) + 2e-3), axis=-1)
        in_wall &= ~on_floor & ~on_ceiling
        for name, where in (("floor", on_floor), ("ceiling", on_ceiling), ("wall", in_wall)):
            agree[name].append(sems[ok & where] == sem[name])
        assert (ok & (on_floor | on_ceiling | in_wall)).sum() / ok.sum() > 0.99  # stage pixels are these
        walls = ok & (inst < FLOOR_ID_BASE)
        inside = []
        for iid in np.unique(inst[walls]):
            b = boxes[int(iid)]
            c, s = np.cos(b.yaw), np.sin(b.yaw)
            d = P[walls & (inst == iid)] - np.asarray(b.center)
            loc = np.stack([d[:, 0] * c + d[:, 1] * s, -d[:, 0] * s + d[:, 1] * c, d[:, 2]], axis=1)
            inside.append(np.all(np.abs(loc) <= np.asarray(b.size) / 2 + 0.02, axis=1))
        assert np.concatenate(inside).mean() > 0.97
    for name, a in agree.items():
        a = np.concatenate(a)
        assert len(a) > 100 and a.mean() > 0.99, (name, len(a), a.mean())


@pytest.fixture(scope="module")
def rcad_tours(tmp_path_factory, rcad):
    from synth.tour.render import TourSpec, render_tour

    F, root, lay = rcad
    base = tmp_path_factory.mktemp("rcad_tours")
    layout_file = save_layout(lay, base / "apt_0.yaml")
    path = base / "path.txt"
    write_tum(path, fixture_poses())
    common = dict(layout=str(layout_file), path=str(path), width=64, height=48, hfov_deg=75.0, chunk_size=2,
                  check_clearance=False)
    mb = render_tour(TourSpec(out=str(base / "blender"), lighting="day", renderer="blender", **common), progress=False)
    mf = render_tour(TourSpec(out=str(base / "fast"), renderer="fast", **common), progress=False)
    assert mb["complete"] and mf["complete"]
    return Tour(base / "blender"), Tour(base / "fast"), lay


@pytest.mark.slow
@pytest.mark.blender
def test_fixture_geometry_blender_matches_fast_renderer(rcad_tours):
    tb, tf, _ = rcad_tours
    for a, b in zip(tb, tf):
        assert_renders_agree(a, b)
    ids = set(np.unique(np.concatenate([f.instance.ravel() for f in tf])).tolist())
    assert 8 in ids and FLOOR_ID_BASE in ids  # the articulated counter and a derived floor are in view


@pytest.mark.blender
def test_fixture_textures_show_in_the_rgb(rcad_tours):
    """The textured objects and floor of the fixture keep their hue: the rendered mean inside each
    instance mask is closest (in chromaticity) to the texture the fixture painted on it."""
    tb, _, lay = rcad_tours
    F = fixture_module()
    want = {1: "frl_apartment_table_01", 8: "kitchen_counter:body", 4: "frl_apartment_sofa"}
    seen = 0
    for frame in tb:
        for iid, key in want.items():
            m = mask_of(frame.instance, iid)
            if m.sum() < 30:
                continue
            got = chroma(frame.rgb[m].mean(axis=0))
            dist = {k: np.abs(got - chroma(srgb_to_linear(c))).max() for k, c in F.TEXTURE_SRGB.items()}
            print(f"\nfixture object {iid}: chromaticity {np.round(got, 3)}, nearest texture {min(dist, key=dist.get)}")
            assert min(dist, key=dist.get) == key, (iid, got, dist)
            seen += 1
    assert seen >= 2


def test_floor_triangles_spanning_rooms_are_split_per_room(tmp_path):
    """One floor quad under two rooms: after splitting (synth.render.meshes.STAGE_MAX_EDGE) each room's floor
    id covers its own room (checked against the room rectangles), and the UVs are interpolated."""
    from replicacad_fixture import ROOMS, make_fixture

    from synth.render.meshes import STAGE_MAX_EDGE, layout_parts
    from synth.sources.replicacad.importer import load_replicacad

    lay = load_replicacad(make_fixture(tmp_path / "rc"), "apt_0")
    floors = [p for p in layout_parts(lay) if FLOOR_ID_BASE <= p.instance_id < CEILING_ID_BASE]
    rect = {FLOOR_ID_BASE + k: r.rect for k, r in enumerate(lay.stage.rooms)}
    assert len(rect) == len(ROOMS) == 2
    for p in floors:
        tri = p.world_vertices()[np.asarray(p.mesh.faces)]
        c = tri.mean(axis=1)
        x0, y0, x1, y1 = rect[p.instance_id]
        # every triangle's centroid within one split triangle of its own room
        assert np.all((c[:, 0] > x0 - STAGE_MAX_EDGE) & (c[:, 0] < x1 + STAGE_MAX_EDGE)), p.instance_id
        assert np.all((c[:, 1] > y0 - STAGE_MAX_EDGE) & (c[:, 1] < y1 + STAGE_MAX_EDGE)), p.instance_id
        edges = np.linalg.norm(tri - np.roll(tri, 1, axis=1), axis=2)
        top = tri[:, :, 2].max(axis=1) > -0.01
        assert edges[top].max() <= STAGE_MAX_EDGE + 1e-9
        assert p.mesh.visual.uv is not None and len(p.mesh.visual.uv) == len(p.mesh.vertices)
