"""Stage variants (synth.sources.replicacad.stages, tools/replicacad_standin.py --stage) on the real-format
ReplicaCAD fixture: each shipped variant builds, with a stage card; each rule does what it says
(footprint, stairs, ceiling, skew, noise, materials); bad variant files are one line, exit 2, nothing
written."""

from __future__ import annotations

import json
import math
import shutil

import numpy as np
import pytest
import trimesh

from vrformats.errors import SceneFormatError
from synth.sources.replicacad.navmesh import StandinSpec, read_navmesh, standin_stage, write_standin_glb
from synth.sources.replicacad.stages import (CARD_SUFFIX, StageRules, build, load_stage_rules, load_stage_variant,
                                             make_stage, object_footprints, stage_scenes, stage_variants,
                                             structure_counts)

from replicacad_real_fixture import STAGE_GLB, STAGE_NAVMESH, standin_tool, write_real_fixture

SHIPPED = ("standin", "plain", "painted", "scanlike")
STAGE = "frl_apartment_stage"


@pytest.fixture(scope="module")
def root(tmp_path_factory):
    """The fixture dataset: its stage built by stages.fill under the ``standin`` variant."""
    return write_real_fixture(tmp_path_factory.mktemp("rc_stagevar"))


@pytest.fixture(scope="module")
def src(root, tmp_path_factory):
    """The fixture without its stage GLB (as the public copy of ReplicaCAD comes)."""
    s = tmp_path_factory.mktemp("src") / "rc"
    shutil.copytree(root, s)
    for p in (s / "stages").iterdir():
        p.unlink()
    return s


@pytest.fixture(scope="module")
def built(src, tmp_path_factory):
    """OUT folders built under the shipped variants (standin is the fixture itself)."""
    out = {}
    for v in ("plain", "painted", "scanlike"):
        out[v] = tmp_path_factory.mktemp("out") / v
        build(src, out[v], load_stage_variant(v))
    return out


@pytest.fixture(scope="module")
def nav(root):
    return read_navmesh(root / STAGE_NAVMESH)


@pytest.fixture(scope="module")
def navmesh_stage(nav):
    """The stand-in with the default rules but footprint navmesh (stairs, windows)."""
    return make_stage(nav, 0.0, StageRules(footprint="navmesh"), STAGE)[0]


def _parts(glb) -> dict:
    from synth.mesh.gltf import load_glb_parts

    return {p.metadata["gltf"]["name"]: p for p in load_glb_parts(glb)}


def _stage(nav, tmp_path, **rules):
    """Build the stand-in under ``rules`` (footprint navmesh unless given) and write its GLB."""
    rules.setdefault("footprint", "navmesh")
    s, visuals, applied = make_stage(nav, 0.0, StageRules(**rules), STAGE)
    glb = write_standin_glb(s, tmp_path / f"stage_{len(list(tmp_path.iterdir()))}.glb", visuals)
    return s, applied, glb


def test_shipped_variants_and_their_rules():
    assert set(SHIPPED) <= set(stage_variants())
    r = {v: load_stage_rules(v) for v in SHIPPED}
    assert r["standin"] == StageRules()  # the tool's default, as it always built it
    assert (r["plain"].footprint, r["plain"].ceiling, r["plain"].stairs, r["plain"].windows) == ("navmesh", 2.6, False, False)
    assert r["plain"].materials == {"walls": "plain", "floor": "plain", "ceiling": "plain"}
    p = r["painted"]
    assert (p.footprint, p.ceiling, p.stairs, p.windows, p.window_frames, p.baseboards) == ("objects", 2.5, True, True, True, True)
    assert (p.materials["walls"], p.materials["floor"]) == ("painted", "tiled")
    s = r["scanlike"]
    assert (s.footprint, s.ceiling, s.stairs, s.window_frames, s.baseboards, s.skew_deg, s.noise_m) == \
        ("navmesh", 3.0, True, True, True, 2.0, 0.01)
    assert (s.materials["walls"], s.materials["floor"]) == ("textured", "textured")


