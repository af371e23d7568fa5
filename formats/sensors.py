"""Seeded RGB-D sensor models, applied when a frame is read (not when it is rendered).

One render serves every sensor setting: ``apply_sensor`` turns a rendered frame (planar depth in
metres, 0 = no hit; linear RGB) into what a given camera would have measured, deterministically
for a seed. ``frame_seed`` derives that seed from (tour, frame, sensor, run seed) with SHA-256, so
every method and every process sees the same noisy frame.

Presets (``formats/sensor_presets/<name>.yaml``; every figure is cited in the file):

* ``ideal``: no effect at all; ``apply_sensor`` returns its inputs (today's output).
* ``structured_light``: a Kinect-v1-class camera. Axial noise
  ``sigma_z = 0.0012 + 0.0019 (z - 0.4)^2`` m (Nguyen, Izadi & Lovell 2012, 3DIMPVT, for
  10-60 deg incidence) plus their incidence term ``0.0001 / sqrt(z) * theta^2 / (pi/2 - theta)^2``;
  lateral noise ~0.8 px (same paper); disparity quantisation with a 7.5 cm baseline, ~580 px focal
  length and 1/8 px disparity steps (Khoshelham & Elberink 2012, Sensors 12(2):1437-1454: random
  error grows quadratically with range, to ~4 cm at 5 m); range 0.5-4.5 m; dropouts at grazing
  incidence and on dark surfaces.
* ``tof``: a Kinect-v2 / Azure-Kinect-class time-of-flight camera: small, roughly linear noise
  (1.5 mm + 0.15 % of range), range 0.5-4.5 m, mixed ("flying") pixels and dropouts at depth
  edges; multipath is ignored.

The depth model, per valid pixel (input depth > 0 and finite), in this order:

1. incidence angle ``theta`` between the surface normal and the viewing ray, with normals from the
   depth image itself (back-projected with the intrinsics; one-sided differences, the side with
   the smaller depth step, so a normal next to a depth edge is the surface's own);
2. lateral noise: the pixel reads depth (and theta) from a neighbour displaced by
   ``round(N(0, lateral_px))`` in u and v (a displaced read of a no-hit pixel gives no depth);
3. axial noise: ``z + sigma(z, theta) * N(0, 1)`` with
   ``sigma = sigma_a + sigma_b (z - sigma_z0)^2 + sigma_c z + sigma_theta / sqrt(z) * theta^2 / (pi/2 - theta)^2``;
4. depth edges (a 4-neighbour whose depth differs by more than ``edge_jump_rel * z``): with
   probability ``edge_flying`` the pixel becomes a mixed pixel (a uniform blend of its depth and
   the most different neighbour's), then with probability ``edge_dropout`` it is dropped;
5. disparity quantisation (``baseline_m > 0``): ``d = f B / z``, ``d_q = round(d / step) step``,
   ``z_q = f B / d_q`` (``f`` = ``focal_px`` or the tour's fx);
6. dropouts (depth set to 0): measured depth outside ``[min_range_m, max_range_m]``; ``theta``
   above ``max_incidence_deg``; where the frame has RGB, linear Rec. 709 luminance below
   ``dark_threshold`` (a proxy for low IR reflectivity: the renderer has no IR albedo, so the
   visible-light luminance under the tour's lighting stands in for it) or above
   ``bright_threshold`` (saturated / specular). Frames without RGB get no dark or bright dropout.

The colour model, in linear space, per channel: ``s_noisy = s + sqrt(s / full_well_e) N1 +
(read_noise_e / full_well_e) N2``, clipped at 0 (shot noise as a Gaussian with variance
proportional to the signal, ``full_well_e`` electrons at linear 1.0, plus read noise). There is no
upper clip, exposure policy or motion blur here (later steps).

Independent random streams: depth and colour draw from separate ``SeedSequence([seed, k])``
children, so reading a frame without RGB gives the same depth as reading it with RGB.
"""

