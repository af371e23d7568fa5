"""Translate a layout's render parts, a resolved lighting and a camera into a Blender scene.

Everything here is translation of plain data (``synth.render.meshes``, ``synth.scene.lighting``,
``vrformats.camera``); the conventions are decided there. The one conversion made here is the
camera's: an OpenCV camera-to-world pose becomes Blender's camera matrix (looking down -Z, +Y up)
through ``vrformats.camera.blender_from_opencv``, and the intrinsics become lens and shift.
"""

from __future__ import annotations

from . import require_python

require_python()  # before bpy: one line, not "No module named bpy", on another Python
import bpy  # noqa: E402
import numpy as np
from mathutils import Matrix, Vector

from vrformats.camera import Intrinsics, blender_from_opencv

from ..scene.lighting import ResolvedLighting


def reset_scene() -> bpy.types.Scene:
    bpy.ops.wm.read_factory_settings(use_empty=True)
    scene = bpy.context.scene
    scene.render.engine = "CYCLES"
    return scene


def add_parts(scene, parts, with_materials: bool) -> dict[str, bpy.types.Material]:
    """One Blender object per part, mesh in the part's local frame, ``pass_index`` = instance id.

    With materials, a part whose material is ``"gltf"`` (``synth.render.meshes.GLTF_MATERIAL``) gets its
    UVs (a UV map "UVMap", per loop), its glTF normals when the file has them (custom normals on
    smooth faces) and a material built from its glTF PBR material
    (``synth.blender.gltf_materials.get_gltf_material``); the geometry pass (no materials) builds the
    same plain meshes as for procedural parts.

    Returns the materials of emitting parts by fixture id (for the lighting to switch)."""
    from ..render.meshes import GLTF_MATERIAL

    emitters: dict[str, list] = {}
    coll = scene.collection
    if with_materials:
        from ..mesh.gltf import pbr
        from .gltf_materials import get_gltf_material
        from .materials import get_material
    for p in parts:
        gltf = with_materials and p.material == GLTF_MATERIAL
        mesh = bpy.data.meshes.new(p.name)
        v = np.asarray(p.mesh.vertices, dtype=np.float32)
        f = np.asarray(p.mesh.faces, dtype=np.int32)
        mesh.vertices.add(len(v))
        mesh.vertices.foreach_set("co", v.ravel())
        mesh.loops.add(f.size)
        mesh.loops.foreach_set("vertex_index", f.ravel())
        mesh.polygons.add(len(f))
        mesh.polygons.foreach_set("loop_start", np.arange(0, f.size, 3, dtype=np.int32))
        mesh.polygons.foreach_set("loop_total", np.full(len(f), 3, dtype=np.int32))
        normals = None
        if gltf:
            uv = getattr(p.mesh.visual, "uv", None)
            if uv is not None:
                layer = mesh.uv_layers.new(name="UVMap")
                layer.data.foreach_set("uv", np.asarray(uv, dtype=np.float32)[f.ravel()].ravel())
            if p.mesh.metadata.get("gltf", {}).get("normals"):
                normals = np.asarray(p.mesh.vertex_normals, dtype=np.float32)
                mesh.polygons.foreach_set("use_smooth", np.ones(len(f), dtype=bool))
        mesh.update(calc_edges=True)
        mesh.validate(verbose=False)
        if normals is not None and len(mesh.vertices) == len(normals):
            mesh.normals_split_custom_set_from_vertices(normals)
        obj = bpy.data.objects.new(p.name, mesh)
        obj.matrix_world = Matrix(np.asarray(p.matrix).tolist())
        obj.pass_index = int(p.instance_id)
        if with_materials:
            key = p.fixture if p.emissive else None
            if gltf:
                mat = get_gltf_material(pbr(p.mesh), emissive=p.emissive, key=key)
            else:
                mat = get_material(p.material, p.color, p.emissive, key=key, seed=p.seed)
            mesh.materials.append(mat)
            if p.emissive and p.fixture and mat.node_tree.nodes.get("emission") is not None:
                emitters.setdefault(p.fixture, []).append(mat)
        coll.objects.link(obj)
    return emitters


def set_camera(scene, intr: Intrinsics) -> bpy.types.Object:
    cam = bpy.data.cameras.new("camera")
    cam.sensor_fit = "HORIZONTAL"
    cam.sensor_width = 36.0
    cam.lens = intr.fx * cam.sensor_width / intr.width
    # Blender puts the principal point at the image centre (continuous coordinates w/2, h/2) plus
    # a shift in units of the larger image side; OpenCV pixel centres sit at integers, so the
    # continuous coordinate of cx is cx + 0.5.
    big = max(intr.width, intr.height)
    cam.shift_x = (intr.cx + 0.5 - intr.width / 2.0) / big
    cam.shift_y = -(intr.cy + 0.5 - intr.height / 2.0) / big
    cam.clip_start = 0.01
    cam.clip_end = 200.0
    obj = bpy.data.objects.new("camera", cam)
    scene.collection.objects.link(obj)
    scene.camera = obj
    r = scene.render
    r.resolution_x, r.resolution_y, r.resolution_percentage = intr.width, intr.height, 100
    r.pixel_aspect_x = r.pixel_aspect_y = 1.0
    return obj


