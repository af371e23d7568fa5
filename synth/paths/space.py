"""The planning space: an exact-clearance grid over the layouts' shared shell (``Space``), and what
both planners share about it: argument checks, reachability of every room, where walks start, and
the metadata record of a planned path.
"""

from __future__ import annotations

import math

import numpy as np

from vrformats.errors import UserError

from ..scene.model import Layout
from .clearance import Boxes, object_boxes, seg_dist, inside_free, path_clearance, room_index, wall_segments
from .model import BAND, CURVE_MARGIN, DCAP, GRID, MARGIN, MAX_YAW_RATE, PREFER

__all__ = ["Space"]


def _same_shell(layouts: list[Layout]) -> None:
    a = layouts[0].stage
    for lay in layouts[1:]:
        b = lay.stage
        same = (
            [(r.name, tuple(np.round(r.outline(), 6).ravel())) for r in a.rooms]
            == [(r.name, tuple(np.round(r.outline(), 6).ravel())) for r in b.rooms]
            and [(o.id, o.wall, round(o.offset, 6), round(o.width, 6)) for o in a.openings if o.kind == "door"]
            == [(o.id, o.wall, round(o.offset, 6), round(o.width, 6)) for o in b.openings if o.kind == "door"]
        )
        if not same:
            raise UserError(f"layouts '{layouts[0].name}' and '{lay.name}' do not share one shell (rooms, doors); "
                            "a shared path needs the same stage")


class Space:
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
        xs = [r.rect[0] for r in st.rooms] + [r.rect[2] for r in st.rooms] + [float(r.outline()[:, 0].min()) for r in st.rooms] \
            + [float(r.outline()[:, 0].max()) for r in st.rooms]
        ys = [r.rect[1] for r in st.rooms] + [r.rect[3] for r in st.rooms] + [float(r.outline()[:, 1].min()) for r in st.rooms] \
            + [float(r.outline()[:, 1].max()) for r in st.rooms]
        self.x0, self.y0 = min(xs) - 0.3, min(ys) - 0.3
        self.nx = int(math.ceil((max(xs) + 0.3 - self.x0) / grid))
        self.ny = int(math.ceil((max(ys) + 0.3 - self.y0) / grid))
        gx, gy = np.meshgrid(self.x0 + (np.arange(self.nx) + 0.5) * grid, self.y0 + (np.arange(self.ny) + 0.5) * grid)
        pts = np.stack([gx.ravel(), gy.ravel()], axis=1)
        self.pts = pts
        self.segs = wall_segments(st)
        inside = inside_free(st, pts)  # the checker's free space (synth.paths.clearance), cell by cell
        dist = np.minimum(seg_dist(pts, self.segs), DCAP)
        dist[~inside] = 0.0
        dist = dist.reshape(self.ny, self.nx)
        self.shell = dist.copy()  # walls only: what an empty room allows
        occ = np.zeros((self.ny, self.nx))
        self.boxes: list[Boxes] = []
        for lay in layouts:
            all_boxes = object_boxes(lay, obstacles)
            if obstacles == "band":
                hit = [b for b in all_boxes if b.zmax > zlo - BAND and b.zmin < zhi + BAND]
                low = [b for b in all_boxes if not (b.zmax > zlo - BAND and b.zmin < zhi + BAND) and b.zmax < zlo]
            else:
                hit, low = all_boxes, []
            bx = Boxes.of(hit)
            self.boxes.append(bx)
            self._splat(dist, bx, DCAP, np.minimum)
            lo = np.full((self.ny, self.nx), DCAP)
            self._splat(lo, Boxes.of(low), 0.6, np.minimum)
            occ += lo < 0.25  # near low furniture in this layout: walking there means climbing over it
        self.dist = dist
        self.occ = occ / len(layouts)
        self.walk = dist >= clearance + MARGIN
        # rooms per cell
        self.room = room_index(st, pts).reshape(self.ny, self.nx)
        # rooms no camera fits in even when empty (a niche, a strip of floor narrower than twice the
        # clearance, a room whose interior lies inside another room's): not required, recorded
        fits = set(np.unique(self.room[self.shell >= clearance + MARGIN])) - {-1}
        self.skipped = [r.name for k, r in enumerate(st.rooms) if k not in fits]
        self.required = [k for k in range(len(st.rooms)) if k in fits]
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
    def _splat(self, field_: np.ndarray, bx: Boxes, reach: float, op) -> None:
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
            one = Boxes(bx.c[k : k + 1], bx.h[k : k + 1], bx.cs[k : k + 1], bx.zmin[k : k + 1], bx.zmax[k : k + 1])
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
        d = seg_dist(xy, self.segs)
        for bx in self.boxes:
            np.minimum(d, bx.dist(xy), out=d)
        d[~inside_free(self.stage, xy)] = 0.0
        return d

    def room_of(self, xy: np.ndarray) -> np.ndarray:
        return room_index(self.stage, xy)

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
        seg = grid_line(self.xy(a), self.xy(b))
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


