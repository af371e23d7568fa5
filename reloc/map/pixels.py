"""Which pixels of a detection mask count, and where they are in the world.

A mask's depth-consistent pixels (:func:`mask_pixels`): valid depth; not on the far side of a
depth discontinuity (:func:`depth_edges`); near the mask's edge, within the depth range of the
mask's interior around them (:func:`_consistent_rim`); for objects, within a band around the mask's
median depth. :class:`Backprojector` places pixels in the world with the frame's camera-to-world
pose.
"""

from __future__ import annotations

import numpy as np

from .settings import MapBuildSettings


class Backprojector:
    def __init__(self, K: np.ndarray, shape: tuple[int, int]):
        H, W = shape
        u, v = np.meshgrid(np.arange(W, dtype=float), np.arange(H, dtype=float))
        pix = np.stack([u, v, np.ones_like(u)], axis=-1).reshape(-1, 3)
        self.rays = pix @ np.linalg.inv(K).T  # camera-frame rays with z = 1, (H*W, 3)
        self.shape = shape

    def __call__(self, depth: np.ndarray, pose: np.ndarray) -> np.ndarray:
        """World points of every pixel, (H*W, 3) (meaningless where depth is 0)."""
        pc = self.rays * depth.reshape(-1, 1)
        return pc @ pose[:3, :3].T + pose[:3, 3]


def depth_edges(z: np.ndarray, valid: np.ndarray, abs_m: float, rel: float) -> np.ndarray:
    """Pixels on the far side of a depth discontinuity: a valid 4-neighbour is nearer by more
    than abs_m + rel * z. These are the flying pixels and the background a mask bleeds onto; the
    near side (an object's own silhouette) is kept."""
    edge = np.zeros(z.shape, bool)
    thr = abs_m + rel * z
    for dy, dx in ((0, 1), (1, 0)):
        a = (slice(None, z.shape[0] - dy), slice(None, z.shape[1] - dx))
        b = (slice(dy, None), slice(dx, None))
        both = valid[a] & valid[b]
        diff = z[b] - z[a]  # > 0: b is farther than a
        edge[b] |= both & (diff > thr[b])
        edge[a] |= both & (-diff > thr[a])
    return edge


def _consistent_rim(mask: np.ndarray, z: np.ndarray, valid: np.ndarray, r: int, abs_m: float,
                    rel: float) -> np.ndarray:
    """The mask less the rim pixels (within ``r`` pixels of its edge) whose depth leaves the range
    of the mask's interior depths within 2r of them by more than abs_m + rel * z plus that range's
    own width (a slanted surface continues its depth ramp): where a mask bleeds
    onto a surface behind or in front of its object. Rim pixels with no interior pixel nearby
    (thin parts: legs, frames) are kept, the depth-edge test being all that checks them."""
    import cv2

    ys, xs = np.nonzero(mask)
    if len(ys) == 0:
        return mask
    H, W = mask.shape
    y0, y1 = max(int(ys.min()) - 2 * r, 0), min(int(ys.max()) + 2 * r + 1, H)
    x0, x1 = max(int(xs.min()) - 2 * r, 0), min(int(xs.max()) + 2 * r + 1, W)
    m = mask[y0:y1, x0:x1]
    zz = z[y0:y1, x0:x1].astype(np.float32)
    k = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * r + 1, 2 * r + 1))
    inner = cv2.erode(m.astype(np.uint8), k, borderType=cv2.BORDER_CONSTANT, borderValue=0).astype(bool)
    inner &= valid[y0:y1, x0:x1]
    rim = m & ~inner
    if not rim.any():
        return mask
    # the interior's depth range within 2r of each rim pixel (twice the rim's width, so that a
    # slanted surface's ramp shows in the range)
    k2 = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (4 * r + 1, 4 * r + 1))
    zmax = cv2.dilate(np.where(inner, zz, 0.0).astype(np.float32), k2)
    zmin = cv2.erode(np.where(inner, zz, np.float32(1e9)).astype(np.float32), k2)
    near = zmax > 0
    # slanted surfaces (seen at grazing angles) continue their interior's depth ramp: allow one
    # more window's worth of it beyond the interior's range
    tol = abs_m + rel * zz + np.where(near, zmax - zmin, 0.0)
    bad = rim & near & ((zz > zmax + tol) | (zz < zmin - tol))
    if not bad.any():
        return mask
    out = mask.copy()
    out[y0:y1, x0:x1] &= ~bad
    return out


def mask_pixels(mask, kind: str, zc: np.ndarray, zf: np.ndarray, valid: np.ndarray, good: np.ndarray,
                 s: MapBuildSettings) -> np.ndarray | None:
    """Flat pixel indices of a detection mask's depth-consistent pixels, or None when fewer than
    ``min_mask_pixels`` are left. ``zc``: the frame's depth (0 where not ``valid``), ``zf`` its flat
    view, ``good`` (flat): valid and not on the far side of a depth discontinuity. The mask loses the
    rim pixels that leave its interior's depth (:func:`_consistent_rim`) and, for objects, the
    pixels outside a band around its median depth."""
    mask = np.asarray(mask, bool)
    if s.rim_px > 0:
        mask = _consistent_rim(mask, zc, valid, s.rim_px, s.edge_abs_m, s.edge_rel)
    idx = np.flatnonzero(mask.ravel() & good)
    if len(idx) < s.min_mask_pixels:
        return None
    if kind == "object":
        zm = zf[idx]
        med = float(np.median(zm))
        idx = idx[np.abs(zm - med) <= s.band_scale * med + s.band_offset_m]
        if len(idx) < s.min_mask_pixels:
            return None
    return idx
