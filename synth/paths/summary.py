"""Summaries and previews of a path: ``path_summary`` (length, speed, heights, rooms, clearance) and
``plot_path`` (the path over the layout's top-down plan).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from vrformats.errors import UserError

from ..scene.model import Layout
from .clearance import path_clearance
from .model import CameraPath

__all__ = ["path_summary", "plot_path"]


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
        # from what the path was planned to keep clear of (band: objects at the camera's height)
        obstacles = str((path.meta.get("planner") or {}).get("obstacles", "all"))
        out["obstacles"] = obstacles
        out["min_clearance_m"] = round(float(path_clearance(path, layout, obstacles).min()), 4) if len(P) else None
    return out


def plot_path(path: CameraPath, layout: Layout, out_path, dpi: float = 150, tick_every_s: float = 2.0) -> Path:
    """``preview.plot_layout``'s top-down plan with the path over it: coloured by frame, start marker, heading ticks."""

    import matplotlib
    from matplotlib import cm, colors
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.collections import LineCollection
    from matplotlib.figure import Figure

    from ..scene import preview as pv

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
