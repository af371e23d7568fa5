"""The box map as map construction writes it (the ``videoreloc-boxes/1`` document that
:mod:`reloc.map.boxmap` reads): the kind of a class, its text form
(:func:`dumps_map`) and the ground-truth document of a tour (:func:`map_from_tour`, what
``reloc map ground-truth`` writes; ``synth scene export-boxes`` writes that of a layout).
"""

from __future__ import annotations

import json

from vrformats.boxes import STRUCTURE_KINDS
from vrformats.tour import Tour


def kind_of(cls: str) -> str:
    return cls if cls in STRUCTURE_KINDS else "object"


def dumps_map(doc: dict) -> str:
    """Compact, diff-friendly JSON: header fields indented, one box per line."""
    head = {k: v for k, v in doc.items() if k != "boxes"}
    lines = ["{"]
    for k, v in head.items():
        lines.append(f" {json.dumps(k)}: {json.dumps(v)},")
    boxes = doc.get("boxes", [])
    lines.append(' "boxes": [' + ("" if boxes else "]"))
    for i, b in enumerate(boxes):
        lines.append("  " + json.dumps(b, separators=(", ", ": ")) + ("," if i + 1 < len(boxes) else ""))
    if boxes:
        lines.append(" ]")
    lines.append("}")
    return "\n".join(lines) + "\n"


def map_from_tour(tour_dir) -> dict:
    """The ground-truth boxes of a tour's layout as a map: its ``objects.json``, which the
    renderer wrote in the same format (``vrformats.boxes``)."""
    return Tour(tour_dir).objects()
