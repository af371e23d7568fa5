"""Camera paths planned once and rendered in every layout x lighting (no Blender here).

Two kinds of path, both as camera-to-world poses (OpenCV axes, ``synth.camera``) at a fixed frame
rate, stored as TUM text (``camera.write_tum``) plus a sidecar YAML with the planner's inputs:

``plan_query_path(layouts)``
    A smooth walk through every room of a set of layouts that share one shell (``apt_0``..``apt_5``):
    the path every layout x lighting is rendered along. It keeps ``clearance`` from the objects of
    *every* layout given, so the same poses are valid in each of them.
``plan_mapping_path(layout)``
    A cross-hatch tour of one layout: in each room lawnmower sweeps along x, then along y, the
    camera looking across the sweep (alternating sides), rooms chained through doors.

Clearance rule (``obstacles``)
    ``"all"`` (default): the camera centre keeps ``clearance`` metres horizontally from the
    footprint of every object except ceiling-mounted ones, whatever its height (a person walking
    on the floor never passes over a table), and from the walls. ``"band"``: only objects whose
    box reaches into the camera's height band (the path's height range widened by ``BAND`` =
    0.3 m both ways) count; objects entirely below or above are at least ``BAND`` away vertically.
    Walls are the edges of the rooms' free interiors (``Room.rect``), cut where an interior door
    (one that connects two rooms) is, plus that door's jambs; the entrance door counts as wall.
    A camera outside every room and door gap has clearance 0.

Planning (both kinds)
    An exact clearance field on a 2.5 cm grid (distance from each cell centre to the nearest wall
    segment and obstacle footprint, min over all layouts) gives the walkable cells
    (>= clearance + ``MARGIN``). Waypoints are picked per room from local maxima of the clearance
    (seeded), ordered into a tour (nearest neighbour + 2-opt on geodesic costs), connected by
    shortest grid paths whose cost prefers staying ``PREFER`` metres from obstacles and floor
    that is free of low furniture in most layouts; dead ends turn in a small loop. The polyline
    is smoothed (Gaussian along arc length); wherever the smoothed curve comes closer than
    ``clearance`` + 1 cm to anything (exact distances) the smoothing is reduced there. Then the
    curve is resampled at the constant step ``speed / fps`` and given heights and headings:
    heading = walking direction (smoothed) + slow look-around, rate-limited and smoothed, slow
    pitch and height changes, a small walking bob and roll. Deterministic for a given seed.

The built-in layouts and 0.3 m
    Rearranged variants put furniture where the reference has free floor, so the free space the
    six built-in layouts share is small. ``synth.rearrange`` therefore keeps every variant out of
    a walkway through all rooms of the reference (planned with 0.35 m): the shared space always
    holds a route through every room, and the shipped query path keeps 0.3 m from every object
    in all six layouts. If the layouts given leave no such route, ``plan_query_path`` raises a
    ``UserError`` naming the unreachable room and the largest clearance they allow.

Files: ``scenes/paths/NAME.txt`` (TUM, ``t = frame / fps``) and ``NAME.yaml``
(``format: synth-camera-path/1``: name, kind, fps, frames, seed, layouts, planner parameters,
summary stats).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import yaml

from . import camera
from .atomic import write_text_atomic
from .errors import SceneFormatError, UnknownNameError, UserError
from .resources import scenes_dir
from .scene import Layout, Stage, object_box

__all__ = [
    "CameraPath", "plan_query_path", "plan_mapping_path", "plan_path", "replan", "save_path", "load_path",
    "path_clearance", "path_clearance_detail", "clearance_report", "declared_clearance", "render_clearance_problem",
    "list_paths", "paths_dir", "path_summary", "plot_path", "generate_shipped", "register_cli",
    "SHIPPED", "FORMAT", "BAND",
]

FORMAT = "synth-camera-path/1"
BAND = 0.3  # m: objects reaching within this height of the camera's height range obstruct it
GRID = 0.025  # m: planning grid
MARGIN = 0.03  # m: walkable cells keep clearance + MARGIN (cell centres; exact distances)
CURVE_MARGIN = 0.01  # m: the smoothed curve keeps clearance + CURVE_MARGIN (exact distances)
PREFER = 0.9  # m: paths prefer to stay this far from obstacles
DCAP = 3.0  # m: clearance values are capped here
MAX_YAW_RATE = math.radians(80.0)  # rad/s, before the final smoothing (which cannot raise it)
DS = 0.05  # m: arc-length step of the dense curve before the final resampling

# query path: heights and head motion
Q_HEIGHT, Q_HEIGHT_VAR, BOB = 1.50, 0.07, 0.012  # m
Q_LOOK, Q_PITCH, Q_PITCH_VAR, Q_ROLL = math.radians(30.0), math.radians(-5.0), math.radians(6.0), math.radians(1.2)
Q_SMOOTH = 0.45  # m: Gaussian sigma of the query curve
# mapping path
M_HEIGHTS = (1.40, 1.60)  # m: x sweeps, y sweeps
M_HEIGHT_VAR = 0.03
M_LOOK, M_PITCH, M_PITCH_VAR, M_ROLL = math.radians(15.0), math.radians(-8.0), math.radians(4.0), math.radians(1.0)
M_SMOOTH = 0.25
M_SPACING = 1.0  # m: nominal distance between sweep lines
M_MIN_RUN = 0.5  # m: shorter free runs on a sweep line are skipped
STEP_HZ = 1.8  # steps per second at 1 m/s


# --------------------------------------------------------------------------------------------
# data


@dataclass
class CameraPath:
    name: str
    poses: np.ndarray  # (N, 4, 4) camera-to-world, OpenCV axes
    fps: float = camera.DEFAULT_FPS
    meta: dict[str, Any] = field(default_factory=dict)

    def __len__(self) -> int:
        return len(self.poses)

    @property
    def positions(self) -> np.ndarray:
        return np.asarray(self.poses)[:, :3, 3]

    @property
    def duration(self) -> float:
        return len(self.poses) / self.fps

    @property
    def length(self) -> float:
        p = self.positions
        return float(np.linalg.norm(np.diff(p, axis=0), axis=1).sum()) if len(p) > 1 else 0.0


# --------------------------------------------------------------------------------------------
# geometry: walls, obstacles, exact clearance


def _interior_doors(stage: Stage):
    return [op for op in stage.openings if op.kind == "door" and len(op.rooms) >= 2]


def wall_segments(stage: Stage) -> np.ndarray:
    """(K, 2, 2) wall segments: room rect edges minus interior door gaps, plus those doors' jambs."""
    doors = []
    for op in _interior_doors(stage):
        w = stage.wall(op.wall)
        c = op.center_xy(w)
        d = w.direction
        doors.append((op, w, c, d))
    segs = []
    for r in stage.rooms:
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
            for p, q in pieces:
                if q - p < 1e-6:
                    continue
                if axis == 0:
                    segs.append(((p, fixed), (q, fixed)))
                else:
                    segs.append(((fixed, p), (fixed, q)))
    for op, w, c, d in doors:
        n = np.array([-d[1], d[0]])
        h = w.thickness / 2 + 0.01
        for s in (-1, 1):
            e = c + d * s * op.width / 2
            segs.append((tuple(e - n * h), tuple(e + n * h)))
    return np.asarray(segs, dtype=float).reshape(-1, 2, 2)


def _inside(stage: Stage, pts: np.ndarray) -> np.ndarray:
    """Points inside a room's free interior or an interior door gap."""
    from matplotlib.path import Path as MplPath
    from .placement import opening_box

    inside = np.zeros(len(pts), bool)
    for r in stage.rooms:
        inside |= (pts[:, 0] >= r.rect[0]) & (pts[:, 0] <= r.rect[2]) & (pts[:, 1] >= r.rect[1]) & (pts[:, 1] <= r.rect[3])
    for op in _interior_doors(stage):
        gap = opening_box(stage, op, depth_extra=0.01)
        inside |= MplPath(gap.corners_2d()).contains_points(pts)
    return inside


