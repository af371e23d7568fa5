"""Frame-to-frame RGB-D odometry (paper Sec. III-C): within-clip camera poses V_i.

VideoReloc chains consecutive frames with Open3D's geometry-based RGB-D odometry into poses
``V_i`` (camera-to-clip, ``V_first = I``). A clip must end at a capture gap or where the odometry
is inconsistent. Open3D's own success flag is no test of that (it is True even without overlap),
so every step here is checked by projective association against the reference frame:

* ``fitness``: fraction of the current frame's valid pixels that land on the reference frame's
  surface (within ``depth_diff_max_m`` along the reference normal and along z);
* ``inlier_rmse``: RMS point-to-plane residual of those pixels (metres);
* the step size (translation, rotation) of the estimated motion.

A step failing any of ``min_fitness``, ``max_inlier_rmse_m``, ``max_step_translation_m`` or
``max_step_rotation_deg`` is not ok and its ``reason`` says which gate it failed.

The solver is Open3D's tensor point-to-plane kernel
(``open3d.t.pipelines.odometry.compute_odometry_result_point_to_plane``, one Gauss-Newton step
per call) driven level by level from here, so that each frame's vertex and normal maps are built
once and reused while it is the reference. Normals skip crease and edge pixels (forward and
backward differences must agree): smoothed normals there biased the solution by centimetres per
step in this project's box-and-plane apartments. ``method="hybrid"`` with RGB uses Open3D's
``rgbd_odometry_multi_scale`` (``Method.Hybrid``) and the same gates.

Depth-only odometry cannot see motion along a plane it slides over (a camera facing one wall,
walking down a corridor). Such directions are found from the eigenvalues of the point-to-plane
information matrix at the solution (``min_information``); along them the estimate is replaced
by the constant-velocity prediction (the previous step's motion), which also seeds every solve.
Steps stay ok then; ``OdometryStep.degenerate_dims`` says how many of the 6 directions came from
the prior. Without a prior (a clip's first step, :func:`relative_motion` without ``init``) the
basin of convergence is about one frame of motion at 1 m/s: fast turns (5 deg per step) from the
identity can end in a wrong minimum that still passes the gates, which is why a chain's first
step is taken over a single frame.

Pieces, from low to high level:

* :class:`Odometry` -- ``step(depth, rgb=None)`` against the previous frame given to it;
* :class:`OdometryChain` -- the streaming front-end's view: frames in one at a time, odometry
  every ``config.stride`` frames against the last keyframe, interpolated poses for the frames in
  between, clip breaks at failed gates; poses come out in frame order, at most ``stride - 1``
  frames late, and ``flush()`` emits the rest at the end of the stream;
* :func:`relative_motion` -- one gated solve between two arbitrary frames (e.g. the back-end's
  boundary odometry between clips).

Depth images are (H, W) planar metres with 0 (or NaN/inf) for no surface; ``K`` is the 3x3
intrinsic matrix of the full-size image with pixel centres at integer coordinates (OpenCV).
Odometry runs at ``config.width`` columns (nearest-neighbour subsampling, K scaled to match).
Poses are 4x4 camera-to-X matrices, OpenCV camera axes.
"""

from __future__ import annotations

import math
from contextlib import contextmanager
from dataclasses import dataclass, field
from typing import NamedTuple

import numpy as np

from ..config import OdometryConfig
from ..geometry import exp_so3 as _exp_so3
from ..geometry import log_so3 as _log_so3

# ours: a level's Gauss-Newton loop stops once an update moves less than this
_CONVERGED_TRANSLATION_M = 1e-5
_CONVERGED_ROTATION_RAD = 1e-5
# ours: a Gauss-Newton update larger than this is divergence, not progress
_MAX_UPDATE_TRANSLATION_M = 0.2
_MAX_UPDATE_ROTATION_DEG = 10.0


# ---------------------------------------------------------------------------------------------
# small SE(3) helpers (the rotation maps themselves are reloc.geometry's)


