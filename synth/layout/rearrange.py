"""The seeded rearrangement operator: layout variants that keep the shell and change the furniture.

``rearrange`` moves and rotates movable objects to new valid placements (same rules as the
apartment generator: supported, collision-free, doors passable), carries whatever stands on a
moved object along with it, adds new instances and removes some. ``make_variant`` repeats it with
derived sub-seeds until the change statistics fall inside the requested ranges (by default the
paper's, Sec. IV-A) and the layout checks clean; which sub-seed was taken is recorded in the
variant's ``meta`` so the result is reproducible from the files alone.

Imported layouts (ReplicaCAD)
    The same operator works on a layout whose objects carry mesh assets (``is_imported``: its
    ``meta["source"]`` is ``"replicacad"`` or any object is not procedural). It needs the stage's
    rooms, walls and openings (derived from the stage mesh on import). What differs:

    * Moving: a mesh object is moved as itself (``synth.layout.placement.placed_copy``: same asset, scale
      and local box; its world box goes where a procedural one would). Mesh objects hold things on
      the top of their box when their mesh has a top there (``synth.mesh.surfaces.mesh_surfaces``).
    * ``free`` objects (resting on something the importer could not name) are not moved, and
      neither is an object whose box holds a ``free`` object's box centre (lifting it would leave
      the ``free`` one in the air): both stay put, though they may be removed when nothing stands
      on them.
    * Adding: copies of the layout's own movable templates (``template_pool``: asset, class, size,
      box offset, scale and ``params`` -- ``params.template`` names the ReplicaCAD template) instead
      of procedural ``ADDABLE`` classes; a copy goes where its template's support says (floor, a
      surface, a wall).
    * Plan and ranges (``make_variant``): the paper's numbers are for an apartment of apt_0's size.
      ``scaled_plan`` and ``synth.scene.stats.scaled_ranges`` scale the counts by
      f = (movable objects of the layout) / (movable objects of the built-in apt_0), counting movable
      objects whose support is not ``free``. In the plan, added and removed scale by f; the move
      counts scale per kind -- floor moves and nudges by the ratio of movable floor objects,
      surface moves by that of objects on surfaces, wall moves by that of wall objects -- which is
      f when the layout's mix of kinds is apt_0's, and keeps the same share of each kind moving
      when it is not (a ReplicaCAD flat holds more small things on tables than apt_0). Counts are
      rounded half up, and never exceed what the layout holds. The median-distance criterion is
      capped by the flat's size (see ``synth.scene.stats.scaled_ranges``). The plan and ranges used are
      recorded in ``meta["plan"]`` and ``meta["ranges"]``.
    * New objects take ids above all of the reference's (a removed object's id is not reused).
    * The variant keeps the reference's import record (``meta`` ``source``, ``root``, ``scene``,
      ...), so its meshes are found again; lamps' light fixtures follow their lamps, fixtures of the
      stage (ceiling lights of the lighting config, placed ones) stay
      (``synth.scene.fixtures.layout_fixtures``).
    * Checks: ``make_variant`` asks of a variant of a reference that does not check clean (real
      scans: chairs pushed under tables) that it adds no problem the reference did not have.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass

import numpy as np

from vrformats.camera import wrap_angle
from vrformats.errors import UserError

from ..paths.model import DEFAULTS
from ..scene import geometry as geo
from ..scene.fixtures import is_light_source, layout_fixtures
from .validity import CheckReport, check_layout
from .placement import GAP, Placer
from ..scene.model import Layout, ObjectInstance, Room, object_box
from ..scene.stats import MOVED_FAR, MOVED_MIN, PAPER_RANGES, change_stats, is_imported, movable_counts, reference_counts, scaled_ranges

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
WALKWAY_CLEARANCE = DEFAULTS.clearance + 0.05  # 0.35 m: the planners' 0.3 m for the camera + 5 cm margin
WALKWAY_FRAMES = 1500


def reference_walkway(ref: Layout, seed: int = 0) -> np.ndarray:
    """(N, 2) points of a walk through every room of ``ref`` that variants must keep free."""
    from ..paths.query import plan_query_path

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


def _family(placer: Placer, obj: ObjectInstance, rests: dict[int, list[int]] | None = None) -> list[ObjectInstance]:
    """``obj``, what stands on it (``Placer.children``) and the ``free`` objects resting in or on any
    of them (``rests``: holder id -> free ids, ``free_rests``), with what stands on those, in turn."""
    fam = [obj] + placer.children(obj.id)
    if not rests:
        return fam
    seen = {o.id for o in fam}
    k = 0
    while k < len(fam):
        for fid in rests.get(fam[k].id, ()):
            if fid not in seen:
                for o in [placer.layout.object(fid)] + placer.children(fid):
                    if o.id not in seen:
                        seen.add(o.id)
                        fam.append(o)
        k += 1
    return fam


def holds_others(placer: Placer, oid: int, rests: dict[int, list[int]] | None = None) -> bool:
    """Whether anything stands on object ``oid`` or a ``free`` object rests in or on it."""
    return bool(placer.children(oid)) or bool(rests and rests.get(oid))


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


def _is_proc(o: ObjectInstance) -> bool:
    return o.asset.startswith("proc:")


def _shape(o: ObjectInstance):
    """(size, template) that the ``Placer`` primitives take to move ``o``: its procedural size, or
    its world box size and itself for a mesh object (``synth.layout.placement.placed_copy``)."""
    if _is_proc(o):
        return o.size, None
    return object_box(o).size, o


def _xy(o: ObjectInstance):
    """Where an object stands: its origin (procedural: the bottom centre) or its box centre (meshes)."""
    if _is_proc(o):
        return o.position[:2]
    return object_box(o).center[:2]


def _pick_room(placer: Placer, current, p_other: float, cls: str):
    rooms = [r for r in placer.stage.rooms if room_accepts(r.type, cls)]
    if current is not None and (placer.rng.random() >= p_other or len(rooms) < 2):
        return current
    others = [r for r in rooms if current is None or r.name != current.name]
    if not others:
        return current
    w = np.array([r.area for r in others])
    return others[placer.rng.choice(len(others), p=w / w.sum())]


def _move_family(placer: Placer, obj: ObjectInstance, propose, tries: int = 12,
                 rests: dict[int, list[int]] | None = None, over: frozenset = frozenset()) -> list[ObjectInstance] | None:
    """Move ``obj`` to the first valid pose from ``propose(ignore_ids)`` and carry what stands on it
    (and the ``free`` objects resting on the family: ``rests``). Returns the moved family.

    Every proposal is checked with the whole family at its new place (``over``: ids it may overlap,
    the flat things on the floor it may stand on); nothing changes on failure (None).
    """
    fam = _family(placer, obj, rests)
    ids = {o.id for o in fam}
    saved = {i: placer.boxes.pop(i) for i in ids}
    for _ in range(tries):
        cand = propose(ids | over if over else ids)
        if cand is None:
            continue
        moved = _transform_family(fam, cand)
        boxes = {o.id: object_box(o) for o in moved}
        if any(placer.collides(b, ids | over) for b in boxes.values()):
            continue
        _replace(placer.layout, moved)
        placer.boxes.update(boxes)
        return moved
    placer.boxes.update(saved)
    return None


def relocate_floor(placer: Placer, obj: ObjectInstance, p_other: float,
                    rests: dict[int, list[int]] | None = None) -> list[ObjectInstance] | None:
    """Somewhere else on the floor, in the same room or (with probability ``p_other``) another."""
    cur_room = placer.stage.room_at(_xy(obj))
    size, tmpl = _shape(obj)

    # a mesh object in a room that is not a rectangle (an imported flat's open plan: Room.polygon)
    # goes back against some wall of the stage, the same side of it to the wall, when it stood
    # against one; in a rectangular room against a side of it as procedural objects do
    rel = _wall_relation(placer.stage, object_box(obj)) if tmpl is not None else None
    tries = 10 if tmpl is None else 25

    def propose(ids):
        room = _pick_room(placer, cur_room, p_other, obj.cls)
        if room is None:
            return None
        if room is cur_room and room.area > LARGE_ROOM_M2:
            room = _window(room, _xy(obj))
        if rel is not None and room.polygon is not None:
            return _against_stage_wall(placer, obj, size, tmpl, room, rel, ids, tries=tries)
        if obj.cls in AGAINST_WALL and (tmpl is None or room.polygon is None):
            return placer.against_wall(obj.id, obj.cls, size, obj.params, room, tries=tries, template=tmpl)
        return placer.free_spot(obj.id, obj.cls, size, obj.params, room, tries=tries, jitter_deg=12.0, template=tmpl)

    return _move_family(placer, obj, propose, rests=rests, over=_flat_ids(placer, obj))


FLAT = 0.05  # m: a mesh object on the floor whose top is at most this high (a rug, a mat) is stood on, as walked over


def _flat_ids(placer: Placer, obj: ObjectInstance) -> frozenset:
    """The flat things on the floor (``FLAT``: rugs, mats of an imported flat) that a mesh object
    which is not flat itself may stand on when it is put on the floor; empty for procedural objects."""
    if _is_proc(obj) or object_box(obj).zmax - placer.stage.floor_z <= FLAT:
        return frozenset()
    return frozenset(o.id for o in placer.layout.objects if o.id != obj.id and not _is_proc(o) and o.support == "floor"
                     and placer.boxes.get(o.id) is not None and placer.boxes[o.id].zmax - placer.stage.floor_z <= FLAT)


WALL_NEAR = 0.15  # m: a mesh object whose box comes this close to a wall face stands against that wall


def _extent_along(box_yaw: float, size, n) -> float:
    """Half the extent of a box footprint (yaw, size) along the unit vector ``n``."""
    c, sn = math.cos(box_yaw), math.sin(box_yaw)
    return 0.5 * (size[0] * abs(c * n[0] + sn * n[1]) + size[1] * abs(-sn * n[0] + c * n[1]))


def _wall_relation(stage, box) -> float | None:
    """How a box stands against the nearest wall of ``stage``: its yaw minus the heading of the
    wall's normal towards it, when its footprint comes within ``WALL_NEAR`` of that wall's face
    (beside the wall, not beyond its ends); else None (it stands free)."""
    best = None
    centre = np.asarray(box.center[:2], float)
    for w in stage.walls:
        if w.length <= 0:
            continue
        d = w.direction
        rel = centre - np.asarray(w.start, float)
        t = float(rel @ d)
        if t < 0 or t > w.length:
            continue
        n = np.array([-d[1], d[0]])
        side = float(rel @ n)
        if side < 0:
            n, side = -n, -side
        gap = side - w.thickness / 2 - _extent_along(box.yaw, box.size, n)
        if gap <= WALL_NEAR and (best is None or gap < best[0]):
            best = (gap, wrap_angle(box.yaw - math.atan2(n[1], n[0])))
    return None if best is None else best[1]


def _against_stage_wall(placer: Placer, obj: ObjectInstance, size, tmpl, room: Room, rel: float, ids, tries: int,
                        oid: int | None = None):
    """A placed copy of ``obj`` with the same side to a wall of the stage as it had (``rel``:
    ``_wall_relation``), the wall point drawn uniformly on the walls that pass through ``room``'s
    rect, on either side; the footprint ``GAP`` off the wall face, its centre inside ``room``."""
    x0, y0, x1, y1 = room.rect
    walls = [w for w in placer.stage.walls if w.length > 0 and min(w.start[0], w.end[0]) <= x1 and max(w.start[0], w.end[0]) >= x0
             and min(w.start[1], w.end[1]) <= y1 and max(w.start[1], w.end[1]) >= y0]
    if not walls:
        return None
    lengths = np.array([w.length for w in walls])
    for _ in range(tries):
        w = walls[placer.rng.choice(len(walls), p=lengths / lengths.sum())]
        d = w.direction
        t = placer.rng.uniform(0.0, w.length)
        n = np.array([-d[1], d[0]]) * (1.0 if placer.rng.random() < 0.5 else -1.0)
        yaw = wrap_angle(math.atan2(n[1], n[0]) + rel)
        xy = np.asarray(w.start, float) + t * d + n * (w.thickness / 2 + _extent_along(yaw, size, n) + GAP)
        if not room.contains(xy)[0]:
            continue
        cand = placer.floor_at(obj.id if oid is None else oid, obj.cls, size, obj.params, (float(xy[0]), float(xy[1])), yaw,
                               ignore=ids, template=tmpl)
        if cand is not None:
            return cand
    return None


# An open plan (a ReplicaCAD flat's one derived room holds living room, kitchen and hall) is not a
# room in the sense of the paper's "moved within its room": a move inside a room larger than this
# goes somewhere within WINDOW_HALF of where the object stood (and inside the room), so the moved
# distances stay those of a room of the built-in apartment's size (its largest room is ~22 m2).
LARGE_ROOM_M2 = 30.0
WINDOW_HALF = 2.5  # m
SURFACE_WINDOW_HALF = 4.0  # m: a small thing put on another surface (not its own) within this of where it stood


def _window(room: Room, xy, half: float = WINDOW_HALF) -> Room:
    """The part of a room within ``WINDOW_HALF`` of ``xy`` (same name and type): the window's rect,
    and the room's polygon, if any, kept as it is (``Room.contains`` then holds points inside both:
    a stand-in for placing only, not a room of the stage)."""
    x0, y0, x1, y1 = room.rect
    cx = min(max(float(xy[0]), x0), x1)
    cy = min(max(float(xy[1]), y0), y1)
    rect = (max(x0, cx - half), max(y0, cy - half), min(x1, cx + half), min(y1, cy + half))
    return Room(room.name, room.type, rect, room.polygon)


def _nudge(placer: Placer, obj: ObjectInstance, rests: dict[int, list[int]] | None = None) -> list[ObjectInstance] | None:
    """Push a floor object 0.15-0.45 m in a random direction and turn it by up to 20 deg."""
    size, tmpl = _shape(obj)
    x0, y0 = _xy(obj)
    yaw0 = obj.yaw if tmpl is None else object_box(obj).yaw

    def propose(ids):
        ang = placer.rng.uniform(-math.pi, math.pi)
        dist = placer.rng.uniform(0.15, 0.45)
        xy = (x0 + dist * math.cos(ang), y0 + dist * math.sin(ang))
        yaw = wrap_angle(yaw0 + math.radians(placer.rng.uniform(-20, 20)))
        return placer.floor_at(obj.id, obj.cls, size, obj.params, xy, yaw, ignore=ids, template=tmpl)

    over = _flat_ids(placer, obj)
    if not _is_proc(obj):  # a mesh object keeps the box overlaps it had (a chair under its table): the checks test its shapes
        mine = placer.boxes.get(obj.id)
        over |= frozenset(i for i, b in placer.boxes.items() if i != obj.id and mine is not None and geo.boxes_overlap(mine, b))
    return _move_family(placer, obj, propose, rests=rests, over=over)


FREE_HOLD_TOL = 0.02  # m: a free object whose bottom is this close to (or inside) a box's z range rests in or on it


def free_holders(layout: Layout) -> dict[int, list[int]]:
    """For each ``free`` object, the objects it may rest in or on: those (not ``free`` themselves)
    whose footprint holds its box centre and whose height range holds its bottom (2 cm tolerance),
    in id order."""
    from .placement import distance_to_box_2d

    free = [o for o in layout.objects if o.support == "free"]
    if not free:
        return {}
    fboxes = [object_box(o) for o in free]
    centres = np.array([b.center[:2] for b in fboxes])
    out: dict[int, list[int]] = {o.id: [] for o in free}
    for o in sorted(layout.objects, key=lambda o: o.id):
        if o.support == "free":
            continue
        b = object_box(o)
        inside = distance_to_box_2d(centres, b) <= 0.0
        for k, fb in enumerate(fboxes):
            if inside[k] and b.zmin - FREE_HOLD_TOL <= fb.zmin <= b.zmax + FREE_HOLD_TOL:
                out[free[k].id].append(o.id)
    return out


def free_rests(layout: Layout) -> tuple[dict[int, list[int]], set[int]]:
    """Where the ``free`` objects go when the operator moves things: (rests, pinned).

    A movable ``free`` object with exactly one holder (``free_holders``), itself movable, rests on
    it: ``rests[holder]`` lists it, and it moves with its holder's family (a cushion on a sofa, shoes
    in a rack). Any other ``free`` object stays where it is, and so does every object it may rest on
    (``pinned``: lifting it would leave the ``free`` object in the air). A layout without ``free``
    objects -- every procedural one -- has neither."""
    by_id = layout.by_id()
    rests: dict[int, list[int]] = {}
    pinned: set[int] = set()
    for fid, holders in free_holders(layout).items():
        if len(holders) == 1 and by_id[fid].movable and by_id[holders[0]].movable:
            rests.setdefault(holders[0], []).append(fid)
        else:
            pinned.update(holders)
    return rests, pinned


def pinned_ids(layout: Layout) -> set[int]:
    """Objects the operator leaves in place because a ``free`` object that cannot move with them
    rests in or on them (``free_rests``)."""
    return free_rests(layout)[1]


def put_elsewhere(placer: Placer, obj: ObjectInstance, plan: RearrangePlan) -> ObjectInstance | None:
    """A small object onto another surface (mostly in its room): the moved object, or None."""
    lay, rng = placer.layout, placer.rng
    size, tmpl = _shape(obj)
    holders = [o for o in lay.objects if o.id != obj.id and placer.surfaces(o)]
    if rng.random() >= plan.other_room:  # most small things stay in their room
        here = placer.stage.room_at(_xy(obj))
        if here is not None and here.area > LARGE_ROOM_M2:  # an open plan: somewhere near (as floor moves)
            win, par = _window(here, _xy(obj), SURFACE_WINDOW_HALF), (obj.support_parent() or (None,))[0]
            local = [o for o in holders if o.id != par and win.contains(_xy(o))[0]]
        else:
            local = [o for o in holders if placer.stage.room_at(_xy(o)) is here]
        holders = local or holders
    saved = placer.boxes.pop(obj.id)
    cand = placer.on_surface(obj.id, obj.cls, size, obj.params, holders,
                             yaw_mode="free" if obj.cls in ("bowl", "vase") else "aligned", template=tmpl)
    if cand is None:
        placer.boxes[obj.id] = saved
        return None
    _replace(lay, [cand])
    placer.boxes[obj.id] = object_box(cand)
    return cand


def _small(placer: Placer, pinned: set[int], rests) -> list[ObjectInstance]:
    """Objects on surfaces that the operator may put elsewhere: movable, holding nothing, not pinned."""
    return [o for o in placer.layout.objects if o.movable and o.support.startswith("object:")
            and not holds_others(placer, o.id, rests) and o.id not in pinned]


def _surface_moves(placer: Placer, plan: RearrangePlan, pinned: set[int], rests) -> None:
    """``plan.surface_moves`` small objects onto other surfaces, anywhere in the flat."""
    small = _small(placer, pinned, rests)
    done = 0
    for k in placer.rng.permutation(len(small)):
        if done >= plan.surface_moves:
            break
        if holds_others(placer, small[k].id, rests):
            continue  # something was put on it since
        if put_elsewhere(placer, placer.layout.object(small[k].id), plan) is not None:
            done += 1


def _wall_moves(placer: Placer, plan: RearrangePlan, pinned: set[int], note=None, reached=None) -> None:
    """Pictures to other walls: ``plan.wall_moves`` of them (fewer once ``reached()``)."""
    lay, rng = placer.layout, placer.rng
    hung = [o for o in lay.objects if o.movable and o.support.startswith("wall:") and o.id not in pinned]
    done = 0
    for k in rng.permutation(len(hung)):
        if done >= plan.wall_moves or (reached is not None and reached()):
            break
        cand = rehang(placer, hung[k], plan.other_room)
        if cand is None:
            continue
        if note is not None:
            note([cand])
        done += 1


def rehang(placer: Placer, obj: ObjectInstance, other_room: float) -> ObjectInstance | None:
    """A wall object onto another wall at its height (another room with probability ``other_room``):
    the moved object, or None (nothing changed)."""
    size, tmpl = _shape(obj)
    saved = placer.boxes.pop(obj.id)
    room = _pick_room(placer, placer.stage.room_at(_xy(obj)), other_room, obj.cls)
    zc = obj.position[2] + obj.size[2] / 2 if tmpl is None else object_box(obj).center[2] - placer.stage.floor_z
    cand = None if room is None else placer.on_wall(obj.id, obj.cls, size, obj.params, room, z_center=zc, template=tmpl)
    if cand is None:
        placer.boxes[obj.id] = saved
        return None
    _replace(placer.layout, [cand])
    placer.boxes[obj.id] = object_box(cand)
    return cand


def _nudge_on_surface(placer: Placer, obj: ObjectInstance, tries: int = 12) -> ObjectInstance | None:
    """Push an object standing on a surface 0.15-0.45 m along that surface (same heading, a
    different spot on the same table or shelf); the moved object, or None."""
    par = obj.support_parent()
    if par is None:
        return None
    parent = placer.layout.by_id().get(par[0])
    if parent is None or par[1] >= len(placer.surfaces(parent)):
        return None
    s = placer.surfaces(parent)[par[1]]
    size, tmpl = _shape(obj)
    b = object_box(obj)
    Rp = geo.rot_z(parent.yaw)[:2, :2]
    l0 = (np.asarray(b.center[:2]) - np.asarray(parent.position[:2])) @ Rp
    yaw0 = b.yaw if tmpl is not None else obj.yaw
    dyaw = wrap_angle(yaw0 - parent.yaw)
    c, sn = abs(math.cos(dyaw)), abs(math.sin(dyaw))
    hx, hy = 0.5 * (c * size[0] + sn * size[1]), 0.5 * (sn * size[0] + c * size[1])
    saved = placer.boxes.pop(obj.id)
    for _ in range(tries):
        ang = placer.rng.uniform(-math.pi, math.pi)
        dist = placer.rng.uniform(0.15, 0.45)
        lx, ly = l0[0] + dist * math.cos(ang), l0[1] + dist * math.sin(ang)
        if not (s.xmin + hx <= lx <= s.xmax - hx and s.ymin + hy <= ly <= s.ymax - hy):
            continue
        cand = placer.at_surface_point(obj.id, obj.cls, size, obj.params, parent, par[1], (lx, ly), dyaw, template=tmpl)
        if cand is not None:
            _replace(placer.layout, [cand])
            placer.boxes[obj.id] = object_box(cand)
            return cand
    placer.boxes[obj.id] = saved
    return None


def _toward_targets(placer: Placer, ref: Layout, plan: RearrangePlan, floor, order, pinned, rests, targets: dict) -> None:
    """The moves of ``rearrange`` when it is given ``targets`` (an imported layout: see there).

    Counts (objects moved by more than 0.1 m, ``n``, and by more than 0.5 m, ``n_far``) aim at the
    middles of ``targets["moved_over_0.1m"]`` and ``targets["moved_over_0.5m"]`` and never pass their
    tops: floor relocations (families, at most ``plan.floor_moves``), wall moves and moves onto other
    surfaces (objects not moved yet) until ``n_far`` is at its middle; then the short moves that
    make up the difference to ``n``'s middle: nudges of floor objects that hold nothing, and of
    objects on surfaces along their own surface (0.15-0.45 m)."""
    lay, rng = placer.layout, placer.rng
    lo, hi = targets["moved_over_0.1m"]
    flo, fhi = targets.get("moved_over_0.5m", (0, hi))
    goal = (lo + hi + 1) // 2
    far_goal = min(goal, (flo + fhi + 1) // 2, fhi)
    ref_centres = {o.id: np.asarray(object_box(o).center) for o in ref.objects}
    moved: set[int] = set()
    far: set[int] = set()

    def note(objs) -> None:
        for o in objs:
            if o.id in ref_centres:
                d = float(np.linalg.norm(np.asarray(object_box(o).center) - ref_centres[o.id]))
                (moved.add if d > MOVED_MIN else moved.discard)(o.id)
                (far.add if d > MOVED_FAR else far.discard)(o.id)

    def far_enough() -> bool:
        return len(far) >= far_goal or len(moved) >= goal

    # far moves: floor furniture with its family, pictures, small things onto other surfaces
    left, done = [], 0
    while order and done < plan.floor_moves and not far_enough():
        k = order.pop(0)
        obj = lay.object(floor[k].id)
        ids = {o.id for o in _family(placer, obj, rests)}
        if len(moved | ids) > hi or len(far | ids) > fhi:
            left.append(k)  # its family would take a count past its range
            continue
        fam = relocate_floor(placer, obj, plan.other_room, rests)
        if fam:
            note(fam)
            done += 1
        else:
            left.append(k)
    _wall_moves(placer, plan, pinned, note, far_enough)
    # small things onto other surfaces: plan.surface_moves of them, where one not moved yet is taken
    # only while the far count is below its middle, and more (not moved yet) until it is there
    small = _small(placer, pinned, rests)
    done = 0
    for k in rng.permutation(len(small)):
        if done >= plan.surface_moves and far_enough():
            break
        obj = lay.object(small[k].id)
        if (obj.id not in moved and far_enough()) or holds_others(placer, obj.id, rests):
            continue  # (something may have been put on it since)
        cand = put_elsewhere(placer, obj, plan)
        if cand is not None:
            note([cand])
            done += 1

    # short moves up to the goal: floor objects nudged (at most plan.nudges), then things on surfaces
    done = 0
    for k in left + order:
        if len(moved) >= goal or done >= plan.nudges:
            break
        obj = lay.object(floor[k].id)
        if not holds_others(placer, obj.id, rests):
            fam = _nudge(placer, obj, rests)
            if fam:
                note(fam)
                done += 1
    small = [o for o in _small(placer, pinned, rests) if o.id not in moved]
    for k in rng.permutation(len(small)):
        if len(moved) >= goal:
            break
        if holds_others(placer, small[k].id, rests):
            continue
        cand = _nudge_on_surface(placer, lay.object(small[k].id))
        if cand is not None:
            note([cand])
    # too few short moves could be made (a crowded flat): far ones make up the rest, within their range
    small = [o for o in _small(placer, pinned, rests) if o.id not in moved]
    for k in rng.permutation(len(small)):
        if len(moved) >= goal or len(far) >= fhi:
            break
        if holds_others(placer, small[k].id, rests):
            continue
        cand = put_elsewhere(placer, lay.object(small[k].id), plan)
        if cand is not None:
            note([cand])


def template_pool(ref: Layout, distinct: bool = True) -> list[ObjectInstance]:
    """The movable objects of ``ref`` whose copies an imported layout's variants may add: one per
    distinct (asset, scale, local box, template name), in order of first id; ``free`` and
    ceiling-mounted objects are left out (where a copy of them could go is not known). With
    ``distinct=False`` every such object, so that a draw from the pool follows the layout's own mix
    of classes (20 books, one sofa)."""
    seen, out = set(), []
    for o in sorted(ref.objects, key=lambda o: o.id):
        if not o.movable or o.support in ("free", "ceiling"):
            continue
        key = (o.asset, tuple(o.scale), tuple(o.size), tuple(o.box_offset), str(o.params.get("template", "")))
        if not distinct or key not in seen:
            seen.add(key)
            out.append(o)
    return out


def _add_copy(placer: Placer, t: ObjectInstance, oid: int, rng) -> ObjectInstance | None:
    """A copy of template ``t`` placed as its own support says (floor, a surface, a wall)."""
    lay = placer.layout
    size = object_box(t).size
    rooms = [r for r in placer.stage.rooms if room_accepts(r.type, t.cls)]
    if not rooms:
        return None
    room = rooms[rng.integers(len(rooms))]
    if t.support.startswith("object:"):
        holders = [o for o in lay.objects if placer.surfaces(o)]
        return placer.on_surface(oid, t.cls, size, t.params, holders, yaw_mode="free" if t.cls in ("bowl", "vase") else "aligned",
                                 template=t)
    if t.support.startswith("wall:"):
        return placer.on_wall(oid, t.cls, size, t.params, room, template=t)
    over = _flat_ids(placer, t)
    rel = _wall_relation(placer.stage, object_box(t))
    if rel is not None and room.polygon is not None:
        return _against_stage_wall(placer, t, size, t, room, rel, over | {oid}, tries=20, oid=oid)
    if t.cls in AGAINST_WALL and room.polygon is None:
        return placer.against_wall(oid, t.cls, size, t.params, room, tries=20, template=t, ignore=over)
    return placer.free_spot(oid, t.cls, size, t.params, room, tries=20, jitter_deg=15.0, template=t, ignore=over)


# meta keys of a variant that are its own, not carried over from an imported reference
VARIANT_META = ("generator", "generator_version", "plan", "walkway", "variant_seed", "attempt", "ranges")


def rearrange(ref: Layout, name: str, seed: int, plan: RearrangePlan = RearrangePlan(),
              walkway: np.ndarray | None = None, targets: dict | None = None) -> Layout:
    """One rearranged variant of ``ref``. Non-movable objects and the stage are never touched; a
    ``free`` object moves with the one object it rests on, or else stays, and so does what it may
    rest on (``free_rests``); nothing is placed within ``WALKWAY_CLEARANCE`` of the ``walkway``
    points (if given). ``plan`` is used as given (see ``scaled_plan`` for imported layouts).

    ``moved_range`` (lo, hi): how many objects should end up moved by more than 0.1 m
    (``synth.scene.stats``). The floor moves and nudges of the plan then stop once the middle of the range
    is reached, a floor object whose family would take the count past ``hi`` is passed over, and
    surface moves (of objects not moved yet) come last and continue past ``plan.surface_moves``
    until the middle is reached, or stop there. Without it (the built-in variants) the plan's
    counts are the operations done."""
    imported = is_imported(ref)
    if imported and not ref.stage.rooms:
        raise UserError(f"layout '{ref.name}': rearranging needs the stage's rooms, walls and openings "
                        "(derived from the stage mesh on import); this layout has none")
    lay = ref.copy()
    lay.name, lay.reference, lay.seed = name, ref.name, seed
    lay.meta = {"generator": "synth.rearrange", "plan": asdict(plan)}
    if imported:  # keep the import record (where the meshes are)
        lay.meta = {**{k: v for k, v in ref.meta.items() if k not in VARIANT_META}, **lay.meta}
    if walkway is not None:
        lay.meta["walkway"] = {"planned_on": ref.name, "clearance_m": WALKWAY_CLEARANCE, "frames": WALKWAY_FRAMES}
    rng = np.random.default_rng(seed)
    # an imported layout's new objects never take a removed object's id (the statistics match by id)
    placer = Placer(lay, rng, keepout=None if walkway is None else (walkway, WALKWAY_CLEARANCE),
                    used_ids=max([o.id for o in ref.objects] + [0]) if imported else 0)
    rests, pinned = free_rests(lay)

    # remove: movable objects that hold nothing
    leaves = [o for o in lay.objects if o.movable and not holds_others(placer, o.id, rests) and o.id not in pinned]
    for k in rng.permutation(len(leaves))[: plan.removed]:
        placer.remove(leaves[k].id)
    present = {o.id for o in lay.objects}
    rests = {h: [f for f in fs if f in present] for h, fs in rests.items() if any(f in present for f in fs)}

    floor = [o for o in lay.objects if o.movable and o.support == "floor" and o.id not in pinned]
    order = list(rng.permutation(len(floor)))
    if targets is not None:
        _toward_targets(placer, ref, plan, floor, order, pinned, rests, targets)
    else:
        # relocate floor furniture (with whatever stands on it)
        done = 0
        while order and done < plan.floor_moves:
            obj = lay.object(floor[order.pop(0)].id)
            if relocate_floor(placer, obj, plan.other_room, rests):
                done += 1
        # nudge some of the others a little
        done = 0
        while order and done < plan.nudges:
            obj = lay.object(floor[order.pop(0)].id)
            if not holds_others(placer, obj.id, rests) and _nudge(placer, obj, rests):
                done += 1
        _surface_moves(placer, plan, pinned, rests)
        _wall_moves(placer, plan, pinned)

    add_objects(placer, ref, plan.added, imported)
    lay.objects.sort(key=lambda o: o.id)
    lay.fixtures = layout_fixtures(lay, previous=ref)
    return lay


def add_objects(placer: Placer, ref: Layout, n: int, imported: bool) -> int:
    """Add up to ``n`` new instances: procedural classes in a procedural flat, copies of its own
    templates in an imported one; returns how many were placed."""
    lay, rng = placer.layout, placer.rng
    added = 0
    attempts = 0
    pool = template_pool(ref) if imported else []
    while added < n and attempts < 20 * n:
        attempts += 1
        if imported:
            if not pool:
                break
            t = pool[rng.integers(len(pool))]
            cand = _add_copy(placer, t, placer.next_id(), rng)
            if cand is not None:
                placer.add(cand)
                added += 1
            continue
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
    return added


def clutter(layout: Layout, pool: list[ObjectInstance], n: int, seed: int, lamps: int = 0, name: str | None = None) -> Layout:
    """A copy of ``layout`` with up to ``n`` objects added: copies of the templates in ``pool``
    (``template_pool`` of any layouts of the same dataset), each placed as its template's support
    says, of which at least ``lamps`` (when the pool has any) are light sources, which go on open tops only.
    For detector training data: the dataset's small objects on another arrangement's furniture,
    as habitat-lab's rearrangement episodes put them into the staging scenes' receptacles.
    Nothing already in ``layout`` moves; fixtures are derived again (the added lamps get lights)."""
    lay = layout.copy()
    lay.name = name or layout.name
    lay.meta = {**layout.meta, "clutter": {"added": 0, "seed": seed, "pool": len(pool)}}
    rng = np.random.default_rng([seed, 11])
    placer = Placer(lay, rng, used_ids=max([o.id for o in layout.objects] + [0]))
    lamp_pool = [t for t in pool if is_light_source(t.cls)]
    added = attempts = 0
    while added < n and attempts < 20 * max(n, 1) and pool:
        attempts += 1
        sub = lamp_pool if (added < lamps and lamp_pool) else pool
        t = sub[rng.integers(len(sub))]
        cand = _add_copy(placer, t, placer.next_id(), rng)
        if cand is not None:
            placer.add(cand)
            added += 1
    lay.objects.sort(key=lambda o: o.id)
    lay.fixtures = layout_fixtures(lay, previous=layout)
    lay.meta["clutter"]["added"] = added
    return lay


def _round_half_up(x: float) -> int:
    return int(math.floor(x + 0.5 + 1e-9))


def scaled_plan(ref: Layout, plan: RearrangePlan = RearrangePlan()) -> RearrangePlan:
    """``plan`` (made for an apartment of apt_0's size) for a layout of ``ref``'s size and mix of
    objects: the rules are in the module docstring. ``scaled_plan(apt_0, plan) == plan``."""
    have, base = movable_counts(ref), reference_counts()[0]

    def by(n: int, kind: str) -> int:
        return _round_half_up(n * have[kind] / base[kind]) if base[kind] else 0

    f = have["total"] / base["total"]
    floor_moves = min(by(plan.floor_moves, "floor"), have["floor"])
    nudges = min(by(plan.nudges, "floor"), have["floor"])  # tried on the floor objects not relocated
    surface_moves = min(by(plan.surface_moves, "surface"), have["surface"])
    wall_moves = min(by(plan.wall_moves, "wall"), have["wall"])
    added = _round_half_up(plan.added * f)
    removed = _round_half_up(plan.removed * f)
    if plan.added > 0:
        added = max(1, added)
    if plan.removed > 0:
        removed = max(1, removed)
    return RearrangePlan(floor_moves=floor_moves, surface_moves=surface_moves, wall_moves=wall_moves, nudges=nudges,
                         added=added, removed=min(removed, have["total"]), other_room=plan.other_room)


def target_ranges(ref: Layout) -> dict:
    """The change ranges a variant of ``ref`` must meet: the paper's for a procedural layout,
    ``scaled_ranges(ref)`` for an imported one."""
    return scaled_ranges(ref) if is_imported(ref) else PAPER_RANGES


def _problems(rep: CheckReport) -> set[tuple]:
    out = {("structure", p["what"]) for p in rep.structure}
    out |= {("collision",) + tuple(sorted((str(c["a"]), str(c["b"])))) for c in rep.collisions}
    out |= {("unsupported", u["id"]) for u in rep.unsupported}
    out |= {("blocked_door", d["door"]) for d in rep.blocked_doors}
    out |= {("covered_opening", c["opening"], c["id"]) for c in rep.covered_openings}
    return out


def new_problems(ref_report: CheckReport, var_report: CheckReport) -> list[tuple]:
    """Problems of a variant's check report that its reference's report does not have (same object
    ids, doors and openings), sorted."""
    return sorted(_problems(var_report) - _problems(ref_report), key=str)


def in_ranges(stats: dict, ranges: dict) -> bool:
    return all(lo <= stats[k] <= hi for k, (lo, hi) in ranges.items())


class NoVariantFound(RuntimeError):
    """``make_variant`` found no rearrangement within the ranges that checks clean."""

    def __init__(self, message: str, attempts: int, last: dict | None, last_check_ok: bool | None, ranges: dict | None = None):
        super().__init__(message)
        self.attempts, self.last, self.last_check_ok = attempts, last, last_check_ok
        self.ranges = ranges if ranges is not None else PAPER_RANGES


def make_variant(ref: Layout, spec: VariantSpec, ranges: dict | None = None, max_attempts: int = 40,
                 walkway: np.ndarray | None = None) -> Layout:
    """``rearrange`` with sub-seeds ``spec.seed * 1000 + k`` until stats are in range and checks pass.

    ``ranges`` default to ``target_ranges(ref)``: the paper's for a procedural layout. For an
    imported layout the plan is ``scaled_plan(ref, spec.plan)`` and the ranges ``scaled_ranges(ref)``
    (both recorded in the variant's ``meta``); when the reference itself does not check clean, a
    variant passes when it adds no problem the reference does not have (``new_problems``).
    Raises ``NoVariantFound`` (a RuntimeError) after ``max_attempts``."""
    imported = is_imported(ref)
    plan = scaled_plan(ref, spec.plan) if imported else spec.plan
    if ranges is None:
        ranges = target_ranges(ref)
    ref_report = check_layout(ref) if imported else None
    last, last_ok = None, None
    for k in range(max_attempts):
        sub = spec.seed * 1000 + k
        var = rearrange(ref, spec.name, sub, plan, walkway, targets=ranges if imported else None)
        st = change_stats(ref, var)
        last = st
        last_ok = None
        if in_ranges(st, ranges):
            rep = check_layout(var)
            last_ok = rep.ok if ref_report is None or ref_report.ok else not new_problems(ref_report, rep)
            if last_ok:
                var.meta["variant_seed"] = spec.seed
                var.meta["attempt"] = k
                if imported:
                    var.meta["ranges"] = {key: [lo, hi] for key, (lo, hi) in ranges.items()}
                return var
    raise NoVariantFound(f"no rearrangement of {ref.name} within the target ranges after {max_attempts} attempts "
                         f"(last: {last})", max_attempts, last, last_ok, ranges)


def new_variant(ref: Layout, name: str, seed: int, plan: RearrangePlan | None = None, attempts: int = 40) -> Layout:
    """A new rearranged variant of ``ref`` from a seed, as ``synth scene rearrange`` and
    ``synth.rearrange`` make it: kept out of the reference's walkway (so one query path serves both),
    retried on sub-seeds until in range and clean (:func:`make_variant`). No such variant is one
    UserError line with the last attempt's statistics against the ranges."""
    if seed < 0:
        raise UserError(f"--seed must be >= 0, got {seed}")
    if attempts <= 0:
        raise UserError(f"--attempts must be positive, got {attempts}")
    if name == ref.name:
        raise UserError(f"--name: the variant needs a name other than its base's ('{ref.name}')")
    try:
        return make_variant(ref, VariantSpec(name, seed, plan or RearrangePlan()), walkway=reference_walkway(ref),
                            max_attempts=attempts)
    except NoVariantFound as e:
        last = e.last or {}
        ranges = getattr(e, "ranges", None) or PAPER_RANGES
        label = "paper" if ranges == PAPER_RANGES else "target"
        detail = ", ".join(f"{k} {last[k]} ({label} {lo}-{hi})" for k, (lo, hi) in ranges.items() if k in last)
        why = "" if e.last_check_ok is not False else "; it was in range but failed the layout checks"
        raise UserError(f"no variant of {ref.name} from seed {seed} within the {label} ranges that checks clean "
                        f"after {e.attempts} attempt(s) (last: {detail}{why}); try another --seed") from None
