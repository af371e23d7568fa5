"""KHR_texture_transform (offset, rotation, scale) in synth.mesh.gltf, the fast renderer's texture lookup
and the Blender material translation.

The expected values come from the extension's own text, worked by hand: its first example
(offset [0, 1], rotation pi/2, scale [0.5, 0.5]) "utilizes only the lower left quadrant of the
source image, rotated clockwise 90 degrees", its second (offset [0, 1], scale [1, -1]) inverts the
T axis. The rendered scene is one flat square whose glTF UVs span [0, 1]^2 with a 4 x 4 grid of
colour cells as its texture and the first example as its transform: at the centre of each quarter
of the square the cell seen is worked out by hand below (and it differs from what no rotation, the
transposed rotation or no transform at all would show). Blender's own glTF importer
(io_scene_gltf2) renders the same file as an independent reference.

Blender runs in a subprocess (tiny image, few samples); that test carries the ``blender`` marker.
"""

from __future__ import annotations

import json
import math
import os
import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np
import pytest
import trimesh
from PIL import Image
from tests.synth.blender.test_gltf_render import glb_chunks, srgb_to_linear, stage_meshes, write_glb, write_glb_chunks, write_json
from trimesh.visual import TextureVisuals
from trimesh.visual.material import PBRMaterial

from vrformats.camera import Intrinsics, pose_from_ypr
from vrformats.errors import SceneFormatError

REPO = Path(__file__).resolve().parents[3]
RCAD = Path("/work/rcad_git/replica_cad/objects")  # the real files, where this machine has them
C = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, -1.0], [0.0, 1.0, 0.0]])  # habitat (Y up) -> ours (Z up), by hand
SCENE = "tt_test"
SPEC_EXAMPLE = {"offset": [0.0, 1.0], "rotation": 1.57079632679, "scale": [0.5, 0.5]}
PLANE_Z = 0.05  # the square's height over the floor (ours)
CELL = 16  # texels per cell side; the texture is 4 x 4 cells

# sRGB 8-bit colour of cell (row from the top, column from the left): 16 distinct, well-separated colours
CELLS = np.array([
    [(230, 30, 30), (30, 200, 60), (40, 60, 220), (240, 220, 40)],
    [(240, 120, 20), (20, 200, 200), (200, 40, 200), (120, 60, 20)],
    [(250, 250, 250), (20, 20, 20), (120, 200, 40), (40, 120, 240)],
    [(240, 150, 180), (90, 30, 140), (160, 160, 160), (200, 180, 120)],
], np.uint8)


def cell_texture() -> Image.Image:
    return Image.fromarray(np.kron(CELLS, np.ones((CELL, CELL, 1), np.uint8)).astype(np.uint8), "RGB")


# ---- the transform itself -------------------------------------------------------------------------


def test_spec_examples_by_hand():
    from synth.mesh.gltf import uv_transform_matrix

    M = uv_transform_matrix(SPEC_EXAMPLE, "gltf")
    corners = np.array([[0, 0, 1], [1, 0, 1], [0, 1, 1], [1, 1, 1]], float).T
    out = (M @ corners)[:2].T
    # worked by hand: S -> (u/2, v/2); R(pi/2) = [[0, 1], [-1, 0]] -> (v/2, -u/2); + (0, 1)
    assert out == pytest.approx(np.array([[0.0, 1.0], [0.0, 0.5], [0.5, 1.0], [0.5, 0.5]]), abs=1e-9)
    # "only the lower left quadrant" (glTF v points down): u' in [0, 0.5], v' in [0.5, 1]
    assert out[:, 0].min() >= -1e-9 and out[:, 0].max() <= 0.5 + 1e-9 and out[:, 1].min() >= 0.5 - 1e-9
    # the image's top-left corner (uv' = (0, 0.5) of the quadrant) is drawn where uv = (1, 0): the
    # quadrant turned clockwise by 90 degrees on the surface
    inv = np.linalg.inv(M) @ np.array([0.0, 0.5, 1.0])
    assert inv[:2] == pytest.approx([1.0, 0.0], abs=1e-9)
    flip = uv_transform_matrix({"offset": [0.0, 1.0], "scale": [1.0, -1.0]}, "gltf")
    assert (flip @ np.array([0.3, 0.2, 1.0]))[:2] == pytest.approx([0.3, 0.8])  # inverts the T axis
    assert np.allclose(uv_transform_matrix(None), np.eye(3)) and np.allclose(uv_transform_matrix({}), np.eye(3))


