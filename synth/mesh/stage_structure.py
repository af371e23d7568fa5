"""Structure of a stage mesh: floor, ceiling, walls, openings and rooms, for the scene model.

ReplicaCAD stages are one mesh (walls, floor, ceiling, door and window frames, ...). The scene model
(``synth.scene.model.Stage``) describes a stage by its floor height, ceiling height, walls (centre lines
with a thickness and a height), openings cut in those walls (doors and windows) and rooms (the
axis-aligned free interior inside the wall faces). ``derive_structure`` recovers those from the
triangles, so that structure boxes, camera-path planning, rearrangement and layout checks work on
an imported stage exactly as on the procedural apartment; ``face_ids`` labels the stage's
triangles with the instance ids of that structure, for both renderers.

Frame: the mesh is given in the world, in OUR frame (right-handed, Z up, metres); gravity is -Z.
No Blender here; numpy and scipy only, vectorised over triangles.

Method
    * Floor: the up-facing horizontal plane (triangles whose normal is within ~18 deg of +Z, grouped
      by height, 1 cm) with the largest area in the lower half of the mesh. Ceiling: the largest
      down-facing plane at least 1.5 m above the floor (else the top of the mesh: an open stage).
    * Walls: triangles with ``|n_z| < 0.1`` are clustered by the direction of their horizontal
      normal folded to a line direction (area weighted, 2 deg), then by the side they face and their
      plane offset (1 cm). Each plane is rasterised on an (along, z) grid of 2 cm cells between
      floor and ceiling, and cut into pieces at full-height gaps. A piece a few cm in front of a
      larger one facing the same way (skirting, architraves, panels) is merged into it; pieces
      shorter than 0.3 m, or not 1 m high over at least 0.3 m of their length, are dropped
      (built-ins, reveals, end caps). Opposite-facing pieces 3-40 cm apart, facing away from each
      other and overlapping along the wall, are the two faces of one thick wall (thickness = their
      distance, centre line midway; the wall runs where both faces exist); a face without a
      partner that lies inside such a wall (the hidden back of trim) is dropped, any other becomes
      a wall of the default thickness 0.1 m BEHIND the face, so the visible face is exact. Wall
      ends, tops and opening edges are snapped from the 2 cm grid to the extent of the triangles
      that make them.
    * Openings: holes in a wall (empty in every face, at least 0.2 m wide and tall): a hole
      touching the floor with wall above it is a door (bottom 0; at least 1.5 m tall and 0.5 m
      wide), one above the floor a window. A hole reaching the ceiling splits the wall instead (a
      gap between two walls, not an opening).
    * Rooms: the floor (up-facing triangles at ``floor_z``) rasterised on 2.5 cm cells, minus the
      wall footprints (which also closes the doors), opened by 12.5 cm (so that slivers and cracks
      do not join rooms; the free cells within that reach are given back afterwards); connected
      pieces of at least 1 m^2 with a ceiling (or any down-facing surface above 1 m) over at least
      half of them (on an open stage, any) are rooms ``room_<k>`` of type ``room``; a terrace or
      the ground outside is not. A piece that holds two or more spaces joined only through floor
      narrower than ``DOORWAY_MAX`` (1.1 m: a doorway whose opening reaches the ceiling, so that no
      wall holds a door there) is split there into rooms (``_split_at_doorways``), which share the
      edge across the doorway; an open plan (wider joins) stays one room. A room's rect is its piece's bounding rectangle in world axes
      (snapped to axis-aligned wall faces within 4 cm): rooms of a stage that is not aligned with
      the world axes (or that are not rectangles, e.g. an open-plan L-shaped living room) are
      their bounding rectangles, and ``report["rooms"]["fill_ratio"]`` says how much of each rect
      is floor (a warning is logged below 0.85). A door's rooms are the rooms 0.3 m out from its
      wall on either side (one room for an entrance door), a window's the room on its inner side.

Determinism: triangles are put in a canonical order first (each triangle starting at its smallest
vertex, then sorted by rounded coordinates), so results do not depend on the order of the triangles
or of their vertices; outputs are rounded by the scene dataclasses (0.1 mm). Ids: walls ``W0``..,
doors ``D0``.., windows ``N0``.., rooms ``room_0``.. in order of position.

Limits (what this does not recover): curved or sloped walls (facets are rejected as small planes),
several floor levels or ceiling heights (the dominant one is used; walls are clipped to it), walls
whose faces are not modelled on either side. Tall built-ins modelled in the stage (a wardrobe
housing) come out as walls, and a wall face left out behind one reads as a door. A wall modelled as
one face relies on the winding: the wall goes behind the face's normal. Holes are not checked for
being see-through.
"""

from __future__ import annotations

import logging
import math
from dataclasses import dataclass, field

import numpy as np
import trimesh
from scipy import ndimage

from vrformats.boxes import CEILING_ID_BASE, FLOOR_ID_BASE, WALL_ID_BASE
from vrformats.fields import fail

from ..scene.model import Opening, Room, Stage, Wall, quantize

log = logging.getLogger(__name__)

__all__ = ["StageStructure", "derive_structure", "face_ids"]

# --------------------------------------------------------------------------------------------
# parameters (metres, degrees)

VERTICAL_NZ = 0.1  # |n_z| below this: a wall triangle
HORIZONTAL_NZ = 0.95  # n_z above this: faces up (floor); below minus this: faces down (ceiling)
PLANE_Z_GAP = 0.01  # horizontal planes: heights closer than this chain into one plane
MIN_FLOOR_AREA = 1.0  # m^2, floor and ceiling planes
MIN_CEILING_CLEARANCE = 1.5  # the ceiling is at least this far above the floor
DIR_BIN_DEG = 0.5  # wall direction histogram bin
DIR_TOL_DEG = 2.0  # wall triangles within this of a direction belong to it
OFFSET_GAP = 0.01  # wall planes: offsets closer than this chain into one plane
MIN_PLANE_AREA = 0.25  # m^2: smaller vertical planes are not rasterised
WALL_CELL = 0.02  # (along, z) grid of a wall plane
GAP_BRIDGE = 0.05  # column gaps up to this are bridged (mesh cracks), wider ones split walls
TRIM_DEPTH = 0.06  # a smaller same-facing piece this close in front/behind is merged (trim, frames)
MIN_WALL_HEIGHT = 1.0
MIN_WALL_LENGTH = 0.3
MAX_WALL_BOTTOM = 0.5  # a wall reaches down to within this of the floor (else it hangs: a bulkhead)
PAIR_MIN, PAIR_MAX = 0.03, 0.40  # distance between the two faces of one thick wall
DEFAULT_THICKNESS = 0.1  # a wall with one visible face: this thick, behind the face
MIN_HOLE = 0.2  # holes narrower or lower than this are ignored (sockets, slots, skirting bands)
DOOR_FLOOR_TOL = 0.05  # a hole whose bottom is this close to the floor touches it
MIN_DOOR_HEIGHT, MIN_DOOR_WIDTH = 1.5, 0.5
ROOM_CELL = 0.025  # floor grid
ROOM_OPEN = 0.125  # free floor is opened by a square this wide (drops slivers and cracks)
MIN_ROOM_AREA = 1.0  # m^2
DOORWAY_MAX = 1.1  # m: free floor narrower than this between two wider spaces is a doorway; rooms meet there
MIN_ROOM_CORE = 0.25  # m^2 of floor farther than DOORWAY_MAX / 2 from any wall: a space that counts as a room
MIN_COVER_Z = 1.0  # down-facing surfaces above this count as a cover (ceiling) over a room
MIN_COVER_FRACTION = 0.5
FILL_WARN = 0.85
RECT_FILL = 0.97  # a room whose floor fills this much of its rect is the rect (no polygon)
POLY_EPS = 1.0  # room polygons are simplified to this many floor cells (Douglas-Peucker)
PROBE = 0.3  # door/window rooms: probe this far out from the wall face
PROBE_RADIUS = 0.1
MAX_GRID_CELLS = 40_000_000  # a raster larger than this gets coarser cells
RAISED_MIN = 0.05  # up-facing surfaces this far above the floor are raised levels (steps, landings, tops)
RAISED_MIN_AREA = 0.02  # m^2: smaller up-facing planes are ignored (slivers)
RAISED_CELL = 0.05  # their XY grid
PLATFORM_DEPTH = (0.45, 0.55)  # probes behind a face, beyond the thickest wall (PAIR_MAX)
PLATFORM_NEAR = (0.05, 0.15, 0.25)  # probes just behind it (a step's own tread)
PLATFORM_TOL = 0.05  # a raised surface within this of a column's top is "at that height"
CEILING_TOL = 0.05  # a column top this close to the ceiling (or above it) reaches the ceiling

