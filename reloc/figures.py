"""The trajectory-over-map figure (paper Fig. 3) of one tour: ``tour_figure``, drawn by ``reloc run
--plot``, ``reloc eval --plot`` and, per tour of an experiment, ``reloc.experiments.plots``.

A column per method: the top panel is a top-down view (world x/y, Z up) of the map boxes (objects
light grey, walls darker; floors and ceilings left out), the ground-truth camera path as a thin grey
line and the estimated camera positions coloured continuously by position error (``error_colors``:
green at 0 m, yellow at 0.5 m, red at 1 m and beyond). The lower panel shows the rolling medians
(``rolling_median``) of the position and rotation errors against the frame index on one log axis,
with the 1 m and 10 deg thresholds dashed. Headless (matplotlib's Agg canvas); written atomically.
"""

from __future__ import annotations

import warnings
from pathlib import Path

import numpy as np
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.cm import ScalarMappable
from matplotlib.collections import PolyCollection
from matplotlib.colors import LinearSegmentedColormap, Normalize
from matplotlib.figure import Figure

from vrformats.atomic import save_figure

from .evaluation import THRESHOLDS, pose_errors

__all__ = ["ERROR_CMAP", "ERROR_MAX_M", "POS_THRESHOLD_M", "ROT_THRESHOLD_DEG", "ROLLING_WINDOW", "DPI",
           "error_colors", "rolling_median", "per_frame", "recall_1m_10deg", "box_corners", "tour_figure",
           "run_figure"]

POS_THRESHOLD_M, ROT_THRESHOLD_DEG = THRESHOLDS["recall_1m_10deg"]
ERROR_MAX_M = 1.0  # the colour scale: 0 m green, 0.5 m yellow, >= 1 m red
ROLLING_WINDOW = 31  # frames
MAX_COLUMNS = 2  # methods side by side in a tour figure (more wrap onto further rows): about 1,050 px wide
DPI = 100

ERROR_CMAP = LinearSegmentedColormap.from_list(
    "reloc_error", [(0.0, (0.0, 0.70, 0.0)), (0.5, (1.0, 0.88, 0.0)), (1.0, (0.85, 0.0, 0.0))]
)
OBJECT_FACE, OBJECT_EDGE = (0.86, 0.86, 0.86), (0.62, 0.62, 0.62)
WALL_FACE, WALL_EDGE = (0.42, 0.42, 0.42), (0.30, 0.30, 0.30)
GT_COLOR = (0.45, 0.45, 0.45)
POS_COLOR, ROT_COLOR = "#1f77b4", "#d62728"
ERR_FLOOR = 1e-3  # log axis: errors below this are drawn at it


# --------------------------------------------------------------------------------------------
# numbers


def error_colors(pos_err) -> np.ndarray:
    """RGBA (N, 4) for position errors in metres: green 0 m, yellow 0.5 m, red >= 1 m (clipped).

    NaN (no error known) gets grey."""
    e = np.asarray(pos_err, dtype=float).reshape(-1)
    out = ERROR_CMAP(np.clip(np.nan_to_num(e, nan=0.0) / ERROR_MAX_M, 0.0, 1.0))
    out[~np.isfinite(e)] = (0.6, 0.6, 0.6, 1.0)
    out[np.isposinf(e)] = ERROR_CMAP(1.0)
    return out


def per_frame(all_frames, frames, values) -> np.ndarray:
    """Values placed on the ``all_frames`` axis (ground-truth frame indices): NaN where a frame has none."""
    all_frames = np.asarray(all_frames, dtype=np.int64)
    out = np.full(len(all_frames), np.nan)
    if len(frames):
        pos = {int(f): k for k, f in enumerate(all_frames)}
        idx = np.array([pos.get(int(f), -1) for f in frames], dtype=np.int64)
        ok = idx >= 0
        out[idx[ok]] = np.asarray(values, dtype=float)[ok]
    return out


