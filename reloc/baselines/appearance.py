"""Appearance-based per-frame relocalizer (baseline; HLoc-lite with classical OpenCV features).

Mapping (``AppearanceMap.build``): the keyframes are the mapping tour's frames that carry RGB
(optionally every ``stride``-th of them). Each keyframe's RGB is tone-mapped with auto exposure (a
camera with auto-exposure) and converted to 8-bit grey (small images are upscaled for detection);
ORB (default) or SIFT keypoints with a valid, locally smooth depth are back-projected with K and
the tour's ground-truth pose into world points. A visual vocabulary (k-means over the mapping
descriptors, fixed seed) turns every keyframe into a TF-IDF bag-of-words vector for retrieval.

Localization (``localize_frame``): features of the query image, the ``top_k`` keyframes by TF-IDF
cosine similarity, ratio-test matches to each of them, the gathered 2D-3D correspondences into
``cv2.solvePnPRansac`` (USAC/MAGSAC++ by default), a Levenberg-Marquardt refinement on the
inliers; the pose is accepted with enough inliers (``AppearanceConfig.inlier_threshold``).

``run_appearance`` localizes every frame of a query tour that has RGB and writes ``causal.txt``
(per-frame estimates: a per-frame method is causal by construction) and, given the clip partition
and odometry of a VideoReloc run, ``closure.txt`` from the clip-rigid protocol
(``reloc.frontend.clip_rigid``). Frames without RGB are skipped, so the per-frame recall is measured over
the frames with RGB (the experiment runner takes care of that).

Map file: one ``.npz`` (``FORMAT``), written atomically; its size is ``AppearanceMap.nbytes(path)``.
"""

from __future__ import annotations

import json
import math
import sys
import time
from dataclasses import asdict, dataclass, fields
from pathlib import Path

import cv2
import numpy as np

from vrformats.atomic import save_npz_atomic
from vrformats.errors import UserError
from vrformats.frames import FrameFileError





FORMAT = "videoreloc-appearance/1"


@dataclass
class AppearanceConfig:
    # "orb" (binary, Hamming) or "sift" (float, L2). ORB is the default: on the toolkit's 160x120 preview
    # renders (smooth, denoised surfaces) its dense FAST corners give far more correct matches than SIFT
    # blobs (day recall at 1 m / 10 deg about 0.75 against 0.45 with the SIFT settings below).
    feature: str = "orb"
    max_features: int = 2000  # keypoints per image at most (strongest kept)
    sift_contrast: float = 0.004  # SIFT contrastThreshold (OpenCV's 0.04 finds few points in small, smooth renders)
    root_sift: bool = True  # SIFT descriptors compared as RootSIFT (Hellinger kernel): better matching
    orb_fast_threshold: int = 5  # ORB's FAST threshold (OpenCV's 20 finds few corners in smooth renders)
    orb_patch: int = 31  # ORB patch size in the (upscaled) detection image; 31 is OpenCV's
    min_width: int = 320  # narrower images are upscaled (bicubic, integer factor) before detection; 0 = never
    vocab_words: int = 256  # visual words: k-means over the mapping descriptors
    vocab_sample: int = 30000  # at most this many descriptors (random, seeded) go into the k-means
    seed: int = 0  # k-means, descriptor sampling and RANSAC seed
    top_k: int = 5  # keyframes retrieved per query
    ratio: float = 0.8  # Lowe ratio test
    pnp_error_frac: float = 0.0125  # RANSAC reprojection threshold as a fraction of the image width ...
    pnp_error_min_px: float = 1.5  # ... but at least this (2 px at 160 px wide, 8 px at 640)
    # accept a pose with this many PnP inliers (distinct query keypoints); 0 = by feature: ORB 20 (with 2000
    # noisy corners a wrong pose gathers up to ~15 chance inliers), SIFT 10 (fewer, cleaner matches: ~6)
    min_inliers: int = 0
    ransac: str = "usac"  # "ap3p": OpenCV RANSAC with AP3P minimal solver; "usac": OpenCV USAC (MAGSAC++)
    ransac_iters: int = 5000  # PnP-RANSAC iterations at most (it stops early once confident)
    ransac_confidence: float = 0.999
    min_depth: float = 0.1  # keyframe points: depth range kept (m) ...
    max_depth: float = 20.0
    depth_edge_rel: float = 0.05  # ... and the 3x3 depth spread must be below this fraction (no depth edges)

    def pnp_error_px(self, width: int) -> float:
        return max(self.pnp_error_min_px, self.pnp_error_frac * width)

    def inlier_threshold(self, feature: str | None = None) -> int:
        if self.min_inliers > 0:
            return int(self.min_inliers)
        return {"orb": 20, "sift": 10}[feature or self.feature]


