"""Physical plausibility of a layout: interpenetrations, support, passable doors.

``check_layout`` is what ``synth scene check`` prints. It works from boxes (an object's mesh lies
inside its box: a property of every generator in ``synth.assets``), the supporting surfaces of
procedural objects, and a free-space grid for door reachability.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from matplotlib.path import Path as MplPath
from scipy import ndimage

from ..assets import registry as assets
from ..scene import geometry as geo
from ..mesh.collision import DEFAULT_MARGIN, PENETRATION_TOL, contact_gap, margin, penetration, stage_distance, stage_drop, touching, world_pieces
from ..mesh.surfaces import mesh_surfaces
from ..scene.openings import door_zone, opening_box
from ..scene.model import Layout, object_box

Z_TOL = 0.003  # how far an object may float above / sink into its support (m)
XY_TOL = 0.002
OVERLAP_TOL = 0.005  # boxes may touch; interpenetration deeper than this counts
WALL_TOL = 0.03
# Structure derived from a stage mesh (ReplicaCAD: synth.mesh.stage_structure) has a finite resolution:
# wall faces found from the mesh, rooms from the floor; a navmesh-built stand-in stage is good to
# about its cell size plus its edge error (5 + 6.5 cm). Footprint-in-room and wall-contact tests on
# such a stage allow this much.
STRUCTURE_TOL = 0.08
# soft furnishings (params["soft"]: ReplicaCAD's beanbags, cushions, cloths, rugs) compress where they
# press on something: two beanbags of ReplicaCAD's apt_3 and apt_5 overlap by a 1.4-1.5 cm ball
SOFT_PENETRATION_TOL = 0.02
GRID = 0.05  # free-space grid resolution (m)
WALKER_RADIUS = 0.2  # half the width a person needs to pass (m)
OBSTACLE_BELOW = 1.5  # objects whose box starts below this height obstruct walking (m)
DOOR_PROBE = 0.45  # how far in front of a door its reachability is tested (m)


@dataclass
class CheckReport:
    layout: str
    objects: int
    classes: int
    collisions: list[dict] = field(default_factory=list)
    unsupported: list[dict] = field(default_factory=list)
    blocked_doors: list[dict] = field(default_factory=list)
    covered_openings: list[dict] = field(default_factory=list)
    structure: list[dict] = field(default_factory=list)  # a shell without rooms or walls

    @property
    def ok(self) -> bool:
        return not (self.structure or self.collisions or self.unsupported or self.blocked_doors or self.covered_openings)

    def to_dict(self) -> dict:
        return {
            "layout": self.layout,
            "objects": self.objects,
            "classes": self.classes,
            "collisions": self.collisions,
            "unsupported": self.unsupported,
            "blocked_doors": self.blocked_doors,
            "covered_openings": self.covered_openings,
            "structure": self.structure,
            "ok": self.ok,
        }


def _support_problem(layout: Layout, o, box: geo.OrientedBox, by_id, boxes, pieces=None) -> str | None:
    st = layout.stage
    floor, ceil = st.floor_z, st.floor_z + st.ceiling_height
    if o.support == "floor":
        if abs(box.zmin - floor) > Z_TOL:
            return f"bottom at z={box.zmin:.3f} m, floor at {floor:.3f} m"
        if st.rooms and not _in_rooms(st, box.corners_2d()):
            return "footprint not inside any room"
        return None
    if o.support == "ceiling":
        if abs(box.zmax - ceil) > Z_TOL:
            return f"top at z={box.zmax:.3f} m, ceiling at {ceil:.3f} m"
        return None
    if o.support.startswith("wall:"):
        w = st.wall(o.support.split(":", 1)[1])
        d = w.direction
        n = np.array([-d[1], d[0]])
        rel = np.asarray(box.center[:2]) - np.asarray(w.start)
        dist = abs(rel @ n)
        want = w.thickness / 2 + box.size[1] / 2
        wyaw = math.atan2(d[1], d[0])
        if abs(math.sin(box.yaw - wyaw)) > 0.02:
            return "not parallel to its wall"
        if abs(dist - want) > WALL_TOL:
            return f"{dist - want:+.3f} m off its wall face"
        along = rel @ d
        if along - box.size[0] / 2 < -XY_TOL or along + box.size[0] / 2 > w.length + XY_TOL:
            return "extends beyond its wall"
        if box.zmin < floor - Z_TOL or box.zmax > ceil + Z_TOL:
            return "extends beyond floor or ceiling"
        return None
    if o.support.startswith("object:"):
        pid, k = o.support_parent()
        parent = by_id.get(pid)
        if parent is None:
            return f"stands on object {pid}, which is missing"
        if parent.asset.startswith("proc:"):
            surfs = assets.support_surfaces(parent.cls, parent.size, parent.params)
        else:  # a mesh object: its box top and the levels below it (synth.mesh.surfaces.mesh_surfaces)
            surfs = mesh_surfaces(parent, layout.meta.get("root"))
            if not surfs:
                return _rests_on_some_box(box, [boxes[pid]], floor)
        if k >= len(surfs):
            return f"surface {k} of object {pid} ({parent.cls}) does not exist"
        s = surfs[k]
        # an object a dataset's physics placed (it has a motion type) stands where it settled: its centre
        # over the surface is enough, and a shelf's clearance (a rule for placing things) does not apply
        dataset_placed = "motion_type" in o.params
        dz = box.zmin - (parent.position[2] + s.z)
        if dz < -Z_TOL or dz > s.band + Z_TOL:
            where = f"{dz:+.3f} m off" if s.band == 0 else f"{dz:+.3f} m above the bottom of (band {s.band:.3f} m)"
            return f"bottom {where} surface {k} of object {pid}"
        if not dataset_placed and box.zmax - (parent.position[2] + s.z) > s.clearance + Z_TOL:
            return f"taller than the {s.clearance:.2f} m clearance of surface {k} of object {pid}"
        # footprint in the parent's frame: inside a board's rectangle; a receptacle (band > 0) is the
        # region the dataset places object centres in (synth.sources.replicacad.receptacles), so its centre must be inside
        Rp = geo.rot_z(parent.yaw)[:2, :2]
        centre_rule = s.band > 0 or dataset_placed
        pts = box.corners_2d() if not centre_rule else np.asarray(box.center[:2], float)[None, :]
        local = (pts - np.asarray(parent.position[:2])) @ Rp
        if not geo.polygon_inside_rect(local, (s.xmin, s.ymin, s.xmax, s.ymax), XY_TOL):
            what = "centre lies outside" if centre_rule else "footprint overhangs"
            return f"{what} surface {k} of object {pid} ({parent.cls})"
        return None
    if o.support == "free":
        why = _rests_on_some_box(box, list(boxes.values()), floor)
        if why and pieces and pieces.get(o.id):
            # a physics-settled object (ReplicaCAD): it rests on, leans against or hangs from what its
            # collision shape touches, within the two shapes' collision margins (synth.mesh.collision):
            # another object's shape, the floor, the stage mesh, or a derived wall (to STRUCTURE_TOL)
            mine, m = pieces[o.id], margin(o)
            stage_margin = _stage_margin(layout)
            if min(float(v[:, 2].min()) for v in mine) - floor <= contact_gap(m, stage_margin):
                return None
            reach = contact_gap(m, DEFAULT_MARGIN)
            near = [p for p, b in boxes.items() if p != o.id and geo.boxes_overlap(b, _grown(box, reach), 0.0)]
            if any(touching(mine, pieces.get(p) or [_box_corners(boxes[p])], contact_gap(m, margin(by_id[p]))) for p in near):
                return None
            if stage_distance(layout, mine) <= contact_gap(m, stage_margin) or _wall_distance(st, box) <= STRUCTURE_TOL:
                return None  # on, against or hanging from the stage mesh (a wall, a built-in shelf, a hook)
            why = f"bottom at z={box.zmin:.3f} m: its collision shape touches no object, the floor, the stage mesh or a wall"
        return why
    return f"unknown support '{o.support}'"


def _stage_margin(layout: Layout) -> float:
    """The stage's collision margin (its config's ``margin``, recorded by the importer; 0 if none)."""
    return float((layout.meta.get("structure") or {}).get("margin", 0.0))


def _on_the_stage(layout: Layout, o, box: geo.OrientedBox, pieces: dict) -> bool:
    """A physics-placed object above the floor that the stage mesh holds, so that the derived rooms
    (main-floor interiors) need not hold its footprint: it stands on the stage below it (the stairs'
    landing: the stage surface under its footprint centre lies within the collision margins of its
    bottom), or it hangs on a wall (its collision shape touches the stage mesh and its centre lies at
    most half its depth plus ``STRUCTURE_TOL`` outside the rooms: a picture on its wall, not one
    pushed through it)."""
    mine = pieces.get(o.id) if pieces else None
    if not mine or box.zmin - layout.stage.floor_z <= 0.05:
        return False
    stage_margin = _stage_margin(layout)
    gap = contact_gap(margin(o), stage_margin)
    if stage_distance(layout, mine) > gap:
        return False
    lowest = min(float(v[:, 2].min()) for v in mine)
    # the stage surface under the centre within the margins of the bottom, above or below it (the ray
    # starts a margin above the bottom: a shape may rest that far into what holds it)
    if stage_drop(layout, (box.center[0], box.center[1], lowest + gap)) <= 2 * gap:
        return True
    return _outside_rooms_by(layout.stage, np.asarray(box.center[:2], float)) <= min(box.size[:2]) / 2.0 + STRUCTURE_TOL


def _outside_rooms_by(st, xy: np.ndarray) -> float:
    """0 for a point inside some room, else its distance to the nearest room outline."""
    if any(r.contains(xy[None, :])[0] for r in st.rooms):
        return 0.0
    best = math.inf
    for r in st.rooms:
        q = r.outline()
        a, b = q, np.roll(q, -1, axis=0)
        ab = b - a
        L2 = np.maximum((ab * ab).sum(1), 1e-12)
        t = np.clip(((xy - a) * ab).sum(1) / L2, 0.0, 1.0)
        best = min(best, float(np.hypot(*(xy - a - t[:, None] * ab).T).min()))
    return best


def _both_static(a, b) -> bool:
    """Two objects a dataset marks STATIC (habitat-sim's motion type: placed by its authors, never
    simulated): their fit is by design (a monitor's neck in its stand's socket) and no physics
    resolved it, so it is not checked. Objects without a motion type (procedural, variants' moved
    copies keep theirs) are always checked."""
    return a.params.get("motion_type") == "STATIC" and b.params.get("motion_type") == "STATIC"


def _grown(b: geo.OrientedBox, d: float) -> geo.OrientedBox:
    return geo.OrientedBox(b.id, b.cls, b.center, tuple(s + 2 * d for s in b.size), b.yaw)


def _wall_distance(st, box: geo.OrientedBox) -> float:
    """Horizontal distance from an object's box footprint to the nearest wall face (inf without walls)."""
    best = math.inf
    pts = box.corners_2d()
    for w in st.walls:
        a, b = np.asarray(w.start, float), np.asarray(w.end, float)
        ab = b - a
        L2 = float(ab @ ab)
        if L2 <= 0:
            continue
        t = np.clip(((pts - a) @ ab) / L2, 0.0, 1.0)
        d = np.hypot(*(pts - a - t[:, None] * ab).T) - w.thickness / 2.0
        best = min(best, float(d.min()))
    return best


