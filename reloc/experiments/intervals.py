"""95 % intervals on an experiment's figures: a block bootstrap over segments of the query path.

Why blocks. Consecutive video frames are not independent: a frame of a clip shares its clip's
placement, and a run that is placed wrong stays wrong for many frames. Counting frames as
independent trials would give intervals a few times too narrow. The resampling unit is therefore a
*segment of the query path*: ``segment_frames`` consecutive frames (default 100, the paper's
shortest clip), the same frames in every query tour, since every layout x lighting (x sensor) tour
walks the same path.

The bootstrap (``IntervalSettings``; one set of draws per experiment, seeded):

* a resample draws the path's segments with replacement (as many as the path has), and every tour
  of that path takes the same draw: tours are strata of fixed size (each tour contributes its own
  frames of each drawn segment, none is ever dropped), and figures of two tours, two lightings,
  two layouts or two methods are **paired** over the same segments (ΔL, ΔR, kept and the checks'
  method comparisons are differences of one draw, not of two independent ones);
* a figure is recomputed on every resample from per-tour sums of frames, successes at both cutoffs
  and posed frames, exactly as its point value is computed (pooled recall = successes / frames over
  the tours it pools; a factor = the mean over its tours of each tour's recall; ΔL, ΔR = differences
  of such means; kept = their ratio);
* the interval is the percentile interval of the resampled values at ``level``.

Assumptions, stated so that a reader can judge the figures: segments are exchangeable and a
failure does not reach further than a segment or two (a run placed wrong for a whole tour makes
neighbouring segments correlated, and then the interval is still too narrow); the population the
interval speaks of is *other stretches of a path like this one in the same layouts and lightings*,
not other apartments; with few segments (a 900-frame tour has 9) the percentile interval covers
somewhat less than its nominal level. Medians of the errors carry no interval.

References: the stratified and block (moving-block) bootstrap for dependent data, A. C. Davison and
D. V. Hinkley, *Bootstrap Methods and their Application*, Cambridge University Press, 1997; H. R.
Künsch, "The jackknife and the bootstrap for general stationary observations", Ann. Statist. 17(3),
1989; resampling whole clusters, C. A. Field and A. H. Welsh, "Bootstrapping clustered data",
J. R. Statist. Soc. B 69(3), 2007.

Only integer counts and integer draws (``Generator.integers``) enter the resampling, so the
intervals are the same on any processor for the same runs.

``results.json`` keeps the counts (``methods.M.modes.MODE.units``: per tour, one ``[frames,
ok_1m_10deg, ok_25cm_5deg, posed]`` per segment), so ``reloc check`` recomputes any figure and any
paired difference from the same draws (``Bootstrap``).
"""

from __future__ import annotations

import dataclasses

import numpy as np

from vrformats import fields

# the columns of a segment's counts
FRAMES, OK_COARSE, OK_FINE, POSED = range(4)
COUNT_OF = {"recall_1m_10deg": OK_COARSE, "recall_25cm_5deg": OK_FINE, "coverage": POSED}
SPEC_KEYS = ("level", "resamples", "segment_frames", "seed")


@dataclasses.dataclass(frozen=True)
class IntervalSettings:
    """How intervals are computed (an experiment spec's ``intervals:``)."""

    level: float = 0.95  # two-sided coverage
    resamples: int = 2000  # bootstrap resamples
    segment_frames: int = 100  # the resampling unit: consecutive frames of the query path
    seed: int = 0  # the draws' seed

    @classmethod
    def from_spec(cls, src, doc) -> "IntervalSettings":
        """``intervals:`` of an experiment spec (every key optional); one line naming the key on error."""
        if doc is None:
            return cls()
        d = fields.mapping(src, doc, "intervals")
        unknown = sorted(set(d) - set(SPEC_KEYS))
        if unknown:
            fields.fail(src, f"intervals.{unknown[0]}", f"unknown key (known: {', '.join(SPEC_KEYS)})")
        out = cls()
        if "level" in d:
            lv = fields.number(src, d["level"], "intervals.level")
            if not 0.5 <= lv < 1.0:
                fields.fail(src, "intervals.level", f"must be in [0.5, 1), got {d['level']!r}")
            out = dataclasses.replace(out, level=lv)
        if "resamples" in d:
            n = fields.integer(src, d["resamples"], "intervals.resamples", lo=100)
            out = dataclasses.replace(out, resamples=n)
        if "segment_frames" in d:
            out = dataclasses.replace(out, segment_frames=fields.positive_int(src, d["segment_frames"],
                                                                               "intervals.segment_frames"))
        if "seed" in d:
            out = dataclasses.replace(out, seed=fields.integer(src, d["seed"], "intervals.seed", lo=0))
        return out

    def as_dict(self) -> dict:
        return dataclasses.asdict(self)