def _check_cfg(cfg: AppearanceConfig) -> None:
    if cfg.feature not in ("sift", "orb"):
        raise UserError(f"appearance baseline: feature must be 'sift' or 'orb', got {cfg.feature!r}")
    if cfg.ransac not in ("ap3p", "usac"):
        raise UserError(f"appearance baseline: ransac must be 'ap3p' or 'usac', got {cfg.ransac!r}")
    for name in ("max_features", "vocab_words", "top_k", "ransac_iters"):
        if int(getattr(cfg, name)) < 1:
            raise UserError(f"appearance baseline: {name} must be >= 1, got {getattr(cfg, name)!r}")
    if int(cfg.min_inliers) < 0:
        raise UserError(f"appearance baseline: min_inliers must be >= 0 (0: by feature), got {cfg.min_inliers!r}")


# ---------------------------------------------------------------------------------------------
# features


def rgb_frames(tour, frames: list[int], counts: dict, depth: bool):
    """(position, frame index, frame) of the frames that carry RGB, in order.

    Frames a render job left without RGB (``Tour.rgb_every``) are not read at all; with ``depth``
    a frame also needs depth. ``counts`` collects ``rgb`` (frames yielded) and ``unreadable``
    (candidate frames whose file cannot be read)."""
    every = tour.rgb_every
    for n, i in enumerate(frames):
        if i % every:
            continue
        try:
            f = tour.frame(i, rgb=True, depth=depth, instance=False, semantic=False)
        except FrameFileError:
            counts["unreadable"] += 1
            continue
        if f.rgb is None or (depth and f.depth is None):
            continue
        counts["rgb"] += 1
        yield n, i, f


def to_gray8(rgb_linear: np.ndarray) -> np.ndarray:
    """Linear radiance -> auto-exposed sRGB -> 8-bit grey (what a camera with auto-exposure delivers)."""
    from vrformats.tour import tonemap

    srgb, _ = tonemap(rgb_linear, exposure=None)
    img = np.clip(srgb * 255.0 + 0.5, 0, 255).astype(np.uint8)
    return cv2.cvtColor(img, cv2.COLOR_RGB2GRAY)


def _detector(cfg: AppearanceConfig):
    if cfg.feature == "sift":
        return cv2.SIFT_create(nfeatures=int(cfg.max_features), contrastThreshold=float(cfg.sift_contrast))
    patch = int(cfg.orb_patch)
    return cv2.ORB_create(nfeatures=int(cfg.max_features), edgeThreshold=patch // 2 + 1, patchSize=patch,
                          fastThreshold=int(cfg.orb_fast_threshold))


def upscale_factor(width: int, cfg: AppearanceConfig) -> int:
    return max(1, math.ceil(cfg.min_width / max(int(width), 1))) if cfg.min_width else 1


def extract(gray: np.ndarray, cfg: AppearanceConfig) -> tuple[np.ndarray, np.ndarray]:
    """(keypoints (n, 2) float32 pixel coordinates of ``gray``, descriptors (n, D) uint8)."""
    s = upscale_factor(gray.shape[1], cfg)
    img = cv2.resize(gray, None, fx=s, fy=s, interpolation=cv2.INTER_CUBIC) if s > 1 else gray
    kps, desc = _detector(cfg).detectAndCompute(img, None)
    if desc is None or not kps:
        d = 128 if cfg.feature == "sift" else 32
        return np.zeros((0, 2), np.float32), np.zeros((0, d), np.uint8)
    xy = np.array([k.pt for k in kps], np.float32)
    if s > 1:  # back to the original pixel grid (pixel centres at integers in both)
        xy = (xy + 0.5) / s - 0.5
    if cfg.feature == "sift":  # OpenCV's SIFT values are integers in 0..255 stored as float
        desc = np.clip(np.round(desc), 0, 255).astype(np.uint8)
    return xy, np.ascontiguousarray(desc, dtype=np.uint8)


