"""Top-down previews of layouts: a floor plan a person can check at a glance (matplotlib, no Blender).

``plot_layout`` draws one layout seen from above, north (+Y) up, metres on both axes:

* room floors shaded by room type, with the room's name and area in a free corner;
* walls as dark bands of their true thickness; doors as gaps with the door leaf and its swing
  arc, windows as light-blue panes in the wall;
* every object's gravity-aligned box footprint (``synth.scene.model.object_box``), filled with the
  colour of its class (``class_color``: fixed per class, the same in every plot), objects that
  stand on other objects drawn over them, a short tick on the front (local +Y) of floor
  furniture, ceiling fixtures as dashed outlines over everything;
* short class labels on footprints larger than ``LABEL_MIN_AREA`` where they do not collide;
* a legend of the classes present (with counts) to the right of the plan.

With ``ref`` the plot is a diff: it shows the variant ``layout`` and marks what changed against
the reference (``diff_layouts``): moved objects with an arrow from the old box centre to the new
one and the old footprint dashed, added objects with a thick green outline and a "+", removed
objects (taken from ``ref``) as red dashed footprints with an "x".

The figure's pixel size depends only on the layout's extent and the legend; ``figure_size``
returns it without drawing. Files are written atomically (temporary file, then rename); the
format follows the extension (png, pdf, svg, ...).
"""

from __future__ import annotations

import math
import zlib
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from matplotlib import patheffects
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure
from matplotlib.legend_handler import HandlerPatch
from matplotlib.patches import Arc, FancyArrowPatch, Patch, Polygon, Rectangle
from matplotlib.ticker import MultipleLocator
from matplotlib.transforms import Bbox

from vrformats.atomic import save_figure
from vrformats.errors import UserError

from . import geometry as geo
from .model import Layout, Stage, Wall, object_box

__all__ = ["plot_layout", "diff_layouts", "figure_size", "class_color", "room_color", "LABEL_MIN_AREA", "BIG_MOVE"]

LABEL_MIN_AREA = 0.05  # m2: smaller footprints get no label
BIG_MOVE = 0.5  # m: moves counted separately in the title

# --------------------------------------------------------------------------------------------
# colours

# One fixed colour per class of scenes/classes.yaml (Tableau 20 / ColorBrewer qualitative
# colours). Classes that are usually seen together (a living room, a kitchen, a bedroom, a
# bathroom) get clearly different hues.
CLASS_COLORS: dict[str, str] = {
    "sofa": "#4e79a7",
    "armchair": "#a0cbe8",
    "chair": "#f28e2b",
    "stool": "#ffbe7d",
    "bench": "#bcbd22",
    "dining_table": "#b6992d",
    "coffee_table": "#9c755f",
    "side_table": "#e3c9b3",
    "desk": "#2a9d8f",
    "bed": "#b07aa1",
    "nightstand": "#d37295",
    "wardrobe": "#6b6ecf",
    "bookshelf": "#8c6d31",
    "cabinet": "#637939",
    "tv_stand": "#843c39",
    "tv": "#393b79",
    "kitchen_counter": "#a9a39c",
    "fridge": "#e0f3f8",
    "stove": "#e15759",
    "toilet": "#76b7b2",
    "bathtub": "#9c9ede",
    "washbasin": "#08519c",
    "floor_lamp": "#edc948",
    "table_lamp": "#fff2ae",
    "ceiling_light": "#e6ab02",
    "plant": "#59a14f",
    "small_plant": "#a1d99b",
    "cushion": "#ff9da7",
    "book": "#ce6dbd",
    "vase": "#17becf",
    "bowl": "#d9d9f3",
    "picture": "#fcd5e3",
    "mirror": "#b3e2cd",
    "bin": "#7f7f7f",
    "shoe_rack": "#a55194",
    "laptop": "#58595b",
    "basket": "#c49c94",
    "other": "#d0d0d0",
    # the ReplicaCAD apartments' own classes
    "door": "#8b5a2b",
    "cup": "#e6550d",
    "plate": "#fdd0a2",
    "kitchen_utensil": "#31a354",
    "cookware": "#636363",
    "small_appliance": "#3182bd",
    "shoe": "#756bb1",
    "box": "#bcbddc",
    "cloth": "#de9ed6",
    "bike": "#e7298a",
    "rug": "#c7e9c0",
    "clock": "#fd8d3c",
    "electronics": "#252525",
    "bag": "#a63603",
    "umbrella": "#6baed6",
    "rack": "#9e9ac8",
    "wall_cabinet": "#74c476",
    "kitchen_item": "#fdae6b",
}
# classes without a fixed colour pick one of these by a hash of their name (stable across runs)
_FALLBACK = (
    "#1f77b4", "#ff7f0e", "#2ca02c", "#d62728", "#9467bd", "#8c564b", "#e377c2", "#17becf",
    "#aec7e8", "#ffbb78", "#98df8a", "#ff9896", "#c5b0d5", "#c49c94", "#f7b6d2", "#9edae5",
    "#393b79", "#637939", "#8c6d31", "#843c39", "#7b4173", "#5254a3", "#8ca252", "#bd9e39",
)

