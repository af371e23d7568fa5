"""Walls, obstacles and exact clearance of a path in a layout; reports against its declared clearance.

``path_clearance`` measures (the clearance rule is in ``synth.paths``); ``clearance_report``,
``render_clearance_problem`` and ``replan_command`` serve ``synth path check`` and the refused
renders (``synth.tour.render``, ``synth.jobs.plan``). The free space is defined here once (``inside_free``,
``wall_segments``, ``wall_clearance``, ``room_index``: rooms by ``Room.outline`` / ``Room.contains``, so
polygon rooms and rect rooms alike); the planning grid (``synth.paths.space``) uses exactly these
functions and the footprints and distances defined here, so a planned path checks as planned.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from vrformats.errors import UserError
from vrformats.fields import is_number

from ..scene.model import Layout, Stage, object_box
from .model import BAND, CameraPath

__all__ = [
    "path_clearance", "path_clearance_detail", "clearance_report", "declared_clearance", "render_clearance_problem",
    "replan_command", "planned_on", "wall_segments", "inside_free", "wall_clearance", "room_index", "Boxes", "NEAREST_WALL", "NEAREST_OUTSIDE", "CLEARANCE_TOL",
]


# --------------------------------------------------------------------------------------------
# geometry: walls, obstacles, exact clearance


def _interior_doors(stage: Stage):
    return [op for op in stage.openings if op.kind == "door" and len(op.rooms) >= 2]


def _cut(lo: float, hi: float, cuts) -> list[tuple[float, float]]:
    """What is left of the interval [lo, hi] once the intervals ``cuts`` are taken out."""
    pieces = [(lo, hi)]
    for a, b in cuts:
        nxt = []
        for p, q in pieces:
            if b <= p or a >= q:
                nxt.append((p, q))
                continue
            if a > p:
                nxt.append((p, a))
            if b < q:
                nxt.append((b, q))
        pieces = nxt
    return [(p, q) for p, q in pieces if q - p >= 1e-6]


SHARED_EDGE_TOL = 0.01  # m: polygon edges of two rooms this close and parallel are one open boundary


def _polygon_edge_pieces(stage: Stage, k: int, doors, outlines) -> list[tuple[tuple, tuple]]:
    """Wall pieces of polygon room ``k``: its edges minus door gaps and minus the stretches it shares
    with another polygon room (an open plan split into rooms has no wall between them)."""
    q = outlines[k]
    out = []
    for i in range(len(q)):
        a, b = q[i], q[(i + 1) % len(q)]
        L = float(np.hypot(*(b - a)))
        if L < 1e-9:
            continue
        u = (b - a) / L
        cuts = []
        for op, w, c, d in doors:
            if abs(u[0] * d[1] - u[1] * d[0]) > 1e-3:  # wall not parallel to this edge
                continue
            rel = c - a
            if abs(u[0] * rel[1] - u[1] * rel[0]) > w.thickness / 2 + 0.05:
                continue
            t = float(rel @ u)
            cuts.append((t - op.width / 2, t + op.width / 2))
        for j, o in outlines.items():
            if j == k:
                continue
            for m in range(len(o)):
                e, f = o[m] - a, o[(m + 1) % len(o)] - a
                if max(abs(u[0] * e[1] - u[1] * e[0]), abs(u[0] * f[1] - u[1] * f[0])) > SHARED_EDGE_TOL:
                    continue
                te, tf = float(e @ u), float(f @ u)
                cuts.append((min(te, tf), max(te, tf)))
        for p, s in _cut(0.0, L, cuts):
            out.append((tuple(a + u * p), tuple(a + u * s)))
    return out


def _stage_wall_faces(stage: Stage) -> list[tuple[tuple, tuple]]:
    """The faces of the stage's own walls (``Stage.walls``: centre line +- thickness / 2, and the end
    caps), their long faces cut at interior doors. Used for stages derived from a mesh
    (``Stage.asset``), whose rooms need not follow the walls: a rect or a navmesh polygon can hold
    a wall stub, a free-standing wall or a window bay; procedural stages' rooms end at the wall faces."""
    out = []
    for w in stage.walls:
        L = w.length
        if L < 1e-9:
            continue
        d = w.direction
        n = np.array([-d[1], d[0]])
        a = np.asarray(w.start, float)
        h = w.thickness / 2
        cuts = [(op.offset - op.width / 2, op.offset + op.width / 2) for op in _interior_doors(stage) if op.wall == w.id]
        for side in (-1.0, 1.0):
            o = a + n * side * h
            for p, q in _cut(0.0, L, cuts):
                out.append((tuple(o + d * p), tuple(o + d * q)))
        for t in (0.0, L):
            e = a + d * t
            out.append((tuple(e - n * h), tuple(e + n * h)))
    return out