def _as_float(desc: np.ndarray, feature: str, root: bool = True) -> np.ndarray:
    """Descriptors as float vectors for k-means, word assignment and SIFT matching.

    ORB: its bits as 0/1. SIFT: RootSIFT (L1-normalised, square root) when ``root``, else as is.
    """
    if feature == "orb":
        return np.unpackbits(desc, axis=1).astype(np.float32)
    d = desc.astype(np.float32)
    if root:
        d = np.sqrt(d / np.maximum(d.sum(axis=1, keepdims=True), 1e-9))
    return d


def _assign_words(desc: np.ndarray, vocab: np.ndarray, feature: str, root: bool) -> np.ndarray:
    """Nearest visual word of every descriptor (in chunks: ORB's unpacked bits are large)."""
    out = np.zeros(len(desc), np.int64)
    v2 = (vocab * vocab).sum(1)[None, :]
    for a in range(0, len(desc), 8192):
        x = _as_float(desc[a:a + 8192], feature, root)
        out[a:a + 8192] = (v2 - 2.0 * x @ vocab.T).argmin(axis=1)
    return out


def _bow(words: np.ndarray, idf: np.ndarray) -> np.ndarray:
    v = np.bincount(words, minlength=len(idf)).astype(np.float32)
    v = v / max(v.sum(), 1.0) * idf
    n = float(np.linalg.norm(v))
    return v / n if n > 0 else v


def _matcher(feature: str):
    return cv2.BFMatcher(cv2.NORM_L2 if feature == "sift" else cv2.NORM_HAMMING)


# ---------------------------------------------------------------------------------------------
# map