def _seg_dist(pts: np.ndarray, segs: np.ndarray) -> np.ndarray:
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
class _Boxes:
    """Object footprints as arrays: centre (K,2), half size (K,2), cos/sin yaw, z range."""

    c: np.ndarray
    h: np.ndarray
    cs: np.ndarray
    zmin: np.ndarray
    zmax: np.ndarray

    @staticmethod
    def of(boxes) -> "_Boxes":
        boxes = list(boxes)
        if not boxes:
            z = np.zeros((0, 2))
            return _Boxes(z, z, z, np.zeros(0), np.zeros(0))
        return _Boxes(
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


def _object_boxes(layout: Layout, obstacles: str):
    if obstacles not in ("band", "all"):
        raise UserError(f"obstacles must be 'band' or 'all', got {obstacles!r}")
    return [object_box(o) for o in layout.objects if obstacles == "band" or o.support != "ceiling"]


def path_clearance(path: CameraPath, layout: Layout, obstacles: str = "all", band: float = BAND) -> np.ndarray:
    """Per-frame horizontal distance (m) from the camera centre to the nearest obstacle and wall.

    Obstacles: with ``"band"`` the footprints of the objects whose box overlaps the frame's height
    band ``[z - band, z + band]``; with ``"all"`` every object except ceiling-mounted ones. Walls:
    room rect edges except interior door gaps, plus door jambs. 0 outside every room / door gap.
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
    d = _seg_dist(xy, wall_segments(st))
    boxes = _object_boxes(layout, obstacles)
    bx = _Boxes.of(boxes)
    mask = None
    if obstacles == "band" and len(bx):
        z = P[:, 2:3]
        mask = (bx.zmax[None, :] > z - band) & (bx.zmin[None, :] < z + band)
    db, k = bx.nearest(xy, mask)
    ids = np.array([b.id for b in boxes], dtype=np.int64)
    nearest = np.where((db < d) & (k >= 0), ids[np.maximum(k, 0)] if len(ids) else NEAREST_WALL, NEAREST_WALL)
    d = np.minimum(d, db)
    outside = ~_inside(st, xy)
    d[outside] = 0.0
    nearest[outside] = NEAREST_OUTSIDE
    return d, nearest


# --------------------------------------------------------------------------------------------
# clearance against a path's declared clearance (synth path check; refused renders)

CLEARANCE_TOL = 1e-6  # m: paths are stored at 1 micrometre


def declared_clearance(path: CameraPath) -> float | None:
    """The clearance the path was planned with (``meta['planner']['clearance_m']``), or None."""
    v = (path.meta.get("planner") or {}).get("clearance_m")
    if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
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
        "frames_below": int(below.sum()), "ranges": ranges, "ok": not ranges,
    }


def _what(o: dict) -> str:
    return f"object {o['id']} ({o['class']})" if o["id"] is not None else o["class"]


def _range_text(r: dict) -> str:
    a, b = r["frames"]
    objs = r["objects"]
    return (f"frames {a}-{b}" if a != b else f"frame {a}") + (
        f": min {r['min_clearance_m']:.3f} m at frame {r['min_frame']}, "
        + ", ".join(_what(o) for o in objs[:3]) + (f" and {len(objs) - 3} more" if len(objs) > 3 else ""))


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
    from .scene import resolve_layout_path

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
            f"'{layout.name}' it passes {worst['min_clearance_m']:.3f} m from {_what(worst['objects'][0])} at frame "
            f"{worst['min_frame']} ({rep['frames_below']} frames closer than {c:g} m: {spans}); replan it for this "
            f"layout (`{replan_command(path, [layout_arg])}`) or pass --allow-clearance-breach")


# --------------------------------------------------------------------------------------------
# the planning space


def _same_shell(layouts: list[Layout]) -> None:
    a = layouts[0].stage
    for lay in layouts[1:]:
        b = lay.stage
        same = (
            [(r.name, tuple(np.round(r.rect, 6))) for r in a.rooms] == [(r.name, tuple(np.round(r.rect, 6))) for r in b.rooms]
            and [(o.id, o.wall, round(o.offset, 6), round(o.width, 6)) for o in a.openings if o.kind == "door"]
            == [(o.id, o.wall, round(o.offset, 6), round(o.width, 6)) for o in b.openings if o.kind == "door"]
        )
        if not same:
            raise UserError(f"layouts '{layouts[0].name}' and '{lay.name}' do not share one shell (rooms, doors); "
                            "a shared path needs the same stage")


class _Space:
    """Planning grid over the layouts' shared shell: exact clearance, walkable cells, rooms, costs."""

    def __init__(self, layouts: list[Layout], clearance: float, zlo: float, zhi: float, obstacles: str, grid: float = GRID):
        from scipy import ndimage

        _same_shell(layouts)
        self.layouts = layouts
        self.stage = st = layouts[0].stage
        if not st.rooms:
            raise UserError(f"layout '{layouts[0].name}' has no rooms to plan a path in")
        self.clearance, self.grid, self.obstacles = clearance, grid, obstacles
        self.zlo, self.zhi = zlo, zhi
        xs = [r.rect[0] for r in st.rooms] + [r.rect[2] for r in st.rooms]
        ys = [r.rect[1] for r in st.rooms] + [r.rect[3] for r in st.rooms]
        self.x0, self.y0 = min(xs) - 0.3, min(ys) - 0.3
        self.nx = int(math.ceil((max(xs) + 0.3 - self.x0) / grid))
        self.ny = int(math.ceil((max(ys) + 0.3 - self.y0) / grid))
        gx, gy = np.meshgrid(self.x0 + (np.arange(self.nx) + 0.5) * grid, self.y0 + (np.arange(self.ny) + 0.5) * grid)
        pts = np.stack([gx.ravel(), gy.ravel()], axis=1)
        self.pts = pts
        self.segs = wall_segments(st)
        inside = _inside(st, pts)
        dist = np.minimum(_seg_dist(pts, self.segs), DCAP)
        dist[~inside] = 0.0
        dist = dist.reshape(self.ny, self.nx)
        occ = np.zeros((self.ny, self.nx))
        self.boxes: list[_Boxes] = []
        for lay in layouts:
            all_boxes = _object_boxes(lay, obstacles)
            if obstacles == "band":
                hit = [b for b in all_boxes if b.zmax > zlo - BAND and b.zmin < zhi + BAND]
                low = [b for b in all_boxes if not (b.zmax > zlo - BAND and b.zmin < zhi + BAND) and b.zmax < zlo]
            else:
                hit, low = all_boxes, []
            bx = _Boxes.of(hit)
            self.boxes.append(bx)
            self._splat(dist, bx, DCAP, np.minimum)
            lo = np.full((self.ny, self.nx), DCAP)
            self._splat(lo, _Boxes.of(low), 0.6, np.minimum)
            occ += lo < 0.25  # near low furniture in this layout: walking there means climbing over it
        self.dist = dist
        self.occ = occ / len(layouts)
        self.walk = dist >= clearance + MARGIN
        # rooms per cell
        room = np.full(self.ny * self.nx, -1, int)
        for k, r in enumerate(st.rooms):
            m = (pts[:, 0] >= r.rect[0]) & (pts[:, 0] <= r.rect[2]) & (pts[:, 1] >= r.rect[1]) & (pts[:, 1] <= r.rect[3])
            room[m & (room < 0)] = k
        self.room = room.reshape(self.ny, self.nx)
        # the connected walkable component that covers the most rooms (then the largest)
        lab, n = ndimage.label(self.walk, structure=np.ones((3, 3), bool))
        best, best_key = 0, None
        for c in range(1, n + 1):
            m = lab == c
            key = (len(set(np.unique(self.room[m])) - {-1}), int(m.sum()))
            if best_key is None or key > best_key:
                best, best_key = c, key
        self.comp = lab == best if n else np.zeros_like(self.walk)
        self._graph = None

    # -- grid helpers
    def _splat(self, field_: np.ndarray, bx: _Boxes, reach: float, op) -> None:
        """Min the exact distance to each box into ``field_`` within ``reach`` of the box."""
        g = self.grid
        for k in range(len(bx)):
            r = float(np.hypot(*bx.h[k])) + reach
            c = bx.c[k]
            i0 = max(0, int((c[1] - r - self.y0) / g))
            i1 = min(self.ny, int((c[1] + r - self.y0) / g) + 1)
            j0 = max(0, int((c[0] - r - self.x0) / g))
            j1 = min(self.nx, int((c[0] + r - self.x0) / g) + 1)
            if i0 >= i1 or j0 >= j1:
                continue
            yy, xx = np.mgrid[i0:i1, j0:j1]
            p = np.stack([self.x0 + (xx.ravel() + 0.5) * g, self.y0 + (yy.ravel() + 0.5) * g], axis=1)
            one = _Boxes(bx.c[k : k + 1], bx.h[k : k + 1], bx.cs[k : k + 1], bx.zmin[k : k + 1], bx.zmax[k : k + 1])
            d = one.dist(p).reshape(i1 - i0, j1 - j0)
            field_[i0:i1, j0:j1] = op(field_[i0:i1, j0:j1], d)

    def cell(self, xy) -> tuple[int, int]:
        return (int(np.clip((xy[1] - self.y0) // self.grid, 0, self.ny - 1)),
                int(np.clip((xy[0] - self.x0) // self.grid, 0, self.nx - 1)))

    def xy(self, idx) -> np.ndarray:
        idx = np.asarray(idx)
        i, j = np.divmod(idx, self.nx)
        return np.stack([self.x0 + (j + 0.5) * self.grid, self.y0 + (i + 0.5) * self.grid], axis=-1)

    def exact(self, xy: np.ndarray) -> np.ndarray:
        """Exact planning clearance of arbitrary points (min over layouts; walls; 0 outside)."""
        xy = np.asarray(xy, float).reshape(-1, 2)
        d = _seg_dist(xy, self.segs)
        for bx in self.boxes:
            np.minimum(d, bx.dist(xy), out=d)
        d[~_inside(self.stage, xy)] = 0.0
        return d

    def room_of(self, xy: np.ndarray) -> np.ndarray:
        xy = np.asarray(xy, float).reshape(-1, 2)
        out = np.full(len(xy), -1, int)
        for k, r in enumerate(self.stage.rooms):
            m = (xy[:, 0] >= r.rect[0]) & (xy[:, 0] <= r.rect[2]) & (xy[:, 1] >= r.rect[1]) & (xy[:, 1] <= r.rect[3])
            out[m & (out < 0)] = k
        return out

    # -- graph search
    def graph(self):
        from scipy import sparse

        if self._graph is None:
            ny, nx, g = self.ny, self.nx, self.grid
            ok = self.comp
            t = np.clip((PREFER - self.dist) / max(PREFER - self.clearance, 1e-6), 0.0, 1.0)
            cost = 1.0 + 4.0 * t**2 + 1.5 * self.occ
            rows, cols, w = [], [], []
            for di, dj in ((0, 1), (1, 0), (1, 1), (1, -1)):
                ia, ja = np.nonzero(ok)
                ib, jb = ia + di, ja + dj
                m = (ib < ny) & (jb >= 0) & (jb < nx)
                ia, ja, ib, jb = ia[m], ja[m], ib[m], jb[m]
                m = ok[ib, jb]
                ia, ja, ib, jb = ia[m], ja[m], ib[m], jb[m]
                L = g * math.hypot(di, dj)
                rows.append(ia * nx + ja)
                cols.append(ib * nx + jb)
                w.append(L * 0.5 * (cost[ia, ja] + cost[ib, jb]))
            r, c, ww = np.concatenate(rows), np.concatenate(cols), np.concatenate(w)
            N = ny * nx
            self._graph = sparse.csr_matrix((np.concatenate([ww, ww]), (np.concatenate([r, c]), np.concatenate([c, r]))), shape=(N, N))
        return self._graph

    def snap(self, xy) -> int:
        """Index of the component cell nearest to ``xy``."""
        i, j = self.cell(xy)
        if self.comp[i, j]:
            return i * self.nx + j
        ii, jj = np.nonzero(self.comp)
        k = int(np.argmin((ii - i) ** 2 + (jj - j) ** 2))
        return int(ii[k] * self.nx + jj[k])

    def shortest(self, sources: list[int], limit: float = np.inf):
        from scipy.sparse.csgraph import dijkstra

        D, P = dijkstra(self.graph(), directed=False, indices=sources, return_predecessors=True, limit=limit)
        return D, P

    def straight(self, a: int, b: int) -> np.ndarray | None:
        """The straight segment from cell a to cell b when it keeps the walkable clearance, else None."""
        seg = _line(self.xy(a), self.xy(b))
        if (self.exact(seg) >= self.clearance + MARGIN - 0.5 * self.grid).all():
            return seg
        return None

    @staticmethod
    def trace(pred_row: np.ndarray, src: int, dst: int) -> list[int]:
        out = [dst]
        while out[-1] != src:
            p = pred_row[out[-1]]
            if p < 0:
                raise RuntimeError("no path")
            out.append(int(p))
        return out[::-1]

    def route(self, a: int, b: int) -> np.ndarray:
        """Cell-centre polyline of the cheapest path from cell a to cell b."""
        if a == b:
            return self.xy([a])
        d_e = float(np.linalg.norm(self.xy(a) - self.xy(b)))
        for lim in (3.0 * d_e + 2.0, np.inf):  # cost units: metres times the cost factor
            D, P = self.shortest([a], limit=lim)
            if np.isfinite(D[0, b]):
                return self.xy(self.trace(P[0], a, b))
        raise UserError("no walkable connection between two points of the path")


# --------------------------------------------------------------------------------------------
# curves


def _polyline_resample(P: np.ndarray, step: float) -> np.ndarray:
    P = np.asarray(P, float)
    seg = np.linalg.norm(np.diff(P, axis=0), axis=1)
    keep = np.concatenate([[True], seg > 1e-9])
    P = P[keep]
    if len(P) < 2:
        return P.copy()
    s = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(P, axis=0), axis=1))])
    n = int(math.floor(s[-1] / step)) + 1
    t = np.arange(n) * step
    return np.stack([np.interp(t, s, P[:, 0]), np.interp(t, s, P[:, 1])], axis=1)


def _line(a: np.ndarray, b: np.ndarray, step: float = GRID) -> np.ndarray:
    n = max(1, int(math.ceil(np.linalg.norm(b - a) / step)))
    return a + (b - a) * np.linspace(0.0, 1.0, n + 1)[:, None]


def _arc(P: np.ndarray) -> np.ndarray:
    return np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(P, axis=0), axis=1))])


