"""Evaluate the learned detector on rendered tours (``reloc detector eval``), per lighting.

For every RGB frame (every ``every``-th) of the tours, against the frame's rendered ground truth:

* per-class IoU of the per-pixel classes (background included in the argmax, not in the mean);
* instances: a ground-truth instance of at least ``min_pixels`` pixels is found when a detection
  of its class overlaps it with mask IoU >= 0.5 (one-to-one, best IoU first); recall = found /
  ground truth, precision = matched detections / detections;
* the most frequent confusions (ground-truth class -> predicted class, in pixels);
* milliseconds per frame of ``detect`` (network and instance cutting) on this machine, median;
* 95 % intervals of mIoU and instance recall per lighting: percentiles of ``BOOTSTRAP_DRAWS``
  bootstrap resamples of the lighting's frames (seeded, so the same tours give the same interval).

Needs onnxruntime only (no PyTorch): it runs the exported model through
``reloc.detection.learned.LearnedDetector``.
"""

from __future__ import annotations

import sys
import time
from collections import Counter, defaultdict

import numpy as np

from vrformats.errors import UserError
from vrformats.tour import Tour

from ..detection.learned import LearnedDetector

IOU_MATCH = 0.5
BOOTSTRAP_DRAWS = 1000


def _miou(conf: np.ndarray) -> float:
    tp = np.diag(conf).astype(float)
    union = conf.sum(0) + conf.sum(1) - np.diag(conf)
    present = conf.sum(1) > 0
    present[0] = False  # background is not in the mean
    return float(np.mean(tp[present] / union[present])) if present.any() else 0.0


def bootstrap_intervals(frame_conf: np.ndarray, gt: np.ndarray, found: np.ndarray, draws: int = BOOTSTRAP_DRAWS,
                        seed: int = 0) -> dict:
    """95 % percentile intervals of mIoU and instance recall over frames resampled with replacement:
    ``frame_conf`` (N, n, n) per-frame confusion counts, ``gt`` / ``found`` (N,) instances."""
    rng = np.random.default_rng(seed)
    N = len(frame_conf)
    flat = frame_conf.reshape(N, -1).astype(np.float64)
    mi, rec = [], []
    for _ in range(draws):
        w = np.bincount(rng.integers(0, N, N), minlength=N).astype(np.float64)
        mi.append(_miou((w @ flat).reshape(frame_conf.shape[1:])))
        g = float(w @ gt)
        if g > 0:
            rec.append(float(w @ found) / g)
    pct = lambda v: [round(float(x), 3) for x in np.percentile(v, [2.5, 97.5])] if v else None  # noqa: E731
    return {"miou_ci": pct(mi), "instance_recall_ci": pct(rec)}


def preset_of(lighting: str | None) -> str:
    """day, evening or night from a tour's lighting name (jittered presets: ``<layout>/<preset>_j<k>``)."""
    if not lighting:
        return "geometry"
    base = str(lighting).rsplit("/", 1)[-1]
    return base.split("_j")[0]


def _match(dets, gt_masks: dict[int, tuple[str, np.ndarray]]) -> tuple[int, int]:
    """(ground-truth instances found, detections matched), one-to-one by IoU >= 0.5, best first."""
    pairs = []
    for i, d in enumerate(dets):
        for g, (cls, m) in gt_masks.items():
            if cls != d.cls:
                continue
            inter = np.count_nonzero(d.mask & m)
            if inter:
                iou = inter / np.count_nonzero(d.mask | m)
                if iou >= IOU_MATCH:
                    pairs.append((iou, i, g))
    used_d, used_g = set(), set()
    for iou, i, g in sorted(pairs, reverse=True):
        if i not in used_d and g not in used_g:
            used_d.add(i)
            used_g.add(g)
    return len(used_g), len(used_d)