def test_the_standin_variant_is_the_tools_old_default(root, nav, tmp_path):
    """Under the ``standin`` rules a stage is byte for byte what the stand-in builder gives with its
    defaults (the tool's output before variants), around the same objects (apt_0's here)."""
    scenes = [x for x in stage_scenes(root)[STAGE] if x[0].name.startswith("apt_0.")]
    keep, tops, bottoms, _ = object_footprints(root, scenes, 0.0, StandinSpec.ceiling)
    assert len(keep) > 100
    s = standin_stage(nav, StandinSpec(floor_z=0.0, keep=keep, keep_tops=tops, keep_bottoms=bottoms))
    old = write_standin_glb(s, tmp_path / "old_default.glb")
    v, visuals, _ = make_stage(nav, 0.0, load_stage_rules("standin"), STAGE, keep, tops, bottoms)
    assert visuals == {} and v.report == s.report
    assert write_standin_glb(v, tmp_path / "standin.glb", visuals).read_bytes() == old.read_bytes()


def test_every_shipped_variant_builds_with_a_stage_card(root, built):
    from synth.version import __version__

    cards = {"standin": json.loads((root / "stages" / f"{STAGE}{CARD_SUFFIX}").read_text())}
    for v, out in built.items():
        assert (out / STAGE_GLB).is_file()
        cards[v] = json.loads((out / "stages" / f"{STAGE}{CARD_SUFFIX}").read_text())
        notes = (out / "STANDIN.md").read_text()
        assert f"Stage variant: **{v}**" in notes and "What a stand-in cannot show" in notes
    for v, c in cards.items():
        rules = load_stage_rules(v)
        assert c["variant"]["name"] == v and c["rules"] == rules.to_dict() and c["seed"] == rules.seed
        assert c["toolkit_version"] == __version__ and c["stage"] == STAGE and c["glb"] == STAGE_GLB
        b = c["built"]
        assert b["variant"] == v and b["ceiling_z"] == pytest.approx(rules.ceiling)
        assert b["footprint_m2"] > 55 and b["levels"] and b["windows"] == len(b["window_list"])
        assert (b["windows"] > 0) == rules.windows
    assert cards["standin"]["structure"] is None  # the fixture is written without the report
    for v in built:
        st = cards[v]["structure"]
        assert st["scene"] == "apt_0" and st["walls"] > 10 and st["rooms"] >= 1 and st["floors"] >= 1 and st["ceilings"] >= 1
        assert st["ceiling_height"] == pytest.approx(load_stage_rules(v).ceiling)  # what the importer finds
        assert st["windows"] >= cards[v]["built"]["windows"] and st["openings"] == st["doors"] + st["windows"]
        assert isinstance(st["fill_ratio_warnings"], list) and set(st["fill_ratio_warnings"]) <= set(st["fill_ratio"])
    # the painted variant's frames and baseboards do not change what the importer finds: as the
    # standin's (test_structure_report_of_the_standin), 4 windows built and one more found
    st = cards["painted"]["structure"]
    assert (st["walls"], st["windows"], cards["painted"]["built"]["windows"]) == (50, 5, 4)
    assert cards["painted"]["built"]["window_frames"] == 4 and cards["painted"]["built"]["baseboards_m2"] > 2


def test_structure_report_of_the_standin(root):
    st = structure_counts(root, stage_scenes(root)[STAGE][0], root / STAGE_GLB)
    assert (st["walls"], st["rooms"], st["doors"], st["windows"]) == (50, 1, 0, 5)
    assert st["ceiling_height"] == pytest.approx(2.8) and st["fill_ratio_warnings"] == ["room_0"]


