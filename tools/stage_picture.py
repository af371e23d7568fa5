#!/usr/bin/env python3
"""The same view on several stage variants: per variant a row of RGB by day, RGB at night (each
auto-exposed), depth (0.5-5.5 m, grey) and instance ids (seeded colours), of apt_0's query tours.

    python tools/stage_picture.py FRAME OUT.jpg NAME=JOBDIR [NAME=JOBDIR ...]

JOBDIR: a ``replicacad_stages`` render of one stage variant (its ``apt_0__day__query`` and
``apt_0__night__query`` tours); FRAME must be one with RGB (every 5th). docs/img/stage_variants.jpg is
``python tools/stage_picture.py 300 docs/img/stage_variants.jpg plain=out/stages/plain
standin=out/stages/standin scanlike=out/stages/scanlike``.
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from vrformats.errors import UserError  # noqa: E402
from vrformats.tour import Tour, tonemap  # noqa: E402

SCALE = 2  # pixels per rendered pixel in the picture


def row(name: str, job: Path, frame: int):
    from PIL import Image, ImageDraw

    tiles = []
    for light in ("day", "night"):
        f = Tour(job / f"apt_0__{light}__query").frame(frame)
        if f.rgb is None:
            raise UserError(f"{job / f'apt_0__{light}__query'}: frame {frame} has no RGB (every 5th frame has)")
        rgb, _ = tonemap(f.rgb)
        tiles.append((np.clip(np.asarray(rgb), 0, 1) * 255).astype(np.uint8))
    d = np.nan_to_num(f.depth, nan=0.0, posinf=0.0)
    g = (np.clip((d - 0.5) / 5.0, 0, 1) * 255).astype(np.uint8)
    tiles.append(np.stack([g] * 3, -1))
    ids = f.instance.astype(np.int64)
    pal = np.random.default_rng(0).integers(40, 255, size=(int(ids.max()) + 1, 3)).astype(np.uint8)
    tiles.append(pal[ids])
    a = np.concatenate(tiles, axis=1)
    img = Image.fromarray(a).resize((a.shape[1] * SCALE, a.shape[0] * SCALE), Image.NEAREST)
    out = Image.new("RGB", (130 + img.width, img.height), "white")
    ImageDraw.Draw(out).text((8, img.height // 2 - 6), name, fill="black")
    out.paste(img, (130, 0))
    return out


def main(argv=None) -> int:
    from PIL import Image

    args = sys.argv[1:] if argv is None else argv
    if len(args) < 3 or not args[0].isdigit() or not all("=" in a for a in args[2:]):
        print(__doc__, file=sys.stderr)
        return 2
    try:
        rows = [row(a.split("=", 1)[0], Path(a.split("=", 1)[1]), int(args[0])) for a in args[2:]]
    except UserError as e:
        print(f"error: {e}", file=sys.stderr)
        return 2
    canvas = Image.new("RGB", (max(r.width for r in rows), sum(r.height for r in rows) + 4 * (len(rows) - 1)), "white")
    y = 0
    for r in rows:
        canvas.paste(r, (0, y))
        y += r.height + 4
    canvas.save(args[1], quality=90)
    print(f"wrote {args[1]} {canvas.size[0]}x{canvas.size[1]}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