def rolling_median(values, window: int = ROLLING_WINDOW) -> np.ndarray:
    """Centred rolling median over ``window`` samples, ignoring NaN (frames without an estimate).

    The window is truncated at both ends; a window without any finite value gives NaN."""
    v = np.asarray(values, dtype=float).reshape(-1)
    n = len(v)
    if n == 0:
        return v.copy()
    window = max(1, int(window))
    half = window // 2
    padded = np.concatenate([np.full(half, np.nan), v, np.full(window - 1 - half, np.nan)])
    win = np.lib.stride_tricks.sliding_window_view(padded, window)  # (n, window); row k centred on k
    out = np.full(n, np.nan)
    has = np.isfinite(win).any(axis=1)
    if has.any():
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)
            out[has] = np.nanmedian(win[has], axis=1)
    return out


def recall_1m_10deg(pos, rot, n_frames: int) -> float:
    """Fraction of ALL ``n_frames`` ground-truth frames within 1 m and 10 deg (missing poses fail)."""
    if n_frames <= 0:
        return 0.0
    ok = (np.asarray(pos) <= POS_THRESHOLD_M) & (np.asarray(rot) <= ROT_THRESHOLD_DEG)
    return float(ok.sum()) / n_frames


def box_corners(centers, sizes, yaws) -> np.ndarray:
    """(N, 4, 2) footprint corners (x, y) of gravity-aligned boxes rotated by yaw about +Z."""
    c = np.asarray(centers, float).reshape(-1, 3)[:, :2]
    h = np.asarray(sizes, float).reshape(-1, 3)[:, :2] / 2.0
    y = np.asarray(yaws, float).reshape(-1)
    local = np.array([[-1.0, -1.0], [1.0, -1.0], [1.0, 1.0], [-1.0, 1.0]])  # (4, 2)
    pts = local[None] * h[:, None, :]  # (N, 4, 2)
    cs, sn = np.cos(y)[:, None], np.sin(y)[:, None]
    x = pts[..., 0] * cs - pts[..., 1] * sn
    yy = pts[..., 0] * sn + pts[..., 1] * cs
    return np.stack([x, yy], axis=-1) + c[:, None, :]


# --------------------------------------------------------------------------------------------
# drawing


def _draw_map(ax, bmap) -> np.ndarray | None:
    """Object and wall footprints; returns all drawn corners (M, 2) for the view limits."""
    if bmap is None or len(bmap) == 0:
        return None
    kinds = np.array(bmap.kinds)
    corners = box_corners(bmap.centers, bmap.sizes, bmap.yaws)
    drawn = []
    for kind, face, edge, z in (("object", OBJECT_FACE, OBJECT_EDGE, 1), ("wall", WALL_FACE, WALL_EDGE, 2)):
        sel = kinds == kind
        if sel.any():
            ax.add_collection(PolyCollection(corners[sel], facecolors=[face], edgecolors=[edge], linewidths=0.5,
                                             zorder=z))
            drawn.append(corners[sel].reshape(-1, 2))
    return np.concatenate(drawn) if drawn else None


def _gt_arrays(gt: dict) -> tuple[np.ndarray, np.ndarray]:
    frames = np.array(sorted(int(i) for i in gt), dtype=np.int64)
    P = np.array([np.asarray(gt[int(i)])[:3, 3] for i in frames]).reshape(-1, 3)
    return frames, P


def _no_poses(ax, text="no poses"):
    ax.text(0.5, 0.5, text, transform=ax.transAxes, ha="center", va="center", fontsize=12, color="0.3",
            bbox={"boxstyle": "round,pad=0.3", "fc": "white", "ec": "0.6", "alpha": 0.9}, zorder=10)