from __future__ import annotations

import hashlib
import math
from dataclasses import dataclass, fields
from pathlib import Path

import numpy as np

from .camera import Intrinsics
from .errors import SceneFormatError
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
    lateral_px: float = 0.0  # std of the lateral (pixel) displacement
    min_range_m: float = 0.0
    max_range_m: float = math.inf
    max_incidence_deg: float = 90.0  # 90 = no grazing dropout
    dark_threshold: float = 0.0  # linear luminance below which depth drops (0 = off)
    bright_threshold: float = math.inf  # linear luminance above which depth drops (inf = off)
    edge_jump_rel: float = 0.0  # a depth edge: neighbour differs by more than this fraction of z (0 = off)
    edge_flying: float = 0.0  # probability an edge pixel becomes a mixed pixel
    edge_dropout: float = 0.0  # probability an edge pixel is dropped
    baseline_m: float = 0.0  # disparity quantisation baseline (0 = no quantisation)
    focal_px: float | None = None  # focal length for quantisation; None = the tour's fx
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
    """Colour noise in linear space: shot noise (``full_well_e`` electrons at 1.0; 0 = off) and read noise."""

    full_well_e: float = 0.0
    read_noise_e: float = 0.0

    def sigma(self, s):
        """Noise std of a linear value ``s`` (before the clip at 0)."""
        if not self.full_well_e:
            return np.zeros_like(np.asarray(s, dtype=np.float64))
        s = np.maximum(np.asarray(s, dtype=np.float64), 0.0)
        return np.sqrt(s / self.full_well_e + (self.read_noise_e / self.full_well_e) ** 2)

    @property
    def is_ideal(self) -> bool:
        return not self.full_well_e


@dataclass(frozen=True)
class Sensor:
    name: str
    depth: DepthModel
    color: ColorModel
    source: str  # where the figures come from

    @property
    def is_ideal(self) -> bool:
        return self.depth.is_ideal and self.color.is_ideal


# ---------------------------------------------------------------- parsing

_NULLABLE = {"focal_px": None, "max_range_m": math.inf, "bright_threshold": math.inf}
_INF_OK = {"max_range_m", "bright_threshold"}
_PROBABILITIES = {"edge_flying", "edge_dropout"}


def _number(v, file: str, field: str) -> float:
    if isinstance(v, bool) or not isinstance(v, (int, float)):
        raise SceneFormatError(file, field, f"expected a number, got {v!r}")
    v = float(v)
    if math.isnan(v):
        raise SceneFormatError(file, field, "NaN is not allowed")
    if v < 0:
        raise SceneFormatError(file, field, f"must not be negative, got {v}")
    return v


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
        x = _number(v, file, field)
        if math.isinf(x) and k not in _INF_OK:
            raise SceneFormatError(file, field, "must be finite")
        if k in _PROBABILITIES and x > 1:
            raise SceneFormatError(file, field, f"a probability must be in [0, 1], got {x}")
        if k == "max_incidence_deg" and not 0 < x <= 90:
            raise SceneFormatError(file, field, f"must be in (0, 90] degrees, got {x}")
        if k in ("focal_px", "disparity_step_px") and x == 0:
            raise SceneFormatError(file, field, "must be positive")
        out[k] = x
    m = cls(**out)
    if isinstance(m, DepthModel) and m.min_range_m > m.max_range_m:
        raise SceneFormatError(file, f"{key}.min_range_m", f"{m.min_range_m} exceeds max_range_m {m.max_range_m}")
    if isinstance(m, ColorModel) and m.read_noise_e and not m.full_well_e:
        raise SceneFormatError(file, f"{key}.read_noise_e", "needs color.full_well_e (electrons at linear 1.0)")
    return m


