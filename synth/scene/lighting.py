"""Lighting presets (``scenes/lighting/NAME.yaml``) and their resolution against a layout.

A preset says what is on: the sky (world background), the sun, and per fixture kind (ceiling
lights, lamps) whether they shine, how warm and how strong. ``resolve_lighting`` turns it into
concrete lights for one layout, as plain data: the Blender code only translates it.

Fixtures come from the layout (``Layout.fixtures``): a lamp's light sits in its shade, a ceiling
light's just below its diffuser, windows get light portals. ``count: N`` on lamps keeps N lamps:
the lowest-id lamp of each room first (rooms ordered by that id), then the next ones, so the
same lamps stay on in every variant of a layout as long as they exist.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from vrformats import fields
from vrformats.color import srgb_decode
from vrformats.errors import SceneFormatError, UnknownNameError, UserError
from vrformats.fields import number
from vrformats.yamlfile import read_yaml

from ..resources import lighting_dir  # $SYNTH_SCENES_DIR/lighting, else scenes/lighting
from .model import Layout


def list_lighting() -> list[str]:
    d = lighting_dir()
    return sorted(p.stem for p in d.glob("*.yaml")) if d.exists() else []


def kelvin_to_rgb(kelvin: float) -> tuple[float, float, float]:
    """Linear Rec.709 colour of a black body at ``kelvin``, normalised to max 1.

    Tanner Helland's fit of the CIE black-body sRGB values, converted from sRGB to linear.
    """
    t = min(max(kelvin, 1000.0), 40000.0) / 100.0
    if t <= 66:
        r = 255.0
        g = 99.4708025861 * math.log(t) - 161.1195681661
        b = 0.0 if t <= 19 else 138.5177312231 * math.log(t - 10) - 305.0447927307
    else:
        r = 329.698727446 * (t - 60) ** -0.1332047592
        g = 288.1221695283 * (t - 60) ** -0.0755148492
        b = 255.0
    srgb = np.clip(np.array([r, g, b]) / 255.0, 0.0, 1.0)
    lin = srgb_decode(srgb)
    lin = lin / lin.max()
    return tuple(float(v) for v in lin)


@dataclass(frozen=True)
class FixtureSetting:
    on: bool = False
    color_temperature: float = 3000.0
    power: float = 60.0  # Blender watts per fixture
    count: int | None = None  # lamps only: how many stay on


@dataclass(frozen=True)
class LightingPreset:
    name: str
    description: str
    sky_color: tuple[float, float, float]
    sky_strength: float
    sun: dict | None  # strength, elevation_deg, azimuth_deg, color_temperature, angle_deg
    window_portals: bool
    ceiling: FixtureSetting
    lamp: FixtureSetting
    source: str = ""


# ---------------------------------------------------------------------------------------------
# the dimmer (issue 29): one dial from day through evening to night and below

DIMMER_MAX = 1.5
DIMMER_BELOW_NIGHT_LOG2 = 6.0  # below night, the lamps lose 2^-6 of their power per unit of level


def _lerp(a: float, b: float, u: float) -> float:
    return round(float(a + (b - a) * u), 4)


def _fade(a: FixtureSetting, b: FixtureSetting, u: float) -> FixtureSetting:
    """Fixtures crossfaded: a render is linear in its lights, so power fades linearly; an off
    fixture counts as power 0; colour temperature is the lit one's (or interpolated if both are);
    the lamp count switches at the middle."""
    pa, pb = a.power * a.on, b.power * b.on
    if a.on and b.on:
        temp = _lerp(a.color_temperature, b.color_temperature, u)
    else:
        temp = a.color_temperature if a.on else b.color_temperature
    return FixtureSetting(a.on or b.on, temp, _lerp(pa, pb, u), a.count if u < 0.5 else b.count)


def dimmed_preset(level: float, name: str | None = None) -> LightingPreset:
    """The lighting at dimmer ``level`` in [0, ``DIMMER_MAX``]: 0 is the day preset, 0.5 evening,
    1 night (the shipped presets themselves), values between crossfade the neighbouring presets'
    lights (sun, sky and fixture power linearly, since a render is linear in its lights; the lamp
    count switches at the middle), and values above 1 dim night's lamps by ``2^-6`` per unit of
    level and leave a single lamp from 1.25 on, under night's sky: darker than the night preset."""
    if not fields.is_number(level) or not 0.0 <= level <= DIMMER_MAX:
        raise UserError(f"dimmer: expected a level in [0, {DIMMER_MAX}] (0 day, 0.5 evening, 1 night, above 1 darker), "
                        f"got {level!r}")
    level = float(level)
    day, evening, night = (load_lighting(n) for n in ("day", "evening", "night"))
    if level in (0.0, 0.5, 1.0):  # the shipped presets themselves
        base = {0.0: day, 0.5: evening, 1.0: night}[level]
    elif level > 1.0:
        k = 2.0 ** (-DIMMER_BELOW_NIGHT_LOG2 * (level - 1.0))
        lamp = FixtureSetting(night.lamp.on, night.lamp.color_temperature, round(night.lamp.power * k, 4),
                              1 if level >= 1.25 else night.lamp.count)
        base = replace(night, lamp=lamp)
    else:
        a, b, u = (day, evening, level / 0.5) if level <= 0.5 else (evening, night, (level - 0.5) / 0.5)
        sun = None
        if a.sun is not None or b.sun is not None:
            src = a.sun if a.sun is not None else b.sun
            sa = a.sun["strength"] if a.sun is not None else 0.0
            sb = b.sun["strength"] if b.sun is not None else 0.0
            sun = {**src, "strength": _lerp(sa, sb, u)}
            if sun["strength"] <= 0:
                sun = None
        base = LightingPreset(
            name="", description="", sky_color=tuple(_lerp(x, y, u) for x, y in zip(a.sky_color, b.sky_color)),
            sky_strength=_lerp(a.sky_strength, b.sky_strength, u), sun=sun,
            window_portals=(a.window_portals and u < 1) or (b.window_portals and u > 0),
            ceiling=_fade(a.ceiling, b.ceiling, u), lamp=_fade(a.lamp, b.lamp, u))
    tag = f"dimmer_{level:g}"
    return replace(base, name=name or tag, description=f"dimmer level {level:g} (0 day, 0.5 evening, 1 night)",
                   source=f"<{tag}>")