def _in_rooms(st, corners: np.ndarray) -> bool:
    """Whether a footprint lies inside the rooms: inside one room's rect (a procedural stage), or, on a
    stage mesh's derived structure, with every corner (moved ``STRUCTURE_TOL`` towards the centre)
    inside some room (an open plan's rooms meet without a wall, so a sofa may span two)."""
    if st.asset is None:
        return any(geo.polygon_inside_rect(corners, r.rect, XY_TOL) for r in st.rooms)
    c = corners.mean(axis=0)
    d = corners - c
    n = np.linalg.norm(d, axis=1, keepdims=True)
    pts = c + d * np.clip(1.0 - STRUCTURE_TOL / np.maximum(n, 1e-9), 0.0, 1.0)
    inside = np.zeros(len(pts), bool)
    for r in st.rooms:
        inside |= r.contains(pts)
    return bool(inside.all())


def _box_corners(b: geo.OrientedBox) -> np.ndarray:
    c2 = b.corners_2d()
    return np.concatenate([np.c_[c2, np.full(4, b.zmin)], np.c_[c2, np.full(4, b.zmax)]])


def _rests_on_some_box(box, others, floor) -> str | None:
    if abs(box.zmin - floor) <= 0.02:
        return None
    for b in others:
        if b.id != box.id and abs(b.zmax - box.zmin) <= 0.02 and geo.polygons_overlap_2d(b.corners_2d(), box.corners_2d()):
            return None
    return f"bottom at z={box.zmin:.3f} m rests on nothing"


