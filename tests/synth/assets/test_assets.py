"""Tests for synth/assets (registry and family modules): procedural object meshes in the object's local frame."""
from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
import trimesh

from synth.assets.materials import MATERIALS
from synth.assets.primitives import Builder, Part
from synth.assets.registry import (
    REGISTRY,
    UnknownClassError,
    known_classes,
    make_mesh,
    make_parts,
    sample_params,
    support_surfaces,
)
from synth.assets.surfaces import Surface

REPO = Path(__file__).resolve().parents[3]
CLASSES = known_classes()
SEEDS = range(5)
TOL = 1e-6
LAMPS = ("floor_lamp", "table_lamp", "ceiling_light")


def _bounds_of(parts):
    v = np.vstack([p.mesh.vertices for p in parts])
    return v.min(axis=0), v.max(axis=0)


def _target(size):
    w, d, h = size
    return np.array([-w / 2, -d / 2, 0.0]), np.array([w / 2, d / 2, h])


def _yamlable(v):
    if isinstance(v, bool) or v is None or isinstance(v, (int, float, str)):
        return type(v) in (bool, int, float, str, type(None))
    if isinstance(v, list):
        return all(_yamlable(x) for x in v)
    if isinstance(v, dict):
        return all(isinstance(k, str) and _yamlable(x) for k, x in v.items())
    return False


def _check_parts(cls, size, parts):
    assert parts, cls
    lo, hi = _target(size)
    blo, bhi = _bounds_of(parts)
    np.testing.assert_allclose(blo, lo, atol=TOL, err_msg=f"{cls} {size} lower bounds")
    np.testing.assert_allclose(bhi, hi, atol=TOL, err_msg=f"{cls} {size} upper bounds")
    names = [p.name for p in parts]
    assert len(set(names)) == len(names), f"{cls}: duplicate part names {names}"
    for p in parts:
        assert isinstance(p, Part)
        assert p.material in MATERIALS, (cls, p.name, p.material)
        assert isinstance(p.mesh, trimesh.Trimesh)
        assert len(p.mesh.faces) > 0, (cls, p.name)
        assert np.all(np.isfinite(p.mesh.vertices)), (cls, p.name)
        assert p.mesh.faces.max() < len(p.mesh.vertices)
        if p.color is not None:
            assert len(p.color) == 3 and all(0.0 <= c <= 1.0 for c in p.color), (cls, p.name, p.color)


def _check_surfaces(cls, size, surfs):
    w, d, h = size
    for s in surfs:
        assert isinstance(s, Surface)
        assert -w / 2 - TOL <= s.xmin < s.xmax <= w / 2 + TOL, (cls, s)
        assert -d / 2 - TOL <= s.ymin < s.ymax <= d / 2 + TOL, (cls, s)
        assert 0.0 <= s.z <= h + TOL, (cls, s)
        assert s.clearance > 0, (cls, s)


# ----------------------------------------------------------------------------------------------


def test_known_classes_match_class_table():
    yaml = pytest.importorskip("yaml")
    table = yaml.safe_load((REPO / "scenes" / "classes.yaml").read_text())["classes"]
    wanted = {name for name, row in table.items() if not row.get("structure", False) and not row.get("imported", False)}
    assert set(CLASSES) == wanted  # every class but structure and those only imported datasets have has a generator
    assert len(CLASSES) == len(set(CLASSES))
    for structure in ("wall", "floor", "ceiling"):
        assert structure not in CLASSES


def test_materials_vocabulary():
    assert isinstance(MATERIALS, tuple) and len(set(MATERIALS)) == len(MATERIALS)
    for m in ("wood_light", "wood_dark", "fabric", "metal", "glass", "leaf", "screen", "lamp_shade", "mirror",
              "marble"):
        assert m in MATERIALS


@pytest.mark.parametrize("cls", CLASSES)
def test_sampled_instances(cls):
    for seed in SEEDS:
        size, params = sample_params(cls, np.random.default_rng(seed))
        assert len(size) == 3 and all(isinstance(v, float) and v > 0 for v in size), (cls, size)
        assert _yamlable(params), (cls, params)
        parts = make_parts(cls, size, params)
        _check_parts(cls, size, parts)
        mesh = make_mesh(cls, size, params)
        assert len(mesh.faces) == sum(len(p.mesh.faces) for p in parts)
        np.testing.assert_array_equal(mesh.vertices, np.vstack([p.mesh.vertices for p in parts]))
        # deterministic, byte for byte
        again = make_mesh(cls, size, params)
        assert mesh.vertices.tobytes() == again.vertices.tobytes()
        assert mesh.faces.tobytes() == again.faces.tobytes()
        _check_surfaces(cls, size, support_surfaces(cls, size, params))


@pytest.mark.parametrize("cls", CLASSES)
def test_sample_params_deterministic(cls):
    a = sample_params(cls, np.random.default_rng(123))
    b = sample_params(cls, np.random.default_rng(123))
    assert a == b