def parse_preset(doc, source: str) -> LightingPreset:
    if not isinstance(doc, dict):
        raise SceneFormatError(source, None, "expected a mapping")
    if "dimmer" in doc:  # a dimmer level instead of lights: {name: ..., dimmer: 0.75}
        extra = sorted(set(doc) - {"name", "description", "dimmer"})
        if extra:
            raise SceneFormatError(source, extra[0], "a dimmer preset holds name, description and dimmer only")
        name = fields.name_text(source, doc["name"], "name") if "name" in doc else Path(source).stem
        try:
            p = dimmed_preset(doc["dimmer"], name=name)
        except UserError as e:
            raise SceneFormatError(source, "dimmer", str(e).split(": ", 1)[1]) from None
        return replace(p, source=source)
    allowed = {"name", "description", "sky", "sun", "window_portals", "fixtures"}
    unknown = set(doc) - allowed
    if unknown:
        raise SceneFormatError(source, None, f"unknown key(s) {sorted(unknown)}; allowed: {sorted(allowed)}")
    sky = doc.get("sky") or {}
    if not isinstance(sky, dict) or set(sky) - {"color", "strength"}:
        raise SceneFormatError(source, "sky", "expected {color: [r, g, b], strength: s}")
    color = sky.get("color", [0.0, 0.0, 0.0])
    if not isinstance(color, list) or len(color) != 3:
        raise SceneFormatError(source, "sky.color", f"expected 3 numbers, got {color!r}")
    sky_color = tuple(number(source, c, "sky.color", lo=0.0) for c in color)
    sun = doc.get("sun")
    if sun is not None:
        keys = {"strength", "elevation_deg", "azimuth_deg", "color_temperature", "angle_deg"}
        if not isinstance(sun, dict) or set(sun) - keys:
            raise SceneFormatError(source, "sun", f"expected a mapping with keys {sorted(keys)} or null")
        sun = {k: number(source, sun.get(k, d), f"sun.{k}") for k, d in
               (("strength", 3.0), ("elevation_deg", 35.0), ("azimuth_deg", 200.0), ("color_temperature", 5600.0), ("angle_deg", 1.0))}
    fx = doc.get("fixtures") or {}
    if not isinstance(fx, dict) or set(fx) - {"ceiling", "lamp"}:
        raise SceneFormatError(source, "fixtures", "expected a mapping with keys ceiling, lamp")

    def setting(kind):
        d = fx.get(kind) or {}
        if not isinstance(d, dict) or set(d) - {"enabled", "color_temperature", "power", "count"}:
            bad = sorted(map(str, set(d) - {"enabled", "color_temperature", "power", "count"})) if isinstance(d, dict) else d
            raise SceneFormatError(source, f"fixtures.{kind}", f"expected keys enabled, color_temperature, power, count; got {bad}")
        on = fields.boolean(source, d.get("enabled", False), f"fixtures.{kind}.enabled")
        count = d.get("count")
        if count is not None:
            fields.nonneg_int(source, count, f"fixtures.{kind}.count")
        return FixtureSetting(on, number(source, d.get("color_temperature", 3000.0), f"fixtures.{kind}.color_temperature", lo=1000.0),
                              number(source, d.get("power", 60.0), f"fixtures.{kind}.power", lo=0.0), count)

    name = fields.name_text(source, doc["name"], "name") if doc.get("name") is not None else Path(source).stem
    portals = fields.boolean(source, doc.get("window_portals", False), "window_portals")
    return LightingPreset(
        name=name, description=fields.text(source, doc.get("description", ""), "description"), sky_color=sky_color,
        sky_strength=number(source, sky.get("strength", 1.0), "sky.strength", lo=0.0), sun=sun,
        window_portals=portals, ceiling=setting("ceiling"), lamp=setting("lamp"), source=source,
    )


