"""Random views: independent camera poses in free space, for training data (not a walk).

Each view stands on a free cell of the planning grid (``clearance`` from walls and from every
object of the layouts, exact distances) in the connected free space, with rooms visited in
proportion to their free area but each room at least ``min_per_room`` views. Height, pitch and
roll are drawn like the query walk's (``Q_HEIGHT`` +- ``Q_HEIGHT_VAR`` plus the step bob, pitch
around ``Q_PITCH`` with ``Q_PITCH_VAR``, roll ``Q_ROLL``), widened by ``spread`` so that a
detector trained on the views has seen the query's poses and a little more; yaw is uniform.

Consecutive views are unrelated, so a views path is for rendering single frames (its frame rate
only numbers them). Same layouts and seed, same poses, byte for byte (the stored precision of
``save_path``).
"""

from __future__ import annotations

import math

import numpy as np

from vrformats import camera
from vrformats.errors import UserError
from vrformats.fields import is_integer

from ..scene.model import Layout
from .curves import track_poses
from .model import BOB, DEFAULTS, Q_HEIGHT, Q_HEIGHT_VAR, Q_PITCH, Q_PITCH_VAR, Q_ROLL, CameraPath
from .space import Space, require_rooms

VIEWS_SPREAD = 1.5  # the query's height, pitch and roll ranges, widened by this factor
MIN_PER_ROOM = 3


def plan_views(layouts: list[Layout], frames: int = DEFAULTS.views_frames, seed: int = DEFAULTS.seed,
               clearance: float = DEFAULTS.clearance, spread: float = VIEWS_SPREAD,
               min_per_room: int = MIN_PER_ROOM, name: str = "views") -> CameraPath:
    """``frames`` random views in the free space that all ``layouts`` share (see the module doc)."""
    if not is_integer(frames) or frames <= 0:
        raise UserError(f"views: frames must be a positive integer, got {frames!r}")
    if not clearance > 0:
        raise UserError(f"views: clearance must be positive, got {clearance!r}")
    if not layouts:
        raise UserError("plan_views needs at least one layout")
    rng = np.random.default_rng([seed, 7])
    h_var = (Q_HEIGHT_VAR + BOB) * spread
    space = Space(list(layouts), clearance, Q_HEIGHT - h_var, Q_HEIGHT + h_var, "all")
    require_rooms(space, "views")
    free = np.flatnonzero((space.comp & (space.room >= 0)).ravel())
    rooms = space.room.ravel()[free]
    present = np.unique(rooms)
    # rooms in proportion to free area, each at least min_per_room (when frames allow)
    area = np.array([np.count_nonzero(rooms == r) for r in present], float)
    base = min(min_per_room, frames // len(present))
    quota = np.full(len(present), base)
    rest = frames - int(quota.sum())
    if rest > 0:
        extra = np.floor(rest * area / area.sum()).astype(int)
        short = rest - int(extra.sum())
        extra[np.argsort(-(rest * area / area.sum() - extra), kind="stable")[:short]] += 1
        quota += extra
    cells = np.concatenate([rng.choice(free[rooms == r], size=int(q), replace=True) for r, q in zip(present, quota) if q])
    rng.shuffle(cells)
    xy = space.xy(cells) + rng.uniform(-0.5, 0.5, (len(cells), 2)) * space.grid  # anywhere in the cell
    ok = space.exact(xy) >= clearance
    xy[~ok] = space.xy(cells[~ok])  # a jitter that left the clearance: the cell centre (walkable)
    n = len(xy)
    z = Q_HEIGHT + rng.uniform(-h_var, h_var, n)
    yaw = rng.uniform(-math.pi, math.pi, n)
    pitch = np.clip(rng.normal(Q_PITCH, Q_PITCH_VAR * spread, n), Q_PITCH - 3 * Q_PITCH_VAR * spread,
                    Q_PITCH + 3 * Q_PITCH_VAR * spread)
    roll = rng.normal(0.0, Q_ROLL * spread, n)
    poses = track_poses(xy, z, yaw, pitch, roll)
    meta = {
        "kind": "views", "layouts": [lay.name for lay in layouts], "seed": int(seed), "frames": int(frames),
        "clearance": float(clearance), "spread": float(spread), "rooms": {space.stage.rooms[int(r)].name: int(q)
                                                                       for r, q in zip(present, quota)},
        "min_clearance_m": round(float(space.exact(xy).min()), 4),
    }
    return CameraPath(name, poses, camera.DEFAULT_FPS, meta)
