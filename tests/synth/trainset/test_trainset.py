"""Detector training data: random views, jittered lighting, the trainset spec and its render job.

Views are checked against geometry computed here from the layout's boxes (not the planner's grid);
jittered presets are read back through the preset parser; the tiny render is checked against the
tour's own ground-truth file (objects.json) and the job runner's files.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest
import yaml
from scipy.spatial.transform import Rotation

from vrformats.design import read_design
from vrformats.errors import SceneFormatError, UserError
from vrformats.tour import Tour
from synth.cli import main as synth_main
from synth.jobs import load_spec
from synth.scene.lighting import LightingJitter, jitter_preset, load_lighting, parse_preset, preset_document
from synth.paths.model import BOB, Q_HEIGHT, Q_HEIGHT_VAR, Q_PITCH, Q_PITCH_VAR
from synth.paths.views import plan_views
from synth.scene.model import boxes_document, load_layout
from synth.trainset.trainset import parse_trainset, prepare

# ---------------------------------------------------------------------------------------------
# views


def _footprint_distance(xy: np.ndarray, box: dict) -> np.ndarray:
    """Horizontal distance of points to a yawed box footprint (0 inside), written out here."""
    c, s = math.cos(box["yaw"]), math.sin(box["yaw"])
    d = xy - np.asarray(box["center"][:2])
    lx, ly = c * d[:, 0] + s * d[:, 1], -s * d[:, 0] + c * d[:, 1]
    ex = np.maximum(np.abs(lx) - box["size"][0] / 2, 0.0)
    ey = np.maximum(np.abs(ly) - box["size"][1] / 2, 0.0)
    return np.hypot(ex, ey)


def test_views_stand_clear_in_every_room_at_query_heights():
    lay = load_layout("apt_2")
    p = plan_views([lay], frames=150, seed=4)
    assert len(p) == 150 and p.meta["kind"] == "views"
    xy, z = p.positions[:, :2], p.positions[:, 2]
    doc = boxes_document(lay)
    floor_z = lay.stage.floor_z
    objects = [b for b in doc["boxes"] if b["kind"] == "object"
               and b["center"][2] - b["size"][2] / 2 < floor_z + 2.3]  # not ceiling-mounted
    near = np.min([_footprint_distance(xy, b) for b in objects], axis=0)
    assert near.min() >= 0.3 - 1e-9  # the clearance, against every object of the layout
    # every view inside a room, every room visited at least 3 times
    rooms = np.array([[r.rect[0] <= x <= r.rect[2] and r.rect[1] <= y <= r.rect[3] for r in lay.stage.rooms]
                      for x, y in xy])
    assert rooms.any(axis=1).all() and (rooms.sum(axis=0) >= 3).all()
    # heights and pitches like the query walk's, widened by 1.5
    h = (Q_HEIGHT_VAR + BOB) * 1.5
    assert (np.abs(z - Q_HEIGHT) <= h + 1e-9).all() and z.std() > 0.02
    R = np.asarray(p.poses)[:, :3, :3]
    pitch = np.degrees(np.arcsin(np.clip(R[:, 2, 2], -1, 1)))  # optical axis below the horizon: negative
    assert abs(np.median(pitch) - math.degrees(Q_PITCH)) < 2.0
    assert np.abs(pitch - math.degrees(Q_PITCH)).max() <= 3 * 1.5 * math.degrees(Q_PITCH_VAR) + 2.0
    # yaw covers every direction (not a walk's travel direction)
    yaw = Rotation.from_matrix(R).as_euler("zyx")[:, 0]
    assert np.histogram(yaw, bins=4, range=(-math.pi, math.pi))[0].min() >= 20


def test_views_are_seeded():
    lay = load_layout("apt_0")
    a, b = plan_views([lay], 20, seed=1), plan_views([lay], 20, seed=1)
    assert np.array_equal(a.poses, b.poses)
    assert not np.allclose(a.poses, plan_views([lay], 20, seed=2).poses)
    with pytest.raises(UserError, match="frames must be a positive integer"):
        plan_views([lay], 0)


# ---------------------------------------------------------------------------------------------
# jittered lighting


@pytest.mark.parametrize("name", ["day", "evening", "night"])
def test_jittered_presets_keep_their_lights_and_stay_in_range(name):
    base = load_lighting(name)
    j = LightingJitter()
    seen = []
    for seed in range(12):
        p = jitter_preset(base, seed)
        assert p == jitter_preset(base, seed)  # seeded
        back = parse_preset(yaml.safe_load(yaml.safe_dump(preset_document(p))), "x.yaml")
        assert dataclasses.replace(back, source="") == dataclasses.replace(p, source="")  # a valid preset file
        assert (p.ceiling.on, p.lamp.on, p.sun is None, p.window_portals) == \
               (base.ceiling.on, base.lamp.on, base.sun is None, base.window_portals)
        g = 2 ** j.strength_log2 + 1e-3
        assert base.sky_strength / g <= p.sky_strength <= base.sky_strength * g
        for f, fb in ((p.ceiling, base.ceiling), (p.lamp, base.lamp)):
            assert fb.power / g <= f.power <= fb.power * g
            assert 1800 <= f.color_temperature <= 9000 and abs(f.color_temperature - fb.color_temperature) <= j.temperature_k + 0.1
        if base.lamp.count is not None:
            assert base.lamp.count <= p.lamp.count <= base.lamp.count + j.lamps_extra
        if base.sun is not None:
            assert 5.0 <= p.sun["elevation_deg"] <= 80.0
            d = (p.sun["azimuth_deg"] - base.sun["azimuth_deg"] + 180) % 360 - 180
            assert abs(d) <= j.sun_azimuth_deg + 1e-6
        seen.append(p.sky_strength)
    assert len(set(seen)) == 12  # every seed a different light


def test_wide_jitter_reaches_one_lamp_and_more_power():
    base = load_lighting("night")
    wide = LightingJitter(strength_log2=1.0, lamps_fewer=1)
    counts = {jitter_preset(base, s, wide).lamp.count for s in range(40)}
    assert counts == {1, 2, 3, 4}  # one lamp fewer to two more
    assert {jitter_preset(base, s).lamp.count for s in range(40)} == {2, 3, 4}  # the default never goes below
    powers = [jitter_preset(base, s, wide).lamp.power / base.lamp.power for s in range(40)]
    assert min(powers) < 2 ** -0.7 and max(powers) > 2 ** 0.7 and all(0.5 - 1e-3 <= p <= 2 + 1e-3 for p in powers)


# ---------------------------------------------------------------------------------------------
# appearance randomisation (synth.trainset.appearance) and the room finishes it writes


def test_appearance_redraws_colours_and_materials_but_not_geometry():
    from synth.trainset.appearance import FAMILIES, randomize_appearance
    from synth.layout.apartment import generate_apartment
    from synth.render.meshes import stage_finishes, stage_parts

    lay = generate_apartment(seed=101, name="train_101")
    same = randomize_appearance(lay, 3, 0.0)
    assert same.objects == lay.objects and "finishes" not in same.meta
    r = randomize_appearance(lay, 3, 1.0)
    assert r == randomize_appearance(lay, 3, 1.0) and r != randomize_appearance(lay, 4, 1.0)  # seeded
    assert [(o.id, o.cls, o.position, o.size, o.rotation) for o in r.objects] == \
           [(o.id, o.cls, o.position, o.size, o.rotation) for o in lay.objects]
    changed = 0
    for a, b in zip(lay.objects, r.objects):
        for k, v in a.params.items():
            if k.endswith("material") and v != b.params[k]:
                assert any(v in fam and b.params[k] in fam for fam in FAMILIES)  # within its family
            if k == "color" or k.endswith("_color"):
                changed += v != b.params[k]
                assert all(0.0 <= c <= 1.0 for c in b.params[k])
    assert changed >= 5
    assert lay.objects[0].params == generate_apartment(seed=101, name="train_101").objects[0].params  # input untouched
    fin = stage_finishes(r)
    assert set(fin) == {"wall_color", "ceiling_color", "floor_color", "floor_material"}
    walls = [p for p in stage_parts(r) if p.material == "wall_paint"]
    floors = [p for p in stage_parts(r) if p.name.startswith("floor/")]
    assert walls and all(p.color == fin["wall_color"] for p in walls)
    assert all(p.material == fin["floor_material"] and p.color == fin["floor_color"] for p in floors)
    assert all(p.color is None for p in stage_parts(lay) if p.material == "wall_paint")  # no finishes: defaults
    with pytest.raises(ValueError, match="strength"):
        randomize_appearance(lay, 3, 1.5)


@pytest.mark.parametrize("finishes, field", [
    ({"wall_color": [1.2, 0, 0]}, "meta.finishes.wall_color"),
    ({"floor_material": "lava"}, "meta.finishes.floor_material"),
    ({"roof": [0, 0, 0]}, "meta.finishes.roof"),
    ([1, 2], "meta.finishes"),
])
def test_bad_finishes_name_the_layout_and_key(finishes, field):
    from synth.layout.apartment import generate_apartment
    from synth.render.meshes import stage_parts

    lay = generate_apartment(seed=101, name="train_101")
    lay.meta["finishes"] = finishes
    with pytest.raises(SceneFormatError) as e:
        stage_parts(lay)
    assert e.value.field == field and "train_101" in str(e.value)


# ---------------------------------------------------------------------------------------------
# the trainset spec


def _doc(**kw):
    d = {"name": "t", "out": "out/t", "seeds": [101], "variants": 0, "lightings": ["night"], "jitter": 1, "views": 3,
         "size": [32, 24]}
    d.update(kw)
    return d


@pytest.mark.parametrize("changes, field", [
    ({"seeds": [101, 7]}, "seeds[1]"),          # apt_0's generator seed
    ({"seeds": [101, 101]}, "seeds"),
    ({"seeds": []}, "seeds"),
    ({"lightings": ["day", "dusk"]}, "lightings[1]"),
    ({"views": 0}, "views"),
    ({"size": [32]}, "size"),
    ({"colour": 1}, "colour"),
    ({"appearance": 1.5}, "appearance"),
    ({"appearance": "lots"}, "appearance"),
    ({"lighting_jitter": {"glow": 1}}, "lighting_jitter.glow"),
    ({"lighting_jitter": {"lamps_fewer": -1}}, "lighting_jitter.lamps_fewer"),
    ({"lighting_jitter": {"strength_log2": "x"}}, "lighting_jitter.strength_log2"),
    ({"lighting_jitter": [1]}, "lighting_jitter"),
])
def test_bad_trainset_specs_name_the_field(changes, field):
    with pytest.raises(SceneFormatError) as e:
        parse_trainset(_doc(**changes), "spec.yaml")
    assert e.value.field == field and str(e.value).startswith("spec.yaml: ")


def test_trainset_cli_refuses_an_experiment_seed_in_one_line(tmp_path, capsys):
    spec = tmp_path / "t.yaml"
    spec.write_text(yaml.safe_dump(_doc(seeds=[7], out=str(tmp_path / "out"))))
    assert synth_main(["trainset", "render", str(spec), "--quiet"]) == 2
    err = capsys.readouterr().err.strip()
    assert "seeds[0]" in err and "apt_0" in err and len(err.splitlines()) == 1
    assert not (tmp_path / "out").exists()


@pytest.mark.slow
def test_prepare_is_deterministic_and_makes_a_valid_render_job(tmp_path):
    spec = parse_trainset(_doc(variants=1, lightings=["day", "night"], jitter=2), "spec.yaml")
    render = prepare(spec, tmp_path / "a", progress=False)
    prepare(spec, tmp_path / "b", progress=False)
    files = sorted(p.relative_to(tmp_path / "a") for p in (tmp_path / "a").rglob("*") if p.is_file())
    assert len(files) == 1 + 2 + 2 * 2 * 2 * 3  # render.yaml, 2 layouts, per (layout, preset, k): light + path + sidecar
    for f in files:  # identical, up to the output folder that render.yaml and the paths name
        a = (tmp_path / "a" / f).read_text().replace(str((tmp_path / "a").resolve()), "OUT")
        assert a == (tmp_path / "b" / f).read_text().replace(str((tmp_path / "b").resolve()), "OUT"), f
    job = load_spec(render)
    assert len(job.designs) == 2 * 2 * 2 and all(d.rgb_every == 1 for d in job.designs)
    names = {load_layout(d.layouts[0]).name for d in job.designs}
    assert names == {"train_101", "train_101_v1"}
    # the variant is a rearrangement: the same shell, other furniture
    a, b = (load_layout(tmp_path / "a" / "scenes" / "layouts" / f"{n}.yaml") for n in ("train_101", "train_101_v1"))
    assert [r.rect for r in a.stage.rooms] == [r.rect for r in b.stage.rooms]
    assert {(o.cls, o.position) for o in a.objects} != {(o.cls, o.position) for o in b.objects}


@pytest.mark.slow
@pytest.mark.blender
def test_tiny_trainset_renders_rgb_and_labels(tmp_path):
    spec_file = tmp_path / "t.yaml"
    spec_file.write_text(yaml.safe_dump(_doc(out=str(tmp_path / "out"), views=2)))
    assert synth_main(["trainset", "render", str(spec_file), "--quiet"]) == 0
    design = read_design(tmp_path / "out")
    assert list(design) == ["train_101__night_j0__views_night_j0"]
    tour = Tour(tmp_path / "out" / "train_101__night_j0__views_night_j0")
    gt = {b["id"] for b in tour.objects()["boxes"]}
    for f in tour:
        assert f.rgb is not None and f.rgb.shape == (24, 32, 3) and np.isfinite(f.rgb).all() and f.rgb.max() > 0
        ids = set(np.unique(f.instance).tolist()) - {0}
        assert ids and ids <= gt  # every labelled pixel belongs to a ground-truth box
        assert f.semantic.shape == (24, 32) and (f.semantic[f.instance > 0] > 0).all()