def test_trimesh_convention_and_blender_mapping_agree():
    """The transform on trimesh/Blender UVs (u, 1 - v) is F M F, and the Blender Mapping node's
    values (Location + Rz(r) (Scale * uv), Rz counter-clockwise) give the same map."""
    from synth.mesh.gltf import blender_mapping, uv_transform_matrix

    rng = np.random.default_rng(4)
    for _ in range(20):
        t = {"offset": list(rng.uniform(-2, 2, 2)), "rotation": float(rng.uniform(-4, 4)),
             "scale": list(rng.uniform(-3, 3, 2))}
        uv_g = rng.uniform(-1, 2, (10, 2))
        M = uv_transform_matrix(t, "gltf")
        want_g = uv_g @ M[:2, :2].T + M[:2, 2]
        uv_t = np.column_stack([uv_g[:, 0], 1 - uv_g[:, 1]])
        Mt = uv_transform_matrix(t)
        got_t = uv_t @ Mt[:2, :2].T + Mt[:2, 2]
        assert got_t == pytest.approx(np.column_stack([want_g[:, 0], 1 - want_g[:, 1]]), abs=1e-9)
        m = blender_mapping(t)
        r = m["rotation"][2]
        Rz = np.array([[math.cos(r), -math.sin(r)], [math.sin(r), math.cos(r)]])
        node = (uv_t * np.asarray(m["scale"][:2])) @ Rz.T + np.asarray(m["location"][:2])
        assert node == pytest.approx(got_t, abs=1e-9)


# ---- the test GLB ---------------------------------------------------------------------------------


def plane_mesh(size=1.0) -> trimesh.Trimesh:
    """A square in OUR frame (x, y in [-size/2, size/2], z = 0, facing +z), written in habitat's
    frame (v_h = C^T v); glTF UVs u = x/size + 1/2, v = 1/2 - y/size (image top at +y)."""
    h = size / 2
    v = np.array([[-h, -h, 0.0], [h, -h, 0.0], [h, h, 0.0], [-h, h, 0.0]])
    f = np.array([[0, 1, 2], [0, 2, 3]])
    uv_gltf = np.column_stack([v[:, 0] / size + 0.5, 0.5 - v[:, 1] / size])
    m = trimesh.Trimesh(v @ C, f, process=False)  # rows: v_h = C^T v
    m.visual = TextureVisuals(uv=np.column_stack([uv_gltf[:, 0], 1 - uv_gltf[:, 1]]), material=PBRMaterial(
        name="cells", baseColorTexture=cell_texture(), baseColorFactor=[1.0, 1.0, 1.0, 1.0], metallicFactor=0.0,
        roughnessFactor=1.0))
    return m


def with_transform(path: Path, transform: dict | None, slot=("pbrMetallicRoughness", "baseColorTexture")) -> Path:
    """Write ``transform`` as the KHR_texture_transform of the GLB's first material's slot."""
    doc, binary = glb_chunks(path)
    info = doc["materials"][0][slot[0]][slot[1]] if slot[0] else doc["materials"][0][slot[1]]
    info.setdefault("extensions", {})["KHR_texture_transform"] = transform
    doc["extensionsUsed"] = sorted(set(doc.get("extensionsUsed", [])) | {"KHR_texture_transform"})
    doc["extensionsRequired"] = ["KHR_texture_transform"]
    write_glb_chunks(path, doc, binary)
    return path