def wall_segments(stage: Stage) -> np.ndarray:
    """(K, 2, 2) wall segments: the edges of every room's free interior (``Room.outline``: its polygon,
    else its rect) minus interior door gaps, plus those doors' jambs. Edges two polygon rooms share
    are open (no wall). A stage from a mesh (``Stage.asset``) adds its walls' faces (``_stage_wall_faces``)."""
    doors = []
    for op in _interior_doors(stage):
        w = stage.wall(op.wall)
        c = op.center_xy(w)
        d = w.direction
        doors.append((op, w, c, d))
    outlines = {k: r.outline() for k, r in enumerate(stage.rooms) if r.polygon is not None}
    segs = []
    for k, r in enumerate(stage.rooms):
        if r.polygon is not None:
            segs += _polygon_edge_pieces(stage, k, doors, outlines)
            continue
        x0, y0, x1, y1 = r.rect
        edges = [(0, y0, x0, x1), (0, y1, x0, x1), (1, x0, y0, y1), (1, x1, y0, y1)]  # (along axis, fixed coord, lo, hi)
        for axis, fixed, lo, hi in edges:
            cuts = []
            for op, w, c, d in doors:
                if abs(d[1 - axis]) > 1e-6:  # wall not parallel to this edge
                    continue
                if abs(c[1 - axis] - fixed) > w.thickness / 2 + 0.05:
                    continue
                cuts.append((c[axis] - op.width / 2, c[axis] + op.width / 2))
            for p, q in _cut(lo, hi, cuts):
                if axis == 0:
                    segs.append(((p, fixed), (q, fixed)))
                else:
                    segs.append(((fixed, p), (fixed, q)))
    if stage.asset is not None:
        segs += _stage_wall_faces(stage)
    for op, w, c, d in doors:
        n = np.array([-d[1], d[0]])
        h = w.thickness / 2 + 0.01
        for s in (-1, 1):
            e = c + d * s * op.width / 2
            segs.append((tuple(e - n * h), tuple(e + n * h)))
    return np.asarray(segs, dtype=float).reshape(-1, 2, 2)


def inside_free(stage: Stage, pts: np.ndarray) -> np.ndarray:
    """Points in the free space: inside a room's free interior (``Room.contains``: its polygon, else
    its rect) or an interior door gap. The one inside test of planner and checker."""
    from matplotlib.path import Path as MplPath
    from ..scene.openings import opening_box

    pts = np.asarray(pts, float).reshape(-1, 2)
    inside = np.zeros(len(pts), bool)
    for r in stage.rooms:
        inside |= r.contains(pts)
    for op in _interior_doors(stage):
        gap = opening_box(stage, op, depth_extra=0.01)
        inside |= MplPath(gap.corners_2d()).contains_points(pts)
    return inside


def wall_clearance(stage: Stage, pts: np.ndarray, segs: np.ndarray | None = None) -> np.ndarray:
    """Distance of each point to the nearest wall (``wall_segments``), 0 outside the free space
    (``inside_free``): the part of the clearance that comes from the shell, the same for planner
    (``synth.paths.space``) and checker (``path_clearance``)."""
    pts = np.asarray(pts, float).reshape(-1, 2)
    d = seg_dist(pts, wall_segments(stage) if segs is None else segs)
    d[~inside_free(stage, pts)] = 0.0
    return d


