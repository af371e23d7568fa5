"""The volumes that doors and windows keep: a door's clearance zone and an opening's box in its wall.

Used by placement and the layout checks (nothing may stand in a door's zone or cover an opening)
and by the camera paths' clearance test (a path may pass only through door openings).
"""

from __future__ import annotations

import math

from . import geometry as geo
from .model import Opening, Stage

DOOR_CLEARANCE = 0.9  # depth of the free zone on each side of a door (m)
DOOR_ZONE_HEIGHT = 2.0


def door_zone(stage: Stage, op: Opening) -> geo.OrientedBox:
    """The box in front of and behind a door that must stay free so the door stays passable."""
    w = stage.wall(op.wall)
    c = op.center_xy(w)
    yaw = math.atan2(w.direction[1], w.direction[0])
    depth = 2 * DOOR_CLEARANCE + w.thickness
    return geo.OrientedBox(0, "door_zone", (float(c[0]), float(c[1]), stage.floor_z + DOOR_ZONE_HEIGHT / 2),
                           (op.width, depth, DOOR_ZONE_HEIGHT), yaw, kind="zone")


def opening_box(stage: Stage, op: Opening, depth_extra: float = 0.0) -> geo.OrientedBox:
    """The volume of an opening inside its wall (optionally deeper than the wall)."""
    w = stage.wall(op.wall)
    c = op.center_xy(w)
    yaw = math.atan2(w.direction[1], w.direction[0])
    return geo.OrientedBox(0, op.kind, (float(c[0]), float(c[1]), stage.floor_z + op.bottom + op.height / 2),
                           (op.width, w.thickness + 2 * depth_extra, op.height), yaw, kind="zone")