def test_params_survive_yaml_round_trip():
    yaml = pytest.importorskip("yaml")
    for cls in CLASSES:
        size, params = sample_params(cls, np.random.default_rng(7))
        loaded = yaml.safe_load(yaml.safe_dump({"size": list(size), "params": params}))
        m0 = make_mesh(cls, size, params)
        m1 = make_mesh(cls, tuple(loaded["size"]), loaded["params"])
        assert m0.vertices.tobytes() == m1.vertices.tobytes(), cls


@pytest.mark.parametrize("cls", CLASSES)
def test_empty_params_and_odd_sizes(cls):
    size, _ = sample_params(cls, np.random.default_rng(0))
    w, d, h = size
    for s in [size, (w * 0.5, d * 0.5, h * 0.5), (w * 2.0, d * 1.5, h * 1.2), (w * 1.3, d * 0.7, h * 0.8),
              (1.0, 1.0, 1.0)]:
        parts = make_parts(cls, s, {})
        _check_parts(cls, s, parts)
        _check_surfaces(cls, s, support_surfaces(cls, s, {}))


@pytest.mark.parametrize("cls", CLASSES)
def test_generators_fill_their_box_without_heavy_rescaling(cls):
    """The final exact fit must be a small correction, not what shapes the object."""
    for seed in SEEDS:
        size, params = sample_params(cls, np.random.default_rng(seed))
        b = Builder()
        REGISTRY[cls].generate(b, *size, dict(params))
        v = np.vstack([p[2].vertices for p in b.parts])
        lo, hi = _target(size)
        ext = hi - lo
        err = np.max(np.abs(np.r_[v.min(axis=0) - lo, v.max(axis=0) - hi]) / np.r_[ext, ext])
        assert err < 0.05, (cls, seed, err)


def test_lamps_emit_light():
    for cls in LAMPS:
        for seed in SEEDS:
            size, params = sample_params(cls, np.random.default_rng(seed))
            parts = make_parts(cls, size, params)
            em = [p for p in parts if p.emissive]
            assert em, (cls, seed)
        assert any(p.emissive for p in make_parts(cls, (0.4, 0.4, 0.5), {}))
    for cls in ("chair", "sofa", "bookshelf", "tv", "other"):
        size, params = sample_params(cls, np.random.default_rng(0))
        assert not any(p.emissive for p in make_parts(cls, size, params))


def test_ceiling_light_diffuser_reaches_the_ceiling():
    for seed in SEEDS:
        size, params = sample_params("ceiling_light", np.random.default_rng(seed))
        parts = make_parts("ceiling_light", size, params)
        diff = [p for p in parts if p.emissive]
        top = max(p.mesh.vertices[:, 2].max() for p in diff)
        assert abs(top - size[2]) < TOL


def test_bookshelf_surfaces():
    for seed in range(8):
        size, params = sample_params("bookshelf", np.random.default_rng(seed))
        assert 3 <= params["n_boards"] <= 5
        surfs = support_surfaces("bookshelf", size, params)
        assert len(surfs) >= 3
        assert len(surfs) >= params["n_boards"] + 1  # every open board level plus the top
        zs = sorted(s.z for s in surfs)
        assert abs(zs[-1] - size[2]) < TOL
        assert math.isinf(max(s.clearance for s in surfs))
        finite = [s for s in surfs if math.isfinite(s.clearance)]
        for s in finite:
            assert s.z + s.clearance <= size[2] + TOL
    assert len(support_surfaces("bookshelf", (0.9, 0.32, 1.8), {})) >= 3


def test_chair_has_parts_and_back_at_minus_y():
    for seed in SEEDS:
        size, params = sample_params("chair", np.random.default_rng(seed))
        parts = {p.name: p for p in make_parts("chair", size, params)}
        assert len(parts) >= 5
        assert "seat" in parts and "back" in parts
        assert sum(n.startswith("leg_") for n in parts) == 4
        assert parts["back"].mesh.vertices[:, 1].mean() < -0.3 * size[1] / 2
        assert parts["back"].mesh.vertices[:, 2].max() > parts["seat"].mesh.vertices[:, 2].max()
        surfs = support_surfaces("chair", size, params)
        assert len(surfs) == 1 and surfs[0].clearance == pytest.approx(0.5)


def test_two_chairs_differ():
    samples = [sample_params("chair", np.random.default_rng(seed)) for seed in range(6)]
    assert len({repr(s) for s in samples}) > 1
    meshes = [make_mesh("chair", s, p) for s, p in samples]
    assert len({m.vertices.tobytes() for m in meshes}) > 1
    styles = {(p["leg_style"], p["back_style"]) for _, p in
              (sample_params("chair", np.random.default_rng(seed)) for seed in range(20))}
    assert len(styles) > 2


