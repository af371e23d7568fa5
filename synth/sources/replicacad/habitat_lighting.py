"""Habitat lighting configs (``configs/lighting/*.lighting_config.json``) as light fixtures of an
imported (ReplicaCAD) layout.

The format (habitat-sim ``docs/pages/attributesJSON.rst``, LightLayoutAttributes, and its
``LightLayoutAttributesManager``)::

    {"lights": {"<id>": {"type": "point" | "directional" | "spot",
                         "position": [x, y, z],        # point lights, habitat world frame (Y up)
                         "direction": [x, y, z],       # directional lights
                         "intensity": f,               # default 1; NEGATIVE values are allowed
                         "color": [r, g, b],           # linear, 0..1; default white
                         "position_model": "global" | "camera" | "object"},  # default global
                ...},
     "positive_intensity_scale": s, "negative_intensity_scale": s}   # optional, default 1

A light without ``type`` is a point light when it has a position, else directional; habitat reads
``spot`` as a point light and so does this module. Negative intensities are habitat's way of
faking shadows in its rasteriser (ReplicaCAD's configs have several): they are read, kept in
``HabitatLight.intensity``, and never become fixtures (a path tracer casts its own shadows).

Intensity scales. ``HabitatLight.intensity`` is the file's intensity times the positive scale
(intensity > 0) or the negative scale (otherwise), as habitat-sim's
``LightLayoutAttributesManager::createLightSetupFromAttributes`` does (``color * (intensity > 0 ?
posIntensityScale : negIntensityScale) * intensity``). Where the scales come from follows
habitat-sim's attribute inheritance (read in its source, src/esp/metadata/managers/):
``SceneDatasetAttributesManager::readDatasetJSONCell`` builds ``light_setups.default_attributes``
of the scene dataset config into an attributes object and makes it the light manager's default
(``setDefaultObject``) before it loads the configs under ``paths``; every lighting config then
starts as a copy of that default (``LightLayoutAttributesManager::initNewObjectInternal`` ->
``constructFromDefault``), and ``setValsFromJSONDoc`` overrides ``positive_intensity_scale`` /
``negative_intensity_scale`` only where the file itself has them. So: the file's own value, else
the dataset config's default, else 1. ReplicaCAD's ``replicaCAD.scene_dataset_config.json`` sets
2.5 and 0.1 and its lighting configs set neither: its lights shine at 2.5 x their file intensity
(and its fake-shadow lights at 0.1 x). ``read_lighting_config(path)`` alone reads no dataset
defaults (scales from the file, else 1); ``read_lighting_config(path, dataset_config=...)`` (a
``*.scene_dataset_config.json`` path, e.g. ``synth.sources.replicacad.habitat_format.dataset_config_path(root)``,
or the defaults dict of :func:`dataset_light_defaults`) applies them.

Frames: positions and directions are converted once, here, with C = ``Y_UP_TO_Z_UP``:
``(x, y, z)_habitat -> (x, -z, y)_ours``. A "global" light is placed in habitat's world frame,
which is the frame the importer converts object poses from.

From lights to fixtures (``fixtures_for_imported``)
    * A point light (positive intensity, ``global`` position model) inside or within
      ``LAMP_REACH`` (0.3 m) of a lamp-class object's box (``floor_lamp``, ``table_lamp``) is that
      lamp's light: a ``lamp`` fixture at the light's position, tied to the lamp (it then moves with
      the lamp in rearranged variants). A lamp near several lights takes the nearest; the others
      are judged by the next rule.
    * Any other such point light in the upper ``CEILING_BAND`` (30 %) of the room height, over a
      room, is a ``ceiling`` fixture of no object, at the light's position (at most
      ``CEILING_DROP`` below the ceiling: ReplicaCAD puts some lights above the ceiling mesh).
    * Every other light is not a fixture: point lights lower down and not at a lamp (habitat's fill
      lights), lights with negative intensity, lights following the camera or an object, and
      directional lights -- the lighting presets (``scenes/lighting``) provide sun and sky.
    * A lamp-class object without a light gets one at 85 % of its height over its box centre, and
      every window opening a window fixture, as ``synth.scene.fixtures.layout_fixtures`` does for the
      procedural apartment (it builds the final list).
    * Placed rule: a room with no ceiling fixture (from the config or a ``ceiling_light`` object)
      gets one, "placed", at its rectangle's centre ``CEILING_DROP`` (10 cm) below the ceiling
      (id ``P_<room>``), so that every room can be lit at night like the procedural apartment's.
    Colour and power of the config are recorded (``color_temperature``: the correlated colour
    temperature of the light's colour, McCamy's formula; ``power``: ``WATTS_PER_INTENSITY`` times
    the scaled intensity), but as for the procedural apartment the presets decide how the fixtures
    shine (``synth.scene.lighting.resolve_lighting``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from vrformats.errors import SceneFormatError
from vrformats.fields import number

from ...scene.geometry import Y_UP_TO_Z_UP
from ...scene.fixtures import LAMP_CLASSES
from ...scene.model import Layout, LightFixture, object_box

C = Y_UP_TO_Z_UP  # habitat (Y up) -> ours (Z up)

LIGHT_TYPES = ("point", "directional", "spot")
POSITION_MODELS = ("global", "camera", "object")
LAMP_REACH = 0.3  # m: a light this close to a lamp's box is the lamp's
CEILING_BAND = 0.3  # the upper part of the room height where point lights are ceiling lights
CEILING_DROP = 0.1  # m below the ceiling: placed ceiling fixtures, and the highest a config one sits
WATTS_PER_INTENSITY = 100.0  # nominal: recorded power of a fixture per unit of habitat intensity
PLACED_CEILING_TEMPERATURE = 4000.0  # as the procedural apartment's ceiling lights
PLACED_CEILING_POWER = 150.0


@dataclass(frozen=True)
class HabitatLight:
    """One light of a habitat lighting config, in OUR frame (Z up)."""

    id: str
    type: str  # point | directional  (spot lights are read as point lights, as habitat does)
    position: tuple[float, float, float] | None  # point lights
    direction: tuple[float, float, float] | None  # directional lights
    color: tuple[float, float, float]
    intensity: float  # as in the file times the file's positive/negative intensity scale; may be < 0
    position_model: str = "global"


def _vec3(path, v, field: str, nonneg: bool = False) -> tuple[float, float, float]:
    if not isinstance(v, (list, tuple)) or len(v) != 3:
        raise SceneFormatError(path, field, f"expected a list of 3 numbers, got {v!r}")
    out = []
    for i, x in enumerate(v):
        out.append(number(path, x, f"{field}[{i}]", lo=0 if nonneg else None))
    return tuple(out)  # type: ignore[return-value]


def _ours(v) -> tuple[float, float, float]:
    return tuple(float(x) + 0.0 for x in C @ np.asarray(v, float))  # type: ignore[return-value]


SCALE_KEYS = ("positive_intensity_scale", "negative_intensity_scale")


def dataset_light_defaults(dataset_config) -> dict[str, float]:
    """The intensity scales a scene dataset config (``<root>/*.scene_dataset_config.json``) gives every
    lighting config: ``light_setups.default_attributes.{positive,negative}_intensity_scale``, only
    those it sets (habitat-sim's default attributes; module docstring). Bad fields raise
    ``SceneFormatError`` naming the file and the field."""
    from .habitat_format import mapping, read_json

    p = Path(dataset_config)
    doc = mapping(p, read_json(p), None)
    setups = mapping(p, doc.get("light_setups", {}), "light_setups")
    attrs = mapping(p, setups.get("default_attributes", {}), "light_setups.default_attributes")
    return {k: number(p, attrs[k], f"light_setups.default_attributes.{k}", lo=0) for k in SCALE_KEYS if k in attrs}


def parse_lighting_config(doc, path="<memory>", defaults: dict | None = None) -> list[HabitatLight]:
    """The lights of a parsed lighting config document (see the module docstring), in file order.
    ``defaults``: the scene dataset's intensity scales (:func:`dataset_light_defaults`), used where
    the document sets none."""
    if not isinstance(doc, dict):
        raise SceneFormatError(path, "(top level)", f"expected a JSON object, got {type(doc).__name__}")
    scale = {}
    for key in SCALE_KEYS:
        scale[key] = number(path, doc[key], key, lo=0) if key in doc else float((defaults or {}).get(key, 1.0))
    lights = doc.get("lights", {})
    if not isinstance(lights, dict):
        raise SceneFormatError(path, "lights", f"expected an object mapping light ids to lights, got {type(lights).__name__}")
    out = []
    for lid, d in lights.items():
        f = f"lights.{lid}"
        if not isinstance(d, dict):
            raise SceneFormatError(path, f, f"expected an object, got {type(d).__name__}")
        position = _vec3(path, d["position"], f + ".position") if "position" in d else None
        direction = _vec3(path, d["direction"], f + ".direction") if "direction" in d else None
        if "type" in d:
            t = d["type"]
            if not isinstance(t, str) or t.lower() not in LIGHT_TYPES:
                raise SceneFormatError(path, f + ".type", f"expected one of {', '.join(LIGHT_TYPES)}, got {t!r}")
            t = "point" if t.lower() == "spot" else t.lower()
        elif position is not None:
            t = "point"
        elif direction is not None:
            t = "directional"
        else:
            raise SceneFormatError(path, f + ".position", "missing (a light needs a position or a direction)")
        if t == "point" and position is None:
            if direction is None:
                raise SceneFormatError(path, f + ".position", "missing (a point light needs one)")
            position = direction  # habitat copies the vector across when the type says otherwise
        if t == "directional" and direction is None:
            if position is None:
                raise SceneFormatError(path, f + ".direction", "missing (a directional light needs one)")
            direction = position
        color = _vec3(path, d["color"], f + ".color", nonneg=True) if "color" in d else (1.0, 1.0, 1.0)
        intensity = number(path, d["intensity"], f + ".intensity") if "intensity" in d else 1.0
        intensity *= scale["positive_intensity_scale"] if intensity > 0 else scale["negative_intensity_scale"]
        model = d.get("position_model", "global")
        if not isinstance(model, str) or model.lower() not in POSITION_MODELS:
            raise SceneFormatError(path, f + ".position_model", f"expected one of {', '.join(POSITION_MODELS)}, got {model!r}")
        out.append(HabitatLight(
            id=str(lid), type=t, position=_ours(position) if t == "point" else None,
            direction=_ours(direction) if t == "directional" else None, color=color, intensity=intensity,
            position_model=model.lower(),
        ))
    return out


def read_lighting_config(path, dataset_config=None) -> list[HabitatLight]:
    """The lights of ``<...>.lighting_config.json`` in OUR frame. Bad files and fields raise
    ``SceneFormatError`` naming the file and the field (``lights.<id>.position`` ...).

    ``dataset_config``: the scene dataset config whose ``light_setups.default_attributes`` intensity
    scales apply where the file sets none (a path, or the dict :func:`dataset_light_defaults`
    returns); None: the file's own scales, else 1."""
    defaults = None
    if dataset_config is not None:
        defaults = dict(dataset_config) if isinstance(dataset_config, dict) else dataset_light_defaults(dataset_config)
    from .habitat_format import read_json

    p = Path(path)
    return parse_lighting_config(read_json(p, expect_object=False), str(p), defaults)


def color_temperature(rgb) -> float:
    """Correlated colour temperature (K) of a linear Rec.709 colour (McCamy's formula), within
    [1000, 20000]; 6500 for black or neutral-less input."""
    r, g, b = (float(v) for v in rgb)
    X = 0.4124 * r + 0.3576 * g + 0.1805 * b
    Y = 0.2126 * r + 0.7152 * g + 0.0722 * b
    Z = 0.0193 * r + 0.1192 * g + 0.9505 * b
    s = X + Y + Z
    if s <= 0:
        return 6500.0
    x, y = X / s, Y / s
    if abs(0.1858 - y) < 1e-9:
        return 6500.0
    n = (x - 0.3320) / (0.1858 - y)
    cct = 449.0 * n**3 + 3525.0 * n**2 + 6823.3 * n + 5520.33
    return float(min(max(cct, 1000.0), 20000.0))


def _distance_to_box(p, box) -> float:
    """3D distance from point ``p`` to a gravity-aligned oriented box (0 inside)."""
    c, s = math.cos(box.yaw), math.sin(box.yaw)
    d = np.asarray(p, float) - np.asarray(box.center, float)
    local = np.array([c * d[0] + s * d[1], -s * d[0] + c * d[1], d[2]])
    out = np.maximum(np.abs(local) - np.asarray(box.size, float) / 2.0, 0.0)
    return float(np.linalg.norm(out))


def assign_lights(layout: Layout, lights: list[HabitatLight]) -> dict[str, str]:
    """What each light becomes (rules in the module docstring): ``"lamp:<object id>"``, ``"ceiling"``
    or ``"ignored: <why>"``, by light id."""
    st = layout.stage
    lamps = [(o.id, object_box(o)) for o in layout.objects if o.cls in LAMP_CLASSES]
    out: dict[str, str] = {}
    near: dict[int, tuple[float, str]] = {}  # lamp id -> (distance, light id) of its nearest light
    cands = []
    for lt in lights:
        if lt.type != "point":
            out[lt.id] = "ignored: directional (the presets provide sun and sky)"
        elif lt.position_model != "global":
            out[lt.id] = f"ignored: placed relative to the {lt.position_model}"
        elif lt.intensity <= 0:
            out[lt.id] = "ignored: negative intensity (habitat's fake shadow)" if lt.intensity < 0 else "ignored: zero intensity"
        else:
            cands.append(lt)
            best = None
            for oid, box in lamps:
                dist = _distance_to_box(lt.position, box)
                if dist <= LAMP_REACH and (best is None or dist < best[0]):
                    best = (dist, oid)
            if best is not None and (best[1] not in near or best[0] < near[best[1]][0]):
                near[best[1]] = (best[0], lt.id)
    for oid, (_, lid) in near.items():
        out[lid] = f"lamp:{oid}"
    band = st.floor_z + (1.0 - CEILING_BAND) * st.ceiling_height
    for lt in cands:
        if lt.id in out:
            continue
        if lt.position[2] < band:
            out[lt.id] = "ignored: below the ceiling band and at no lamp (a fill light)"
        elif st.rooms and st.room_at(lt.position[:2]) is None:
            out[lt.id] = "ignored: over no room"
        else:
            out[lt.id] = "ceiling"
    return {lt.id: out[lt.id] for lt in lights}


def fixtures_for_imported(layout: Layout, lights: list[HabitatLight]) -> list[LightFixture]:
    """Light fixtures of an imported layout from its lighting config's lights (rules in the module
    docstring): lamps, ceiling lights (from the config, else placed), windows."""
    st = layout.stage
    top = st.floor_z + st.ceiling_height
    roles = assign_lights(layout, lights)
    prelim: list[LightFixture] = []
    for lt in lights:
        role = roles[lt.id]
        if role.startswith("ignored"):
            continue
        temp, power = color_temperature(lt.color), WATTS_PER_INTENSITY * lt.intensity
        if role.startswith("lamp:"):
            oid = int(role.split(":", 1)[1])
            room = st.room_at(lt.position[:2])
            prelim.append(LightFixture(f"L{oid}", "lamp", lt.position, room.name if room else None, object=oid,
                                       color_temperature=temp, power=power))
        else:
            pos = (lt.position[0], lt.position[1], min(lt.position[2], top - CEILING_DROP))
            room = st.room_at(pos[:2])
            prelim.append(LightFixture(f"H{lt.id}", "ceiling", pos, room.name if room else None,
                                       color_temperature=temp, power=power))
    lit = {f.room for f in prelim if f.kind == "ceiling"}
    for o in layout.objects:
        if o.cls == "ceiling_light":
            room = st.room_at(o.position[:2])
            lit.add(room.name if room else None)
    for r in st.rooms:
        if r.name not in lit:
            c = ((r.rect[0] + r.rect[2]) / 2.0, (r.rect[1] + r.rect[3]) / 2.0, top - CEILING_DROP)
            prelim.append(LightFixture(f"P_{r.name}", "ceiling", c, r.name, color_temperature=PLACED_CEILING_TEMPERATURE,
                                       power=PLACED_CEILING_POWER))
    from ...scene.fixtures import layout_fixtures

    return layout_fixtures(replace(layout, fixtures=prelim))