def lighting_file(name_or_file) -> Path:
    """The file of a preset name (``day``) or the given file."""
    p = Path(name_or_file)
    if p.suffix not in (".yaml", ".yml") and not p.exists():
        p = lighting_dir() / f"{name_or_file}.yaml"
        if not p.exists():
            raise UnknownNameError(f"unknown lighting preset '{name_or_file}'; known: {', '.join(list_lighting()) or 'none'}")
    return p


def load_lighting(name_or_file) -> LightingPreset:
    p = lighting_file(name_or_file)
    return parse_preset(read_yaml(p), str(p))


def preset_document(preset: LightingPreset) -> dict:
    """The YAML document of a preset (what ``parse_preset`` reads back to an equal preset)."""
    def fixture(f: FixtureSetting) -> dict:
        d = {"enabled": f.on, "color_temperature": f.color_temperature, "power": f.power}
        if f.count is not None:
            d["count"] = f.count
        return d

    return {"name": preset.name, "description": preset.description,
            "sky": {"color": [float(c) for c in preset.sky_color], "strength": preset.sky_strength},
            "sun": dict(preset.sun) if preset.sun is not None else None, "window_portals": preset.window_portals,
            "fixtures": {"ceiling": fixture(preset.ceiling), "lamp": fixture(preset.lamp)}}


@dataclass(frozen=True)
class LightingJitter:
    """How far ``jitter_preset`` moves a preset (training data: the detector must not learn one light)."""

    sun_azimuth_deg: float = 60.0  # +- uniform
    sun_elevation_deg: float = 15.0  # +- uniform, kept within [5, 80]
    strength_log2: float = 0.7  # sun, sky and fixture power times 2**U(-x, x)
    sky_tint: float = 0.15  # each sky colour channel times 1 + U(-x, x)
    temperature_k: float = 500.0  # colour temperatures +- uniform, kept within [1800, 9000] K
    lamps_extra: int = 2  # a preset keeping N lamps keeps N + U{-lamps_fewer..x} (at least one)
    lamps_fewer: int = 0


