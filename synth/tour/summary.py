"""A rendered design (a render job's folder) at a glance: ``synth tour check JOBDIR`` prints its
tours, frames, lightings, layouts and sizes (``design_summary``, ``format_summary``), ``synth tour
show JOBDIR --out FILE`` draws the first frame of every tour in one mosaic (``design_mosaic``: rows
layout x path, columns lighting). No Blender here."""

from __future__ import annotations

import os
from pathlib import Path

from vrformats.design import DESIGN_FILE, list_tours, read_design
from vrformats.errors import UserError
from vrformats.tour import Tour


def is_design_folder(d) -> bool:
    """A folder of tours (a render job's output), not a tour: it has design.json, or tours and no camera.json."""
    d = Path(d)
    return d.is_dir() and not (d / "camera.json").is_file() and ((d / DESIGN_FILE).is_file() or bool(list_tours(d)))


def _size(path: Path) -> int:
    total = 0
    for root, _dirs, files in os.walk(path):
        for f in files:
            try:
                total += (Path(root) / f).lstat().st_size
            except OSError:
                pass
    return total


def design_summary(root) -> dict:
    """{root, tours: {name: {layout, lighting, path, frames, planned, rgb_every, complete, bytes}}, totals}."""
    root = Path(root)
    found = list_tours(root)
    planned = read_design(root) or {}
    if not found and not planned:
        raise UserError(f"{root}: no rendered design here (no {DESIGN_FILE}, no tour with a meta.json)")
    tours = {}
    for name in sorted(set(found) | set(planned)):
        meta = found.get(name) or {}
        p = planned.get(name) or {}
        frames = 0
        if meta:
            try:
                frames = len(Tour(root / name))
            except UserError:
                frames = 0
        tours[name] = {"layout": meta.get("layout", p.get("layout")), "lighting": meta.get("lighting", p.get("lighting")),
                       "path": meta.get("path", p.get("path")), "frames": frames, "planned": p.get("n_frames"),
                       "rgb_every": ((meta.get("settings") or {}).get("rgb_every") or (1 if meta.get("lighting") else None)),
                       "complete": bool(meta) and meta.get("complete") is not False,
                       "bytes": _size(root / name) if (root / name).is_dir() else 0}
    rgb = sum(t["frames"] // t["rgb_every"] + (1 if t["frames"] % t["rgb_every"] else 0)
              for t in tours.values() if t["rgb_every"] and t["frames"])
    return {"root": str(root), "tours": tours,
            "layouts": sorted({t["layout"] for t in tours.values() if t["layout"]}),
            "lightings": sorted({t["lighting"] or "geometry only" for t in tours.values()}),
            "paths": sorted({t["path"] for t in tours.values() if t["path"]}),
            "frames": sum(t["frames"] for t in tours.values()), "rgb_frames": rgb,
            "complete": sum(t["complete"] for t in tours.values()), "bytes": _size(root)}


def format_summary(s: dict) -> str:
    lines = [f"{s['root']}: {len(s['tours'])} tours ({s['complete']} complete), {s['frames']:,} frames "
             f"({s['rgb_frames']:,} with RGB), {s['bytes'] / 2**20:.1f} MiB",
             f"layouts: {', '.join(s['layouts'])}; lightings: {', '.join(s['lightings'])}; paths: {', '.join(s['paths'])}",
             "", f"{'tour':<34} {'frames':>7} {'RGB every':>9} {'MiB':>8}  state"]
    for name, t in s["tours"].items():
        state = "complete" if t["complete"] else ("missing" if not t["frames"] else "incomplete")
        planned = f"/{t['planned']}" if t["planned"] and t["planned"] != t["frames"] else ""
        lines.append(f"{name:<34} {str(t['frames']) + planned:>7} {t['rgb_every'] or '-':>9} {t['bytes'] / 2**20:>8.1f}  {state}")
    return "\n".join(lines)


def design_mosaic(root, out, scale: int = 1, path: str | None = None) -> Path:
    """The first frame (with RGB where the tour has any) of every tour (of camera path ``path`` only,
    if given): rows layout x path, columns lighting, each cell RGB | depth | instance ids; written
    atomically (PNG or JPEG)."""
    from PIL import Image, ImageDraw

    from .show import LABEL_PX, _picks, _tour_scales, frame_row, save_still, still_format

    root, out = Path(root), Path(out)
    fmt = still_format(out, "mosaic")
    found = list_tours(root)
    if path is not None:
        paths = sorted({m["path"] for m in found.values()})
        found = {n: m for n, m in found.items() if m["path"] == path}
        if not found:
            raise UserError(f"--path {path}: no tour of that camera path in {root} (its paths: {', '.join(paths)})")
    if not found:
        raise UserError(f"{root}: no rendered tour here (no tour with a meta.json)")
    rows = sorted({(m["layout"], m["path"]) for m in found.values()})
    cols = sorted({m.get("lighting") or "" for m in found.values()}, key=lambda x: ("day", "evening", "night", "").index(x)
                  if x in ("day", "evening", "night", "") else 4)
    cells = {}
    for name, m in found.items():
        t = Tour(root / name)
        if not len(t):
            continue
        i = _picks(t, 1)[0]
        exposure, depth_max = _tour_scales(t, [i])
        cells[(m["layout"], m["path"]), m.get("lighting") or ""] = Image.fromarray(frame_row(t, i, exposure, depth_max, scale))
    if not cells:
        raise UserError(f"{root}: no tour here has a frame")
    cw = max(c.width for c in cells.values())
    ch = max(c.height for c in cells.values())
    left = 110
    sheet = Image.new("RGB", (left + len(cols) * (cw + 6), LABEL_PX + len(rows) * (ch + 6)), "white")
    draw = ImageDraw.Draw(sheet)
    for k, c in enumerate(cols):
        draw.text((left + k * (cw + 6) + 2, 1), (c or "geometry only") + ": RGB | depth | ids", fill="black")
    for r, (layout, path) in enumerate(rows):
        y = LABEL_PX + r * (ch + 6)
        draw.text((2, y + ch // 2 - 6), f"{layout} / {path}", fill="black")
        for k, c in enumerate(cols):
            if ((layout, path), c) in cells:
                sheet.paste(cells[(layout, path), c], (left + k * (cw + 6), y))
    return save_still(sheet, out, fmt)
