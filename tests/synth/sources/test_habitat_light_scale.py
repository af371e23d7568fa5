"""Intensity scales of habitat lighting configs: the scene dataset config's
``light_setups.default_attributes`` apply where a lighting file sets none, a file's own value wins
(habitat-sim's attribute inheritance; see synth/sources/replicacad/habitat_lighting.py), and fixture powers record the
scaled intensity.

The documents below have the real files' structure: ReplicaCAD's replicaCAD.scene_dataset_config.json
(``light_setups`` with ``default_attributes`` 2.5 / 0.1 and ``paths``) and lights copied from its
configs/lighting/frl_apartment_stage.lighting_config.json (the lighting of apt_0..apt_5; no scales of
its own). Where the real dataset is on this machine, its own files are read too.
"""

from __future__ import annotations

import json
import shutil
import sys
from pathlib import Path

import pytest

from vrformats.errors import SceneFormatError
from synth.sources.replicacad.habitat_format import dataset_config_path, dataset_root
from synth.sources.replicacad.habitat_lighting import (WATTS_PER_INTENSITY, assign_lights, dataset_light_defaults, fixtures_for_imported,
                                    parse_lighting_config, read_lighting_config)

REAL = Path("/work/rcad_git/replica_cad")

DATASET_CONFIG = {  # the real file's light_setups (and two of its other cells), as ReplicaCAD ships it
    "stages": {"paths": {".json": ["configs/stages"]}},
    "objects": {"paths": {".json": ["configs/objects"]}},
    "light_setups": {"default_attributes": {"positive_intensity_scale": 2.5, "negative_intensity_scale": 0.1},
                     "paths": {".json": ["configs/lighting"]}},
}

STAGE_LIGHTS = {"lights": {  # from frl_apartment_stage.lighting_config.json (habitat frame, Y up)
    "0": {"type": "point", "position": [-0.91, 2.3, 2.53], "intensity": 3.64, "color": [0.93, 0.98, 1]},
    "3": {"type": "point", "position": [6.928, 3.3, 6.849], "intensity": 14, "color": [1, 1, 1]},
    "4": {"type": "point", "position": [7.048, 3.3, 2.378], "intensity": 23, "color": [1, 1, 1]},
    "7": {"type": "point", "position": [1.65, 2.6, -2.03], "intensity": -4.2, "color": [1, 1, 1]},
    "8": {"type": "point", "position": [6.06, 2.6, -2.67], "intensity": -8.4, "color": [1, 1, 1]},
}}


def write(path: Path, doc) -> Path:
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps(doc))
    return path


@pytest.fixture
def root(tmp_path) -> Path:
    write(tmp_path / "replicaCAD.scene_dataset_config.json", DATASET_CONFIG)
    write(tmp_path / "configs/lighting/frl_apartment_stage.lighting_config.json", STAGE_LIGHTS)
    return tmp_path


def raw(doc) -> dict[str, float]:
    return {k: float(v.get("intensity", 1.0)) for k, v in doc["lights"].items()}


def test_dataset_defaults_scale_every_light(root):
    cfg = dataset_config_path(root)
    assert cfg == root / "replicaCAD.scene_dataset_config.json"
    assert dataset_light_defaults(cfg) == {"positive_intensity_scale": 2.5, "negative_intensity_scale": 0.1}
    path = root / "configs/lighting/frl_apartment_stage.lighting_config.json"
    lights = {lt.id: lt.intensity for lt in read_lighting_config(path, dataset_config=cfg)}
    want = {k: v * (2.5 if v > 0 else 0.1) for k, v in raw(STAGE_LIGHTS).items()}
    assert lights == pytest.approx(want)
    assert lights["4"] == pytest.approx(57.5) and lights["8"] == pytest.approx(-0.84)
    # the defaults as a dict do the same; without a dataset config the file alone (scales 1), as before
    assert [lt.intensity for lt in read_lighting_config(path, dataset_config=dataset_light_defaults(cfg))] == \
        pytest.approx(list(want.values()))
    assert {lt.id: lt.intensity for lt in read_lighting_config(path)} == pytest.approx(raw(STAGE_LIGHTS))


def test_a_files_own_scale_overrides_the_default_key_by_key(root):
    cfg = dataset_config_path(root)
    doc = dict(STAGE_LIGHTS, positive_intensity_scale=2.0)  # negative scale: not set, inherited
    lights = {lt.id: lt.intensity for lt in parse_lighting_config(doc, "own.json", dataset_light_defaults(cfg))}
    assert lights["3"] == pytest.approx(28.0)  # 14 x the file's 2.0, not the dataset's 2.5
    assert lights["7"] == pytest.approx(-0.42)  # -4.2 x the dataset's 0.1
    doc = dict(STAGE_LIGHTS, negative_intensity_scale=1.0)
    lights = {lt.id: lt.intensity for lt in parse_lighting_config(doc, "own.json", dataset_light_defaults(cfg))}
    assert lights["3"] == pytest.approx(35.0) and lights["7"] == pytest.approx(-4.2)


def test_dataset_config_without_light_defaults_scales_nothing(tmp_path):
    cfg = write(tmp_path / "d.scene_dataset_config.json", {"light_setups": {"paths": {".json": ["configs/lighting"]}}})
    assert dataset_light_defaults(cfg) == {}
    assert dataset_light_defaults(write(tmp_path / "e.json", {"objects": {}})) == {}
    lights = parse_lighting_config(STAGE_LIGHTS, "x.json", dataset_light_defaults(cfg))
    assert [lt.intensity for lt in lights] == pytest.approx(list(raw(STAGE_LIGHTS).values()))


