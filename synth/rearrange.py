"""The seeded rearrangement operator: layout variants that keep the shell and change the furniture.

``rearrange`` moves and rotates movable objects to new valid placements (same rules as the
apartment generator: supported, collision-free, doors passable), carries whatever stands on a
moved object along with it, adds new instances and removes some. ``make_variant`` repeats it with
derived sub-seeds until the change statistics fall inside the requested ranges (by default the
paper's, Sec. IV-A) and the layout checks clean; which sub-seed was taken is recorded in the
variant's ``meta`` so the result is reproducible from the files alone.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass

import numpy as np

from . import geometry as geo
from .apartment import layout_fixtures
from .checks import check_layout
from .placement import Placer
from .scene import Layout, ObjectInstance, object_box
from .stats import PAPER_RANGES, change_stats

# classes that go with their back to a wall; the others stand anywhere
AGAINST_WALL = {"sofa", "bookshelf", "tv_stand", "cabinet", "desk", "bed", "nightstand", "shoe_rack", "wardrobe"}
# what a person would not move into a room of this type
ROOM_EXCLUDES = {
    "bathroom": {"sofa", "bed", "bookshelf", "desk", "dining_table", "armchair", "tv_stand", "coffee_table", "bench",
                 "floor_lamp", "side_table", "shoe_rack", "nightstand", "chair"},
    "hallway": {"sofa", "bed", "desk", "dining_table", "armchair", "tv_stand", "coffee_table", "nightstand"},
    "kitchen": {"bed", "sofa", "nightstand", "tv_stand"},
    "living": {"bed", "nightstand"},
    "bedroom": {"dining_table", "tv_stand"},
}


def room_accepts(room_type: str, cls: str) -> bool:
    return cls not in ROOM_EXCLUDES.get(room_type, ())


# classes the operator may add new instances of
ADDABLE = ["chair", "stool", "plant", "basket", "bin", "side_table", "floor_lamp", "cushion", "book", "vase", "bowl",
           "small_plant", "picture", "armchair"]


@dataclass(frozen=True)
class RearrangePlan:
    floor_moves: int = 33  # movable floor objects relocated (what stands on them moves along)
    surface_moves: int = 24  # small objects put on another surface
    wall_moves: int = 4  # pictures re-hung
    nudges: int = 6  # floor objects holding nothing, pushed 0.15-0.45 m and turned a little (chairs, baskets...)
    added: int = 9
    removed: int = 5
    other_room: float = 0.2  # probability that a relocated object changes room


# The query camera path of an experiment must keep 0.3 m from every object in every layout
# (it is planned on the free space they share). Variants therefore keep out of the reference
# layout's own walkway: a tour through every room of the reference, planned with this clearance.
WALKWAY_CLEARANCE = 0.35  # 0.3 m for the camera + 5 cm margin
WALKWAY_FRAMES = 1500


def reference_walkway(ref: Layout, seed: int = 0) -> np.ndarray:
    """(N, 2) points of a walk through every room of ``ref`` that variants must keep free."""
    from .paths.query import plan_query_path

    path = plan_query_path([ref], frames=WALKWAY_FRAMES, seed=seed, clearance=WALKWAY_CLEARANCE, obstacles="all", name="walkway")
    return path.poses[::3, :2, 3].copy()


@dataclass(frozen=True)
class VariantSpec:
    name: str
    seed: int
    plan: RearrangePlan


# The built-in variants of apt_0 (paper Sec. IV-A: five rearranged layouts of one apartment).
BUILTIN_VARIANTS = [
    VariantSpec("apt_1", 1001, RearrangePlan(removed=2, added=8)),
    VariantSpec("apt_2", 1002, RearrangePlan(removed=5, added=9)),
    VariantSpec("apt_3", 1003, RearrangePlan(removed=8, added=10)),
    VariantSpec("apt_4", 1004, RearrangePlan(removed=3, added=9, other_room=0.3)),
    VariantSpec("apt_5", 1005, RearrangePlan(removed=9, added=8, other_room=0.2)),
]


def _family(placer: Placer, obj: ObjectInstance) -> list[ObjectInstance]:
    return [obj] + placer.children(obj.id)


def _transform_family(family: list[ObjectInstance], new_obj: ObjectInstance) -> list[ObjectInstance]:
    """Move ``family[0]`` to ``new_obj``'s pose and carry the rest rigidly."""
    old = family[0]
    d = new_obj.matrix() @ np.linalg.inv(old.matrix())
    out = [new_obj]
    for ch in family[1:]:
        T = d @ ch.matrix()
        out.append(ObjectInstance(**{**ch.__dict__, "position": tuple(float(v) for v in T[:3, 3]),
                                     "rotation": geo.matrix_to_quat(T[:3, :3])}))
    return out