class AppearanceMap:
    """Keyframes (frame ids, poses), their 2D keypoints, world points and descriptors, and a BoW index."""

    def __init__(self, cfg: AppearanceConfig, K: np.ndarray, size: tuple[int, int], kf_frames, kf_poses,
                 offsets, xy, xyz, desc, vocab, idf, bow, source: str = "<memory>"):
        self.cfg = cfg
        self.K = np.asarray(K, float)
        self.size = (int(size[0]), int(size[1]))  # width, height of the mapping images
        self.kf_frames = np.asarray(kf_frames, np.int64)
        self.kf_poses = np.asarray(kf_poses, np.float64).reshape(-1, 4, 4)
        self.offsets = np.asarray(offsets, np.int64)  # keyframe k owns points offsets[k]:offsets[k + 1]
        self.xy = np.asarray(xy, np.float32).reshape(-1, 2)
        self.xyz = np.asarray(xyz, np.float32).reshape(-1, 3)
        self.desc = np.ascontiguousarray(desc, dtype=np.uint8)
        self.vocab = np.asarray(vocab, np.float32)
        self.idf = np.asarray(idf, np.float32)
        self.bow = np.asarray(bow, np.float32).reshape(len(self.kf_frames), -1)
        self.source = source
        self.build_info: dict = {}
        self._desc_f = None

    def __len__(self) -> int:
        return len(self.kf_frames)

    def __repr__(self) -> str:
        return f"AppearanceMap({len(self)} keyframes, {len(self.xyz)} points, {self.cfg.feature}, from {self.source})"

    def keyframe_desc(self, k: int) -> np.ndarray:
        a, b = self.offsets[k], self.offsets[k + 1]
        if self.cfg.feature == "sift":
            if self._desc_f is None:
                self._desc_f = _as_float(self.desc, "sift", self.cfg.root_sift)
            return self._desc_f[a:b]
        return self.desc[a:b]

    # -- building --------------------------------------------------------------------------------

    @classmethod
    def build(cls, tour, stride: int | None = None, cfg: AppearanceConfig | None = None,
              progress: bool = False) -> "AppearanceMap":
        """Map from a mapping tour (``vrformats.tour.Tour`` or its directory) with ground-truth poses."""
        from vrformats.tour import Tour

        cfg = cfg or AppearanceConfig()
        _check_cfg(cfg)
        if stride is not None and int(stride) < 1:
            raise UserError(f"appearance map: stride must be >= 1, got {stride!r}")
        tour = tour if isinstance(tour, Tour) else Tour(tour)
        t0 = time.perf_counter()
        K = tour.K
        Kinv = np.linalg.inv(K)
        kf_frames, kf_poses, offsets, XY, XYZ, D = [], [], [0], [], [], []
        frames = [int(i) for i in tour.frame_indices]
        counts = {"rgb": 0, "unreadable": 0}
        for n, i, f in rgb_frames(tour, frames, counts, depth=True):
            if stride and (counts["rgb"] - 1) % int(stride):
                continue
            xy, desc = extract(to_gray8(f.rgb), cfg)
            keep = _valid_depth(f.depth, xy, cfg)
            xy, desc = xy[keep[0]], desc[keep[0]]
            z = keep[1]
            pc = (np.c_[xy.astype(np.float64), np.ones(len(xy))] @ Kinv.T) * z[:, None]
            pw = pc @ f.pose[:3, :3].T + f.pose[:3, 3]
            kf_frames.append(i)
            kf_poses.append(f.pose)
            XY.append(xy)
            XYZ.append(pw.astype(np.float32))
            D.append(desc)
            offsets.append(offsets[-1] + len(xy))
            if progress:
                print(f"\rappearance map: {len(kf_frames)} keyframes, {offsets[-1]} points "
                      f"({n + 1}/{len(frames)} frames)", end="", file=sys.stderr, flush=True)
        if progress:
            print(file=sys.stderr)
        if not kf_frames:
            raise UserError(f"{tour.root}: no frame with RGB and depth to build an appearance map from")
        d = 128 if cfg.feature == "sift" else 32
        desc = np.concatenate(D) if D else np.zeros((0, d), np.uint8)
        vocab = _vocabulary(desc, cfg)
        words = _assign_words(desc, vocab, cfg.feature, cfg.root_sift)
        nw = len(vocab)
        # document frequency per word -> idf
        df = np.zeros(nw)
        for k in range(len(kf_frames)):
            df[np.unique(words[offsets[k]:offsets[k + 1]])] += 1
        idf = np.log((len(kf_frames) + 1.0) / (df + 1.0)).astype(np.float32)
        bow = np.stack([_bow(words[offsets[k]:offsets[k + 1]], idf) for k in range(len(kf_frames))])
        m = cls(cfg, K, (tour.intrinsics.width, tour.intrinsics.height), kf_frames, np.stack(kf_poses),
                offsets, np.concatenate(XY), np.concatenate(XYZ), desc, vocab, idf, bow, source=str(tour.root))
        m.build_info = {"tour": str(tour.root), "frames": len(frames), "frames_rgb": counts["rgb"],
                        "frames_unreadable": counts["unreadable"], "keyframes": len(kf_frames), "points": int(offsets[-1]),
                        "seconds": round(time.perf_counter() - t0, 2)}
        return m

    # -- files -----------------------------------------------------------------------------------

    def save(self, path) -> Path:
        """Write the map to one ``.npz`` file, atomically (temporary name, then rename)."""
        path = Path(path)
        path.parent.mkdir(parents=True, exist_ok=True)
        meta = {"format": FORMAT, "config": asdict(self.cfg), "size": list(self.size), "build": self.build_info}
        save_npz_atomic(path, meta=np.array(json.dumps(meta)), K=self.K, kf_frames=self.kf_frames,
                        kf_poses=self.kf_poses, offsets=self.offsets, xy=self.xy, xyz=self.xyz,
                        desc=self.desc, vocab=self.vocab, idf=self.idf, bow=self.bow)
        return path

    @classmethod
    def load(cls, path) -> "AppearanceMap":
        path = Path(path)
        if not path.is_file():
            raise UserError(f"{path}: appearance map not found")
        keys = ("meta", "K", "kf_frames", "kf_poses", "offsets", "xy", "xyz", "desc", "vocab", "idf", "bow")
        try:
            with np.load(path, allow_pickle=False) as z:
                missing = [k for k in keys if k not in z.files]
                if missing:
                    raise UserError(f"{path}: not an appearance map (missing {', '.join(missing)})")
                a = {k: z[k] for k in keys}
            meta = json.loads(str(a["meta"]))
        except UserError:
            raise
        except Exception as e:  # BadZipFile, ValueError, OSError, JSONDecodeError, ...
            raise UserError(f"{path}: not a readable appearance map ({str(e).splitlines()[0] if str(e) else type(e).__name__})") from None
        if not isinstance(meta, dict) or meta.get("format") != FORMAT:
            raise UserError(f"{path}: format: expected {FORMAT!r}, got {meta.get('format') if isinstance(meta, dict) else meta!r}")
        names = {f.name for f in fields(AppearanceConfig)}
        cfg = AppearanceConfig(**{k: v for k, v in meta.get("config", {}).items() if k in names})
        n = len(a["kf_frames"])
        off = a["offsets"]
        if (len(off) != n + 1 or a["kf_poses"].shape != (n, 4, 4) or int(off[-1]) != len(a["xyz"])
                or len(a["xy"]) != len(a["xyz"]) or len(a["desc"]) != len(a["xyz"]) or a["bow"].shape[0] != n):
            raise UserError(f"{path}: inconsistent appearance map (array sizes do not agree)")
        m = cls(cfg, a["K"], tuple(meta.get("size", (0, 0))), a["kf_frames"], a["kf_poses"], off, a["xy"], a["xyz"],
                a["desc"], a["vocab"], a["idf"], a["bow"], source=str(path))
        m.build_info = meta.get("build", {})
        return m

    @staticmethod
    def nbytes(path) -> int:
        """Size of a saved map in bytes (the file size)."""
        return Path(path).stat().st_size