def _smooth_valid(space: _Space, Q: np.ndarray, sigma_m: float) -> tuple[np.ndarray, np.ndarray]:
    """Gaussian-smooth a dense valid polyline, less where the smooth curve would come too close."""
    from scipy import ndimage

    need = space.clearance + CURVE_MARGIN
    if len(Q) < 3 or sigma_m <= 0:
        return Q.copy(), np.zeros(len(Q))
    S = ndimage.gaussian_filter1d(Q, sigma_m / DS, axis=0, mode="nearest")
    w = np.ones(len(Q))
    grow = int(0.5 * sigma_m / DS) + 1
    for _ in range(24):
        P = Q + w[:, None] * (S - Q)
        bad = space.exact(P) < need
        if not bad.any():
            return P, w
        region = ndimage.binary_dilation(bad, iterations=grow)
        w[region] *= 0.7
        w = np.minimum(w, ndimage.gaussian_filter1d(w, 0.3 * sigma_m / DS, mode="nearest"))
    P = Q + w[:, None] * (S - Q)
    bad = space.exact(P) < need
    w[bad] = 0.0
    return Q + w[:, None] * (S - Q), w


def _turn_loops(space: _Space, raw: np.ndarray, marks: list[int], rng, attrs: np.ndarray | None = None):
    """Replace sharp reversals at junctions (indices ``marks`` into ``raw``) by a loop.

    The loop is a circle around a point of the incoming path (the junction itself when there is
    room, else up to 1.5 m back), with a radius below that point's clearance minus what the path
    must keep, so it is valid by construction (clearance is 1-Lipschitz). The stretch of path
    inside the circle (the spike into the corner and back) is cut out. ``attrs`` (N, k) per-point
    values are carried along (loop points get NaN in column 0 and the entry values elsewhere).
    Returns (points, attrs).
    """
    need = space.clearance + MARGIN
    A = np.zeros((len(raw), 0)) if attrs is None else np.asarray(attrs, float).reshape(len(raw), -1)
    out, out_a, last = [], [], 0
    for m in sorted(set(marks)):
        if m <= last or m >= len(raw) - 1:
            continue
        W = raw[m]
        dW = np.linalg.norm(raw - W, axis=1)

        def away(idx, dist=0.5):
            k = np.nonzero(dW[idx] >= dist)[0]
            return raw[idx[k[0]]] if len(k) else raw[idx[-1]]
        u = W - away(np.arange(m - 1, last - 1, -1))
        v = away(np.arange(m + 1, len(raw))) - W
        if np.linalg.norm(u) < 1e-6 or np.linalg.norm(v) < 1e-6:
            continue
        u, v = u / np.linalg.norm(u), v / np.linalg.norm(v)
        if float(u @ v) > -0.5:  # turn below 120 degrees: smoothing handles it
            continue
        back = np.arange(m, last, -1)
        arcb = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(raw[back], axis=0), axis=1))])
        back = back[arcb <= 1.5]
        r_all = np.minimum(0.55, space.exact(raw[back]) - need - 0.01)
        good = np.nonzero(r_all >= 0.3)[0]
        if len(good):
            i = int(back[good[0]])
            r = float(r_all[good[0]])
        else:
            k = int(np.argmax(r_all))
            i, r = int(back[k]), float(r_all[k])
            if r < 0.15:
                continue
        C = raw[i]
        dC = np.linalg.norm(raw - C, axis=1)
        a = i
        while a > last and dC[a] < r:
            a -= 1
        # where the path leaves the circle again: only just after the junction (never a later visit)
        ahead = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(raw[m:], axis=0), axis=1))])
        win = m + int(np.searchsorted(ahead, 3.5))
        inside = np.nonzero(dC[m:win] < r)[0]
        if dC[a] < 0.8 * r or not len(inside):
            continue
        j = m + int(inside[0])
        exits = np.nonzero(dC[j:win] >= r)[0]
        if not len(exits):
            continue
        b = j + int(exits[0])
        sgn = 1.0 if rng.random() < 0.5 else -1.0
        t_in = math.atan2(raw[a][1] - C[1], raw[a][0] - C[0])
        t_out = math.atan2(raw[b][1] - C[1], raw[b][0] - C[0])
        delta = (sgn * (t_out - t_in)) % (2 * math.pi)
        if delta < math.pi:
            delta += 2 * math.pi
        th = t_in + sgn * np.linspace(0.0, delta, int(delta * r / DS) + 2)
        circ = C + r * np.stack([np.cos(th), np.sin(th)], axis=1)
        out.append(raw[last : a + 1])
        out_a.append(A[last : a + 1])
        out.append(circ[1:-1])
        ca = np.repeat(A[a : a + 1], len(circ) - 2, axis=0)
        if ca.shape[1]:
            ca[:, 0] = np.nan
        out_a.append(ca)
        last = b
    out.append(raw[last:])
    out_a.append(A[last:])
    return np.concatenate(out, axis=0), np.concatenate(out_a, axis=0)


def _smooth_noise(rng, t: np.ndarray, pmin: float, pmax: float, n: int = 3) -> np.ndarray:
    """Slow, smooth noise in [-1, 1]: a sum of sinusoids with seeded periods and phases."""
    P = rng.uniform(pmin, pmax, n)
    ph = rng.uniform(0.0, 2 * math.pi, n)
    a = rng.uniform(0.5, 1.0, n)
    a /= a.sum()
    return np.sum(a[:, None] * np.sin(2 * math.pi * t[None, :] / P[:, None] + ph[:, None]), axis=0)


