"""Training sets for the learned detector: rendered tours packed into one small file.

``pack`` reads the RGB frames of tours (``vrformats.tour``), encodes them as the camera would (per-frame
auto exposure, ``vrformats.tour.tonemap``, 8-bit sRGB; the exposure's scale is kept per frame, so that
training can recover linear light for the camera augmentation) and stores each frame as a JPEG (RGB) and two
lossless PNGs (class index, 16-bit instance id), with the frame's tour, layout and lighting. One ``.npz`` of byte strings keeps 3,840 frames at 160x120 near
45 MB, small enough to travel to a training machine; ``load`` decodes it with Pillow, so training
needs neither OpenEXR nor the rest of the toolkit.

Classes: index 0 is background; index k >= 1 names a class (``tour_classes``: the classes of the
tours' objects.json, in semantic-id order), stored in the file and later in the exported model.
Semantic ids of the frames are mapped through each tour's objects.json ``classes`` (name -> id).
"""

from __future__ import annotations

import io
import json
import sys
from dataclasses import dataclass
from pathlib import Path

import numpy as np

PACK_FORMAT = "videoreloc-detector-data/1"
JPEG_QUALITY = 92


@dataclass
class TrainingSet:
    rgb: np.ndarray  # (N, H, W, 3) uint8 sRGB
    semantic: np.ndarray  # (N, H, W) uint8 class index (0 background)
    instance: np.ndarray  # (N, H, W) int32 instance id (0 none)
    tours: list[str]
    lightings: list[str | None]
    layouts: list[str]
    classes: list[str]  # index -> class name (index 0: "background")
    scales: np.ndarray | None = None  # (N,) the tonemap's exposure scale per frame (linear = decode(rgb) / scale); None: an older pack

    def __len__(self) -> int:
        return len(self.rgb)


def _encode(img: np.ndarray, fmt: str) -> bytes:
    from PIL import Image

    buf = io.BytesIO()
    if fmt == "JPEG":
        Image.fromarray(img).save(buf, format="JPEG", quality=JPEG_QUALITY, subsampling=0)
    else:
        Image.fromarray(img).save(buf, format="PNG", optimize=True)
    return buf.getvalue()


def _decode(b: bytes) -> np.ndarray:
    from PIL import Image

    return np.asarray(Image.open(io.BytesIO(b)))


def tour_classes(tour_dirs) -> list[str]:
    """["background", then every class of the tours' objects.json, in semantic-id order]."""
    from vrformats.tour import Tour

    ids: dict[str, int] = {}
    for d in tour_dirs:
        for name, sid in Tour(d).objects()["classes"].items():
            ids.setdefault(name, int(sid))
    return ["background"] + sorted(ids, key=lambda n: (ids[n], n))


def pack(tour_dirs, out, classes: list[str], every: int = 1, progress: bool = True) -> dict:
    """Pack every ``every``-th RGB frame of the tours into ``out`` (.npz); returns a summary."""
    from vrformats.atomic import save_npz_atomic
    from vrformats.errors import UserError
    from vrformats.tour import Tour, tonemap

    index = {c: k for k, c in enumerate(classes)}
    blobs: list[bytes] = []
    meta = []
    for d in tour_dirs:
        tour = Tour(d)
        if not tour.has_rgb():
            raise UserError(f"{tour.root}: no RGB frames to train a detector on")
        sem_map = np.zeros(65536, np.uint8)
        for name, sid in tour.objects()["classes"].items():
            if name in index:
                sem_map[int(sid)] = index[name]
        lighting = tour.meta.get("lighting")
        layout = tour.meta.get("layout")
        for i in tour.frame_indices[::every]:
            f = tour.frame(int(i), rgb=True, depth=False, instance=True, semantic=True)
            if f.rgb is None:
                continue
            srgb, scale = tonemap(f.rgb)
            rgb8 = np.round(srgb * 255.0).astype(np.uint8)
            sem = sem_map[np.minimum(f.semantic, 65535).astype(np.int64)]
            inst = np.minimum(f.instance, 65535).astype(np.uint16)
            blobs += [_encode(rgb8, "JPEG"), _encode(sem, "PNG"), _encode(inst, "PNG")]
            meta.append({"tour": tour.name, "frame": int(i), "lighting": lighting, "layout": layout,
                         "exposure": float(scale)})
        if progress:
            print(f"packed {tour.name}: {len(meta)} frames so far", file=sys.stderr)
    if not meta:
        raise UserError("no RGB frames in the given tours")
    sizes = np.array([len(b) for b in blobs], np.int64)
    header = {"format": PACK_FORMAT, "classes": list(classes), "frames": meta, "jpeg_quality": JPEG_QUALITY}
    save_npz_atomic(out, compressed=False, blob=np.frombuffer(b"".join(blobs), np.uint8), sizes=sizes,
                    header=np.frombuffer(json.dumps(header).encode(), np.uint8))
    return {"frames": len(meta), "bytes": int(Path(out).stat().st_size), "classes": len(classes)}


def open_pack(path):
    """(the open .npz, its header) of a packed training set; a ``UserError`` naming the file when it
    is not one (another file, another .npz, a damaged one)."""
    import zipfile

    from vrformats.errors import UserError, one_line

    what = f"{path}: not a training set from reloc detector pack"
    if not zipfile.is_zipfile(path):
        raise UserError(f"{what} (not an .npz archive)")
    try:
        z = np.load(path)
        if not isinstance(z, np.lib.npyio.NpzFile) or not {"header", "blob", "sizes"} <= set(z.files):
            raise UserError(f"{what} (a {PACK_FORMAT} .npz holds header, blob and sizes)")
        header = json.loads(bytes(z["header"]).decode())
    except (OSError, ValueError, EOFError, zipfile.BadZipFile, UnicodeDecodeError) as e:
        raise UserError(f"{what} ({one_line(e, 120)})") from None
    if not isinstance(header, dict) or header.get("format") != PACK_FORMAT:
        raise UserError(f"{what} (format {header.get('format') if isinstance(header, dict) else None!r}, "
                        f"expected {PACK_FORMAT})")
    return z, header


def load(path) -> TrainingSet:
    """Decode a packed training set (needs numpy and Pillow only)."""
    z, header = open_pack(path)
    blob, sizes = z["blob"], z["sizes"]
    ends = np.cumsum(sizes)
    starts = ends - sizes
    parts = [bytes(blob[a:b]) for a, b in zip(starts, ends)]
    rgb = np.stack([_decode(b) for b in parts[0::3]])
    sem = np.stack([_decode(b) for b in parts[1::3]]).astype(np.uint8)
    inst = np.stack([_decode(b) for b in parts[2::3]]).astype(np.int32)
    fr = header["frames"]
    scales = np.array([m["exposure"] for m in fr], np.float32) if all("exposure" in m for m in fr) else None
    return TrainingSet(rgb, sem, inst, [m["tour"] for m in fr], [m["lighting"] for m in fr],
                       [m["layout"] for m in fr], header["classes"], scales)


def boundaries(instance: np.ndarray) -> np.ndarray:
    """(…, H, W) bool: pixels whose 4-neighbour has another instance id (0 counts as an id), so
    two touching instances of one class are cut apart."""
    b = np.zeros(instance.shape, bool)
    d = instance[..., 1:, :] != instance[..., :-1, :]
    b[..., 1:, :] |= d
    b[..., :-1, :] |= d
    d = instance[..., :, 1:] != instance[..., :, :-1]
    b[..., :, 1:] |= d
    b[..., :, :-1] |= d
    return b