def rotation_deg(T: np.ndarray) -> float:
    """Rotation angle of a 4x4 (or 3x3) transform in degrees."""
    R = T[:3, :3]
    return math.degrees(math.acos(max(-1.0, min(1.0, (float(np.trace(R)) - 1.0) / 2.0))))


def interpolate_pose(A: np.ndarray, B: np.ndarray, f: float) -> np.ndarray:
    """Pose a fraction ``f`` of the way from ``A`` to ``B``: SLERP rotation, linear translation."""
    out = np.eye(4)
    Ra, Rb = A[:3, :3], B[:3, :3]
    out[:3, :3] = Ra @ _exp_so3(f * _log_so3(Ra.T @ Rb))
    out[:3, 3] = (1.0 - f) * A[:3, 3] + f * B[:3, 3]
    return out


def scale_motion(T: np.ndarray, f: float) -> np.ndarray:
    """A relative motion scaled by ``f`` (f * rotation angle about the same axis, f * translation)."""
    return interpolate_pose(np.eye(4), T, f)


# ---------------------------------------------------------------------------------------------
# results


@dataclass
class OdometryStep:
    """One odometry solve: the current camera's pose in the previous (reference) camera frame."""

    T_prev_cur: np.ndarray  # 4x4; x_prev = T_prev_cur @ x_cur; identity when no solve was possible
    ok: bool
    fitness: float = 0.0  # fraction of the current frame's valid pixels with a correspondence
    inlier_rmse: float = float("nan")  # RMS point-to-plane residual of those, metres
    reason: str = ""  # why not ok (empty when ok)
    translation_m: float = 0.0  # |t| of T_prev_cur
    rotation_deg: float = 0.0  # rotation angle of T_prev_cur
    degenerate_dims: int = 0  # directions (of 6) the geometry does not fix, taken from the prior


class ChainPose(NamedTuple):
    """One frame's pose as :class:`OdometryChain` emits it.

    ``V`` is the camera-to-clip pose (the clip's first frame is the identity), or None for a
    frame without usable depth (it belongs to no clip). ``status``:

    * ``"start"``: first frame of a clip, after the stream's start, a reset or unusable frames;
    * ``"break"``: first frame of a clip because odometry from the previous clip to this frame
      failed a gate (``reason`` says which) -- the previous clip ended at the frame before;
    * ``"ok"``: a pose within the current clip (``keyframe`` False: interpolated between two
      odometry keyframes);
    * ``"invalid"``: no usable depth (``reason``), ``V`` is None, ``clip`` is -1; the clip
      before it has ended.
    """

    frame_index: int
    V: np.ndarray | None
    status: str
    clip: int
    reason: str = ""
    keyframe: bool = True

    @property
    def new_clip(self) -> bool:
        return self.status in ("start", "break")


@dataclass
class PreparedFrame:
    """A frame at odometry resolution: depth (NaN = invalid) and its vertex/normal pyramids."""

    depth: np.ndarray  # (h, w) float32, NaN where invalid
    valid_fraction: float
    vertex: list = field(default_factory=list)  # per level, finest first: o3c (h, w, 3) float32
    normal: list = field(default_factory=list)  # per level: o3c (h, w, 3) float32, NaN invalid
    K: list = field(default_factory=list)  # per level: o3c (3, 3) float64
    K_np: np.ndarray | None = None  # finest level
    vertex_np: np.ndarray | None = None  # finest level, (h * w, 3)
    normal_np: np.ndarray | None = None  # finest level, (h * w, 3)
    points: np.ndarray | None = None  # finest level, valid vertices only, (n, 3)
    rgb: np.ndarray | None = None  # (h, w, 3) float32 in [0, 1] for the hybrid method

    @property
    def usable(self) -> bool:
        return bool(self.vertex)


# ---------------------------------------------------------------------------------------------
# odometry


def _o3d():
    from vrformats.native import import_open3d

    o3d = import_open3d()  # a missing libGL is one line naming its package
    import open3d.core as o3c
    import open3d.t.pipelines.odometry as od

    return o3d, o3c, od