# face_ids tolerances
FACE_TOL = 0.03  # a wall triangle lies within this of its wall box's face
FLOOR_TOL = 0.05  # floor / ceiling triangles lie within this of floor_z / the ceiling
ALIGN_COS = 0.9  # a face's normal within ~25 deg of the box face's outward normal
HOLE_INSET = 0.01  # triangles more than this inside an opening (frames, glass) are not wall


@dataclass
class StageStructure:
    """What ``derive_structure`` found, in our frame. ``report``: counts and diagnostics."""

    floor_z: float
    ceiling_height: float
    walls: list[Wall]
    openings: list[Opening]
    rooms: list[Room]
    report: dict = field(default_factory=dict)


# --------------------------------------------------------------------------------------------
# small helpers


def _canonical(tri: np.ndarray) -> np.ndarray:
    """Triangles in an order that depends only on their geometry: each triangle's vertices rotated
    (winding kept) to start at its lexicographically smallest vertex, then triangles sorted."""
    F = len(tri)
    if F == 0:
        return tri
    key = np.round(tri * 1e6).astype(np.int64)  # micrometres
    flat = key.reshape(-1, 3)
    owner = np.repeat(np.arange(F), 3)
    order = np.lexsort((flat[:, 2], flat[:, 1], flat[:, 0], owner))
    first = order[0::3] - 3 * np.arange(F)  # index (0..2) of each triangle's smallest vertex
    idx = (first[:, None] + np.arange(3)[None, :]) % 3
    tri = np.take_along_axis(tri, idx[:, :, None], axis=1)
    key = np.take_along_axis(key, idx[:, :, None], axis=1).reshape(F, 9)
    perm = np.lexsort(key.T[::-1])
    return tri[perm]


def _runs(b: np.ndarray) -> list[tuple[int, int]]:
    """[start, end) of every run of True in a 1-D bool array."""
    b = np.asarray(b, bool)
    if b.size == 0:
        return []
    d = np.diff(np.concatenate(([0], b.astype(np.int8), [0])))
    return list(zip(np.flatnonzero(d == 1).tolist(), np.flatnonzero(d == -1).tolist()))


def _bridge(col: np.ndarray, gap: int) -> np.ndarray:
    """Fill runs of False of at most ``gap`` cells that lie between True cells."""
    col = col.copy()
    n = len(col)
    for a, b in _runs(~col):
        if a > 0 and b < n and b - a <= gap:
            col[a:b] = True
    return col


def rasterise(tri: np.ndarray, shape: tuple[int, int], max_pairs: int = 1_000_000) -> np.ndarray:
    """Cells (i, j) of a ``shape`` grid whose centre (i + 0.5, j + 0.5) lies in one of the triangles
    ``tri`` (M, 3, 2), given in cell units; plus the cell of every triangle's centroid (so that
    triangles smaller than a cell still count)."""
    W, H = shape
    mask = np.zeros((W, H), bool)
    if len(tri) == 0 or W <= 0 or H <= 0:
        return mask
    cen = np.floor(tri.mean(axis=1)).astype(np.int64)
    ok = (cen[:, 0] >= 0) & (cen[:, 0] < W) & (cen[:, 1] >= 0) & (cen[:, 1] < H)
    mask[cen[ok, 0], cen[ok, 1]] = True
    a, b, c = tri[:, 0], tri[:, 1], tri[:, 2]
    area2 = (b[:, 0] - a[:, 0]) * (c[:, 1] - a[:, 1]) - (b[:, 1] - a[:, 1]) * (c[:, 0] - a[:, 0])
    keep = np.abs(area2) > 1e-12
    tri, area2 = tri[keep], area2[keep]
    if len(tri) == 0:
        return mask
    lo = np.ceil(tri.min(axis=1) - 0.5)
    hi = np.floor(tri.max(axis=1) - 0.5)
    lo = np.maximum(lo, 0).astype(np.int64)
    hi = np.minimum(hi, [W - 1, H - 1]).astype(np.int64)
    nx = np.maximum(hi[:, 0] - lo[:, 0] + 1, 0)
    ny = np.maximum(hi[:, 1] - lo[:, 1] + 1, 0)
    cnt = nx * ny
    sgn = np.sign(area2)
    # edge vectors and their lengths (for an inclusive test with a relative tolerance)
    P = [tri[:, 0], tri[:, 1], tri[:, 2]]
    E = [P[1] - P[0], P[2] - P[1], P[0] - P[2]]
    tol = [1e-6 * np.hypot(e[:, 0], e[:, 1]) for e in E]
    cum = np.cumsum(cnt)
    start, M = 0, len(tri)
    while start < M:
        base = int(cum[start - 1]) if start else 0
        end = max(int(np.searchsorted(cum, base + max_pairs, side="right")), start + 1)
        sl = slice(start, end)
        c_ = cnt[sl]
        total = int(c_.sum())
        if total:
            ti = np.repeat(np.arange(start, end), c_)
            off = np.arange(total) - np.repeat(np.cumsum(c_) - c_, c_)
            ci = lo[ti, 0] + off % nx[ti]
            cj = lo[ti, 1] + off // nx[ti]
            px, py = ci + 0.5, cj + 0.5
            inside = np.ones(total, bool)
            for k in range(3):
                p0, e = P[k][ti], E[k][ti]
                w = (e[:, 0] * (py - p0[:, 1]) - e[:, 1] * (px - p0[:, 0])) * sgn[ti]
                inside &= w >= -tol[k][ti]
            mask[ci[inside], cj[inside]] = True
        start = end
    return mask


def _planes_1d(values: np.ndarray, weights: np.ndarray, gap: float) -> list[tuple[float, float, np.ndarray]]:
    """Group sorted 1-D values where consecutive ones are closer than ``gap``:
    (weighted mean, total weight, indices into ``values``) per group."""
    if len(values) == 0:
        return []
    order = np.argsort(values, kind="stable")
    v = values[order]
    cuts = np.flatnonzero(np.diff(v) > gap) + 1
    out = []
    for g in np.split(order, cuts):
        w = weights[g]
        tot = float(w.sum())
        mean = float((values[g] * w).sum() / tot) if tot > 0 else float(values[g].mean())
        out.append((mean, tot, g))
    return out


def _snap(edge: float, cand: np.ndarray, tol: float, pick: str) -> float:
    """``edge`` moved to the smallest (``pick='min'``) or largest candidate within ``tol``; else kept."""
    if cand.size == 0:
        return edge
    c = cand[np.abs(cand - edge) <= tol]
    if c.size == 0:
        return edge
    return float(c.min() if pick == "min" else c.max())


# --------------------------------------------------------------------------------------------
# internal records


@dataclass
class _Dir:
    psi: float  # line direction angle, (-pi/2, pi/2]
    t: np.ndarray  # unit along the line
    n: np.ndarray  # unit normal, left of t


@dataclass
class _Piece:
    dir: int
    side: int  # +1: faces +n of its direction, -1: faces -n
    offset: float  # plane offset along n
    i0: int  # global column index of mask[0]
    mask: np.ndarray  # (columns, rows) bool
    tris: np.ndarray  # triangle indices
    area: float
    tops: np.ndarray | None = None  # per column: the face's top row (cells above the floor, not clipped at the ceiling; -1: empty)

    @property
    def i1(self) -> int:
        return self.i0 + self.mask.shape[0]

    def merge(self, other: "_Piece") -> None:
        lo, hi = min(self.i0, other.i0), max(self.i1, other.i1)
        m = np.zeros((hi - lo, self.mask.shape[1]), bool)
        m[self.i0 - lo : self.i1 - lo] |= self.mask
        m[other.i0 - lo : other.i1 - lo] |= other.mask
        if self.tops is not None and other.tops is not None:
            t = np.full(hi - lo, -1, np.int64)
            t[self.i0 - lo : self.i1 - lo] = self.tops
            t[other.i0 - lo : other.i1 - lo] = np.maximum(t[other.i0 - lo : other.i1 - lo], other.tops)
            self.tops = t
        else:
            self.tops = None
        self.i0, self.mask = lo, m
        self.tris = np.union1d(self.tris, other.tris)
        self.area += other.area


@dataclass
class _WallRec:
    dir: int
    u0: float
    u1: float
    centre: float  # offset of the centre line along n
    thickness: float
    height: float
    source: str  # "paired faces" | "default"
    holes: list  # (kind, hu0, hu1, bottom, height)


# --------------------------------------------------------------------------------------------
# floor and ceiling