def test_plain_has_no_steps_and_its_walls_hug_the_navmesh_footprint(built, nav):
    from synth.mesh.stage_structure import rasterise

    parts = _parts(built["plain"] / STAGE_GLB)
    assert set(parts) == {"floor", "walls", "ceiling"}
    main = nav.levels()[0]
    fp = nav.footprint(main)
    cell = fp.cell
    floor = parts["floor"]
    up = (floor.face_normals[:, 2] > 0.99) & (np.abs(floor.triangles_center[:, 2]) < 1e-6)
    got = rasterise((floor.triangles[up][:, :, :2] - fp.origin) / cell, fp.mask.shape)
    assert np.array_equal(got, fp.mask)  # the free floor is the main level's navmesh footprint, cell for cell
    w = parts["walls"]
    vert = np.abs(w.face_normals[:, 2]) < 1e-6
    ahead = w.triangles_center[vert][:, :2] + 0.5 * cell * w.face_normals[vert][:, :2]
    behind = w.triangles_center[vert][:, :2] - 0.5 * cell * w.face_normals[vert][:, :2]
    inner = fp.contains(ahead)
    assert not fp.contains(behind[inner]).any()  # inner faces lie on the footprint's edge
    area = 0.5 * np.linalg.norm(np.cross(w.triangles[:, 1] - w.triangles[:, 0], w.triangles[:, 2] - w.triangles[:, 0]), axis=1)
    m = fp.mask
    perimeter = (np.sum(m[1:] != m[:-1]) + np.sum(m[:, 1:] != m[:, :-1])) * cell
    assert area[vert][inner].sum() == pytest.approx(perimeter * 2.6, rel=1e-6)  # ... all of its edge, floor to ceiling


def test_no_stairs_gives_one_level_and_no_raised_floor(nav, navmesh_stage, tmp_path):
    with_stairs = navmesh_stage
    s, applied, glb = _stage(nav, tmp_path, stairs=False, windows=False)
    assert len(with_stairs.report["levels"]) == 5 and with_stairs.report["raised_m2"] > 5 and "steps" in with_stairs.parts
    assert len(s.report["levels"]) == 1 and s.report["raised_m2"] == 0 and s.report["floating_m2"] == 0
    assert "steps" not in s.parts and s.stair_ceiling_z is None and applied["levels_left_out"] == 4
    m = trimesh.util.concatenate(list(_parts(glb).values()))
    up = m.face_normals[:, 2] > 0.99
    z = m.triangles_center[up, 2]
    assert np.all((np.abs(z) < 1e-6) | (z > 2.8 - 1e-6))  # up-facing: the floor, or the top of the ceiling slab
    # where the stairs were is floor only where it is the main level's footprint
    assert s.footprint.area == pytest.approx(nav.footprint(nav.levels()[0]).area)


@pytest.mark.parametrize("ceiling", [2.4])  # the shipped variants' (2.5, 2.6, 3.0): their cards, above
def test_the_ceiling_is_the_rule(nav, tmp_path, ceiling):
    from synth.mesh.gltf import glb_geometry
    from synth.mesh.stage_structure import derive_structure

    s, _, glb = _stage(nav, tmp_path, stairs=False, ceiling=ceiling)
    assert s.ceiling_z == pytest.approx(ceiling)
    assert derive_structure(glb_geometry(glb), str(glb)).ceiling_height == pytest.approx(ceiling)


@pytest.mark.parametrize("skew", [2.0, -7.5])
def test_skew_rotates_the_wall_normals(nav, navmesh_stage, tmp_path, skew):
    from synth.mesh.gltf import glb_geometry

    straight = navmesh_stage
    s, applied, glb = _stage(nav, tmp_path, skew_deg=skew)
    w = _parts(glb)["walls"]
    vert = np.abs(w.face_normals[:, 2]) < 1e-6
    ang = np.degrees(np.arctan2(w.face_normals[vert, 1], w.face_normals[vert, 0]))
    off = (ang - skew + 45.0) % 90.0 - 45.0
    assert vert.sum() > 100 and np.abs(off).max() < 0.01  # every wall face turned by the angle (float32 in the GLB)
    assert applied["skew"]["deg"] == skew
    m = straight.footprint.mask
    perimeter = (np.sum(m[1:] != m[:-1]) + np.sum(m[:, 1:] != m[:, :-1])) * straight.footprint.cell
    assert abs(s.footprint.area - straight.footprint.area) < perimeter * straight.footprint.cell  # within a cell
    # a wall's staircase of runs on the rotated grid is one run for the windows: no more windows than straight
    assert straight.report["windows"] / 2 <= s.report["windows"] <= straight.report["windows"] + 1
    m = glb_geometry(glb)
    assert m.bounds[0][2] == pytest.approx(-0.1) and m.bounds[1][2] == pytest.approx(straight.stair_ceiling_z + 0.1)  # about Z only


