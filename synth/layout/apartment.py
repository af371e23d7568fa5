"""The built-in procedural apartment ``apt_0``: a Manhattan flat of five rooms, furnished.

Deterministic from a seed: the seed jitters the floor plan (about 85-110 m2), picks every
object's size and style (``synth.assets.registry.sample_params``) and places it with ``synth.layout.placement``.

Floor plan (north up; x east, y north; one wall centre line per edge)::

    +----------------------+-----------------+
    |                      |                 |
    |     living room      |     bedroom     |
    |                      |                 |
    +---------+ +-----+-+--+-+---+-----------+   y = ys
    | kitchen /     hallway  |   bathroom    |
    | dining  |  (entrance)  |               |
    +---------+-----/ /------+---------------+   y = 0
    x=0       x1            x2               W
"""

from __future__ import annotations

import math

import numpy as np

from .placement import Placer
from ..scene.fixtures import layout_fixtures
from ..scene.model import Layout, ObjectInstance, Opening, Room, Stage, Wall

EXTERIOR_T = 0.2
INTERIOR_T = 0.1
DOOR_H = 2.1

DEFAULT_SEED = 7


def _rect(x0, y0, x1, y1, t_left, t_bottom, t_right, t_top):
    return (x0 + t_left / 2, y0 + t_bottom / 2, x1 - t_right / 2, y1 - t_top / 2)


def build_stage(rng: np.random.Generator) -> Stage:
    W = round(float(rng.uniform(10.6, 11.4)), 2)
    H = round(float(rng.uniform(8.6, 9.4)), 2)
    ys = round(float(rng.uniform(3.8, 4.2)), 2)
    x1 = round(float(rng.uniform(4.7, 5.2)), 2)
    x2 = round(x1 + float(rng.uniform(2.4, 2.7)), 2)
    xl = round(float(rng.uniform(x1 + 1.0, x2 - 1.2)), 2)
    ceiling = round(float(rng.uniform(2.6, 2.75)), 2)
    E, I = EXTERIOR_T, INTERIOR_T
    rooms = [
        Room("living", "living", _rect(0, ys, xl, H, E, I, I, E)),
        Room("bedroom", "bedroom", _rect(xl, ys, W, H, I, I, E, E)),
        Room("kitchen", "kitchen", _rect(0, 0, x1, ys, E, E, I, I)),
        Room("hallway", "hallway", _rect(x1, 0, x2, ys, I, E, I, I)),
        Room("bathroom", "bathroom", _rect(x2, 0, W, ys, I, E, E, I)),
    ]
    segs = [
        # exterior, counter-clockwise from the south-west corner
        ((0, 0), (x1, 0), E), ((x1, 0), (x2, 0), E), ((x2, 0), (W, 0), E),
        ((W, 0), (W, ys), E), ((W, ys), (W, H), E),
        ((W, H), (xl, H), E), ((xl, H), (0, H), E),
        ((0, H), (0, ys), E), ((0, ys), (0, 0), E),
        # interior
        ((0, ys), (x1, ys), I), ((x1, ys), (xl, ys), I), ((xl, ys), (x2, ys), I), ((x2, ys), (W, ys), I),
        ((x1, 0), (x1, ys), I), ((x2, 0), (x2, ys), I), ((xl, ys), (xl, H), I),
    ]
    walls = [Wall(f"W{k}", tuple(map(float, a)), tuple(map(float, b)), t, ceiling) for k, (a, b, t) in enumerate(segs)]

    def opening(oid, kind, wall_idx, frac, width, bottom, height, rooms):
        w = walls[wall_idx]
        off = round(frac * w.length, 3)
        off = min(max(off, width / 2 + 0.15), w.length - width / 2 - 0.15)
        return Opening(oid, kind, w.id, off, width, bottom, height, rooms)

    hall_living = (xl - x1)
    openings = [
        opening("D_entry", "door", 1, 0.5, 0.95, 0.0, DOOR_H, ("hallway",)),
        opening("D_living", "door", 10, 0.5, min(0.9, hall_living - 0.35), 0.0, DOOR_H, ("hallway", "living")),
        opening("D_bedroom", "door", 11, 0.5, min(0.85, x2 - xl - 0.35), 0.0, DOOR_H, ("hallway", "bedroom")),
        opening("D_kitchen_living", "door", 9, 0.62, 1.3, 0.0, DOOR_H, ("kitchen", "living")),
        opening("D_kitchen", "door", 13, 0.6, 0.85, 0.0, DOOR_H, ("kitchen", "hallway")),
        opening("D_bathroom", "door", 14, 0.5, 0.8, 0.0, DOOR_H, ("hallway", "bathroom")),
        opening("N_living_1", "window", 6, 0.3, 1.5, 0.85, 1.45, ("living",)),
        opening("N_living_2", "window", 6, 0.75, 1.3, 0.85, 1.45, ("living",)),
        opening("N_living_w", "window", 7, 0.5, 1.2, 0.9, 1.4, ("living",)),
        opening("N_bedroom", "window", 5, 0.45, 1.4, 0.9, 1.4, ("bedroom",)),
        opening("N_bedroom_e", "window", 4, 0.5, 1.1, 0.9, 1.4, ("bedroom",)),
        opening("N_kitchen", "window", 0, 0.5, 1.2, 1.0, 1.2, ("kitchen",)),
        opening("N_kitchen_w", "window", 8, 0.55, 1.0, 1.0, 1.2, ("kitchen",)),
        opening("N_bathroom", "window", 3, 0.5, 0.7, 1.5, 0.7, ("bathroom",)),
    ]
    return Stage(ceiling_height=ceiling, rooms=rooms, walls=walls, openings=openings)


