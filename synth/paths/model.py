"""The camera path itself (``CameraPath``: poses, frame rate, metadata) and the planners' constants.

Poses are camera-to-world, OpenCV axes (``vrformats.camera``). The constants are shared by the
clearance checks (``BAND``), the planning grid and both planners; ``synth.paths`` explains them.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from vrformats import camera


__all__ = ["CameraPath", "FORMAT", "BAND", "PlannerDefaults", "DEFAULTS"]

FORMAT = "synth-camera-path/1"
BAND = 0.3  # m: objects reaching within this height of the camera's height range obstruct it
GRID = 0.025  # m: planning grid
MARGIN = 0.03  # m: walkable cells keep clearance + MARGIN (cell centres; exact distances)
CURVE_MARGIN = 0.01  # m: the smoothed curve keeps clearance + CURVE_MARGIN (exact distances)
PREFER = 0.9  # m: paths prefer to stay this far from obstacles
DCAP = 3.0  # m: clearance values are capped here
MAX_YAW_RATE = math.radians(80.0)  # rad/s, before the final smoothing (which cannot raise it)
DS = 0.05  # m: arc-length step of the dense curve before the final resampling

# query path: heights and head motion
Q_HEIGHT, Q_HEIGHT_VAR, BOB = 1.50, 0.07, 0.012  # m
Q_LOOK, Q_PITCH, Q_PITCH_VAR, Q_ROLL = math.radians(30.0), math.radians(-5.0), math.radians(6.0), math.radians(1.2)
Q_SMOOTH = 0.45  # m: Gaussian sigma of the query curve
# mapping path
M_HEIGHTS = (1.40, 1.60)  # m: x sweeps, y sweeps
M_HEIGHT_VAR = 0.03
M_LOOK, M_PITCH, M_PITCH_VAR, M_ROLL = math.radians(15.0), math.radians(-8.0), math.radians(4.0), math.radians(1.0)
M_SMOOTH = 0.25
M_SPACING = 1.0  # m: nominal distance between sweep lines
M_MIN_RUN = 0.5  # m: shorter free runs on a sweep line are skipped
STEP_HZ = 1.8  # steps per second at 1 m/s


@dataclass(frozen=True)
class PlannerDefaults:
    """The planners' input defaults, in one place: the ``plan_*_path`` functions' keyword defaults,
    ``synth path plan``'s option defaults and the shipped paths (``synth.paths.shipped.SHIPPED``)
    read them from :data:`DEFAULTS`."""

    fps: float = camera.DEFAULT_FPS  # frames per second (the cameras' default, vrformats.camera)
    speed: float = 1.0  # m/s along the path
    clearance: float = 0.3  # m the camera centre keeps from obstacles and walls
    obstacles: str = "all"  # "all": every object but ceiling-mounted ones; "band": those in the height band
    seed: int = 0
    query_frames: int = 4000  # the paper's query tour
    mapping_frames: int = 6000  # the paper's mapping tour
    views_frames: int = 200  # random views (synth.paths.views)


DEFAULTS = PlannerDefaults()


# --------------------------------------------------------------------------------------------
# data


@dataclass
class CameraPath:
    name: str
    poses: np.ndarray  # (N, 4, 4) camera-to-world, OpenCV axes
    fps: float = camera.DEFAULT_FPS
    meta: dict[str, Any] = field(default_factory=dict)

    def __len__(self) -> int:
        return len(self.poses)

    @property
    def positions(self) -> np.ndarray:
        return np.asarray(self.poses)[:, :3, 3]

    @property
    def duration(self) -> float:
        return len(self.poses) / self.fps

    @property
    def length(self) -> float:
        p = self.positions
        return float(np.linalg.norm(np.diff(p, axis=0), axis=1).sum()) if len(p) > 1 else 0.0
