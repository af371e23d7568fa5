"""``synth tour show``: the contact sheet of one frame of a tour: RGB, depth, instance and semantic
images in one PNG (``contact_sheet``), and the colours it gives ids and classes.

No Blender here; this module imports without bpy.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from vrformats.errors import UserError
from vrformats.tour import Tour, tonemap


def id_colors(ids, salt: int = 0) -> np.ndarray:
    """A stable pseudo-random colour per integer id ((n, 3) in [0, 1]); id 0 is black."""
    from matplotlib.colors import hsv_to_rgb

    ids = np.asarray(ids, dtype=np.uint64)
    h = (ids + np.uint64(salt)) * np.uint64(0x9E3779B97F4A7C15)
    h ^= h >> np.uint64(29)
    h *= np.uint64(0xBF58476D1CE4E5B9)
    h ^= h >> np.uint64(32)
    hue = (h & np.uint64(0xFFFF)).astype(np.float64) / 65536.0
    sat = 0.55 + 0.4 * ((h >> np.uint64(16)) & np.uint64(0xFF)).astype(np.float64) / 255.0
    val = 0.7 + 0.3 * ((h >> np.uint64(24)) & np.uint64(0xFF)).astype(np.float64) / 255.0
    rgb = hsv_to_rgb(np.stack([hue, sat, val], axis=-1))
    rgb[ids == 0] = 0.0
    return rgb


def class_colors(ids) -> np.ndarray:
    """A fixed colour per semantic class id ((n, 3) in [0, 1]): a 60-colour qualitative palette, 0 black."""
    import matplotlib

    pal = []
    for name in ("tab20", "tab20b", "tab20c"):
        c = np.asarray(matplotlib.colormaps[name].colors)[:, :3]
        pal.append(np.concatenate([c[0::2], c[1::2]]))  # strong colours first, their light twins after
    pal = np.concatenate(pal)
    ids = np.asarray(ids, dtype=np.int64)
    out = pal[(ids - 1) % len(pal)]
    out[ids == 0] = 0.0
    return out


def _colorize_ids(img: np.ndarray, salt: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    ids, inv, counts = np.unique(img, return_inverse=True, return_counts=True)
    lut = id_colors(ids, salt)
    return lut[inv.reshape(img.shape)], ids, counts


def contact_sheet(tour: Tour, index: int, out, exposure: float | None = None, dpi: float = 110) -> Path:
    """One PNG with the frame's RGB, depth, instance and semantic images (written atomically)."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure
    from matplotlib.patches import Patch

    out = Path(out)
    fmt = out.suffix.lower().lstrip(".") or "png"
    f = tour.frame(index)
    H, W = f.depth.shape if f.depth is not None else (tour.intrinsics.height, tour.intrinsics.width)
    panel_w = 5.2
    panel_h = panel_w * H / W
    fig = Figure(figsize=(2 * panel_w + 2.6, 2 * panel_h + 1.5), dpi=dpi)
    canvas = FigureCanvasAgg(fig)
    if fmt not in canvas.get_supported_filetypes():
        raise UserError(f"{out}: cannot write '.{fmt}' images; use .png")
    gs = fig.add_gridspec(2, 2, left=0.03, right=0.8, top=1 - 1.0 / fig.get_figheight(), bottom=0.03,
                          wspace=0.28, hspace=0.14)
    axes = [fig.add_subplot(gs[r, c]) for r in range(2) for c in range(2)]
    for ax in axes:
        ax.set_xticks([])
        ax.set_yticks([])
    ax_rgb, ax_d, ax_i, ax_s = axes
    blank = np.zeros((H, W, 3), np.float32)

    def missing(ax, text):
        ax.imshow(blank + 0.15)
        ax.text(0.5, 0.5, text, transform=ax.transAxes, ha="center", va="center", color="white", fontsize=11)

    # RGB
    if f.rgb is not None:
        img, scale = tonemap(f.rgb, exposure)
        ax_rgb.imshow(img, interpolation="nearest")
        ax_rgb.set_title(f"RGB (linear x {scale:.3g}, sRGB)", fontsize=10)
    else:
        missing(ax_rgb, "no RGB (geometry-only tour)")
        ax_rgb.set_title("RGB", fontsize=10)
    # depth
    if f.depth is not None:
        import matplotlib

        d = np.ma.masked_where(~(np.isfinite(f.depth) & (f.depth > 0)), f.depth)
        cmap = matplotlib.colormaps["turbo"].with_extremes(bad="black")
        vals = d.compressed()
        vmin, vmax = (float(vals.min()), float(np.percentile(vals, 99.5))) if vals.size else (0.0, 1.0)
        im = ax_d.imshow(d, cmap=cmap, vmin=vmin, vmax=max(vmax, vmin + 1e-3), interpolation="nearest")
        cb = fig.colorbar(im, cax=ax_d.inset_axes((1.02, 0.0, 0.035, 1.0)))  # outside: panels keep one size
        cb.set_label("depth (m)", fontsize=9)
        cb.ax.tick_params(labelsize=8)
        nohit = float(d.mask.mean()) if d.mask is not np.ma.nomask else 0.0
        ax_d.set_title(f"planar depth, {vals.min() if vals.size else 0:.2f}-{vals.max() if vals.size else 0:.2f} m"
                       + (f", no hit {nohit:.0%} (black)" if nohit else ""), fontsize=10)
    else:
        missing(ax_d, "no depth channel")
        ax_d.set_title("depth", fontsize=10)
    names = tour.class_names()
    box_class = {}
    try:
        box_class = {int(b["id"]): str(b.get("class", "")) for b in tour.objects()["boxes"]}
    except UserError:
        pass
    # instance
    if f.instance is not None:
        col, ids, counts = _colorize_ids(f.instance, salt=0)
        ax_i.imshow(col, interpolation="nearest")
        from scipy.ndimage import distance_transform_edt

        shown = 0
        for k in np.argsort(-counts):
            iid = int(ids[k])
            if iid == 0 or counts[k] < 0.005 * f.instance.size or shown >= 25:
                continue
            # label at the instance's most interior pixel (farthest from its outline and the image border)
            dist = distance_transform_edt(np.pad(f.instance == iid, 1))[1:-1, 1:-1]
            v, u = np.unravel_index(int(dist.argmax()), dist.shape)
            label = f"{iid} {box_class[iid]}" if box_class.get(iid) else str(iid)
            ax_i.text(u, v, label, fontsize=7, ha="center", va="center", color="white",
                      bbox={"boxstyle": "round,pad=0.15", "fc": "black", "alpha": 0.55, "lw": 0})
            shown += 1
        ax_i.set_title(f"instance ids ({int((ids != 0).sum())} visible, 0 black)", fontsize=10)
    else:
        missing(ax_i, "no instance channel")
        ax_i.set_title("instance ids", fontsize=10)
    # semantic
    if f.semantic is not None:
        ids, inv, counts = np.unique(f.semantic, return_inverse=True, return_counts=True)
        lut = class_colors(ids)
        ax_s.imshow(lut[inv.reshape(f.semantic.shape)], interpolation="nearest")
        handles = [Patch(facecolor=lut[k], edgecolor="none", label=f"{int(s)} {names.get(int(s), '?')}")
                   for k, s in sorted(enumerate(ids), key=lambda x: -counts[x[0]]) if s != 0][:30]
        if handles:
            ax_s.legend(handles=handles, loc="upper left", bbox_to_anchor=(1.02, 1.0), fontsize=7, frameon=False,
                        title="classes", title_fontsize=8, handlelength=1.0, borderaxespad=0.0)
        ax_s.set_title(f"semantic classes ({len(handles)} present)", fontsize=10)
    else:
        missing(ax_s, "no semantic channel")
        ax_s.set_title("semantic", fontsize=10)

    p = f.position
    meta = tour.meta
    sub = ", ".join(f"{k} {meta[k]}" for k in ("layout", "lighting", "renderer") if meta.get(k) is not None)
    if meta.get("lighting") is None and "lighting" in meta:
        sub = ", ".join(x for x in (sub, "geometry only") if x)
    fig.suptitle(f"{tour.name}  |  frame {index}  |  camera at ({p[0]:.2f}, {p[1]:.2f}, {p[2]:.2f}) m"
                 + (f"\n{sub}" if sub else ""), fontsize=12, y=1 - 0.1 / fig.get_figheight(), va="top")

    from vrformats.atomic import save_figure

    return save_figure(fig, out, dpi)


