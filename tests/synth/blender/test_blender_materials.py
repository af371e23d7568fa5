"""Procedural Cycles materials (synth.blender.materials).

bpy runs in ONE subprocess for this module (a module-scoped fixture): it builds every material,
checks the node trees, renders a tiny Cycles image (64x48, 16 samples, CPU) of a few cubes seen from
straight above by an orthographic camera and reports JSON; bpy state never reaches other tests.
"""
from __future__ import annotations

import json
import os
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

from synth.assets.materials import MATERIALS

REPO = Path(__file__).resolve().parents[3]

SCRIPT = textwrap.dedent(r'''
    import json, sys, time
    import bpy
    import numpy as np
    from synth.blender import materials as M
    from synth.blender.shading import set_emission

    out = sys.argv[1]
    res = {"materials": {}}
    bpy.ops.wm.read_factory_settings(use_empty=True)

    def describe(mat):
        nt = mat.node_tree
        outs = [n for n in nt.nodes if n.bl_idname == "ShaderNodeOutputMaterial"]
        em = nt.nodes.get("emission")
        return {
            "type": type(mat).__name__,
            "n_nodes": len(nt.nodes),
            "output_linked": bool(outs) and outs[0].inputs["Surface"].is_linked,
            "emission": None if em is None else {
                "strength": em.inputs["Strength"].default_value,
                "color": list(em.inputs["Color"].default_value),
                "strength_linked": em.inputs["Strength"].is_linked,
                "reaches_output": any(l.from_node == em for l in nt.links)},
        }

    for name in M.ALL_MATERIALS:
        res["materials"][name] = {"plain": describe(M.get_material(name)),
                                  "colored": describe(M.get_material(name, (0.2, 0.4, 0.6), seed=3)),
                                  "emissive": describe(M.get_material(name, emissive=True, key="k"))}

    a1 = M.get_material("fabric", (0.5, 0.1, 0.1))
    a2 = M.get_material("fabric", [0.5, 0.1, 0.1])
    b = M.get_material("fabric", (0.5, 0.1, 0.1), key="other")
    l1 = M.get_material("lamp_shade", key="L1")
    l2 = M.get_material("lamp_shade", key="L2")
    l1.node_tree.nodes["emission"].inputs["Strength"].default_value = 3.0
    l3 = M.get_material("diffuser", key="L3")
    set_emission(l3, 7.0, (1.0, 0.5, 0.25))
    em3 = l3.node_tree.nodes["emission"]
    res["set_emission"] = [em3.inputs["Strength"].default_value] + list(em3.inputs["Color"].default_value)[:3]
    try:
        set_emission(M.get_material("plastic"), 1.0)
        res["set_emission_plain_raises"] = False
    except ValueError:
        res["set_emission_plain_raises"] = True
    res["cache"] = {
        "same": a1 == a2 and a1.name == a2.name,
        "key_differs": b != a1 and b.name != a1.name,
        "lamps_differ": l1 != l2,
        "lamp2_strength": l2.node_tree.nodes["emission"].inputs["Strength"].default_value,
        "seed_differs": M.get_material("canvas", seed=1) != M.get_material("canvas", seed=2),
    }
    bpy.ops.wm.read_factory_settings(use_empty=True)  # cached materials are gone: rebuilt, not stale
    fresh = M.get_material("fabric", (0.5, 0.1, 0.1))
    res["cache"]["rebuilt_after_reset"] = fresh.name in bpy.data.materials and len(fresh.node_tree.nodes) > 2
    try:
        M.get_material("unobtainium")
        res["unknown_raises"] = False
    except ValueError:
        res["unknown_raises"] = True

    # ---- tiny render: cubes seen from above, orthographic, 16 px per metre -----------------
    bpy.ops.wm.read_factory_settings(use_empty=True)
    sc = bpy.context.scene
    sc.render.engine = "CYCLES"
    sc.cycles.device = "CPU"
    sc.cycles.samples = 16
    sc.cycles.use_denoising = False
    sc.cycles.max_bounces = 2
    sc.render.resolution_x, sc.render.resolution_y, sc.render.resolution_percentage = 64, 48, 100
    sc.render.image_settings.file_format = "PNG"
    sc.view_settings.view_transform = "Standard"
    sc.render.filepath = out + ".png"
    world = bpy.data.worlds.new("w"); sc.world = world; world.use_nodes = True
    world.node_tree.nodes["Background"].inputs["Strength"].default_value = 0.3

    def cube(name, x, y, mat):
        bpy.ops.mesh.primitive_cube_add(size=0.8, location=(x, y, 0.4))
        ob = bpy.context.object
        ob.name = name
        ob.data.materials.append(mat)

    plain = bpy.data.materials.new("plain"); plain.use_nodes = True
    plain.node_tree.nodes["Principled BSDF"].inputs["Base Color"].default_value = (0.4, 0.3, 0.2, 1)
    lamp_on = M.get_material("lamp_shade", key="on")
    lamp_off = M.get_material("lamp_shade", key="off")
    lamp_on.node_tree.nodes["emission"].inputs["Strength"].default_value = 5.0
    layout = {  # name: (x, y, material)
        "wood": (-1.3, 0.7, M.get_material("wood_light")),
        "tile": (0.0, 0.7, M.get_material("floor_tile")),
        "canvas": (1.3, 0.7, M.get_material("canvas", seed=5)),
        "plain": (-1.3, -0.7, plain),
        "lamp_on": (0.0, -0.7, lamp_on),
        "lamp_off": (1.3, -0.7, lamp_off),
    }
    for name, (x, y, mat) in layout.items():
        cube(name, x, y, mat)
    cam = bpy.data.cameras.new("cam"); cam.type = "ORTHO"; cam.ortho_scale = 4.0
    co = bpy.data.objects.new("cam", cam); sc.collection.objects.link(co); sc.camera = co
    co.location = (0.0, 0.0, 10.0)
    sun = bpy.data.lights.new("sun", "SUN"); sun.energy = 3.0
    so = bpy.data.objects.new("sun", sun); sc.collection.objects.link(so)
    so.rotation_euler = (0.3, 0.2, 0.0)
    t0 = time.time()
    bpy.ops.render.render(write_still=True)
    res["render_s"] = time.time() - t0
    img = bpy.data.images.load(out + ".png")
    px = np.array(img.pixels[:], dtype=np.float64).reshape(img.size[1], img.size[0], img.channels)[:, :, :3]
    lum = px @ np.array([0.2126, 0.7152, 0.0722])
    res["regions"] = {}
    for name, (x, y, _) in layout.items():
        cx, cy = int(round((x + 2.0) * 16)), int(round((y + 1.5) * 16))  # rows from the bottom
        reg = lum[cy - 4:cy + 4, cx - 4:cx + 4]
        res["regions"][name] = {"mean": float(reg.mean()), "std": float(reg.std()),
                                "rgb": px[cy - 4:cy + 4, cx - 4:cx + 4].reshape(-1, 3).mean(0).tolist()}
    with open(out, "w") as f:
        json.dump(res, f)
''')