def grid_line(a: np.ndarray, b: np.ndarray, step: float = GRID) -> np.ndarray:
    n = max(1, int(math.ceil(np.linalg.norm(b - a) / step)))
    return a + (b - a) * np.linspace(0.0, 1.0, n + 1)[:, None]


# --------------------------------------------------------------------------------------------
# shared by both planners


def start_cell(space: Space) -> int:
    """Where walks begin: inside the entrance door (a door with one room), else the first room's best cell."""
    st = space.stage
    for op in st.openings:
        if op.kind == "door" and len(op.rooms) == 1:
            w = st.wall(op.wall)
            c = op.center_xy(w)
            r = st.room(op.rooms[0])
            n = np.array([-w.direction[1], w.direction[0]])
            if r.polygon is None:
                mid = np.array([(r.rect[0] + r.rect[2]) / 2, (r.rect[1] + r.rect[3]) / 2])
                if n @ (mid - c) < 0:
                    n = -n
            else:  # the side of the door the room's interior is on
                ins = [float(r.contains(c + s * n * dd).sum()) for s in (1, -1) for dd in (0.5, 1.0)]
                if ins[2] + ins[3] > ins[0] + ins[1]:
                    n = -n
            return space.snap(c + n * 1.0)
    m = space.comp
    i, j = np.unravel_index(int(np.argmax(np.where(m, space.dist, -1))), m.shape)
    return int(i * space.nx + j)


def check_args(frames, fps, speed, clearance):
    if not (isinstance(frames, (int, np.integer)) and frames >= 2):
        raise UserError(f"frames must be an integer >= 2, got {frames!r}")
    for nm, v in (("fps", fps), ("speed", speed)):
        if not (math.isfinite(v) and v > 0):
            raise UserError(f"{nm} must be > 0, got {v!r}")
    if not (math.isfinite(clearance) and clearance >= 0):
        raise UserError(f"clearance must be >= 0, got {clearance!r}")


def require_rooms(space: Space, what: str) -> None:
    """Every room a camera fits in (``Space.required``) must be in the walkable component; else say
    which, how much clearance each one's roomiest spot has and at what clearance it would connect."""
    have = set(np.unique(space.room[space.comp])) - {-1}
    missing = [k for k in space.required if k not in have]
    if missing:
        names = ", ".join(l.name for l in space.layouts)
        best = _max_connecting_clearance(space) - MARGIN
        hint = (f"; the most these layouts allow is about {math.floor(best * 100) / 100:.2f} m" if best > 0.05 else "")
        where = []
        for k in missing:
            m = space.room == k
            i, j = np.unravel_index(int(np.argmax(np.where(m, space.dist, -1.0))), m.shape)
            x, y = space.xy(i * space.nx + j)
            reach = _joining_clearance(space, k) - MARGIN
            where.append(f"{space.stage.rooms[k].name} (roomiest spot ({x:.2f}, {y:.2f}) with {space.dist[i, j]:.2f} m; "
                         f"joins the others at up to {max(reach, 0.0):.2f} m)")
        raise UserError(f"{what}: room(s) {', '.join(where)} cannot be reached with {space.clearance:g} m clearance "
                        f"(obstacles '{space.obstacles}') in every layout ({names}){hint}")


def _max_connecting_clearance(space: Space) -> float:
    """The largest clearance at which one walkable component still reaches every required room (bisection)."""
    from scipy import ndimage

    need = set(space.required)

    def ok(th):
        lab, n = ndimage.label(space.dist >= th, structure=np.ones((3, 3), bool))
        for c in range(1, n + 1):
            if need <= set(np.unique(space.room[lab == c])):
                return True
        return False
    return _bisect(ok, float(space.dist.max()))


def _joining_clearance(space: Space, k: int) -> float:
    """The largest clearance at which room ``k`` joins the walkable component (bisection)."""
    from scipy import ndimage

    def ok(th):
        lab, _ = ndimage.label(space.dist >= th, structure=np.ones((3, 3), bool))
        joined = set(np.unique(lab[space.comp])) - {0}
        return bool(np.isin(lab[space.room == k], list(joined)).any())
    return _bisect(ok, space.clearance + MARGIN)


def _bisect(ok, hi: float) -> float:
    lo = 0.0
    if not ok(lo + 1e-6):
        return 0.0
    for _ in range(12):
        mid = (lo + hi) / 2
        lo, hi = (mid, hi) if ok(mid) else (lo, mid)
    return lo


def path_meta(kind, layouts, seed, frames, fps, speed, clearance, obstacles, space, path, extra) -> dict:
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
            **({"rooms_skipped": list(space.skipped)} if space.skipped else {}),  # no camera fits in them
        },
    }
