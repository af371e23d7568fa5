"""FPFH-ICP: the dense geometric clip-rigid control (paper Table IV, dagger).

"FPFH-ICP registers each clip's fused depth to a 5 cm point-cloud map [of the mapping tour] with
FPFH descriptors, RANSAC and ICP, providing a dense geometric control without object semantics."
Clip-rigid protocol: VideoReloc's clip partition and within-clip odometry (``clip_poses.npz`` of a
``reloc run``), one independent registration per clip at its closure, no cross-clip back-end.

* ``PointMap.build``: depth of every ``map_stride``-th mapping frame, placed with the mapping tour's
  ground-truth poses, fused, voxel-downsampled (5 cm), normals (oriented towards the cameras that
  saw each voxel), FPFH at the keypoints (the non-flat points). ``save``/``load``: one ``.npz``
  (float32 points, normals, keypoint FPFH features); its size in bytes is the map size the
  experiment reports.
* ``register_clip``: the clip's depth frames (every ``clip_stride``-th and the last, VideoReloc's
  observation cadence) fused with the odometry poses V_i into the clip frame, downsampled, FPFH
  at its keypoints, mutual nearest neighbours in FPFH space (exact search) that pass a ratio
  test, RANSAC on those matches (``ransac``: Open3D's sampler and edge-length / distance checks,
  vectorised, with the textbook stopping rule on the match inlier ratio; Open3D's own
  ``registration_ransac_based_on_feature_matching`` takes minutes per clip on a 175k-point
  apartment map and stops early on wrong partial overlaps), point-to-plane ICP, then an
  acceptance test (point count, geometric degeneracy before and after registration, ICP fitness
  and inlier RMSE). It returns the clip-to-map S (``T_i = S V_i``) or None with a reason.
* ``run_fpfh_icp``: every clip of a run; writes ``closure.txt``, ``clips.json`` and ``run.json``.

Command line (for experiments): ``python -m reloc.baselines.fpfh_icp map --tour MAPPING_TOUR --out map.npz``
and ``python -m reloc.baselines.fpfh_icp run --map map.npz --tour QUERY_TOUR --clips VIDEORELOC_RUN --out DIR``.
"""

from __future__ import annotations

import json
import math
import sys
import time
import zipfile
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np
from scipy.spatial import cKDTree

from vrformats.atomic import save_npz_atomic, write_json_atomic
from vrformats.camera import write_tum
from vrformats.errors import UserError
from vrformats.fields import is_number
from vrformats.native import import_open3d

o3d = import_open3d()  # a missing libGL is one line naming its package





FORMAT = "videoreloc-fpfh-map/1"
reg = o3d.pipelines.registration


@dataclass
class FpfhConfig:
    """FPFH-ICP settings. Only the 5 cm voxel is the paper's; every other value is ours."""

    # -- the point clouds ------------------------------------------------------------------------
    voxel: float = 0.05  # PAPER: 5 cm voxel grid for the map and the clip clouds
    map_stride: int = 10  # ours: every 10th mapping frame is fused into the map (3 frames/s at 30 fps)
    clip_stride: int = 5  # ours, = VideoReloc's observation cadence: every 5th clip frame, plus the last
    min_depth: float = 0.1  # ours: depth below this (m) is ignored
    max_depth: float = 6.0  # ours: depth beyond this (m) is ignored (sparse, grazing far surfaces)
    # -- normals, keypoints, descriptors (radii in voxels) ------------------------------------------
    normal_radius: float = 2.0  # ours (Open3D's usual choice): normals from neighbours within 2 voxels ...
    normal_max_nn: int = 30  # ... at most 30 of them
    keypoint_variation: float = 0.01  # ours: points whose neighbourhood (normal radius) has surface variation
    #                                   l0 / (l0 + l1 + l2) above this are matched by their FPFH; flat points
    #                                   (about 3/4 of an apartment) all share one histogram, so their matches
    #                                   are arbitrary; they still count in ICP and in the acceptance test
    max_keypoints: int = 5000  # ours: at most this many clip keypoints are matched (seeded random subset)
    fpfh_radius: float = 5.0  # ours (Open3D's usual choice): FPFH histograms over 5 voxels ...
    fpfh_max_nn: int = 100  # ... at most 100 neighbours
    # -- global registration: RANSAC on FPFH matches ----------------------------------------------
    mutual_filter: bool = True  # ours: keep only mutual nearest neighbours in feature space (exact search)
    ratio_test: float = 0.9  # ours: and only matches whose nearest map feature is clearly nearer than the
    #                          second (Lowe's ratio of distances < 0.9; 1 = off); a 5 cm apartment has
    #                          1-3 % correct matches, this raises that by about half
    min_matches: int = 10  # ours: fewer matches -> not registered
    ransac_distance: float = 1.5  # ours (Open3D's usual choice): inlier distance 1.5 voxels
    ransac_n: int = 3  # minimal sample of a rigid transform
    edge_length_ratio: float = 0.9  # ours (Open3D's usual choice): prune samples whose edge lengths differ > 10 %
    ransac_max_iterations: int = 1_000_000  # ours: upper bound on RANSAC iterations, drawn in chunks ...
    ransac_chunk: int = 20_000  # ... of this many; after each chunk ...
    ransac_confidence: float = 0.999  # ... stop when the best hypothesis' match inlier ratio w says a correct
    #                                   sample was drawn with this probability: 1 - (1 - w^3)^iterations
    ransac_candidates: int = 5  # ours: the best distinct hypotheses, ranked by point overlap with the map
    seed: int = 0  # RANSAC's random generator (numpy), so runs are reproducible
    # -- refinement: point-to-plane ICP, coarse to fine (max correspondence distance, voxels) --------
    icp_distances: tuple[float, ...] = (2.0, 1.0)  # ours: 10 cm, then 5 cm
    icp_max_iterations: int = 30  # ours: per stage
    # -- acceptance --------------------------------------------------------------------------------
    min_points: int = 500  # ours: a clip cloud with fewer voxels is not registered ("too few points")
    min_constraint: float = 0.02  # ours: smallest eigenvalue of the normalised point-to-plane information
    #                               matrix (``constraint``), on the clip cloud and on the ICP inliers; a
    #                               plane, or a floor with one wall, leaves a direction free and scores ~0
    min_fitness: float = 0.7  # ours: at least 70 % of the clip's voxels within 1 voxel of the map after ICP
    max_rmse: float = 0.03  # ours: inlier RMSE (point-to-point, m) of the final ICP stage at most 3 cm

    def to_dict(self) -> dict:
        d = asdict(self)
        d["icp_distances"] = list(self.icp_distances)
        return d


