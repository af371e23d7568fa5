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




# ---------------------------------------------------------------------------------------------
# a whole tour at a glance: a contact strip and an animation of RGB | depth | instance ids

PANELS = ("RGB", "depth", "instance ids")
GAP_PX = 4  # between panels and rows
LABEL_PX = 14  # the caption line above each row


def _tour_scales(tour: Tour, picks: list[int]) -> tuple[float | None, float]:
    """One RGB exposure and one depth range for every frame shown (no flicker between frames): the
    median automatic exposure and the 99.5th depth percentile over up to 12 of ``picks``."""
    exposures, depths = [], []
    for i in picks[:: max(1, len(picks) // 12)][:12]:
        f = tour.frame(int(i), instance=False, semantic=False)
        if f.rgb is not None:
            exposures.append(tonemap(f.rgb)[1])
        if f.depth is not None:
            d = f.depth[np.isfinite(f.depth) & (f.depth > 0)]
            if d.size:
                depths.append(float(np.percentile(d, 99.5)))
    return (float(np.median(exposures)) if exposures else None), (max(depths) if depths else 1.0)


def frame_row(tour: Tour, index: int, exposure: float | None, depth_max: float, scale: int = 1) -> np.ndarray:
    """Frame ``index`` as one uint8 image: RGB | depth (turbo, 0 to ``depth_max`` m, no hit black) |
    instance ids (stable colours, 0 black), each ``scale`` times the frame's size. A frame without a
    channel shows a grey panel."""
    import matplotlib

    f = tour.frame(int(index), semantic=False)
    H, W = tour.intrinsics.height, tour.intrinsics.width
    grey = np.full((H, W, 3), 0.25, np.float32)
    rgb = tonemap(f.rgb, exposure)[0] if f.rgb is not None else grey
    if f.depth is not None:
        ok = np.isfinite(f.depth) & (f.depth > 0)
        d = matplotlib.colormaps["turbo"](np.clip(np.where(ok, f.depth, 0) / max(depth_max, 1e-3), 0, 1))[..., :3]
        d[~ok] = 0.0
    else:
        d = grey
    ids = _colorize_ids(f.instance, salt=0)[0] if f.instance is not None else grey
    gap = np.ones((H, GAP_PX // max(scale, 1) or 1, 3), np.float32)
    row = np.concatenate([rgb, gap, d, gap, ids], axis=1)
    row = (np.clip(row, 0, 1) * 255 + 0.5).astype(np.uint8)
    if scale > 1:
        row = row.repeat(scale, axis=0).repeat(scale, axis=1)
    return row


def _captioned(row: np.ndarray, text: str, missing_rgb: bool):
    from PIL import Image, ImageDraw

    img = Image.new("RGB", (row.shape[1], row.shape[0] + LABEL_PX), "white")
    img.paste(Image.fromarray(row), (0, LABEL_PX))
    draw = ImageDraw.Draw(img)
    draw.text((2, 1), text, fill="black")
    if missing_rgb:
        w = (row.shape[1] - 2 * GAP_PX) // 3
        draw.text((w // 2 - 18, LABEL_PX + row.shape[0] // 2 - 6), "no RGB", fill="white")
    return img


def _picks(tour: Tour, count: int) -> list[int]:
    """``count`` frames spread along the tour, on frames with RGB when the tour has any."""
    idx = [int(i) for i in tour.frame_indices]
    if not idx:
        raise UserError(f"{tour.root}: the tour has no frames")
    if tour.has_rgb() and tour.rgb_every > 1:
        idx = [i for i in idx if i % tour.rgb_every == 0] or idx
    if count >= len(idx):
        return idx
    return [idx[round(k * (len(idx) - 1) / (count - 1))] for k in range(count)] if count > 1 else idx[:1]


STILL_FORMATS = {".png": "PNG", ".jpg": "JPEG", ".jpeg": "JPEG"}


def still_format(out: Path, what: str) -> str:
    """Pillow's format for a still picture file, or a one-line error naming the file."""
    fmt = STILL_FORMATS.get(out.suffix.lower())
    if fmt is None:
        raise UserError(f"{out}: a {what} is written as .png or .jpg")
    return fmt


def save_still(img, out: Path, fmt: str) -> Path:
    """A Pillow image written atomically as PNG (optimised) or JPEG (quality 88)."""
    import io

    from vrformats.atomic import write_bytes_atomic

    buf = io.BytesIO()
    img.save(buf, format=fmt, **({"quality": 88} if fmt == "JPEG" else {"optimize": True}))
    return write_bytes_atomic(out, buf.getvalue())


def tour_strip(tour: Tour, out, count: int = 6, scale: int = 2) -> Path:
    """A contact strip of ``count`` frames spread along the tour, one row per frame: RGB | depth |
    instance ids, captioned with the frame, its time and the tour; written atomically (PNG or JPEG)."""
    from PIL import Image

    if count < 1:
        raise UserError(f"--count must be at least 1, got {count}")
    out = Path(out)
    fmt = still_format(out, "strip")
    picks = _picks(tour, count)
    exposure, depth_max = _tour_scales(tour, picks)
    rows = []
    for i in picks:
        f_has_rgb = tour.has_rgb() and i % tour.rgb_every == 0
        rows.append(_captioned(frame_row(tour, i, exposure, depth_max, scale),
                               f"{tour.name}  frame {i}  t={i / tour.fps:.1f} s", not f_has_rgb))
    head = f"RGB | depth 0-{depth_max:.1f} m | instance ids"
    W = max(r.width for r in rows)
    sheet = Image.new("RGB", (W, LABEL_PX + sum(r.height + GAP_PX for r in rows)), "white")
    from PIL import ImageDraw

    ImageDraw.Draw(sheet).text((2, 1), head, fill="black")
    y = LABEL_PX
    for r in rows:
        sheet.paste(r, (0, y))
        y += r.height + GAP_PX
    return save_still(sheet, out, fmt)


def tour_video(tour: Tour, out, every: int | None = None, fps: float = 10.0, max_frames: int = 300,
               scale: int = 1) -> tuple[Path, int]:
    """An animation of the tour, RGB | depth | instance ids side by side: a GIF (Pillow), or an MP4
    when the file ends in .mp4 and imageio-ffmpeg is installed. ``every``: every N-th frame
    (default: the tour's RGB frames, at most ``max_frames``). Returns (file, frames written)."""
    from PIL import Image

    from vrformats.atomic import write_bytes_atomic

    out = Path(out)
    suffix = out.suffix.lower()
    if suffix not in (".gif", ".mp4"):
        raise UserError(f"{out}: an animation is written as .gif (or .mp4 with imageio-ffmpeg installed)")
    if not (0 < fps <= 60):
        raise UserError(f"--fps must be in (0, 60], got {fps:g}")
    idx = [int(i) for i in tour.frame_indices]
    if not idx:
        raise UserError(f"{tour.root}: the tour has no frames")
    step = every or (tour.rgb_every if tour.has_rgb() else 1)
    if step < 1:
        raise UserError(f"--every must be at least 1, got {step}")
    picks = idx[::step]
    if len(picks) > max_frames:
        picks = picks[:: -(-len(picks) // max_frames)]
    exposure, depth_max = _tour_scales(tour, picks)
    frames = [Image.fromarray(frame_row(tour, i, exposure, depth_max, scale)) for i in picks]
    if suffix == ".mp4":
        import importlib.util

        try:
            import imageio.v3 as iio

            if importlib.util.find_spec("imageio_ffmpeg") is None:  # the encoder imageio needs for .mp4
                raise ImportError("imageio_ffmpeg")
        except ImportError:
            raise UserError(f"{out}: MP4 needs imageio and imageio-ffmpeg (pip install imageio imageio-ffmpeg); "
                            "write a .gif instead") from None
        import tempfile

        with tempfile.TemporaryDirectory() as tmp:
            tmp_file = Path(tmp) / "tour.mp4"
            even = [np.asarray(f)[: f.height // 2 * 2, : f.width // 2 * 2] for f in frames]
            iio.imwrite(tmp_file, np.stack(even), fps=fps, codec="libx264")
            return write_bytes_atomic(out, tmp_file.read_bytes()), len(frames)
    import io

    buf = io.BytesIO()
    frames[0].save(buf, format="GIF", save_all=True, append_images=frames[1:], duration=round(1000 / fps), loop=0,
                   optimize=False)
    return write_bytes_atomic(out, buf.getvalue()), len(frames)


def write_previews(tour_dir) -> int:
    """``--previews`` for the frames the Blender worker did not preview (the fast renderer's, the
    geometry frames between RGB frames): ``previews/NNNNNN.png``, depth | instance ids at the frame's
    size, written atomically; frames that already have a preview keep it. Returns how many were written."""
    from PIL import Image

    from vrformats.atomic import replacing

    tour = Tour(tour_dir)
    d = Path(tour_dir) / "previews"
    todo = [int(i) for i in tour.frame_indices if not (d / f"{int(i):06d}.png").is_file()]
    if not todo:
        return 0
    d.mkdir(exist_ok=True)
    _, depth_max = _tour_scales(tour, todo)
    W = tour.intrinsics.width
    for i in todo:
        row = frame_row(tour, i, None, depth_max)[:, W + max(GAP_PX, 1):]  # depth | ids: no RGB to show
        with replacing(d / f"{i:06d}.png") as tmp:
            Image.fromarray(row).save(tmp, format="PNG")
    return len(todo)