def _floor_ceiling(source, cen, n, area, zmin, zmax, report) -> tuple[float, float]:
    up = n[:, 2] > HORIZONTAL_NZ
    mid = (zmin + zmax) / 2.0
    planes = [(z, a) for z, a, _ in _planes_1d(cen[up, 2], area[up], PLANE_Z_GAP)]
    low = [p for p in planes if p[0] <= mid]
    cand = [p for p in low if p[1] >= MIN_FLOOR_AREA]
    report["floor"] = {"up_planes": len(planes)}
    if not cand:
        best = max(low, key=lambda p: p[1], default=None)
        found = f"largest there: {best[1]:.2f} m2 at z {best[0]:.2f}" if best else "none there"
        ang = math.degrees(math.acos(HORIZONTAL_NZ))
        fail(source, "stage", f"no floor found: looked for an up-facing horizontal plane (normal within {ang:.0f} deg of +Z) "
                      f"of at least {MIN_FLOOR_AREA:g} m2 in the lower half of the mesh (z {zmin:.2f} .. {mid:.2f}); {found}")
    fz, fa = max(cand, key=lambda p: (p[1], -p[0]))
    floor_z = quantize(fz)
    report["floor"].update({"z": floor_z, "area_m2": round(fa, 3)})
    down = n[:, 2] < -HORIZONTAL_NZ
    planes = [(z, a) for z, a, _ in _planes_1d(cen[down, 2], area[down], PLANE_Z_GAP)]
    cand = [p for p in planes if p[0] >= floor_z + MIN_CEILING_CLEARANCE and p[1] >= MIN_FLOOR_AREA]
    if cand:
        cz, ca = max(cand, key=lambda p: (p[1], -p[0]))
        report["ceiling"] = {"z": quantize(cz), "area_m2": round(ca, 3), "source": "plane", "down_planes": len(planes)}
    elif zmax - floor_z >= MIN_CEILING_CLEARANCE:
        cz = zmax
        report["ceiling"] = {"z": quantize(cz), "area_m2": 0.0, "source": "top of the mesh (no down-facing plane)",
                             "down_planes": len(planes)}
    else:
        fail(source, "stage", f"no ceiling found: the mesh ends {zmax - floor_z:.2f} m above the floor (z {floor_z:.2f}); "
                      f"looked for a down-facing plane at least {MIN_CEILING_CLEARANCE:g} m above it")
    return floor_z, quantize(cz)


# --------------------------------------------------------------------------------------------
# walls


def _directions(h: np.ndarray, area: np.ndarray) -> list[tuple[_Dir, np.ndarray]]:
    """Cluster horizontal unit normals ``h`` (K, 2) by line direction (normal folded by 180 deg)."""
    two = np.arctan2(2.0 * h[:, 0] * h[:, 1], h[:, 0] ** 2 - h[:, 1] ** 2)  # doubled normal angle
    nb = int(round(360.0 / (2 * DIR_BIN_DEG)))
    bins = (np.floor((two + math.pi) / (2 * math.pi) * nb).astype(np.int64)) % nb
    tol2 = math.radians(2 * DIR_TOL_DEG)
    remaining = np.ones(len(h), bool)
    out = []
    while remaining.any():
        w = np.bincount(bins[remaining], weights=area[remaining], minlength=nb)
        k = int(np.argmax(w))
        if w[k] < MIN_PLANE_AREA:
            break
        centre = -math.pi + (k + 0.5) * 2 * math.pi / nb
        for _ in range(2):  # re-centre on the weighted mean of the members
            diff = np.angle(np.exp(1j * (two - centre)))
            sel = remaining & (np.abs(diff) <= tol2)
            if not sel.any():
                break
            centre = centre + float((diff[sel] * area[sel]).sum() / area[sel].sum())
        diff = np.angle(np.exp(1j * (two - centre)))
        sel = remaining & (np.abs(diff) <= tol2)
        if not sel.any():  # cannot happen (the peak bin is within tolerance); guard the loop
            remaining[bins == k] = False
            continue
        remaining &= ~sel
        out.append((_direction(centre), np.flatnonzero(sel)))
    return out


def _direction(two_normal: float) -> _Dir:
    psi = (two_normal + math.pi) / 2.0  # line angle = normal angle + 90 deg
    psi = math.atan2(math.sin(psi), math.cos(psi))
    if psi <= -math.pi / 2:
        psi += math.pi
    elif psi > math.pi / 2:
        psi -= math.pi
    psi = round(psi, 9)
    if abs(psi) < 1e-7:
        psi, t = 0.0, np.array([1.0, 0.0])
    elif abs(psi - math.pi / 2) < 1e-7:
        psi, t = math.pi / 2, np.array([0.0, 1.0])
    else:
        t = np.array([math.cos(psi), math.sin(psi)])
    return _Dir(psi, t, np.array([-t[1], t[0]]))


def _pieces(dirs, tri, cen, n, area, vert_idx, floor_z, nrows, report, xrows: int | None = None) -> list[_Piece]:
    """Wall planes rasterised on (along, z) and cut at full-height gaps into pieces. ``xrows``: rows up
    to the top of the mesh (for the pieces' unclipped column tops; default ``nrows``)."""
    pieces: list[_Piece] = []
    found = small = 0
    gap = int(round(GAP_BRIDGE / WALL_CELL))
    for k, (d, members) in enumerate(dirs):
        idx = vert_idx[members]
        side = np.where(n[idx, :2] @ d.n >= 0, 1, -1)
        off = cen[idx, :2] @ d.n
        for s in (-1, 1):
            sel = idx[side == s]
            for mean, tot, g in _planes_1d(off[side == s], area[sel], OFFSET_GAP):
                found += 1
                if tot < MIN_PLANE_AREA:
                    small += 1
                    continue
                ti = sel[g]
                u = tri[ti, :, :2] @ d.t
                z = tri[ti, :, 2]
                i_lo = int(math.floor(float(u.min()) / WALL_CELL))
                i_hi = int(math.floor(float(u.max()) / WALL_CELL)) + 1
                W = i_hi - i_lo
                if W * nrows > MAX_GRID_CELLS:
                    small += 1  # absurdly long plane (an exterior ground skirt...): not a wall
                    continue
                grid = np.stack([u / WALL_CELL - i_lo, (z - floor_z) / WALL_CELL], axis=-1)
                full = rasterise(grid, (W, max(nrows, xrows or nrows)))
                mask = full[:, :nrows]
                anyf = full.any(axis=1)
                tops_all = np.where(anyf, full.shape[1] - 1 - np.argmax(full[:, ::-1], axis=1), -1)
                col = _bridge(mask.any(axis=1), gap)
                umin, umax = u.min(axis=1), u.max(axis=1)
                for a, b in _runs(col):
                    pm = mask[a:b]
                    lo_u, hi_u = (i_lo + a) * WALL_CELL, (i_lo + b) * WALL_CELL
                    pt = ti[(umax > lo_u - WALL_CELL) & (umin < hi_u + WALL_CELL)]
                    pieces.append(_Piece(k, s, mean, i_lo + a, pm.copy(), pt, float(pm.sum()) * WALL_CELL**2,
                                         tops_all[a:b].copy()))
    report["planes"] = {"found": found, "below_min_area": small}
    return pieces


def _absorb(pieces: list[_Piece], report) -> list[_Piece]:
    """Merge small same-facing pieces a few cm in front of / behind a larger one into it."""
    kept: list[_Piece] = []
    absorbed = 0
    for p in sorted(pieces, key=lambda p: (p.dir, p.side, -p.area, p.offset, p.i0)):
        w = p.mask.shape[0]
        for q in kept:
            if q.dir != p.dir or q.side != p.side or abs(q.offset - p.offset) > TRIM_DEPTH:
                continue
            ov = min(q.i1, p.i1) - max(q.i0, p.i0)
            if ov >= 0.5 * w:
                q.merge(p)
                absorbed += 1
                break
        else:
            kept.append(p)
    report["pieces"] = {"found": len(pieces), "merged_trim": absorbed}
    return kept