ROOM_COLORS: dict[str, str] = {
    "living": "#f8f1dc",
    "kitchen": "#fbe6d4",
    "dining": "#f9ead3",
    "bedroom": "#e5ebf7",
    "bathroom": "#dcf0f0",
    "hallway": "#ececec",
    "corridor": "#ececec",
    "entrance": "#ececec",
    "office": "#e6f2df",
    "study": "#e6f2df",
    "storage": "#efe8df",
    "closet": "#efe8df",
}
_ROOM_FALLBACK = ("#f3e9f2", "#e9f3ea", "#f4efe2", "#e8eef3", "#f2e8e3")

WALL_COLOR = "#333333"
DOOR_COLOR = "#5a5a5a"
WINDOW_COLOR = "#5fa8dc"
MOVED_COLOR = "#5e3c99"
ADDED_COLOR = "#1a9850"
REMOVED_COLOR = "#d73027"
TEXT_COLOR = "#222222"


def class_color(cls: str) -> str:
    """The fill colour of a class: the same in every plot."""
    if cls in CLASS_COLORS:
        return CLASS_COLORS[cls]
    return _FALLBACK[zlib.crc32(cls.encode()) % len(_FALLBACK)]


def room_color(room_type: str) -> str:
    if room_type in ROOM_COLORS:
        return ROOM_COLORS[room_type]
    return _ROOM_FALLBACK[zlib.crc32(room_type.encode()) % len(_ROOM_FALLBACK)]


def _darker(color: str, f: float = 0.6) -> tuple[float, float, float]:
    c = color.lstrip("#")
    rgb = [int(c[i : i + 2], 16) / 255.0 for i in (0, 2, 4)]
    return tuple(v * f for v in rgb)


# --------------------------------------------------------------------------------------------
# diff


def diff_layouts(ref: Layout, var: Layout, moved_threshold: float = 0.1) -> dict:
    """What changed from ``ref`` to ``var``, matching objects by id.

    Returns ``{"moved": [(id, from_xyz, to_xyz, dist)], "added": [ids], "removed": [ids]}``:
    ``moved`` lists the objects in both layouts whose box centre (``object_box``, 3D) moved by
    more than ``moved_threshold`` metres, ``added`` the ids only in ``var``, ``removed`` the ids
    only in ``ref``; all sorted by id.
    """
    r, v = ref.by_id(), var.by_id()
    moved = []
    for oid in sorted(set(r) & set(v)):
        a = tuple(float(x) for x in object_box(r[oid]).center)
        b = tuple(float(x) for x in object_box(v[oid]).center)
        d = math.dist(a, b)
        if d > moved_threshold:
            moved.append((oid, a, b, d))
    return {"moved": moved, "added": sorted(set(v) - set(r)), "removed": sorted(set(r) - set(v))}


# --------------------------------------------------------------------------------------------
# geometry of the plan


def _wall_rect(wall: Wall, a: float, b: float) -> np.ndarray:
    """Corners of the part [a, b] (metres along the wall from its start) of a wall's band."""
    s = np.asarray(wall.start, dtype=float)
    d = wall.direction
    n = np.array([-d[1], d[0]]) * wall.thickness / 2.0
    p, q = s + d * a, s + d * b
    return np.array([p - n, q - n, q + n, p + n])


def _point_segment_dist(p, a, b) -> float:
    p, a, b = (np.asarray(v, dtype=float) for v in (p, a, b))
    ab = b - a
    t = float(np.clip(np.dot(p - a, ab) / max(np.dot(ab, ab), 1e-12), 0.0, 1.0))
    return float(np.linalg.norm(p - (a + t * ab)))


def _end_extensions(wall: Wall, walls: list[Wall]) -> tuple[float, float]:
    """How far to extend a wall band past its ends so that it closes the corner with a wall it meets."""
    ext = []
    for p in (wall.start, wall.end):
        joins = any(
            o is not wall and _point_segment_dist(p, o.start, o.end) <= o.thickness / 2.0 + 1e-3 for o in walls
        )
        ext.append(wall.thickness / 2.0 if joins else 0.0)
    return ext[0], ext[1]


@dataclass
class _WallPart:
    kind: str  # solid | door | window
    wall: Wall
    a: float
    b: float
    opening: object = None