def evaluate(model, tour_dirs, every: int = 1, min_pixels: int = 20, progress: bool = True,
             sensor: str | None = None) -> dict:
    """The report (see the module docstring); ``sensor``: a sensor preset or file
    (``vrformats.sensors``) the frames are read through, as the experiments' ``sensors:`` do."""
    from vrformats.sensors import load_sensor

    sens = load_sensor(sensor) if sensor else None
    det = LearnedDetector(model)
    index = {c: k for k, c in enumerate(det.classes)}
    n = len(det.classes)
    acc = defaultdict(lambda: {"conf": np.zeros((n, n), np.int64), "gt": 0, "found": 0, "dets": 0, "matched": 0,
                               "frames": 0, "per_frame": []})
    times = []
    blind = []  # tours without a single RGB frame among those read
    for d in tour_dirs:
        tour = Tour(d, sensor=sens)
        seen = 0
        lighting = preset_of(tour.meta.get("lighting"))
        names = tour.class_names()  # semantic id -> name
        sem_map = np.zeros(65536, np.int64)
        for sid, name in names.items():
            sem_map[int(sid)] = index.get(name, 0)
        a = acc[lighting]
        for i in tour.frame_indices[::every]:
            f = tour.frame(int(i), rgb=True, depth=True, instance=True, semantic=True)
            if f.rgb is None:
                continue
            seen += 1
            t0 = time.perf_counter()
            pred = det.predict(f.rgb)  # what detect() does, keeping the class map for the pixel scores
            dets = det.instances(*pred, f.depth)
            times.append(time.perf_counter() - t0)
            cls = pred[0]
            gt_cls = sem_map[np.minimum(f.semantic, 65535).astype(np.int64)]
            fconf = np.bincount(gt_cls.ravel() * n + cls.ravel(), minlength=n * n).reshape(n, n)
            a["conf"] += fconf
            gt_masks = {}
            for iid in np.unique(f.instance):
                if iid == 0:
                    continue
                m = f.instance == iid
                c = det.classes[int(np.bincount(gt_cls[m]).argmax())]
                if c != "background" and np.count_nonzero(m) >= min_pixels:
                    gt_masks[int(iid)] = (c, m)
            found, matched = _match(dets, gt_masks)
            a["gt"] += len(gt_masks)
            a["found"] += found
            a["dets"] += len(dets)
            a["matched"] += matched
            a["frames"] += 1
            a["per_frame"].append((fconf, len(gt_masks), found))
        if not seen:
            blind.append(str(d))
        elif progress:
            print(f"evaluated {tour.name}", file=sys.stderr)
    for lighting in [k for k, a in acc.items() if not a["frames"]]:
        del acc[lighting]
    if not acc:
        raise UserError(f"{blind[0]}: no frame with RGB{' (nor in ' + str(len(blind) - 1) + ' more tours)' if len(blind) > 1 else ''}; "
                        "a geometry-only tour cannot be seen by a detector: render RGB (rgb_every, the Blender renderer)")
    if blind and progress:
        print(f"skipped {len(blind)} tours without RGB frames: {', '.join(blind)}", file=sys.stderr)
    rep = {"model": str(model), "sensor": sens.name if sens else "ideal", "ms_per_frame": round(1000 * float(np.median(times)), 1) if times else None,
           "lightings": {}}
    for lighting, a in sorted(acc.items()):
        conf = a["conf"]
        tp = np.diag(conf).astype(float)
        union = conf.sum(0) + conf.sum(1) - np.diag(conf)
        present = conf.sum(1) > 0
        iou = {det.classes[k]: round(float(tp[k] / union[k]), 3) for k in range(1, n) if present[k]}
        off = conf.copy()
        np.fill_diagonal(off, 0)
        top = Counter({(det.classes[g], det.classes[p]): int(off[g, p]) for g, p in zip(*np.nonzero(off))})
        pf = a["per_frame"]
        ci = bootstrap_intervals(np.stack([c for c, _, _ in pf]), np.array([g for _, g, _ in pf], float),
                                 np.array([f for _, _, f in pf], float))
        rep["lightings"][lighting] = {
            "frames": a["frames"], **ci,
            "miou": round(float(np.mean(list(iou.values()))), 3) if iou else 0.0,
            "pixel_acc": round(float(tp.sum() / max(conf.sum(), 1)), 3),
            "instance_recall": round(a["found"] / a["gt"], 3) if a["gt"] else None,
            "instance_precision": round(a["matched"] / a["dets"], 3) if a["dets"] else None,
            "gt_instances": a["gt"], "detections": a["dets"],
            "class_iou": iou,
            "confusions": [{"true": g, "predicted": p, "pixels": c} for (g, p), c in top.most_common(8)],
        }
    return rep


def format_report(rep: dict) -> str:
    def ci(v):
        return f"[{v[0]:.3f}, {v[1]:.3f}]" if v else "-"

    lines = [f"{'lighting':<10} {'frames':>6} {'mIoU':>6} {'95% interval':>16} {'pix acc':>8} {'inst R':>7} "
             f"{'95% interval':>16} {'inst P':>7}"]
    for name, r in rep["lightings"].items():
        lines.append(f"{name:<10} {r['frames']:>6} {r['miou']:>6.3f} {ci(r.get('miou_ci')):>16} {r['pixel_acc']:>8.3f} "
                     f"{(r['instance_recall'] or 0):>7.3f} {ci(r.get('instance_recall_ci')):>16} "
                     f"{(r['instance_precision'] or 0):>7.3f}")
        conf = ", ".join(f"{c['true']}->{c['predicted']} {c['pixels']}" for c in r["confusions"][:4])
        lines.append(f"  top confusions: {conf or 'none'}")
    lines.append(f"detect: {rep['ms_per_frame']} ms/frame (median, this machine); sensor: {rep.get('sensor', 'ideal')}")
    return "\n".join(lines)