def _raised(tri, cen, n, area, floor_z) -> tuple[np.ndarray | None, np.ndarray, float]:
    """The highest raised level at every XY cell: up-facing planes above the floor (steps, landings,
    upper levels, the tops of low walls) with something down-facing at least ``MIN_COVER_Z`` above
    them (a ceiling over them: the top of the ceiling slab or of the roof is not a level).
    (max z per cell, -inf where none; grid origin; cell), or (None, ...) without any."""
    cell = RAISED_CELL
    up = np.flatnonzero((n[:, 2] > HORIZONTAL_NZ) & (cen[:, 2] > floor_z + RAISED_MIN))
    if up.size == 0:
        return None, np.zeros(2), cell
    down = np.flatnonzero(n[:, 2] < -HORIZONTAL_NZ)
    xy = tri[np.concatenate([up, down])][:, :, :2].reshape(-1, 2)
    lo = np.floor((xy.min(axis=0) - 1.0) / cell) * cell
    hi = xy.max(axis=0) + 1.0
    while np.prod(np.ceil((hi - lo) / cell)) > MAX_GRID_CELLS / 16:
        cell *= 2
    shape = tuple(int(v) for v in np.ceil((hi - lo) / cell))

    def highest(idx, min_area):
        out = np.full(shape, -np.inf)
        for z, a, g in _planes_1d(cen[idx, 2], area[idx], PLANE_Z_GAP):
            if a >= min_area:
                m = rasterise((tri[idx[g]][:, :, :2] - lo) / cell, shape)
                out[m] = np.maximum(out[m], z)
        return out

    top_down = highest(down, 0.0)
    best = np.full(shape, -np.inf)
    for z, a, g in _planes_1d(cen[up, 2], area[up], PLANE_Z_GAP):
        if a < RAISED_MIN_AREA:
            continue
        m = rasterise((tri[up[g]][:, :, :2] - lo) / cell, shape) & (top_down >= z + MIN_COVER_Z)
        best[m] = np.maximum(best[m], z)
    return best, lo, cell


def _drop_platform_sides(pieces: list[_Piece], dirs, raised, floor_z, ceil_z, tri, report) -> list[_Piece]:
    """Stairs and raised levels are not walls: the columns of a piece whose top lies below the ceiling
    and that have behind the face, farther in than the thickest wall (``PAIR_MAX``), a raised level
    (``_raised``) at the column's height or higher -- or one at any height while the column's own
    height continues just behind the face (the top step of a flight going down behind it) -- are the
    side of a step, a flight or a landing and are cut out; what is left of the piece stays (a wall
    beside the stairs, the part of a face that reaches the ceiling). A half-height wall stays: its
    top is narrower than ``PAIR_MAX`` and the floor lies beyond it."""
    best, lo, cell = raised
    if best is None:
        report["pieces"]["platform_columns"] = 0
        return pieces
    shape = best.shape
    out, dropped = [], 0
    for p in pieces:
        d = dirs[p.dir][0]
        ncol = p.mask.shape[0]
        tops = p.tops if p.tops is not None else _col_spans(p.mask) - 1
        top_z = floor_z + (tops + 1) * WALL_CELL
        cand = (tops >= 0) & (top_z < ceil_z - CEILING_TOL)
        plat = np.zeros(ncol, bool)
        if cand.any():
            ci = np.flatnonzero(cand)
            u = (p.i0 + ci + 0.5) * WALL_CELL

            def probe(depth):
                q = u[:, None] * d.t[None, :] + (p.offset - p.side * depth) * d.n[None, :]
                ij = np.floor((q - lo) / cell).astype(np.int64)
                ok = (ij[:, 0] >= 0) & (ij[:, 0] < shape[0]) & (ij[:, 1] >= 0) & (ij[:, 1] < shape[1])
                h = np.full(len(ci), -np.inf)
                h[ok] = best[ij[ok, 0], ij[ok, 1]]
                return h

            want = top_z[ci] - PLATFORM_TOL
            far = np.max([probe(x) for x in PLATFORM_DEPTH], axis=0)
            near = np.max([probe(x) for x in PLATFORM_NEAR], axis=0)
            plat[ci[(far >= want) | ((near >= want) & np.isfinite(far))]] = True
        if not plat.any():
            out.append(p)
            continue
        dropped += int(plat.sum())
        keep = ~plat & p.mask.any(axis=1)
        for a, b in _runs(keep):
            pm = p.mask[a:b]
            lo_u, hi_u = (p.i0 + a) * WALL_CELL, (p.i0 + b) * WALL_CELL
            uu = tri[p.tris, :, :2] @ d.t
            pt = p.tris[(uu.max(axis=1) > lo_u - WALL_CELL) & (uu.min(axis=1) < hi_u + WALL_CELL)]
            out.append(_Piece(p.dir, p.side, p.offset, p.i0 + a, pm.copy(), pt, float(pm.sum()) * WALL_CELL**2,
                              None if p.tops is None else p.tops[a:b].copy()))
    report["pieces"]["platform_columns"] = dropped
    return out


def _col_spans(mask: np.ndarray) -> np.ndarray:
    """Per column, the height (in cells) from its lowest to its highest covered cell (0 if empty)."""
    anyc = mask.any(axis=1)
    first = np.argmax(mask, axis=1)
    last = mask.shape[1] - 1 - np.argmax(mask[:, ::-1], axis=1)
    return np.where(anyc, last - first + 1, 0)


def _piece_ok(p: _Piece) -> str | None:
    """Why a piece cannot be (a face of) a wall, or None. A wall is at least MIN_WALL_LENGTH long and
    stands at least MIN_WALL_HEIGHT high over at least MIN_WALL_LENGTH of it (so a low strip joined
    to a few tall slivers -- skirting between end caps -- is not one)."""
    if p.mask.shape[0] * WALL_CELL < MIN_WALL_LENGTH - 1e-9:
        return "shorter than %.1f m" % MIN_WALL_LENGTH
    tall = (_col_spans(p.mask) * WALL_CELL >= MIN_WALL_HEIGHT - 1e-9).sum()
    if tall * WALL_CELL < MIN_WALL_LENGTH - 1e-9:
        return "lower than %.1f m" % MIN_WALL_HEIGHT
    return None


def _pair_groups(pieces: list[_Piece], report) -> list[list[int]]:
    """Union of pieces that are the two faces of one wall (edges: nearest partner of each piece)."""
    parent = list(range(len(pieces)))

    def find(i):
        while parent[i] != i:
            parent[i] = parent[parent[i]]
            i = parent[i]
        return i

    min_ov = int(round(MIN_WALL_LENGTH / WALL_CELL))
    min_rows = int(round(0.5 / WALL_CELL))
    rows = [np.flatnonzero(p.mask.any(axis=0)) for p in pieces]
    edges = []
    for i, m in enumerate(pieces):
        if m.side != -1:
            continue
        for j, p in enumerate(pieces):
            if p.side != 1 or p.dir != m.dir:
                continue
            dist = p.offset - m.offset
            if not PAIR_MIN <= dist <= PAIR_MAX:
                continue
            if min(m.i1, p.i1) - max(m.i0, p.i0) < min_ov:
                continue
            zov = min(rows[i][-1], rows[j][-1]) - max(rows[i][0], rows[j][0]) + 1
            if zov < min_rows:
                continue
            edges.append((i, j, dist))
    best: dict[int, float] = {}
    for i, j, dist in edges:
        best[i] = min(best.get(i, math.inf), dist)
        best[j] = min(best.get(j, math.inf), dist)
    kept = 0
    for i, j, dist in edges:
        if dist <= best[i] + 0.01 or dist <= best[j] + 0.01:
            kept += 1
            ri, rj = find(i), find(j)
            if ri != rj:
                parent[max(ri, rj)] = min(ri, rj)
    groups: dict[int, list[int]] = {}
    for i in range(len(pieces)):
        groups.setdefault(find(i), []).append(i)
    report["pairs"] = kept
    return [groups[r] for r in sorted(groups)]


