"""A built map against the ground truth: per-box center, size and yaw errors, boxes matched by track
id or by nearest same-class center, and medians by kind (:func:`box_errors`).
"""

from __future__ import annotations

import math

import numpy as np

from .document import kind_of


def _yaw_size_align(yaw_b, size_b, yaw_g):
    """The built box's size in the ground-truth box's axes and the yaw error modulo 90 degrees
    (a box is the same box under (sx, sy, yaw) -> (sy, sx, yaw + 90))."""
    d = (yaw_b - yaw_g) % math.pi  # in [0, pi)
    sb = list(size_b)
    if math.pi / 4 <= d < 3 * math.pi / 4:
        sb = [sb[1], sb[0], sb[2]]
    err = abs((d + math.pi / 4) % (math.pi / 2) - math.pi / 4)
    return np.asarray(sb, float), err


def box_errors(doc: dict, gt_doc: dict, match: str = "auto", max_match_m: float = 1.0,
               max_match_structure_m: float = 2.5) -> dict:
    """Per-box errors of a built map against ground truth, and medians by kind.

    ``match``: ``id`` (same id and class: the map kept the track ids), ``nearest`` (same class,
    minimum-cost assignment of center distances within ``max_match_m``, or
    ``max_match_structure_m`` for walls/floors/ceilings), ``mixed`` (``id`` for the track ids,
    ``nearest`` for the boxes the map numbered itself, ``mapping.assigned_ids``) or ``auto``
    (what the map's ``mapping.ids`` says; ``nearest`` for maps without it). Id matches ignore the
    class (a track whose majority label is wrong is counted in ``class_errors``); nearest matches
    need it. Sizes are compared axis by axis after turning the built box by the multiple of 90
    degrees closest to the ground truth's yaw; ``yaw_err_deg`` is modulo 90 degrees (the same box).
    Partially observed objects legitimately get smaller boxes; their errors are reported as they
    are (``size_ratio``: built volume / ground-truth volume).
    """
    from scipy.optimize import linear_sum_assignment

    built = list(doc.get("boxes", []))
    gt = list(gt_doc.get("boxes", []))
    info = doc.get("mapping") or {}
    if match == "auto":
        match = {"track": "id", "mixed": "mixed"}.get(info.get("ids"), "nearest")
    if match not in ("id", "nearest", "mixed"):
        raise ValueError(f"match must be auto, id, nearest or mixed, got {match!r}")
    pairs: list[tuple[int, int]] = []
    if match in ("id", "mixed"):
        assigned = set(info.get("assigned_ids", [])) if match == "mixed" else set()
        gi = {g["id"]: j for j, g in enumerate(gt)}
        for k, b in enumerate(built):
            j = gi.get(b["id"])
            if b["id"] not in assigned and j is not None:
                pairs.append((k, j))
    if match in ("nearest", "mixed"):
        done_b, done_g = {k for k, _ in pairs}, {j for _, j in pairs}
        for cls in sorted({b["class"] for b in built}):
            bk = [k for k, b in enumerate(built) if b["class"] == cls and k not in done_b]
            gk = [j for j, g in enumerate(gt) if g["class"] == cls and j not in done_g]
            if not bk or not gk:
                continue
            lim = max_match_m if kind_of(cls) == "object" else max_match_structure_m
            C = np.linalg.norm(np.array([built[k]["center"] for k in bk], float)[:, None]
                               - np.array([gt[j]["center"] for j in gk], float)[None], axis=-1)
            r, c = linear_sum_assignment(np.where(C <= lim, C, 1e6))
            pairs += [(bk[a], gk[b]) for a, b in zip(r, c) if C[a, b] <= lim]
    rows = []
    for k, j in sorted(pairs):
        b, g = built[k], gt[j]
        sb, yerr = _yaw_size_align(float(b["yaw"]), b["size"], float(g["yaw"]))
        se = np.abs(sb - np.asarray(g["size"], float))
        rows.append({
            "id": b["id"], "gt_id": g["id"], "class": b["class"], "kind": b.get("kind", "object"),
            "class_ok": b["class"] == g["class"],
            "center_err_m": round(float(np.linalg.norm(np.subtract(b["center"], g["center"]))), 4),
            "size_err_m": [round(float(v), 4) for v in se],
            "size_err_max_m": round(float(se.max()), 4),
            "size_ratio": round(float(np.prod(sb) / max(np.prod(g["size"]), 1e-12)), 3),
            "yaw_err_deg": round(math.degrees(yerr), 3),
            "size": [round(float(v), 4) for v in sb], "gt_size": [round(float(v), 4) for v in g["size"]],
        })
    matched_b = {k for k, _ in pairs}
    matched_g = {j for _, j in pairs}
    by_kind = {}
    for kind in ("object", "wall", "floor", "ceiling"):
        rk = [r for r in rows if r["kind"] == kind]
        gt_n = sum(1 for g in gt if g.get("kind", "object") == kind)
        unobs = [gt[j] for j in range(len(gt)) if j not in matched_g and gt[j].get("kind", "object") == kind]
        by_kind[kind] = {
            "gt": gt_n,
            "built": sum(1 for b in built if b.get("kind", "object") == kind),
            "matched": len(rk),
            "median_center_err_m": _med([r["center_err_m"] for r in rk]),
            "median_size_err_max_m": _med([r["size_err_max_m"] for r in rk]),
            "median_size_err_m": [_med([r["size_err_m"][a] for r in rk]) for a in range(3)] if rk else None,
            "median_yaw_err_deg": _med([r["yaw_err_deg"] for r in rk]),
            "unobserved": len(unobs),
        }
    unobserved = [{"id": g["id"], "class": g["class"], "kind": g.get("kind", "object")}
                  for j, g in enumerate(gt) if j not in matched_g]
    unmatched = [{"id": b["id"], "class": b["class"], "kind": b.get("kind", "object")}
                 for k, b in enumerate(built) if k not in matched_b]
    return {
        "match": match,
        "boxes": rows,
        "by_kind": by_kind,
        "class_errors": sum(1 for r in rows if not r["class_ok"]),
        "gt_unobserved": len(unobserved),
        "unobserved": unobserved,
        "built_unmatched": len(unmatched),
        "unmatched": unmatched,
    }


def errors_against_ground_truth(tour, doc: dict) -> dict | None:
    """:func:`box_errors` of a map built from ``tour`` (a ``vrformats.tour.Tour``) against the tour's
    ground-truth boxes (objects.json); None when the tour has none."""
    from vrformats.errors import UserError

    try:
        gt = tour.objects()
    except UserError:
        return None
    return box_errors(doc, gt)


def _med(v):
    return round(float(np.median(v)), 4) if len(v) else None
