"""Seeded RGB-D sensor models, applied when a frame is read (not when it is rendered).

One render serves every sensor setting: ``apply_sensor`` turns a rendered frame (planar depth in
metres, 0 = no hit; linear scene-referred RGB radiance as Cycles renders it) into what a given
camera would have measured, deterministically for a seed. ``frame_seed`` derives that seed from
(tour, frame, sensor, run seed) with SHA-256, so every method and every process sees the same noisy
frame.

Presets (``vrformats/sensor_presets/<name>.yaml``; every figure is cited in the file, and the ones
that are choices say so):

* ``ideal``: no effect at all; ``apply_sensor`` returns its inputs (today's output).
* ``structured_light``: a Kinect-v1-class camera. Axial noise
  ``sigma_z = 0.0012 + 0.0019 (z - 0.4)^2`` m (Nguyen, Izadi & Lovell 2012, 3DIMPVT, for
  10-60 deg incidence) plus their incidence term ``0.0001 / sqrt(z) * theta^2 / (pi/2 - theta)^2``;
  lateral noise ~0.8 px (same paper); disparity quantisation with a 7.5 cm baseline, ~580 px focal
  length and 1/8 px disparity steps (Khoshelham & Elberink 2012, Sensors 12(2):1437-1454: random
  error grows quadratically with range, to ~4 cm at 5 m); range 0.5-4.5 m; dropouts at grazing
  incidence.
* ``tof``: a Kinect-v2 / Azure-Kinect-class time-of-flight camera: small, roughly linear noise
  (1.5 mm + 0.15 % of range), range 0.5-4.5 m, mixed ("flying") pixels and dropouts at depth
  edges; multipath is ignored.

Both non-ideal presets share one generic small-pixel CMOS colour camera: full well 10,000 e-, read
noise 3 e- (typical for the class, not verified), 2500 e-/ms at linear 1.0 (a choice: Cycles'
radiance has no absolute scale; on the demo tours it gives a median 3.6 ms by day, 6.3 ms in the
evening and 33.3 ms with gain on ~3/4 of the night frames), auto exposure and motion blur on.
Their dark-surface depth dropout is OFF: the renders hold visible radiance, not IR reflectivity,
and the luminance proxy (``dark_relative``, below) keeps only 8-13 % of a night frame's depth on
the demo tours (two lamps: most of the room in deep shade), which an active sensor with its own
light does not do. Doing it properly needs an albedo or IR channel in the renders.

Depth model
-----------
Per valid pixel (input depth > 0 and finite), in this order:

1. incidence angle ``theta`` between the surface normal and the viewing ray, with normals from the
   depth image itself (back-projected with the intrinsics; one-sided differences, the side with
   the smaller depth step, so a normal next to a depth edge is the surface's own);
2. lateral noise: the pixel reads depth (and theta) from a neighbour displaced by
   ``round(N(0, s))`` in u and v (a displaced read of a no-hit pixel gives no depth), with
   ``s = lateral_px * fx / focal_px``: ``lateral_px`` is in the sensor's own pixels (its focal
   length ``focal_px``; without one, in the tour's pixels), so the same angular noise reaches a
   160x120 render as a 640x480 one (0.8 Kinect pixels are 0.2 pixels of a 160x120 render: most
   reads stay on their own pixel);
3. axial noise: ``z + sigma(z, theta) * N(0, 1)`` with
   ``sigma = sigma_a + sigma_b (z - sigma_z0)^2 + sigma_c z + sigma_theta / sqrt(z) * theta^2 / (pi/2 - theta)^2``;
4. depth edges (a 4-neighbour whose depth differs by more than ``edge_jump_rel * z``): with
   probability ``edge_flying`` the pixel becomes a mixed pixel (a uniform blend of its depth and
   the most different neighbour's), then with probability ``edge_dropout`` it is dropped;
5. disparity quantisation (``baseline_m > 0``): ``d = f B / z``, ``d_q = round(d / step) step``,
   ``z_q = f B / d_q`` (``f`` = ``focal_px`` or the tour's fx);
6. dropouts (depth set to 0): measured depth outside ``[min_range_m, max_range_m]``; ``theta``
   above ``max_incidence_deg``; and, where the frame has RGB, dark or bright surfaces relative to
   the frame: ``r = lum / p97``, with ``lum`` the rendered (noise-free, unblurred) linear Rec. 709
   luminance of the pixel and ``p97`` the 97th percentile of ``lum`` over the pixels with valid
   input depth; depth drops where ``r < dark_relative`` or ``r > bright_relative``. This is a proxy
   for low (high) IR reflectivity: the renderer has no IR albedo, and the active sensors bring
   their own IR light, so the absolute visible light level must not matter (the same frame scaled
   by 1e-4, a night frame, drops the same pixels), while local shadows, which the proxy cannot
   tell from dark albedo, still count. Frames whose ``p97`` is ~0 (<= 1e-12) get no dark or bright
   dropout, and neither do frames without RGB.

Parameters (``depth:`` section; the defaults are "no effect"):
``sigma_a`` (m), ``sigma_b`` (1/m), ``sigma_z0`` (m), ``sigma_c`` (fraction of z), ``sigma_theta``
(m^1.5), ``lateral_px`` (px), ``min_range_m`` (0), ``max_range_m`` (inf; null = inf),
``max_incidence_deg`` (90 = off), ``dark_relative`` (0 = off), ``bright_relative`` (inf = off; null
= inf), ``edge_jump_rel`` (0 = off), ``edge_flying``, ``edge_dropout`` (probabilities),
``baseline_m`` (0 = no quantisation), ``focal_px`` (null = the tour's fx), ``disparity_step_px``
(0.125).

Depth is not motion-blurred: the depth images are the render's, at the frame's pose (a real
structured-light / ToF camera integrates its IR exposure over a short time of its own; depth errors
from motion are not modelled).

Colour model
------------
A simple physically consistent camera, per channel, in this order (``color:`` section):

1. auto exposure, metered on the frame's own rendered radiance (no exposure lag, a choice): the
   exposure time ``t`` (ms) brings the frame's ``exposure_percentile`` luminance ``L_p`` to
   ``exposure_target`` of the full well, ``t = exposure_target * full_well_e / (electrons_per_ms
   * L_p)``, clamped to ``[exposure_min_ms, exposure_max_ms]``; only when ``t`` hits the maximum,
   an analog gain ``g = min(max_gain, t_wanted / exposure_max_ms)`` (>= 1) makes up the rest;
   beyond ``max_gain`` the raw frame stays darker (a frame whose ``L_p`` is 0 gets the maximum
   exposure and gain). ``exposure(color_model, rgb)`` returns ``(t, g)``;
2. motion blur (``motion_blur: true`` and ``apply_sensor(..., motion=Motion(...))``): the sensor
   integrates the radiance over ``[-t/2, +t/2]`` around the frame's time. Sub-poses at times
   ``tau`` are interpolated between the frame's pose and the neighbouring frame's pose (the
   previous one for ``tau < 0``, the next one for ``tau > 0``; where one is missing, at a tour's
   ends, the other one is extrapolated), linearly in translation and by slerp in rotation
   (``R(s) = R_T exp(s log(R_T^T R_n))``, ``s = |tau| / dt``). For each pixel ``p`` with depth
   ``z`` the flow ``f_tau(p)`` is where its 3-D point projects in the sub-pose camera minus ``p``
   (pixels without depth use the rotation-only flow, i.e. depth -> infinity); the blurred image is
   the mean over ``tau`` of the image sampled at ``p - f_tau(p)`` (bilinear, border replicated).
   ``n`` samples at the midpoints of ``n`` equal sub-intervals, ``n = ceil(longest flow over the
   exposure in px)``, at least 1 (1 = no blur), at most ``blur_samples_max``. Rolling shutter is
   not modelled (a global shutter), nor defocus;
3. electrons: ``e = electrons_per_ms * t * s`` for the (blurred) linear value ``s``; shot noise
   (Poisson, as a Gaussian of variance ``e``) plus read noise (Gaussian, ``read_noise_e``), clipped
   to ``[0, full_well_e]``;
4. gain: the analog gain multiplies signal and noise alike after collection (read noise is added
   before the gain; no post-gain noise, no ADC quantisation): the digital value ``g e`` clips at
   ``full_well_e``, i.e. ``e`` at ``full_well_e / g``;
5. back to scene-referred linear units: ``out = e / (electrons_per_ms * t)``, so the output means
   what the input meant (downstream code auto-tonemaps it); the noise std in these units is
   ``sqrt(e + read_noise_e^2) / (electrons_per_ms * t)`` whatever the gain, and saturated pixels
   read ``full_well_e / (g * electrons_per_ms * t)``.

Parameters (``color:`` section; ``electrons_per_ms: 0``, the default, turns the whole colour model
off, blur included, and then no other colour key may be set):
``electrons_per_ms`` (electrons a pixel collects per millisecond at linear scene value 1.0; 0),
``full_well_e`` (pixel capacity, electrons; required when on), ``read_noise_e`` (electrons rms; 0),
``exposure_percentile`` (97), ``exposure_target`` (fraction of the full well, 0.8),
``exposure_min_ms`` (0.01), ``exposure_max_ms`` (33.3: one frame at 30 fps), ``max_gain`` (16),
``motion_blur`` (false; true in both presets), ``blur_samples_max`` (16).
No colour filter array / demosaicing, vignetting, white balance, dark current or quantisation.

Independent random streams: depth and colour draw from separate ``SeedSequence([seed, k])``
children, so reading a frame without RGB gives the same depth as reading it with RGB.
"""