def _wall_parts(stage: Stage) -> list[_WallPart]:
    parts = []
    for w in stage.walls:
        L = w.length
        e0, e1 = _end_extensions(w, stage.walls)
        cuts = []
        for o in stage.openings:
            if o.wall != w.id:
                continue
            a, b = max(0.0, o.offset - o.width / 2.0), min(L, o.offset + o.width / 2.0)
            if b > a:
                cuts.append((a, b, o))
        cuts.sort(key=lambda c: c[0])
        pos = -e0
        for a, b, o in cuts:
            if a > pos:
                parts.append(_WallPart("solid", w, pos, a))
            parts.append(_WallPart(o.kind, w, a, b, o))
            pos = max(pos, b)
        if L + e1 > pos:
            parts.append(_WallPart("solid", w, pos, L + e1))
    return parts


def _door_swing(stage: Stage, part: _WallPart):
    """Hinge point, unit leaf direction, unit wall direction and radius of a door's swing."""
    w, o = part.wall, part.opening
    d = w.direction
    n = np.array([-d[1], d[0]])
    side = 1.0
    mid = np.asarray(w.start, dtype=float) + d * (part.a + part.b) / 2.0
    if o.rooms:
        probe = mid + n * (w.thickness / 2.0 + 0.25)
        room = stage.room_at(probe)
        if room is None or room.name != o.rooms[0]:
            room_other = stage.room_at(mid - n * (w.thickness / 2.0 + 0.25))
            if room_other is not None and room_other.name == o.rooms[0]:
                side = -1.0
    ns = n * side
    hinge = np.asarray(w.start, dtype=float) + d * part.a + ns * w.thickness / 2.0
    return hinge, ns, d, part.b - part.a


def _object_levels(layout: Layout) -> dict[int, int]:
    """How many objects each object stands on (0 on the floor, 1 on a table, 2 on a book on a table)."""
    by_id = layout.by_id()
    levels: dict[int, int] = {}
    for o in layout.objects:
        lvl, cur, seen = 0, o, {o.id}
        while (par := cur.support_parent()) is not None and par[0] in by_id and par[0] not in seen:
            lvl += 1
            seen.add(par[0])
            cur = by_id[par[0]]
        levels[o.id] = lvl
    return levels


def _extent(layout: Layout, ref: Layout | None) -> tuple[float, float, float, float] | None:
    pts = []
    st = layout.stage
    for r in st.rooms:
        pts += [(r.rect[0], r.rect[1]), (r.rect[2], r.rect[3])]
    for part in _wall_parts(st):
        pts += list(_wall_rect(part.wall, part.a, part.b))
    for lay in (layout, ref):
        if lay is None:
            continue
        for o in lay.objects:
            pts += list(object_box(o).corners_2d())
    if not pts:
        return None
    p = np.asarray(pts, dtype=float)
    return float(p[:, 0].min()), float(p[:, 1].min()), float(p[:, 0].max()), float(p[:, 1].max())


# --------------------------------------------------------------------------------------------
# figure plan (sizes in inches; the same numbers for figure_size and plot_layout)

PAD = 0.35  # m around the plan
MAX_AX_W, MAX_AX_H = 11.0, 8.5  # in
MAX_SCALE = 1.25  # in per metre
MIN_AX = 3.2  # in
LEFT, BOTTOM, GAP_R, RIGHT = 0.7, 0.55, 0.25, 0.2
TITLE_LINE = 0.24
LEGEND_FS = 7.5
LEGEND_ROW = LEGEND_FS / 72.0 * 1.75  # in per legend row
LEGEND_TITLE = 0.32


@dataclass
class _Plan:
    xlim: tuple[float, float]
    ylim: tuple[float, float]
    scale: float  # in per metre
    ax_w: float
    ax_h: float
    title_lines: int
    legend_entries: list[tuple[str, str]]  # (kind, label)
    legend_cols: int
    legend_w: float
    fig_w: float
    fig_h: float
    width_px: int
    height_px: int


def _legend_entries(layout: Layout, diff: dict | None) -> list[tuple[str, str]]:
    entries = []
    if diff is not None:
        n_big = sum(1 for m in diff["moved"] if m[3] > BIG_MOVE)
        entries.append(("moved", f"moved ({len(diff['moved'])}, >{BIG_MOVE:g} m: {n_big})"))
        entries.append(("moved_old", "old place of moved"))
        entries.append(("added", f"added ({len(diff['added'])})"))
        entries.append(("removed", f"removed ({len(diff['removed'])})"))
    counts: dict[str, int] = {}
    for o in layout.objects:
        counts[o.cls] = counts.get(o.cls, 0) + 1
    on_ceiling = {o.cls for o in layout.objects if o.support == "ceiling"}
    on_ceiling -= {o.cls for o in layout.objects if o.support != "ceiling"}
    for cls in sorted(counts):
        entries.append(("ceiling:" + cls if cls in on_ceiling else "class:" + cls, f"{cls.replace('_', ' ')} ({counts[cls]})"))
    return entries