def room_index(stage: Stage, pts: np.ndarray) -> np.ndarray:
    """Index of the (first) room whose free interior holds each point (``Room.contains``), -1 for none."""
    pts = np.asarray(pts, float).reshape(-1, 2)
    out = np.full(len(pts), -1, int)
    for k, r in enumerate(stage.rooms):
        m = r.contains(pts)
        out[m & (out < 0)] = k
    return out


def seg_dist(pts: np.ndarray, segs: np.ndarray) -> np.ndarray:
    """Min distance of each point to a set of segments."""
    out = np.full(len(pts), np.inf)
    for a, b in segs:
        ab = b - a
        L2 = float(ab @ ab)
        t = np.clip(((pts - a) @ ab) / L2, 0.0, 1.0) if L2 > 0 else np.zeros(len(pts))
        d = np.hypot(pts[:, 0] - a[0] - t * ab[0], pts[:, 1] - a[1] - t * ab[1])
        np.minimum(out, d, out=out)
    return out


@dataclass
class Boxes:
    """Object footprints as arrays: centre (K,2), half size (K,2), cos/sin yaw, z range."""

    c: np.ndarray
    h: np.ndarray
    cs: np.ndarray
    zmin: np.ndarray
    zmax: np.ndarray

    @staticmethod
    def of(boxes) -> "Boxes":
        boxes = list(boxes)
        if not boxes:
            z = np.zeros((0, 2))
            return Boxes(z, z, z, np.zeros(0), np.zeros(0))
        return Boxes(
            np.array([b.center[:2] for b in boxes], float),
            np.array([b.size[:2] for b in boxes], float) / 2.0,
            np.array([(math.cos(b.yaw), math.sin(b.yaw)) for b in boxes], float),
            np.array([b.zmin for b in boxes], float),
            np.array([b.zmax for b in boxes], float),
        )

    def __len__(self) -> int:
        return len(self.c)

    def dist(self, pts: np.ndarray, mask: np.ndarray | None = None, chunk: int = 4096) -> np.ndarray:
        """Min distance of each point to the footprints (``mask`` (N, K): which boxes count per point)."""
        return self.nearest(pts, mask, chunk)[0]

    def nearest(self, pts: np.ndarray, mask: np.ndarray | None = None, chunk: int = 4096) -> tuple[np.ndarray, np.ndarray]:
        """(min distance, index of the nearest footprint; -1 when none counts) of each point."""
        out = np.full(len(pts), np.inf)
        arg = np.full(len(pts), -1, dtype=np.int64)
        if len(self) == 0:
            return out, arg
        for s in range(0, len(pts), chunk):
            p = pts[s : s + chunk]
            dx = p[:, None, 0] - self.c[None, :, 0]
            dy = p[:, None, 1] - self.c[None, :, 1]
            lx = np.abs(dx * self.cs[None, :, 0] + dy * self.cs[None, :, 1]) - self.h[None, :, 0]
            ly = np.abs(-dx * self.cs[None, :, 1] + dy * self.cs[None, :, 0]) - self.h[None, :, 1]
            d = np.hypot(np.maximum(lx, 0.0), np.maximum(ly, 0.0))
            if mask is not None:
                d = np.where(mask[s : s + chunk], d, np.inf)
            k = d.argmin(axis=1)
            out[s : s + chunk] = d[np.arange(len(k)), k]
            arg[s : s + chunk] = np.where(np.isfinite(out[s : s + chunk]), k, -1)
        return out, arg


FLAT = 0.05  # m: an object whose top is at most this far above the floor (a rug, a mat) is walked over


def object_boxes(layout: Layout, obstacles: str):
    """The boxes that obstruct a camera: every object but ceiling-mounted ones (``all``; every
    object for ``band``), except flat ones on the floor (top <= floor + ``FLAT``: rugs, mats)."""
    if obstacles not in ("band", "all"):
        raise UserError(f"obstacles must be 'band' or 'all', got {obstacles!r}")
    top = layout.stage.floor_z + FLAT
    boxes = [object_box(o) for o in layout.objects if obstacles == "band" or o.support != "ceiling"]
    return [b for b in boxes if b.zmax > top]