from __future__ import annotations

import hashlib
import math
import re
from dataclasses import dataclass, fields, replace
from pathlib import Path

import numpy as np

from .camera import Intrinsics
from .errors import SceneFormatError
from .fields import boolean, is_integer, is_number, number, shown
from .yamlfile import read_yaml

PRESET_DIR = Path(__file__).parent / "sensor_presets"
LUMA = np.array([0.2126, 0.7152, 0.0722])  # Rec. 709 luminance of linear RGB


@dataclass(frozen=True)
class DepthModel:
    """Depth sensor model; the defaults are "no effect" (see the module docstring for the order)."""

    sigma_a: float = 0.0  # m: constant axial noise
    sigma_b: float = 0.0  # 1/m: quadratic axial noise coefficient, times (z - sigma_z0)^2
    sigma_z0: float = 0.0  # m
    sigma_c: float = 0.0  # linear axial noise, fraction of z
    sigma_theta: float = 0.0  # m^1.5: Nguyen et al.'s incidence term, / sqrt(z) * theta^2 / (pi/2 - theta)^2
    lateral_px: float = 0.0  # std of the lateral displacement, in the sensor's pixels (focal_px; else the tour's)
    min_range_m: float = 0.0
    max_range_m: float = math.inf
    max_incidence_deg: float = 90.0  # 90 = no grazing dropout
    dark_relative: float = 0.0  # depth drops where lum / p97(lum over valid depth) is below this (0 = off)
    bright_relative: float = math.inf  # ... or above this (inf = off)
    edge_jump_rel: float = 0.0  # a depth edge: neighbour differs by more than this fraction of z (0 = off)
    edge_flying: float = 0.0  # probability an edge pixel becomes a mixed pixel
    edge_dropout: float = 0.0  # probability an edge pixel is dropped
    baseline_m: float = 0.0  # disparity quantisation baseline (0 = no quantisation)
    focal_px: float | None = None  # the sensor's focal length (px): quantisation, lateral noise; None = the tour's fx
    disparity_step_px: float = 0.125

    def sigma(self, z, theta=0.0):
        """Axial noise std (m) at planar depth ``z`` (m) and incidence ``theta`` (rad)."""
        z = np.asarray(z, dtype=np.float64)
        s = self.sigma_a + self.sigma_b * (z - self.sigma_z0) ** 2 + self.sigma_c * z
        if self.sigma_theta:
            th = np.minimum(np.asarray(theta, dtype=np.float64), math.pi / 2 - 1e-3)
            s = s + self.sigma_theta / np.sqrt(np.maximum(z, 1e-6)) * th**2 / (math.pi / 2 - th) ** 2
        return s

    @property
    def is_ideal(self) -> bool:
        return self == DepthModel()