def _plan(layout: Layout, ref: Layout | None, diff: dict | None, dpi: float) -> _Plan:
    ext = _extent(layout, ref)
    if ext is None:
        ext = (-2.0, -2.0, 2.0, 2.0)
    x0, y0, x1, y1 = ext[0] - PAD, ext[1] - PAD, ext[2] + PAD, ext[3] + PAD
    W, H = max(x1 - x0, 1.0), max(y1 - y0, 1.0)
    s = min(MAX_AX_W / W, MAX_AX_H / H, MAX_SCALE)
    ax_w, ax_h = max(W * s, MIN_AX), max(H * s, MIN_AX)
    cx, cy = (x0 + x1) / 2.0, (y0 + y1) / 2.0
    xlim = (cx - ax_w / s / 2.0, cx + ax_w / s / 2.0)
    ylim = (cy - ax_h / s / 2.0, cy + ax_h / s / 2.0)

    title_lines = 3 if diff is not None else 2
    entries = _legend_entries(layout, diff)
    if entries:
        rows_fit = max(1, int((ax_h - LEGEND_TITLE) / LEGEND_ROW))
        cols = math.ceil(len(entries) / rows_fit)
        longest = max(len(lbl) for _, lbl in entries)
        col_w = 0.55 + longest * LEGEND_FS / 72.0 * 0.58
        legend_w = cols * col_w + 0.15
    else:
        cols, legend_w = 0, 0.9
    fig_w = LEFT + ax_w + GAP_R + legend_w + RIGHT
    fig_w = max(fig_w, 6.2)  # room for the title lines
    fig_h = BOTTOM + ax_h + 0.2 + title_lines * TITLE_LINE + 0.1
    w_px, h_px = int(round(fig_w * dpi)), int(round(fig_h * dpi))
    return _Plan(xlim, ylim, s, ax_w, ax_h, title_lines, entries, cols, legend_w,
                 (w_px + 0.25) / dpi, (h_px + 0.25) / dpi, w_px, h_px)


def figure_size(layout: Layout, ref: Layout | None = None, dpi: float = 150, moved_threshold: float = 0.1) -> tuple[int, int]:
    """(width, height) in pixels of the PNG that ``plot_layout`` writes for these arguments."""
    diff = diff_layouts(ref, layout, moved_threshold) if ref is not None else None
    p = _plan(layout, ref, diff, dpi)
    return p.width_px, p.height_px


# --------------------------------------------------------------------------------------------
# drawing


def _halo(width: float = 2.2):
    return [patheffects.withStroke(linewidth=width, foreground="white", alpha=0.85)]


def _short_label(cls: str) -> str:
    return cls.replace("_", " ")


class _Labeler:
    """Places text labels without overlapping each other (display-coordinate boxes)."""

    def __init__(self, fig, ax):
        self.fig, self.ax = fig, ax
        self.renderer = fig.canvas.get_renderer()
        self.taken: list[Bbox] = []
        self._arr: np.ndarray | None = None  # self.taken as an (n, 4) array, rebuilt when it grows
        self.ax_box = ax.get_window_extent(self.renderer)

    def extent(self, t) -> Bbox:
        return t.get_window_extent(self.renderer).expanded(1.06, 1.1)

    def free(self, bb: Bbox) -> bool:
        if not (self.ax_box.x0 <= bb.x0 and bb.x1 <= self.ax_box.x1 and self.ax_box.y0 <= bb.y0 and bb.y1 <= self.ax_box.y1):
            return False
        if not self.taken:
            return True
        if self._arr is None or len(self._arr) != len(self.taken):
            self._arr = np.array([[o.x0, o.y0, o.x1, o.y1] for o in self.taken])
        a = self._arr  # strict overlap, as Bbox.overlaps
        hit = (bb.x0 < a[:, 2]) & (bb.x1 > a[:, 0]) & (bb.y0 < a[:, 3]) & (bb.y1 > a[:, 1])
        return not hit.any()

    def block_point(self, xy, radius_pt: float) -> None:
        """Keep labels off a marker drawn at data point ``xy``."""
        x, y = self.ax.transData.transform(xy)
        r = radius_pt * self.fig.dpi / 72.0
        self.taken.append(Bbox([[x - r, y - r], [x + r, y + r]]))

    def block_segment(self, a, b, half_width_pt: float) -> None:
        """Keep labels off a line (an arrow) from data point ``a`` to ``b``."""
        pa, pb = self.ax.transData.transform([a, b])
        r = half_width_pt * self.fig.dpi / 72.0
        n = max(2, int(np.linalg.norm(pb - pa) / r) + 1)
        for t in np.linspace(0.0, 1.0, n):
            x, y = pa + t * (pb - pa)
            self.taken.append(Bbox([[x - r, y - r], [x + r, y + r]]))

    def place(self, candidates, make) -> object | None:
        """Try the candidate (x, y, text, rotation) in order; keep the first that is free."""
        for x, y, text, rot in candidates:
            t = make(x, y, text, rot)
            bb = self.extent(t)
            if self.free(bb):
                self.taken.append(bb)
                return t
            t.remove()
        return None


