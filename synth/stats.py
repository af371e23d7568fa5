"""Change statistics of a rearranged layout against its reference (paper, Sec. IV-A).

Objects are matched by id. An object "moved" by the distance between its box centres in the two
layouts; the median is taken over the objects that moved by more than 0.1 m.
"""

from __future__ import annotations

import numpy as np

from .scene import Layout, object_box

MOVED_MIN = 0.1
MOVED_FAR = 0.5

# The paper's ReplicaCAD variants (Sec. IV-A): what apt_1..apt_5 must reproduce.
PAPER_RANGES = {
    "moved_over_0.1m": (68, 76),
    "moved_over_0.5m": (59, 68),
    "moved_median_m": (1.9, 3.5),
    "added": (8, 10),
    "removed": (1, 10),
}


def moved_distances(ref: Layout, var: Layout) -> dict[int, float]:
    rb = {o.id: np.asarray(object_box(o).center) for o in ref.objects}
    vb = {o.id: np.asarray(object_box(o).center) for o in var.objects}
    return {i: float(np.linalg.norm(vb[i] - rb[i])) for i in sorted(rb.keys() & vb.keys())}


def change_stats(ref: Layout, var: Layout) -> dict:
    d = moved_distances(ref, var)
    moved = [v for v in d.values() if v > MOVED_MIN]
    ref_ids, var_ids = {o.id for o in ref.objects}, {o.id for o in var.objects}
    return {
        "reference": ref.name,
        "variant": var.name,
        "moved_over_0.1m": len(moved),
        "moved_over_0.5m": sum(v > MOVED_FAR for v in moved),
        "moved_median_m": round(float(np.median(moved)), 3) if moved else 0.0,
        "added": len(var_ids - ref_ids),
        "removed": len(ref_ids - var_ids),
    }


def within_paper_ranges(stats: dict) -> dict[str, bool]:
    return {k: lo <= stats[k] <= hi for k, (lo, hi) in PAPER_RANGES.items()}