@dataclass(frozen=True)
class ColorModel:
    """Colour camera: auto exposure, motion blur, shot / read noise in electrons, full-well clip
    (see the module docstring). ``electrons_per_ms == 0`` (the default) turns it off."""

    electrons_per_ms: float = 0.0  # electrons per ms at linear scene value 1.0 (0 = colour model off)
    full_well_e: float = 0.0  # pixel capacity (electrons); the digital value clips there
    read_noise_e: float = 0.0  # electrons rms, added before the gain
    exposure_percentile: float = 97.0  # the metered luminance percentile
    exposure_target: float = 0.8  # ... brought to this fraction of the full well
    exposure_min_ms: float = 0.01
    exposure_max_ms: float = 33.3  # one frame at 30 fps
    max_gain: float = 16.0  # analog gain, used only at the maximum exposure
    motion_blur: bool = False  # blur over the exposure from neighbouring poses (needs a Motion)
    blur_samples_max: int = 16

    def sigma(self, s, exposure_ms: float):
        """Noise std, in scene units, of a linear value ``s`` exposed for ``exposure_ms`` (before the clips)."""
        if self.is_ideal:
            return np.zeros_like(np.asarray(s, dtype=np.float64))
        k = self.electrons_per_ms * exposure_ms
        e = k * np.maximum(np.asarray(s, dtype=np.float64), 0.0)
        return np.sqrt(e + self.read_noise_e**2) / k

    @property
    def is_ideal(self) -> bool:
        return not self.electrons_per_ms


@dataclass(frozen=True)
class Motion:
    """The camera's motion around one frame, for motion blur: the frame's pose, the previous and next
    frames' poses (4x4 camera-to-world, OpenCV axes; None at a tour's ends) and the time (s) from
    the previous frame to this one and from this one to the next."""

    pose: np.ndarray
    prev_pose: np.ndarray | None = None
    next_pose: np.ndarray | None = None
    dt_prev: float = 1.0 / 30.0
    dt_next: float = 1.0 / 30.0


@dataclass(frozen=True)
class Sensor:
    name: str
    depth: DepthModel
    color: ColorModel
    source: str  # where the figures come from
    resolution: tuple[int, int] | None = None  # (width, height) the model is for; None = any tour's
    file: str = ""  # the YAML file it was read from (named by errors)

    @property
    def is_ideal(self) -> bool:
        return self.depth.is_ideal and self.color.is_ideal

    def check_resolution(self, width: int, height: int, tour: str) -> None:
        """A sensor made for one resolution reads only tours of that resolution (SceneFormatError
        naming the sensor's file and ``resolution`` otherwise)."""
        if self.resolution is not None and tuple(self.resolution) != (int(width), int(height)):
            w, h = self.resolution
            raise SceneFormatError(self.file or self.name, "resolution",
                                   f"sensor {self.name!r} is {w}x{h}, but tour {tour} is {width}x{height}")


# ---------------------------------------------------------------- parsing

_NULLABLE = {"focal_px": None, "max_range_m": math.inf, "bright_relative": math.inf}
_INF_OK = {"max_range_m", "bright_relative"}
_PROBABILITIES = {"edge_flying", "edge_dropout"}
_BOOLS = {"motion_blur"}
_INTEGERS = {"blur_samples_max"}
_POSITIVE = {"focal_px", "disparity_step_px", "exposure_percentile", "exposure_target", "exposure_min_ms",
             "exposure_max_ms", "blur_samples_max"}


