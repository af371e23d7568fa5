"""Relocalization methods, registered by name: one module per method.

``registry`` holds ``Method`` (what an experiment asks of a method: the maps it needs and how
they are built, how it runs on a query tour, its Table I rows and labels) and ``register``/``get``/
``names``; the modules below each register one in-tree method, in the order of the experiment's
runs (VideoReloc first: the clip-rigid controls reuse its clips). A new method is one module that
calls ``register(Method(...))``: add it to the imports below, or import it before the experiment
runs (docs/experiments.md, "Adding a method"). Methods run as commands on exported tours stay in
:mod:`reloc.experiments.external`.
"""

from __future__ import annotations

from . import videoreloc, videoreloc_oracle, fpfh_icp, appearance, one_frame  # they register
from .registry import (LAST, MapKind, Method, Row, active, all_methods, clip_methods, default_names, get,
                       map_kind, map_kinds, map_names, names, register, register_map, rows, table_method, unregister,
                       unregister_map)

# the in-tree methods' modules, in registration order
IN_TREE = (videoreloc, videoreloc_oracle, fpfh_icp, appearance, one_frame)
__all__ = ["LAST", "MapKind", "Method", "Row", "active", "all_methods", "clip_methods", "default_names", "get",
           "map_kind", "map_kinds", "map_names", "names", "register", "register_map", "rows", "table_method",
           "unregister", "unregister_map"]