def _noisy(nav, tmp_path, noise, seed):
    s, applied, glb = _stage(nav, tmp_path, stairs=False, noise_m=noise, seed=seed)
    return s, applied


def test_noise_is_seeded_bounded_horizontal_and_keeps_the_surface_closed(nav, tmp_path):
    ref, _ = _noisy(nav, tmp_path, 1e-9, 1)  # the same split of the T-junctions, all but unmoved
    a, info = _noisy(nav, tmp_path, 0.01, 1)
    b, _ = _noisy(nav, tmp_path, 0.01, 1)
    c, _ = _noisy(nav, tmp_path, 0.01, 2)
    for n in a.parts:
        assert np.array_equal(a.parts[n].vertices, b.parts[n].vertices)  # same seed, same mesh
    assert any(not np.array_equal(a.parts[n].vertices, c.parts[n].vertices) for n in a.parts)  # another seed, another
    clip = min(3 * 0.01, 0.45 * nav.cell_size)
    d = np.concatenate([a.parts[n].vertices - ref.parts[n].vertices for n in a.parts])
    assert np.abs(d[:, 2]).max() < 1e-12  # horizontal only
    assert np.abs(d[:, :2]).max() <= clip + 1e-6 and np.abs(d[:, :2]).max() > 0.015
    assert 0.007 < info["noise"]["rms_m"] < 0.013 and info["noise"]["max_m"] <= clip
    # vertices at one XY move together: a wall's quads stay vertical (the triangles fanned where
    # T-junctions were split lean by less than a degree), and the surface stays closed
    vert = np.abs(ref.parts["walls"].face_normals[:, 2]) < 1e-9
    nz = np.abs(a.parts["walls"].face_normals[vert, 2])
    assert vert.mean() > 0.5 and (nz < 1e-9).mean() > 0.9 and nz.max() < math.sin(math.radians(1.0))
    for s in (ref, a):
        m = trimesh.util.concatenate(list(s.parts.values()))
        m.merge_vertices()
        assert m.is_watertight and m.is_winding_consistent
    with pytest.raises(SceneFormatError, match="noise_m"):
        StageRules(noise_m=0.03)


def test_a_tiled_floor_is_a_texture_the_gltf_reader_reads(nav, tmp_path):
    from synth.mesh.gltf import check_glb, pbr, sample_base_color

    s, applied, glb = _stage(nav, tmp_path, stairs=False, materials={"floor": "tiled", "walls": "painted"}, seed=5)
    check_glb(glb)
    parts = _parts(glb)
    floor = pbr(parts["floor"])
    tex = floor["base_color_texture"]
    assert tex is not None and tex.size == (256, 256) and "baseColorTexture" in floor["sources"]
    uv = parts["floor"].visual.uv
    assert uv is not None and len(uv) == len(parts["floor"].vertices)
    tile = applied["material_details"]["floor"]["tile_m"]
    assert 0.3 <= tile <= 0.6
    # UVs are the floor's XY over 4 tiles: the texture repeats every 4 tiles on the floor
    f = parts["floor"]
    up = np.flatnonzero(f.face_normals[:, 2] > 0.99)
    k = up[np.argmax(f.area_faces[up])]
    corners = f.faces[k]
    np.testing.assert_allclose(uv[corners] * 4 * tile, f.vertices[corners][:, :2], atol=1e-6)
    # grout between the tiles is darker than the tiles
    img = np.asarray(tex.convert("RGB"), float)
    assert img[::64].mean() < 0.8 * img[32::64].mean()
    col = sample_base_color(parts["floor"], np.array([k]), np.array([[1 / 3, 1 / 3, 1 / 3]]))
    assert col.shape == (1, 3) and np.all(col > 0)
    walls = pbr(parts["walls"])
    assert walls["base_color_texture"] is None and walls["base_color"][:3] == pytest.approx(
        applied["material_details"]["walls"]["colour"], abs=1 / 255)  # (trimesh writes factors in 8 bits)
    assert pbr(parts["ceiling"])["base_color_texture"] is None  # plain: today's colour
    # another seed, another tile
    _, other, _ = _stage(nav, tmp_path, stairs=False, windows=False, materials={"floor": "tiled"}, seed=6)
    assert other["material_details"]["floor"]["tile_m"] != tile