def _section(doc, cls, file: str, key: str):
    if doc is None:
        return cls()
    if not isinstance(doc, dict):
        raise SceneFormatError(file, key, f"expected a mapping, got {type(doc).__name__}")
    known = {f.name for f in fields(cls)}
    out = {}
    for k, v in doc.items():
        field = f"{key}.{k}"
        if k not in known:
            raise SceneFormatError(file, field, f"unknown key; known: {', '.join(sorted(known))}")
        if v is None and k in _NULLABLE:
            out[k] = _NULLABLE[k]
            continue
        if k in _BOOLS:
            out[k] = boolean(file, v, field)
            continue
        if k in _INF_OK and isinstance(v, float) and v == math.inf:
            x = math.inf  # "no limit": the one non-finite value these keys take (vrformats.fields.number refuses it)
        else:
            x = number(file, v, field, lo=0.0)
        if k in _PROBABILITIES and x > 1:
            raise SceneFormatError(file, field, f"a probability must be in [0, 1], got {x}")
        if k == "max_incidence_deg" and not 0 < x <= 90:
            raise SceneFormatError(file, field, f"must be in (0, 90] degrees, got {x}")
        if k in _POSITIVE and x == 0:
            raise SceneFormatError(file, field, "must be positive")
        if k in _INTEGERS:
            if x != int(x):
                raise SceneFormatError(file, field, f"expected a whole number, got {v!r}")
            x = int(x)
        if k == "exposure_percentile" and x > 100:
            raise SceneFormatError(file, field, f"a percentile must be in (0, 100], got {x}")
        if k == "exposure_target" and x > 1:
            raise SceneFormatError(file, field, f"a fraction of the full well must be in (0, 1], got {x}")
        if k == "max_gain" and x < 1:
            raise SceneFormatError(file, field, f"must be at least 1 (no gain), got {x}")
        out[k] = x
    m = cls(**out)
    if isinstance(m, DepthModel) and m.min_range_m > m.max_range_m:
        raise SceneFormatError(file, f"{key}.min_range_m", f"{m.min_range_m} exceeds max_range_m {m.max_range_m}")
    if isinstance(m, ColorModel):
        others = sorted(str(k) for k in doc if k != "electrons_per_ms")
        if m.is_ideal and others:
            raise SceneFormatError(file, f"{key}.electrons_per_ms",
                                   f"missing or 0 (colour model off) while {', '.join(others)} "
                                   "set; give the electrons a pixel collects per ms at linear 1.0")
        if not m.is_ideal and not m.full_well_e:
            raise SceneFormatError(file, f"{key}.full_well_e", "must be positive when the colour model is on "
                                   "(electrons_per_ms > 0)")
        if m.exposure_min_ms > m.exposure_max_ms:
            raise SceneFormatError(file, f"{key}.exposure_min_ms",
                                   f"{m.exposure_min_ms} exceeds exposure_max_ms {m.exposure_max_ms}")
    return m


def parse_sensor(doc, source: str, _chain: tuple = ()) -> Sensor:
    """A Sensor from a YAML document (keys: name, source, depth, color); ``source`` is the file the
    document came from, named by every error together with the offending key."""
    if not isinstance(doc, dict):
        raise SceneFormatError(source, None, f"expected a mapping with name, source, depth, color; got {type(doc).__name__}")
    if "base" in doc:  # a preset with its noise scaled: {name: ..., base: structured_light, noise_scale: 2}
        extra = sorted(map(str, set(doc) - {"name", "base", "noise_scale"}))
        if extra:
            raise SceneFormatError(source, extra[0], "a scaled sensor holds name, base and noise_scale only")
        name = doc.get("name", Path(str(source)).stem)
        if not isinstance(name, str) or not re.fullmatch(r"[A-Za-z0-9_-]{1,120}", name):
            raise SceneFormatError(source, "name", f"expected a name of letters, digits, _ and - (at most 120), got {shown(name)}")
        base = doc["base"]
        if not isinstance(base, str) or not base:
            raise SceneFormatError(source, "base", f"expected the name of another sensor preset or file, got {shown(base)}")
        here = Path(str(source))
        bp = _sensor_file(base, source, "base", here.parent)
        chain = (*_chain, here.resolve())
        if bp.resolve() in chain:
            loop = " -> ".join(c.name for c in chain[chain.index(bp.resolve()):]) + f" -> {bp.name}"
            raise SceneFormatError(source, "base", f"a cycle of bases: {loop}")
        if len(chain) > MAX_BASE_CHAIN:
            raise SceneFormatError(source, "base", f"more than {MAX_BASE_CHAIN} bases deep")
        try:
            return scale_noise(parse_sensor(read_yaml(bp), str(bp), chain), doc.get("noise_scale", 1.0), name)
        except ValueError as e:
            raise SceneFormatError(source, "noise_scale", str(e).split(": ", 1)[1]) from None
    allowed = {"name", "source", "depth", "color", "resolution"}
    for k in doc:
        if k not in allowed:
            raise SceneFormatError(source, str(k), f"unknown key; known: {', '.join(sorted(allowed))}")
    name = doc.get("name", Path(str(source)).stem)
    if not isinstance(name, str) or not re.fullmatch(r"[A-Za-z0-9_-]{1,120}", name):
        raise SceneFormatError(source, "name", f"expected a name of letters, digits, _ and - (it names folders and "
                                               f"check keys; at most 120), got {shown(name)}")
    cite = doc.get("source", str(source))
    if not isinstance(cite, str):
        raise SceneFormatError(source, "source", f"expected text, got {cite!r}")
    res = doc.get("resolution")
    if res is not None:
        if (not isinstance(res, list) or len(res) != 2
                or any(not is_integer(v) or v <= 0 for v in res)):
            raise SceneFormatError(source, "resolution", f"expected [width, height] in pixels, got {res!r}")
        res = (int(res[0]), int(res[1]))
    return Sensor(name, _section(doc.get("depth"), DepthModel, source, "depth"),
                  _section(doc.get("color"), ColorModel, source, "color"), cite.strip(), res, str(source))