def path_clearance(path: CameraPath, layout: Layout, obstacles: str = "all", band: float = BAND) -> np.ndarray:
    """Per-frame horizontal distance (m) from the camera centre to the nearest obstacle and wall.

    Obstacles: with ``"band"`` the footprints of the objects whose box overlaps the frame's height
    band ``[z - band, z + band]``; with ``"all"`` every object except ceiling-mounted ones. Walls:
    ``wall_segments``. 0 outside the free space (``inside_free``: every room and door gap).
    """
    return path_clearance_detail(path, layout, obstacles, band)[0]


NEAREST_WALL, NEAREST_OUTSIDE = 0, -1


def path_clearance_detail(path: CameraPath, layout: Layout, obstacles: str = "all",
                          band: float = BAND) -> tuple[np.ndarray, np.ndarray]:
    """``path_clearance`` and, per frame, what is nearest: an object id (> 0), ``NEAREST_WALL`` (0)
    or ``NEAREST_OUTSIDE`` (-1: the camera is outside every room and door gap)."""
    P = np.asarray(path.poses)[:, :3, 3]
    xy = P[:, :2]
    st = layout.stage
    inside = inside_free(st, xy)
    d = seg_dist(xy, wall_segments(st))
    boxes = object_boxes(layout, obstacles)
    bx = Boxes.of(boxes)
    mask = None
    if obstacles == "band" and len(bx):
        z = P[:, 2:3]
        mask = (bx.zmax[None, :] > z - band) & (bx.zmin[None, :] < z + band)
    db, k = bx.nearest(xy, mask)
    ids = np.array([b.id for b in boxes], dtype=np.int64)
    nearest = np.where((db < d) & (k >= 0), ids[np.maximum(k, 0)] if len(ids) else NEAREST_WALL, NEAREST_WALL)
    d = np.minimum(d, db)
    outside = ~inside
    d[outside] = 0.0
    nearest[outside] = NEAREST_OUTSIDE
    return d, nearest


# --------------------------------------------------------------------------------------------
# clearance against a path's declared clearance (synth path check; refused renders)

CLEARANCE_TOL = 1e-6  # m: paths are stored at 1 micrometre


def declared_clearance(path: CameraPath) -> float | None:
    """The clearance the path was planned with (``meta['planner']['clearance_m']``), or None."""
    v = (path.meta.get("planner") or {}).get("clearance_m")
    if not is_number(v):
        return None
    return float(v)


def clearance_report(path: CameraPath, layout: Layout, clearance: float | None = None, frames: int | None = None,
                     obstacles: str | None = None) -> dict:
    """Where ``path`` (its first ``frames`` frames) comes closer than ``clearance`` (default: the
    declared one) to an object or wall of ``layout``: frame ranges, their minimum, the objects.

    Obstacles follow the path's planner (``meta['planner']['obstacles']``, default ``all``)."""
    if clearance is None:
        clearance = declared_clearance(path)
        if clearance is None:
            raise UserError(f"camera path '{path.name}' declares no clearance (planner.clearance_m in its .yaml); "
                            "give --clearance")
    obstacles = obstacles or str((path.meta.get("planner") or {}).get("obstacles", "all"))
    sub = path if frames is None else CameraPath(path.name, np.asarray(path.poses)[:frames], path.fps, path.meta)
    d, nearest = path_clearance_detail(sub, layout, obstacles)
    classes = {o.id: o.cls for o in layout.objects}

    def what(n: int) -> dict:
        if n > 0:
            return {"id": int(n), "class": classes.get(int(n), "?")}
        return {"id": None, "class": "wall" if n == NEAREST_WALL else "outside every room"}

    below = d < clearance - CLEARANCE_TOL
    ranges = []
    idx = np.flatnonzero(below)
    if len(idx):
        splits = np.flatnonzero(np.diff(idx) > 1) + 1
        for run in np.split(idx, splits):
            k = int(run[np.argmin(d[run])])
            order = []
            for n in nearest[run[np.argsort(d[run], kind="stable")]]:
                if int(n) not in order:
                    order.append(int(n))
            ranges.append({"frames": [int(run[0]), int(run[-1])], "count": int(len(run)),
                           "min_clearance_m": round(float(d[k]), 4), "min_frame": k,
                           "objects": [what(n) for n in order]})
    k = int(np.argmin(d)) if len(d) else None
    return {
        "path": path.name, "layout": layout.name, "clearance_m": float(clearance), "obstacles": obstacles,
        "frames": int(len(d)), "min_clearance_m": round(float(d[k]), 4) if k is not None else None,
        "min_frame": k, "nearest": what(int(nearest[k])) if k is not None else None,
        "frames_below": int(below.sum()), "frames_outside": int((nearest == NEAREST_OUTSIDE).sum()),
        "ranges": ranges, "ok": not ranges,
    }