def _object_label_candidates(box, cls: str, scale: float, fontsize: float):
    """Candidate label positions: centre (one line, two lines, turned), then just above/below."""
    c = box.corners_2d()
    cx, cy = float(box.center[0]), float(box.center[1])
    w_m = float(c[:, 0].max() - c[:, 0].min())
    h_m = float(c[:, 1].max() - c[:, 1].min())
    one = _short_label(cls)
    two = one.replace(" ", "\n", 1)
    char_m = fontsize / 72.0 * 0.6 / scale  # rough width of a character in metres
    line_m = fontsize / 72.0 * 1.25 / scale
    cands = []
    fits_one = len(one) * char_m <= w_m * 1.05
    fits_two = max(len(s) for s in two.split("\n")) * char_m <= w_m * 1.05
    if fits_one or not (h_m > 1.5 * w_m):
        cands.append((cx, cy, one if fits_one or two == one or not fits_two else two, 0))
    if h_m > 1.5 * w_m:
        cands.append((cx, cy, one, 90))
    cands.append((cx, cy, two if two != one else one, 0))
    for k in (1.1, -1.1, 2.0, -2.0):
        cands.append((cx, cy + line_m * k, one, 0))
    for fy in (0.0, 0.3, -0.3):  # elsewhere inside larger footprints
        for fx in (-0.25, 0.25):
            cands.append((cx + fx * w_m, cy + fy * h_m, one if fits_one else two, 0))
    seen, out = set(), []
    for cand in cands:
        if cand not in seen:
            seen.add(cand)
            out.append(cand)
    return out


def plot_layout(layout: Layout, out_path, ref: Layout | None = None, title: str | None = None, labels: bool = True,
                dpi: float = 150, moved_threshold: float = 0.1) -> Path:
    """Draw ``layout`` from above (a diff against ``ref`` when given) and write it to ``out_path``.

    The format follows the extension (png, pdf, svg, ...; no extension: png). The parent folder
    is created; the file is written to a temporary name and renamed. Returns the path.
    """
    out = Path(out_path)
    fmt = out.suffix.lower().lstrip(".") or "png"
    fig = Figure(dpi=dpi)
    FigureCanvasAgg(fig)
    supported = fig.canvas.get_supported_filetypes()
    if fmt not in supported:
        raise UserError(f"{out}: cannot write '.{fmt}' plots; use one of: {', '.join(sorted(supported))}")

    diff = diff_layouts(ref, layout, moved_threshold) if ref is not None else None
    plan = _plan(layout, ref, diff, dpi)
    fig.set_size_inches(plan.fig_w, plan.fig_h)
    ax = fig.add_axes((LEFT / plan.fig_w, BOTTOM / plan.fig_h, plan.ax_w / plan.fig_w, plan.ax_h / plan.fig_h))
    _draw(fig, ax, layout, ref, diff, plan, title, labels)

    return save_figure(fig, out, dpi)