def scale_noise(sensor: Sensor, scale: float, name: str | None = None) -> Sensor:
    """``sensor`` with every noise multiplied by ``scale`` (issue 29's graded sensor factor): 0 is the
    ideal sensor, 1 the sensor itself, 2-3 worse. Depth: the axial noise terms, the lateral noise
    and the disparity step times ``scale``; the edge probabilities (flying pixels, dropouts) times
    ``scale``, at most 1. Colour: the electrons per ms and the full well divided by ``scale^2`` and
    the read noise by ``scale``: the auto exposure picks the same time and gain, and shot and read
    noise relative to the signal both grow by ``scale``, in bright and dark frames alike. What is not noise stays: ranges, grazing and brightness dropouts, motion
    blur, resolution."""
    if not is_number(scale) or scale < 0:
        raise ValueError(f"noise_scale: expected a number >= 0 (0 ideal, 1 the preset, 2-3 worse), got {scale!r}")
    label = name or f"{sensor.name}_x{scale:g}".replace(".", "p")
    if scale == 0:
        return Sensor(label, DepthModel(), ColorModel(), f"{sensor.source} (noise x 0: ideal)", sensor.resolution, sensor.file)
    d, c = sensor.depth, sensor.color
    depth = replace(d, sigma_a=d.sigma_a * scale, sigma_b=d.sigma_b * scale, sigma_c=d.sigma_c * scale,
                    sigma_theta=d.sigma_theta * scale, lateral_px=d.lateral_px * scale,
                    edge_flying=min(1.0, d.edge_flying * scale), edge_dropout=min(1.0, d.edge_dropout * scale),
                    disparity_step_px=d.disparity_step_px * scale)
    color = c if c.is_ideal else replace(c, electrons_per_ms=c.electrons_per_ms / scale**2,
                                         full_well_e=c.full_well_e / scale**2, read_noise_e=c.read_noise_e / scale)
    return Sensor(label, depth, color, f"{sensor.source} (noise x {scale:g})", sensor.resolution, sensor.file)


def list_sensors() -> list[str]:
    return sorted(p.stem for p in PRESET_DIR.glob("*.yaml"))


def _sensor_file(s: str, source=None, field: str = "sensor", folder: Path | None = None) -> Path:
    """The file a sensor name or path names: a preset name (``vrformats/sensor_presets/<name>.yaml``),
    else a YAML file (relative to ``folder``, the naming file's, when given). An unknown preset is
    reported against ``source`` and ``field`` (the file and key that named it)."""
    p = Path(s)
    if p.suffix.lower() not in (".yaml", ".yml", ".json") and "/" not in s and "\\" not in s:
        p = PRESET_DIR / f"{s}.yaml"
        if not p.is_file():
            raise SceneFormatError(source if source is not None else PRESET_DIR, field,
                                   f"unknown sensor preset {shown(s)}; known: {', '.join(list_sensors())} (or a YAML file)")
        return p
    return folder / p if folder is not None and not p.is_absolute() else p


MAX_BASE_CHAIN = 8  # a scaled sensor's base may itself be scaled, this many levels deep


def load_sensor(name_or_file, _chain: tuple = ()) -> Sensor:
    """A preset by name (``vrformats/sensor_presets/<name>.yaml``) or a sensor YAML file."""
    if isinstance(name_or_file, Sensor):
        return name_or_file
    p = _sensor_file(str(name_or_file))
    return parse_sensor(read_yaml(p), str(p), _chain)


# ---------------------------------------------------------------- seeding


def frame_seed(tour_key: str, frame: int, sensor_name: str, seed: int = 0) -> int:
    """A 63-bit seed for one frame of one tour under one sensor: the first 8 bytes (big-endian) of
    SHA-256 of ``"{tour_key}\\x1f{frame}\\x1f{sensor_name}\\x1f{seed}"`` (UTF-8), top bit cleared.
    Stable across processes and machines (unlike Python's ``hash``)."""
    msg = f"{tour_key}\x1f{int(frame)}\x1f{sensor_name}\x1f{int(seed)}".encode()
    return int.from_bytes(hashlib.sha256(msg).digest()[:8], "big") >> 1


# ---------------------------------------------------------------- models