def free_space(layout: Layout, boxes: list[geo.OrientedBox], grid: float = GRID, radius: float = WALKER_RADIUS):
    """Walkable grid: room interiors and door gaps, minus obstacles, eroded by the walker radius.

    Returns (walkable bool array [ny, nx], origin xy, grid).
    """
    st = layout.stage
    xs = [r.rect[0] for r in st.rooms] + [r.rect[2] for r in st.rooms]
    ys = [r.rect[1] for r in st.rooms] + [r.rect[3] for r in st.rooms]
    x0, y0 = min(xs) - 0.5, min(ys) - 0.5
    nx, ny = int(math.ceil((max(xs) + 0.5 - x0) / grid)), int(math.ceil((max(ys) + 0.5 - y0) / grid))
    gx, gy = np.meshgrid(x0 + (np.arange(nx) + 0.5) * grid, y0 + (np.arange(ny) + 0.5) * grid)
    pts = np.stack([gx.ravel(), gy.ravel()], axis=1)
    free = np.zeros(ny * nx, bool)
    for r in st.rooms:
        free |= (pts[:, 0] >= r.rect[0]) & (pts[:, 0] <= r.rect[2]) & (pts[:, 1] >= r.rect[1]) & (pts[:, 1] <= r.rect[3])
    for op in st.openings:
        if op.kind == "door":
            gap = opening_box(st, op, depth_extra=0.01)
            free |= MplPath(gap.corners_2d()).contains_points(pts)
    for b in boxes:
        if b.zmin < st.floor_z + OBSTACLE_BELOW:
            c = b.corners_2d()
            lo, hi = c.min(0), c.max(0)
            m = (pts[:, 0] >= lo[0]) & (pts[:, 0] <= hi[0]) & (pts[:, 1] >= lo[1]) & (pts[:, 1] <= hi[1])
            idx = np.nonzero(m)[0]
            if len(idx):
                free[idx[MplPath(c).contains_points(pts[idx])]] = False
    free = free.reshape(ny, nx)
    r = int(math.ceil(radius / grid))
    yy, xx = np.mgrid[-r : r + 1, -r : r + 1]
    disk = (xx**2 + yy**2) <= r * r
    walkable = ~ndimage.binary_dilation(~free, structure=disk)
    return walkable, (x0, y0), grid


