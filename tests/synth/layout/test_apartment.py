"""The built-in apartment and its variants: requirements of the paper's design and plausibility."""

from __future__ import annotations

import json
from collections import Counter

import pytest

from synth.layout.apartment import DEFAULT_SEED, generate_apartment
from synth.layout.validity import check_layout
from synth.cli import main as synth_main
from synth.layout.rearrange import BUILTIN_VARIANTS, RearrangePlan, rearrange
from synth.scene.model import layout_to_dict, load_layout, object_box
from synth.scene.stats import PAPER_RANGES, change_stats

VARIANTS = [v.name for v in BUILTIN_VARIANTS]
ALL = ["apt_0"] + VARIANTS


@pytest.fixture(scope="module")
def apt0():
    return load_layout("apt_0")


def test_generation_is_deterministic_and_matches_shipped_file(apt0):
    a = generate_apartment(DEFAULT_SEED, "apt_0")
    b = generate_apartment(DEFAULT_SEED, "apt_0")
    assert layout_to_dict(a) == layout_to_dict(b)
    # the shipped scenes/layouts/apt_0.yaml is what the generator makes (no drift)
    assert layout_to_dict(a) == layout_to_dict(apt0)
    c = generate_apartment(DEFAULT_SEED + 1, "apt_0")
    assert layout_to_dict(c) != layout_to_dict(a)


def test_apartment_size_rooms_objects_classes(apt0):
    assert 80.0 <= apt0.stage.area <= 110.0
    types = {r.type for r in apt0.stage.rooms}
    assert {"living", "kitchen", "bedroom", "bathroom", "hallway"} <= types
    assert len(apt0.objects) >= 90
    counts = Counter(o.cls for o in apt0.objects)
    assert len(counts) >= 25
    # repeated classes make labels ambiguous, as in real homes
    for cls, n in {"chair": 4, "cushion": 3, "book": 6, "picture": 4}.items():
        assert counts[cls] >= n, (cls, counts[cls])
    assert counts["plant"] + counts["small_plant"] >= 4
    assert counts["floor_lamp"] + counts["table_lamp"] >= 3
    # every lamp is a light fixture; every window is one too
    lamp_ids = {o.id for o in apt0.objects if o.cls in ("floor_lamp", "table_lamp")}
    assert lamp_ids <= {f.object for f in apt0.fixtures if f.kind == "lamp"}
    assert sum(f.kind == "window" for f in apt0.fixtures) == sum(o.kind == "window" for o in apt0.stage.openings)


def test_objects_vary_within_a_class(apt0):
    chairs = [o for o in generate_apartment(11).objects + apt0.objects if o.cls == "chair"]
    assert len({(tuple(o.size), json.dumps(o.params, sort_keys=True)) for o in chairs}) > 1


@pytest.mark.parametrize("name", ALL)
def test_builtin_layouts_check_clean(name):
    rep = check_layout(load_layout(name))
    assert rep.ok, rep.to_dict()


@pytest.mark.parametrize("name", VARIANTS)
def test_variant_stats_in_paper_ranges(apt0, name):
    st = change_stats(apt0, load_layout(name))
    for k, (lo, hi) in PAPER_RANGES.items():
        assert lo <= st[k] <= hi, (name, k, st[k])


@pytest.mark.parametrize("name", VARIANTS)
def test_variants_keep_shell_and_fixed_objects(apt0, name):
    var = load_layout(name)
    assert layout_to_dict(var)["stage"] == layout_to_dict(apt0)["stage"]
    ref = apt0.by_id()
    for o in var.objects:
        if o.id in ref and not ref[o.id].movable:
            assert o.position == ref[o.id].position and o.rotation == ref[o.id].rotation, o.id
    assert var.reference == "apt_0"


def test_stats_cli_json_keys(capsys):
    assert synth_main(["scene", "stats", "apt_0", "apt_1", "--json"]) == 0
    st = json.loads(capsys.readouterr().out)
    assert {"moved_over_0.1m", "moved_over_0.5m", "moved_median_m", "added", "removed"} <= set(st)


def test_stats_against_hand_made_change(apt0):
    var = apt0.copy(name="hand")
    o = next(o for o in var.objects if o.cls == "basket")
    before = object_box(o).center
    o.position = (o.position[0] + 0.24, o.position[1] + 0.32, o.position[2])  # a 0.4 m move
    removed = var.objects.pop(-1)
    st = change_stats(apt0, var)
    assert st["moved_over_0.1m"] == 1 and st["moved_over_0.5m"] == 0
    assert st["moved_median_m"] == pytest.approx(0.4, abs=1e-3)
    assert st["removed"] == 1 and st["added"] == 0
    assert removed.id not in var.by_id() and before != object_box(o).center


def test_check_cli_json(capsys):
    assert synth_main(["scene", "check", "apt_3", "--json"]) == 0
    rep = json.loads(capsys.readouterr().out)
    assert rep["collisions"] == [] and rep["unsupported"] == [] and rep["blocked_doors"] == []
    assert rep["objects"] >= 90 and rep["classes"] >= 25


# ---- the check can fail: each kind of problem is found -------------------------------------


def test_check_finds_interpenetration(apt0):
    lay = apt0.copy()
    a, b = [o for o in lay.objects if o.cls == "chair"][:2]
    b.position = (a.position[0] + 0.05, a.position[1], a.position[2])
    rep = check_layout(lay)
    assert any({c["a"], c["b"]} == {a.id, b.id} for c in rep.collisions)


def test_check_finds_floating_and_overhanging_objects(apt0):
    lay = apt0.copy()
    sofa = next(o for o in lay.objects if o.cls == "sofa")
    sofa.position = (sofa.position[0], sofa.position[1], 0.2)
    book = next(o for o in lay.objects if o.cls == "book" and o.support.startswith("object:"))
    book.position = (book.position[0] + 5.0, book.position[1], book.position[2])
    rep = check_layout(lay)
    bad = {u["id"] for u in rep.unsupported}
    assert sofa.id in bad and book.id in bad


def test_check_finds_object_through_ceiling(apt0):
    lay = apt0.copy()
    lamp = next(o for o in lay.objects if o.cls == "floor_lamp")
    lamp.position = (lamp.position[0], lamp.position[1], lay.stage.ceiling_height - 0.5)
    rep = check_layout(lay)
    assert any(c["a"] == lamp.id and c["b"] == "ceiling" for c in rep.collisions)
    assert any(u["id"] == lamp.id for u in rep.unsupported)


def test_check_finds_blocked_door(apt0):
    lay = apt0.copy()
    door = next(op for op in lay.stage.openings if op.id == "D_bathroom")
    c = door.center_xy(lay.stage.wall(door.wall))
    cab = next(o for o in lay.objects if o.cls == "cabinet")
    cab.position = (float(c[0]) - 0.5, float(c[1]), 0.0)
    rep = check_layout(lay)
    assert any(d["door"] == "D_bathroom" for d in rep.blocked_doors)


def test_rearrange_is_seeded(apt0):
    plan = RearrangePlan(floor_moves=5, surface_moves=3, wall_moves=1, added=2, removed=1)
    a = rearrange(apt0, "x", 5, plan)
    b = rearrange(apt0, "x", 5, plan)
    c = rearrange(apt0, "x", 6, plan)
    assert layout_to_dict(a) == layout_to_dict(b)
    assert layout_to_dict(a) != layout_to_dict(c)
    assert check_layout(a).ok