def _view_limits(bmap, gt_P: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Top-down view limits from the drawn map boxes and the ground-truth path, with a margin."""
    pts = []
    if bmap is not None and len(bmap):
        sel = np.array([k in ("object", "wall") for k in bmap.kinds])
        if sel.any():
            pts.append(box_corners(bmap.centers[sel], bmap.sizes[sel], bmap.yaws[sel]).reshape(-1, 2))
    if len(gt_P):
        pts.append(gt_P[:, :2])
    if not pts:
        return np.array([-1.0, -1.0]), np.array([1.0, 1.0])
    allp = np.concatenate(pts)
    return allp.min(axis=0) - 0.4, allp.max(axis=0) + 0.4


def tour_figure(bmap, gt: dict, estimates: dict, out_png, title: str = "", window: int = ROLLING_WINDOW,
                dpi: float = DPI, scored: dict | None = None) -> Path:
    """One figure for a query tour: a column per method (label -> {frame: 4x4 camera-to-world}).

    ``scored``: label -> (recall, frames) of a method scored on a subset of the frames (the
    experiment's per-tour figure, e.g. the one-frame unit on every 15th frame); its column title gives
    that recall. Other columns' recall is over ALL ground-truth frames.

    ``bmap`` is a ``reloc.map.boxmap.BoxMap`` (or None: no map drawn); ``gt`` maps frame -> 4x4 ground
    truth. A label whose estimates are empty or None shows "no poses". Estimated positions outside
    the view (map and ground-truth path) are clipped and counted in the panel. Returns the PNG path."""
    from matplotlib.ticker import LogLocator, NullLocator

    labels = list(estimates) or ["(no methods)"]
    ncol = min(len(labels), MAX_COLUMNS)
    nblock = -(-len(labels) // ncol)  # rows of methods
    gt_frames, gt_P = _gt_arrays(gt)
    n_gt = len(gt_frames)
    lo, hi = _view_limits(bmap, gt_P)
    ext = np.maximum(hi - lo, 1e-6)

    # layout in inches: the top panels get the view's aspect, so little space is wasted
    col_w = 4.0
    top_h = float(np.clip(col_w * ext[1] / ext[0], 2.0, 6.0))
    bot_h, left, gap, right = 1.7, 0.85, 0.55, 1.05  # right: room for the colour bar
    col_head, mid, xlab = 0.55, 0.75, 0.45  # column titles (two lines), between the panels, frame axis label
    block_h = col_head + top_h + mid + bot_h + xlab
    head = 0.1 + (0.4 if title else 0.0)  # the figure title
    foot = 0.4  # the legend of the error curves
    W = left + ncol * col_w + (ncol - 1) * gap + right
    H = head + nblock * block_h + foot
    fig = Figure(figsize=(W, H), dpi=dpi)
    FigureCanvasAgg(fig)
    major = LogLocator(base=10.0, numticks=8)
    for k, label in enumerate(labels):
        b, c = divmod(k, ncol)
        x0 = left + c * (col_w + gap)
        y_top = H - head - b * block_h - col_head
        ax = fig.add_axes((x0 / W, (y_top - top_h) / H, col_w / W, top_h / H))
        axb = fig.add_axes((x0 / W, (y_top - top_h - mid - bot_h) / H, col_w / W, bot_h / H))
        ax.set_xlim(lo[0], hi[0])
        ax.set_ylim(lo[1], hi[1])
        ax.set_aspect("equal", adjustable="box")
        _draw_map(ax, bmap)
        if n_gt:
            ax.plot(gt_P[:, 0], gt_P[:, 1], color=GT_COLOR, lw=0.8, zorder=3)
        est = estimates.get(label) or {}
        frames, pos, rot = pose_errors(est, gt) if est else (np.empty(0, np.int64), np.empty(0), np.empty(0))
        r = recall_1m_10deg(pos, rot, n_gt)
        if len(frames):
            E = np.array([np.asarray(est[int(i)])[:3, 3] for i in frames])
            order = np.argsort(pos, kind="stable")  # worst drawn last, on top
            ax.scatter(E[order, 0], E[order, 1], c=error_colors(pos[order]), s=7, linewidths=0, zorder=4)
            out_view = int((((E[:, :2] < lo) | (E[:, :2] > hi)).any(axis=1)).sum())
            if out_view:
                ax.text(0.01, 0.01, f"{out_view} poses outside the view", transform=ax.transAxes, fontsize=7,
                        ha="left", va="bottom", color="0.25", zorder=10)
        else:
            _no_poses(ax)
        if scored and label in scored and scored[label][1] != n_gt:
            r_s, n_s = scored[label]
            scores = f"recall 1 m/10\u00b0: {100 * r_s:.1f}% of {n_s} scored frames  ({len(frames)} posed)"
        else:
            scores = f"recall 1 m/10\u00b0: {100 * r:.1f}%  ({len(frames)}/{n_gt} posed)"
        ax.set_title(f"{label}\n{scores}", fontsize=9)
        ax.set_xlabel("x (m)", fontsize=8, labelpad=1)
        if c == 0:
            ax.set_ylabel("y (m)", fontsize=8, labelpad=1)
        ax.tick_params(labelsize=7)

        # lower panel: rolling medians of both errors on one log axis, thresholds dashed
        axb.set_yscale("log")
        axb.yaxis.set_major_locator(major)
        axb.yaxis.set_minor_locator(NullLocator())  # minor log ticks are most of the drawing time
        axb.set_ylim(ERR_FLOOR * 0.8, 200.0)
        axb.axhline(POS_THRESHOLD_M, color=POS_COLOR, ls="--", lw=0.9, alpha=0.8)
        axb.axhline(ROT_THRESHOLD_DEG, color=ROT_COLOR, ls="--", lw=0.9, alpha=0.8)
        if len(frames):
            x = gt_frames.astype(float)
            mp = rolling_median(per_frame(gt_frames, frames, pos), window)
            mr = rolling_median(per_frame(gt_frames, frames, rot), window)
            axb.plot(x, np.maximum(mp, ERR_FLOOR), color=POS_COLOR, lw=1.1, label="position (m), 1 m dashed")
            axb.plot(x, np.maximum(mr, ERR_FLOOR), color=ROT_COLOR, lw=1.1, label="rotation (deg), 10\u00b0 dashed")
        else:
            _no_poses(axb)
        if n_gt:
            axb.set_xlim(float(gt_frames[0]), float(max(gt_frames[-1], gt_frames[0] + 1)))
        axb.set_xlabel("frame", fontsize=8, labelpad=1)
        if c == 0:
            axb.set_ylabel(f"error, rolling median\nof {window} frames", fontsize=8)
        axb.tick_params(labelsize=7)
        axb.grid(True, which="major", axis="y", lw=0.4, alpha=0.5)

    from matplotlib.lines import Line2D

    fig.legend(handles=[Line2D([], [], color=POS_COLOR, lw=1.1, label="position error (m)"),
                        Line2D([], [], color=POS_COLOR, lw=0.9, ls="--", label="1 m"),
                        Line2D([], [], color=ROT_COLOR, lw=1.1, label="rotation error (deg)"),
                        Line2D([], [], color=ROT_COLOR, lw=0.9, ls="--", label="10\u00b0")],
               loc="lower center", ncol=4, fontsize=8, frameon=False, bbox_to_anchor=(0.5, 0.02 / H))

    # one colour bar, to the right of the top row
    y1 = H - head - col_head  # beside the first row's map panels
    y0 = y1 - top_h
    cax = fig.add_axes(((W - right + 0.25) / W, (y0 + 0.1 * (y1 - y0)) / H, 0.14 / W, 0.8 * (y1 - y0) / H))
    cb = fig.colorbar(ScalarMappable(norm=Normalize(0.0, ERROR_MAX_M), cmap=ERROR_CMAP), cax=cax, extend="max")
    cb.set_label("position error (m)", fontsize=8)
    cb.set_ticks([0.0, 0.25, 0.5, 0.75, 1.0])
    cb.ax.tick_params(labelsize=7)
    if title:
        fig.suptitle(title, fontsize=11, y=1 - 0.12 / H, va="top")
    return save_figure(fig, out_png, dpi)


def run_figure(tour, trajectories: dict, out_png, bmap=None, title: str | None = None) -> Path:
    """``tour_figure`` of one run: ``trajectories`` label -> {frame: 4x4 camera-to-world} (a run's
    causal and closure poses, or a pose file's) against ``tour``'s ground truth, over ``bmap`` (or no
    map). The title names the tour, its layout, lighting and frames."""
    gt = {int(i): T for i, T in zip(tour.frame_indices, tour.poses)}
    meta = tour.meta
    bits = [str(meta[k]) for k in ("layout", "lighting") if meta.get(k)]
    head = title or f"{tour.name}  ({', '.join(bits + [f'{len(gt)} frames'])})"
    return tour_figure(bmap, gt, trajectories, out_png, title=head)


MATCHED = (0.20, 0.65, 0.25)  # a built box matched to a ground-truth box of its class
WRONG_CLASS = (1.0, 0.60, 0.0)  # matched, but labelled with another class
EXTRA = (0.35, 0.45, 0.95)  # built, matching nothing
MISSED = (0.85, 0.0, 0.0)  # a ground-truth box no built box matched


def map_figure(doc: dict, out_png, gt_doc: dict | None = None, errors: dict | None = None, title: str = "",
               dpi: float = DPI) -> Path:
    """A built map (``videoreloc-boxes/1``) top-down: objects and walls (floors and ceilings left out).
    With the ground truth (``gt_doc`` and ``reloc.map.scoring.box_errors``' ``errors``), built boxes
    are filled by how they matched (green: matched, orange: matched with another class, blue: extra)
    and the ground-truth boxes are outlined (red: missed by the map)."""
    from matplotlib.patches import Patch

    def polys(boxes):
        if not boxes:
            return np.empty((0, 4, 2))
        return box_corners([b["center"] for b in boxes], [b["size"] for b in boxes], [b["yaw"] for b in boxes])

    def shown(boxes):
        return [b for b in boxes if b.get("kind", "object") in ("object", "wall")]

    built = shown(doc.get("boxes", []))
    gt = shown((gt_doc or {}).get("boxes", []))
    state = {}
    if errors is not None:
        for r in errors["boxes"]:
            state[r["id"]] = MATCHED if r["class_ok"] else WRONG_CLASS
        for u in errors["unmatched"]:
            state[u["id"]] = EXTRA
    missed = {u["id"] for u in (errors or {}).get("unobserved", [])}
    allc = np.concatenate([polys(built).reshape(-1, 2), polys(gt).reshape(-1, 2), np.zeros((1, 2))])
    lo, hi = allc.min(0) - 0.3, allc.max(0) + 0.3
    ext = np.maximum(hi - lo, 1e-6)
    W = 8.0
    H = float(np.clip(W * ext[1] / ext[0], 3.0, 10.0)) + 1.2
    fig = Figure(figsize=(W + 2.6, H), dpi=dpi)
    FigureCanvasAgg(fig)
    ax = fig.add_axes((0.07, 0.08, 0.68, 0.82))
    ax.set_xlim(lo[0], hi[0])
    ax.set_ylim(lo[1], hi[1])
    ax.set_aspect("equal", adjustable="box")
    if built:
        faces = [state.get(b["id"], OBJECT_FACE if errors is None else EXTRA) for b in built]
        ax.add_collection(PolyCollection(polys(built), facecolors=faces, edgecolors="0.2", linewidths=0.4, alpha=0.75,
                                         zorder=2))
    if gt:
        edges = [MISSED if g["id"] in missed else (0.3, 0.3, 0.3) for g in gt]
        ax.add_collection(PolyCollection(polys(gt), facecolors="none", edgecolors=edges,
                                         linewidths=[1.6 if g["id"] in missed else 0.7 for g in gt], zorder=3))
    ax.set_xlabel("x (m)", fontsize=9)
    ax.set_ylabel("y (m)", fontsize=9)
    ax.tick_params(labelsize=8)
    if errors is not None:
        drawn = [state.get(b["id"], EXTRA) for b in built]  # the counts of what is drawn (objects and walls)
        n = {c: sum(1 for v in drawn if v == c) for c in (MATCHED, WRONG_CLASS, EXTRA)}
        handles = [Patch(facecolor=MATCHED, label=f"matched ({n[MATCHED]})"),
                   Patch(facecolor=WRONG_CLASS, label=f"matched, other class ({n[WRONG_CLASS]})"),
                   Patch(facecolor=EXTRA, label=f"extra ({n[EXTRA]})"),
                   Patch(facecolor="none", edgecolor="0.3", label=f"ground truth ({len(gt)})"),
                   Patch(facecolor="none", edgecolor=MISSED, linewidth=1.6,
                         label=f"missed ({sum(1 for g in gt if g['id'] in missed)})")]
        ax.legend(handles=handles, loc="upper left", bbox_to_anchor=(1.02, 1.0), fontsize=8, frameon=False)
    fig.suptitle(title or f"map of {doc.get('layout', '?')}: {len(built)} object and wall boxes (floors and ceilings "
                 "left out)", fontsize=11)
    return save_figure(fig, out_png, dpi)
