"""Walls, floors and ceilings pooled without track ids, split geometrically: walls into straight
vertical runs cut at T-junctions (:func:`split_walls`), floors and ceilings into rooms separated by
the walls (:func:`split_rooms`); and the side a split piece was seen from (:func:`structure_camera`).
"""

from __future__ import annotations

import math

import numpy as np


def _run_geometry(xy: np.ndarray):
    """Centroid, unit direction (PCA), unit normal and [t0, t1] extent of 2D points."""
    c = xy.mean(axis=0)
    if len(xy) > 1:
        _, _, Vt = np.linalg.svd(xy - c, full_matrices=False)
        d = Vt[0]
    else:
        d = np.array([1.0, 0.0])
    n = np.array([-d[1], d[0]])
    t = (xy - c) @ d
    return c, d, n, float(t.min()), float(t.max())


def split_walls(points: np.ndarray, voxel: float, tol: float, gap: float, min_points: int,
                seed: int = 0) -> list[np.ndarray]:
    """Index arrays of straight vertical wall segments, for wall points pooled without track ids.

    On the occupied XY cells: sequential RANSAC lines (inliers within ``tol``), each split where
    its cells leave a gap over ``gap``; parallel runs closer than 0.3 m (the two faces of a wall,
    or leftovers of a slightly tilted line) are merged; runs are cut where another run ends
    against them (T-junctions), as the ground truth splits wall segments there.
    """
    if len(points) < min_points:
        return []
    cell = np.floor(points[:, :2] / voxel).astype(np.int64)
    cells, inv = np.unique(cell, axis=0, return_inverse=True)
    inv = inv.ravel()
    xy = (cells + 0.5) * voxel
    rng = np.random.default_rng(seed)
    free = np.ones(len(xy), bool)
    min_cells = max(3, int(math.ceil(0.3 / voxel)))
    runs: list[np.ndarray] = []  # cell indices
    while free.sum() >= min_cells:
        idx = np.flatnonzero(free)
        Q = xy[idx]
        a = rng.integers(len(Q), size=300)
        b = rng.integers(len(Q), size=300)
        d = Q[b] - Q[a]
        nrm = np.linalg.norm(d, axis=1)
        ok = nrm > 2 * voxel
        if not ok.any():
            break
        a, d = a[ok], d[ok] / nrm[ok, None]
        n = np.stack([-d[:, 1], d[:, 0]], axis=1)
        dist = np.abs(n @ Q.T - np.sum(n * Q[a], axis=1)[:, None])  # (lines, cells)
        score = (dist < tol).sum(axis=1)
        k = int(np.argmax(score))
        if score[k] < min_cells:
            break
        inl = dist[k] < tol
        for _ in range(2):  # refine: PCA of the inliers, inliers again
            c0, dirn, nn, _, _ = _run_geometry(Q[inl])
            new = np.abs((Q - c0) @ nn) < tol
            if new.sum() < min_cells:
                break
            inl = new
        c0, dirn, nn, _, _ = _run_geometry(Q[inl])
        members = idx[inl]
        free[members] = False
        t = (xy[members] - c0) @ dirn
        order = np.argsort(t)
        cut = np.flatnonzero(np.diff(t[order]) > gap) + 1
        runs += [p for p in np.split(members[order], cut) if len(p) >= min_cells]

    def geom(r):
        return _run_geometry(xy[r])

    # merge parallel runs closer than 0.3 m that overlap along their length
    merged = True
    while merged:
        merged = False
        G = [geom(r) for r in runs]
        for i in range(len(runs)):
            ci, di, ni, ti0, ti1 = G[i]
            for j in range(len(runs)):
                if j == i or abs(float(di @ G[j][1])) < math.cos(math.radians(5)):
                    continue
                rel = xy[runs[j]] - ci
                if np.median(np.abs(rel @ ni)) > 0.3:
                    continue
                tj = rel @ di
                ov = min(ti1, tj.max()) - max(ti0, tj.min())
                if ov < 0.5 * min(ti1 - ti0, tj.max() - tj.min()):
                    continue
                runs[i] = np.concatenate([runs[i], runs[j]])
                del runs[j]
                merged = True
                break
            if merged:
                break
    # cut runs at T-junctions: where a run at least 45 degrees off ends within 0.35 m of the line
    G = [geom(r) for r in runs]
    out_runs = []
    for i, r in enumerate(runs):
        ci, di, ni, ti0, ti1 = G[i]
        cuts = []
        for j, (cj, dj, _, tj0, tj1) in enumerate(G):
            if j == i or abs(float(di @ dj)) > math.cos(math.radians(45)) or tj1 - tj0 < 0.5:
                continue
            for e in (cj + dj * tj0, cj + dj * tj1):
                rel = e - ci
                t = float(rel @ di)
                if abs(float(rel @ ni)) < 0.35 and ti0 + 0.3 < t < ti1 - 0.3:
                    cuts.append(t)
        t = (xy[r] - ci) @ di
        edges = [-np.inf] + sorted(cuts) + [np.inf]
        for lo, hi in zip(edges[:-1], edges[1:]):
            sel = (t >= lo) & (t < hi)
            # runs shorter than 0.4 m are reveals (a wall's thickness seen in a door or window)
            if sel.sum() >= min_cells and np.ptp(t[sel]) >= 0.4:
                out_runs.append(r[sel])
    label = np.full(len(xy), -1)
    for k, r in enumerate(out_runs):
        label[r] = k
    pl = label[inv]
    out = [np.flatnonzero(pl == k) for k in range(len(out_runs))]
    return [o for o in out if len(o) >= min_points]