def segment_counts(frames, ok_coarse, ok_fine, posed, segment_frames: int, n_segments: int) -> list[list[int]]:
    """Per segment of the path: ``[frames, ok at 1 m/10 deg, ok at 0.25 m/5 deg, posed]`` over the
    evaluated ``frames`` (path frame indices) and their per-frame outcomes (booleans)."""
    seg = np.asarray(frames, dtype=np.int64) // int(segment_frames)
    out = np.zeros((n_segments, 4), dtype=np.int64)
    if len(seg):
        if seg.max() >= n_segments:
            raise ValueError(f"frame {int(np.max(frames))} lies beyond the path's {n_segments} segments")
        for col, v in ((FRAMES, np.ones(len(seg), bool)), (OK_COARSE, ok_coarse), (OK_FINE, ok_fine), (POSED, posed)):
            np.add.at(out[:, col], seg, np.asarray(v, dtype=np.int64))
    return out.tolist()


def n_segments(path_frames: int, segment_frames: int) -> int:
    """Segments of a path of ``path_frames`` frames (the last one may be shorter)."""
    return max(1, -(-int(path_frames) // int(segment_frames)))


# ---------------------------------------------------------------------------------------------
# figures as functions of per-tour sums


def pooled(sums: np.ndarray, col: int) -> np.ndarray:
    """Pooled fraction over the tours of ``sums`` (shape (..., tours, 4)): sum of ``col`` / sum of frames."""
    n = sums[..., FRAMES].sum(axis=-1)
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(n > 0, sums[..., col].sum(axis=-1) / np.maximum(n, 1), np.nan)


def tour_mean(sums: np.ndarray, col: int) -> np.ndarray:
    """The mean over tours of each tour's fraction (Table II's lighting and layout columns); a tour
    with no frame in a resample counts as missing."""
    n = sums[..., FRAMES]
    with np.errstate(invalid="ignore", divide="ignore"):
        r = np.where(n > 0, sums[..., col] / np.maximum(n, 1), np.nan)
    k = np.isfinite(r).sum(axis=-1)
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(k > 0, np.where(np.isfinite(r), r, 0.0).sum(axis=-1) / np.maximum(k, 1), np.nan)


class Bootstrap:
    """One experiment's resamples: ``units`` = {run key: {tour: segment counts}} (run key
    ``METHOD.MODE``), ``paths`` = {tour: path name}. Every run takes the same draw of a path's
    segments, so figures of different runs and tours are paired."""

    def __init__(self, units: dict, paths: dict, settings: IntervalSettings = IntervalSettings()):
        self.settings = settings
        self.paths = dict(paths)
        self.units = units
        seg_of: dict = {}
        for key, tours in units.items():
            for t, c in tours.items():
                n = len(c)
                p = self.paths[t]
                if seg_of.setdefault(p, n) != n:
                    raise ValueError(f"{key}: tour {t} has {n} segments, other tours of path {p!r} {seg_of[p]}")
        self.n_segments = seg_of
        rng = np.random.default_rng(settings.seed)
        B = settings.resamples
        self._weights = {}
        for p in sorted(seg_of):  # sorted: the same draws whatever the order of the runs
            n = seg_of[p]
            idx = rng.integers(0, n, size=(B, n))
            w = np.zeros((B, n), dtype=np.int64)
            np.add.at(w, (np.repeat(np.arange(B), n), idx.ravel()), 1)
            self._weights[p] = w
        self._cache: dict = {}

    def sums(self, key: str, tours: list[str]) -> tuple[np.ndarray, np.ndarray]:
        """(point, resampled) per-tour sums of run ``key`` over ``tours``: shapes (T, 4) and (B, T, 4)."""
        runs = self.units[key]
        point = np.array([np.sum(runs[t], axis=0) for t in tours], dtype=np.int64).reshape(len(tours), 4)
        res = np.empty((self.settings.resamples, len(tours), 4), dtype=np.int64)
        for j, t in enumerate(tours):
            ck = (key, t)
            if ck not in self._cache:
                self._cache[ck] = self._weights[self.paths[t]] @ np.asarray(runs[t], dtype=np.int64)
            res[:, j, :] = self._cache[ck]
        return point, res

    def interval(self, values: np.ndarray) -> list[float] | None:
        """The percentile interval of resampled ``values`` (None when most resamples have no value)."""
        v = np.asarray(values, dtype=float)
        v = v[np.isfinite(v)]
        if len(v) < 0.5 * self.settings.resamples:
            return None
        a = 100.0 * (1.0 - self.settings.level) / 2.0
        lo, hi = np.percentile(v, [a, 100.0 - a])
        return [float(lo), float(hi)]


# Figures: name -> (kind, column, tour selections). A selection is a tuple of tour names.
#   ("pooled", col, (A,))            pooled fraction over A
#   ("mean", col, (A,))              mean over A of per-tour fractions
#   ("diff", col, (A, B))            mean over A - mean over B
#   ("ratio", col, (A, B))           mean over A / mean over B

def evaluate_figure(fig: tuple, point_sums, resampled_sums) -> tuple[float | None, np.ndarray]:
    """A figure's point value and its resampled values from ``(point, resampled)`` sums of each selection."""
    kind, col, _ = fig
    vals = []
    for s in (point_sums, resampled_sums):
        if kind == "pooled":
            v = pooled(s[0], col)
        elif kind == "mean":
            v = tour_mean(s[0], col)
        else:
            a, b = tour_mean(s[0], col), tour_mean(s[1], col)
            with np.errstate(invalid="ignore", divide="ignore"):
                v = a - b if kind == "diff" else np.where(b > 0, a / np.where(b > 0, b, 1), np.nan)
        vals.append(v)
    p = float(vals[0])
    return (None if not np.isfinite(p) else p), vals[1]


def figure_values(boot: Bootstrap, key: str, fig: tuple) -> tuple[float | None, np.ndarray]:
    """Point value and resamples of ``fig`` for run ``key``."""
    pts, res = [], []
    for sel in fig[2]:
        p, r = boot.sums(key, list(sel))
        pts.append(p)
        res.append(r)
    return evaluate_figure(fig, pts, res)


def factor_figures(tours: dict, unchanged: str, reference: str, sensors: list, lightings: tuple) -> dict:
    """Table II's figures (``tables.FACTOR_KEYS`` and the sensor columns) as figure tuples over the
    query ``tours`` (name -> info with lighting, layout, sensor; ``lightings``: ``tables.LIGHTINGS``);
    selections that are empty are left out."""
    ref = [n for n, t in tours.items() if t.get("sensor", "ideal") == reference]
    col = OK_COARSE
    sel = {light: tuple(n for n in ref if tours[n]["lighting"] == light) for light in lightings}
    sel["unchanged"] = tuple(n for n in ref if tours[n]["layout"] == unchanged)
    sel["rearranged"] = tuple(n for n in ref if tours[n]["layout"] != unchanged)
    figs = {k: ("mean", col, (v,)) for k, v in sel.items() if v}
    if sel["day"] and sel["night"]:
        figs["delta_L"] = ("diff", col, (sel["night"], sel["day"]))
    if sel["unchanged"] and sel["rearranged"]:
        figs["delta_R"] = ("diff", col, (sel["rearranged"], sel["unchanged"]))
        figs["kept"] = ("ratio", col, (sel["rearranged"], sel["unchanged"]))
    if sensors and len(sensors) > 1:
        by = {s: tuple(n for n, t in tours.items() if t.get("sensor", "ideal") == s) for s in sensors}
        for s in sensors:
            if by[s]:
                figs[f"sensor.{s}"] = ("mean", col, (by[s],))
                if s != reference and by[reference]:
                    figs[f"sensor.{s}.delta"] = ("diff", col, (by[s], by[reference]))
    return figs


def pooled_figures(tours: list[str]) -> dict:
    """Table I's fractions pooled over ``tours``."""
    return {k: ("pooled", c, (tuple(tours),)) for k, c in COUNT_OF.items()} if tours else {}


def tour_figures(tour: str) -> dict:
    return {k: ("pooled", c, ((tour,),)) for k, c in COUNT_OF.items()}


def units_note(n_segments: dict, settings: IntervalSettings, n_tours: int) -> str:
    """One sentence on what the intervals rest on, for the tables' notes and the report."""
    segs = ", ".join(str(n) for n in sorted(set(n_segments.values()))) or "0"
    return (f"[lo, hi]: {100 * settings.level:.0f} % interval, a block bootstrap over {segs} segments of "
            f"{settings.segment_frames} frames of the query path (each seen in all {n_tours} query tours, resampled "
            f"together, so differences are paired; {settings.resamples} resamples, seed {settings.seed}); "
            "docs/experiments.md#intervals says what they assume.")