# ---------------------------------------------------------------------------------------------
# fusing depth


def _back_project(depth: np.ndarray, K: np.ndarray, cfg: FpfhConfig) -> np.ndarray:
    """Camera-frame points (N, 3) of the valid pixels of a planar depth image."""
    d = np.asarray(depth, dtype=np.float64)
    ok = np.isfinite(d) & (d >= cfg.min_depth) & (d <= cfg.max_depth)
    v, u = np.nonzero(ok)
    z = d[v, u]
    return np.stack([(u - K[0, 2]) / K[0, 0] * z, (v - K[1, 2]) / K[1, 1] * z, z], axis=1)


class _Fuser:
    """Accumulates posed depth frames into one point per occupied voxel of a fixed world grid.

    A voxel's point is the mean of every depth point that fell in it (cells ``round(p / voxel)``,
    the same grid for every batch and frame; cells are centred on multiples of the voxel, so the
    scenes' walls and floors at round coordinates lie mid-cell instead of being split in two).
    Each voxel also keeps the sum of its points' viewing directions (point -> camera centre); the
    surface normals estimated later are flipped to agree with it, so map and clip normals point
    into the free space the cameras saw (FPFH depends on the sign).
    """

    _BITS = 21  # per axis: +-2^20 voxels (52 km at 5 cm), packed into one int64 key

    def __init__(self, voxel: float, batch: int = 500_000, merge_rows: int = 4_000_000):
        self.voxel = voxel
        self.batch = batch  # raw points reduced at a time ...
        self.merge_rows = merge_rows  # ... and reduced batches merged when they hold this many rows
        self.parts: list[tuple[np.ndarray, np.ndarray]] = []  # (keys, sums: x, y, z, view x, y, z, count)
        self.n_rows = 0
        self.pending: list[np.ndarray] = []
        self.n_pending = 0
        self.frames = 0

    def add(self, pts_cam: np.ndarray, T: np.ndarray) -> None:
        if not len(pts_cam):
            return
        p = pts_cam @ T[:3, :3].T + T[:3, 3]
        view = T[:3, 3] - p
        view /= np.maximum(np.linalg.norm(view, axis=1, keepdims=True), 1e-9)
        self.pending.append(np.concatenate([p, view, np.ones((len(p), 1))], axis=1))
        self.n_pending += len(p)
        self.frames += 1
        if self.n_pending >= self.batch:
            self._flush()

    def _key(self, p: np.ndarray) -> np.ndarray:
        half = 1 << (self._BITS - 1)
        c = np.clip(np.floor(p / self.voxel + 0.5).astype(np.int64), -half, half - 1) + half
        return (c[:, 0] << (2 * self._BITS)) | (c[:, 1] << self._BITS) | c[:, 2]

    @staticmethod
    def _reduce(keys: np.ndarray, vals: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        uniq, inv = np.unique(keys, return_inverse=True)
        sums = np.stack([np.bincount(inv, weights=vals[:, k], minlength=len(uniq)) for k in range(vals.shape[1])], 1)
        return uniq, sums

    def _merge(self) -> None:
        if len(self.parts) > 1:
            self.parts = [self._reduce(np.concatenate([k for k, _ in self.parts]),
                                       np.concatenate([v for _, v in self.parts]))]
            self.n_rows = len(self.parts[0][0])

    def _flush(self) -> None:
        if not self.pending:
            return
        new = np.concatenate(self.pending)
        self.pending, self.n_pending = [], 0
        part = self._reduce(self._key(new[:, :3]), new)
        self.parts.append(part)
        self.n_rows += len(part[0])
        if self.n_rows >= self.merge_rows:
            self._merge()

    def cloud(self) -> o3d.geometry.PointCloud:
        self._flush()
        self._merge()
        pc = o3d.geometry.PointCloud()
        if self.parts:
            sums = self.parts[0][1]
            pc.points = o3d.utility.Vector3dVector(sums[:, :3] / sums[:, 6:7])
            pc.normals = o3d.utility.Vector3dVector(sums[:, 3:6])
        return pc


def _describe(pc: o3d.geometry.PointCloud, cfg: FpfhConfig) -> tuple[np.ndarray, np.ndarray]:
    """Normals (in place), keypoints and their FPFH features: (indices (K,), features (K, 33) float32).

    Normals come from the neighbourhood covariances within ``normal_radius`` and are flipped to
    agree with the stored viewing directions. Keypoints are the points whose neighbourhood is not
    flat (surface variation above ``keypoint_variation``): on a plane every FPFH histogram is the
    same, so a flat point's match is arbitrary; they still take part in ICP and in the acceptance.
    FPFH (``fpfh_radius``) is computed at the keypoints only, from all points' neighbourhoods.
    """
    n = len(pc.points)
    view = np.asarray(pc.normals).copy() if pc.has_normals() else None
    nparam = o3d.geometry.KDTreeSearchParamHybrid(radius=cfg.normal_radius * cfg.voxel, max_nn=cfg.normal_max_nn)
    pc.estimate_covariances(nparam)
    ev = np.linalg.eigvalsh(np.asarray(pc.covariances))
    variation = ev[:, 0] / np.maximum(ev.sum(axis=1), 1e-12)
    pc.estimate_normals(nparam)  # reuses the covariances
    if view is not None and len(view) == n:
        nrm = np.asarray(pc.normals)
        flip = np.einsum("ij,ij->i", nrm, view) < 0
        nrm[flip] *= -1.0
        pc.normals = o3d.utility.Vector3dVector(nrm)
    keys = np.nonzero(variation > cfg.keypoint_variation)[0].astype(np.int64)
    if not len(keys):
        return keys, np.zeros((0, 33), np.float32)
    fparam = o3d.geometry.KDTreeSearchParamHybrid(radius=cfg.fpfh_radius * cfg.voxel, max_nn=cfg.fpfh_max_nn)
    feat = reg.compute_fpfh_feature(pc, fparam, o3d.utility.IntVector(keys.tolist()))
    return keys, np.ascontiguousarray(np.asarray(feat.data).T, np.float32)


def constraint(points: np.ndarray, normals: np.ndarray) -> float:
    """How well point-to-plane alignment pins down all six degrees of freedom (0 = degenerate).

    The smallest eigenvalue of ``J^T J / N`` with rows ``J_i = [((p_i - c) x n_i) / L, n_i]``
    (c: centroid, L: RMS distance to it, so rotations and translations are comparable). A single
    plane leaves three directions free, a floor with one wall still one (sliding along the wall);
    the apartments' clips score about 0.04-0.15.
    """
    if len(points) < 6:
        return 0.0
    c = points.mean(axis=0)
    q = points - c
    L = math.sqrt(float((q * q).sum(axis=1).mean())) or 1.0
    J = np.concatenate([np.cross(q, normals) / L, normals], axis=1)
    H = J.T @ J / len(J)
    return float(max(np.linalg.eigvalsh(H)[0], 0.0))


# ---------------------------------------------------------------------------------------------
# the map


@dataclass(eq=False, repr=False)
class PointMap:
    """The 5 cm point-cloud map of a mapping tour: points, oriented normals, keypoint FPFH features."""

    points: np.ndarray  # (N, 3) float32, world metres
    normals: np.ndarray  # (N, 3) float32, unit, pointing into the free space the cameras saw
    keypoints: np.ndarray  # (K,) int32: the non-flat points, matched by their features
    features: np.ndarray  # (K, 33) float32: FPFH of points[keypoints]
    voxel: float = 0.05
    meta: dict = field(default_factory=dict)
    source: str = "<memory>"

    def __len__(self) -> int:
        return len(self.points)

    def __repr__(self) -> str:
        return (f"PointMap({self.source!r}, {len(self)} points, {len(self.keypoints)} keypoints, "
                f"voxel {self.voxel:g} m)")

    @staticmethod
    def build(tour, cfg: FpfhConfig | None = None, progress: bool = False) -> "PointMap":
        """Fuse every ``map_stride``-th frame's depth with the tour's ground-truth poses."""
        cfg = cfg or FpfhConfig()
        t0 = time.perf_counter()
        idx = [int(i) for i in tour.frame_indices][::max(1, int(cfg.map_stride))]
        fuser = _Fuser(cfg.voxel)
        K = tour.K
        bar = None
        if progress:
            from tqdm import tqdm

            bar = tqdm(total=len(idx), desc="fpfh map", unit="frame", file=sys.stderr)
        for i in idx:
            f = tour.frame(i, rgb=False, depth=True, instance=False, semantic=False)
            if f.depth is not None:
                fuser.add(_back_project(f.depth, K, cfg), tour.pose(i))
            if bar is not None:
                bar.update(1)
        if bar is not None:
            bar.close()
        pc = fuser.cloud()
        if len(pc.points) < 1:
            raise UserError(f"{tour.root}: no usable depth in the mapping frames (stride {cfg.map_stride})")
        keys, feat = _describe(pc, cfg)
        meta = {"format": FORMAT, "tour": str(tour.root), "frames": len(idx), "frames_with_depth": fuser.frames,
                "config": cfg.to_dict(), "build_seconds": round(time.perf_counter() - t0, 2)}
        return PointMap(np.asarray(pc.points, np.float32), np.asarray(pc.normals, np.float32),
                        keys.astype(np.int32), feat, cfg.voxel, meta)

    # -- search structures (built on first use) ------------------------------------------------------

    def cloud(self) -> o3d.geometry.PointCloud:
        if getattr(self, "_pc", None) is None:
            pc = o3d.geometry.PointCloud()
            pc.points = o3d.utility.Vector3dVector(self.points.astype(np.float64))
            pc.normals = o3d.utility.Vector3dVector(self.normals.astype(np.float64))
            self._pc = pc
        return self._pc

    def point_tree(self) -> cKDTree:
        if getattr(self, "_ptree", None) is None:
            self._ptree = cKDTree(self.points.astype(np.float64))
        return self._ptree

    def feature_tree(self) -> cKDTree:
        if getattr(self, "_tree", None) is None:
            self._tree = cKDTree(self.features)
        return self._tree

    # -- files ---------------------------------------------------------------------------------------

    def save(self, path) -> Path:
        """One ``.npz`` file (uncompressed arrays + JSON metadata), written atomically."""
        path = Path(path)
        path.parent.mkdir(parents=True, exist_ok=True)
        meta = dict(self.meta, format=FORMAT, voxel=self.voxel)
        save_npz_atomic(path, compressed=False, points=self.points.astype(np.float32),
                        normals=self.normals.astype(np.float32), keypoints=self.keypoints.astype(np.int32),
                        features=self.features.astype(np.float32), meta=np.array(json.dumps(meta)))
        return path

    @staticmethod
    def load(path) -> "PointMap":
        """A saved map; a missing, corrupt or inconsistent file is a UserError naming it."""
        path = Path(path)
        if not path.is_file():
            raise UserError(f"{path}: point-cloud map not found (make one with 'python -m reloc.baselines.fpfh_icp map')")
        names = ("points", "normals", "keypoints", "features", "meta")
        try:
            with np.load(path, allow_pickle=False) as z:
                missing = [k for k in names if k not in z.files]
                if missing:
                    raise UserError(f"{path}: not an FPFH point-cloud map (missing {', '.join(missing)})")
                pts, nrm, keys, feat = (np.asarray(z[k]) for k in names[:4])
                meta = json.loads(str(z["meta"]))
        except UserError:
            raise
        except (OSError, ValueError, EOFError, zipfile.BadZipFile, KeyError) as e:
            raise UserError(f"{path}: corrupt or unreadable point-cloud map ({e or type(e).__name__})") from None
        if not isinstance(meta, dict) or meta.get("format") != FORMAT:
            got = meta.get("format") if isinstance(meta, dict) else meta
            raise UserError(f"{path}: format is {got!r}, expected {FORMAT!r}")
        n = len(pts)
        if (n == 0 or pts.shape != (n, 3) or nrm.shape != (n, 3) or keys.ndim != 1
                or feat.shape != (len(keys), 33) or not np.issubdtype(keys.dtype, np.integer)):
            raise UserError(f"{path}: inconsistent arrays (points {pts.shape}, normals {nrm.shape}, "
                            f"keypoints {keys.shape}, features {feat.shape})")
        if len(keys) and (keys.min() < 0 or keys.max() >= n):
            raise UserError(f"{path}: keypoint index out of range")
        if not (np.isfinite(pts).all() and np.isfinite(nrm).all() and np.isfinite(feat).all()):
            raise UserError(f"{path}: non-finite values in the map")
        voxel = meta.get("voxel")
        if not is_number(voxel) or not voxel > 0:
            raise UserError(f"{path}: meta.voxel: expected a positive number, got {voxel!r}")
        return PointMap(pts.astype(np.float32), nrm.astype(np.float32), keys.astype(np.int32),
                        feat.astype(np.float32), float(voxel), meta, str(path))


# ---------------------------------------------------------------------------------------------
# registering one clip


def clip_frames(frames, stride: int) -> list[int]:
    """VideoReloc's observation cadence: every ``stride``-th frame of the clip, plus its last."""
    fr = sorted(int(i) for i in frames)
    if not fr:
        return []
    out = fr[::max(1, int(stride))]
    if out[-1] != fr[-1]:
        out.append(fr[-1])
    return out


def clip_cloud(tour, V: dict, cfg: FpfhConfig) -> o3d.geometry.PointCloud:
    """The clip's depth frames fused in the clip frame with the odometry poses V_i (downsampled)."""
    fuser = _Fuser(cfg.voxel)
    K = tour.K
    for i in clip_frames(V, cfg.clip_stride):
        f = tour.frame(i, rgb=False, depth=True, instance=False, semantic=False)
        if f.depth is None:
            continue
        fuser.add(_back_project(f.depth, K, cfg), np.asarray(V[i], dtype=np.float64))
    return fuser.cloud()


def match_features(src_feat: np.ndarray, pmap: PointMap, mutual: bool = True,
                   ratio: float = 1.0) -> tuple[np.ndarray, np.ndarray]:
    """(source rows, map keypoint rows): nearest neighbours in FPFH space (exact search), optionally
    mutual, optionally passing the ratio test (nearest / second nearest map distance < ``ratio``)."""
    if not len(src_feat) or not len(pmap.features):
        return np.zeros(0, np.int64), np.zeros(0, np.int64)
    use_ratio = ratio < 1.0 and len(pmap.features) >= 2
    d, j = pmap.feature_tree().query(src_feat, k=2 if use_ratio else 1, workers=-1)
    keep = np.ones(len(src_feat), bool)
    if use_ratio:
        keep = d[:, 0] < ratio * d[:, 1]
        j = j[:, 0]
    i = np.arange(len(src_feat))
    if mutual:
        _, back = cKDTree(src_feat).query(pmap.features[j], k=1, workers=-1)
        keep &= back == i
    return i[keep], np.asarray(j[keep], np.int64)


def _kabsch(P: np.ndarray, Q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Batched least-squares rigid fits: (..., n, 3) point sets -> R (..., 3, 3), t (..., 3), Q ~ R P + t."""
    cp, cq = P.mean(axis=-2), Q.mean(axis=-2)
    H = np.einsum("...ni,...nj->...ij", P - cp[..., None, :], Q - cq[..., None, :])
    U, _, Vt = np.linalg.svd(H)
    d = np.sign(np.linalg.det(np.einsum("...ji,...kj->...ik", Vt, U)))
    D = np.zeros(H.shape)
    D[..., 0, 0] = 1.0
    D[..., 1, 1] = 1.0
    D[..., 2, 2] = np.where(d == 0, 1.0, d)
    R = np.einsum("...ji,...jk,...lk->...il", Vt, D, U)
    return R, cq - np.einsum("...ij,...j->...i", R, cp)


def ransac(P: np.ndarray, Q: np.ndarray, cfg: FpfhConfig, score=None) -> tuple[np.ndarray | None, dict]:
    """RANSAC over matched points Q_k ~ S P_k: the best clip-to-map S (4x4) or None, and statistics.

    Open3D's sampler and checkers (``registration_ransac_based_on_correspondence``), vectorised
    with a seeded numpy generator: 3 random matches, the edge-length check (every pairwise
    distance agrees within ``edge_length_ratio``), a rigid fit, the distance check (all three
    within ``ransac_distance``). Hypotheses are scored by their inlier matches and the run stops
    when the best inlier ratio w gives ``1 - (1 - w^3)^iterations >= ransac_confidence``, or at
    ``ransac_max_iterations``. (Open3D's own stop uses the point overlap as w, which ends a run
    after about a hundred iterations at a wrong partial overlap; its full-cloud scoring of every
    hypothesis is also what makes it slow here.) The ``ransac_candidates`` best distinct
    hypotheses, refitted to their inliers, are then ranked by ``score(S)`` (the point overlap
    with the map, as Open3D ranks) when given, else by inlier count.
    """
    m = len(P)
    dist = cfg.ransac_distance * cfg.voxel
    stats = {"iterations": 0, "inlier_matches": 0}
    if m < cfg.ransac_n:
        return None, stats
    rng = np.random.default_rng(cfg.seed)
    ratio = cfg.edge_length_ratio
    pairs = [(a, b) for a in range(cfg.ransac_n) for b in range(a + 1, cfg.ransac_n)]
    best: list[tuple[int, int, np.ndarray, np.ndarray]] = []  # (inliers, order, R, t)
    top = 0
    it = 0
    while it < cfg.ransac_max_iterations:
        n = min(max(1, cfg.ransac_chunk), cfg.ransac_max_iterations - it)
        idx = rng.integers(0, m, size=(n, cfg.ransac_n))
        it += n
        ok = np.ones(n, bool)
        for a, b in pairs:
            ok &= idx[:, a] != idx[:, b]
            ls = np.linalg.norm(P[idx[:, a]] - P[idx[:, b]], axis=1)
            lt = np.linalg.norm(Q[idx[:, a]] - Q[idx[:, b]], axis=1)
            ok &= (ls > ratio * lt) & (lt > ratio * ls)
        idx = idx[ok]
        if len(idx):
            R, t = _kabsch(P[idx], Q[idx])
            r = np.einsum("nij,nkj->nki", R, P[idx]) + t[:, None, :] - Q[idx]
            ok = (np.linalg.norm(r, axis=2) < dist).all(axis=1)
            R, t = R[ok], t[ok]
            if len(R):
                res = np.einsum("nij,kj->nki", R, P) + t[:, None, :] - Q[None]
                cnt = (np.einsum("nki,nki->nk", res, res) < dist * dist).sum(axis=1)
                for k in np.argsort(-cnt, kind="stable")[:2 * max(1, cfg.ransac_candidates)]:
                    best.append((int(cnt[k]), len(best), R[k], t[k]))
                best.sort(key=lambda x: (-x[0], x[1]))
                del best[4 * max(1, cfg.ransac_candidates):]
                top = best[0][0]
        w = top / m
        if w > 0 and (1.0 - w ** cfg.ransac_n) ** it <= 1.0 - cfg.ransac_confidence:
            break
    stats["iterations"] = it
    stats["inlier_matches"] = top
    if not best:
        return None, stats
    # distinct candidates, each refitted to its inlier matches
    cands: list[np.ndarray] = []
    for _, _, R, t in best:
        S = np.eye(4)
        S[:3, :3], S[:3, 3] = R, t
        inl = np.linalg.norm(P @ R.T + t - Q, axis=1) < dist
        if inl.sum() >= cfg.ransac_n:
            R2, t2 = _kabsch(P[inl], Q[inl])
            S[:3, :3], S[:3, 3] = R2, t2
        if all(np.linalg.norm(S[:3, 3] - C[:3, 3]) > 2 * dist or _angle(S[:3, :3], C[:3, :3]) > 0.1
               for C in cands):
            cands.append(S)
        if len(cands) >= max(1, cfg.ransac_candidates):
            break
    if score is None or len(cands) == 1:
        return cands[0], stats
    scores = [score(S) for S in cands]
    stats["candidate_scores"] = [round(float(x), 4) for x in scores]
    return cands[int(np.argmax(scores))], stats


def _angle(Ra: np.ndarray, Rb: np.ndarray) -> float:
    return float(np.arccos(np.clip((np.trace(Ra.T @ Rb) - 1.0) / 2.0, -1.0, 1.0)))


def register_clip(pmap: PointMap, tour, V: dict, cfg: FpfhConfig | None = None):
    """Clip-to-map S of one clip (``T_i = S V_i``), or None; and an info dict.

    info: ``fitness`` and ``rmse`` (final ICP stage), ``points`` (clip voxels), ``keypoints``,
    ``matches`` (mutual FPFH matches), ``constraint`` (before registration, on the clip cloud;
    ``inlier_constraint`` after, on the ICP inliers), ``ransac_fitness`` (point overlap of the
    RANSAC pose), ``ransac_iterations``, ``ransac_inliers`` (matches), ``reason`` (None when
    registered), ``seconds`` and per-stage ``timings``.
    """
    cfg = cfg or FpfhConfig()
    t0 = time.perf_counter()
    info: dict = {"frames": len(V), "fitness": 0.0, "rmse": None, "points": 0, "reason": None, "timings": {}}
    last = [t0]

    def lap(stage):
        now = time.perf_counter()
        info["timings"][stage] = round(now - last[0], 3)
        last[0] = now

    def done(S, reason=None):
        info["reason"] = reason
        info["seconds"] = round(time.perf_counter() - t0, 3)
        return S, info

    if abs(cfg.voxel - pmap.voxel) > 1e-9:
        return done(None, f"map voxel {pmap.voxel:g} m differs from the configured {cfg.voxel:g} m")
    if not V:
        return done(None, "empty clip")
    src = clip_cloud(tour, V, cfg)
    info["points"] = n = len(src.points)
    lap("cloud")
    if n < cfg.min_points:
        return done(None, f"too few points ({n} voxels < {cfg.min_points})")
    keys, feat = _describe(src, cfg)
    pts, nrm = np.asarray(src.points), np.asarray(src.normals)
    lap("features")
    info["constraint"] = round(constraint(pts, nrm), 4)
    if info["constraint"] < cfg.min_constraint:
        return done(None, f"degenerate geometry (constraint {info['constraint']:.3f} < {cfg.min_constraint})")
    if len(keys) > cfg.max_keypoints > 0:  # a seeded random subset
        pick = np.sort(np.random.default_rng(cfg.seed).choice(len(keys), cfg.max_keypoints, replace=False))
        keys, feat = keys[pick], feat[pick]
    info["keypoints"] = len(keys)
    si, mj = match_features(feat, pmap, cfg.mutual_filter, cfg.ratio_test)
    info["matches"] = len(si)
    lap("match")
    if len(si) < max(cfg.ransac_n, cfg.min_matches):
        return done(None, f"too few feature matches ({len(si)} < {max(cfg.ransac_n, cfg.min_matches)})")

    # global: RANSAC on the feature matches, candidates ranked by their point overlap with the map
    dist = cfg.ransac_distance * cfg.voxel

    def overlap(S):
        d, _ = pmap.point_tree().query(pts @ S[:3, :3].T + S[:3, 3], k=1, distance_upper_bound=dist, workers=-1)
        return float(np.isfinite(d).mean())

    T, rs = ransac(pts[keys[si]], pmap.points[pmap.keypoints[mj]].astype(np.float64), cfg, score=overlap)
    info["ransac_iterations"] = rs["iterations"]
    info["ransac_inliers"] = rs["inlier_matches"]
    if T is None:
        return done(None, "RANSAC found no consistent set of feature matches")
    info["ransac_fitness"] = round(overlap(T), 4)
    lap("ransac")

    # local: point-to-plane ICP, coarse to fine, against the map around the placed clip
    margin = 2.0 * max(cfg.icp_distances) * cfg.voxel
    placed = pts @ T[:3, :3].T + T[:3, 3]
    near = np.nonzero(((pmap.points >= placed.min(axis=0) - margin - 0.5)
                       & (pmap.points <= placed.max(axis=0) + margin + 0.5)).all(axis=1))[0]
    if len(near) < cfg.min_points * cfg.min_fitness:
        return done(None, "the RANSAC pose puts the clip outside the map")
    tgt = pmap.cloud().select_by_index(near.tolist())
    icp = None
    for k in cfg.icp_distances:
        icp = reg.registration_icp(src, tgt, k * cfg.voxel, T, reg.TransformationEstimationPointToPlane(),
                                   reg.ICPConvergenceCriteria(max_iteration=cfg.icp_max_iterations))
        T = np.asarray(icp.transformation).copy()
    info["fitness"] = round(float(icp.fitness), 4)
    info["rmse"] = round(float(icp.inlier_rmse), 4)
    inl = np.asarray(icp.correspondence_set)
    if len(inl):
        p = pts[inl[:, 0]] @ T[:3, :3].T + T[:3, 3]
        info["inlier_constraint"] = round(constraint(p, np.asarray(tgt.normals)[inl[:, 1]]), 4)
    else:
        info["inlier_constraint"] = 0.0
    lap("icp")
    if icp.fitness < cfg.min_fitness:
        return done(None, f"low ICP fitness ({icp.fitness:.2f} < {cfg.min_fitness})")
    if icp.inlier_rmse > cfg.max_rmse:
        return done(None, f"high ICP inlier RMSE ({icp.inlier_rmse * 100:.1f} cm > {cfg.max_rmse * 100:.1f} cm)")
    if info["inlier_constraint"] < cfg.min_constraint:
        return done(None, f"degenerate overlap with the map (constraint {info['inlier_constraint']:.3f} "
                          f"< {cfg.min_constraint})")
    return done(T)


# ---------------------------------------------------------------------------------------------
# a whole run


def run_fpfh_icp(tour, pmap: PointMap, clip_poses: dict, out_dir, cfg: FpfhConfig | None = None,
                 progress: bool = True) -> dict:
    """Register every clip independently; write closure.txt, clips.json and run.json in ``out_dir``."""
    cfg = cfg or FpfhConfig()
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    t0 = time.perf_counter()
    closure: dict[int, np.ndarray] = {}
    rows = []
    ids = sorted(clip_poses)
    bar = None
    if progress:
        from tqdm import tqdm

        bar = tqdm(total=len(ids), desc="fpfh-icp", unit="clip", file=sys.stderr)
    for c in ids:
        V = clip_poses[c]
        S, info = register_clip(pmap, tour, V, cfg)
        if S is not None:
            for i, Vi in V.items():
                closure[int(i)] = S @ np.asarray(Vi)
        fr = sorted(int(i) for i in V)
        rows.append({"clip": int(c), "start": fr[0] if fr else None, "end": fr[-1] if fr else None,
                     "frames": len(fr), "registered": S is not None, "fitness": info["fitness"],
                     "rmse": info["rmse"], "points": info["points"], "keypoints": info.get("keypoints"),
                     "matches": info.get("matches"), "constraint": info.get("constraint"),
                     "inlier_constraint": info.get("inlier_constraint"),
                     "ransac_fitness": info.get("ransac_fitness"), "ransac_iterations": info.get("ransac_iterations"),
                     "ransac_inliers": info.get("ransac_inliers"),
                     "seconds": info["seconds"], "timings": info["timings"],
                     "reason": info["reason"], "S": None if S is None else np.round(S, 6).tolist()})
        if bar is not None:
            bar.update(1)
    if bar is not None:
        bar.close()
    seconds = time.perf_counter() - t0
    fr = sorted(closure)
    write_tum(out / "closure.txt", [closure[i] for i in fr], fps=tour.fps, frames=fr,
              header=f"FPFH-ICP (clip-rigid) closure trajectory of {tour.root} (camera-to-world, OpenCV axes)")
    n_reg = sum(r["registered"] for r in rows)
    src = Path(pmap.source)
    reasons: dict[str, int] = {}
    for r in rows:
        if r["reason"]:
            key = r["reason"].split(" (")[0]
            reasons[key] = reasons.get(key, 0) + 1
    summary = {
        "method": "fpfh-icp", "protocol": "clip-rigid: VideoReloc's clips and odometry, one registration per clip",
        "tour": str(tour.root), "map": pmap.source, "map_points": len(pmap),
        "map_bytes": src.stat().st_size if src.is_file() else None,
        "clips": len(rows), "registered": n_reg, "frames": sum(r["frames"] for r in rows),
        "closure_frames": len(closure), "seconds": round(seconds, 2),
        "seconds_per_clip": round(seconds / len(rows), 3) if rows else None,
        "not_registered": reasons, "config": cfg.to_dict(),
    }
    write_json_atomic(out / "clips.json", rows)
    write_json_atomic(out / "run.json", summary)
    return summary


# ---------------------------------------------------------------------------------------------
# command line (experiments)


def main(argv=None) -> int:
    import argparse

    from vrformats.tour import Tour
    from vrformats.cli import run_command

    from ..backend.run import load_clip_poses

    ap = argparse.ArgumentParser(prog="python -m reloc.baselines.fpfh_icp", description=__doc__.split("\n")[0])
    sub = ap.add_subparsers(dest="cmd", required=True)
    m = sub.add_parser("map", help="build the 5 cm FPFH point-cloud map of a mapping tour (ground-truth poses)")
    m.add_argument("--tour", required=True)
    m.add_argument("--out", required=True, help="map file (.npz)")
    m.add_argument("--stride", type=int, help="mapping frame stride (default %d)" % FpfhConfig.map_stride)
    r = sub.add_parser("run", help="register every clip of a VideoReloc run to the map")
    r.add_argument("--map", required=True)
    r.add_argument("--tour", required=True)
    r.add_argument("--clips", required=True, help="a 'reloc run' output directory (clip_poses.npz)")
    r.add_argument("--out", required=True)
    for p in (m, r):
        p.add_argument("--quiet", action="store_true")
    args = ap.parse_args(argv)

    def cmd_map(a):
        cfg = FpfhConfig() if a.stride is None else FpfhConfig(map_stride=a.stride)
        pm = PointMap.build(Tour(a.tour), cfg, progress=not a.quiet)
        path = pm.save(a.out)
        print(f"{len(pm)} points from {pm.meta['frames']} frames in {pm.meta['build_seconds']} s; "
              f"{path.stat().st_size / 1e6:.1f} MB -> {path}")
        return 0

    def cmd_run(a):
        s = run_fpfh_icp(Tour(a.tour), PointMap.load(a.map), load_clip_poses(a.clips), a.out, progress=not a.quiet)
        print(f"{s['registered']}/{s['clips']} clips registered, {s['closure_frames']} frames, "
              f"{s['seconds']} s ({s['seconds_per_clip']} s/clip) -> {a.out}")
        return 0

    return run_command("reloc.baselines.fpfh_icp", cmd_map if args.cmd == "map" else cmd_run, args)


if __name__ == "__main__":
    sys.exit(main())