@pytest.mark.parametrize("cls,part", [("sofa", "back"), ("armchair", "back"), ("bed", "headboard"),
                                      ("toilet", "tank")])
def test_backs_are_at_minus_y(cls, part):
    for seed in SEEDS:
        size, params = sample_params(cls, np.random.default_rng(seed))
        parts = {p.name: p for p in make_parts(cls, size, params)}
        assert parts[part].mesh.vertices[:, 1].mean() < 0, (cls, seed)


@pytest.mark.parametrize("cls", ["tv", "laptop"])
def test_screens_face_plus_y(cls):
    for seed in SEEDS:
        size, params = sample_params(cls, np.random.default_rng(seed))
        parts = {p.name: p for p in make_parts(cls, size, params)}
        scr = parts["screen"].mesh
        # the screen's outward faces point towards +y (the front)
        normals = scr.face_normals
        areas = scr.area_faces
        best = normals[np.argmax(areas * normals[:, 1])]
        assert best[1] > 0.8, (cls, seed, best)
        body = parts["panel" if cls == "tv" else "lid"].mesh
        assert scr.vertices[:, 1].mean() > body.vertices[:, 1].mean()  # in front of the panel / lid


@pytest.mark.parametrize("cls", ["picture", "mirror"])
def test_wall_objects_hang_with_back_at_minus_y(cls):
    for seed in SEEDS:
        size, params = sample_params(cls, np.random.default_rng(seed))
        assert size[1] < 0.1 and size[1] < size[0] and size[1] < size[2]
        parts = {p.name: p for p in make_parts(cls, size, params)}
        face = parts["canvas" if cls == "picture" else "pane"].mesh
        assert face.vertices[:, 1].min() == pytest.approx(-size[1] / 2, abs=1e-6)


def test_bed_surface_is_mattress_top():
    for seed in SEEDS:
        size, params = sample_params("bed", np.random.default_rng(seed))
        parts = {p.name: p for p in make_parts("bed", size, params)}
        top = parts["mattress"].mesh.vertices[:, 2].max()
        surfs = support_surfaces("bed", size, params)
        assert surfs
        assert min(abs(s.z - top) for s in surfs) < 1e-6
        assert all(s.z < size[2] for s in surfs)


def test_surfaces_of_tables_and_seats():
    size, params = sample_params("dining_table", np.random.default_rng(0))
    s = support_surfaces("dining_table", size, params)
    assert any(abs(x.z - size[2]) < TOL and math.isinf(x.clearance) for x in s)
    for cls in ("sofa", "armchair"):
        size, params = sample_params(cls, np.random.default_rng(1))
        s = support_surfaces(cls, size, params)
        assert len(s) == 1 and 0 < s[0].z < size[2]
    for cls in ("picture", "mirror", "plant", "floor_lamp", "ceiling_light", "vase"):
        size, params = sample_params(cls, np.random.default_rng(0))
        assert support_surfaces(cls, size, params) == []


def test_book_orientation_follows_params():
    standing = make_parts("book", (0.03, 0.2, 0.24), {"orientation": "standing"})
    lying = make_parts("book", (0.16, 0.24, 0.03), {"orientation": "lying"})
    _check_parts("book", (0.03, 0.2, 0.24), standing)
    _check_parts("book", (0.16, 0.24, 0.03), lying)
    for seed in range(10):
        size, params = sample_params("book", np.random.default_rng(seed))
        w, d, h = size
        if params["orientation"] == "standing":
            assert w < h
        else:
            assert h < w


def test_other_is_a_box():
    parts = make_parts("other", (0.3, 0.2, 0.1), {})
    assert len(parts) == 1
    assert len(parts[0].mesh.vertices) == 8


@pytest.mark.parametrize("fn", [
    lambda c: make_parts(c, (1, 1, 1), {}),
    lambda c: make_mesh(c, (1, 1, 1), {}),
    lambda c: support_surfaces(c, (1, 1, 1), {}),
    lambda c: sample_params(c, np.random.default_rng(0)),
])
@pytest.mark.parametrize("cls", ["sofaa", "wall", "floor", "ceiling"])
def test_unknown_class_raises(fn, cls):
    with pytest.raises(ValueError, match=repr(cls)) as info:
        fn(cls)
    assert isinstance(info.value, UnknownClassError)


@pytest.mark.parametrize("size", [(0, 1, 1), (1, -1, 1), (1, 1, float("nan")), (1, 1)])
def test_bad_size_raises(size):
    with pytest.raises(ValueError):
        make_parts("chair", size, {})


def test_params_with_junk_values_fall_back():
    parts = make_parts("chair", (0.45, 0.5, 0.85), {"leg_thickness": "thick", "n_slats": None,
                                                    "frame_material": "unobtainium", "seat_color": [1, 2]})
    _check_parts("chair", (0.45, 0.5, 0.85), parts)
