"""A ReplicaCAD dataset root made of the REAL dataset's text files, with box stand-ins for its meshes.

``write_real_fixture(dir) -> Path`` writes it (about a second): the files vendored under
``tests/data/replicacad/files/`` unchanged (the scene dataset config, ``configs/scenes/apt_0..apt_5``,
every object, stage and lighting config, the semantic lexicon, every URDF and ``*.ao_config.json``,
the ``empty_stage`` and ``apt_0..apt_5`` navmeshes), plus

* a box GLB for every object GLB and URDF link GLB of the real dataset, at the bounds the real GLB
  has in its own (Y-up) frame (``tests/data/replicacad/glb_bounds.json``, measured once from the
  real files through ``synth.mesh.gltf.glb_geometry``; the three GLBs the public copy lacks have the
  bounds of their collision asset, or of a sibling: see the table's ``source``). Each box has a
  base colour factor; the first ``TEXTURED`` of them also a 4 x 4 base-colour texture with UVs.
* the stand-in stage ``stages/frl_apartment_stage.glb`` (and its stage card), built by
  ``synth.sources.replicacad.stages.fill`` under the ``standin`` variant, the way
  ``tools/replicacad_standin.py`` builds the real data's: from the vendored empty-stage navmesh,
  the floor at z 0 (the median bottom of the scenes' objects, here the box GLBs), the floor holding
  the box of every object of apt_0..apt_5 (+2 cm, to the cell for those hung on walls or standing on
  furniture; all but one apt_2 shoe that stands outside), each added cell on the level the object
  stands on, no window behind one. The four ``Stage_v3_sc*`` stage configs are vendored but their GLBs are not written
  (no v3 scene is vendored); collision assets (``objects/convex/``) are not written either.

``python tests/replicacad_real_fixture.py --vendor SRC`` (re)vendors from a real ReplicaCAD folder
(SRC = ``replica_cad/`` of github angli66/SAPIEN-ReplicaCAD) and rewrites the manifest (sha256 of
every vendored file) and the bounds table; ``python tests/replicacad_real_fixture.py OUT`` writes a
fixture for demos. Licence of the vendored files: CC BY-NC 4.0 (``tests/data/replicacad/LICENSE.txt``).
"""

from __future__ import annotations

import hashlib
import json
import shutil
import sys
from pathlib import Path

import numpy as np

DATA = Path(__file__).resolve().parent / "data" / "replicacad"
FILES = DATA / "files"
MANIFEST = DATA / "MANIFEST.json"
BOUNDS = DATA / "glb_bounds.json"
STAGE_GLB = "stages/frl_apartment_stage.glb"
STAGE_NAVMESH = "navmeshes/empty_stage.navmesh"
STAGE_FLOOR_Z = 0.0
TEXTURED = 4
VENDORED_GLOBS = (
    "replicaCAD.scene_dataset_config.json",
    "configs/scenes/apt_[0-5].scene_instance.json",
    "configs/objects/*.object_config.json",
    "configs/stages/*.stage_config.json",
    "configs/lighting/*.lighting_config.json",
    "configs/ssd/replicaCAD_semantic_lexicon.json",
    "urdf/*/*.urdf",
    "urdf/*/*.ao_config.json",
    "navmeshes/empty_stage.navmesh",
    "navmeshes/apt_[0-5].navmesh",
)
_C = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, -1.0], [0.0, 1.0, 0.0]])  # habitat -> ours (synth.sources.replicacad.habitat_format)


def sha256(path: Path) -> str:
    return hashlib.sha256(Path(path).read_bytes()).hexdigest()


def manifest() -> dict[str, str]:
    return json.loads(MANIFEST.read_text())["sha256"]


def bounds_table() -> dict[str, dict]:
    return json.loads(BOUNDS.read_text())["glbs"]


def _colour(rel: str) -> list[float]:
    h = hashlib.sha256(rel.encode()).digest()
    return [round(0.25 + 0.6 * h[k] / 255.0, 3) for k in range(3)] + [1.0]


def box_glb(path: Path, lo, hi, colour, textured: bool) -> None:
    """A box with bounds [lo, hi] (GLB frame, Y up) and one PBR material."""
    import trimesh
    from PIL import Image
    from trimesh.visual import TextureVisuals
    from trimesh.visual.material import PBRMaterial

    lo, hi = np.asarray(lo, float), np.asarray(hi, float)
    b = trimesh.creation.box(extents=np.maximum(hi - lo, 1e-5))
    b.apply_translation((lo + hi) / 2.0)
    name = path.stem
    if textured:
        v = b.vertices[b.faces].reshape(-1, 3)  # unshared vertices: planar UVs per face
        b = trimesh.Trimesh(v, np.arange(len(v)).reshape(-1, 3), process=False)
        ax = np.repeat(np.argmax(np.abs(b.face_normals), axis=1), 3)
        keep = np.array([[1, 2], [0, 2], [0, 1]])[ax]
        span = np.maximum(hi - lo, 1e-5)
        uv = ((v - lo) / span)[np.arange(len(v))[:, None], keep]
        px = np.zeros((4, 4, 3), np.uint8)
        px[:] = (np.asarray(colour[:3]) * 255).astype(np.uint8)
        px[::2, ::2] = 255 - px[::2, ::2]
        mat = PBRMaterial(name=name, baseColorTexture=Image.fromarray(px, "RGB"), baseColorFactor=[1.0, 1.0, 1.0, 1.0],
                          metallicFactor=0.0, roughnessFactor=0.8)
        b.visual = TextureVisuals(uv=uv, material=mat)
    else:
        b.visual = TextureVisuals(material=PBRMaterial(name=name, baseColorFactor=list(colour), metallicFactor=0.0,
                                                       roughnessFactor=0.8))
    scene = trimesh.Scene()
    scene.add_geometry(b, node_name=name, geom_name=name)
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_bytes(trimesh.exchange.gltf.export_glb(scene))