def make_dataset(root: Path) -> Path:
    write_glb(root / "stages/stage.glb", stage_meshes())
    write_glb(root / "objects/cells.glb", [plane_mesh()])
    with_transform(root / "objects/cells.glb", SPEC_EXAMPLE)
    write_json(root / "configs/stages/stage.stage_config.json", {"render_asset": "../../stages/stage.glb"})
    write_json(root / "configs/objects/cells.object_config.json", {"render_asset": "../../objects/cells.glb"})
    write_json(root / "replicaCAD.scene_dataset_config.json", {"objects": {"paths": {".json": ["configs/objects"]}}})
    write_json(root / f"configs/scenes/{SCENE}.scene_instance.json", {
        "stage_instance": {"template_name": "stages/stage"}, "translation_origin": "asset_local",
        "object_instances": [{"template_name": "objects/cells", "translation": [0.0, PLANE_Z, 0.0],
                              "rotation": [1, 0, 0, 0], "motion_type": "STATIC"}]})
    return root


@pytest.fixture(scope="module")
def dataset(tmp_path_factory) -> Path:
    return make_dataset(tmp_path_factory.mktemp("tt_dataset"))


def test_transform_is_recorded_and_applied_to_the_uvs(dataset):
    from synth.mesh.gltf import check_glb, load_glb_parts, pbr, texture_uv

    path = dataset / "objects/cells.glb"
    check_glb(path)
    (part,) = load_glb_parts(path)
    t = pbr(part)["texture_transforms"]
    assert set(t) == {"baseColorTexture"}
    assert t["baseColorTexture"]["offset"] == [0.0, 1.0] and t["baseColorTexture"]["scale"] == [0.5, 0.5]
    assert t["baseColorTexture"]["rotation"] == pytest.approx(math.pi / 2, abs=1e-10)
    assert t["baseColorTexture"]["texCoord"] is None
    # the plane's corners (ours) and their sampling coordinates (trimesh convention), by hand:
    # glTF uv' = (v/2, 1 - u/2) -> trimesh (v/2, u/2) with u = x + 1/2, v = 1/2 - y
    v = np.asarray(part.vertices)
    u_g, v_g = v[:, 0] + 0.5, 0.5 - v[:, 1]
    assert texture_uv(part) == pytest.approx(np.column_stack([v_g / 2, u_g / 2]), abs=1e-9)
    assert texture_uv(part, "normalTexture") == pytest.approx(np.asarray(part.visual.uv))  # no transform there


@pytest.mark.parametrize("transform, field, match", [
    ({"scale": [1.0]}, "scale", "expected 2 numbers"),
    ({"offset": "left"}, "offset", "expected 2 numbers"),
    ({"rotation": "a lot"}, "rotation", "expected a finite number"),
    ({"texCoord": -1}, "texCoord", "integer >= 0"),
    ([1, 2], None, "expected a JSON object"),
])
def test_malformed_transform_names_the_field(tmp_path, transform, field, match):
    from synth.mesh.gltf import check_glb, load_glb_parts

    path = write_glb_and_transform(tmp_path, transform)
    want = "materials[0].pbrMetallicRoughness.baseColorTexture.extensions.KHR_texture_transform"
    for fn in (check_glb, load_glb_parts):
        with pytest.raises(SceneFormatError, match=match) as e:
            fn(path)
        assert e.value.file == str(path) and e.value.field == (want + "." + field if field else want)
        assert len(str(e.value).splitlines()) == 1


def write_glb_and_transform(tmp_path, transform, slot=("pbrMetallicRoughness", "baseColorTexture")) -> Path:
    path = tmp_path / "t.glb"
    write_glb(path, [plane_mesh()])
    return with_transform(path, transform, slot)