def jitter_preset(preset: LightingPreset, seed: int, jitter: LightingJitter = LightingJitter()) -> LightingPreset:
    """A seeded variation of ``preset``: the same lights on and off, moved in direction, strength
    and colour (``jitter``). Exposure is not a property of the light: it belongs to the camera,
    which applies it to the linear frames later. Same preset and seed, same result."""
    rng = np.random.default_rng([int(seed), 11])

    def gain() -> float:
        return float(2.0 ** rng.uniform(-jitter.strength_log2, jitter.strength_log2))

    def temp(t: float) -> float:
        return round(float(np.clip(t + rng.uniform(-jitter.temperature_k, jitter.temperature_k), 1800.0, 9000.0)), 1)

    sun = None
    if preset.sun is not None:
        sun = dict(preset.sun)
        sun["azimuth_deg"] = round((sun["azimuth_deg"] + rng.uniform(-jitter.sun_azimuth_deg, jitter.sun_azimuth_deg)) % 360.0, 3)
        sun["elevation_deg"] = round(float(np.clip(sun["elevation_deg"] + rng.uniform(-jitter.sun_elevation_deg,
                                                                                       jitter.sun_elevation_deg), 5.0, 80.0)), 3)
        sun["strength"] = round(sun["strength"] * gain(), 4)
        sun["color_temperature"] = temp(sun["color_temperature"])
    sky_color = tuple(round(float(c * (1.0 + rng.uniform(-jitter.sky_tint, jitter.sky_tint))), 4) for c in preset.sky_color)

    def fixture(f: FixtureSetting) -> FixtureSetting:
        count = f.count if f.count is None else max(1, f.count + int(rng.integers(-jitter.lamps_fewer, jitter.lamps_extra + 1)))
        return FixtureSetting(f.on, temp(f.color_temperature), round(f.power * gain(), 3), count)

    return LightingPreset(
        name=f"{preset.name}_j{int(seed)}", description=f"{preset.name}, jittered with seed {int(seed)}",
        sky_color=sky_color, sky_strength=round(preset.sky_strength * gain(), 4), sun=sun,
        window_portals=preset.window_portals, ceiling=fixture(preset.ceiling), lamp=fixture(preset.lamp))


@dataclass
class Light:
    kind: str  # point | area | sun | portal
    name: str
    position: tuple[float, float, float] = (0.0, 0.0, 0.0)
    direction: tuple[float, float, float] = (0.0, 0.0, -1.0)  # where the light shines (area, sun)
    up: tuple[float, float, float] = (0.0, 0.0, 1.0)  # in-plane orientation of area lights / portals
    size: tuple[float, float] = (0.1, 0.1)  # area / portal width and height; point: radius in [0]
    color: tuple[float, float, float] = (1.0, 1.0, 1.0)
    power: float = 0.0  # W (point, area); W/m2 (sun)
    angle: float = 0.0  # sun angular diameter (rad)


@dataclass
class ResolvedLighting:
    preset: str
    sky_color: tuple[float, float, float]
    sky_strength: float
    lights: list[Light] = field(default_factory=list)
    emission: dict[str, tuple[tuple[float, float, float], float]] = field(default_factory=dict)  # fixture -> (colour, strength)


LAMP_EMISSION = 6.0  # emission strength of a lit lamp shade (the light itself is a point light inside)
CEILING_EMISSION = 8.0


def enclosed_lamps(layout: Layout) -> set[str]:
    """Lamp fixtures whose light lies inside another mesh object's box (a lamp shut in a cupboard):
    their light reaches no camera. Procedural furniture has no doors (a lamp on a bookshelf's board
    is inside its box but in the open), so only mesh objects enclose."""
    from .model import object_box

    boxes = [(o.id, object_box(o)) for o in layout.objects if not o.asset.startswith("proc:")]
    return {f.id for f in layout.fixtures if f.kind == "lamp"
            and any(oid != f.object and b.contains(f.position, margin=-0.01) for oid, b in boxes)}


