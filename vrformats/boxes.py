"""The box format (``videoreloc-boxes/1``) and the instance ids it shares with the label images.

One file holds the boxes of a scene: a tour's ground truth (``objects.json``, written from the
layout by ``synth``) and VideoReloc's map (``reloc map``, read by ``reloc.map.boxmap.BoxMap``)::

    {"format": "videoreloc-boxes/1", "layout": NAME, "frame": "world: right-handed, Z up, metres; ...",
     "classes": {class name: semantic id},
     "boxes": [{"id", "class", "kind", "center": [x, y, z], "size": [sx, sy, sz], "yaw", "movable"}, ...]}

Boxes are gravity-aligned with a yaw about +Z (radians); ``kind`` is object, wall, floor or
ceiling. Instance ids, in the boxes and in the frames' instance channel alike: objects 1..999,
walls 1000+k, floors 2000+k, ceilings 3000+k (0: nothing).
"""

from __future__ import annotations

BOXES_FORMAT = "videoreloc-boxes/1"
FRAME_TEXT = "world: right-handed, Z up, metres; yaw about +Z in radians"

MAX_OBJECT_ID = 999
WALL_ID_BASE, FLOOR_ID_BASE, CEILING_ID_BASE = 1000, 2000, 3000
ID_BASE = {"object": 1, "wall": WALL_ID_BASE, "floor": FLOOR_ID_BASE, "ceiling": CEILING_ID_BASE}
STRUCTURE_KINDS = ("wall", "floor", "ceiling")  # also the class names of structure boxes and detections
STRUCTURE_ID_MIN, STRUCTURE_ID_MAX = WALL_ID_BASE, CEILING_ID_BASE + 999
STRUCTURE_CLASSES = ((WALL_ID_BASE, "wall"), (FLOOR_ID_BASE, "floor"), (CEILING_ID_BASE, "ceiling"))

STRUCT_SLAB = 0.1  # thickness of floor and ceiling boxes (m)


def kind_of_id(instance_id: int) -> str | None:
    """object, wall, floor or ceiling for an instance id; None for 0 (nothing) or out of range."""
    i = int(instance_id)
    if 1 <= i <= MAX_OBJECT_ID:
        return "object"
    for base, kind in STRUCTURE_CLASSES:
        if base <= i < base + 1000:
            return kind
    return None