def _one_sided(comps, z: np.ndarray, valid: np.ndarray, axis: int):
    """Per-pixel derivative of the point components ``comps`` along ``axis``: the forward or the
    backward difference, whichever has the smaller depth step among those whose both ends are
    valid; and whether one existed."""
    dz = np.abs(np.diff(z, axis=axis))
    ok = valid[1:, :] & valid[:-1, :] if axis == 0 else valid[:, 1:] & valid[:, :-1]
    dz[~ok] = np.inf
    H, W = z.shape
    fwd_dz = np.full((H, W), np.inf)
    bwd_dz = np.full((H, W), np.inf)
    if axis == 0:
        fwd_dz[:-1], bwd_dz[1:] = dz, dz
    else:
        fwd_dz[:, :-1], bwd_dz[:, 1:] = dz, dz
    use_fwd = fwd_dz <= bwd_dz
    out = []
    for c in comps:
        d = np.diff(c, axis=axis)
        f = np.zeros((H, W))
        b = np.zeros((H, W))
        if axis == 0:
            f[:-1], b[1:] = d, d
        else:
            f[:, :-1], b[:, 1:] = d, d
        out.append(np.where(use_fwd, f, b))
    return out, np.isfinite(np.minimum(fwd_dz, bwd_dz))


def incidence_angle(depth: np.ndarray, intr: Intrinsics) -> np.ndarray:
    """Angle (rad) between the surface normal and the viewing ray per pixel, from the depth image
    alone (normals from back-projected neighbours); 0 where it cannot be estimated."""
    z = np.asarray(depth, dtype=np.float64)
    valid = np.isfinite(z) & (z > 0)
    z = np.where(valid, z, 0.0)
    H, W = z.shape
    u = (np.arange(W, dtype=np.float64) - intr.cx) / intr.fx
    v = (np.arange(H, dtype=np.float64) - intr.cy) / intr.fy
    P = (z * u[None, :], z * v[:, None], z)
    (ax, ay, az), hu = _one_sided(P, z, valid, 1)
    (bx, by, bz), hv = _one_sided(P, z, valid, 0)
    nx, ny, nz = ay * bz - az * by, az * bx - ax * bz, ax * by - ay * bx  # normal = dP/du x dP/dv
    nn = np.sqrt(nx * nx + ny * ny + nz * nz)
    pn = z * np.sqrt(u[None, :] ** 2 + v[:, None] ** 2 + 1.0)
    ok = valid & hu & hv & (nn > 0)
    cos = np.abs(nx * P[0] + ny * P[1] + nz * P[2]) / np.where(ok, nn * pn, 1.0)
    return np.where(ok, np.arccos(np.clip(cos, 0.0, 1.0)), 0.0)


def _edges(z: np.ndarray, valid: np.ndarray, rel: float) -> tuple[np.ndarray, np.ndarray]:
    """Depth-edge pixels (a valid 4-neighbour differing by more than rel * z) and, per pixel, the
    depth of the most different such neighbour."""
    H, W = z.shape
    zp = np.pad(z, 1)
    vp = np.pad(valid, 1)
    best = np.zeros_like(z)
    best_diff = np.zeros_like(z)
    for dy, dx in ((-1, 0), (1, 0), (0, -1), (0, 1)):
        zn = zp[1 + dy:1 + dy + H, 1 + dx:1 + dx + W]
        vn = vp[1 + dy:1 + dy + H, 1 + dx:1 + dx + W]
        diff = np.where(vn & valid, np.abs(zn - z), 0.0)
        take = diff > best_diff
        best = np.where(take, zn, best)
        best_diff = np.where(take, diff, best_diff)
    return valid & (best_diff > rel * z), best


def _apply_depth(m: DepthModel, depth: np.ndarray, rgb, intr: Intrinsics, ss: np.random.SeedSequence) -> np.ndarray:
    rng_lat, rng_ax, rng_edge = (np.random.default_rng(s) for s in ss.spawn(3))
    z0 = np.asarray(depth, dtype=np.float64)
    valid = np.isfinite(z0) & (z0 > 0)
    z0 = np.where(valid, z0, 0.0)
    H, W = z0.shape
    need_theta = m.sigma_theta > 0 or m.max_incidence_deg < 90
    theta = incidence_angle(z0, intr) if need_theta else np.zeros_like(z0)

    z, th, ok = z0, theta, valid
    if m.lateral_px > 0:
        lat = m.lateral_px * (intr.fx / m.focal_px if m.focal_px else 1.0)  # in the tour's pixels
        dy = np.rint(rng_lat.normal(0.0, lat, (H, W))).astype(np.int64)
        dx = np.rint(rng_lat.normal(0.0, lat, (H, W))).astype(np.int64)
        rows = np.clip(np.arange(H)[:, None] + dy, 0, H - 1)
        cols = np.clip(np.arange(W)[None, :] + dx, 0, W - 1)
        z, th = z0[rows, cols], theta[rows, cols]
        ok = valid & valid[rows, cols]
        z = np.where(ok, z, 0.0)

    sig = m.sigma(np.where(ok, z, 1.0), th)
    if np.any(sig > 0):
        z = z + sig * rng_ax.standard_normal((H, W))

    drop = ~ok
    if m.edge_jump_rel > 0 and (m.edge_flying > 0 or m.edge_dropout > 0):
        edge, znb = _edges(z0, valid, m.edge_jump_rel)
        u_fly, t_fly, u_drop = rng_edge.random((3, H, W))
        fly = edge & ok & (u_fly < m.edge_flying)
        z = np.where(fly, z + t_fly * (znb - z), z)
        drop |= edge & (u_drop < m.edge_dropout)

    if m.baseline_m > 0:
        fB = (m.focal_px if m.focal_px is not None else intr.fx) * m.baseline_m
        with np.errstate(divide="ignore", invalid="ignore"):
            d = fB / z
            dq = np.rint(d / m.disparity_step_px) * m.disparity_step_px
            zq = fB / dq
        good = np.isfinite(zq) & (dq > 0)
        drop |= ~good
        z = np.where(good, zq, 0.0)

    drop |= (z < m.min_range_m) | (z > m.max_range_m) | ~(z > 0)
    if m.max_incidence_deg < 90:
        drop |= th > math.radians(m.max_incidence_deg)
    if rgb is not None and (m.dark_relative > 0 or math.isfinite(m.bright_relative)) and valid.any():
        lum = _luminance(rgb)
        p97 = float(np.percentile(lum[valid], 97))
        if p97 > 1e-12:  # a black frame (or black where there is depth): no reference, no dropout
            r = lum / p97
            drop |= (r < m.dark_relative) | (r > m.bright_relative)
    return np.where(drop, 0.0, z).astype(np.float32)