def split_rooms(points: np.ndarray, min_points: int, cell: float = 0.05, barrier: np.ndarray | None = None,
                min_area_m2: float = 1.0) -> list[np.ndarray]:
    """Index arrays of floor (or ceiling) points per room, for points pooled without track ids.

    The occupied XY grid, less the cells of ``barrier`` points (the walls, whose lintels close
    the doorways) grown by one cell, falls into connected regions; regions of at least
    ``min_area_m2`` are rooms and every occupied cell joins the nearest room.
    """
    from scipy import ndimage

    if len(points) < min_points:
        return []
    g = np.floor(points[:, :2] / cell).astype(np.int64)
    g0 = g.min(axis=0) - 2
    g -= g0
    shape = tuple(g.max(axis=0) + 3)
    occ = np.zeros(shape, bool)
    occ[g[:, 0], g[:, 1]] = True
    free = occ.copy()
    if barrier is not None and len(barrier):
        b = np.floor(barrier[:, :2] / cell).astype(np.int64) - g0
        inside = np.all((b >= 0) & (b < np.array(shape)), axis=1)
        wall = np.zeros(shape, bool)
        wall[b[inside, 0], b[inside, 1]] = True
        free &= ~ndimage.binary_dilation(wall)
    lab, n = ndimage.label(free)
    if n == 0:
        return [np.arange(len(points))]
    area = ndimage.sum(free, lab, index=np.arange(1, n + 1)) * cell * cell
    keep = np.zeros(n + 1, bool)
    keep[1:] = area >= min_area_m2
    if not keep.any():
        keep[1 + int(np.argmax(area))] = True
    lab = np.where(keep[lab], lab, 0)
    _, (ix, iy) = ndimage.distance_transform_edt(lab == 0, return_indices=True)
    near = lab[ix, iy]
    pl = near[g[:, 0], g[:, 1]]
    out = [np.flatnonzero(pl == k) for k in np.unique(pl) if k > 0]
    return [o for o in out if len(o) >= min_points]


def structure_camera(kind, P, camera):
    """The side a pooled structure piece was seen from: its own mean camera is not known after
    the split, so floors are seen from above, ceilings from below, walls from the pooled mean."""
    if kind == "floor":
        return np.array([*P[:, :2].mean(axis=0), P[:, 2].max() + 1.0])
    if kind == "ceiling":
        return np.array([*P[:, :2].mean(axis=0), P[:, 2].min() - 1.0])
    return camera