@contextmanager
def _one_thread():
    """Run Open3D on one thread inside the block, so that odometry is bitwise reproducible.

    Open3D's CPU kernels add their per-thread partial sums in the order the threads finish: with
    more than one thread the same solve gives a different last bit on each call (20 distinct
    results in 20 calls here), and over a tour such noise can tip a gate or a clip checkpoint,
    so two runs of one tour differed by 0.3 mm. On one thread the result is identical call to
    call and process to process, at the same speed at this project's odometry resolution
    (median 0.51 s against 0.50 s for 120 frames at 160x120 on 2 cores).
    """
    o3d, _, _ = _o3d()
    before = o3d.utility.get_max_threads()
    o3d.utility.set_max_threads(1)
    try:
        yield
    finally:
        o3d.utility.set_max_threads(before)


def scaled_intrinsics(K: np.ndarray, width: int, height: int, out_width: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Column/row indices for nearest-neighbour subsampling to ``out_width`` columns (rows keep
    the aspect ratio) and the matching K (pixel centres at integer coordinates).

    Returns (cols, rows, K_small). Small pixel u' samples full-size column
    ``floor((u' + 0.5) * a)`` for the factor a = width / out_width: an exact affine map
    ``u = a u' + b`` for integer factors, within half a source pixel otherwise; K_small is fitted
    to the sampled positions, so a small pixel's ray is its source pixel's ray.
    """
    out_width = int(min(max(out_width, 8), width))
    a = width / out_width
    out_height = max(1, round(height / a))
    cols = np.clip(np.floor((np.arange(out_width) + 0.5) * a).astype(int), 0, width - 1)
    rows = np.clip(np.floor((np.arange(out_height) + 0.5) * (height / out_height)).astype(int), 0, height - 1)
    # affine fit source = s * small + o per axis (exact for integer factors)
    su, ou = np.polyfit(np.arange(out_width), cols, 1) if out_width > 1 else (1.0, float(cols[0]))
    sv, ov = np.polyfit(np.arange(out_height), rows, 1) if out_height > 1 else (1.0, float(rows[0]))
    Ks = np.array(K, dtype=np.float64).copy()
    Ks[0, 0] = K[0, 0] / su
    Ks[0, 1] = K[0, 1] / su
    Ks[0, 2] = (K[0, 2] - ou) / su
    Ks[1, 1] = K[1, 1] / sv
    Ks[1, 2] = (K[1, 2] - ov) / sv
    return cols, rows, Ks


_NORMAL_COS = math.cos(math.radians(15.0))


def _consistent_normals(V: np.ndarray) -> np.ndarray:
    """Per-pixel normals of a vertex map (h, w, 3), facing the camera: the mean of the normals
    from forward and from backward differences, NaN where those disagree by more than 15 deg
    (creases, depth edges) or a neighbour is invalid. Crease pixels would bias point-to-plane
    odometry; the synthetic depth needs no smoothing."""
    h, w, _ = V.shape
    out = np.full((h, w, 3), np.nan, np.float32)
    if h < 3 or w < 3:
        return out
    X, Y, Z = (np.ascontiguousarray(V[..., k]) for k in range(3))

    def cross(a, b):
        return a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]

    c = [A[1:-1, 1:-1] for A in (X, Y, Z)]
    du_f = [A[1:-1, 2:] - cc for A, cc in zip((X, Y, Z), c)]
    du_b = [cc - A[1:-1, :-2] for A, cc in zip((X, Y, Z), c)]
    dv_f = [A[2:, 1:-1] - cc for A, cc in zip((X, Y, Z), c)]
    dv_b = [cc - A[:-2, 1:-1] for A, cc in zip((X, Y, Z), c)]
    nf = cross(du_f, dv_f)
    nb = cross(du_b, dv_b)
    with np.errstate(invalid="ignore", divide="ignore"):
        lf = 1.0 / np.sqrt(nf[0] ** 2 + nf[1] ** 2 + nf[2] ** 2)
        lb = 1.0 / np.sqrt(nb[0] ** 2 + nb[1] ** 2 + nb[2] ** 2)
        nf = [x * lf for x in nf]
        nb = [x * lb for x in nb]
        ok = (nf[0] * nb[0] + nf[1] * nb[1] + nf[2] * nb[2]) > _NORMAL_COS
        m = [x + y for x, y in zip(nf, nb)]
        lm = 1.0 / np.sqrt(m[0] ** 2 + m[1] ** 2 + m[2] ** 2)
        # face the camera (normal . point < 0)
        lm = np.where(m[0] * c[0] + m[1] * c[1] + m[2] * c[2] > 0, -lm, lm)
        lm[~ok] = np.nan
    for k in range(3):
        out[1:-1, 1:-1, k] = m[k] * lm
    return out


class Odometry:
    """Frame-to-frame odometry with gates.

    ``Odometry(K, width, height, config)``: ``K`` 3x3 intrinsics of the full-size (``width`` x
    ``height``) images that ``step`` will get.

    ``step(depth, rgb=None) -> OdometryStep`` estimates the motion of this frame relative to the
    previous frame given to ``step`` (``T_prev_cur``), seeded with the previous ok step's motion
    (constant velocity). The current frame then becomes the reference for the next call, whether
    the step was ok or not (a failed step means a new clip starts at this frame); a frame without
    usable depth leaves no reference, and the next frame's step is not ok ("no previous frame").
    Never raises for bad depth (zeros, NaN, inf): the step is not ok and ``reason`` says why.

    ``reset()`` forgets the reference frame and the velocity.

    Lower level, for :class:`OdometryChain` and :func:`relative_motion`: ``prepare(depth, rgb)``
    -> :class:`PreparedFrame` and ``solve(cur, ref, prior) -> OdometryStep``.
    """

    def __init__(self, K, width: int, height: int, config: OdometryConfig | None = None):
        self.config = config or OdometryConfig()
        if self.config.method not in ("point_to_plane", "hybrid"):
            raise ValueError(f"odometry method {self.config.method!r}: expected point_to_plane or hybrid")
        if not self.config.iterations:
            raise ValueError("odometry iterations: at least one pyramid level")
        self.K = np.asarray(K, dtype=np.float64)
        self.width, self.height = int(width), int(height)
        self._cols, self._rows, self.K_small = scaled_intrinsics(self.K, self.width, self.height, self.config.width)
        self.small_size = (len(self._cols), len(self._rows))
        self._ref: PreparedFrame | None = None
        self._velocity: np.ndarray | None = None

    # -- public --------------------------------------------------------------------------------

    def reset(self) -> None:
        self._ref = None
        self._velocity = None

    def step(self, depth, rgb=None) -> OdometryStep:
        cur = self.prepare(depth, rgb)
        ref, self._ref = self._ref, (cur if cur.usable else None)
        if not cur.usable:
            self._velocity = None
            return self._unusable(cur)
        if ref is None:
            self._velocity = None
            return OdometryStep(np.eye(4), False, reason="no previous frame")
        s = self.solve(cur, ref, self._velocity)
        self._velocity = s.T_prev_cur if s.ok else None
        return s

    # -- lower level ---------------------------------------------------------------------------

    def _unusable(self, f: PreparedFrame) -> OdometryStep:
        return OdometryStep(np.eye(4), False, reason=self.unusable_reason(f))

    def unusable_reason(self, f: PreparedFrame) -> str:
        if f.valid_fraction <= 0.0:
            return "no valid depth"
        return f"valid depth {f.valid_fraction:.1%} < {self.config.min_valid_depth_fraction:.1%}"

    def prepare(self, depth, rgb=None) -> PreparedFrame:
        """Subsample, clean (NaN/inf/<=0/beyond depth_max_m -> invalid) and build the pyramids."""
        cfg = self.config
        d = np.asarray(depth)
        if d.ndim != 2 or d.shape != (self.height, self.width):
            raise ValueError(f"depth has shape {d.shape}, expected ({self.height}, {self.width})")
        d = d[np.ix_(self._rows, self._cols)].astype(np.float32)
        with np.errstate(invalid="ignore"):
            bad = ~np.isfinite(d) | (d <= 0) | (d > cfg.depth_max_m)
        d[bad] = np.nan
        frac = 1.0 - float(bad.mean())
        f = PreparedFrame(depth=d, valid_fraction=frac)
        if frac < max(cfg.min_valid_depth_fraction, 1e-9):
            return f
        if rgb is not None and cfg.method == "hybrid":
            c = np.asarray(rgb)[np.ix_(self._rows, self._cols)].astype(np.float32)
            if c.ndim == 3 and c.shape[2] >= 3:
                c = c[..., :3]
                if np.issubdtype(np.asarray(rgb).dtype, np.integer):
                    c = c / 255.0
                f.rgb = np.ascontiguousarray(np.nan_to_num(np.clip(c, 0.0, 1.0), nan=0.0))
        self._pyramid(f)
        return f

    def _pyramid(self, f: PreparedFrame) -> None:
        o3d, o3c, _ = _o3d()
        K = self.K_small.copy()
        d = f.depth
        for level in range(len(self.config.iterations)):
            if level:
                d = np.ascontiguousarray(d[::2, ::2])  # source pixel 2u' -> K / 2 exactly
                K = K.copy()
                K[:2, :] /= 2.0
            Kt = o3c.Tensor(K)
            img = o3d.t.geometry.Image(o3c.Tensor(np.ascontiguousarray(d)))
            v = img.create_vertex_map(Kt, float("nan"))
            n = o3c.Tensor(_consistent_normals(v.as_tensor().numpy()))
            f.vertex.append(v.as_tensor())
            f.normal.append(n)
            f.K.append(Kt)
            if level == 0:
                f.K_np = K
                f.vertex_np = f.vertex[0].numpy().reshape(-1, 3)
                f.normal_np = f.normal[0].numpy().reshape(-1, 3)
                f.points = f.vertex_np[np.isfinite(f.vertex_np[:, 2])]

    def solve(self, cur: PreparedFrame, ref: PreparedFrame, prior: np.ndarray | None = None) -> OdometryStep:
        """Motion of ``cur`` in ``ref``'s camera frame, seeded with ``prior`` (default identity), gated."""
        if not cur.usable:
            return self._unusable(cur)
        if not ref.usable:
            return OdometryStep(np.eye(4), False, reason="reference frame: " + self.unusable_reason(ref))
        prior = np.eye(4) if prior is None else np.asarray(prior, dtype=np.float64)
        with _one_thread():
            if self.config.method == "hybrid" and cur.rgb is not None and ref.rgb is not None:
                # texture may fix what the geometry does not: no degeneracy remapping
                return self._verify(cur, ref, self._solve_hybrid(cur, ref, prior), prior, remap=False)
            return self._verify(cur, ref, self._solve_point_to_plane(cur, ref, prior), prior)

    def _solve_point_to_plane(self, cur: PreparedFrame, ref: PreparedFrame, T: np.ndarray) -> np.ndarray:
        _, o3c, od = _o3d()
        cfg = self.config
        T = T.copy()
        n_levels = len(cfg.iterations)
        for k, iters in enumerate(cfg.iterations):  # coarse to fine
            level = n_levels - 1 - k
            for _ in range(int(iters)):
                try:
                    r = od.compute_odometry_result_point_to_plane(
                        cur.vertex[level], ref.vertex[level], ref.normal[level], ref.K[level], o3c.Tensor(T),
                        cfg.depth_diff_max_m, cfg.depth_huber_delta_m)
                except RuntimeError:  # singular system: no overlap or fully degenerate geometry
                    break
                D = r.transformation.numpy()
                if (not np.isfinite(D).all() or np.linalg.norm(D[:3, 3]) > _MAX_UPDATE_TRANSLATION_M
                        or rotation_deg(D) > _MAX_UPDATE_ROTATION_DEG):
                    break  # diverging (ill-conditioned system): keep the last estimate
                T = D @ T
                if (np.linalg.norm(D[:3, 3]) < _CONVERGED_TRANSLATION_M
                        and rotation_deg(D) < math.degrees(_CONVERGED_ROTATION_RAD)):
                    break
        return T

    def _solve_hybrid(self, cur: PreparedFrame, ref: PreparedFrame, T: np.ndarray) -> np.ndarray:
        o3d, o3c, od = _o3d()
        cfg = self.config

        def rgbd(f):
            d = np.nan_to_num(f.depth, nan=0.0)
            return o3d.t.geometry.RGBDImage(o3d.t.geometry.Image(o3c.Tensor(f.rgb)),
                                            o3d.t.geometry.Image(o3c.Tensor(np.ascontiguousarray(d))))

        try:
            r = od.rgbd_odometry_multi_scale(
                rgbd(cur), rgbd(ref), o3c.Tensor(cur.K_np), o3c.Tensor(T), 1.0, cfg.depth_max_m,
                [od.OdometryConvergenceCriteria(int(i)) for i in cfg.iterations], od.Method.Hybrid,
                od.OdometryLossParams(cfg.depth_diff_max_m, cfg.depth_huber_delta_m, 0.1))
            out = r.transformation.numpy()
            return out if np.isfinite(out).all() else T
        except RuntimeError:
            return T

    def _associate(self, cur: PreparedFrame, ref: PreparedFrame, T: np.ndarray):
        """Projective association of cur's valid pixels into ref at pose T.

        Returns (n_valid, n_inliers, Q, N, r): cur's valid pixel count; how many land on ref's
        surface (depth within ``depth_diff_max_m``, and plane distance too where ref has a
        normal); and for the inliers with a normal their points in ref's frame, ref's normals and
        the point-to-plane residuals.
        """
        cfg = self.config
        P = cur.points
        n_valid = len(P)
        Q = P @ T[:3, :3].T.astype(np.float32) + T[:3, 3].astype(np.float32)
        K = ref.K_np
        h, w = ref.depth.shape
        z = Q[:, 2]
        with np.errstate(divide="ignore", invalid="ignore"):
            iz = 1.0 / z
            u = (K[0, 0] * iz) * Q[:, 0] + K[0, 2]
            v = (K[1, 1] * iz) * Q[:, 1] + K[1, 2]
            inside = (z > 1e-6) & (u > -0.5) & (u < w - 0.5) & (v > -0.5) & (v < h - 0.5)
        Q = Q[inside]
        lin = (v[inside] + 0.5).astype(np.int64) * w + (u[inside] + 0.5).astype(np.int64)
        tv = ref.vertex_np[lin]
        tn = ref.normal_np[lin]
        d = Q - tv
        r = d[:, 0] * tn[:, 0] + d[:, 1] * tn[:, 1] + d[:, 2] * tn[:, 2]
        has_n = np.isfinite(r)
        with np.errstate(invalid="ignore"):
            close = np.abs(d[:, 2]) < cfg.depth_diff_max_m
            plane = np.abs(r) < cfg.depth_diff_max_m
        inl = close & (plane | ~has_n)
        use = inl & has_n
        return n_valid, int(inl.sum()), Q[use], tn[use], r[use]

    def _verify(self, cur: PreparedFrame, ref: PreparedFrame, T: np.ndarray, prior: np.ndarray,
                remap: bool = True) -> OdometryStep:
        cfg = self.config
        n_valid, n_inl, Q, N, r = self._associate(cur, ref, T)
        degenerate = 0
        if remap and len(r) >= 6 and cfg.min_information > 0:
            # point-to-plane information (left perturbation T <- exp(xi) T, xi = (t, w * L))
            L = max(float(np.median(Q[:, 2])), 0.1)
            J = np.concatenate([N, np.cross(Q, N) / L], axis=1)
            H = J.T @ J / len(J)
            evals, evecs = np.linalg.eigh(H)
            weak = evals < cfg.min_information
            degenerate = int(weak.sum())
            if degenerate:
                # replace the estimate by the prior along the weak directions
                D = T @ np.linalg.inv(prior)
                xi = np.concatenate([D[:3, 3], _log_so3(D[:3, :3]) * L])
                U = evecs[:, ~weak]
                xi = U @ (U.T @ xi)
                E = np.eye(4)
                E[:3, :3] = _exp_so3(xi[3:] / L)
                E[:3, 3] = xi[:3]
                T = E @ prior
                n_valid, n_inl, Q, N, r = self._associate(cur, ref, T)
        fitness = n_inl / n_valid if n_valid else 0.0
        rmse = float(np.sqrt(np.mean(r * r))) if len(r) else float("nan")
        tr, rot = float(np.linalg.norm(T[:3, 3])), rotation_deg(T)
        reason = ""
        if fitness < cfg.min_fitness:
            reason = f"fitness {fitness:.2f} < {cfg.min_fitness:g}"
        elif not rmse <= cfg.max_inlier_rmse_m:
            reason = f"inlier rmse {rmse:.3f} m > {cfg.max_inlier_rmse_m:g} m"
        elif tr > cfg.max_step_translation_m:
            reason = f"step {tr:.2f} m > {cfg.max_step_translation_m:g} m"
        elif rot > cfg.max_step_rotation_deg:
            reason = f"rotation {rot:.1f} deg > {cfg.max_step_rotation_deg:g} deg"
        return OdometryStep(T, not reason, fitness, rmse, reason, tr, rot, degenerate)


# ---------------------------------------------------------------------------------------------
# chain with stride


class OdometryChain:
    """Streaming within-clip poses with a frame stride.

    ``OdometryChain(K, width, height, config)``; then, per frame in stream order,
    ``add(frame_index, depth, rgb=None) -> list[ChainPose]``, and ``flush() -> list[ChainPose]``
    at the end of the stream (or whenever every frame given so far must have its pose).

    Odometry runs every ``config.stride`` frames (counted in ``add`` calls) from the last
    keyframe to the newest frame, seeded with the previous keyframe step's motion scaled to the
    frame-index gap; a clip's first step, which has no such prior, runs on the clip's second
    frame. The frames in between get poses interpolated between the two keyframes
    (SLERP rotation, linear translation, by frame index). Every frame given to ``add`` comes out
    exactly once, in the order given, at most ``stride - 1`` calls late.

    When a keyframe step fails a gate, the frames in between are tried one by one (stride 1)
    from the last keyframe: poses continue up to the last frame that passes, and the first frame
    that fails starts a new clip (status ``"break"``, ``V = I``, ``reason`` = the failed gate).
    A frame without usable depth (all zero / NaN, or less than ``min_valid_depth_fraction``)
    ends the clip (``"invalid"``, ``V`` None); the next usable frame starts a new one
    (``"start"``). ``clip`` numbers the clips from 0.
    """

    def __init__(self, K, width: int, height: int, config: OdometryConfig | None = None):
        self.odometry = Odometry(K, width, height, config)
        self.config = self.odometry.config
        self.stride = max(1, int(self.config.stride))
        self.reset()

    def reset(self) -> None:
        """End the current clip; pending frames are dropped (call flush() first to keep them)."""
        self._key: tuple[int, PreparedFrame] | None = None
        self._V_key = np.eye(4)
        self._pending: list[tuple[int, PreparedFrame]] = []
        self._velocity: tuple[np.ndarray, float] | None = None  # (T_prev_cur, frame-index gap)
        self._clip = getattr(self, "_clip", -1)
        self._next_reason = ""
        self.steps: list[OdometryStep] = []  # every solve since the last reset (for diagnostics)

    @property
    def clip(self) -> int:
        """Number of the current clip (-1 before the first)."""
        return self._clip

    def add(self, frame_index: int, depth, rgb=None) -> list[ChainPose]:
        frame_index = int(frame_index)
        f = self.odometry.prepare(depth, rgb)
        out: list[ChainPose] = []
        if not f.usable:
            out += self._resolve(final=True)
            reason = self.odometry.unusable_reason(f)
            out.append(ChainPose(frame_index, None, "invalid", -1, reason, False))
            self._end_clip(reason)
            return out
        if self._key is None:
            out.append(self._start(frame_index, f, "start"))
            return out
        self._pending.append((frame_index, f))
        out += self._resolve()
        return out

    def flush(self) -> list[ChainPose]:
        """Poses of all frames still pending (the clip continues if more frames follow)."""
        return self._resolve(final=True)

    # -- internals -----------------------------------------------------------------------------

    def _end_clip(self, reason: str) -> None:
        self._key = None
        self._velocity = None
        self._next_reason = reason

    def _start(self, index: int, f: PreparedFrame, status: str, reason: str | None = None) -> ChainPose:
        self._clip += 1
        self._key = (index, f)
        self._V_key = np.eye(4)
        self._velocity = None
        reason = self._next_reason if reason is None else reason
        self._next_reason = ""
        return ChainPose(index, np.eye(4), status, self._clip, reason, True)

    def _prior(self, gap: float) -> np.ndarray | None:
        if self._velocity is None:
            return None
        T, g = self._velocity
        return scale_motion(T, gap / g) if g > 0 else None

    def _solve(self, index: int, f: PreparedFrame) -> OdometryStep:
        ki, kf = self._key
        s = self.odometry.solve(f, kf, self._prior(index - ki))
        self.steps.append(s)
        return s

    def _advance(self, index: int, f: PreparedFrame, s: OdometryStep) -> np.ndarray:
        ki, _ = self._key
        V = self._V_key @ s.T_prev_cur
        self._velocity = (s.T_prev_cur, float(index - ki)) if index != ki else None
        self._key, self._V_key = (index, f), V
        return V

    def _resolve(self, final: bool = False) -> list[ChainPose]:
        """Poses for the pending frames: all of them if ``final``, else while a stride is full."""
        out: list[ChainPose] = []
        # without a motion prior (a clip's first step) the next frame is solved at once: cold
        # starts converge far more reliably over one frame of motion than over a stride
        while self._pending and (final or len(self._pending) >= self.stride or self._velocity is None):
            pending, self._pending = self._pending, []
            ki = self._key[0]
            V0 = self._V_key
            idx, f = pending[-1]
            s = self._solve(idx, f)
            if s.ok:
                V1 = self._advance(idx, f, s)
                span = float(idx - ki)
                for j, _ in pending[:-1]:
                    frac = (j - ki) / span if span else 0.0
                    out.append(ChainPose(j, interpolate_pose(V0, V1, frac), "ok", self._clip, "", False))
                out.append(ChainPose(idx, V1, "ok", self._clip, "", True))
                continue
            if len(pending) == 1:
                out.append(self._start(idx, f, "break", s.reason))
                continue
            # the keyframe step failed: walk the frames one by one to find where the clip ends
            for k, (j, g) in enumerate(pending):
                s1 = self._solve(j, g)
                if s1.ok:
                    out.append(ChainPose(j, self._advance(j, g, s1), "ok", self._clip, "", True))
                    continue
                out.append(self._start(j, g, "break", s1.reason))
                self._pending = pending[k + 1:]  # the rest continue the new clip
                break
        return out


# ---------------------------------------------------------------------------------------------
# one solve between two frames


def relative_motion(depth_a, depth_b, K, config: OdometryConfig | None = None, init=None,
                    rgb_a=None, rgb_b=None) -> OdometryStep:
    """Gated odometry between two arbitrary frames of one camera: the pose of camera ``b`` in
    camera ``a``'s frame (``T_prev_cur`` with a = previous, b = current), seeded with ``init``
    (4x4, default identity). Both depths have the same shape; ``K`` is their intrinsic matrix.

    Without ``init`` this is reliable for about one frame of motion (a capture gap or a larger
    baseline fails the gates or, with fast turns, may converge wrongly); pass a prediction, e.g.
    the chain's motion scaled to the gap (:func:`scale_motion`), for anything larger. Directions
    the geometry does not fix keep ``init``'s value."""
    depth_a = np.asarray(depth_a)
    depth_b = np.asarray(depth_b)
    if depth_a.shape != depth_b.shape or depth_a.ndim != 2:
        raise ValueError(f"depth shapes {depth_a.shape} and {depth_b.shape}: expected two equal (H, W)")
    h, w = depth_a.shape
    odo = Odometry(K, w, h, config)
    fa = odo.prepare(depth_a, rgb_a)
    fb = odo.prepare(depth_b, rgb_b)
    return odo.solve(fb, fa, init)