def _draw(fig, ax, layout: Layout, ref: Layout | None, diff: dict | None, plan: _Plan, title: str | None, labels: bool):
    st = layout.stage
    s = plan.scale
    ax.set_xlim(*plan.xlim)
    ax.set_ylim(*plan.ylim)
    ax.set_aspect("equal", adjustable="box")
    span = max(plan.xlim[1] - plan.xlim[0], plan.ylim[1] - plan.ylim[0])
    step = 1.0 if span <= 20 else 2.0 if span <= 40 else 5.0
    ax.xaxis.set_major_locator(MultipleLocator(step))
    ax.yaxis.set_major_locator(MultipleLocator(step))
    ax.tick_params(labelsize=7, length=3, color="#888888", labelcolor="#555555")
    ax.set_xlabel("x [m]", fontsize=7.5, color="#555555", labelpad=2)
    ax.set_ylabel("y [m]  (north up)", fontsize=7.5, color="#555555", labelpad=2)
    ax.grid(True, color="#e4e4e4", lw=0.5, zorder=0)
    ax.set_axisbelow(True)
    for sp in ax.spines.values():
        sp.set_color("#bbbbbb")
        sp.set_linewidth(0.6)

    if not st.rooms and not st.walls and not layout.objects and not (ref is not None and ref.objects):
        ax.text(0.5, 0.5, "empty layout", transform=ax.transAxes, ha="center", va="center", fontsize=10,
                color="#999999", style="italic")

    # floors
    for r in st.rooms:
        x0, y0, x1, y1 = r.rect
        ax.add_patch(Rectangle((x0, y0), x1 - x0, y1 - y0, facecolor=room_color(r.type),
                               edgecolor="none" if st.walls else "#9a9a9a", lw=0.6, zorder=1))

    # walls, doors, windows
    parts = _wall_parts(st)
    for part in parts:
        poly = _wall_rect(part.wall, part.a, part.b)
        if part.kind == "solid":
            ax.add_patch(Polygon(poly, closed=True, facecolor=WALL_COLOR, edgecolor=WALL_COLOR, lw=0.3, zorder=2))
        elif part.kind == "window":
            ax.add_patch(Polygon(poly, closed=True, facecolor="#eef6fc", edgecolor="#4a7fa8", lw=0.5, zorder=2))
            w = part.wall
            sxy, d = np.asarray(w.start, dtype=float), w.direction
            a, b = sxy + d * part.a, sxy + d * part.b
            ax.plot([a[0], b[0]], [a[1], b[1]], color=WINDOW_COLOR, lw=1.6, solid_capstyle="butt", zorder=2.1)
        else:  # door: a gap, the leaf and its swing arc
            hinge, ns, d, r = _door_swing(st, part)
            tip = hinge + ns * r
            ax.plot([hinge[0], tip[0]], [hinge[1], tip[1]], color=DOOR_COLOR, lw=1.1, solid_capstyle="butt", zorder=2.2)
            a_d, a_n = math.degrees(math.atan2(d[1], d[0])), math.degrees(math.atan2(ns[1], ns[0]))
            cross = d[0] * ns[1] - d[1] * ns[0]
            t1, t2 = (a_d, a_n) if cross > 0 else (a_n, a_d)
            ax.add_patch(Arc(tuple(hinge), 2 * r, 2 * r, theta1=t1, theta2=t2, color=DOOR_COLOR, lw=0.6, zorder=2.2))

    # objects, lowest first; objects on objects after their supports; ceiling fixtures last
    levels = _object_levels(layout)
    boxes = {o.id: object_box(o) for o in layout.objects}
    ceiling = [o for o in layout.objects if o.support == "ceiling"]
    ground = [o for o in layout.objects if o.support != "ceiling"]
    ground.sort(key=lambda o: (levels[o.id], boxes[o.id].zmax, o.id))
    moved = {m[0]: m for m in diff["moved"]} if diff else {}
    added = set(diff["added"]) if diff else set()
    ticks = []
    for o in ground:
        b = boxes[o.id]
        col = class_color(o.cls)
        edge, lw = _darker(col), 0.6
        if o.id in moved:
            edge, lw = MOVED_COLOR, 1.3
        ax.add_patch(Polygon(b.corners_2d(), closed=True, facecolor=col, edgecolor=edge, lw=lw, zorder=3, joinstyle="miter"))
        if o.id in added:
            ax.add_patch(Polygon(b.corners_2d(), closed=True, fill=False, edgecolor=ADDED_COLOR, lw=2.4, zorder=3.01, joinstyle="miter"))
        if o.support == "floor":
            R = geo.quat_to_matrix(o.rotation)
            f = np.asarray(R[:2, 1], dtype=float)
            if np.linalg.norm(f) > 1e-6:
                f /= np.linalg.norm(f)
                c = np.asarray(b.center[:2])
                reach = float(((b.corners_2d() - c) @ f).max())
                tick = min(0.14, 0.45 * reach + 0.03)
                p0, p1 = c + f * (reach - 0.5 * tick), c + f * (reach + tick)
                ax.plot([p0[0], p1[0]], [p0[1], p1[1]], color=_darker(col, 0.45), lw=1.2, solid_capstyle="butt", zorder=3)
                ticks.append((p0, p1))
    for o in ceiling:
        b = boxes[o.id]
        ax.add_patch(Polygon(b.corners_2d(), closed=True, facecolor="none", edgecolor=_darker(class_color(o.cls), 0.75),
                             lw=1.0, ls=(0, (1, 1.2)), zorder=5))

    # diff marks
    if diff is not None:
        rb = ref.by_id()
        for oid, a, bpos, dist in diff["moved"]:
            old = object_box(rb[oid])
            ax.add_patch(Polygon(old.corners_2d(), closed=True, fill=False, edgecolor=MOVED_COLOR, lw=1.0,
                                 ls=(0, (3, 2)), zorder=5))
        for oid in diff["removed"]:
            old = object_box(rb[oid])
            ax.add_patch(Polygon(old.corners_2d(), closed=True, facecolor=(0.84, 0.19, 0.15, 0.10), edgecolor=REMOVED_COLOR,
                                 lw=1.3, ls=(0, (3, 2)), zorder=5))
            ax.plot([old.center[0]], [old.center[1]], marker="x", ms=7, mew=2.0, color=REMOVED_COLOR, zorder=6.5)
        for oid in diff["added"]:
            b = boxes[oid]
            ax.plot([b.center[0]], [b.center[1]], marker="+", ms=9, mew=2.2, color=ADDED_COLOR, zorder=6.5,
                    path_effects=_halo(3.5))
        for oid, a, bpos, dist in diff["moved"]:
            ax.plot([a[0]], [a[1]], marker="o", ms=3.2, color=MOVED_COLOR, zorder=7.5)
            ax.add_patch(FancyArrowPatch((a[0], a[1]), (bpos[0], bpos[1]), arrowstyle="-|>", mutation_scale=11,
                                         color=MOVED_COLOR, lw=1.5, shrinkA=0, shrinkB=0, zorder=7.5,
                                         path_effects=_halo(3.2)))

    # text: room names first, then object labels
    labeler = _Labeler(fig, ax)
    for p0, p1 in ticks:
        labeler.block_segment(p0, p1, 1.2)
    if diff is not None:
        rb = ref.by_id()
        for oid, a, bpos, dist in diff["moved"]:
            labeler.block_segment(a[:2], bpos[:2], 3.0)
        for oid in diff["removed"]:
            labeler.block_point(object_box(rb[oid]).center[:2], 5.0)
        for oid in diff["added"]:
            labeler.block_point(boxes[oid].center[:2], 6.0)
    foot = [(b.corners_2d(), o) for o, b in ((o, boxes[o.id]) for o in layout.objects)]
    for r in st.rooms:
        _place_room_label(ax, labeler, r, foot, s)
    if labels:
        fs = float(np.clip(5.0 + 1.6 * s, 5.5, 7.0))
        cand = [o for o in ground if boxes[o.id].size[0] * boxes[o.id].size[1] > LABEL_MIN_AREA]
        # objects on top first (they are what hides the others), then by footprint
        cand.sort(key=lambda o: (-levels[o.id], -boxes[o.id].size[0] * boxes[o.id].size[1]))
        for o in cand:
            b = boxes[o.id]

            def make(x, y, text, rot, _fs=fs):
                return ax.text(x, y, text, fontsize=_fs, ha="center", va="center", rotation=rot, color=TEXT_COLOR,
                               zorder=7, linespacing=0.95, path_effects=_halo(), clip_on=True)

            labeler.place(_object_label_candidates(b, o.cls, s, fs), make)
        if diff is not None:
            rb = ref.by_id()
            for oid in diff["removed"]:
                b = object_box(rb[oid])
                if b.size[0] * b.size[1] <= LABEL_MIN_AREA:
                    continue
                line_m = fs / 72.0 * 1.25 / s

                def make_r(x, y, text, rot, _fs=fs):
                    return ax.text(x, y, text, fontsize=_fs, ha="center", va="center", rotation=rot, color=REMOVED_COLOR,
                                   style="italic", zorder=7, path_effects=_halo(), clip_on=True)

                cx, cy = b.center[0], b.center[1]
                labeler.place([(cx, cy - line_m * 1.2, _short_label(rb[oid].cls), 0),
                               (cx, cy + line_m * 1.2, _short_label(rb[oid].cls), 0)], make_r)

    _draw_title(fig, layout, ref, diff, plan, title)
    _draw_legend(fig, plan)