class _Furnisher:
    """Room-by-room furnishing rules. Every ``put`` asks the placer for a valid spot and skips
    the object if none is found (the seed then decides which optional pieces make it in)."""

    def __init__(self, layout: Layout, rng: np.random.Generator):
        self.p = Placer(layout, rng)
        self.rng = rng
        self.layout = layout

    def room(self, name):
        return self.layout.stage.room(name)

    def _try(self, cls, fn, *args, **kw) -> ObjectInstance | None:
        for _ in range(6):  # a few size/style draws before giving up
            size, params = self.p.sample(cls)
            obj = fn(self.p.next_id(), cls, size, params, *args, **kw)
            if obj is not None:
                return self.p.add(obj)
        return None

    def wall(self, cls, room, **kw):
        return self._try(cls, self.p.against_wall, self.room(room), **kw)

    def free(self, cls, room, **kw):
        return self._try(cls, self.p.free_spot, self.room(room), **kw)

    def corner(self, cls, room):
        return self._try(cls, self.p.corner, self.room(room))

    def rel(self, cls, parent, dxy_fn, dyaw):
        """``dxy_fn(size) -> (dx, dy)`` offset in the parent's frame."""
        for _ in range(6):
            size, params = self.p.sample(cls)
            obj = self.p.relative(self.p.next_id(), cls, size, params, parent, dxy_fn(size), dyaw)
            if obj is not None:
                return self.p.add(obj)
        return None

    def on(self, cls, parents, n=1, yaw_mode="aligned"):
        parents = [q for q in parents if q is not None]
        out = []
        for _ in range(n):
            o = self._try(cls, self.p.on_surface, parents, yaw_mode=yaw_mode)
            if o is not None:
                out.append(o)
        return out

    def hang(self, cls, room, **kw):
        return self._try(cls, self.p.on_wall, self.room(room), **kw)

    def ceiling(self, room):
        return self._try("ceiling_light", self.p.on_ceiling, self.room(room))

    def longest_free_side(self, room_name) -> str:
        """The room side with the longest wall run without doors (for sofas, beds...)."""
        from .placement import side_of_wall

        room = self.room(room_name)
        best, best_len = "S", -1.0
        for side in ("S", "N", "W", "E"):
            run = 0.0
            for w in self.layout.stage.walls:
                if side_of_wall(room, w) == side:
                    doors = [o for o in self.layout.stage.openings if o.wall == w.id and o.kind == "door"]
                    run = max(run, w.length - sum(o.width + 2 * 0.9 for o in doors))
            if run > best_len:
                best, best_len = side, run
        return best