@pytest.fixture(scope="module")
def report(tmp_path_factory):
    out = tmp_path_factory.mktemp("materials") / "report.json"
    env = dict(os.environ, PYTHONPATH=str(REPO) + os.pathsep + os.environ.get("PYTHONPATH", ""))
    r = subprocess.run([sys.executable, "-c", SCRIPT, str(out)], capture_output=True, text=True, timeout=300,
                       cwd=REPO, env=env)
    assert r.returncode == 0, r.stdout[-3000:] + r.stderr[-3000:]
    return json.loads(out.read_text())


STAGE = ("floor_wood", "floor_tile", "wall_paint", "ceiling_paint", "door_frame")


@pytest.mark.blender
def test_every_material_builds_with_a_connected_output(report):
    mats = report["materials"]
    assert set(mats) == set(MATERIALS) | set(STAGE)
    for name, variants in mats.items():
        for kind, d in variants.items():
            assert d["type"] == "Material", (name, kind)
            assert d["output_linked"], (name, kind)
            assert d["n_nodes"] <= 14, (name, kind, d["n_nodes"])  # light trees: render time matters


@pytest.mark.blender
def test_emissive_materials_have_an_emission_node_off_by_default(report):
    mats = report["materials"]
    for name, variants in mats.items():
        em = variants["emissive"]["emission"]
        assert em is not None, name
        assert em["strength"] == 0.0 and not em["strength_linked"] and em["reaches_output"], name
        always = name in ("lamp_shade", "diffuser")
        assert (variants["plain"]["emission"] is not None) == always, name
    # the emission colour defaults to the material colour
    assert mats["lamp_shade"]["colored"]["emission"]["color"][:3] == pytest.approx([0.2, 0.4, 0.6])


@pytest.mark.blender
def test_cache_reuses_materials_and_key_makes_them_unique(report):
    c = report["cache"]
    assert c["same"]
    assert c["rebuilt_after_reset"]
    assert c["key_differs"]
    assert c["lamps_differ"]
    assert c["lamp2_strength"] == 0.0  # changing one lamp leaves the other alone
    assert c["seed_differs"]
    assert report["unknown_raises"]
    assert report["set_emission"] == pytest.approx([7.0, 1.0, 0.5, 0.25])
    assert report["set_emission_plain_raises"]


@pytest.mark.blender
def test_render_shows_texture(report):
    reg = report["regions"]
    noise = reg["plain"]["std"]  # sampling noise on an untextured face
    for name in ("wood", "tile", "canvas"):
        assert reg[name]["std"] > max(0.01, 3.0 * noise), (name, reg[name], noise)
    assert max(reg["canvas"]["rgb"]) - min(reg["canvas"]["rgb"]) > 0.05  # colourful, not grey


@pytest.mark.blender
def test_emission_strength_brightens_a_lamp_shade(report):
    reg = report["regions"]
    assert reg["lamp_on"]["mean"] > reg["lamp_off"]["mean"] + 0.15, reg
    assert report["render_s"] < 30