def _place_room_label(ax, labeler: _Labeler, room, foot, s: float):
    x0, y0, x1, y1 = room.rect
    m = 0.08
    text = f"{room.name}  {room.area:.1f} m\u00b2"
    corners = [(x0 + m, y1 - m, "left", "top"), (x1 - m, y1 - m, "right", "top"),
               (x0 + m, y0 + m, "left", "bottom"), (x1 - m, y0 + m, "right", "bottom")]
    inv = ax.transData.inverted()
    best, best_cost = None, None
    for x, y, ha, va in corners:
        t = ax.text(x, y, text, fontsize=7.5, ha=ha, va=va, color="#4a4a4a", style="italic", fontweight="bold",
                    zorder=6, path_effects=_halo(2.5), clip_on=True)
        bb = labeler.extent(t)
        (dx0, dy0), (dx1, dy1) = inv.transform([(bb.x0, bb.y0), (bb.x1, bb.y1)])
        cost = 0.0
        for poly, _ in foot:
            px0, py0 = poly.min(axis=0)
            px1, py1 = poly.max(axis=0)
            ix = max(0.0, min(dx1, px1) - max(dx0, px0))
            iy = max(0.0, min(dy1, py1) - max(dy0, py0))
            cost += ix * iy
        if any(bb.overlaps(o) for o in labeler.taken):
            cost += 1e3
        if best_cost is None or cost < best_cost - 1e-9:
            if best is not None:
                best[0].remove()
            best, best_cost = (t, bb), cost
        else:
            t.remove()
    if best is not None:
        labeler.taken.append(best[1])


