"""Bad input at the level of a whole ReplicaCAD folder: each is one line naming the file (and the
field), exit status 2 through ``synth scene import-replicacad``.

Every case starts from the ReplicaCAD-shaped fixture (tests/replicacad_fixture.py), copied and then
damaged the way real folders are: the scene dataset config missing (a folder that is not the
dataset's root), GLBs and textures that are Git LFS pointers (a clone made without ``git lfs``, the
most common state of a cloned ReplicaCAD), a truncated GLB (an interrupted download), a file that is
not a GLB at all. The files to damage are found through apt_0's own scene instance and configs, so
the tests follow the fixture when it changes.
"""

from __future__ import annotations

import json
import os
import shutil
import sys
import xml.etree.ElementTree as ET
from pathlib import Path

import pytest

from vrformats.errors import SceneFormatError
from synth.cli import main as synth_main

SCENE = "apt_0"
LFS_POINTER = ("version https://git-lfs.github.com/spec/v1\n"
               "oid sha256:0f6e2f1c3a8d1b9e7c5a4f2e1d0c9b8a7f6e5d4c3b2a1908f7e6d5c4b3a29180\n"
               "size 7340032\n")


def fixture_module():
    sys.path.insert(0, str(Path(__file__).resolve().parents[2]))
    import replicacad_fixture as F

    return F


@pytest.fixture(scope="module")
def pristine(tmp_path_factory) -> Path:
    return fixture_module().make_fixture(tmp_path_factory.mktemp("rcad_pristine")).resolve()


@pytest.fixture
def root(pristine, tmp_path) -> Path:
    dst = (tmp_path / "replica_cad").resolve()
    shutil.copytree(pristine, dst)
    return dst


def scene_doc(root: Path) -> dict:
    return json.loads((root / f"configs/scenes/{SCENE}.scene_instance.json").read_text())


def render_asset_of(config: Path) -> Path:
    cfg = json.loads(config.read_text())
    return Path(os.path.normpath(config.parent / cfg["render_asset"]))


def object_glb(root: Path) -> Path:
    """The GLB of apt_0's first object instance (through its object config's render_asset)."""
    for inst in scene_doc(root)["object_instances"]:
        base = inst["template_name"].rsplit("/", 1)[-1]
        hits = sorted((root / "configs/objects").rglob(f"{base}.object_config.json"))
        if hits:
            return render_asset_of(hits[0])
    raise AssertionError("apt_0 of the fixture has no object with a config")


def stage_glb(root: Path) -> Path:
    base = scene_doc(root)["stage_instance"]["template_name"].rsplit("/", 1)[-1]
    return render_asset_of(root / f"configs/stages/{base}.stage_config.json")


def urdf_glb(root: Path) -> Path:
    """A link mesh of apt_0's first articulated object (its URDF under urdf/<name>/)."""
    for inst in scene_doc(root).get("articulated_object_instances", []):
        base = inst["template_name"].rsplit("/", 1)[-1]
        urdfs = sorted((root / "urdf").rglob(f"{base}.urdf"))
        if urdfs:
            mesh = next(ET.parse(urdfs[0]).iter("mesh"))
            return Path(os.path.normpath(urdfs[0].parent / mesh.get("filename")))
    raise AssertionError("apt_0 of the fixture has no articulated object with a URDF")


def import_error(root: Path, tmp_path: Path, capsys) -> str:
    """Run the CLI import of apt_0; assert exit 2, one line, no output file; return the message."""
    out = tmp_path / "apt_0.yaml"
    code = synth_main(["scene", "import-replicacad", str(root), SCENE, "--out", str(out)])
    err = capsys.readouterr().err.strip()
    assert code == 2, err
    assert err.startswith("synth: error: ") and len(err.splitlines()) == 1, err
    assert not out.exists()
    return err


def test_the_fixture_imports_cleanly(root, tmp_path, capsys):
    """The undamaged copy imports (so each failure below is the damage's)."""
    out = tmp_path / "ok.yaml"
    assert synth_main(["scene", "import-replicacad", str(root), SCENE, "--out", str(out), "--allow-unknown"]) == 0
    assert out.is_file()
    for f in (object_glb(root), stage_glb(root), urdf_glb(root)):
        assert f.is_file() and f.read_bytes()[:4] == b"glTF", f


# ---- the scene dataset config ------------------------------------------------------------------------


def test_folder_without_its_dataset_config_is_refused(root):
    from synth.sources.replicacad.habitat_format import dataset_config_path, dataset_root

    (root / "replicaCAD.scene_dataset_config.json").unlink()
    for call in (lambda: dataset_root(root, require_config=True), lambda: dataset_config_path(root)):
        with pytest.raises(SceneFormatError) as e:
            call()
        msg = str(e.value)
        assert e.value.file == str(root) and "no *.scene_dataset_config.json in the ReplicaCAD folder" in msg
        assert len(msg.splitlines()) == 1


def test_configs_folder_given_as_the_root_is_refused(root):
    """A common slip: pointing at replica_cad/configs instead of replica_cad."""
    from synth.sources.replicacad.habitat_format import dataset_root

    with pytest.raises(SceneFormatError, match="no .*scene_dataset_config.json") as e:
        dataset_root(root / "configs", require_config=True)
    assert e.value.file == str(root / "configs")


def test_folder_without_its_dataset_config_exits_2(root, tmp_path, capsys):
    (root / "replicaCAD.scene_dataset_config.json").unlink()
    err = import_error(root, tmp_path, capsys)
    assert f"{root}: no *.scene_dataset_config.json in the ReplicaCAD folder" in err