def place_camera(cam_obj, T_world_cam: np.ndarray) -> None:
    cam_obj.matrix_world = Matrix(blender_from_opencv(np.asarray(T_world_cam)).tolist())


def _aim(obj, direction, up=(0.0, 0.0, 1.0)) -> None:
    """Orient an object so its local -Z points along ``direction`` (Blender lights shine along -Z)."""
    d = Vector(direction).normalized()
    obj.rotation_mode = "QUATERNION"
    obj.rotation_quaternion = d.to_track_quat("-Z", "Y" if abs(d.z) < 0.99 else "X")


def add_lighting(scene, lighting: ResolvedLighting, emitters: dict[str, list]) -> None:
    world = bpy.data.worlds.new("world")
    scene.world = world
    world.use_nodes = True
    bg = world.node_tree.nodes["Background"]
    bg.inputs["Color"].default_value = (*lighting.sky_color, 1.0)
    bg.inputs["Strength"].default_value = lighting.sky_strength
    for L in lighting.lights:
        if L.kind == "sun":
            data = bpy.data.lights.new(L.name, "SUN")
            data.energy = L.power
            data.angle = L.angle
        elif L.kind == "point":
            data = bpy.data.lights.new(L.name, "POINT")
            data.energy = L.power
            data.shadow_soft_size = L.size[0]
        else:  # area light or light portal
            data = bpy.data.lights.new(L.name, "AREA")
            data.shape = "RECTANGLE"
            data.size, data.size_y = L.size
            data.energy = L.power
            if L.kind == "portal":
                data.cycles.is_portal = True
        data.color = L.color
        obj = bpy.data.objects.new(L.name, data)
        obj.location = L.position
        if L.kind in ("sun", "area", "portal"):
            _aim(obj, L.direction)
        scene.collection.objects.link(obj)
    for fixture, mats in emitters.items():
        color, strength = lighting.emission.get(fixture, ((1.0, 1.0, 1.0), 0.0))
        for mat in mats:
            node = mat.node_tree.nodes.get("emission")
            if node is None:
                continue
            light = mat.node_tree.nodes.get("emission_light")  # glTF emitters: texture x factor x light colour
            if light is not None:
                light.outputs[0].default_value = (*color, 1.0)
            else:
                node.inputs["Color"].default_value = (*color, 1.0)
            node.inputs["Strength"].default_value = strength


def choose_device(scene, device: str) -> str:
    """Use the GPU (OptiX, else CUDA, else HIP/oneAPI/Metal) when asked or when 'auto' finds one."""
    if device == "cpu":
        scene.cycles.device = "CPU"
        return "CPU"
    prefs = bpy.context.preferences.addons["cycles"].preferences
    for backend in ("OPTIX", "CUDA", "HIP", "ONEAPI", "METAL"):
        try:
            prefs.compute_device_type = backend
        except TypeError:
            continue
        prefs.get_devices()
        gpus = [d for d in prefs.devices if d.type == backend]
        if gpus:
            for d in prefs.devices:
                d.use = d.type == backend
            scene.cycles.device = "GPU"
            return backend
    if device == "gpu":
        raise RuntimeError("no GPU found by Cycles (OptiX, CUDA, HIP, oneAPI, Metal); use --device cpu")
    scene.cycles.device = "CPU"
    return "CPU"


def configure_geometry(scene) -> None:
    """One sample through each pixel centre: exact depth and ids, no anti-aliasing."""
    c = scene.cycles
    c.samples = 1
    c.use_adaptive_sampling = False
    c.use_denoising = False
    c.filter_width = 0.01
    c.max_bounces = 0
    c.caustics_reflective = c.caustics_refractive = False
    vl = scene.view_layers[0]
    vl.use_pass_z = True
    vl.use_pass_object_index = True


def configure_rgb(scene, q: dict, seed: int) -> None:
    c = scene.cycles
    c.samples = int(q["samples"])
    c.use_adaptive_sampling = True
    c.adaptive_threshold = float(q["adaptive_threshold"])
    c.max_bounces = int(q["max_bounces"])
    c.diffuse_bounces = int(q["diffuse_bounces"])
    c.glossy_bounces = int(q["glossy_bounces"])
    c.transmission_bounces = int(q["transmission_bounces"])
    c.use_denoising = bool(q["denoise"])
    if c.use_denoising:
        c.denoiser = "OPENIMAGEDENOISE"
        c.denoising_prefilter = q.get("denoise_prefilter", "ACCURATE")
    c.seed = int(seed)
    scene.render.use_persistent_data = True  # keep the BVH between frames of a chunk
    scene.view_settings.view_transform = "Standard"


def configure_output(scene, filepath: str) -> None:
    s = scene.render.image_settings
    s.file_format = "OPEN_EXR_MULTILAYER"
    s.color_depth = "32"
    s.exr_codec = "ZIP"
    scene.render.filepath = filepath
    scene.render.use_compositing = False
    scene.render.use_sequencer = False