def _valid_depth(depth: np.ndarray, xy: np.ndarray, cfg: AppearanceConfig) -> tuple[np.ndarray, np.ndarray]:
    """(mask of keypoints with usable depth, their depths): in range, and no depth edge around them."""
    h, w = depth.shape
    if len(xy) == 0:
        return np.zeros(0, bool), np.zeros(0)
    u = np.clip(np.round(xy[:, 0]).astype(int), 0, w - 1)
    v = np.clip(np.round(xy[:, 1]).astype(int), 0, h - 1)
    d = np.nan_to_num(depth.astype(np.float64), nan=0.0, posinf=0.0, neginf=0.0)
    pad = np.pad(d, 1, mode="edge")
    nb = np.stack([pad[v + 1 + dv, u + 1 + du] for dv in (-1, 0, 1) for du in (-1, 0, 1)], axis=1)
    z = d[v, u]
    ok = (z >= cfg.min_depth) & (z <= cfg.max_depth) & (nb.min(1) > 0)
    ok &= (nb.max(1) - nb.min(1)) <= cfg.depth_edge_rel * np.maximum(z, 1e-9)
    # away from depth edges: bilinear depth at the sub-pixel keypoint (from its 3x3 neighbourhood)
    fu = np.clip(xy[:, 0] - u, -0.5, 0.5)
    fv = np.clip(xy[:, 1] - v, -0.5, 0.5)
    su, sv = np.sign(fu).astype(int), np.sign(fv).astype(int)
    au, av = np.abs(fu), np.abs(fv)
    col = (su + 1) + 3 * 1  # the neighbours at (v, u + su), (v + sv, u), (v + sv, u + su) in nb's row-major 3x3
    z_u = nb[np.arange(len(z)), col]
    z_v = nb[np.arange(len(z)), 1 + 3 * (sv + 1)]
    z_uv = nb[np.arange(len(z)), (su + 1) + 3 * (sv + 1)]
    zi = (z * (1 - au) + z_u * au) * (1 - av) + (z_v * (1 - au) + z_uv * au) * av
    return ok, zi[ok]


def _vocabulary(desc: np.ndarray, cfg: AppearanceConfig) -> np.ndarray:
    x = _as_float(desc, cfg.feature, cfg.root_sift)
    rng = np.random.default_rng(cfg.seed)
    if len(x) > cfg.vocab_sample:
        x = x[rng.choice(len(x), cfg.vocab_sample, replace=False)]
    k = int(min(cfg.vocab_words, len(x)))
    if k < 1:
        return np.zeros((1, x.shape[1] if x.ndim == 2 else 128), np.float32)
    cv2.setRNGSeed(int(cfg.seed))
    crit = (cv2.TERM_CRITERIA_EPS + cv2.TERM_CRITERIA_MAX_ITER, 25, 0.5)
    _, _, centers = cv2.kmeans(np.ascontiguousarray(x, np.float32), k, None, crit, 1, cv2.KMEANS_PP_CENTERS)
    return centers.astype(np.float32)


# ---------------------------------------------------------------------------------------------
# localization