def _replace(layout: Layout, objs: list[ObjectInstance]) -> None:
    new = {o.id: o for o in objs}
    layout.objects = [new.get(o.id, o) for o in layout.objects]


def _pick_room(placer: Placer, current, p_other: float, cls: str):
    rooms = [r for r in placer.stage.rooms if room_accepts(r.type, cls)]
    if current is not None and (placer.rng.random() >= p_other or len(rooms) < 2):
        return current
    others = [r for r in rooms if current is None or r.name != current.name]
    w = np.array([r.area for r in others])
    return others[placer.rng.choice(len(others), p=w / w.sum())]


def _move_family(placer: Placer, obj: ObjectInstance, propose, tries: int = 12) -> bool:
    """Move ``obj`` to the first valid pose from ``propose(ignore_ids)`` and carry what stands on it.

    Every proposal is checked with the whole family at its new place; nothing changes on failure.
    """
    fam = _family(placer, obj)
    ids = {o.id for o in fam}
    saved = {i: placer.boxes.pop(i) for i in ids}
    for _ in range(tries):
        cand = propose(ids)
        if cand is None:
            continue
        moved = _transform_family(fam, cand)
        boxes = {o.id: object_box(o) for o in moved}
        if any(placer.collides(b, ids) for b in boxes.values()):
            continue
        _replace(placer.layout, moved)
        placer.boxes.update(boxes)
        return True
    placer.boxes.update(saved)
    return False


def _relocate_floor(placer: Placer, obj: ObjectInstance, p_other: float) -> bool:
    """Somewhere else on the floor, in the same room or (with probability ``p_other``) another."""
    cur_room = placer.stage.room_at(obj.position[:2])

    def propose(ids):
        room = _pick_room(placer, cur_room, p_other, obj.cls)
        if obj.cls in AGAINST_WALL:
            return placer.against_wall(obj.id, obj.cls, obj.size, obj.params, room, tries=10)
        return placer.free_spot(obj.id, obj.cls, obj.size, obj.params, room, tries=10, jitter_deg=12.0)

    return _move_family(placer, obj, propose)


def _nudge(placer: Placer, obj: ObjectInstance) -> bool:
    """Push a floor object 0.15-0.45 m in a random direction and turn it by up to 20 deg."""

    def propose(ids):
        ang = placer.rng.uniform(-math.pi, math.pi)
        dist = placer.rng.uniform(0.15, 0.45)
        xy = (obj.position[0] + dist * math.cos(ang), obj.position[1] + dist * math.sin(ang))
        yaw = geo.wrap_angle(obj.yaw + math.radians(placer.rng.uniform(-20, 20)))
        return placer.floor_at(obj.id, obj.cls, obj.size, obj.params, xy, yaw, ignore=ids)

    return _move_family(placer, obj, propose)