# ---- Git LFS pointers, truncated and foreign files ----------------------------------------------------


@pytest.mark.parametrize("which", ["object", "stage", "urdf"])
def test_glb_that_is_a_git_lfs_pointer(root, tmp_path, capsys, which):
    from synth.mesh.gltf import check_glb, glb_geometry

    glb = {"object": object_glb, "stage": stage_glb, "urdf": urdf_glb}[which](root)
    glb.write_text(LFS_POINTER)
    for fn in (check_glb, glb_geometry):
        with pytest.raises(SceneFormatError) as e:
            fn(glb)
        assert e.value.file == str(glb) and e.value.field is None
        assert "is a Git LFS pointer" in str(e.value) and "(run git lfs pull)" in str(e.value)
    err = import_error(root, tmp_path, capsys)
    assert f"{glb}: cannot read GLB: is a Git LFS pointer" in err and "git lfs pull" in err


def test_truncated_glb(root, tmp_path, capsys):
    from synth.mesh.gltf import check_glb, glb_geometry

    glb = object_glb(root)
    data = glb.read_bytes()
    glb.write_bytes(data[: len(data) // 2])
    for fn in (check_glb, glb_geometry):
        with pytest.raises(SceneFormatError, match=r"cannot read GLB: truncated \(\d+ of \d+ bytes\)") as e:
            fn(glb)
        assert e.value.file == str(glb)
    assert f"{glb}: cannot read GLB: truncated" in import_error(root, tmp_path, capsys)
    glb.write_bytes(data[:14])  # not even the first chunk's header
    with pytest.raises(SceneFormatError, match="cannot read GLB: truncated"):
        check_glb(glb)


def test_file_that_is_not_a_glb(root, tmp_path, capsys):
    from synth.mesh.gltf import check_glb, glb_geometry

    glb = object_glb(root)
    glb.write_bytes(b"\x89PNG\r\n\x1a\n" + bytes(200))  # an image saved under the GLB's name
    for fn in (check_glb, glb_geometry):
        with pytest.raises(SceneFormatError, match=r"cannot read GLB: not a binary glTF file") as e:
            fn(glb)
        assert e.value.file == str(glb)
    assert f"{glb}: cannot read GLB: not a binary glTF file" in import_error(root, tmp_path, capsys)


def external_texture(glb: Path) -> Path:
    """Rewrite ``glb`` so that its first image is an external file next to it (the PNG it held);
    return that file."""
    from tests.synth.blender.test_gltf_render import glb_chunks, write_glb_chunks

    doc, binary = glb_chunks(glb)
    assert doc.get("images"), f"{glb} has no image to move out"
    img = doc["images"][0]
    bv = doc["bufferViews"][img["bufferView"]]
    start = bv.get("byteOffset", 0)
    png = glb.parent / "textures" / f"{glb.stem}_0.png"
    png.parent.mkdir(exist_ok=True)
    png.write_bytes(binary[start: start + bv["byteLength"]])
    doc["images"][0] = {"uri": f"textures/{png.name}"}
    write_glb_chunks(glb, doc, binary)
    return png


def test_texture_that_is_a_git_lfs_pointer(root, tmp_path, capsys):
    from synth.mesh.gltf import check_glb, clear_cache, load_glb_parts, pbr

    glb = object_glb(root)
    png = external_texture(glb)
    (part, *_) = load_glb_parts(glb)  # the external texture itself is fine ...
    assert pbr(part)["base_color_texture"] is not None or pbr(part)["emissive_texture"] is not None
    png.write_text(LFS_POINTER)  # ... until it is an LFS pointer
    clear_cache()  # loads are cached by the GLB's own stat: a texture changed under a loaded GLB is not seen
    for fn in (check_glb, load_glb_parts):
        with pytest.raises(SceneFormatError) as e:
            fn(glb)
        assert e.value.file == str(glb) and e.value.field == "images[0].uri"
        assert f"texture {png} is a Git LFS pointer" in str(e.value) and "(run git lfs pull)" in str(e.value)
        assert len(str(e.value).splitlines()) == 1
    err = import_error(root, tmp_path, capsys)
    assert f"{glb}: images[0].uri: texture {png} is a Git LFS pointer" in err


def test_external_buffer_that_is_a_git_lfs_pointer(tmp_path):
    from tests.synth.blender.test_gltf_render import glb_chunks, plain_box, write_glb, write_glb_chunks

    from synth.mesh.gltf import check_glb

    glb = tmp_path / "b.glb"
    write_glb(glb, [plain_box()])
    doc, binary = glb_chunks(glb)
    (tmp_path / "b.bin").write_text(LFS_POINTER)
    doc["buffers"] = [{"uri": "b.bin", "byteLength": len(binary)}]
    write_glb_chunks(glb, doc, b"")
    with pytest.raises(SceneFormatError, match="buffer .*b.bin is a Git LFS pointer") as e:
        check_glb(glb)
    assert e.value.field == "buffers[0].uri"


def test_render_asset_names_the_pointer_and_its_config(root):
    """The importer meets the pointer first through the config's render_asset."""
    from synth.sources.replicacad.habitat_format import render_asset

    glb = object_glb(root)
    glb.write_text(LFS_POINTER)
    config = next(p for p in sorted((root / "configs/objects").rglob("*.object_config.json"))
                  if render_asset_of(p) == glb)
    with pytest.raises(SceneFormatError) as e:
        render_asset(root, config, json.loads(config.read_text()))
    assert e.value.file == str(glb) and str(config) in str(e.value) and "render_asset" in str(e.value)