def _walls(dirs, pieces, groups, tri, floor_z, ceil_z, nrows, report) -> list[_WallRec]:
    walls: list[_WallRec] = []
    rejected: dict[str, int] = {}
    holes_rejected: dict[str, int] = {}
    gap = int(round(GAP_BRIDGE / WALL_CELL))

    def reject(why):
        rejected[why] = rejected.get(why, 0) + 1

    # slabs of the paired walls: a face without a partner that lies in one of them (the hidden back
    # of a skirting board or of an architrave, end caps) is inside a wall, not a wall
    slabs = []
    for g in groups:
        mem = [pieces[i] for i in g]
        if {p.side for p in mem} == {-1, 1}:
            a = max((p for p in mem if p.side == -1), key=lambda p: (p.area, -p.offset)).offset
            b = max((p for p in mem if p.side == 1), key=lambda p: (p.area, -p.offset)).offset
            lo = min(p.i0 for p in mem)
            cov = {}
            for s in (-1, 1):
                c = np.zeros(max(p.i1 for p in mem) - lo, bool)
                for p in mem:
                    if p.side == s:
                        c[p.i0 - lo : p.i1 - lo] |= p.mask.any(axis=1)
                cov[s] = c
            slabs.append((mem[0].dir, a, b, lo, cov[-1] & cov[1]))
    inside = 0
    kept_groups = []
    for g in groups:
        mem = [pieces[i] for i in g]
        if len({p.side for p in mem}) == 1:
            p = max(mem, key=lambda p: (p.area, -p.offset))
            pc = np.zeros(max(q.i1 for q in mem) - min(q.i0 for q in mem), bool)
            plo = min(q.i0 for q in mem)
            for q in mem:
                pc[q.i0 - plo : q.i1 - plo] |= q.mask.any(axis=1)
            hidden = False
            for k, a, b, lo, both in slabs:
                if k != p.dir or not a - 0.01 <= p.offset <= b + 0.01:
                    continue
                x0, x1 = max(plo, lo), min(plo + len(pc), lo + len(both))
                if x1 > x0 and (pc[x0 - plo : x1 - plo] & both[x0 - lo : x1 - lo]).sum() >= 0.5 * pc.sum():
                    hidden = True
                    break
            if hidden:
                inside += 1
                continue
        kept_groups.append(g)
    report["faces_inside_walls"] = inside

    for g in kept_groups:
        mem = [pieces[i] for i in g]
        d = dirs[mem[0].dir][0]
        lo = min(p.i0 for p in mem)
        hi = max(p.i1 for p in mem)
        side_mask, side_ext, side_off = {}, {}, {}
        for s in (-1, 1):
            ps = [p for p in mem if p.side == s]
            if not ps:
                continue
            m = np.zeros((hi - lo, nrows), bool)
            for p in ps:
                m[p.i0 - lo : p.i1 - lo] |= p.mask
            side_mask[s] = m
            ti = np.unique(np.concatenate([p.tris for p in ps]))
            u = tri[ti, :, :2] @ d.t
            z = tri[ti, :, 2]
            side_ext[s] = np.stack([u.min(axis=1), u.max(axis=1), z.min(axis=1), z.max(axis=1)], axis=1)
            side_off[s] = max(ps, key=lambda p: (p.area, -p.offset)).offset
        cols = {s: m.any(axis=1) for s, m in side_mask.items()}
        jobs = []  # (columns, sides used, centre, thickness, source)
        if len(side_mask) == 2:
            a, b = side_off[-1], side_off[1]
            both = _bridge(cols[-1] & cols[1], gap)
            jobs.append((both, (-1, 1), (a + b) / 2.0, b - a, "paired faces"))
            for s in (-1, 1):
                left = _bridge(cols[s] & ~both, gap) & ~both
                jobs.append((left, (s,), side_off[s] - s * DEFAULT_THICKNESS / 2.0, DEFAULT_THICKNESS, "default"))
        else:
            (s,) = side_mask
            jobs.append((_bridge(cols[s], gap), (s,), side_off[s] - s * DEFAULT_THICKNESS / 2.0, DEFAULT_THICKNESS, "default"))
        for colmask, sides, centre, thick, src in jobs:
            for a, b in _runs(colmask):
                mask = np.zeros((b - a, nrows), bool)
                for s in sides:
                    mask |= side_mask[s][a:b]
                rec = _wall_segment(d, lo + a, lo + b, mask, sides, cols, side_ext, a, b, centre, thick, src,
                                    floor_z, ceil_z, reject, holes_rejected)
                if rec is not None:
                    rec.dir = mem[0].dir
                    walls.append(rec)
    report["walls_rejected"] = rejected
    report["holes_rejected"] = holes_rejected
    return walls


def _wall_segment(d, g0, g1, mask, sides, cols, side_ext, a, b, centre, thick, src, floor_z, ceil_z,
                  reject, holes_rejected) -> _WallRec | None:
    """One wall from the columns [g0, g1) of a group: ends, top and holes from the grid, then each
    edge snapped to the extent of the triangles that make it (within one cell)."""
    cell = WALL_CELL
    rows = np.flatnonzero(mask.any(axis=0))
    if rows.size == 0:
        return None
    if rows[0] * cell > MAX_WALL_BOTTOM:
        reject("does not reach the floor")
        return None
    ext = np.concatenate([side_ext[s] for s in sides])  # (T, 4): umin, umax, zmin, zmax per triangle
    top_row = int(rows[-1])
    top = min(floor_z + (top_row + 1) * cell, ceil_z)
    top = min(_snap(top, ext[:, 3], cell, "max"), ceil_z)
    height = top - floor_z
    if height < MIN_WALL_HEIGHT - 1e-9:
        reject("lower than %.1f m" % MIN_WALL_HEIGHT)
        return None

    # ends: snapped to the triangles of the face(s) that end there
    def end_ext(at_start: bool):
        out = []
        for s in sides:
            c = cols[s]
            if at_start and (a == 0 or not c[a - 1]):
                out.append(side_ext[s])
            if not at_start and (b == len(c) or not c[b]):
                out.append(side_ext[s])
        return np.concatenate(out) if out else ext

    u0 = _snap(g0 * cell, end_ext(True)[:, 0], cell, "min")
    u1 = _snap(g1 * cell, end_ext(False)[:, 1], cell, "max")
    if u1 - u0 < MIN_WALL_LENGTH - 1e-9:
        reject("shorter than %.1f m" % MIN_WALL_LENGTH)
        return None

    holes = []
    empty = ~mask[:, : top_row + 1]
    k = max(1, int(round(MIN_HOLE / cell)))
    empty = ndimage.binary_opening(empty, structure=np.ones((k, k), bool))
    lab, _ = ndimage.label(empty)
    for sl_ in ndimage.find_objects(lab):
        if sl_ is None:
            continue
        ci0, ci1 = sl_[0].start, sl_[0].stop
        rj0, rj1 = sl_[1].start, sl_[1].stop
        if rj1 > top_row:  # open to the top of the wall: a notch, not an opening
            holes_rejected["notch at the top"] = holes_rejected.get("notch at the top", 0) + 1
            continue
        z0r, z1r = floor_z + rj0 * cell, floor_z + rj1 * cell
        hu0r, hu1r = (g0 + ci0) * cell, (g0 + ci1) * cell
        # triangles beside the hole (overlapping its height) give its sides, those above/below its top/bottom
        inz = (ext[:, 3] > z0r + cell) & (ext[:, 2] < z1r - cell)
        inu = (ext[:, 1] > hu0r + cell) & (ext[:, 0] < hu1r - cell)
        hu0 = max(_snap(hu0r, ext[inz, 1], cell, "max"), u0)
        hu1 = min(_snap(hu1r, ext[inz, 0], cell, "min"), u1)
        z1 = _snap(z1r, ext[inu, 2], cell, "min")
        width = hu1 - hu0
        if rj0 * cell <= DOOR_FLOOR_TOL:
            h = z1 - floor_z
            if h >= MIN_DOOR_HEIGHT - 1e-9 and width >= MIN_DOOR_WIDTH - 1e-9:
                holes.append(("door", hu0, hu1, 0.0, h))
            else:
                why = "low or narrow hole at the floor"
                holes_rejected[why] = holes_rejected.get(why, 0) + 1
        else:
            z0 = _snap(z0r, ext[inu, 3], cell, "max")
            if width >= MIN_HOLE - 1e-9 and z1 - z0 >= MIN_HOLE - 1e-9:
                holes.append(("window", hu0, hu1, z0 - floor_z, z1 - z0))
            else:
                holes_rejected["small hole"] = holes_rejected.get("small hole", 0) + 1
    return _WallRec(-1, u0, u1, centre, thick, height, src, holes)


# --------------------------------------------------------------------------------------------
# rooms


def _trace(mask: np.ndarray) -> list[np.ndarray]:
    """Boundary loops of the set cells of a 2-D bool grid, in cell-corner coordinates (i, j): outer
    boundaries counter-clockwise, holes clockwise (interior on the left); at a corner where two cells
    touch only diagonally the loops turn left, so such cells give separate loops. Collinear corners
    are dropped."""
    m = np.pad(np.asarray(mask, bool), 1)
    nxt: dict[tuple[int, int], list[tuple[int, int]]] = {}

    def add(a, b):
        nxt.setdefault(a, []).append(b)

    I, J = np.nonzero(m[1:-1, 1:-1])
    for i, j in zip(I.tolist(), J.tolist()):
        pi, pj = i + 1, j + 1
        if not m[pi, pj - 1]:
            add((i, j), (i + 1, j))
        if not m[pi + 1, pj]:
            add((i + 1, j), (i + 1, j + 1))
        if not m[pi, pj + 1]:
            add((i + 1, j + 1), (i, j + 1))
        if not m[pi - 1, pj]:
            add((i, j + 1), (i, j))
    loops = []
    while nxt:
        start = next(iter(nxt))
        loop, cur, prev = [start], start, None
        while True:
            outs = nxt[cur]
            if len(outs) == 1:
                b = outs.pop()
            else:  # a diagonal pinch: turn left of the incoming direction
                din = (cur[0] - prev[0], cur[1] - prev[1])
                left = (-din[1], din[0])
                b = next((o for o in outs if (o[0] - cur[0], o[1] - cur[1]) == left), outs[0])
                outs.remove(b)
            if not outs:
                del nxt[cur]
            prev, cur = cur, b
            if cur == start:
                break
            loop.append(cur)
        q = np.asarray(loop, float)
        keep = np.ones(len(q), bool)
        for k in range(len(q)):
            a, b, c = q[k - 1], q[k], q[(k + 1) % len(q)]
            if (b[0] - a[0]) * (c[1] - b[1]) - (b[1] - a[1]) * (c[0] - b[0]) == 0:
                keep[k] = False
        loops.append(q[keep])
    return loops