def describe_object(o: dict) -> str:
    return f"object {o['id']} ({o['class']})" if o["id"] is not None else o["class"]


def range_text(r: dict) -> str:
    a, b = r["frames"]
    objs = r["objects"]
    return (f"frames {a}-{b}" if a != b else f"frame {a}") + (
        f": min {r['min_clearance_m']:.3f} m at frame {r['min_frame']}, "
        + ", ".join(describe_object(o) for o in objs[:3]) + (f" and {len(objs) - 3} more" if len(objs) > 3 else ""))


def replan_command(path: CameraPath, layout_args: list[str]) -> str:
    """The ``synth path plan`` command that replans ``path`` for its layouts plus ``layout_args``."""
    m = path.meta
    pl = m.get("planner") or {}
    kind = m.get("kind")
    opts = ""
    if pl.get("clearance_m") is not None:
        opts += f" --clearance {float(pl['clearance_m']):g}"
    if pl.get("frames") is not None:
        opts += f" --frames {int(pl['frames'])}"
    if kind == "mapping":
        return f"synth path plan mapping --layout {layout_args[-1]}{opts} --out FILE.txt"
    names = [str(n) for n in (m.get("layouts") or [])]
    names += [a for a in layout_args if a not in names]
    return f"synth path plan query --layouts {' '.join(names)}{opts} --out FILE.txt"


def planned_on(path: CameraPath, layout_file) -> bool:
    """Whether ``layout_file`` is one of the layouts the path was planned on (``meta['layouts']``)."""
    from ..scene.model import resolve_layout_path

    target = Path(layout_file).resolve()
    for n in path.meta.get("layouts") or []:
        try:
            if resolve_layout_path(str(n)).resolve() == target:
                return True
        except UserError:
            continue
    return False


def render_clearance_problem(path: CameraPath, layout: Layout, layout_file, layout_arg: str,
                             frames: int | None = None) -> str | None:
    """Why rendering ``path`` through ``layout`` breaks the path's declared clearance, or None.

    Only layouts the path was not planned on are checked (the planner guarantees the others),
    and only paths that declare a clearance. One line: the layout, the minimum, the frames, the
    object, and the remedy (replan with ``synth path plan``, or allow the breach)."""
    c = declared_clearance(path)
    if c is None or planned_on(path, layout_file):
        return None
    rep = clearance_report(path, layout, c, frames)
    if rep["ok"]:
        return None
    worst = min(rep["ranges"], key=lambda r: r["min_clearance_m"])
    spans = ", ".join(f"{r['frames'][0]}-{r['frames'][1]}" for r in rep["ranges"][:4])
    if len(rep["ranges"]) > 4:
        spans += f" and {len(rep['ranges']) - 4} more"
    planned = ", ".join(map(str, path.meta.get("layouts") or [])) or "no named layouts"
    return (f"camera path '{path.name}' was planned on {planned} with {c:g} m clearance, but in layout "
            f"'{layout.name}' it passes {worst['min_clearance_m']:.3f} m from {describe_object(worst['objects'][0])} at frame "
            f"{worst['min_frame']} ({rep['frames_below']} frames closer than {c:g} m: {spans}); replan it for this "
            f"layout (`{replan_command(path, [layout_arg])}`) or pass --allow-clearance-breach")