def test_other_texcoord_set_is_logged_once(tmp_path, caplog):
    from synth.mesh import gltf

    path = write_glb_and_transform(tmp_path, {"scale": [2.0, 2.0], "texCoord": 1})
    with caplog.at_level("WARNING", logger="synth.mesh.gltf"):
        gltf.load_glb_parts(path)
        gltf.clear_cache()
        gltf.load_glb_parts(path)
    msgs = [r.getMessage() for r in caplog.records if "texture coordinate set" in r.getMessage()]
    assert len(msgs) == 1 and str(path) in msgs[0] and "baseColorTexture: 1" in msgs[0]


def test_emissive_slot_transform(tmp_path):
    """Transforms of other slots are recorded under their own slot name."""
    from synth.mesh.gltf import load_glb_parts, texture_uv

    path = tmp_path / "e.glb"
    m = plane_mesh()
    m.visual.material.emissiveTexture = cell_texture()
    m.visual.material.emissiveFactor = [1.0, 1.0, 1.0]
    write_glb(path, [m])
    with_transform(path, {"offset": [0.25, 0.0]}, (None, "emissiveTexture"))
    (part,) = load_glb_parts(path)
    assert set(part.metadata["gltf"]["texture_transforms"]) == {"emissiveTexture"}
    assert texture_uv(part, "emissiveTexture") == pytest.approx(np.asarray(part.visual.uv) + [0.25, 0.0])
    assert texture_uv(part) == pytest.approx(np.asarray(part.visual.uv))


@pytest.mark.skipif(not RCAD.is_dir(), reason="the real ReplicaCAD objects are not on this machine")
@pytest.mark.parametrize("name", ["frl_apartment_bin_01", "frl_apartment_cloth_03", "frl_apartment_vase_01"])
def test_real_replicacad_glbs_load_with_their_transform(name):
    """The three ReplicaCAD objects that use the extension (the only ones; extensionsRequired): offset
    (0, 0.99), scale 0.01, so each samples the 1 % corner patch at the image's bottom-left."""
    from synth.mesh.gltf import check_glb, load_glb_parts, pbr, texture_uv

    path = RCAD / f"{name}.glb"
    doc = check_glb(path)
    assert "KHR_texture_transform" in doc.get("extensionsRequired", [])
    parts = load_glb_parts(path)
    t = pbr(parts[0])["texture_transforms"]["baseColorTexture"]
    assert t["offset"] == pytest.approx([0.0, 0.99]) and t["scale"] == pytest.approx([0.01, 0.01])
    assert t["rotation"] == 0.0
    uv = texture_uv(parts[0])
    assert uv.min() >= 0.0 and uv.max() <= 0.01 + 1e-6  # trimesh convention: the bottom-left corner


# ---- the fast renderer's lookup and Blender ---------------------------------------------------------

W = H = 48
HFOV = 50.0
POSE = pose_from_ypr((0.0, 0.0, PLANE_Z + 1.6), yaw=0.3, pitch=-np.pi / 2)  # straight down, turned a little
PROBES = [(0.25, 0.25), (-0.25, 0.25), (-0.25, -0.25), (0.25, -0.25)]  # centres of the square's quarters (ours)


def expected_cells() -> list[tuple[int, int]]:
    """(row, column) of the cell seen at each probe, by hand: u = x + 1/2, v = 1/2 - y;
    uv' = (v/2, 1 - u/2) (the spec example worked out above); cell = (floor(4 v'), floor(4 u'))."""
    out = []
    for x, y in PROBES:
        u, v = x + 0.5, 0.5 - y
        uu, vv = v / 2, 1 - u / 2
        out.append((int(4 * vv), int(4 * uu)))
    return out


def probe_pixels(intr: Intrinsics) -> list[tuple[int, int]]:
    """(row, column) of each probe point, projected with the pinhole model here."""
    R, t = POSE[:3, :3], POSE[:3, 3]
    out = []
    for x, y in PROBES:
        pc = R.T @ (np.array([x, y, PLANE_Z]) - t)
        out.append((int(round(intr.fy * pc[1] / pc[2] + intr.cy)), int(round(intr.fx * pc[0] / pc[2] + intr.cx))))
    return out