def localize_frame(amap: AppearanceMap, rgb_linear: np.ndarray, K: np.ndarray,
                   cfg: AppearanceConfig | None = None) -> tuple[np.ndarray | None, dict]:
    """Camera-to-world pose of one image (or None) and an info dict (inliers, keyframe, reason, ...).

    ``cfg`` may change the localization settings (top_k, ratio, thresholds); the features are the map's.
    """
    cfg = cfg or amap.cfg
    feature = amap.cfg.feature
    info: dict = {"keypoints": 0, "matches": 0, "inliers": 0, "keyframe": None, "reason": None}
    if rgb_linear is None:
        info["reason"] = "no RGB"
        return None, info
    gray = to_gray8(rgb_linear)
    h, w = gray.shape
    xy, desc = extract(gray, amap.cfg)  # detection as in the map
    info["keypoints"] = len(xy)
    if len(xy) < 4:
        info["reason"] = f"too few features ({len(xy)})"
        return None, info
    root = amap.cfg.root_sift
    q = _bow(_assign_words(desc, amap.vocab, feature, root), amap.idf)
    sims = amap.bow @ q
    top = np.argsort(-sims, kind="stable")[: int(cfg.top_k)]
    info["retrieved"] = [int(amap.kf_frames[k]) for k in top]
    qd = _as_float(desc, "sift", root) if feature == "sift" else desc
    bf = _matcher(feature)
    p2, p3, src, qsrc = [], [], [], []
    for k in top:
        kd = amap.keyframe_desc(int(k))
        if len(kd) < 2:
            continue
        good = [m[0] for m in bf.knnMatch(qd, kd, k=2) if len(m) == 2 and m[0].distance < cfg.ratio * m[1].distance]
        if not good:
            continue
        qi = np.array([m.queryIdx for m in good])
        ti = np.array([m.trainIdx for m in good]) + amap.offsets[k]
        p2.append(xy[qi])
        p3.append(amap.xyz[ti])
        src.append(np.full(len(good), k))
        qsrc.append(qi)
    if not p2:
        info["reason"] = "no matches"
        return None, info
    p2 = np.concatenate(p2).astype(np.float64)
    p3 = np.concatenate(p3).astype(np.float64)
    src = np.concatenate(src)
    qsrc = np.concatenate(qsrc)
    info["matches"] = len(p2)
    min_inl = max(cfg.inlier_threshold(feature), 4)
    if len(p2) < min_inl:
        info["reason"] = f"too few matches ({len(p2)})"
        return None, info
    K = np.asarray(K, float)
    err = cfg.pnp_error_px(w)
    cv2.setRNGSeed(int(cfg.seed))
    flags = cv2.SOLVEPNP_AP3P if cfg.ransac == "ap3p" else cv2.USAC_MAGSAC
    try:
        ok, rvec, tvec, inl = cv2.solvePnPRansac(p3, p2, K, None, iterationsCount=int(cfg.ransac_iters),
                                                 reprojectionError=float(err), confidence=float(cfg.ransac_confidence),
                                                 flags=flags)
    except cv2.error as e:
        info["reason"] = f"PnP failed ({str(e).strip().splitlines()[-1][:80]})"
        return None, info
    if not ok or inl is None or len(inl) < 4:
        info["reason"] = "PnP-RANSAC found no pose"
        return None, info
    inl = inl.ravel()
    # refine on the inliers, then re-collect the inliers of the refined pose
    try:
        rvec, tvec = cv2.solvePnPRefineLM(p3[inl], p2[inl], K, None, rvec, tvec)
        proj, _ = cv2.projectPoints(p3, rvec, tvec, K, None)
        R = cv2.Rodrigues(rvec)[0]
        zc = p3 @ R[2] + tvec[2, 0]
        e2 = np.linalg.norm(proj.reshape(-1, 2) - p2, axis=1)
        inl2 = np.flatnonzero((e2 <= err) & (zc > 0))
        if len(inl2) >= len(inl):
            inl = inl2
    except cv2.error:
        pass
    # inliers are counted as distinct query keypoints (one may match the same point in several keyframes)
    n_inl = len(np.unique(qsrc[inl]))
    info["inliers"] = int(n_inl)
    counts = np.bincount(src[inl], minlength=len(amap))
    info["keyframe"] = int(amap.kf_frames[int(counts.argmax())])
    if n_inl < min_inl:
        info["reason"] = f"too few inliers ({n_inl} < {min_inl})"
        return None, info
    R = cv2.Rodrigues(rvec)[0]
    Tcw = np.eye(4)
    Tcw[:3, :3] = R
    Tcw[:3, 3] = tvec.ravel()
    T = np.linalg.inv(Tcw)
    if not np.isfinite(T).all():
        info["reason"] = "non-finite pose"
        return None, info
    return T, info