def standin_tool():
    """``tools/replicacad_standin.py`` as a module (``tools/`` is not a package)."""
    import importlib.util

    name = "replicacad_standin_tool"
    if name not in sys.modules:
        spec = importlib.util.spec_from_file_location(name, Path(__file__).resolve().parents[1] / "tools" / "replicacad_standin.py")
        mod = importlib.util.module_from_spec(spec)
        sys.modules[name] = mod
        spec.loader.exec_module(mod)
    return sys.modules[name]


def write_real_fixture(root) -> Path:
    """Write the fixture dataset root at ``root`` (created; existing files are overwritten)."""
    from synth.sources.replicacad.stages import fill, load_stage_variant

    root = Path(root)
    root.mkdir(parents=True, exist_ok=True)
    for rel in manifest():
        dst = root / rel
        dst.parent.mkdir(parents=True, exist_ok=True)
        shutil.copyfile(FILES / rel, dst)
    for k, (rel, b) in enumerate(sorted(bounds_table().items())):
        box_glb(root / rel, b["min"], b["max"], _colour(rel), textured=k < TEXTURED)
    # the stand-in stage, as the tool builds the real data's (its object GLBs are all there: it adds none)
    rows = fill(root, load_stage_variant("standin"), structure_report=False)
    built = [r for r in rows if r.get("file") == STAGE_GLB]
    if len(built) != 1 or built[0].get("floor_z") != STAGE_FLOOR_Z or any(r["kind"] == "object" for r in rows):
        raise RuntimeError(f"fixture stand-in stage: unexpected build rows {rows}")
    return root


# --------------------------------------------------------------------------------------------
# vendoring (run once, by hand, against the real files)


def _glb_bounds_h(path: Path) -> tuple[list[float], list[float]]:
    from synth.mesh.gltf import glb_geometry

    v = glb_geometry(path).vertices @ _C  # ours -> the GLB's own frame (C^T v)
    return [round(float(x), 6) for x in v.min(0)], [round(float(x), 6) for x in v.max(0)]


def vendor(src: Path) -> None:
    import re

    src = Path(src).resolve()
    if FILES.exists():
        shutil.rmtree(FILES)
    sums = {}
    for pat in VENDORED_GLOBS:
        for p in sorted(src.glob(pat)):
            rel = p.relative_to(src).as_posix()
            (FILES / rel).parent.mkdir(parents=True, exist_ok=True)
            shutil.copyfile(p, FILES / rel)
            sums[rel] = sha256(p)
    shutil.copyfile(src / "LICENSE.txt", DATA / "LICENSE.txt")
    glbs: dict[str, dict] = {}
    for cfg in sorted((src / "configs" / "objects").glob("*.object_config.json")):
        doc = json.loads(cfg.read_text())
        glb = (cfg.parent / doc["render_asset"]).resolve()
        rel = glb.relative_to(src).as_posix()
        if glb.is_file():
            lo, hi = _glb_bounds_h(glb)
            source = "measured"
        else:
            col = (cfg.parent / doc["collision_asset"]).resolve() if "collision_asset" in doc else None
            if col is None or not col.is_file():
                m = re.fullmatch(r"(.*_)(\d+)", glb.stem)
                col = next(c for c in sorted(glb.parent.glob(m.group(1) + "*.glb")) if c != glb)
            lo, hi = _glb_bounds_h(col)
            source = "stand-in: bounds of " + col.relative_to(src).as_posix()
        glbs[rel] = {"min": lo, "max": hi, "source": source}
    for urdf in sorted(src.glob("urdf/*/*.urdf")):
        for name in sorted(set(re.findall(r'filename="([^"]+\.glb)"', urdf.read_text()))):
            glb = (urdf.parent / name).resolve()
            rel = glb.relative_to(src).as_posix()
            if rel not in glbs:
                lo, hi = _glb_bounds_h(glb)
                glbs[rel] = {"min": lo, "max": hi, "source": "measured"}
    MANIFEST.write_text(json.dumps({"source": "github angli66/SAPIEN-ReplicaCAD, folder replica_cad/ (CC BY-NC 4.0)",
                                    "sha256": sums}, indent=1, sort_keys=True) + "\n")
    BOUNDS.write_text(json.dumps({"frame": "each GLB's own frame (glTF, Y up), metres, through synth.mesh.gltf.glb_geometry",
                                  "glbs": glbs}, indent=1, sort_keys=True) + "\n")
    print(f"vendored {len(sums)} files, {len(glbs)} GLB bounds")


if __name__ == "__main__":
    sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
    if len(sys.argv) == 3 and sys.argv[1] == "--vendor":
        vendor(Path(sys.argv[2]))
    elif len(sys.argv) == 2:
        print(write_real_fixture(Path(sys.argv[1])))
    else:
        sys.exit("usage: python tests/replicacad_real_fixture.py OUT | --vendor REPLICA_CAD_FOLDER")