@pytest.mark.parametrize("doc, field", [
    ({"light_setups": {"default_attributes": {"positive_intensity_scale": -1}}},
     "light_setups.default_attributes.positive_intensity_scale"),
    ({"light_setups": {"default_attributes": {"negative_intensity_scale": "dim"}}},
     "light_setups.default_attributes.negative_intensity_scale"),
    ({"light_setups": {"default_attributes": [2.5]}}, "light_setups.default_attributes"),
    ({"light_setups": 3}, "light_setups"),
])
def test_bad_dataset_light_defaults_name_the_file_and_field(tmp_path, doc, field):
    cfg = write(tmp_path / "replicaCAD.scene_dataset_config.json", doc)
    light = write(tmp_path / "configs/lighting/a.lighting_config.json", STAGE_LIGHTS)
    for call in (lambda: dataset_light_defaults(cfg), lambda: read_lighting_config(light, dataset_config=cfg)):
        with pytest.raises(SceneFormatError) as e:
            call()
        assert e.value.file == str(cfg) and e.value.field == field
        assert len(str(e.value).splitlines()) == 1
    (tmp_path / "broken.scene_dataset_config.json").write_text("{not json")
    with pytest.raises(SceneFormatError, match="not valid JSON"):
        dataset_light_defaults(tmp_path / "broken.scene_dataset_config.json")


def test_dataset_config_path_finds_one_or_says_why(tmp_path):
    with pytest.raises(SceneFormatError, match=r"no \*\.scene_dataset_config\.json in the ReplicaCAD folder") as e:
        dataset_config_path(tmp_path)
    assert e.value.file == str(tmp_path) and len(str(e.value).splitlines()) == 1
    assert dataset_config_path(tmp_path, required=False) is None
    assert dataset_root(tmp_path) == tmp_path.resolve()  # the plain check, as before
    with pytest.raises(SceneFormatError, match="no .*scene_dataset_config"):
        dataset_root(tmp_path, require_config=True)
    write(tmp_path / "a.scene_dataset_config.json", {})
    assert dataset_root(tmp_path, require_config=True) == tmp_path.resolve()
    write(tmp_path / "b.scene_dataset_config.json", {})
    with pytest.raises(SceneFormatError, match="several scene dataset configs .*a.scene_dataset_config.json"):
        dataset_config_path(tmp_path)


# ---- fixture powers --------------------------------------------------------------------------------


def fixture_module():
    sys.path.insert(0, str(Path(__file__).resolve().parents[2]))
    import replicacad_fixture as F

    return F


@pytest.fixture(scope="module")
def fx(tmp_path_factory):
    from synth.sources.replicacad.importer import load_replicacad

    F = fixture_module()
    root = F.make_fixture(tmp_path_factory.mktemp("rcad_light"))
    return root, load_replicacad(root, "apt_0")


def test_fixture_powers_record_the_scaled_intensity(fx):
    """apt_0 of the ReplicaCAD-shaped fixture: every fixture made from a config light has power
    WATTS_PER_INTENSITY x file intensity x the dataset's 2.5."""
    root, lay = fx
    lighting = root / lay.meta["lighting_config"]
    doc = json.loads(lighting.read_text())
    cfg = dataset_config_path(root)
    scale = dataset_light_defaults(cfg)["positive_intensity_scale"]
    assert scale == 2.5  # the fixture's dataset config says what ReplicaCAD's does
    lights = read_lighting_config(lighting, dataset_config=cfg)
    roles = assign_lights(lay, lights)
    fixtures = {f.id: f for f in fixtures_for_imported(lay, lights)}
    checked = 0
    for lid, role in roles.items():
        if role.startswith("ignored"):
            continue
        fid = f"L{role.split(':', 1)[1]}" if role.startswith("lamp:") else f"H{lid}"
        want = WATTS_PER_INTENSITY * scale * float(doc["lights"][lid].get("intensity", 1.0))
        assert fixtures[fid].power == pytest.approx(want, rel=1e-6), fid
        checked += 1
    assert checked >= 2
    unscaled = {f.id: f.power for f in fixtures_for_imported(lay, read_lighting_config(lighting))}
    for fid, p in unscaled.items():
        if fid[0] in "HL" and fid in fixtures and fixtures[fid].kind != "window":
            assert fixtures[fid].power == pytest.approx(scale * p, rel=1e-6), fid


# ---- the real files, where they are ------------------------------------------------------------------


@pytest.mark.skipif(not REAL.is_dir(), reason="the real ReplicaCAD files are not on this machine")
def test_real_replicacad_lighting_configs(tmp_path):
    """ReplicaCAD's own dataset config and its seven lighting configs (copied): none sets a scale of
    its own, so every positive light is 2.5 x, every negative one 0.1 x its file intensity."""
    shutil.copy(REAL / "replicaCAD.scene_dataset_config.json", tmp_path)
    shutil.copytree(REAL / "configs/lighting", tmp_path / "configs/lighting")
    cfg = dataset_config_path(tmp_path)
    assert dataset_light_defaults(cfg) == {"positive_intensity_scale": 2.5, "negative_intensity_scale": 0.1}
    files = sorted((tmp_path / "configs/lighting").glob("*.lighting_config.json"))
    assert len(files) == 7
    for f in files:
        doc = json.loads(f.read_text())
        assert not {"positive_intensity_scale", "negative_intensity_scale"} & set(doc)
        got = {lt.id: lt.intensity for lt in read_lighting_config(f, dataset_config=cfg)}
        assert got == pytest.approx({k: v * (2.5 if v > 0 else 0.1) for k, v in raw(doc).items()}), f.name