def _continuous(raw: np.ndarray) -> np.ndarray:
    """Angles made continuous (each within pi of the previous)."""
    out = np.empty_like(raw)
    out[0] = raw[0]
    for i in range(1, len(raw)):
        out[i] = out[i - 1] + (raw[i] - out[i - 1] + math.pi) % (2 * math.pi) - math.pi
    return out


def _rate_limit(x: np.ndarray, max_step: float) -> np.ndarray:
    y = np.empty_like(x)
    y[0] = x[0]
    for i in range(1, len(x)):
        y[i] = y[i - 1] + np.clip(x[i] - y[i - 1], -max_step, max_step)
    return y


def _travel_yaw(xy: np.ndarray) -> np.ndarray:
    if len(xy) < 2:
        return np.zeros(len(xy))
    d = np.diff(xy, axis=0)
    d = np.vstack([d, d[-1:]])
    return np.unwrap(np.arctan2(d[:, 1], d[:, 0]))


def _resample_track(P: np.ndarray, attrs: dict[str, np.ndarray], frames: int, step: float):
    """Constant arc-length samples of a dense curve (and of per-point attributes, nearest)."""
    s = _arc(P)
    n = min(frames, int(math.floor(s[-1] / step)) + 1)
    t = np.arange(n) * step
    xy = np.stack([np.interp(t, s, P[:, 0]), np.interp(t, s, P[:, 1])], axis=1)
    k = np.clip(np.searchsorted(s, t), 0, len(s) - 1)
    return xy, {key: v[k] for key, v in attrs.items()}


def _poses(xy, z, yaw, pitch, roll) -> np.ndarray:
    return np.stack([camera.pose_from_ypr((float(p[0]), float(p[1]), float(h)), float(a), float(b), float(c))
                     for p, h, a, b, c in zip(xy, z, yaw, pitch, roll)]) if len(xy) else np.zeros((0, 4, 4))


# --------------------------------------------------------------------------------------------
# query path


def _pick_waypoints(space: _Space, rng) -> list[tuple[int, int]]:
    """(room index, cell index) waypoints: a few local clearance maxima per room (seeded)."""
    from scipy import ndimage

    g = space.grid
    score = np.minimum(space.dist, 1.2) - 0.4 * space.occ
    score = np.where(space.comp, score, -np.inf)
    peak = ndimage.maximum_filter(np.where(np.isfinite(score), score, -9.0), size=int(0.8 / g) | 1)
    cand = space.comp & (score >= peak - 1e-9)
    out = []
    for k, r in enumerate(space.stage.rooms):
        m = space.comp & (space.room == k)
        if not m.any():
            continue
        area = m.sum() * g * g
        n = int(np.clip(round(area / 4.0), 1, 4))
        roomy = space.dist >= space.clearance + 0.35  # room to turn around without a tight curl
        ii, jj = np.nonzero(cand & m & roomy)
        if len(ii) == 0:
            ii, jj = np.nonzero(cand & m)
        if len(ii) == 0:
            ii, jj = np.nonzero(m)
        sc = score[ii, jj] + rng.uniform(0.0, 0.35, len(ii))
        order = np.argsort(-sc, kind="stable")
        chosen = []
        for o in order:
            p = space.xy(ii[o] * space.nx + jj[o])
            if all(np.linalg.norm(p - q) >= 1.4 for q in chosen):
                chosen.append(p)
                out.append((k, int(ii[o] * space.nx + jj[o])))
            if len(chosen) >= n:
                break
    return out


def _tour(D: np.ndarray, start: int) -> list[int]:
    """Open tour over all nodes from ``start``: nearest neighbour, then 2-opt."""
    n = len(D)
    order, left = [start], set(range(n)) - {start}
    while left:
        cur = order[-1]
        nxt = min(left, key=lambda j: (D[cur, j], j))
        order.append(nxt)
        left.remove(nxt)
    improved = True
    while improved:
        improved = False
        for i in range(1, n - 1):
            for j in range(i + 1, n):
                a, b = order[i - 1], order[i]
                c = order[j]
                d = order[j + 1] if j + 1 < n else None
                before = D[a, b] + (D[c, d] if d is not None else 0.0)
                after = D[a, c] + (D[b, d] if d is not None else 0.0)
                if after < before - 1e-9:
                    order[i : j + 1] = order[i : j + 1][::-1]
                    improved = True
    return order


def _start_cell(space: _Space) -> int:
    """Where walks begin: inside the entrance door (a door with one room), else the first room's best cell."""
    st = space.stage
    for op in st.openings:
        if op.kind == "door" and len(op.rooms) == 1:
            w = st.wall(op.wall)
            c = op.center_xy(w)
            r = st.room(op.rooms[0])
            mid = np.array([(r.rect[0] + r.rect[2]) / 2, (r.rect[1] + r.rect[3]) / 2])
            n = np.array([-w.direction[1], w.direction[0]])
            if n @ (mid - c) < 0:
                n = -n
            return space.snap(c + n * 1.0)
    m = space.comp
    i, j = np.unravel_index(int(np.argmax(np.where(m, space.dist, -1))), m.shape)
    return int(i * space.nx + j)


def plan_query_path(layouts: list[Layout], frames: int = 4000, seed: int = 0, fps: float = camera.DEFAULT_FPS,
                    speed: float = 1.0, clearance: float = 0.3, obstacles: str = "all", name: str = "query") -> CameraPath:
    """The shared query walk: every room, ``clearance`` from the objects of every layout given."""
    from scipy import ndimage

    _check_args(frames, fps, speed, clearance)
    if not layouts:
        raise UserError("plan_query_path needs at least one layout")
    rng = np.random.default_rng([seed, 1])
    zlo = Q_HEIGHT - Q_HEIGHT_VAR - BOB
    zhi = Q_HEIGHT + Q_HEIGHT_VAR + BOB
    space = _Space(layouts, clearance, zlo, zhi, obstacles)
    _require_rooms(space, "query path")
    step = speed / fps
    need = (frames - 1) * step
    cur = _start_cell(space)
    pieces, marks, n_loops = [space.xy([cur])], [], 0
    raw_len = 0.0
    while True:
        wps = _pick_waypoints(space, np.random.default_rng([seed, 2, n_loops]))
        cells = [c for _, c in wps]
        D, Pred = space.shortest(cells)
        start = int(np.argmin(D[:, cur]))
        Dm = D[:, cells]
        order = _tour(Dm, start)
        seq = [cur] + [cells[o] for o in order]
        for a, b in zip(seq[:-1], seq[1:]):
            if a == b:
                continue
            if a in cells:
                poly = space.xy(space.trace(Pred[cells.index(a)], a, b))
            else:
                poly = space.xy(space.trace(Pred[cells.index(b)], b, a))[::-1]
            pieces.append(poly[1:])
            marks.append(sum(len(p) for p in pieces) - 1)
            raw_len += float(np.linalg.norm(np.diff(poly, axis=0), axis=1).sum())
        cur = seq[-1]
        n_loops += 1
        if raw_len >= 1.25 * need + 2.0 or n_loops >= 100:
            raw = np.concatenate(pieces)
            P = _dense_smooth(space, raw, marks[:-1], Q_SMOOTH, rng)
            if _arc(P)[-1] >= need:
                break
            if n_loops >= 100:
                raise UserError(f"query path: the free space shared by {', '.join(l.name for l in layouts)} is too "
                                f"small to walk {need:.1f} m without standing still")
    xy, _ = _resample_track(P, {}, frames, step)
    n = len(xy)
    t = np.arange(n) / fps
    nr = np.random.default_rng([seed, 3])
    z = Q_HEIGHT + Q_HEIGHT_VAR * _smooth_noise(nr, t, 14.0, 40.0) + BOB * np.sin(2 * math.pi * STEP_HZ * speed * t)
    travel = ndimage.gaussian_filter1d(_travel_yaw(xy), 0.6 * fps, mode="nearest") if n > 1 else np.zeros(n)
    target = travel + Q_LOOK * _smooth_noise(nr, t, 9.0, 22.0)
    yaw = _final_yaw(target, fps)
    pitch = Q_PITCH + Q_PITCH_VAR * _smooth_noise(nr, t, 7.0, 19.0)
    roll = Q_ROLL * _smooth_noise(nr, t, 5.0, 13.0) + math.radians(0.4) * np.sin(math.pi * STEP_HZ * speed * t)
    poses = _poses(xy, z, yaw, pitch, roll)
    path = CameraPath(name, poses, float(fps), {})
    path.meta = _meta("query", layouts, seed, frames, fps, speed, clearance, obstacles, space, path,
                      {"loops": n_loops, "smoothing_sigma_m": Q_SMOOTH, "height_m": Q_HEIGHT, "height_var_m": Q_HEIGHT_VAR,
                       "bob_m": BOB, "look_around_deg": round(math.degrees(Q_LOOK), 3)})
    return path


def _final_yaw(target: np.ndarray, fps: float) -> np.ndarray:
    """Rate-limit a continuous yaw target, then smooth it (smoothing cannot raise the rate)."""
    from scipy import ndimage

    if len(target) < 2:
        return target.copy()
    y = _rate_limit(ndimage.gaussian_filter1d(target, 0.25 * fps, mode="nearest"), MAX_YAW_RATE / fps)
    return ndimage.gaussian_filter1d(y, 0.2 * fps, mode="nearest")


