"""Graded rearrangement (issue 29): nested variants of one layout at strengths from 0 to 1.

The paper's variants change a layout by one amount. To ask *where* a relocalizer breaks, the
amount must be a dial. ``graded_variants`` orders the layout's movable units (floor objects with
what stands on them, small objects on surfaces, things on walls; the ones the operator of
``synth.layout.rearrange`` moves) in a seeded random order and moves them one after the other with
that operator's primitives, each to a valid place in the layout as the previous moves left it
(supported, collision-free, doors passable, clear of the reference's walkway). The variant at
strength ``s`` is the layout after the first ``round(s * N)`` moves of that one sequence, so

* level 0 is the reference itself, unchanged;
* the objects moved at strength ``s`` are a subset of those moved at any ``s' > s``, and each level
  adds change and nothing else (same seed, same sequence);
* every level is valid, because every move was checked against the layout it is applied to: by
  the placer, and in an imported flat also by ``check_layout`` (a move that adds a problem the
  reference lacks, such as a picture hung into the flat's mesh wall, is undone and its unit stays).

A unit whose move finds no valid place stays (the step still counts, and the level's ``meta``
says how many units moved). ``beyond``: one more level past strength 1, which also moves the fixed
fittings the operator keeps (non-movable floor objects: counters, wardrobes, bathtubs), removes
objects and adds new ones (``RearrangePlan``'s counts; scaled to the flat's size for an imported
one, ``scaled_plan``): change beyond the paper's range.
"""

from __future__ import annotations


import numpy as np

from vrformats.errors import UserError
from vrformats.fields import is_number

from ..scene.fixtures import layout_fixtures
from ..scene.model import Layout
from .placement import Placer
from ..scene.stats import is_imported
from .rearrange import (VARIANT_META, RearrangePlan, add_objects, holds_others, put_elsewhere, rehang, relocate_floor,
                        free_rests, new_problems)
from .validity import check_layout

BEYOND = "beyond"


def check_strengths(strengths, what: str = "strength") -> list[float]:
    """Strengths as sorted distinct floats in [0, 1] (one-line UserError naming ``what`` otherwise)."""
    out = []
    for s in strengths:
        if not is_number(s) or not 0.0 <= s <= 1.0:
            raise UserError(f"{what}: expected a number in [0, 1] (0 = unchanged, 1 = every movable object moved), got {s!r}")
        out.append(float(s))
    if len(set(out)) != len(out):
        raise UserError(f"{what}: a level is listed twice ({', '.join(map(str, out))})")
    out = sorted(out)
    for a, b in zip(out, out[1:]):  # level names are in whole percent (apt_0_g050): two levels must not share one
        if level_name("x", a) == level_name("x", b):
            raise UserError(f"{what}: {a:g} and {b:g} are the same level to the percent that names it "
                            f"({level_name('x', a)[2:]}); levels must differ by at least 0.01")
    return out


def level_name(base: str, level) -> str:
    """``apt_0_g025`` for strength 0.25; ``apt_0_gbeyond`` for the beyond level."""
    return f"{base}_g{level}" if level == BEYOND else f"{base}_g{int(round(float(level) * 100)):03d}"


def _units(placer: Placer, pinned: set[int]) -> list:
    lay = placer.layout
    return [o for o in sorted(lay.objects, key=lambda o: o.id) if o.movable and o.id not in pinned
            and (o.support == "floor" or o.support.startswith("object:") or o.support.startswith("wall:"))]


def _move(placer: Placer, oid: int, rests, other_room: float, ref_report=None) -> bool:
    """Move unit ``oid``; with ``ref_report`` (the reference's ``check_layout``), a move after which
    the layout has a check problem the reference lacks (an imported flat's walls are meshes the
    placer's boxes do not see) is undone, and the unit stays."""
    if ref_report is None:
        return _try_move(placer, oid, rests, other_room)
    lay = placer.layout
    saved_objects, saved_boxes = list(lay.objects), dict(placer.boxes)  # to undo a refused move
    ok = _try_move(placer, oid, rests, other_room)
    if ok and new_problems(ref_report, check_layout(lay)):
        lay.objects, placer.boxes = saved_objects, saved_boxes
        return False
    return ok


def _try_move(placer: Placer, oid: int, rests, other_room: float) -> bool:
    obj = placer.layout.object(oid)
    if obj.support == "floor":
        return relocate_floor(placer, obj, other_room, rests) is not None
    if obj.support.startswith("wall:"):
        return rehang(placer, obj, other_room) is not None
    if holds_others(placer, oid, rests):  # a small object something was put on since: it stays
        return False
    return put_elsewhere(placer, obj, RearrangePlan(other_room=other_room)) is not None