def _tool(args, capsys):
    code = standin_tool().main([str(a) for a in args])
    err = capsys.readouterr().err.strip()
    return code, err


@pytest.mark.parametrize("rules,field,words", [
    ("ceiling: 1.9", "rules.ceiling", "from 2.4 to 3"),
    ("materials: {walls: marble}", "rules.materials.walls", "plain, painted, tiled, textured"),
    ("colour: red", "rules.colour", "unknown rule"),
    ("skew_deg: two", "rules.skew_deg", "expected an angle"),
    ("stairs: yes please", "rules.stairs", "true or false"),
    ("noise_m: 0.05", "rules.noise_m", "from 0 to 0.02"),
])
def test_a_bad_variant_file_is_one_line_exit_2_nothing_written(root, tmp_path, capsys, rules, field, words):
    f = tmp_path / "bad.yaml"
    f.write_text(f"name: bad\ndescription: a bad variant\nrules:\n  {rules}\n")
    out = tmp_path / "out"
    code, err = _tool([root, out, "--stage", f], capsys)
    assert code == 2 and len(err.splitlines()) == 1, err
    assert f"{f}: {field}: " in err and words in err, err
    assert not out.exists() and not (tmp_path / "out.building").exists()


def test_unknown_variant_names_and_bad_rules_in_code(root, tmp_path, capsys):
    code, err = _tool([root, tmp_path / "out", "--stage", "nosuch"], capsys)
    assert code == 2 and "nosuch" in err and "standin" in err and "scanlike" in err and not (tmp_path / "out").exists()
    code, err = _tool([root, tmp_path / "out", "--ceiling", "nan"], capsys)
    assert code == 2 and "--ceiling" in err
    for kw, field in ((dict(ceiling=1.0), "ceiling"), (dict(footprint="walls"), "footprint"), (dict(seed=-1), "seed"),
                      (dict(materials={"floor": "marble"}), "materials.floor"), (dict(skew_deg="2"), "skew_deg")):
        with pytest.raises(SceneFormatError, match=f"StageRules: {field}: "):
            StageRules(**kw)


def test_furnished_floor_is_the_scenes_own_navmeshes_and_splits_the_flat(src, tmp_path):
    """`furnished` (the rules under which the issue-55 user's stand-in broke our checks): the floor is the
    union of the scenes' own navmeshes (navmeshes/apt_K.navmesh, built with the furniture; the vendored
    real files), smaller than the empty stage's footprint, with walls just outside it; the importer
    finds two rooms on it, as that user saw."""
    out = tmp_path / "furnished"
    rows = build(src, out, load_stage_variant("furnished"))
    row = next(r for r in rows if r["kind"] == "stage" and r["file"].endswith(f"{STAGE}.glb"))
    assert sorted(row["navmeshes"]) == [f"navmeshes/apt_{k}.navmesh" for k in range(6)]
    plain = build(src, tmp_path / "plain", load_stage_variant("plain"))
    plain_row = next(r for r in plain if r["kind"] == "stage" and r["file"].endswith(f"{STAGE}.glb"))
    assert row["footprint_m2"] < plain_row["footprint_m2"] - 1.0, (row["footprint_m2"], plain_row["footprint_m2"])
    card = json.loads((out / "stages" / f"{STAGE}{CARD_SUFFIX}").read_text())
    assert card["variant"]["name"] == "furnished" and card["rules"]["footprint"] == "furnished"
    assert card["structure"]["rooms"] == 2, card["structure"]