def _signed_area(q: np.ndarray) -> float:
    return 0.5 * float(np.dot(q[:, 0], np.roll(q[:, 1], -1)) - np.dot(q[:, 1], np.roll(q[:, 0], -1)))


def _simplify(q: np.ndarray, eps: float) -> np.ndarray:
    """Douglas-Peucker on a closed ring (split at the vertex farthest from the first), keeping corners
    more than ``eps`` off the simplified line; a ring that would fall under 3 vertices is kept."""
    n = len(q)
    if n <= 4:
        return q
    far = int(np.argmax(np.hypot(*(q - q[0]).T)))

    def dp(pts):
        if len(pts) < 3:
            return [0, len(pts) - 1]
        a, b = pts[0], pts[-1]
        ab = b - a
        L = float(np.hypot(*ab))
        if L < 1e-12:
            d = np.hypot(*(pts - a).T)
        else:
            d = np.abs(ab[0] * (pts[:, 1] - a[1]) - ab[1] * (pts[:, 0] - a[0])) / L
        k = int(np.argmax(d[1:-1])) + 1
        if d[k] <= eps:
            return [0, len(pts) - 1]
        left = dp(pts[: k + 1])
        right = dp(pts[k:])
        return left[:-1] + [k + r for r in right]

    ring = np.concatenate([q, q[:1]])
    i1 = dp(ring[: far + 1])
    i2 = dp(ring[far:])
    idx = i1[:-1] + [far + r for r in i2][:-1]
    out = q[idx]
    return out if len(out) >= 3 else q


def _room_polygon(mine: np.ndarray, origin: np.ndarray, cell: float, rect, eps: float = POLY_EPS) -> tuple[tuple, float, float]:
    """The free floor of one room (``mine``: its cells, grid origin at ``origin``) as one simple
    counter-clockwise polygon in world XY, simplified to ``POLY_EPS`` cells and clipped to ``rect``:
    (polygon, area of the holes filled, area of the pieces left off) -- the polygon is the largest
    outer boundary; holes in it (a pillar, an island of stairs) are filled, other pieces touching it
    only at a corner are left off."""
    loops = _trace(mine)
    outer = [q for q in loops if _signed_area(q) > 0]
    holes = [q for q in loops if _signed_area(q) < 0]
    outer.sort(key=lambda q: -_signed_area(q))
    main = outer[0]
    q = _simplify(main, eps) if eps > 0 else main
    if _signed_area(q) <= 0:
        q = main
    w = origin + q * cell
    x0, y0, x1, y1 = rect
    w[:, 0] = np.clip(w[:, 0], x0, x1)
    w[:, 1] = np.clip(w[:, 1], y0, y1)
    filled = -sum(_signed_area(h) for h in holes) * cell * cell
    left = sum(_signed_area(o) for o in outer[1:]) * cell * cell
    return tuple((float(a), float(b)) for a, b in w), filled, left


def _split_at_doorways(mine: np.ndarray, cell: float) -> np.ndarray | None:
    """Labels 1..k of the rooms one connected piece of free floor (``mine``, bool) holds, or None if
    it is one room. A room is a space with at least ``MIN_ROOM_CORE`` of floor farther than
    ``DOORWAY_MAX`` / 2 from its edges (its core); the cores are grown over the rest of the floor
    widest cells first (a watershed on the distance to the edges), so two rooms meet where the floor
    between them is narrowest: in the doorway. A meeting line that runs across an axis-aligned
    doorway is then made straight (one grid line), so the two rooms' outlines share that edge
    exactly and the path planner sees it open (``synth.paths.clearance``). A corridor narrower than
    a doorway everywhere has no core and joins the rooms it leads to."""
    import heapq

    d2 = np.rint(ndimage.distance_transform_edt(mine) ** 2).astype(np.int64)  # squared cells: exact
    half = DOORWAY_MAX / 2.0 / cell
    seeds, ns = ndimage.label(d2 > half * half)
    if ns < 2:
        return None
    sizes = np.bincount(seeds.ravel(), minlength=ns + 1)
    keep = np.flatnonzero(sizes * cell * cell >= MIN_ROOM_CORE)
    keep = keep[keep > 0]
    if len(keep) < 2:
        return None
    lab = np.zeros(mine.shape, np.int32)
    for k, s in enumerate(keep, start=1):
        lab[seeds == s] = k
    W, H = mine.shape
    heap = []
    steps = ((-1, 0), (1, 0), (0, -1), (0, 1))

    def push_around(i, j):
        for di, dj in steps:
            a, b = i + di, j + dj
            if 0 <= a < W and 0 <= b < H and mine[a, b] and lab[a, b] == 0:
                heapq.heappush(heap, (-int(d2[a, b]), a, b))

    for i, j in zip(*np.nonzero(lab)):
        push_around(int(i), int(j))
    while heap:
        _, i, j = heapq.heappop(heap)
        if lab[i, j]:
            continue
        nb = [lab[i + di, j + dj] for di, dj in steps if 0 <= i + di < W and 0 <= j + dj < H and lab[i + di, j + dj]]
        lab[i, j] = min(nb)
        push_around(i, j)
    # straighten each meeting line that crosses an axis-aligned doorway
    k = len(keep)
    for a in range(1, k + 1):
        for b in range(a + 1, k + 1):
            for axis in (0, 1):
                sl_lo = [slice(None), slice(None)]
                sl_hi = [slice(None), slice(None)]
                sl_lo[axis], sl_hi[axis] = slice(None, -1), slice(1, None)
                lo_, hi_ = lab[tuple(sl_lo)], lab[tuple(sl_hi)]
                e = ((lo_ == a) & (hi_ == b)) | ((lo_ == b) & (hi_ == a))
                if not e.any():
                    continue
                ii, jj = np.nonzero(e)
                along, across = (jj, ii) if axis == 0 else (ii, jj)  # edges between cells c and c+1 on `axis`
                if across.max() - across.min() > max(2, int(0.3 / cell)):
                    continue  # not a thin line across one doorway: left as grown
                line = int(np.median(across)) + 1  # cells < line on one side
                span = int(across.max() - across.min()) + 2
                r0, r1 = max(line - span, 0), min(line + span, mine.shape[axis])
                c0, c1 = int(along.min()), int(along.max()) + 1
                win = [slice(None), slice(None)]
                win[axis], win[1 - axis] = slice(r0, r1), slice(c0, c1)
                sub = lab[tuple(win)]
                pos = np.indices(sub.shape)[axis] + r0
                ab = (sub == a) | (sub == b)
                low_is_a = pos[sub == a].mean() < pos[sub == b].mean()
                low, high = (a, b) if low_is_a else (b, a)
                sub[ab & (pos < line)] = low
                sub[ab & (pos >= line)] = high
    return lab