def _luminance(rgb) -> np.ndarray:
    """Linear Rec. 709 luminance, non-finite values read as 0."""
    lum = np.asarray(rgb, dtype=np.float64)[..., :3] @ LUMA
    return np.where(np.isfinite(lum), lum, 0.0)


def exposure(color_model: ColorModel, rgb: np.ndarray) -> tuple[float, float]:
    """(exposure time in ms, analog gain) the colour model's auto exposure picks for the linear frame
    ``rgb``; ``(0.0, 1.0)`` when the colour model is off. See the module docstring."""
    m = color_model
    if m.is_ideal:
        return 0.0, 1.0
    if not m.full_well_e > 0:
        raise ValueError("ColorModel: full_well_e must be positive when electrons_per_ms > 0")
    lum = _luminance(rgb)
    p = float(np.percentile(lum, m.exposure_percentile)) if lum.size else 0.0
    if not p > 0:
        return float(m.exposure_max_ms), float(m.max_gain)
    want = m.exposure_target * m.full_well_e / (m.electrons_per_ms * p)
    t = min(max(want, m.exposure_min_ms), m.exposure_max_ms)
    gain = min(max(want / t, 1.0), m.max_gain) if want > m.exposure_max_ms else 1.0
    return float(t), float(gain)


def _rotvec_to_matrix(w: np.ndarray) -> np.ndarray:
    """Rodrigues: the rotation matrix exp([w]x)."""
    th = float(np.linalg.norm(w))
    if th < 1e-12:
        return np.eye(3)
    k = w / th
    Kx = np.array([[0.0, -k[2], k[1]], [k[2], 0.0, -k[0]], [-k[1], k[0], 0.0]])
    return np.eye(3) + math.sin(th) * Kx + (1.0 - math.cos(th)) * (Kx @ Kx)


def _pose_interpolator(motion: Motion):
    """A function tau (s from the frame's time) -> (R, t) taking points from the frame's camera to the
    camera at tau (interpolated toward the neighbour on tau's side, extrapolated from the other one
    when it is missing); None when the motion has no neighbour."""
    T = np.asarray(motion.pose, dtype=np.float64)
    R_T, t_T = T[:3, :3], T[:3, 3]
    sides = {}
    for key, nb, dt in (("prev", motion.prev_pose, motion.dt_prev), ("next", motion.next_pose, motion.dt_next)):
        if nb is not None and dt is not None and dt > 0:
            from scipy.spatial.transform import Rotation

            N = np.asarray(nb, dtype=np.float64)
            sides[key] = (Rotation.from_matrix(R_T.T @ N[:3, :3]).as_rotvec(), N[:3, 3] - t_T, float(dt))
    if not sides:
        return None

    def at(tau: float):
        if tau == 0:
            return np.eye(3), np.zeros(3)
        order = ("prev", "next") if tau < 0 else ("next", "prev")
        key = order[0] if order[0] in sides else order[1]
        w, d, dt = sides[key]
        s = (-tau if key == "prev" else tau) / dt  # fraction of the way to that neighbour (< 0: away from it)
        R_s = R_T @ _rotvec_to_matrix(s * w)  # slerp: R_T exp(s log(R_T^T R_N))
        # X_s = R_s^T (T X - t_s), t_s = t_T + s d:  X_s = R_s^T R_T X - s R_s^T d
        return R_s.T @ R_T, -s * (R_s.T @ d)

    return at


def _rays(depth, intr: Intrinsics):
    """Per-pixel normalised ray coordinates x, y (broadcastable) and inverse depth (0 = at infinity)."""
    z = np.asarray(depth, dtype=np.float64)
    H, W = z.shape
    x = ((np.arange(W, dtype=np.float64) - intr.cx) / intr.fx)[None, :]
    y = ((np.arange(H, dtype=np.float64) - intr.cy) / intr.fy)[:, None]
    finite = np.isfinite(z) & (z > 0)
    iz = np.where(finite, 1.0 / np.where(finite, z, 1.0), 0.0)
    return x, y, iz