def rearrange(ref: Layout, name: str, seed: int, plan: RearrangePlan = RearrangePlan(),
              walkway: np.ndarray | None = None) -> Layout:
    """One rearranged variant of ``ref``. Non-movable objects and the stage are never touched;
    nothing is placed within ``WALKWAY_CLEARANCE`` of the ``walkway`` points (if given)."""
    lay = ref.copy()
    lay.name, lay.reference, lay.seed = name, ref.name, seed
    lay.meta = {"generator": "synth.rearrange", "plan": asdict(plan)}
    if walkway is not None:
        lay.meta["walkway"] = {"planned_on": ref.name, "clearance_m": WALKWAY_CLEARANCE, "frames": WALKWAY_FRAMES}
    rng = np.random.default_rng(seed)
    placer = Placer(lay, rng, keepout=None if walkway is None else (walkway, WALKWAY_CLEARANCE))

    # remove: movable objects that hold nothing
    leaves = [o for o in lay.objects if o.movable and not placer.children(o.id)]
    for k in rng.permutation(len(leaves))[: plan.removed]:
        placer.remove(leaves[k].id)

    # relocate floor furniture (with whatever stands on it)
    floor = [o for o in lay.objects if o.movable and o.support == "floor"]
    order = list(rng.permutation(len(floor)))
    done = 0
    while order and done < plan.floor_moves:
        obj = lay.object(floor[order.pop(0)].id)
        if _relocate_floor(placer, obj, plan.other_room):
            done += 1
    # nudge some of the others a little
    done = 0
    while order and done < plan.nudges:
        obj = lay.object(floor[order.pop(0)].id)
        if not placer.children(obj.id) and _nudge(placer, obj):
            done += 1

    # small objects onto other surfaces, anywhere in the flat
    small = [o for o in lay.objects if o.movable and o.support.startswith("object:") and not placer.children(o.id)]
    done = 0
    for k in rng.permutation(len(small)):
        if done >= plan.surface_moves:
            break
        obj = lay.object(small[k].id)
        holders = [o for o in lay.objects if o.id != obj.id and placer.surfaces(o)]
        if rng.random() >= plan.other_room:  # most small things stay in their room
            here = placer.stage.room_at(obj.position[:2])
            local = [o for o in holders if placer.stage.room_at(o.position[:2]) is here]
            holders = local or holders
        saved = placer.boxes.pop(obj.id)
        cand = placer.on_surface(obj.id, obj.cls, obj.size, obj.params, holders, yaw_mode="free" if obj.cls in ("bowl", "vase") else "aligned")
        if cand is None:
            placer.boxes[obj.id] = saved
            continue
        _replace(lay, [cand])
        placer.boxes[obj.id] = object_box(cand)
        done += 1

    # pictures to other walls
    hung = [o for o in lay.objects if o.movable and o.support.startswith("wall:")]
    done = 0
    for k in rng.permutation(len(hung)):
        if done >= plan.wall_moves:
            break
        obj = hung[k]
        saved = placer.boxes.pop(obj.id)
        room = _pick_room(placer, placer.stage.room_at(obj.position[:2]), plan.other_room, obj.cls)
        cand = placer.on_wall(obj.id, obj.cls, obj.size, obj.params, room, z_center=obj.position[2] + obj.size[2] / 2)
        if cand is None:
            placer.boxes[obj.id] = saved
            continue
        _replace(lay, [cand])
        placer.boxes[obj.id] = object_box(cand)
        done += 1

    # add new instances
    added = 0
    attempts = 0
    while added < plan.added and attempts < 20 * plan.added:
        attempts += 1
        cls = ADDABLE[rng.integers(len(ADDABLE))]
        size, params = placer.sample(cls)
        oid = placer.next_id()
        support = placer.classes.get(cls).support
        rooms = [r for r in placer.stage.rooms if room_accepts(r.type, cls)]
        room = rooms[rng.integers(len(rooms))]
        if support == "surface":
            holders = [o for o in lay.objects if placer.surfaces(o)]
            cand = placer.on_surface(oid, cls, size, params, holders)
        elif support == "wall":
            cand = placer.on_wall(oid, cls, size, params, room)
        else:
            cand = placer.free_spot(oid, cls, size, params, room, tries=20, jitter_deg=15.0)
        if cand is not None:
            placer.add(cand)
            added += 1

    lay.objects.sort(key=lambda o: o.id)
    lay.fixtures = layout_fixtures(lay)
    return lay


def in_ranges(stats: dict, ranges: dict) -> bool:
    return all(lo <= stats[k] <= hi for k, (lo, hi) in ranges.items())


class NoVariantFound(RuntimeError):
    """``make_variant`` found no rearrangement within the ranges that checks clean."""

    def __init__(self, message: str, attempts: int, last: dict | None, last_check_ok: bool | None):
        super().__init__(message)
        self.attempts, self.last, self.last_check_ok = attempts, last, last_check_ok


def make_variant(ref: Layout, spec: VariantSpec, ranges: dict = PAPER_RANGES, max_attempts: int = 40,
                 walkway: np.ndarray | None = None) -> Layout:
    """``rearrange`` with sub-seeds ``spec.seed * 1000 + k`` until stats are in range and checks pass.

    Raises ``NoVariantFound`` (a RuntimeError) after ``max_attempts``."""
    last, last_ok = None, None
    for k in range(max_attempts):
        sub = spec.seed * 1000 + k
        var = rearrange(ref, spec.name, sub, spec.plan, walkway)
        st = change_stats(ref, var)
        last = st
        last_ok = None
        if in_ranges(st, ranges):
            last_ok = check_layout(var).ok
            if last_ok:
                var.meta["variant_seed"] = spec.seed
                var.meta["attempt"] = k
                return var
    raise NoVariantFound(f"no rearrangement of {ref.name} within the target ranges after {max_attempts} attempts "
                         f"(last: {last})", max_attempts, last, last_ok)