def parse_sensor(doc, source: str) -> Sensor:
    """A Sensor from a YAML document (keys: name, source, depth, color); ``source`` is the file the
    document came from, named by every error together with the offending key."""
    if not isinstance(doc, dict):
        raise SceneFormatError(source, None, f"expected a mapping with name, source, depth, color; got {type(doc).__name__}")
    allowed = {"name", "source", "depth", "color"}
    for k in doc:
        if k not in allowed:
            raise SceneFormatError(source, str(k), f"unknown key; known: {', '.join(sorted(allowed))}")
    name = doc.get("name", Path(str(source)).stem)
    if not isinstance(name, str) or not name:
        raise SceneFormatError(source, "name", f"expected a non-empty string, got {name!r}")
    cite = doc.get("source", str(source))
    if not isinstance(cite, str):
        raise SceneFormatError(source, "source", f"expected text, got {cite!r}")
    return Sensor(name, _section(doc.get("depth"), DepthModel, source, "depth"),
                  _section(doc.get("color"), ColorModel, source, "color"), cite.strip())


def list_sensors() -> list[str]:
    return sorted(p.stem for p in PRESET_DIR.glob("*.yaml"))


def load_sensor(name_or_file) -> Sensor:
    """A preset by name (``formats/sensor_presets/<name>.yaml``) or a sensor YAML file."""
    if isinstance(name_or_file, Sensor):
        return name_or_file
    s = str(name_or_file)
    p = Path(s)
    if p.suffix.lower() not in (".yaml", ".yml", ".json") and "/" not in s and "\\" not in s:
        p = PRESET_DIR / f"{s}.yaml"
        if not p.is_file():
            raise SceneFormatError(PRESET_DIR, "sensor", f"unknown sensor preset {s!r}; known: {', '.join(list_sensors())} (or a YAML file)")
    return parse_sensor(read_yaml(p), str(p))


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
        dy = np.rint(rng_lat.normal(0.0, m.lateral_px, (H, W))).astype(np.int64)
        dx = np.rint(rng_lat.normal(0.0, m.lateral_px, (H, W))).astype(np.int64)
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
    if rgb is not None and (m.dark_threshold > 0 or math.isfinite(m.bright_threshold)):
        lum = np.asarray(rgb, dtype=np.float64)[..., :3] @ LUMA
        drop |= (lum < m.dark_threshold) | (lum > m.bright_threshold)
    return np.where(drop, 0.0, z).astype(np.float32)


def _apply_color(m: ColorModel, rgb: np.ndarray, ss: np.random.SeedSequence) -> np.ndarray:
    rng = np.random.default_rng(ss)
    s = np.asarray(rgb)
    sig = m.sigma(s)
    out = np.maximum(s.astype(np.float64) + sig * rng.standard_normal(s.shape), 0.0)
    return out.astype(s.dtype if np.issubdtype(s.dtype, np.floating) else np.float32)


def apply_sensor(sensor: Sensor, depth: np.ndarray, rgb: np.ndarray | None, intr: Intrinsics, seed: int) -> tuple[np.ndarray, np.ndarray | None]:
    """Noisy (depth, rgb) for one frame; deterministic for a seed; the input arrays are not modified.

    ``depth``: (H, W) planar metres, 0 = no hit; ``rgb``: (H, W, 3) linear or None (no dark or
    bright dropout then). An ideal sensor (or an ideal half) returns its inputs as they are (the
    same arrays); otherwise new float32 depth / float rgb arrays. ``seed``: see ``frame_seed``.
    """
    ss_depth, ss_color = np.random.SeedSequence([int(seed) & (2**64 - 1), 0]), np.random.SeedSequence([int(seed) & (2**64 - 1), 1])
    out_depth = depth if depth is None or sensor.depth.is_ideal else _apply_depth(sensor.depth, depth, rgb, intr, ss_depth)
    out_rgb = rgb if rgb is None or sensor.color.is_ideal else _apply_color(sensor.color, rgb, ss_color)
    return out_depth, out_rgb