def chosen_lamps(layout: Layout, count: int | None) -> list[str]:
    """The lamps a preset keeping ``count`` lamps lights: the lowest-id lamp of each room first (rooms
    in the order of those ids), then the next ones, so that the same lamps stay on in every variant
    of a layout as long as they exist; a lamp shut inside another object (``enclosed_lamps``) comes
    after every other, since its light would reach no camera."""
    shut = enclosed_lamps(layout) if count is not None else set()
    lamps = sorted((f for f in layout.fixtures if f.kind == "lamp"), key=lambda f: (f.id in shut, f.object or 0, f.id))
    if count is None:
        return [f.id for f in lamps]
    first_per_room, rest, seen = [], [], set()
    for f in lamps:
        (rest if f.room in seen else first_per_room).append(f)
        seen.add(f.room)
    return [f.id for f in (first_per_room + rest)[:count]]


DARK_MIN_VISIBLE = 0.1  # a lamp-lit tour needs a lit lamp in line of sight from this share of its poses
# (the built-in night tours: 20-42 %; a lamp shut in a cupboard: 0 %)
DARK_SAMPLES = 40  # poses sampled along a tour for that
DARK_MIN_FRAMES = 100  # shorter tours are not checked: cheap to render, and a few frames may look away from every lamp


def _segments_hit_box(a: np.ndarray, b: np.ndarray, box) -> np.ndarray:
    """For segments a[i] -> b[i] (N x 3), whether each passes through the oriented ``box`` (slab test
    in the box's frame)."""
    c, sn = math.cos(box.yaw), math.sin(box.yaw)
    R = np.array([[c, sn, 0.0], [-sn, c, 0.0], [0.0, 0.0, 1.0]])  # world -> box
    pa = (a - np.asarray(box.center)) @ R.T
    d = (b - a) @ R.T
    half = np.asarray(box.size) / 2.0
    with np.errstate(divide="ignore", invalid="ignore"):
        t1 = (-half - pa) / d
        t2 = (half - pa) / d
    lo = np.where(np.isnan(t1), -np.inf, np.minimum(t1, t2))
    hi = np.where(np.isnan(t2), np.inf, np.maximum(t1, t2))
    inside_slab = np.abs(pa) <= half  # a segment parallel to a slab: inside it or never
    lo = np.where(d == 0, np.where(inside_slab, -np.inf, np.inf), lo)
    hi = np.where(d == 0, np.where(inside_slab, np.inf, -np.inf), hi)
    t0, t_1 = lo.max(axis=1), hi.min(axis=1)
    return (t0 <= t_1) & (t_1 >= 1e-6) & (t0 <= 1.0 - 1e-6)


def lamp_visibility(layout: Layout, lamp_ids, positions: np.ndarray) -> np.ndarray:
    """For each camera position (N x 3), whether some lamp of ``lamp_ids`` is in line of sight: no
    wall box and no mesh object's box (but the lamp's own) between the camera and the lamp's light.
    Procedural furniture does not block: its boxes hold open shelves, legs and air."""
    from .model import object_box, structure_boxes

    fx = {f.id: f for f in layout.fixtures}
    # procedural furniture is open (no doors, see-through shelves and legs): only mesh objects and walls block
    boxes = [(o.id, object_box(o)) for o in layout.objects if not o.asset.startswith("proc:")] + [
        (None, b) for b in structure_boxes(layout.stage) if b.kind == "wall"]
    seen = np.zeros(len(positions), bool)
    for lid in lamp_ids:
        f = fx[lid]
        light = np.broadcast_to(np.asarray(f.position, float), positions.shape)
        blocked = np.zeros(len(positions), bool)
        for oid, b in boxes:
            if oid is not None and oid == f.object:
                continue
            blocked |= _segments_hit_box(positions, light, b)
        seen |= ~blocked
    return seen