def _rooms(tri, cen, n, floor_z, walls: list[Wall], need_cover: bool, report):
    """(rooms, label grid, grid origin, cell, label -> room index). ``need_cover``: a room must have
    something above it (false for a stage without a ceiling)."""
    corners = []
    for w in walls:
        dvec = w.direction
        nv = np.array([-dvec[1], dvec[0]]) * w.thickness / 2.0
        for p in (np.asarray(w.start), np.asarray(w.end)):
            corners += [p + nv, p - nv]
    corners = np.asarray(corners)
    lo = np.floor((corners.min(axis=0) - 0.2) / ROOM_CELL) * ROOM_CELL
    hi = corners.max(axis=0) + 0.2
    cell = ROOM_CELL
    while np.prod(np.ceil((hi - lo) / cell)) > MAX_GRID_CELLS:
        cell *= 2
    shape = tuple(int(v) for v in np.ceil((hi - lo) / cell))

    def grid(sel):
        return rasterise((tri[sel][:, :, :2] - lo) / cell, shape)

    floor = grid((n[:, 2] > HORIZONTAL_NZ) & (np.abs(cen[:, 2] - floor_z) <= FLOOR_TOL))
    cover = grid((n[:, 2] < -HORIZONTAL_NZ) & (cen[:, 2] >= floor_z + MIN_COVER_Z))
    foot = []
    for w in walls:
        dvec = w.direction
        nv = np.array([-dvec[1], dvec[0]]) * w.thickness / 2.0
        s, e = np.asarray(w.start), np.asarray(w.end)
        q = [s - nv, e - nv, e + nv, s + nv]
        foot += [[q[0], q[1], q[2]], [q[0], q[2], q[3]]]
    wallm = rasterise((np.asarray(foot) - lo) / cell, shape) if foot else np.zeros(shape, bool)
    free_raw = floor & ~wallm
    k = max(1, int(round(ROOM_OPEN / cell)))
    sq = np.ones((k, k), bool)
    free = ndimage.binary_opening(free_raw, structure=sq)
    lab, nlab = ndimage.label(free)

    # candidate snap lines: faces of axis-aligned walls
    xs, ys = [], []
    for w in walls:
        if w.start[0] == w.end[0]:
            xs += [w.start[0] - w.thickness / 2, w.start[0] + w.thickness / 2]
        elif w.start[1] == w.end[1]:
            ys += [w.start[1] - w.thickness / 2, w.start[1] + w.thickness / 2]
    xs, ys = np.asarray(xs, float), np.asarray(ys, float)

    def snap(v, cand):
        if cand.size == 0:
            return v
        j = int(np.argmin(np.abs(cand - v)))
        return float(cand[j]) if abs(cand[j] - v) <= 1.5 * cell else v

    found = []
    holes_filled, pieces_left = [0.0], [0.0]
    rejected: dict[str, int] = {}
    next_label, split_pieces = [nlab + 1], [0]
    counts = np.bincount(lab.ravel(), minlength=nlab + 1)
    covered = np.bincount(lab.ravel(), weights=cover.ravel().astype(float), minlength=nlab + 1)
    for li, sl_ in enumerate(ndimage.find_objects(lab), start=1):
        if sl_ is None:
            continue
        if counts[li] * cell * cell < MIN_ROOM_AREA:
            rejected["smaller than 1 m2"] = rejected.get("smaller than 1 m2", 0) + 1
            continue
        if need_cover and covered[li] / counts[li] < MIN_COVER_FRACTION:
            rejected["no ceiling above"] = rejected.get("no ceiling above", 0) + 1
            continue
        # the opening (which keeps slivers from joining rooms) also blunts corners that are not
        # axis-aligned: give the component back the free cells within the opening's reach
        i0, j0 = max(sl_[0].start - k, 0), max(sl_[1].start - k, 0)
        win = (slice(i0, sl_[0].stop + k), slice(j0, sl_[1].stop + k))
        whole = ndimage.binary_dilation(lab[win] == li, structure=sq) & free_raw[win]
        parts = _split_at_doorways(whole, cell)
        if parts is None:
            pieces = [(li, whole)]
        else:  # rooms meeting in doorways: new labels on the grid the door probes read
            pieces = []
            for pk in range(1, int(parts.max()) + 1):
                lid = li if pk == 1 else next_label[0]
                next_label[0] += pk != 1
                lw = lab[win]
                lw[(lw == li) & (parts == pk)] = lid
                pieces.append((lid, parts == pk))
            split_pieces[0] += len(pieces)
        for lid, mine in pieces:
            ii, jj = np.nonzero(mine)
            cells = int(mine.sum())
            area = cells * cell * cell
            x0 = snap(lo[0] + (i0 + ii.min()) * cell, xs)
            x1 = snap(lo[0] + (i0 + ii.max() + 1) * cell, xs)
            y0 = snap(lo[1] + (j0 + jj.min()) * cell, ys)
            y1 = snap(lo[1] + (j0 + jj.max() + 1) * cell, ys)
            fill = area / max((x1 - x0) * (y1 - y0), 1e-12)
            poly = None
            if fill < RECT_FILL or parts is not None:  # split rooms are polygons: their shared edges are open
                sub = np.zeros((ii.max() + 1, jj.max() + 1), bool)
                sub[ii, jj] = True
                poly, filled, left = _room_polygon(sub, lo + np.array([i0, j0]) * cell, cell, (x0, y0, x1, y1),
                                                   eps=POLY_EPS if parts is None else 0.0)
                holes_filled[0] += filled
                pieces_left[0] += left
            found.append((lid, (x0, y0, x1, y1), area, min(fill, 1.0), poly))
    found.sort(key=lambda r: (quantize(r[1][0], 3), quantize(r[1][1], 3), quantize(r[1][2], 3), quantize(r[1][3], 3)))
    rooms, fills, poly_fills, lab_to_room = [], {}, {}, {}
    for k_, (li, rect, area, fill, poly) in enumerate(found):
        name = f"room_{k_}"
        room = Room(name, "room", rect, poly)
        rooms.append(room)
        fills[name] = round(float(fill), 3)
        poly_fills[name] = round(float(min(area / max(room.area, 1e-12), 1.0)), 3)
        lab_to_room[li] = k_
        if poly_fills[name] < FILL_WARN:
            log.warning("stage structure: room %s: its floor fills %.0f%% of its outline", name, 100 * poly_fills[name])
    report["rooms"] = {"count": len(rooms), "rejected_components": rejected, "fill_ratio": fills,
                       "outline_fill_ratio": poly_fills,
                       "polygon_vertices": {r.name: 0 if r.polygon is None else len(r.polygon) for r in rooms},
                       "holes_filled_m2": round(holes_filled[0], 3), "split_at_doorways": split_pieces[0], "pieces_left_off_m2": round(pieces_left[0], 3),
                       "area_m2": {r.name: round(float(a), 3) for r, (_, _, a, _, _) in zip(rooms, found)}}
    return rooms, lab, lo, cell, lab_to_room


def _probe(lab, lo, cell, lab_to_room, p) -> int | None:
    r = int(math.ceil(PROBE_RADIUS / cell))
    ci, cj = int(math.floor((p[0] - lo[0]) / cell)), int(math.floor((p[1] - lo[1]) / cell))
    W, H = lab.shape
    votes: dict[int, int] = {}
    for di in range(-r, r + 1):
        for dj in range(-r, r + 1):
            if di * di + dj * dj > r * r:
                continue
            i, j = ci + di, cj + dj
            if 0 <= i < W and 0 <= j < H and lab[i, j] in lab_to_room:
                k = lab_to_room[int(lab[i, j])]
                votes[k] = votes.get(k, 0) + 1
    if not votes:
        return None
    return min(votes, key=lambda k: (-votes[k], k))


# --------------------------------------------------------------------------------------------
# public


