"""Supporting surfaces: the rectangles of an object where smaller objects can stand.

Procedural objects get theirs from their generator (``synth.assets.registry.support_surfaces``), mesh
objects from their geometry (``synth.mesh.surfaces``), ReplicaCAD receptacles from their boxes
(``synth.sources.replicacad.receptacles``); all three are ``Surface`` rectangles. No dependencies.
"""
from __future__ import annotations

from dataclasses import dataclass

__all__ = ["Surface"]


@dataclass(frozen=True)
class Surface:
    """A supporting rectangle in the object's local frame.

    ``z`` is the height of the surface above the object's bottom; ``xmin..xmax`` x ``ymin..ymax`` the
    usable area (about 2 cm inside the supporting board's edges, excluding arm- and backrests);
    ``clearance`` the free height above it (to the next board for shelves, 0.5 for seats,
    ``inf`` for open tops); ``band`` how far above ``z`` a resting object's bottom may be (0 for
    boards; a ReplicaCAD receptacle's box height, ``synth.sources.replicacad.receptacles``)."""

    z: float
    xmin: float
    xmax: float
    ymin: float
    ymax: float
    clearance: float
    band: float = 0.0  # the bottom of what stands here may lie up to this far above z (a receptacle box)