def _draw_title(fig, layout: Layout, ref, diff, plan: _Plan, title: str | None):
    fw, fh = plan.fig_w, plan.fig_h
    x = LEFT / fw
    y = 1.0 - 0.12 / fh
    head = title or (f"{layout.name}  (vs {ref.name})" if ref is not None else layout.name)
    fig.text(x, y, head, fontsize=11, fontweight="bold", ha="left", va="top", color=TEXT_COLOR)
    n_cls = len({o.cls for o in layout.objects})
    st = layout.stage
    parts = [f"{len(layout.objects)} objects", f"{n_cls} classes"]
    if st.rooms:
        parts.append(f"floor area {st.area:.1f} m\u00b2 in {len(st.rooms)} room{'s' if len(st.rooms) != 1 else ''}")
    else:
        parts.append("no rooms in the stage" if st.asset is None else f"stage mesh {Path(st.asset).name}")
    fig.text(x, y - TITLE_LINE / fh * 1.15, "  \u00b7  ".join(parts), fontsize=8.5, ha="left", va="top", color="#444444")
    if diff is not None:
        n_big = sum(1 for m in diff["moved"] if m[3] > BIG_MOVE)
        line = (f"moved {len(diff['moved'])} (>{BIG_MOVE:g} m: {n_big}), added {len(diff['added'])}, "
                f"removed {len(diff['removed'])}")
        fig.text(x, y - 2 * TITLE_LINE / fh * 1.05, line, fontsize=8.5, ha="left", va="top", color=MOVED_COLOR,
                 fontweight="bold")


def _arrow_handle(legend, orig_handle, xdescent, ydescent, width, height, fontsize):
    return FancyArrowPatch((-xdescent, height / 2 - ydescent), (width - xdescent, height / 2 - ydescent),
                           arrowstyle="-|>", mutation_scale=9, color=MOVED_COLOR, lw=1.4, shrinkA=0, shrinkB=0)


def _draw_legend(fig, plan: _Plan):
    fw, fh = plan.fig_w, plan.fig_h
    lx = (LEFT + plan.ax_w + GAP_R) / fw
    top = (BOTTOM + plan.ax_h) / fh
    # north arrow under the legend column, at the bottom of the plan
    fig.text(lx + 0.05 / fw, BOTTOM / fh, "N\n\u2191", fontsize=9, fontweight="bold", ha="center", va="bottom",
             color="#555555", linespacing=0.9)
    if not plan.legend_entries:
        fig.text(lx, top, "no objects", fontsize=LEGEND_FS, ha="left", va="top", color="#777777", style="italic")
        return
    handles, labels = [], []
    handler_map = {}
    for kind, label in plan.legend_entries:
        if kind == "moved":
            h = FancyArrowPatch((0, 0), (1, 0))
            handler_map[h] = HandlerPatch(patch_func=_arrow_handle)
        elif kind == "moved_old":
            h = Patch(fill=False, edgecolor=MOVED_COLOR, lw=1.0, ls=(0, (3, 2)))
        elif kind == "added":
            h = Patch(facecolor="#f4f4f4", edgecolor=ADDED_COLOR, lw=2.2)
        elif kind == "removed":
            h = Patch(facecolor=(0.84, 0.19, 0.15, 0.10), edgecolor=REMOVED_COLOR, lw=1.3, ls=(0, (3, 2)))
        elif kind.startswith("ceiling:"):
            col = class_color(kind.split(":", 1)[1])
            h = Patch(fill=False, edgecolor=_darker(col, 0.75), lw=1.0, ls=(0, (1, 1.2)))
        else:
            col = class_color(kind.split(":", 1)[1])
            h = Patch(facecolor=col, edgecolor=_darker(col), lw=0.6)
        handles.append(h)
        labels.append(label)
    leg = fig.legend(handles, labels, loc="upper left", bbox_to_anchor=(lx, top), ncol=plan.legend_cols,
                     fontsize=LEGEND_FS, frameon=False, handlelength=1.6, handleheight=0.9, handletextpad=0.5,
                     columnspacing=0.9, labelspacing=0.45, borderaxespad=0.0, borderpad=0.0,
                     title="changes / classes" if any(k == "moved" for k, _ in plan.legend_entries) else "classes",
                     title_fontsize=8, alignment="left", handler_map=handler_map)
    leg.get_title().set_color("#444444")
    leg.get_title().set_fontweight("bold")