def derive_structure(mesh: trimesh.Trimesh, source: str) -> StageStructure:
    """Floor, ceiling, walls, openings and rooms of a stage mesh (see the module docstring).

    ``mesh``: the stage's triangles already placed in the world, in our Z-up frame (face winding
    gives the outward normals). ``source``: the file named in errors. Raises ``SceneFormatError``
    (field ``stage``) when no floor or no wall is found. Rooms are axis-aligned rects: the bounding
    rectangles of the free floor pieces (for a stage not aligned with the world axes, of the
    rotated rooms)."""
    source = str(source)
    tri = np.asarray(mesh.triangles, dtype=np.float64).reshape(-1, 3, 3) if len(mesh.faces) else np.zeros((0, 3, 3))
    report: dict = {"triangles": int(len(tri))}
    tri = tri[np.isfinite(tri).all(axis=(1, 2))]
    tri = _canonical(tri)
    cr = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    dbl = np.linalg.norm(cr, axis=1)
    ok = dbl > 1e-12
    tri, cr, dbl = tri[ok], cr[ok], dbl[ok]
    report["degenerate_triangles"] = int((~ok).sum())
    n = cr / dbl[:, None] if len(tri) else np.zeros((0, 3))
    area = 0.5 * dbl
    cen = tri.mean(axis=1) if len(tri) else np.zeros((0, 3))
    if len(tri) == 0:
        fail(source, "stage", "no floor found: the mesh has no (non-degenerate) triangles")
    zmin, zmax = float(tri[:, :, 2].min()), float(tri[:, :, 2].max())

    floor_z, ceil_z = _floor_ceiling(source, cen, n, area, zmin, zmax, report)
    ceiling_height = quantize(ceil_z - floor_z)
    nrows = int(math.ceil((ceil_z - floor_z) / WALL_CELL - 1e-9))
    xrows = max(nrows, int(math.ceil((zmax - floor_z) / WALL_CELL - 1e-9)))

    # ---- walls
    vert = np.flatnonzero(np.abs(n[:, 2]) < VERTICAL_NZ)
    h = n[vert, :2]
    h = h / np.linalg.norm(h, axis=1)[:, None]
    dirs = _directions(h, area[vert])
    report["wall_directions"] = [round(math.degrees(d.psi), 3) for d, _ in dirs]
    pieces = _pieces(dirs, tri, cen, n, area, vert, floor_z, nrows, report, xrows)
    pieces = _absorb(pieces, report)
    pieces = _drop_platform_sides(pieces, dirs, _raised(tri, cen, n, area, floor_z), floor_z, ceil_z, tri, report)
    reasons: dict[str, int] = {}
    good = []
    for p in pieces:
        why = _piece_ok(p)
        if why:
            reasons[why] = reasons.get(why, 0) + 1
        else:
            good.append(p)
    report["pieces"]["rejected"] = reasons
    groups = _pair_groups(good, report)
    recs = _walls(dirs, good, groups, tri, floor_z, ceil_z, nrows, report)
    if not recs:
        fail(source, "stage", f"no walls found: looked for vertical faces (|n_z| < {VERTICAL_NZ:g}) at least {MIN_WALL_HEIGHT:g} m "
                      f"high and {MIN_WALL_LENGTH:g} m long between the floor (z {floor_z:.2f}) and the ceiling "
                      f"(z {ceil_z:.2f}); found {report['planes']['found']} vertical planes, none of that size")

    # ---- walls in the scene model, in order of position
    built = []
    for r in recs:
        d = dirs[r.dir][0]
        start = r.u0 * d.t + r.centre * d.n
        end = r.u1 * d.t + r.centre * d.n
        w = Wall("", (float(start[0]), float(start[1])), (float(end[0]), float(end[1])), r.thickness, r.height)
        built.append((w, r))
    built.sort(key=lambda wr: (wr[0].start, wr[0].end, wr[0].thickness, wr[0].height))
    walls = []
    for k, (w, r) in enumerate(built):
        w.id = f"W{k}"
        walls.append(w)

    # ---- rooms
    rooms, lab, lo, cell, lab_to_room = _rooms(tri, cen, n, floor_z, walls, report["ceiling"]["source"] == "plane", report)

    # ---- openings
    ops = []
    for k, (w, r) in enumerate(built):
        d = dirs[r.dir][0]
        for kind, hu0, hu1, bottom, height in r.holes:
            uc = (hu0 + hu1) / 2.0
            c = uc * d.t + r.centre * d.n
            found = []
            for s in (-1, 1):
                p = c + s * d.n * (r.thickness / 2.0 + PROBE)
                ri = _probe(lab, lo, cell, lab_to_room, p)
                if ri is not None and ri not in found:
                    found.append(ri)
            names = tuple(rooms[i].name for i in sorted(found))
            ops.append((kind, k, quantize(uc - r.u0), Opening("", kind, w.id, uc - r.u0, hu1 - hu0, bottom, height, names)))
    ops.sort(key=lambda o: (o[0] != "door", o[1], o[2]))
    openings, nd, nw = [], 0, 0
    for kind, _, _, op in ops:
        if kind == "door":
            op.id, nd = f"D{nd}", nd + 1
        else:
            op.id, nw = f"N{nw}", nw + 1
        openings.append(op)

    report["walls"] = {"count": len(walls), "paired": sum(r.source == "paired faces" for _, r in built),
                       "default": sum(r.source == "default" for _, r in built)}
    report["wall_thickness_source"] = {w.id: r.source for w, r in built}
    report["openings"] = {"doors": nd, "windows": nw}
    report["cells_m"] = {"wall": WALL_CELL, "room": cell}
    return StageStructure(floor_z=floor_z, ceiling_height=ceiling_height, walls=walls, openings=openings, rooms=rooms,
                          report=report)


def face_ids(stage: Stage, centroids: np.ndarray, normals: np.ndarray) -> np.ndarray:
    """Instance id of every triangle of a stage mesh, from its centroid and normal (world, Z up).

    Floor (``FLOOR_ID_BASE + k``): faces up (``n_z > 0.95``) within 5 cm of ``floor_z``; ceiling
    (``CEILING_ID_BASE + k``): faces down within 5 cm of ``floor_z + ceiling_height``; both go to
    the room whose outline holds the centroid (the first, in stage order), else to the nearest room
    rect. Wall (``WALL_ID_BASE + k``): the centroid lies within 3 cm of wall k's box but not more
    than 1 cm inside one of its openings (reveals, sills and lintels are wall; door frames and glass
    inside the opening are not), preferably on a face of the box whose outward normal matches the
    triangle's (within ~25 deg); triangles on no matching face come after those, and among equals
    the closest box, then the lowest index, wins. Everything else is 0 (frames inside openings or
    standing out more than 3 cm, slab edges, the outside of the shell). Pure numpy; the same inputs
    give the same ids, triangle by triangle.
    """
    c = np.asarray(centroids, dtype=np.float64).reshape(-1, 3)
    nv = np.asarray(normals, dtype=np.float64).reshape(-1, 3)
    norm = np.linalg.norm(nv, axis=1)
    nv = np.where(norm[:, None] > 0, nv / np.where(norm > 0, norm, 1.0)[:, None], 0.0)
    N = len(c)
    out = np.zeros(N, dtype=np.int64)
    if N == 0:
        return out
    fz = float(stage.floor_z)
    cz = fz + float(stage.ceiling_height)
    is_floor = (nv[:, 2] > HORIZONTAL_NZ) & (np.abs(c[:, 2] - fz) <= FLOOR_TOL)
    is_ceil = (nv[:, 2] < -HORIZONTAL_NZ) & (np.abs(c[:, 2] - cz) <= FLOOR_TOL)

    # walls
    best = np.full(N, np.inf)
    best_k = np.full(N, -1, dtype=np.int64)
    for k, w in enumerate(stage.walls):
        L, t, H = w.length, w.thickness, w.height
        if L <= 0:
            continue
        d = w.direction
        nw = np.array([-d[1], d[0]])
        rel = c[:, :2] - np.asarray(w.start)
        u = rel @ d
        v = rel @ nw
        z = c[:, 2] - fz
        half = np.array([L / 2.0, t / 2.0, H / 2.0])
        loc = np.stack([u - L / 2.0, v, z - H / 2.0], axis=1)  # relative to the box centre
        outside = np.maximum(np.abs(loc) - half, 0.0)
        d_out = np.linalg.norm(outside, axis=1)
        near = d_out <= FACE_TOL
        if not near.any():
            continue
        nloc = np.stack([nv[:, :2] @ d, nv[:, :2] @ nw, nv[:, 2]], axis=1)
        exact = np.full(N, np.inf)
        for ax in range(3):
            for sgn in (-1.0, 1.0):
                aligned = sgn * nloc[:, ax] > ALIGN_COS
                plane = np.abs(loc[:, ax] - sgn * half[ax])
                ok = aligned & (plane <= FACE_TOL)
                exact = np.where(ok, np.minimum(exact, plane), exact)
        score = np.where(np.isfinite(exact), exact + d_out, 1.0 + d_out)
        score = np.where(near, score, np.inf)
        for op in stage.openings:  # inside an opening (not on its reveals): frames, glass -- not wall
            if op.wall != w.id:
                continue
            hole = ((np.abs(u - op.offset) < op.width / 2.0 - HOLE_INSET) & (z > op.bottom + HOLE_INSET)
                    & (z < op.bottom + op.height - HOLE_INSET) & (np.abs(v) <= t / 2.0 + FACE_TOL))
            score = np.where(hole, np.inf, score)
        better = score < best
        best = np.where(better, score, best)
        best_k = np.where(better, k, best_k)
    wall_hit = best_k >= 0
    out[wall_hit] = WALL_ID_BASE + best_k[wall_hit]

    # floors and ceilings (before walls: a threshold in a door opening is floor)
    rooms = stage.rooms
    flat = is_floor | is_ceil
    if rooms and flat.any():
        rect = np.asarray([r.rect for r in rooms], dtype=np.float64)  # (R, 4)
        p = c[flat, :2]
        dx = np.maximum(np.maximum(rect[None, :, 0] - p[:, None, 0], p[:, None, 0] - rect[None, :, 2]), 0.0)
        dy = np.maximum(np.maximum(rect[None, :, 1] - p[:, None, 1], p[:, None, 1] - rect[None, :, 3]), 0.0)
        dist = np.hypot(dx, dy)
        for r_, room in enumerate(rooms):  # a polygon room holds only the part of its rect inside the polygon
            if room.polygon is not None:
                dist[:, r_] += np.where(room.contains(p), 0.0, 1e-3)
        k = np.argmin(dist, axis=1)  # inside -> 0 distance; the first such room in stage order
        base = np.where(is_floor[flat], FLOOR_ID_BASE, CEILING_ID_BASE)
        out[flat] = base + k
    elif flat.any():
        out[flat] = 0
    return out