def graded_variants(ref: Layout, strengths, seed: int, walkway: np.ndarray | None = None, beyond: bool = False,
                    other_room: float = 0.2, plan: RearrangePlan = RearrangePlan()) -> list[tuple[object, Layout]]:
    """``[(level, layout)]`` for each strength (sorted; level 0 is ``ref`` itself) and, with
    ``beyond``, a last ``("beyond", layout)``. See the module docstring."""
    levels = check_strengths(strengths)
    if is_imported(ref) and not ref.stage.rooms:
        raise UserError(f"layout '{ref.name}': rearranging needs the stage's rooms, walls and openings")
    from .rearrange import WALKWAY_CLEARANCE

    lay = ref.copy()
    rng = np.random.default_rng([int(seed), 29])
    placer = Placer(lay, rng, keepout=None if walkway is None else (walkway, WALKWAY_CLEARANCE),
                    used_ids=max([o.id for o in ref.objects] + [0]) if is_imported(ref) else 0)
    rests, pinned = free_rests(lay)
    # an imported flat's walls are meshes the placer's boxes do not see: each move is checked there
    # (a procedural flat's placer applies the check's own rules; its levels are checked by the tests)
    ref_report = check_layout(ref) if is_imported(ref) else None
    units = _units(placer, pinned)
    order = [units[k].id for k in rng.permutation(len(units))]
    want: dict[int, float] = {}
    for s_ in levels:  # each level moves its own number of units, or it is not a level of its own
        k = int(round(s_ * len(order)))
        if k in want:
            raise UserError(f"levels {want[k]:g} and {s_:g} both move {k} of the {len(order)} movable units of "
                            f"'{ref.name}'; on this flat levels must differ by at least {1 / max(len(order), 1):.3g}")
        want[k] = s_
    out: list[tuple[object, Layout]] = []
    moved = fixed_moved = 0

    def snapshot(level, steps: int) -> Layout:
        lay.fixtures = layout_fixtures(lay, previous=ref)  # lamps' lights follow their lamps; removed ones go
        v = lay.copy()
        v.name, v.reference, v.seed = level_name(ref.name, level), ref.name, int(seed)
        v.meta = {**{k: x for k, x in ref.meta.items() if k not in VARIANT_META},  # an import record stays
                  "generator": "synth.graded", "strength": level, "units": len(order), "steps": steps,
                  "units_moved": moved, "fixed_moved": fixed_moved, "graded_seed": int(seed)}
        if walkway is not None:
            v.meta["walkway"] = {"planned_on": ref.name, "clearance_m": WALKWAY_CLEARANCE}
        v.objects.sort(key=lambda o: o.id)
        return v

    if 0 in want:
        out.append((want[0], ref))
    for k, oid in enumerate(order):
        if (k + 1) > max(want):
            break
        if any(o.id == oid for o in lay.objects):
            moved += _move(placer, oid, rests, other_room, ref_report)
        if (k + 1) in want:
            out.append((want[k + 1], snapshot(want[k + 1], k + 1)))
    if beyond:
        if is_imported(ref):  # counts for a flat of another size, as make_variant scales them
            from .rearrange import scaled_plan

            plan = scaled_plan(ref, plan)
        for k in range(max(want), len(order)):  # the rest of the sequence, if the last level was below 1
            moved += _move(placer, order[k], rests, other_room, ref_report)
        fixed = [o.id for o in sorted(lay.objects, key=lambda o: o.id) if not o.movable and o.support == "floor"]
        for k in rng.permutation(len(fixed)):
            saved_objects, saved_boxes = list(lay.objects), dict(placer.boxes)
            if relocate_floor(placer, lay.object(fixed[k]), other_room, rests) is not None:
                if ref_report is not None and new_problems(ref_report, check_layout(lay)):
                    lay.objects, placer.boxes = saved_objects, saved_boxes
                else:
                    fixed_moved += 1
        leaves = [o for o in lay.objects if o.movable and not holds_others(placer, o.id, rests) and o.id not in pinned]
        for k in rng.permutation(len(leaves))[: plan.removed]:
            placer.remove(leaves[k].id)
        add_objects(placer, ref, plan.added, is_imported(ref))
        out.append((BEYOND, snapshot(BEYOND, len(order))))
    return out


def moved_ids(ref: Layout, var: Layout, min_m: float = 0.0) -> set[int]:
    """Ids of ``ref``'s objects whose pose differs in ``var`` (position by more than ``min_m`` or any
    rotation), and those ``var`` removed."""
    by = var.by_id()
    out = set()
    for o in ref.objects:
        v = by.get(o.id)
        if v is None:
            out.add(o.id)
            continue
        d = float(np.linalg.norm(np.subtract(o.position, v.position)))
        if d > min_m or tuple(o.rotation) != tuple(v.rotation):
            out.add(o.id)
    return out