def dark_tour_problem(preset: LightingPreset, layout: Layout, poses: np.ndarray) -> str | None:
    """Why a tour in ``preset`` would render (nearly) black, or None. Only a preset lit by lamps
    alone is checked (no sun, no ceiling lights): it is dark when the layout has no lamp to light,
    or when no lit lamp is in line of sight (``lamp_visibility``) from at least ``DARK_MIN_VISIBLE``
    of ``DARK_SAMPLES`` poses spread over the tour. A lamp shut in a cupboard, or lamps all behind
    walls the camera never passes, fail it. Tours under ``DARK_MIN_FRAMES`` frames are not checked.
    Line of sight is stricter than light (a lamp lights the walls of its room for a camera that
    cannot see it), so the bar is low: the built-in night tours see a lamp from 20-42 % of poses."""
    if (preset.sun is not None and preset.sun.get("strength", 0) > 0) or preset.ceiling.on:
        return None
    if not preset.lamp.on or len(poses) < DARK_MIN_FRAMES:
        return None  # a preset that means to be dark (no lamps at all) is what it says
    on = chosen_lamps(layout, preset.lamp.count)
    if not on:
        return f"lighting '{preset.name}' lights only lamps, and layout '{layout.name}' has none"
    idx = np.unique(np.linspace(0, len(poses) - 1, min(DARK_SAMPLES, len(poses))).astype(int))
    pos = np.asarray(poses, float)[idx, :3, 3]
    share = float(lamp_visibility(layout, on, pos).mean())
    if share < DARK_MIN_VISIBLE:
        return (f"lighting '{preset.name}' lights only lamps ({', '.join(on)}), and one is in sight from "
                f"{share:.0%} of the tour's poses (at least {DARK_MIN_VISIBLE:.0%} needed): the tour would be nearly black")
    return None


def resolve_lighting(preset: LightingPreset, layout: Layout) -> ResolvedLighting:
    out = ResolvedLighting(preset.name, preset.sky_color, preset.sky_strength)
    if preset.sun is not None and preset.sun["strength"] > 0:
        el, az = math.radians(preset.sun["elevation_deg"]), math.radians(preset.sun["azimuth_deg"])
        to_sun = np.array([math.cos(el) * math.cos(az), math.cos(el) * math.sin(az), math.sin(el)])
        out.lights.append(Light("sun", "sun", direction=tuple(-to_sun), color=kelvin_to_rgb(preset.sun["color_temperature"]),
                                power=preset.sun["strength"], angle=math.radians(preset.sun["angle_deg"])))
    objs = layout.by_id()
    if preset.ceiling.on:
        col = kelvin_to_rgb(preset.ceiling.color_temperature)
        for f in layout.fixtures:
            if f.kind != "ceiling":
                continue
            o = objs.get(f.object)
            z = (o.position[2] - 0.02) if o is not None else layout.stage.floor_z + layout.stage.ceiling_height - 0.1
            w = max(0.1, min(o.size[0], o.size[1]) * 0.9) if o is not None else 0.3
            out.lights.append(Light("area", f.id, (f.position[0], f.position[1], z), (0.0, 0.0, -1.0), size=(w, w),
                                    color=col, power=preset.ceiling.power))
            out.emission[f.id] = (col, CEILING_EMISSION)
    if preset.lamp.on:
        col = kelvin_to_rgb(preset.lamp.color_temperature)
        on = set(chosen_lamps(layout, preset.lamp.count))
        for f in layout.fixtures:
            if f.kind == "lamp" and f.id in on:
                out.lights.append(Light("point", f.id, tuple(f.position), size=(0.04, 0.04), color=col, power=preset.lamp.power))
                out.emission[f.id] = (col, LAMP_EMISSION)
    if preset.window_portals:
        st = layout.stage
        for op in st.openings:
            if op.kind != "window":
                continue
            w = st.wall(op.wall)
            c = op.center_xy(w)
            n = np.array([-w.direction[1], w.direction[0], 0.0])
            # the portal faces into the room the window belongs to
            if op.rooms:
                r = st.room(op.rooms[0])
                centre = np.array([(r.rect[0] + r.rect[2]) / 2, (r.rect[1] + r.rect[3]) / 2, 0.0])
                if n @ (centre - np.array([c[0], c[1], 0.0])) < 0:
                    n = -n
            pos = (float(c[0]), float(c[1]), st.floor_z + op.bottom + op.height / 2)
            out.lights.append(Light("portal", op.id, pos, tuple(n), up=(0.0, 0.0, 1.0), size=(op.width, op.height)))
    return out