def _furnish(layout: Layout, rng: np.random.Generator) -> None:
    f = _Furnisher(layout, rng)
    opp = {"S": "N", "N": "S", "W": "E", "E": "W"}

    # ---- living room ------------------------------------------------------------------------
    lr = f.room("living")
    sofa_side = "S" if (lr.rect[3] - lr.rect[1]) >= (lr.rect[2] - lr.rect[0]) * 0.6 else f.longest_free_side("living")
    sofa_side = "W" if lr.rect[2] - lr.rect[0] > 5.0 else sofa_side
    along_mid = (lr.rect[1] + lr.rect[3]) / 2 if sofa_side in ("W", "E") else (lr.rect[0] + lr.rect[2]) / 2
    sofa = f.wall("sofa", "living", side=sofa_side, along=along_mid)
    coffee = armchairs = None
    if sofa is not None:
        coffee = f.rel("coffee_table", sofa, lambda s: (0.0, sofa.size[1] / 2 + 0.45 + s[1] / 2), 0.0)
        armchairs = [
            f.rel("armchair", sofa, lambda s, k=k: (k * (sofa.size[0] / 2 + 0.35 + s[0] / 2), sofa.size[1] / 2 + 0.55), -k * math.radians(60))
            for k in (-1, 1)
        ]
        f.wall("tv_stand", "living", side=opp[sofa_side], along=along_mid)
        f.rel("side_table", sofa, lambda s: (sofa.size[0] / 2 + 0.05 + s[0] / 2, -sofa.size[1] / 2 + s[1] / 2), 0.0)
    tv_stand = [o for o in layout.objects if o.cls == "tv_stand"]
    f.on("tv", tv_stand)
    side_tables = [o for o in layout.objects if o.cls == "side_table"]
    f.on("table_lamp", side_tables)
    shelves = [f.wall("bookshelf", "living") for _ in range(2)]
    f.corner("floor_lamp", "living")
    f.corner("floor_lamp", "living")
    f.corner("plant", "living")
    f.wall("plant", "living")
    f.on("cushion", [sofa], n=3, yaw_mode="aligned")
    f.on("cushion", armchairs or [], n=2)
    f.on("book", shelves, n=10)
    f.on("small_plant", shelves, n=1)
    f.on("vase", [coffee], n=1, yaw_mode="free")
    f.on("bowl", [coffee], n=1, yaw_mode="free")
    f.wall("basket", "living")
    f.hang("picture", "living")
    f.hang("picture", "living")
    f.hang("picture", "living")
    f.ceiling("living")

    # ---- kitchen / dining ------------------------------------------------------------------------
    kr = f.room("kitchen")
    # the counter run along the south wall: fridge, counter, stove, counter
    run_side = "S"
    x = kr.rect[0] + 0.02
    for cls in ("fridge", "kitchen_counter", "stove", "kitchen_counter"):
        size, params = f.p.sample(cls)
        if x + size[0] > kr.rect[2] - 0.02:
            break
        obj = f.p.against_wall(f.p.next_id(), cls, size, params, kr, side=run_side, along=x + size[0] / 2, tries=1)
        if obj is not None:
            f.p.add(obj)
            x += size[0] + 0.005
    table = f.free("dining_table", "kitchen", yaw=0.0, margin=0.7)
    if table is not None:
        for sx in (-1, 1):
            for sy in (-1, 1):
                f.rel("chair", table, lambda s, sx=sx, sy=sy: (sx * table.size[0] / 4, sy * (table.size[1] / 2 + 0.12 + s[1] / 2)),
                      0.0 if sy < 0 else math.pi)
        f.on("vase", [table], n=1, yaw_mode="free")
        f.on("bowl", [table], n=1, yaw_mode="free")
    counters = [o for o in layout.objects if o.cls == "kitchen_counter"]
    f.on("bowl", counters, n=2, yaw_mode="free")
    f.on("small_plant", counters, n=1, yaw_mode="free")
    cab = f.wall("cabinet", "kitchen")
    f.on("vase", [cab], n=1, yaw_mode="free")
    f.wall("bin", "kitchen")
    f.corner("plant", "kitchen")
    f.wall("stool", "kitchen")
    f.hang("picture", "kitchen")
    f.ceiling("kitchen")

    # ---- bedroom ------------------------------------------------------------------------------
    br = f.room("bedroom")
    bed_side = "N"
    bed = f.wall("bed", "bedroom", side=bed_side, along=(br.rect[0] + br.rect[2]) / 2)
    stands = []
    if bed is not None:
        for k in (-1, 1):
            stands.append(f.rel("nightstand", bed, lambda s, k=k: (k * (bed.size[0] / 2 + 0.04 + s[0] / 2), -bed.size[1] / 2 + s[1] / 2), 0.0))
        f.rel("bench", bed, lambda s: (0.0, bed.size[1] / 2 + 0.1 + s[1] / 2), math.pi)
    for st in stands:
        if st is not None:
            f.on("table_lamp", [st], n=1)
    f.on("cushion", [bed], n=2)
    f.on("book", [s for s in stands if s is not None], n=2, yaw_mode="free")
    f.wall("wardrobe", "bedroom")
    desk = f.wall("desk", "bedroom")
    if desk is not None:
        f.rel("chair", desk, lambda s: (0.0, desk.size[1] / 2 + 0.15 + s[1] / 2 - 0.1), math.pi)
        f.on("laptop", [desk], n=1)
        f.on("book", [desk], n=2, yaw_mode="any90")
    f.wall("bookshelf", "bedroom")
    f.on("book", [o for o in layout.objects if o.cls == "bookshelf" and br.rect[0] <= o.position[0] <= br.rect[2] and br.rect[1] <= o.position[1] <= br.rect[3]], n=5)
    f.corner("plant", "bedroom")
    f.wall("basket", "bedroom")
    f.hang("picture", "bedroom")
    f.hang("picture", "bedroom")
    f.hang("mirror", "bedroom")
    f.ceiling("bedroom")

    # ---- bathroom ------------------------------------------------------------------------------
    f.wall("bathtub", "bathroom", side="N")
    basin = f.wall("washbasin", "bathroom")
    if basin is not None:
        b = basin
        side = {0.0: "S", round(math.pi, 6): "N", round(-math.pi / 2, 6): "W", round(math.pi / 2, 6): "E"}.get(round(b.yaw, 6))
        along = b.position[0] if side in ("S", "N") else b.position[1]
        f.hang("mirror", "bathroom", side=side, along=along, z_center=1.55)
        f.on("small_plant", [basin], n=1, yaw_mode="free")
    f.wall("toilet", "bathroom")
    f.wall("cabinet", "bathroom")
    f.wall("bin", "bathroom")
    f.wall("basket", "bathroom")
    f.ceiling("bathroom")

    # ---- hallway --------------------------------------------------------------------------------
    f.wall("shoe_rack", "hallway")
    hc = f.wall("cabinet", "hallway")
    f.on("vase", [hc], n=1, yaw_mode="free")
    f.on("bowl", [hc], n=1, yaw_mode="free")
    f.corner("plant", "hallway")
    f.hang("picture", "hallway")
    f.hang("picture", "hallway")
    f.hang("mirror", "hallway")
    f.ceiling("hallway")


def generate_apartment(seed: int = DEFAULT_SEED, name: str = "apt_0") -> Layout:
    """The furnished reference apartment. Same seed, same layout, byte for byte."""
    rng = np.random.default_rng(seed)
    stage = build_stage(rng)
    layout = Layout(name=name, stage=stage, seed=seed, meta={"generator": "synth.apartment", "generator_version": 1})
    _furnish(layout, rng)
    layout.fixtures = layout_fixtures(layout)
    return layout