def check_layout(layout: Layout) -> CheckReport:
    objs = layout.objects
    by_id = {o.id: o for o in objs}
    boxes = {o.id: object_box(o) for o in objs}
    rep = CheckReport(layout.name, len(objs), len({o.cls for o in objs}))
    st = layout.stage

    # the shell: a procedural stage needs rooms (free space, floors, ceilings) and walls; a stage
    # mesh (ReplicaCAD) carries what synth.mesh.stage_structure derived from it, or nothing when it was
    # imported without structure
    if st.asset is None:
        if not st.rooms:
            rep.structure.append({"what": "rooms", "why": "no rooms (stage.rooms is empty): a layout needs at least one"})
        if not st.walls:
            rep.structure.append({"what": "walls", "why": "no walls (stage.walls is empty)"})

    root = layout.meta.get("root")
    pieces = {o.id: world_pieces(o, root) for o in objs} if root is not None else {}
    # support
    for o in objs:
        why = _support_problem(layout, o, boxes[o.id], by_id, boxes, pieces)
        if why:
            rep.unsupported.append({"id": o.id, "class": o.cls, "support": o.support, "why": why})

    # interpenetration between objects (an object may overlap the box of what holds it). Objects
    # with collision shapes (ReplicaCAD: synth.mesh.collision) are tested on those where their boxes
    # overlap: a chair under a table, a book in a cabinet, shoes in a rack are no collision
    ids = sorted(boxes)
    parent = {o.id: (o.support_parent() or (None, None))[0] for o in objs}
    for i, a in enumerate(ids):
        for b in ids[i + 1 :]:
            if parent[a] == b or parent[b] == a:
                continue
            if _both_static(by_id[a], by_id[b]):
                continue
            if geo.boxes_overlap(boxes[a], boxes[b], OVERLAP_TOL):
                pa, pb = pieces.get(a), pieces.get(b)
                if pa or pb:
                    tol = SOFT_PENETRATION_TOL if (by_id[a].params.get("soft") or by_id[b].params.get("soft")) else PENETRATION_TOL
                    depth = penetration(pa or [_box_corners(boxes[a])], pb or [_box_corners(boxes[b])], stop_at=tol)
                    if depth < tol:
                        continue
                rep.collisions.append({"a": a, "b": b, "classes": [by_id[a].cls, by_id[b].cls]})
    # objects poking through the ceiling (a ceiling light touches it; nothing may go through)
    ceil = st.floor_z + st.ceiling_height
    for o in objs:
        top = max(float(v[:, 2].max()) for v in pieces[o.id]) if pieces.get(o.id) else boxes[o.id].zmax
        if top > ceil + Z_TOL:
            rep.collisions.append({"a": o.id, "b": "ceiling", "classes": [o.cls, "ceiling"]})
    # objects poking through walls: footprints must lie inside a room (procedural stages)
    if st.rooms:
        for o in objs:
            if o.support.startswith("wall:") or o.support.startswith("object:"):
                continue
            if o.support == "free" and _on_the_stage(layout, o, boxes[o.id], pieces):
                continue  # hangs on a wall, stands on the stairs' landing: the stage holds it, no room has it
            if not _in_rooms(st, boxes[o.id].corners_2d()):
                if not any(u["id"] == o.id for u in rep.unsupported):
                    rep.collisions.append({"a": o.id, "b": "wall", "classes": [o.cls, "wall"]})

    # openings covered by objects: a picture hung over a window or door, or anything reaching
    # into the hole in the wall itself (things merely standing in front of a window are fine)
    for op in st.openings:
        hole = opening_box(st, op)
        front = opening_box(st, op, depth_extra=0.05)
        for o in objs:
            zone = front if o.support.startswith("wall:") else hole
            if geo.boxes_overlap(boxes[o.id], zone, tol=0.0):
                rep.covered_openings.append({"opening": op.id, "id": o.id, "class": o.cls})

    # doors: free clearance zones and one connected walkable space joining all of them
    doors = [op for op in st.openings if op.kind == "door"]
    if doors and st.rooms:
        for op in doors:
            z = door_zone(st, op)
            hit = [o.id for o in objs if geo.boxes_overlap(boxes[o.id], z, tol=0.0)]
            if hit:
                rep.blocked_doors.append({"door": op.id, "why": f"clearance zone holds object(s) {hit}"})
        walkable, (x0, y0), g = free_space(layout, list(boxes.values()))
        labels, _ = ndimage.label(walkable)

        def label_at(xy):
            i, j = int((xy[1] - y0) / g), int((xy[0] - x0) / g)
            return labels[i, j] if 0 <= i < labels.shape[0] and 0 <= j < labels.shape[1] else 0

        # a door is passable when the spots just in front of it, in every room it connects,
        # lie in walkable space, and all doors join one walkable component
        sides = {}
        for op in doors:
            w = st.wall(op.wall)
            c = op.center_xy(w)
            n = np.array([-w.direction[1], w.direction[0]])
            spots = [c + sgn * n * (w.thickness / 2 + DOOR_PROBE) for sgn in (-1, 1)]
            spots = [p for p in spots if st.room_at(p) is not None]
            sides[op.id] = [label_at(p) for p in spots]
        counts = {}
        for labs in sides.values():
            for lab in set(labs):
                if lab:
                    counts[lab] = counts.get(lab, 0) + 1
        main = max(counts, key=counts.get) if counts else 0
        for op in doors:
            labs = sides[op.id]
            if not labs or any(lab != main for lab in labs):
                if not any(d["door"] == op.id for d in rep.blocked_doors):
                    rep.blocked_doors.append({"door": op.id, "why": "no walkable way through it to the other doors"})
    return rep
