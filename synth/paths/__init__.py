"""Camera paths planned once and rendered in every layout x lighting (no Blender here).

Two kinds of path, both as camera-to-world poses (OpenCV axes, ``vrformats.camera``) at a fixed frame
rate, stored as TUM text (``camera.write_tum``) plus a sidecar YAML with the planner's inputs:

``plan_query_path(layouts)``
    A smooth walk through every room of a set of layouts that share one shell (``apt_0``..``apt_5``):
    the path every layout x lighting is rendered along. It keeps ``clearance`` from the objects of
    *every* layout given, so the same poses are valid in each of them.
``plan_mapping_path(layout)``
    A cross-hatch tour of one layout: in each room lawnmower sweeps along x, then along y, the
    camera looking across the sweep (alternating sides), rooms chained through doors.

Clearance rule (``obstacles``)
    ``"all"`` (default): the camera centre keeps ``clearance`` metres horizontally from the
    footprint of every object except ceiling-mounted ones, whatever its height (a person walking
    on the floor never passes over a table), and from the walls. ``"band"``: only objects whose
    box reaches into the camera's height band (the path's height range widened by ``BAND`` =
    0.3 m both ways) count; objects entirely below or above are at least ``BAND`` away vertically.
    Walls are the edges of the rooms' free interiors (``Room.outline``: the room's polygon when it
    has one, an L-shaped room or a part of an open plan, else its rect), cut where an interior door
    (one that connects two rooms) is, plus that door's jambs; the entrance door counts as wall.
    An edge two polygon rooms share (an open plan split into rooms) is open. A stage derived from a
    mesh (``Stage.asset``: ReplicaCAD) adds the faces of its own walls (``Stage.walls``, cut at
    interior doors): its rooms need not end at the walls. Flat objects on the floor (top at most
    ``FLAT`` = 5 cm above it: rugs, mats) are walked over, not obstacles. A camera outside every
    room (``Room.contains``) and door gap has clearance 0. Objects of class ``door`` (ReplicaCAD's
    articulated door leaves, loaded open) are obstacles like any other: a leaf standing in a
    doorway is where a camera would hit it. Planner and checker use the same functions for all of
    this (``clearance.inside_free``, ``wall_segments``, ``room_index``), so a planned path checks
    with the clearance the planner reported. ``synth path plan`` records a layout given as a file
    by its absolute path (a ReplicaCAD import is named ``apt_0`` like the built-in layout), so
    ``synth path check`` and replanning read that file.

Planning (both kinds)
    An exact clearance field on a 2.5 cm grid (distance from each cell centre to the nearest wall
    segment and obstacle footprint, min over all layouts) gives the walkable cells
    (>= clearance + ``MARGIN``). Waypoints are picked per room (cells inside its polygon or rect) from local maxima of the clearance
    (seeded), ordered into a tour (nearest neighbour + 2-opt on geodesic costs), connected by
    shortest grid paths whose cost prefers staying ``PREFER`` metres from obstacles and floor
    that is free of low furniture in most layouts; dead ends turn in a small loop. The polyline
    is smoothed (Gaussian along arc length); wherever the smoothed curve comes closer than
    ``clearance`` + 1 cm to anything (exact distances) the smoothing is reduced there. Then the
    curve is resampled at the constant step ``speed / fps`` and given heights and headings:
    heading = walking direction (smoothed) + slow look-around, rate-limited and smoothed, slow
    pitch and height changes, a small walking bob and roll. Deterministic for a given seed.

The built-in layouts and 0.3 m
    Rearranged variants put furniture where the reference has free floor, so the free space the
    six built-in layouts share is small. ``synth.layout.rearrange`` therefore keeps every variant out of
    a walkway through all rooms of the reference (planned with 0.35 m): the shared space always
    holds a route through every room, and the shipped query path keeps 0.3 m from every object
    in all six layouts. If the layouts given leave no such route, ``plan_query_path`` raises a
    ``UserError`` naming each unreachable room, its roomiest spot, the clearance at which it would
    join the others, and the largest clearance the layouts allow. A room no camera fits in even
    when empty (no point ``clearance`` + ``MARGIN`` from its walls: a niche, a strip of floor, a
    rect inside another room's) is not required; ``stats.rooms_skipped`` names it.

Files: ``scenes/paths/NAME.txt`` (TUM, ``t = frame / fps``) and ``NAME.yaml``
(``format: synth-camera-path/1``: name, kind, fps, frames, seed, layouts, planner parameters,
summary stats).

Modules (import from them; this package re-exports nothing)
    ``model``: ``CameraPath`` and the constants. ``clearance``: walls, footprints, exact clearance,
    reports against a path's declared clearance. ``space``: the planning grid and what both
    planners share. ``curves``: smoothing, turn loops, slow noise, poses. ``query``, ``mapping``:
    the planners. ``shipped``: ``SHIPPED``, ``plan_path``, ``replan``, ``generate_shipped``.
    ``files``: save, load, list. ``summary``: ``path_summary``, ``plot_path``. ``cli``: ``synth path``.
"""