# ---------------------------------------------------------------------------------------------
# a query tour


def run_appearance(tour, amap: AppearanceMap, out_dir, clip_poses: dict[int, dict[int, np.ndarray]] | None = None,
                   cfg: AppearanceConfig | None = None, progress: bool = True, clip_rigid=None) -> dict:
    """Localize every frame of ``tour`` that has RGB; write causal.txt (+ closure.txt), frames.json, run.json.

    ``clip_poses``: clip id -> {frame: V_i} (``reloc.backend.run.load_clip_poses``) for the clip-rigid
    variant; closure.txt then covers every frame of each clip with a consensus transform and keeps
    the frame estimates of the others (``clip_rigid``: the fit's tolerances, a
    ``reloc.config.ClipRigidConfig``; the experiment passes its config's). Returns the run.json summary.
    """
    from vrformats.camera import write_tum
    from vrformats.tour import Tour

    from ..frontend.clip_rigid import clip_rigid_trajectory
    from vrformats.atomic import write_json_atomic

    cfg = cfg or amap.cfg
    _check_cfg(cfg)
    tour = tour if isinstance(tour, Tour) else Tour(tour)
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    K = tour.K
    est: dict[int, np.ndarray] = {}
    rows = []
    t_loc = 0.0
    t0 = time.perf_counter()
    frames = [int(i) for i in tour.frame_indices]
    counts = {"rgb": 0, "unreadable": 0}
    for n, i, f in rgb_frames(tour, frames, counts, depth=False):
        t1 = time.perf_counter()
        T, info = localize_frame(amap, f.rgb, K, cfg)
        t_loc += time.perf_counter() - t1
        if T is not None:
            est[i] = T
        rows.append({"frame": i, "localized": T is not None, "inliers": info["inliers"], "matches": info["matches"],
                     "keyframe": info["keyframe"], "reason": info["reason"]})
        if progress:
            print(f"\rappearance: {len(est)}/{counts['rgb']} localized ({n + 1}/{len(frames)} frames)", end="",
                  file=sys.stderr, flush=True)
    if progress:
        print(file=sys.stderr)
    seconds = time.perf_counter() - t0
    fps = tour.fps
    src = f"appearance baseline ({amap.cfg.feature}) on {tour.root}, map {amap.source}"
    fr = sorted(est)
    write_tum(out / "causal.txt", [est[i] for i in fr], fps=fps, frames=fr,
              header=f"{src}: per-frame estimates (camera-to-world, OpenCV axes)")
    summary = {
        "method": "appearance", "feature": amap.cfg.feature, "tour": str(tour.root), "map": amap.source,
        "frames": len(frames), "frames_rgb": counts["rgb"], "frames_unreadable": counts["unreadable"], "localized": len(est),
        "seconds": round(seconds, 2), "ms_per_frame": round(1000.0 * t_loc / max(counts["rgb"], 1), 2),
        "config": asdict(cfg),
        "note": "frames without RGB are skipped: per-frame recall is over the frames with RGB",
    }
    if clip_poses is not None:
        traj, stats = clip_rigid_trajectory(est, clip_poses, clip_rigid)
        fr = sorted(traj)
        write_tum(out / "closure.txt", [traj[i] for i in fr], fps=fps, frames=fr,
                  header=f"{src}: clip-rigid trajectory (camera-to-world, OpenCV axes)")
        summary.update({"clips": stats["clips"], "clips_fitted": stats["clips_fitted"],
                        "clips_fallback": stats["clips_fallback"], "closure_frames": len(traj)})
        write_json_atomic(out / "clips.json", stats["per_clip"])
    else:
        for stale in ("closure.txt", "clips.json"):  # a previous run's clip-rigid output would mislead
            (out / stale).unlink(missing_ok=True)
    write_json_atomic(out / "frames.json", rows, indent=None)
    write_json_atomic(out / "run.json", summary)
    return summary


__all__ = ["AppearanceConfig", "AppearanceMap", "localize_frame", "run_appearance", "to_gray8", "extract", "FORMAT"]
