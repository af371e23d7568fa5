"""A layout's light fixtures, derived from its objects and openings (lamps, ceiling lights, windows).

The procedural generator, the rearrangement operator and the ReplicaCAD lighting import all derive
fixtures the same way, so the rule lives here, beside the scene model it reads.
"""

from __future__ import annotations

import numpy as np

from .model import Layout, LightFixture, object_box

LAMP_CLASSES = ("floor_lamp", "table_lamp")  # objects that carry a light source of their own
# a light source stands on a parent's open top: its bottom no lower than this under the parent's box top (m)
OPEN_TOP_TOLERANCE = 0.03


def is_light_source(cls: str) -> bool:
    return cls in LAMP_CLASSES


def layout_fixtures(layout: Layout, previous: Layout | None = None) -> list[LightFixture]:
    """Light fixtures: every lamp's shade, every ceiling light, every window, and the fixtures of an
    imported stage.

    * A lamp (``floor_lamp``, ``table_lamp``) has its light at 85 % of its box height above its
      bottom, over its box centre (procedural lamps: above their origin, the same point). A mesh
      lamp that had a lamp fixture in ``previous`` (default: ``layout`` itself) -- e.g. a light of
      its ReplicaCAD lighting config (``synth.sources.replicacad.habitat_lighting``) -- keeps it, carried rigidly with
      the lamp from its pose in ``previous``.
    * A ``ceiling_light`` object has its fixture at its origin.
    * Ceiling fixtures of ``previous`` that belong to no object (an imported stage's ceiling lights,
      placed ones) are kept as they are: the shell does not change.
    * Every window opening has one, at its centre.

    For a procedural layout this is exactly the fixtures the generator makes (``previous`` plays
    no part). ``synth.layout.rearrange.rearrange`` calls it with the reference as ``previous``."""
    prev = previous if previous is not None else layout
    prev_objs = prev.by_id()
    prev_lamps = {f.object: f for f in prev.fixtures if f.kind == "lamp" and f.object is not None}
    fx = []
    for o in layout.objects:
        proc = o.asset.startswith("proc:")
        if is_light_source(o.cls):
            old, was = prev_lamps.get(o.id), prev_objs.get(o.id)
            if not proc and old is not None and was is not None:
                if was.position == o.position and was.rotation == o.rotation:
                    p = tuple(old.position)
                else:
                    d = o.matrix() @ np.linalg.inv(was.matrix())
                    p = tuple(float(v) for v in d[:3, :3] @ np.asarray(old.position, float) + d[:3, 3])
                room = layout.stage.room_at(p[:2])
                fx.append(LightFixture(old.id, "lamp", p, room.name if room else old.room, object=o.id,
                                       color_temperature=old.color_temperature, power=old.power))
                continue
            if proc:
                room = layout.stage.room_at(o.position[:2])
                top = (o.position[0], o.position[1], o.position[2] + o.size[2] * 0.85)
            else:
                b = object_box(o)
                room = layout.stage.room_at(b.center[:2])
                top = (b.center[0], b.center[1], b.zmin + b.size[2] * 0.85)
            fx.append(LightFixture(f"L{o.id}", "lamp", top, room.name if room else None, object=o.id,
                                   color_temperature=2700.0, power=40.0 if o.cls == "table_lamp" else 60.0))
        elif o.cls == "ceiling_light":
            room = layout.stage.room_at(o.position[:2])
            fx.append(LightFixture(f"C{o.id}", "ceiling", tuple(o.position), room.name if room else None, object=o.id,
                                   color_temperature=4000.0, power=150.0))
    fx += [LightFixture(**f.__dict__) for f in prev.fixtures if f.kind == "ceiling" and f.object is None]
    for op in layout.stage.openings:
        if op.kind != "window":
            continue
        w = layout.stage.wall(op.wall)
        c = op.center_xy(w)
        fx.append(LightFixture(f"{op.id}", "window", (float(c[0]), float(c[1]), layout.stage.floor_z + op.bottom + op.height / 2),
                               op.rooms[0] if op.rooms else None, opening=op.id, color_temperature=6500.0, power=0.0))
    return fx