def test_expected_cells_tell_the_variants_apart():
    cells = expected_cells()
    assert cells == [(2, 0), (3, 0), (3, 1), (2, 1)]  # all in the lower-left quadrant, turned
    assert len(set(cells)) == 4

    def seen(f):  # cell at each probe for uv' = f(u, v) (glTF convention, REPEAT wrapping)
        out = []
        for x, y in PROBES:
            uu, vv = f(x + 0.5, 0.5 - y)
            out.append((int(4 * (vv % 1.0)), int(4 * (uu % 1.0))))
        return out

    variants = {"no transform": seen(lambda u, v: (u, v)),
                "no rotation": seen(lambda u, v: (u / 2, v / 2 + 1)),
                "transposed rotation (the README's GLSL)": seen(lambda u, v: (-v / 2, u / 2 + 1))}
    for name, other in variants.items():
        assert sum(a != b for a, b in zip(cells, other)) >= 3, name


@pytest.fixture(scope="module")
def layout(dataset):
    from synth.sources.replicacad.importer import load_replicacad

    return load_replicacad(dataset, SCENE, allow_unknown=True, structure=False)


def test_fast_renderer_shows_the_transformed_texture(layout, dataset):
    from synth.render.fast_render import FastRenderer

    intr = Intrinsics.from_fov(W, H, HFOV)
    fr = FastRenderer(layout)
    albedo = fr.render_base_color(POSE, intr)
    depth, inst, _ = fr.render(POSE, intr)
    assert albedo.shape == (H, W, 3) and albedo.dtype == np.float32
    for (r, c), (i, j) in zip(probe_pixels(intr), expected_cells()):
        assert inst[r, c] == 1 and depth[r, c] == pytest.approx(1.6, abs=1e-4)
        want = srgb_to_linear(CELLS[i, j])
        assert albedo[r, c] == pytest.approx(want, abs=2e-3), ((r, c), (i, j))
    # the stage's floor around it: its plain baseColorFactor, as written in the file
    doc, _ = glb_chunks(dataset / "stages/stage.glb")
    factors = [m["pbrMetallicRoughness"]["baseColorFactor"][:3] for m in doc["materials"]]
    floor = (inst == 1000) & (depth > 1.6)
    assert floor.any() and np.allclose(albedo[floor], factors[0], atol=1e-6)
    assert np.all(albedo[depth == 0] == 0.0)


BLENDER_SCRIPT = textwrap.dedent(r'''
    import json, sys
    import numpy as np
    import bpy
    from vrformats.camera import Intrinsics
    from synth.blender import scene_builder as sb
    from synth.blender.worker import read_blender_exr
    from synth.mesh.gltf import load_glb_parts
    from synth.render.meshes import RenderPart

    args = json.loads(sys.argv[1])
    intr = Intrinsics.from_dict(args["intrinsics"])
    out, res = args["out"], {}
    M = np.eye(4); M[2, 3] = args["z"]
    for mode in ("ours", "importer"):
        scene = sb.reset_scene()
        if mode == "ours":
            (part,) = load_glb_parts(args["glb"])
            sb.add_parts(scene, [RenderPart("plane", 1, 1, "gltf", part, M)], with_materials=True)
            mat = bpy.data.objects["plane"].data.materials[0]
            res["nodes"] = sorted(n.bl_idname for n in mat.node_tree.nodes)
            mp = next(n for n in mat.node_tree.nodes if n.bl_idname == "ShaderNodeMapping")
            res["mapping"] = {k: list(mp.inputs[k].default_value) for k in ("Location", "Rotation", "Scale")}
        else:
            before = set(bpy.data.objects)
            bpy.ops.import_scene.gltf(filepath=args["glb"])
            for ob in set(bpy.data.objects) - before:
                if ob.parent is None:
                    ob.location = (ob.location[0], ob.location[1], ob.location[2] + args["z"])
        world = bpy.data.worlds.new("w"); scene.world = world; world.use_nodes = True
        bg = world.node_tree.nodes["Background"]
        bg.inputs["Color"].default_value = (1.0, 1.0, 1.0, 1.0); bg.inputs["Strength"].default_value = 1.0
        cam = sb.set_camera(scene, intr)
        sb.place_camera(cam, np.asarray(args["pose"]))
        sb.choose_device(scene, "cpu")
        scene.cycles.samples = 8; scene.cycles.use_denoising = False; scene.cycles.seed = 1
        scene.cycles.max_bounces = 2
        scene.view_settings.view_transform = "Standard"
        sb.configure_output(scene, f"{out}/{mode}.exr")
        bpy.ops.render.render(write_still=True)
        res[mode] = read_blender_exr(f"{out}/{mode}.exr")["Combined"][..., :3].tolist()
    with open(f"{out}/report.json", "w") as f:
        json.dump(res, f)
''')


