"""Change statistics of a rearranged layout against its reference (paper, Sec. IV-A).

Objects are matched by id. An object "moved" by the distance between its box centres in the two
layouts; the median is taken over the objects that moved by more than 0.1 m.

Scenes of another size (``scaled_ranges``)
    ``PAPER_RANGES`` are the paper's numbers for an apartment of apt_0's size (82 movable objects,
    97 m2). For another layout ``ref`` (an imported ReplicaCAD scene) the counts scale by
    f = (movable objects of ref) / (movable objects of the built-in apt_0), where an object counts
    when it is movable and its support is not ``free`` (the operator does not move those): a range
    (lo, hi) becomes (floor(lo f), ceil(hi f)), at least 1 where the paper's lower bound is, and
    never empty. The distances keep the paper's range where the flat allows: the median-moved
    range is multiplied by min(1, L(ref) / L(apt_0)), where L is the mean distance between two
    points drawn uniformly on the flat's floor (the union of its room rectangles, computed on a
    grid; about 5.2 m for apt_0). A flat at least as large as apt_0 keeps 1.9-3.5 m; a smaller one
    asks for proportionally shorter moves, since moving a thing across a small flat cannot take it
    as far. ``scaled_ranges(apt_0)`` is ``PAPER_RANGES``.
"""

from __future__ import annotations

import functools
import math

import numpy as np

from .model import Layout, object_box

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


# --------------------------------------------------------------------------------------------
# scenes of another size


def is_imported(layout: Layout) -> bool:
    """True for a layout that is not the procedural kind: imported from ReplicaCAD (``meta["source"]``)
    or holding any object whose asset is not procedural."""
    return layout.meta.get("source") == "replicacad" or any(not o.asset.startswith("proc:") for o in layout.objects)


def movable_counts(layout: Layout) -> dict[str, int]:
    """Movable objects the operator may move (support not ``free``): in all and per support kind
    (``floor``, ``surface`` -- standing on another object --, ``wall``)."""
    objs = [o for o in layout.objects if o.movable and o.support != "free"]
    return {
        "total": len(objs),
        "floor": sum(o.support == "floor" for o in objs),
        "surface": sum(o.support.startswith("object:") for o in objs),
        "wall": sum(o.support.startswith("wall:") for o in objs),
    }


def flat_mean_distance(layout: Layout, max_cells: int = 3000) -> float:
    """Mean distance (m) between two points drawn uniformly on the floor of the flat (the union of
    its room rectangles), on a grid of at least 0.25 m and at most ``max_cells`` cells; 0 without rooms."""
    rooms = layout.stage.rooms
    if not rooms:
        return 0.0
    area = sum(r.area for r in rooms)
    step = max(0.25, math.sqrt(area / max_cells))
    x0, y0 = min(r.rect[0] for r in rooms), min(r.rect[1] for r in rooms)
    x1, y1 = max(r.rect[2] for r in rooms), max(r.rect[3] for r in rooms)
    xs = x0 + (np.arange(max(1, int(math.ceil((x1 - x0) / step)))) + 0.5) * step
    ys = y0 + (np.arange(max(1, int(math.ceil((y1 - y0) / step)))) + 0.5) * step
    gx, gy = np.meshgrid(xs, ys)
    pts = np.stack([gx.ravel(), gy.ravel()], axis=1)
    inside = np.zeros(len(pts), bool)
    for r in rooms:
        inside |= (pts[:, 0] >= r.rect[0]) & (pts[:, 0] <= r.rect[2]) & (pts[:, 1] >= r.rect[1]) & (pts[:, 1] <= r.rect[3])
    p = pts[inside]
    if len(p) < 2:
        return 0.0
    total = 0.0
    for k in range(0, len(p), 512):  # blocks: bounded memory
        d = p[k : k + 512, None, :] - p[None, :, :]
        total += float(np.sqrt((d * d).sum(axis=2)).sum())
    return total / (len(p) * len(p))


@functools.lru_cache(maxsize=1)
def reference_counts() -> tuple[dict[str, int], float]:
    """``movable_counts`` and ``flat_mean_distance`` of the built-in apt_0 (what ``PAPER_RANGES`` and
    the default ``RearrangePlan`` are for)."""
    from .model import load_layout

    apt0 = load_layout("apt_0")
    return movable_counts(apt0), flat_mean_distance(apt0)


def count_scale(layout: Layout) -> float:
    """f = movable objects of ``layout`` / movable objects of the built-in apt_0 (see the module docstring)."""
    return movable_counts(layout)["total"] / reference_counts()[0]["total"]


def distance_scale(layout: Layout) -> float:
    """min(1, L(layout) / L(apt_0)) with L = ``flat_mean_distance``."""
    return min(1.0, flat_mean_distance(layout) / reference_counts()[1])


def scaled_ranges(ref: Layout, ranges: dict = PAPER_RANGES) -> dict:
    """``ranges`` (the paper's) for a layout of ``ref``'s size (rules in the module docstring)."""
    f, d = count_scale(ref), distance_scale(ref)
    out = {}
    for k, (lo, hi) in ranges.items():
        if k == "moved_median_m":
            out[k] = (round(lo * d, 2), round(hi * d, 2))
            continue
        a = math.floor(lo * f + 1e-9)
        if lo > 0:
            a = max(1, a)
        out[k] = (a, max(a, math.ceil(hi * f - 1e-9)))
    return out


# --------------------------------------------------------------------------------------------
# the table the CLI prints

LABELS = {
    "moved_over_0.1m": "moved > 0.1 m",
    "moved_over_0.5m": "moved > 0.5 m",
    "moved_median_m": "moved median (m)",
    "added": "added",
    "removed": "removed",
}


def _fmt(v) -> str:
    return f"{v:.2f}" if isinstance(v, float) else str(v)


def _span(lo, hi) -> str:
    return f"{_fmt(lo)}-{_fmt(hi)}"


def scale_note(ref: Layout) -> str:
    """One line saying how ``scaled_ranges(ref)`` scaled the paper's ranges."""
    have, (base, base_l) = movable_counts(ref)["total"], reference_counts()
    return (f"counts x {count_scale(ref):.3f} ({have} movable objects not free / {base['total']} in the built-in apt_0), "
            f"median x {distance_scale(ref):.2f} (mean floor distance {flat_mean_distance(ref):.1f} m / {base_l:.1f} m)")


def change_table(stats: dict, ranges: dict, paper: dict = PAPER_RANGES) -> list[str]:
    """The change statistics of a variant as a table, one statistic a row: the value, the range it
    must meet (``ranges``: the paper's, or scaled for an imported flat), ``ok``/``OUT`` against it,
    and the paper's own range (unscaled, Sec. IV-A). Returns the lines (no trailing newline)."""
    scaled = ranges != paper
    head = ("statistic", "value", "target" + (" (scaled)" if scaled else ""), "", "paper (apt_0 size)")
    rows = []
    for k, (lo, hi) in ranges.items():
        v = stats[k]
        p = paper.get(k)
        rows.append((LABELS.get(k, k), _fmt(v), _span(lo, hi), "ok" if lo <= v <= hi else "OUT",
                     _span(*p) if p is not None else "-"))
    w = [max(len(r[i]) for r in [head] + rows) for i in range(5)]
    line = lambda r: f"  {r[0]:<{w[0]}}  {r[1]:>{w[1]}}  {r[2]:>{w[2]}} {r[3]:<{w[3]}}  {r[4]:>{w[4]}}".rstrip()  # noqa: E731
    return [line(head)] + [line(r) for r in rows]