def _dense_smooth(space: _Space, raw: np.ndarray, marks: list[int], sigma: float, rng) -> np.ndarray:
    looped, _ = _turn_loops(space, raw, marks, rng)
    Q = _polyline_resample(looped, DS)
    Q, _ = _smooth_valid(space, Q, 0.1)  # takes the grid staircase off first (nearly always valid)
    P, _ = _smooth_valid(space, Q, sigma)
    return P


def _check_args(frames, fps, speed, clearance):
    if not (isinstance(frames, (int, np.integer)) and frames >= 2):
        raise UserError(f"frames must be an integer >= 2, got {frames!r}")
    for nm, v in (("fps", fps), ("speed", speed)):
        if not (math.isfinite(v) and v > 0):
            raise UserError(f"{nm} must be > 0, got {v!r}")
    if not (math.isfinite(clearance) and clearance >= 0):
        raise UserError(f"clearance must be >= 0, got {clearance!r}")


def _require_rooms(space: _Space, what: str) -> None:
    have = set(np.unique(space.room[space.comp])) - {-1}
    missing = [r.name for k, r in enumerate(space.stage.rooms) if k not in have]
    if missing:
        names = ", ".join(l.name for l in space.layouts)
        best = _max_connecting_clearance(space) - MARGIN
        hint = (f"; the most these layouts allow is about {math.floor(best * 100) / 100:.2f} m" if best > 0.05 else "")
        raise UserError(f"{what}: room(s) {', '.join(missing)} cannot be reached with {space.clearance:g} m clearance "
                        f"(obstacles '{space.obstacles}') in every layout ({names}){hint}")


def _max_connecting_clearance(space: _Space) -> float:
    """The largest clearance at which one walkable component still reaches every room (bisection)."""
    from scipy import ndimage

    n_rooms = len(space.stage.rooms)

    def ok(th):
        lab, n = ndimage.label(space.dist >= th, structure=np.ones((3, 3), bool))
        for c in range(1, n + 1):
            if len(set(np.unique(space.room[lab == c])) - {-1}) == n_rooms:
                return True
        return False
    lo, hi = 0.0, float(space.dist.max())
    if not ok(lo + 1e-6):
        return 0.0
    for _ in range(12):
        mid = (lo + hi) / 2
        lo, hi = (mid, hi) if ok(mid) else (lo, mid)
    return lo


def _meta(kind, layouts, seed, frames, fps, speed, clearance, obstacles, space, path, extra) -> dict:
    xy = path.positions[:, :2]
    rooms = space.room_of(xy)
    visited = []
    for k in rooms:
        if k >= 0 and space.stage.rooms[k].name not in visited:
            visited.append(space.stage.rooms[k].name)
    clr = min(float(path_clearance(path, lay, obstacles).min()) for lay in layouts) if len(path) else 0.0
    return {
        "kind": kind,
        "seed": int(seed),
        "layouts": [l.name for l in layouts],
        "planner": {
            "frames": int(frames), "fps": float(fps), "speed_mps": float(speed), "clearance_m": float(clearance),
            "obstacles": obstacles, "band_m": BAND, "height_range_m": [round(space.zlo, 4), round(space.zhi, 4)],
            "grid_m": space.grid, "margin_m": MARGIN, "curve_margin_m": CURVE_MARGIN, "prefer_m": PREFER,
            "max_yaw_rate_deg_s": round(math.degrees(MAX_YAW_RATE), 3), **extra,
        },
        "stats": {
            "length_m": round(path.length, 3), "duration_s": round(path.duration, 3),
            "min_clearance_m": round(clr, 4), "rooms": visited,
        },
    }


# --------------------------------------------------------------------------------------------
# mapping path


def _line_runs(space: _Space, k: int, axis: int) -> dict[int, list[tuple[int, int]]]:
    """Free runs (>= M_MIN_RUN) of every grid row (axis 0) or column (axis 1) crossing room ``k`` (cached)."""
    cache = space.__dict__.setdefault("_runs_cache", {})
    key = (k, axis)
    if key not in cache:
        m = space.comp & (space.room == k)
        lines = np.nonzero(m.any(axis=1 - axis))[0]
        cache[key] = {int(i): _runs(m[i, :] if axis == 0 else m[:, i], int(M_MIN_RUN / space.grid)) for i in lines}
    return cache[key]