@pytest.mark.blender
def test_blender_shows_the_transformed_texture(tmp_path, dataset):
    """Our material (a Mapping node between UV map and image) and Blender's own glTF importer,
    under a uniform white sky: at each probe pixel the colour is the cell worked out by hand."""
    from synth.mesh.gltf import blender_mapping

    intr = Intrinsics.from_fov(W, H, HFOV)
    args = {"glb": str(dataset / "objects/cells.glb"), "intrinsics": intr.to_dict(), "pose": POSE.tolist(),
            "z": PLANE_Z, "out": str(tmp_path)}
    env = dict(os.environ, PYTHONPATH=str(REPO) + os.pathsep + os.environ.get("PYTHONPATH", ""))
    r = subprocess.run([sys.executable, "-c", BLENDER_SCRIPT, json.dumps(args)], capture_output=True, text=True,
                       timeout=600, cwd=REPO, env=env)
    assert r.returncode == 0, r.stdout[-3000:] + r.stderr[-3000:]
    rep = json.loads((tmp_path / "report.json").read_text())
    assert "ShaderNodeMapping" in rep["nodes"] and "ShaderNodeUVMap" in rep["nodes"]
    m = blender_mapping(SPEC_EXAMPLE)
    assert rep["mapping"]["Location"] == pytest.approx(list(m["location"]), abs=1e-6)
    assert rep["mapping"]["Rotation"] == pytest.approx(list(m["rotation"]), abs=1e-6)
    ours, theirs = np.asarray(rep["ours"]), np.asarray(rep["importer"])
    palette = srgb_to_linear(CELLS.reshape(-1, 3))
    for (r_, c), (i, j) in zip(probe_pixels(intr), expected_cells()):
        want = srgb_to_linear(CELLS[i, j])
        for name, img in (("ours", ours), ("importer", theirs)):
            got = img[r_ - 1: r_ + 2, c - 1: c + 2].reshape(-1, 3).mean(axis=0)  # 3 x 3 pixels, inside the cell
            # a rough dielectric under a uniform white sky: albedo plus a few per cent of neutral
            # specular reflection; the nearest of the 16 cell colours must be the expected one
            nearest = int(np.argmin(np.abs(palette - got).sum(axis=1)))
            print(f"\n{name} at {(r_, c)}: {np.round(got, 3)}, cell {(i, j)} {np.round(want, 3)}")
            assert nearest == 4 * i + j, (name, (r_, c), got, want)
            assert np.all(np.abs(got - want) <= 0.06 + 0.1 * want), (name, got, want)
        a = ours[r_ - 1: r_ + 2, c - 1: c + 2].reshape(-1, 3).mean(axis=0)
        b = theirs[r_ - 1: r_ + 2, c - 1: c + 2].reshape(-1, 3).mean(axis=0)
        assert np.all(np.abs(a - b) <= 0.1 * np.maximum(b, 0.02) + 0.01), (a, b)