def _flow(rays, intr: Intrinsics, R: np.ndarray, t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    x, y, iz = rays
    X = [R[i, 0] * x + R[i, 1] * y + R[i, 2] + t[i] * iz for i in range(3)]  # X' / z; t counts at finite depth only
    front = X[2] > 1e-9
    Z = np.where(front, X[2], 1.0)
    du = np.where(front, intr.fx * (X[0] / Z - x), 0.0)
    dv = np.where(front, intr.fy * (X[1] / Z - y), 0.0)
    return np.broadcast_arrays(du, dv)


def motion_flow(depth: np.ndarray, intr: Intrinsics, R: np.ndarray, t: np.ndarray) -> np.ndarray:
    """(H, W, 2) flow (du, dv) in px: where each pixel's 3-D point (planar ``depth``, 0 / non-finite =
    at infinity) projects in a camera related to the frame's by ``X' = R X + t``, minus the pixel;
    0 where the point would be behind that camera."""
    return np.stack(_flow(_rays(depth, intr), intr, np.asarray(R, float), np.asarray(t, float)), axis=-1)


def motion_blur(rgb: np.ndarray, depth: np.ndarray | None, intr: Intrinsics, motion: Motion | None,
                exposure_ms: float, samples_max: int = 16) -> np.ndarray:
    """The frame ``rgb`` integrated over an exposure of ``exposure_ms`` centred on the frame's time,
    the camera moving as ``motion`` says (see the module docstring); the input itself when there is
    no motion, no neighbour, or less than ~1 px of blur. Depth: planar metres, 0 = no hit
    (rotation-only flow there); None = everything at infinity."""
    if motion is None or not exposure_ms > 0:
        return rgb
    at = _pose_interpolator(motion)
    if at is None:
        return rgb
    H, W = np.asarray(rgb).shape[:2]
    rays = _rays(np.zeros((H, W)) if depth is None else depth, intr)
    half = exposure_ms / 2000.0  # s
    (u0, v0), (u1, v1) = (_flow(rays, intr, *at(tau)) for tau in (-half, half))
    longest = float(np.sqrt((u1 - u0) ** 2 + (v1 - v0) ** 2).max())
    n = int(min(max(math.ceil(longest), 1), max(int(samples_max), 1)))
    if n == 1:
        return rgb
    import cv2

    src = np.ascontiguousarray(np.asarray(rgb, dtype=np.float32))
    uu = np.arange(W, dtype=np.float64)[None, :]
    vv = np.arange(H, dtype=np.float64)[:, None]
    acc = np.zeros(src.shape, dtype=np.float64)
    for k in range(n):
        du, dv = _flow(rays, intr, *at(-half + (k + 0.5) * (2 * half) / n))
        mx = (uu - du).astype(np.float32)
        my = (vv - dv).astype(np.float32)
        acc += cv2.remap(src, mx, my, cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE).reshape(src.shape)
    return (acc / n).astype(src.dtype)


def _apply_color(m: ColorModel, rgb: np.ndarray, depth, intr: Intrinsics, motion: Motion | None,
                 ss: np.random.SeedSequence) -> np.ndarray:
    rng = np.random.default_rng(ss)
    s_in = np.asarray(rgb)
    t, gain = exposure(m, s_in)
    s = s_in
    if m.motion_blur and motion is not None:
        s = motion_blur(s_in, depth, intr, motion, t, m.blur_samples_max)
    k = m.electrons_per_ms * t  # electrons per unit of linear value
    e = np.nan_to_num(np.asarray(s, dtype=np.float64) * k, nan=0.0, posinf=m.full_well_e, neginf=0.0)
    e = np.maximum(e, 0.0)
    e = e + np.sqrt(e + m.read_noise_e**2) * rng.standard_normal(e.shape)  # shot (Gaussian) + read noise
    e = np.clip(e, 0.0, m.full_well_e)
    e = np.minimum(e * gain, m.full_well_e) / gain  # the digital value g e clips at the full well
    out = e / k
    return out.astype(s_in.dtype if np.issubdtype(s_in.dtype, np.floating) else np.float32)


def apply_sensor(sensor: Sensor, depth: np.ndarray, rgb: np.ndarray | None, intr: Intrinsics, seed: int,
                 motion: Motion | None = None) -> tuple[np.ndarray, np.ndarray | None]:
    """Noisy (depth, rgb) for one frame; deterministic for a seed; the input arrays are not modified.

    ``depth``: (H, W) planar metres, 0 = no hit; ``rgb``: (H, W, 3) linear scene-referred radiance
    or None (no dark or bright dropout then). An ideal sensor (or an ideal half) returns its inputs
    as they are (the same arrays); otherwise new float32 depth / float rgb arrays (the rgb still
    scene-referred linear). ``seed``: see ``frame_seed``. ``motion``: the camera's motion around
    the frame (``Motion``), for motion blur of the colour image; None = no blur.
    """
    ss_depth, ss_color = np.random.SeedSequence([int(seed) & (2**64 - 1), 0]), np.random.SeedSequence([int(seed) & (2**64 - 1), 1])
    out_depth = depth if depth is None or sensor.depth.is_ideal else _apply_depth(sensor.depth, depth, rgb, intr, ss_depth)
    out_rgb = (rgb if rgb is None or sensor.color.is_ideal
               else _apply_color(sensor.color, rgb, depth, intr, motion, ss_color))
    return out_depth, out_rgb