def _sweep_runs(space: _Space, k: int, axis: int, spacing: float, offset: float) -> list[list[tuple[np.ndarray, np.ndarray]]]:
    """Free runs on lawnmower lines in room ``k``: lines along x (axis 0) or y (axis 1), ~``spacing`` apart.

    Each line takes the grid row near its nominal position (within 0.45 spacing) with the most
    free length; a room where no nominal line finds any gets its single best row.
    """
    g = space.grid
    r = space.stage.rooms[k].rect
    table = _line_runs(space, k, axis)
    if not table:
        return []
    perp_lo, perp_hi = (r[1], r[3]) if axis == 0 else (r[0], r[2])
    c = space.clearance + MARGIN
    lo, hi = perp_lo + c, perp_hi - c
    if hi < lo:
        lo = hi = (perp_lo + perp_hi) / 2
    n = max(1, int(math.floor((hi - lo) / spacing + 1e-9)) + 1)
    span = (n - 1) * spacing
    pos = np.clip((lo + hi) / 2 - span / 2 + np.arange(n) * spacing + offset * spacing, lo, hi)
    origin = space.y0 if axis == 0 else space.x0
    used, lines = set(), []
    tot = {i: sum(b - a for a, b in runs) * g for i, runs in table.items()}
    for p in pos:
        base = int((p - origin) // g)
        reach = max(1, int(0.45 * spacing / g))
        cand = [i for i in range(base - reach, base + reach + 1) if tot.get(i, 0.0) > 0 and i not in used]
        if not cand:
            continue
        best = max(cand, key=lambda i: (tot[i] - 0.5 * abs(i - base) * g, -abs(i - base), -i))
        used.update(range(best - 2, best + 3))
        lines.append(best)
    if not lines:
        lines = [max(tot, key=lambda i: (tot[i], -i))]
    out = []
    for idx in sorted(lines):
        segs = []
        for a, b in table[idx]:
            ia, ib = (idx * space.nx + a, idx * space.nx + b - 1) if axis == 0 else (a * space.nx + idx, (b - 1) * space.nx + idx)
            segs.append((space.xy(ia), space.xy(ib)))
        out.append(segs)
    return out


def _runs(row: np.ndarray, min_len: int) -> list[tuple[int, int]]:
    d = np.diff(np.concatenate([[0], row.astype(int), [0]]))
    starts, ends = np.nonzero(d == 1)[0], np.nonzero(d == -1)[0]
    return [(int(a), int(b)) for a, b in zip(starts, ends) if b - a >= min_len]


def _room_pattern(space: _Space, k: int, spacing: float, offset: float, flip: int) -> list[tuple[np.ndarray, np.ndarray, float, float]]:
    """Sweep segments of one room: (start, end, look yaw, height); x sweeps then y sweeps."""
    out = []
    for s_i, axis in enumerate((0, 1) if flip % 2 == 0 else (1, 0)):
        lines = _sweep_runs(space, k, axis, spacing, offset)
        if (flip // 2) % 2:
            lines = lines[::-1]
        z = M_HEIGHTS[axis]
        reverse_first = (flip // 4) % 2 == 1
        for j, segs in enumerate(lines):
            forward = (j % 2 == 0) != reverse_first
            segs = segs if forward else [(b, a) for a, b in segs[::-1]]
            # look across the sweep, alternating sides line by line; the first line looks into the room
            first_look = +1 if ((flip // 2) % 2 == 0) else -1
            side = first_look if j % 2 == 0 else -first_look
            look = (math.pi / 2 if side > 0 else -math.pi / 2) if axis == 0 else (0.0 if side > 0 else math.pi)
            for a, b in segs:
                out.append((a, b, look, z))
    return out


def plan_mapping_path(layout: Layout, frames: int = 6000, seed: int = 0, fps: float = camera.DEFAULT_FPS,
                      speed: float = 1.0, clearance: float = 0.3, obstacles: str = "all", name: str = "mapping") -> CameraPath:
    """Cross-hatch tour of one layout: lawnmower sweeps along x and y in every room, rooms chained through doors."""
    from scipy import ndimage

    _check_args(frames, fps, speed, clearance)
    zlo = min(M_HEIGHTS) - M_HEIGHT_VAR
    zhi = max(M_HEIGHTS) + M_HEIGHT_VAR
    space = _Space([layout], clearance, zlo, zhi, obstacles)
    _require_rooms(space, "mapping path")
    step = speed / fps
    need = (frames - 1) * step
    max_dim = max(max(r.rect[2] - r.rect[0], r.rect[3] - r.rect[1]) for r in space.stage.rooms)

    def one_pass(sp, offset=0.0, k=0, start=None):
        return _mapping_pass(space, sp, offset, np.random.default_rng([seed, 11, k]), start=start)
    spacing = M_SPACING
    P, attrs = one_pass(spacing)
    if _arc(P)[-1] > need:  # too long: sparser sweeps (never fewer rooms)
        lo, hi = spacing, 2.0 * max_dim
        P_hi, a_hi = one_pass(hi)
        L = _arc(P_hi)[-1]
        if L > need:
            raise UserError(f"mapping path: {frames} frames at {speed:g} m/s ({need:.1f} m) cannot cover every room of "
                            f"'{layout.name}' even with one sweep line per direction ({L:.1f} m); use at least "
                            f"{int(math.ceil(L / step)) + 1} frames or a higher speed")
        for _ in range(7):
            mid = math.sqrt(lo * hi)
            P_mid, a_mid = one_pass(mid)
            if _arc(P_mid)[-1] <= need:
                hi, P_hi, a_hi = mid, P_mid, a_mid
            else:
                lo = mid
        spacing, P, attrs = hi, P_hi, a_hi
    passes = 1
    while _arc(P)[-1] < need and passes < 8:  # fill with offset passes, cut to length
        P2, a2 = one_pass(spacing, 0.5 if passes % 2 else 0.25, passes, start=P[-1])
        P = np.concatenate([P, P2[1:]])
        attrs = {k: np.concatenate([attrs[k], a2[k][1:]]) for k in attrs}
        passes += 1
    xy, at = _resample_track(P, attrs, frames, step)
    n = len(xy)
    t = np.arange(n) / fps
    nr = np.random.default_rng([seed, 13])
    travel = ndimage.gaussian_filter1d(_travel_yaw(xy), 0.4 * fps, mode="nearest") if n > 1 else np.zeros(n)
    look = at["look"]
    sweeping = np.isfinite(look)
    raw = np.where(sweeping, look, travel) + np.where(sweeping, M_LOOK * _smooth_noise(nr, t, 5.0, 11.0), 0.0)
    yaw = _final_yaw(_continuous(raw), fps)
    zt = at["z"]
    z = ndimage.gaussian_filter1d(_rate_limit(zt, 0.15 / fps), 0.5 * fps, mode="nearest") if n > 1 else zt
    z = z + M_HEIGHT_VAR * _smooth_noise(nr, t, 8.0, 20.0) * 0.6 + 0.4 * BOB * np.sin(2 * math.pi * STEP_HZ * speed * t)
    pitch = M_PITCH + M_PITCH_VAR * _smooth_noise(nr, t, 6.0, 15.0)
    roll = M_ROLL * _smooth_noise(nr, t, 5.0, 13.0)
    poses = _poses(xy, z, yaw, pitch, roll)
    path = CameraPath(name, poses, float(fps), {})
    path.meta = _meta("mapping", [layout], seed, frames, fps, speed, clearance, obstacles, space, path,
                      {"sweep_spacing_m": round(spacing, 4), "passes": passes, "smoothing_sigma_m": M_SMOOTH,
                       "heights_m": list(M_HEIGHTS), "look_sweep_deg": round(math.degrees(M_LOOK), 3)})
    return path


def _mapping_pass(space: _Space, spacing: float, offset: float, rng, start=None):
    """One cross-hatch tour over all rooms: dense smoothed curve + per-point look yaw / height."""
    st = space.stage
    cur = _start_cell(space) if start is None else space.snap(start)
    todo = [k for k in range(len(st.rooms)) if (space.comp & (space.room == k)).any()]
    pts, looks, zs = [space.xy([cur])], [np.array([np.nan])], [np.array([M_HEIGHTS[0]])]
    marks = []
    z_now = M_HEIGHTS[0]
    while todo:
        # the room (and sweep variant) whose first segment is nearest along the floor
        D, _ = space.shortest([cur])
        best = None
        for k in todo:
            for flip in range(8):
                pat = _room_pattern(space, k, spacing, offset, flip)
                if not pat:  # nothing to sweep: walk to the room's roomiest spot
                    m = space.comp & (space.room == k)
                    i, j = np.unravel_index(int(np.argmax(np.where(m, space.dist, -1.0))), m.shape)
                    p = space.xy(i * space.nx + j)
                    pat = [(p, p, np.nan, z_now)]
                c0 = space.snap(pat[0][0])
                key = (float(D[0, c0]), k, flip)
                if best is None or key < best[0]:
                    best = (key, k, pat)
        _, k, pat = best
        todo.remove(k)
        for a, b, look, z in pat:
            ca, cb = space.snap(a), space.snap(b)
            conn = space.straight(cur, ca)
            if conn is None:
                conn = space.route(cur, ca)
            if len(conn) > 1:
                pts.append(conn[1:])
                looks.append(np.full(len(conn) - 1, np.nan))
                zs.append(np.full(len(conn) - 1, z_now))
                marks.append(sum(len(p) for p in pts) - 1)
            seg = _line(space.xy(ca), space.xy(cb))  # a run of walkable cells on one grid line
            if len(seg) > 1:
                pts.append(seg[1:])
                looks.append(np.full(len(seg) - 1, look))
                zs.append(np.full(len(seg) - 1, z))
                marks.append(sum(len(p) for p in pts) - 1)
            z_now = z
            cur = cb
    raw = np.concatenate(pts)
    raw, A = _turn_loops(space, raw, marks[:-1], rng,
                         np.stack([np.concatenate(looks), np.concatenate(zs)], axis=1))
    look, zz = A[:, 0], A[:, 1]
    # dense resampling carrying attributes
    s = _arc(raw)
    keep = np.concatenate([[True], np.diff(s) > 1e-9])
    raw, look, zz, s = raw[keep], look[keep], zz[keep], s[keep]
    t = np.arange(int(math.floor(s[-1] / DS)) + 1) * DS
    Q = np.stack([np.interp(t, s, raw[:, 0]), np.interp(t, s, raw[:, 1])], axis=1)
    k = np.clip(np.searchsorted(s, t), 0, len(s) - 1)
    P, _ = _smooth_valid(space, Q, M_SMOOTH)
    return P, {"look": look[k], "z": zz[k]}


# --------------------------------------------------------------------------------------------
# shipped paths

# The paths under scenes/paths/ (``synth path generate`` rewrites them). The query path cannot keep
# 0.3 m in all six built-in layouts: floor lamps of different variants leave a hallway bottleneck
# in front of the bathroom door where at most ~0.29 m is possible (see the module doc), so it is
# planned with 0.25 m.
SHIPPED: dict[str, dict[str, Any]] = {
    "query": {"kind": "query", "layouts": [f"apt_{i}" for i in range(6)], "frames": 4000, "seed": 0, "clearance": 0.3},
    "mapping": {"kind": "mapping", "layouts": ["apt_0"], "frames": 6000, "seed": 0, "clearance": 0.3},
}


def plan_path(kind: str, layouts: list[Layout], frames: int, seed: int = 0, fps: float = camera.DEFAULT_FPS,
              speed: float = 1.0, clearance: float = 0.3, obstacles: str = "all", name: str | None = None) -> CameraPath:
    """``plan_query_path`` or ``plan_mapping_path`` by kind."""
    if kind == "query":
        return plan_query_path(layouts, frames, seed, fps, speed, clearance, obstacles, name or "query")
    if kind == "mapping":
        if len(layouts) != 1:
            raise UserError(f"a mapping path is planned on one layout, got {len(layouts)}")
        return plan_mapping_path(layouts[0], frames, seed, fps, speed, clearance, obstacles, name or "mapping")
    raise UserError(f"unknown path kind {kind!r}; use query or mapping")


def replan(path: CameraPath) -> CameraPath:
    """Plan a saved path again from the inputs its metadata records (to check for drift)."""
    from .scene import load_layout

    m = path.meta
    pl = m.get("planner") or {}
    try:
        lays = [load_layout(n) for n in m["layouts"]]
        return plan_path(m["kind"], lays, int(pl["frames"]), int(m["seed"]), float(pl["fps"]), float(pl["speed_mps"]),
                         float(pl["clearance_m"]), str(pl.get("obstacles", "all")), path.name)
    except KeyError as e:
        raise UserError(f"camera path '{path.name}' does not record its planner input {e}") from None


def generate_shipped(out_dir=None, names=None) -> list[Path]:
    """(Re)write the shipped paths (``SHIPPED``) into ``out_dir`` (default scenes/paths)."""
    from .scene import load_layout

    out_dir = Path(out_dir) if out_dir else paths_dir()
    written = []
    for name, spec in SHIPPED.items():
        if names and name not in names:
            continue
        lays = [load_layout(n) for n in spec["layouts"]]
        path = plan_path(spec["kind"], lays, spec["frames"], spec["seed"], clearance=spec["clearance"], name=name)
        written.append(save_path(path, out_dir / f"{name}.txt"))
    return written


# --------------------------------------------------------------------------------------------
# files


def paths_dir() -> Path:
    return scenes_dir() / "paths"


def list_paths() -> list[str]:
    d = paths_dir()
    return sorted(p.stem for p in d.glob("*.txt")) if d.is_dir() else []


def _plain(v):
    if isinstance(v, dict):
        return {str(k): _plain(x) for k, x in v.items()}
    if isinstance(v, (list, tuple)):
        return [_plain(x) for x in v]
    if isinstance(v, (np.floating, float)):
        return float(v)
    if isinstance(v, (np.integer, int)) and not isinstance(v, bool):
        return int(v)
    return v


def save_path(path: CameraPath, file) -> Path:
    """Write ``file`` (TUM poses) and its sidecar ``<stem>.yaml``; returns the TUM file's path."""
    file = Path(file)
    if file.suffix.lower() == ".yaml":
        raise UserError(f"{file}: give the trajectory file (.txt); the .yaml sidecar is written next to it")
    if file.suffix == "":
        file = file.with_suffix(".txt")
    header = (f"camera path {path.name}: {len(path.poses)} frames at {path.fps:g} fps, camera-to-world, OpenCV axes "
              f"(x right, y down, z forward)\nt tx ty tz qx qy qz qw   (t = frame / fps); see {file.stem}.yaml")
    camera.write_tum(file, path.poses, fps=path.fps, header=header)
    meta = dict(path.meta)
    doc = {"format": FORMAT, "name": path.name, "kind": meta.pop("kind", None), "fps": float(path.fps),
           "frames": int(len(path.poses)), "poses": file.name}
    for key in ("seed", "layouts", "planner", "stats"):
        if key in meta:
            doc[key] = meta.pop(key)
    if meta:
        doc["meta"] = meta
    side = file.with_suffix(".yaml")
    write_text_atomic(side, yaml.safe_dump(_plain(doc), sort_keys=False, default_flow_style=None, width=110))
    return file


def _resolve(name_or_file) -> Path:
    s = str(name_or_file)
    p = Path(s)
    if p.suffix.lower() in (".txt", ".yaml", ".tum") or "/" in s or "\\" in s or p.exists():
        return p.with_suffix(".txt") if p.suffix.lower() == ".yaml" else p
    f = paths_dir() / f"{s}.txt"
    if not f.exists():
        known = list_paths()
        raise UnknownNameError(f"unknown camera path '{s}'; known paths: {', '.join(known) if known else '(none)'} "
                               f"(in {paths_dir()}), or give a file")
    return f


def load_path(name_or_file) -> CameraPath:
    """A saved path: a name (``scenes/paths/<name>.txt`` + ``.yaml``) or a file."""
    txt = _resolve(name_or_file)
    side = txt.with_suffix(".yaml")
    fps, meta, name, n_expect = camera.DEFAULT_FPS, {}, txt.stem, None
    if side.exists():
        try:
            doc = yaml.safe_load(side.read_text())
        except yaml.YAMLError as e:
            mark = getattr(e, "problem_mark", None)
            where = f"line {mark.line + 1}" if mark is not None else None
            raise SceneFormatError(side, where, f"not valid YAML ({getattr(e, 'problem', e)})") from None
        if not isinstance(doc, dict):
            raise SceneFormatError(side, None, "expected a mapping")
        if doc.get("format", FORMAT) != FORMAT:
            raise SceneFormatError(side, "format", f"expected '{FORMAT}', got {doc.get('format')!r}")
        fps = doc.get("fps", fps)
        if isinstance(fps, bool) or not isinstance(fps, (int, float)) or not (math.isfinite(fps) and fps > 0):
            raise SceneFormatError(side, "fps", f"expected a number > 0, got {fps!r}")
        fps = float(fps)
        n_expect = doc.get("frames")
        if n_expect is not None and (isinstance(n_expect, bool) or not isinstance(n_expect, int)):
            raise SceneFormatError(side, "frames", f"expected an integer, got {n_expect!r}")
        name = str(doc.get("name") or name)
        meta = {k: v for k, v in doc.items() if k not in ("format", "name", "fps", "frames", "poses")}
        meta.update(meta.pop("meta", None) or {})
    idx, poses = camera.read_tum(txt, fps=fps)
    if n_expect is not None and n_expect != len(poses):
        raise SceneFormatError(txt, None, f"{len(poses)} poses, but {side.name} says frames: {n_expect}")
    if side.exists() and len(idx) and not np.array_equal(idx, np.arange(len(idx))):
        bad = int(np.nonzero(idx != np.arange(len(idx)))[0][0])
        raise SceneFormatError(txt, f"pose {bad + 1}", f"timestamp gives frame {idx[bad]}, expected {bad} (t = frame / fps at {fps:g} fps)")
    return CameraPath(name, poses, fps, meta)


# --------------------------------------------------------------------------------------------
# summaries and previews


def _yaw_pitch(poses: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    z = np.asarray(poses)[:, :3, 2]
    return np.arctan2(z[:, 1], z[:, 0]), np.arcsin(np.clip(z[:, 2], -1, 1))


def path_summary(path: CameraPath, layout: Layout | None = None) -> dict:
    P = path.positions
    steps = np.linalg.norm(np.diff(P, axis=0), axis=1) if len(P) > 1 else np.zeros(0)
    yaw, pitch = _yaw_pitch(path.poses)
    rate = np.abs(np.diff(np.unwrap(yaw))) * path.fps if len(yaw) > 1 else np.zeros(0)
    out = {
        "name": path.name, "frames": len(path), "fps": path.fps, "length_m": round(path.length, 3),
        "duration_s": round(path.duration, 3),
        "mean_speed_mps": round(float(steps.mean() * path.fps), 4) if len(steps) else 0.0,
        "height_m": [round(float(P[:, 2].min()), 3), round(float(P[:, 2].max()), 3)] if len(P) else None,
        "pitch_deg": [round(float(np.degrees(pitch.min())), 2), round(float(np.degrees(pitch.max())), 2)] if len(P) else None,
        "max_yaw_rate_deg_s": round(float(np.degrees(rate.max())), 2) if len(rate) else 0.0,
        "kind": path.meta.get("kind"), "seed": path.meta.get("seed"), "layouts": path.meta.get("layouts"),
    }
    if layout is not None:
        rooms: dict[str, int] = {}
        for p in P:
            r = layout.stage.room_at(p[:2])
            if r is not None:
                rooms[r.name] = rooms.get(r.name, 0) + 1
        out["layout"] = layout.name
        out["rooms_frames"] = rooms
        out["min_clearance_m"] = round(float(path_clearance(path, layout).min()), 4) if len(P) else None
    return out


def plot_path(path: CameraPath, layout: Layout, out_path, dpi: float = 150, tick_every_s: float = 2.0) -> Path:
    """``preview.plot_layout``'s top-down plan with the path over it: coloured by frame, start marker, heading ticks."""

    import matplotlib
    from matplotlib import cm, colors
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.collections import LineCollection
    from matplotlib.figure import Figure

    from . import preview as pv

    out = Path(out_path)
    fmt = out.suffix.lower().lstrip(".") or "png"
    fig = Figure(dpi=dpi)
    FigureCanvasAgg(fig)
    if fmt not in fig.canvas.get_supported_filetypes():
        raise UserError(f"{out}: cannot write '.{fmt}' plots")
    plan = pv._plan(layout, None, None, dpi)
    fig.set_size_inches(plan.fig_w, plan.fig_h)
    ax = fig.add_axes((pv.LEFT / plan.fig_w, pv.BOTTOM / plan.fig_h, plan.ax_w / plan.fig_w, plan.ax_h / plan.fig_h))
    s = path_summary(path)
    title = (f"camera path {path.name} over {layout.name}: {s['frames']} frames, {s['length_m']:.1f} m, "
             f"{s['duration_s']:.1f} s")
    pv._draw(fig, ax, layout, None, None, plan, title, False)
    P = path.positions
    n = len(P)
    cmap = matplotlib.colormaps["viridis"]
    norm = colors.Normalize(0, max(n - 1, 1))
    if n > 1:
        segs = np.stack([P[:-1, :2], P[1:, :2]], axis=1)
        lc = LineCollection(segs, cmap=cmap, norm=norm, linewidths=1.8, zorder=9, capstyle="round")
        lc.set_array(np.arange(n - 1))
        ax.add_collection(lc)
    if n:
        every = max(1, int(round(tick_every_s * path.fps)))
        z = path.poses[::every, :3, 2]
        for p, d, i in zip(P[::every, :2], z[:, :2], range(0, n, every)):
            nd = np.linalg.norm(d)
            if nd < 1e-6:
                continue
            q = p + d / nd * 0.32
            ax.plot([p[0], q[0]], [p[1], q[1]], color=cmap(norm(i)), lw=1.1, zorder=9.5, solid_capstyle="butt")
            ax.plot([p[0]], [p[1]], marker="o", ms=1.8, color=cmap(norm(i)), zorder=9.6)
        ax.plot([P[0, 0]], [P[0, 1]], marker="o", ms=8, mfc="white", mec="black", mew=1.5, zorder=10)
        ax.plot([P[-1, 0]], [P[-1, 1]], marker="s", ms=6, mfc=cmap(1.0), mec="black", mew=1.0, zorder=10)
        ax.annotate("start", (P[0, 0], P[0, 1]), xytext=(6, 6), textcoords="offset points", fontsize=7.5,
                    fontweight="bold", zorder=10, path_effects=pv._halo())
    # colour bar of frame index, at the top right of the title band
    fw, fh = plan.fig_w, plan.fig_h
    cax = fig.add_axes((1.0 - 2.9 / fw, 1.0 - 0.42 / fh, 2.3 / fw, 0.1 / fh))
    cb = fig.colorbar(cm.ScalarMappable(norm=norm, cmap=cmap), cax=cax, orientation="horizontal")
    cb.ax.tick_params(labelsize=6.5, length=2)
    cb.set_label(f"frame (ticks: heading every {tick_every_s:g} s)", fontsize=7, labelpad=1)
    return pv.save_figure(fig, out, dpi)


# --------------------------------------------------------------------------------------------
# command line: `synth path ...`


def _layout(name):
    from .scene import load_layout

    return load_layout(name)


def _cmd_plan_query(args) -> int:
    lays = [_layout(n) for n in args.layouts]
    path = plan_query_path(lays, frames=args.frames, seed=args.seed, fps=args.fps, speed=args.speed,
                           clearance=args.clearance, obstacles=args.obstacles, name=args.name or Path(args.out).stem)
    out = save_path(path, args.out)
    st = path.meta["stats"]
    print(f"wrote {out} (+ {out.with_suffix('.yaml').name}): {len(path)} frames, {st['length_m']:.1f} m, "
          f"min clearance {st['min_clearance_m']:.3f} m over {len(lays)} layout(s)")
    return 0


def _cmd_plan_mapping(args) -> int:
    lay = _layout(args.layout)
    path = plan_mapping_path(lay, frames=args.frames, seed=args.seed, fps=args.fps, speed=args.speed,
                             clearance=args.clearance, obstacles=args.obstacles, name=args.name or Path(args.out).stem)
    out = save_path(path, args.out)
    st = path.meta["stats"]
    print(f"wrote {out} (+ {out.with_suffix('.yaml').name}): {len(path)} frames, {st['length_m']:.1f} m, "
          f"sweep spacing {path.meta['planner']['sweep_spacing_m']:.2f} m, min clearance {st['min_clearance_m']:.3f} m")
    return 0


def _default_layout(path: CameraPath, name):
    if name:
        return _layout(name)
    lays = path.meta.get("layouts") or []
    if lays:
        try:
            return _layout(lays[0])
        except UserError:
            return None
    return None


def _cmd_preview(args) -> int:
    path = load_path(args.path)
    lay = _default_layout(path, args.layout)
    if lay is None:
        raise UserError(f"path '{path.name}' names no layout it was planned on; give --layout")
    out = plot_path(path, lay, args.out)
    print(f"wrote {out}")
    return 0


def _cmd_show(args) -> int:
    import json

    path = load_path(args.path)
    lay = _default_layout(path, args.layout)
    s = path_summary(path, lay)
    if args.json:
        print(json.dumps(s, indent=2))
        return 0
    print(f"camera path {s['name']}" + (f" ({s['kind']}, seed {s['seed']})" if s.get("kind") else ""))
    if s.get("layouts"):
        print(f"  planned on: {', '.join(s['layouts'])}")
    print(f"  frames {s['frames']} at {s['fps']:g} fps: duration {s['duration_s']:.1f} s, length {s['length_m']:.1f} m, "
          f"mean speed {s['mean_speed_mps']:.2f} m/s")
    if s["height_m"]:
        print(f"  height {s['height_m'][0]:.2f}-{s['height_m'][1]:.2f} m, pitch {s['pitch_deg'][0]:.1f} to "
              f"{s['pitch_deg'][1]:.1f} deg, max yaw rate {s['max_yaw_rate_deg_s']:.0f} deg/s")
    if lay is not None:
        rooms = ", ".join(f"{r} ({n} frames)" for r, n in s["rooms_frames"].items())
        print(f"  rooms visited in {lay.name}: {rooms or 'none'}")
        c = declared_clearance(path)
        note = (f" (below the path's {c:g} m clearance: see `synth path check {args.path} --layout {args.layout or lay.name}`)"
                if c is not None and s["min_clearance_m"] is not None and s["min_clearance_m"] < c - CLEARANCE_TOL else "")
        print(f"  min clearance in {lay.name}: {s['min_clearance_m']:.3f} m{note}")
    else:
        print("  rooms visited: unknown (give --layout)")
    return 0


def _cmd_check(args) -> int:
    import json

    path = load_path(args.path)
    names = args.layout or [str(n) for n in path.meta.get("layouts") or []]
    if not names:
        raise UserError(f"camera path '{path.name}' names no layout it was planned on; give --layout")
    if args.clearance is not None and not (math.isfinite(args.clearance) and args.clearance >= 0):
        raise UserError(f"--clearance must be >= 0, got {args.clearance!r}")
    lays = []
    for n in names:
        try:
            lays.append(_layout(n))
        except UnknownNameError:
            if args.layout:
                raise
            raise UserError(f"camera path '{path.name}' was planned on layout '{n}', which is not in "
                            f"scenes/layouts; give its file with --layout") from None
    reps = [clearance_report(path, lay, args.clearance) for lay in lays]
    ok = all(r["ok"] for r in reps)
    if args.json:
        print(json.dumps({"path": path.name, "ok": ok, "layouts": reps}, indent=2))
        return 0 if ok else 1
    c = reps[0]["clearance_m"]
    if ok:
        worst = min(reps, key=lambda r: r["min_clearance_m"] if r["min_clearance_m"] is not None else np.inf)
        print(f"OK: camera path '{path.name}' keeps {c:g} m clearance in {', '.join(r['layout'] for r in reps)} "
              f"(min {worst['min_clearance_m']:.3f} m, in {worst['layout']} at frame {worst['min_frame']})")
        return 0
    for r, arg in zip(reps, names):
        if r["ok"]:
            print(f"{r['layout']}: ok (min {r['min_clearance_m']:.3f} m)")
            continue
        print(f"{r['layout']}: {r['frames_below']} frames closer than {c:g} m (min {r['min_clearance_m']:.3f} m at "
              f"frame {r['min_frame']}, {_what(r['nearest'])})")
        for rg in r["ranges"]:
            print(f"  {_range_text(rg)}")
    bad = [arg for r, arg in zip(reps, names) if not r["ok"]]
    print(f"PROBLEMS FOUND: camera path '{path.name}' breaks its {c:g} m clearance in {len(bad)} of {len(reps)} "
          f"layout(s); replan it: {replan_command(path, bad)}")
    return 1


def _cmd_generate(args) -> int:
    for f in generate_shipped(args.out_dir, args.only):
        p = load_path(f)
        st = p.meta["stats"]
        print(f"wrote {f} (+ .yaml): {len(p)} frames, {st['length_m']:.1f} m, min clearance {st['min_clearance_m']:.3f} m, "
              f"rooms {', '.join(st['rooms'])}")
    return 0


def register_cli(subparsers) -> None:
    """Add the ``path`` group to the ``synth`` command line."""
    grp = subparsers.add_parser("path", help="camera paths: plan (query, mapping), show, check, preview")
    sub = grp.add_subparsers(dest="cmd", required=True)
    plan = sub.add_parser("plan", help="plan a camera path and write it (TUM + .yaml)")
    ps = plan.add_subparsers(dest="kind", required=True)

    def common(a, frames):
        a.add_argument("--frames", type=int, default=frames)
        a.add_argument("--seed", type=int, default=0)
        a.add_argument("--fps", type=float, default=camera.DEFAULT_FPS)
        a.add_argument("--speed", type=float, default=1.0, help="m/s (default 1)")
        a.add_argument("--clearance", type=float, default=0.3, help="m from obstacles and walls (default 0.3)")
        a.add_argument("--obstacles", choices=("band", "all"), default="all",
                       help="all: every object but ceiling-mounted ones (default); band: objects reaching the camera height band")
        a.add_argument("--name", help="path name (default: the output file's stem)")
        a.add_argument("--out", required=True, help="trajectory file (.txt); the .yaml sidecar goes next to it")

    a = ps.add_parser("query", help="a walk through every room, clear of the objects of every layout given")
    a.add_argument("--layouts", nargs="+", required=True, metavar="LAYOUT")
    common(a, 4000)
    a.set_defaults(fn=_cmd_plan_query)
    a = ps.add_parser("mapping", help="a cross-hatch tour of one layout")
    a.add_argument("--layout", required=True)
    common(a, 6000)
    a.set_defaults(fn=_cmd_plan_mapping)
    a = sub.add_parser("generate", help="rewrite the shipped paths (scenes/paths: query, mapping)")
    a.add_argument("--out-dir", help="default: scenes/paths")
    a.add_argument("--only", nargs="*", choices=sorted(SHIPPED))
    a.set_defaults(fn=_cmd_generate)
    a = sub.add_parser("show", help="frames, length, duration, speed, heights, rooms visited")
    a.add_argument("path", help="path name (scenes/paths/NAME.txt) or file")
    a.add_argument("--layout", help="layout for rooms and clearance (default: the first it was planned on)")
    a.add_argument("--json", action="store_true")
    a.set_defaults(fn=_cmd_show)
    a = sub.add_parser("check", help="does the path keep its declared clearance in these layouts? (exit 1 if not)")
    a.add_argument("path", help="path name or file")
    a.add_argument("--layout", action="append", metavar="LAYOUT",
                   help="layout to check (repeat for several; default: the layouts it was planned on)")
    a.add_argument("--clearance", type=float, help="m (default: the clearance the path was planned with)")
    a.add_argument("--json", action="store_true")
    a.set_defaults(fn=_cmd_check)
    a = sub.add_parser("preview", help="top-down plot of a path over a layout")
    a.add_argument("path", help="path name or file")
    a.add_argument("--layout", help="default: the first layout it was planned on")
    a.add_argument("--out", required=True)
    a.set_defaults(fn=_cmd_preview)
