"""Experiment figures (reloc/plots.py) and the experiment report (reloc/report.py).

The tests build a small fake results directory that follows the videoreloc-experiment/1 schema:
a box map, one query tour directory (camera.json, poses.txt, meta.json; no frames: the plots do
not read them), TUM trajectories with known errors and markdown tables.
"""

from __future__ import annotations

import json
import math
import struct

import numpy as np
import pytest

import reloc.experiments.plots as plots
import reloc.figures
from reloc.experiments.plots import box_corners, error_colors, per_frame, plot_experiment, rolling_median, tour_png_name
from reloc.experiments.report import markdown_to_html, split_row, table_to_html, write_report

from vrformats import camera as cam
from conftest import make_tour


FPS = 30.0
N = 240
TOUR = "apt_t__day__query"
TOUR2 = "apt_t__night__rearranged"
MISSING = set(range(100, 160))  # frames without an estimate in the closure trajectory
OFFSET = np.array([0.3, 0.0, 0.0])  # closure estimate = ground truth shifted 0.3 m in x


def gt_poses(n=N):
    return [cam.pose_from_ypr((1.0 + 3.0 * i / n, 1.0 + 1.5 * math.sin(i / 30), 1.4), yaw=0.02 * i)
            for i in range(n)]


def poses_tour(root, n=N):
    make_tour(root, gt_poses(n), intrinsics=cam.Intrinsics.from_fov(64, 48, 75.0), fps=FPS, layout="apt_t",
              lighting="day")


def map_doc():
    def box(i, cls, kind, c, s, yaw=0.0):
        return {"id": i, "class": cls, "kind": kind, "center": c, "size": s, "yaw": yaw, "movable": kind == "object"}

    boxes = [box(1, "sofa", "object", [2.0, 3.0, 0.4], [1.8, 0.8, 0.8], 0.3),
             box(2, "table", "object", [4.0, 1.0, 0.4], [1.0, 0.6, 0.8]),
             box(3, "chair", "object", [3.0, 2.0, 0.45], [0.5, 0.5, 0.9], 1.0),
             box(1000, "wall", "wall", [0.0, 2.5, 1.3], [0.1, 5.0, 2.6]),
             box(1001, "wall", "wall", [6.0, 2.5, 1.3], [0.1, 5.0, 2.6]),
             box(1002, "wall", "wall", [3.0, 0.0, 1.3], [6.0, 0.1, 2.6]),
             box(1003, "wall", "wall", [3.0, 5.0, 1.3], [6.0, 0.1, 2.6]),
             box(2000, "floor", "floor", [3.0, 2.5, -0.05], [6.0, 5.0, 0.1]),
             box(3000, "ceiling", "ceiling", [3.0, 2.5, 2.65], [6.0, 5.0, 0.1])]
    return {"format": "videoreloc-boxes/1", "layout": "apt_t", "classes": {}, "boxes": boxes}


MAIN_MD = """| method | recall 1 m/10° | median pos (m) |
|---|---:|---:|
| VideoReloc, with clip closure | 75.0% | 0.30 |
| Appearance (SIFT + PnP), per frame | 0.0% | — |
| Appearance <clip-rigid> † | 12.5% | 1.20 |
"""
FACTORS_MD = """| method | day | night | unchanged | rearranged |
|---|---:|---:|---:|---:|
| VideoReloc, with clip closure | 75.0% | — | 75.0% | — |
| Appearance (SIFT + PnP), per frame | 0.0% | — | 0.0% | — |
"""


@pytest.fixture
def results_dir(tmp_path):
    rd = tmp_path / "results"
    (rd / "maps").mkdir(parents=True)
    (rd / "maps" / "videoreloc_map.json").write_text(json.dumps(map_doc()))
    tour_dir = tmp_path / "tours" / TOUR
    poses_tour(tour_dir)
    gt = gt_poses()
    est_frames = [i for i in range(N) if i not in MISSING]
    est = []
    for i in est_frames:
        T = gt[i].copy()
        T[:3, 3] += OFFSET
        est.append(T)
    cam.write_tum(rd / "runs" / "videoreloc" / TOUR / "closure.txt", est, fps=FPS, frames=est_frames)
    # appearance.causal: no trajectory file at all
    tables = rd / "tables"
    tables.mkdir()
    (tables / "main.md").write_text(MAIN_MD)
    (tables / "factors.md").write_text(FACTORS_MD)
    rec = (N - len(MISSING)) / N
    results = {
        "format": "videoreloc-experiment/1", "name": "test<exp>", "spec": "reloc/specs/test.yaml",
        "map": str(rd / "maps" / "videoreloc_map.json"),
        "tours": {TOUR: {"dir": str(tour_dir), "layout": "apt_t", "lighting": "day", "rearranged": False,
                         "frames": N, "fps": FPS}},
        "rows": [
            {"key": "appearance.causal", "method": "appearance", "mode": "causal",
             "label": "Appearance (SIFT + PnP), per frame", "dagger": False},
            {"key": "videoreloc.closure", "method": "videoreloc", "mode": "closure",
             "label": "VideoReloc, with clip closure", "dagger": False},
        ],
        "methods": {
            "appearance": {"label": "Appearance", "map_bytes": 123456, "primary": "causal", "modes": {"causal": {
                "tours": {TOUR: {"recall_1m_10deg": 0.0, "coverage": 0.0, "frames": N,
                                 "file": f"runs/appearance/{TOUR}/causal.txt"}},
                "factors": {"day": 0.0, "evening": None, "unchanged": 0.0, "rearranged": None}}}},
            "videoreloc": {"label": "VideoReloc", "map_bytes": 2048, "primary": "closure", "modes": {"closure": {
                "tours": {TOUR: {"recall_1m_10deg": rec, "coverage": rec, "frames": N,
                                 "file": f"runs/videoreloc/{TOUR}/closure.txt"}},
                "factors": {"day": rec, "unchanged": rec}}}},
        },
        "seconds": {"render": None, "map": 12.3, "videoreloc": 180.0, "appearance": 4.5},
        "failed": {"appearance/apt_t__day__query": "RuntimeError: <boom>"},
    }
    (rd / "results.json").write_text(json.dumps(results, indent=1))
    return rd


def png_size(path):
    data = path.read_bytes()
    assert data[:8] == b"\x89PNG\r\n\x1a\n", f"{path} is not a PNG"
    assert data[12:16] == b"IHDR"
    return struct.unpack(">II", data[16:24])


@pytest.fixture
def captured(monkeypatch):
    """The figures plots.py and reloc.figures save, by file name (saved for real as well)."""
    figs = {}
    real = plots.save_figure

    def spy(fig, out, dpi):
        figs[out.name] = fig
        return real(fig, out, dpi)

    import reloc.figures

    monkeypatch.setattr(plots, "save_figure", spy)
    monkeypatch.setattr(reloc.figures, "save_figure", spy)  # the per-tour figure's module
    return figs


def all_texts(fig):
    out = [t.get_text() for t in fig.texts]
    for ax in fig.axes:
        out += [t.get_text() for t in ax.texts] + [ax.get_title()]
    return out


# ---------------------------------------------------------------------------------------------
# reading figures back: pixels of the saved PNG, located through the drawn figure's transforms

# the colour code by hand: a straight line from green (0, 0.70, 0) at 0 m to yellow (1, 0.88, 0) at
# 0.5 m and on to red (0.85, 0, 0) at 1 m and beyond
GREEN, YELLOW, RED = (0.0, 0.70, 0.0), (1.0, 0.88, 0.0), (0.85, 0.0, 0.0)


def colour_by_hand(err_m: float) -> np.ndarray:
    t = min(max(err_m, 0.0), 1.0)
    a, b, u = (GREEN, YELLOW, t / 0.5) if t <= 0.5 else (YELLOW, RED, (t - 0.5) / 0.5)
    return (1 - u) * np.array(a) + u * np.array(b)


def read_png(path) -> np.ndarray:
    from matplotlib.image import imread

    return imread(str(path))[..., :3]  # (H, W, 3) floats in [0, 1]


def pixel_of(ax, x, y, img) -> tuple[int, int]:
    """(row, column) in the saved PNG of data point (x, y) of ``ax`` (figure and PNG share the dpi)."""
    dx, dy = ax.transData.transform((x, y))
    return int(img.shape[0] - dy), int(dx)


def near(img, rc, colour, tol=4 / 255, r=1) -> bool:
    """Some pixel within r of rc has ``colour`` (each channel within tol)."""
    row, col = rc
    patch = img[max(row - r, 0): row + r + 1, max(col - r, 0): col + r + 1]
    return bool((np.abs(patch - np.asarray(colour)).max(axis=-1) <= tol).any())


def pixels_like(img, box, colour, tol=4 / 255) -> int:
    """How many pixels inside the display-space bbox ``box`` have ``colour``."""
    (x0, y0), (x1, y1) = box.get_points()
    H = img.shape[0]
    patch = img[int(H - y1) + 1: int(H - y0) - 1, int(x0) + 1: int(x1) - 1]
    return int((np.abs(patch - np.asarray(colour)).max(axis=-1) <= tol).sum())


# ---------------------------------------------------------------------------------------------
# numbers


def test_error_colors_green_yellow_red():
    c = error_colors([0.0, 0.5, 1.0, 2.0, 50.0, np.nan, np.inf])
    assert c.shape == (7, 4)
    r, g, b = c[0, :3]
    assert g > 0.6 and r < 0.1 and b < 0.1  # green
    r, g, b = c[1, :3]
    assert r > 0.9 and g > 0.8 and b < 0.1  # yellow
    for k in (2, 3, 4, 6):  # red, clipped beyond 1 m
        r, g, b = c[k, :3]
        assert r > 0.8 and g < 0.1 and b < 0.1
        np.testing.assert_allclose(c[k], c[2])
    np.testing.assert_allclose(c[5, :3], 0.6)  # unknown: grey
    # continuous: 0.25 m lies between green and yellow
    mid = error_colors([0.25])[0]
    assert c[0, 0] < mid[0] < c[1, 0]


def test_rolling_median_matches_direct_computation_with_nan_windows():
    rng = np.random.default_rng(0)
    v = rng.lognormal(size=200)
    v[rng.random(200) < 0.3] = np.nan
    v[60:120] = np.nan  # longer than the window: some windows have no value at all
    for w in (1, 5, 31, 32):
        got = rolling_median(v, w)
        half = w // 2
        want = np.full(len(v), np.nan)
        for k in range(len(v)):
            seg = v[max(0, k - half): k - half + w]
            seg = seg[np.isfinite(seg)]
            if len(seg):
                want[k] = np.median(seg)
        np.testing.assert_array_equal(np.isnan(got), np.isnan(want))
        np.testing.assert_allclose(got[~np.isnan(got)], want[~np.isnan(want)])
    assert np.isnan(rolling_median(v, 31)[90])
    assert rolling_median(np.array([]), 31).shape == (0,)


def test_per_frame_places_values_and_ignores_unknown_frames():
    out = per_frame([10, 11, 12, 13], [11, 13, 99], [1.0, 3.0, 7.0])
    np.testing.assert_array_equal(np.isnan(out), [True, False, True, False])
    assert out[1] == 1.0 and out[3] == 3.0


def test_box_corners_rotate_about_z():
    c = box_corners([[1.0, 2.0, 0.5]], [[2.0, 1.0, 1.0]], [math.pi / 2])[0]
    lo, hi = c.min(axis=0), c.max(axis=0)
    np.testing.assert_allclose(hi - lo, [1.0, 2.0], atol=1e-12)  # extents swapped
    np.testing.assert_allclose(c.mean(axis=0), [1.0, 2.0], atol=1e-12)


# ---------------------------------------------------------------------------------------------
# figures


def test_plot_experiment_writes_valid_pngs(results_dir, captured):
    paths = plot_experiment(results_dir)
    names = [p.name for p in paths]
    assert names == [tour_png_name(TOUR), "recall_bars.png"]
    for p in paths:
        assert p.parent == results_dir / "plots"
        w, h = png_size(p)
        assert 500 <= w <= 3000 and 300 <= h <= 2000, (p.name, w, h)
    assert not [p for p in (results_dir / "plots").iterdir() if p.name.startswith(".")]  # no temporary files

    fig = captured[tour_png_name(TOUR)]
    texts = all_texts(fig)
    # the missing trajectory is a column without poses, recall 0
    assert any("no poses" in t for t in texts)
    assert any("Appearance" in t and "0.0%" in t and f"(0/{N} posed)" in t for t in texts)
    # the closure column: every posed frame is within 0.3 m, so recall = posed / all frames
    posed = N - len(MISSING)
    assert any("VideoReloc" in t and f"{100 * posed / N:.1f}%" in t and f"({posed}/{N} posed)" in t for t in texts)

    # the saved image: the closure column draws each estimate in the colour of 0.3 m (a yellowish
    # green), and no estimate in any other colour of the code; the empty column draws none
    img = read_png(paths[0])
    top = {ax.get_title().split("\n")[0]: ax for ax in fig.axes if ax.get_title()}
    ax = top["VideoReloc, with clip closure"]
    gt = gt_poses()
    want = colour_by_hand(0.3)
    np.testing.assert_allclose(want, [0.6, 0.808, 0.0])
    for i in (0, 50, 99, 160, 200, 239):
        x, y = gt[i][:2, 3] + OFFSET[:2]
        assert near(img, pixel_of(ax, x, y, img), want), i
    assert pixels_like(img, ax.bbox, want) > 200
    for other in (GREEN, YELLOW, RED, colour_by_hand(0.1), colour_by_hand(0.6)):
        assert pixels_like(img, ax.bbox, other) == 0, other
    empty = top["Appearance (SIFT + PnP), per frame"]
    assert all(pixels_like(img, empty.bbox, c) == 0 for c in (want, GREEN, YELLOW, RED))

    bars_fig = captured["recall_bars.png"]
    bars = all_texts(bars_fig)
    assert f"{100 * posed / N:.0f}%" in bars and "0%" in bars
    # the design has day and unchanged only: no evening/night or rearranged groups
    ticks = [t.get_text() for ax in bars_fig.axes for t in ax.get_xticklabels()]
    assert "day" in ticks and "unchanged" in ticks
    assert "evening" not in ticks and "night" not in ticks and "rearranged" not in ticks
    # each VideoReloc bar rises to its recall in the saved image: the bar's colour runs from the axis
    # up to the pixel row of 0.75, the appearance bar (recall 0) has no height
    img = read_png(paths[1])
    import matplotlib

    colour = np.array(matplotlib.colormaps["tab10"].colors[1])  # second row: VideoReloc
    for bar_ax in bars_fig.axes[:2]:
        x = bar_ax.get_xticks()[0] + 0.5 * 0.8 / 2  # the second of two bars around group 0
        col = pixel_of(bar_ax, x, 0.0, img)[1]
        rows = np.flatnonzero(np.abs(img[:, col] - colour).max(axis=-1) <= 4 / 255)
        assert len(rows), bar_ax.get_title()
        top_row, base_row = pixel_of(bar_ax, x, posed / N, img)[0], pixel_of(bar_ax, x, 0.0, img)[0]
        assert abs(rows.min() - top_row) <= 2 and abs(rows.max() - base_row) <= 2, (rows.min(), top_row)


def test_points_are_coloured_by_their_position_error(results_dir, captured):
    plot_experiment(results_dir)
    fig = captured[tour_png_name(TOUR)]
    cols = [c for ax in fig.axes for c in ax.collections if c.__class__.__name__ == "PathCollection"]
    assert len(cols) == 1  # one scatter: the closure column; the missing one draws none
    fc = cols[0].get_facecolors()
    assert len(fc) == N - len(MISSING)
    np.testing.assert_allclose(fc, error_colors(np.full(len(fc), 0.3)))


def test_missing_tour_is_skipped_and_missing_map_tolerated(results_dir, capsys):
    res = json.loads((results_dir / "results.json").read_text())
    res["tours"][TOUR2] = {"dir": str(results_dir / "nope"), "layout": "apt_t", "lighting": "night",
                           "rearranged": True, "frames": 10, "fps": FPS}
    res["map"] = str(results_dir / "maps" / "missing.json")
    (results_dir / "results.json").write_text(json.dumps(res))
    paths = plot_experiment(results_dir)
    assert [p.name for p in paths] == [tour_png_name(TOUR), "recall_bars.png"]
    err = capsys.readouterr().err
    assert TOUR2 in err and "missing.json" in err


def test_tour_figure_with_empty_estimates_and_no_map(tmp_path, captured):
    gt = {i: T for i, T in enumerate(gt_poses(50))}
    out = plots.tour_figure(None, gt, {"nothing": {}}, tmp_path / "t.png", title="x")
    assert png_size(out)[0] > 300
    fig = captured["t.png"]
    top, bottom = fig.axes[0], fig.axes[1]
    # without a map the view is the ground-truth path with a 0.4 m margin
    P = np.array([T[:3, 3] for T in gt.values()])
    np.testing.assert_allclose(top.get_xlim(), (P[:, 0].min() - 0.4, P[:, 0].max() + 0.4))
    np.testing.assert_allclose(top.get_ylim(), (P[:, 1].min() - 0.4, P[:, 1].max() + 0.4))
    assert not top.collections  # no map boxes, no estimates
    assert bottom.get_xlim() == (0.0, 49.0) and not bottom.get_lines()[2:]  # only the two dashed thresholds
    assert [t.get_text() for t in top.texts + bottom.texts] == ["no poses", "no poses"]
    assert "(0/50 posed)" in top.get_title()
    # the saved image: the grey ground-truth path passes through every third frame's position (except
    # where the "no poses" label covers it)
    img = read_png(out)
    label = top.texts[0].get_bbox_patch().get_window_extent().padded(3)
    seen = 0
    for i in range(0, 50, 3):
        if label.contains(*top.transData.transform(P[i, :2])):
            continue
        # an antialiased 0.8 pt line: its darkest pixel near each position is within 0.2 of the grey
        assert near(img, pixel_of(top, P[i, 0], P[i, 1], img), reloc.figures.GT_COLOR, tol=0.2), i
        seen += 1
    assert seen >= 8
    assert all(pixels_like(img, top.bbox, c) == 0 for c in (GREEN, YELLOW, RED))


def test_estimates_are_green_yellow_red_by_their_error_in_the_image(tmp_path, captured):
    """Known errors (0 m, 0.5 m, 1.2 m on three stretches of the path, each estimate moved by its error
    in -x, which keeps it in view): each is drawn green, yellow or red in the saved PNG, where it lies."""
    gt = {i: T for i, T in enumerate(gt_poses())}
    err = {i: 0.0 if i < 80 else 0.5 if i < 160 else 1.2 for i in gt}
    est = {}
    for i, T in gt.items():
        E = T.copy()
        E[:3, 3] -= [err[i], 0.0, 0.0]
        est[i] = E
    out = plots.tour_figure(None, gt, {"known errors": est}, tmp_path / "k.png")
    ax = captured["k.png"].axes[0]
    img = read_png(out)
    px = {i: np.array(pixel_of(ax, *est[i][:2, 3], img)) for i in est}
    checked = {0.0: 0, 0.5: 0, 1.2: 0}
    for i in range(0, N, 4):
        # only where no estimate of another colour is drawn within 6 px
        if any(err[j] != err[i] and np.abs(px[j] - px[i]).max() <= 6 for j in est):
            continue
        assert near(img, px[i], colour_by_hand(err[i])), (i, err[i], img[tuple(px[i])])
        checked[err[i]] += 1
    assert min(checked.values()) >= 5, checked
    assert not [t for t in ax.texts if "outside the view" in t.get_text()]
    assert "recall 1 m/10°: 66.7%" in ax.get_title()  # 160 of 240 frames within 1 m


def test_split_row_and_table_to_html():
    assert split_row("| a | b \\| c |  d|") == ["a", "b | c", "d"]
    h = table_to_html(["| name | value |", "|:---|---:|", "| <x> | 1 |", "| y |"])
    assert "<thead><tr><th style=\"text-align:left\">name</th><th style=\"text-align:right\">value</th></tr></thead>" in h
    assert "<td style=\"text-align:left\">&lt;x&gt;</td><td style=\"text-align:right\">1</td>" in h
    assert "<tr><td style=\"text-align:left\">y</td><td style=\"text-align:right\"></td></tr>" in h  # padded
    assert "<x>" not in h
    # no separator line: all body rows
    h2 = table_to_html(["| a | b |", "| c | d |"])
    assert "<th" not in h2 and h2.count("<tr>") == 2


def test_markdown_to_html_escapes_and_converts():
    h = markdown_to_html("# T <1>\n\nsome <b>bold</b> & **strong** `a<b`\n\n- one\n- two\n\n"
                         "![cap <x>](plots/a.png)\n\n| a |\n|---|\n| <i> |\n")
    assert "<h1>T &lt;1&gt;</h1>" in h
    assert "some &lt;b&gt;bold&lt;/b&gt; &amp; <strong>strong</strong> <code>a&lt;b</code>" in h
    assert "<ul>\n<li>one</li>\n<li>two</li>\n</ul>" in h
    assert '<img src="plots/a.png" alt="cap &lt;x&gt;">' in h
    assert "<td>&lt;i&gt;</td>" in h and "<b>" not in h and "<i>" not in h


def test_report_gathers_tables_plots_and_timings(results_dir):
    plot_experiment(results_dir)
    html_path, md_path = write_report(results_dir)
    assert (html_path, md_path) == (results_dir / "report.html", results_dir / "report.md")
    md, h = md_path.read_text(), html_path.read_text()
    assert md.startswith("# VideoReloc experiment report: test<exp>")
    assert "<title>VideoReloc experiment report: test&lt;exp&gt;</title>" in h
    # every table row, verbatim in the markdown, as cells in the HTML; main before factors
    for text in (MAIN_MD, FACTORS_MD):
        for line in text.strip().splitlines():
            assert line in md
    # headings: the paper's numbers and captions, in its order
    i = md.index("### Table I: Comparison of recall and pose errors across relocalization methods")
    assert i < md.index("### Table II: Recall at 1 m/10\u00b0 under illumination and furniture changes")
    assert "<td>VideoReloc, with clip closure</td>" in h
    assert "<td>Appearance &lt;clip-rigid&gt; †</td>" in h and "<clip-rigid>" not in h
    # every plot, by relative path; recall bars before the tour figures
    pngs = sorted(p.name for p in (results_dir / "plots").glob("*.png"))
    assert pngs
    for name in pngs:
        assert f"](plots/{name})" in md
        assert f'<img src="plots/{name}"' in h
    assert md.index("plots/recall_bars.png") < md.index(f"plots/{tour_png_name(TOUR)}")
    # protocol and timings
    assert "a frame without a returned pose is a failure" in md and "\u2020" in md
    assert "| videoreloc | 180.0 (3.0 min) |" in md and "| render | \u2014 |" in md
    assert "<td>map</td><td>12.3</td>" in h
    assert "## Failed runs" in md and "<li><code>appearance/apt_t__day__query</code>: RuntimeError: &lt;boom&gt;</li>" in h
    assert "<script" not in h and h.count("<table>") >= 5  # tours, methods, 2 tables, timings
    assert not [p for p in results_dir.iterdir() if p.name.startswith(".")]


def test_report_without_plots_or_tables(tmp_path):
    rd = tmp_path / "r"
    rd.mkdir()
    (rd / "results.json").write_text(json.dumps({"format": "videoreloc-experiment/1", "name": "bare"}))
    html_path, md_path = write_report(rd)
    md = md_path.read_text()
    assert "No tables were found" in md and "No plots were found" in md
    assert "<h1>VideoReloc experiment report: bare</h1>" in html_path.read_text()


def test_oracle_rows_are_drawn_as_the_upper_bound():
    from reloc.experiments.plots import _is_bound

    assert _is_bound({"method": "videoreloc_oracle", "mode": "closure"})
    assert _is_bound({"key": "videoreloc_oracle.causal"})
    assert not _is_bound({"method": "videoreloc", "mode": "closure"})
    assert not _is_bound({"key": "appearance.causal"})


def test_a_sampled_baseline_is_titled_with_its_recall_on_the_frames_it_is_scored_on(results_dir, captured):
    """The one-frame unit is scored on every 15th frame: its column's recall is the table's (over
    the frames it is scored on), not its hits divided by every frame of the tour."""
    gt = gt_poses()
    sampled = list(range(0, N, 15))
    cam.write_tum(results_dir / "runs" / "one_frame" / TOUR / "causal.txt", [gt[i] for i in sampled], fps=FPS,
                  frames=sampled)
    res = json.loads((results_dir / "results.json").read_text())
    res["rows"].append({"key": "one_frame.causal", "method": "one_frame", "mode": "causal",
                        "label": "One-frame object unit", "dagger": False})
    res["methods"]["one_frame"] = {"label": "One-frame object unit", "map_bytes": 2048, "primary": "causal", "modes": {
        "causal": {"tours": {TOUR: {"recall_1m_10deg": 1.0, "coverage": 1.0, "frames": len(sampled),
                                    "file": f"runs/one_frame/{TOUR}/causal.txt"}}, "factors": {"day": 1.0}}}}
    (results_dir / "results.json").write_text(json.dumps(res))
    plot_experiment(results_dir)
    top = {ax.get_title().split("\n")[0]: ax.get_title() for ax in captured[tour_png_name(TOUR)].axes if ax.get_title()}
    title = top["One-frame object unit"]
    assert "100.0%" in title and f"{len(sampled)} scored" in title, title
    posed = N - len(MISSING)  # a method scored on every frame keeps its title
    assert f"{100 * posed / N:.1f}%" in top["VideoReloc, with clip closure"]


def test_report_has_per_tour_recall_checks_environment_and_linked_plots(results_dir, tmp_path, capsys):
    """report.html: the per-tour table (recall with its interval), the last `reloc check`'s results,
    the commit/machine/libraries, and every plot a link to its full-size image."""
    from reloc.cli import main as reloc_main
    from vrformats.environment import cpu_model

    res = json.loads((results_dir / "results.json").read_text())
    res["methods"]["videoreloc"]["modes"]["closure"]["intervals"] = {
        "tours": {TOUR: {"recall_1m_10deg": [0.70, 0.80]}}}
    for m, mode in (("videoreloc", "closure"), ("appearance", "causal")):  # the pooled figures reloc check reads
        d = res["methods"][m]["modes"][mode]
        d["all"] = {k: d["tours"][TOUR].get(k) for k in ("recall_1m_10deg", "coverage")}
    res["environment"] = {"toolkit": "0.1.0", "commit": "abc1234", "cpu_model": "Test CPU 9000", "cpu_count": 64,
                          "platform": "Linux-test", "libraries": {"python": "3.11.9", "numpy": "1.26.4"}}
    (results_dir / "results.json").write_text(json.dumps(res))
    plot_experiment(results_dir)
    html_path, md_path = write_report(results_dir)
    md, h = md_path.read_text(), html_path.read_text()
    posed = N - len(MISSING)
    assert f"| {TOUR} | VideoReloc, with clip closure | {100 * posed / N:.1f}% | 70.0\u201380.0% | " in md
    assert f"| {TOUR} | Appearance (SIFT + PnP), per frame | 0.0% | \u2014 | 0.0% | {N} |" in md
    assert "No checks were run on these results" in md
    assert "- code: videoreloc-synth commit abc1234" in md
    assert "- machine: Test CPU 9000, 64 cores; Linux-test" in md and "numpy 1.26.4" in md
    name = tour_png_name(TOUR)
    assert f'<a href="plots/{name}"><img src="plots/{name}"' in h

    # reloc check records its rows in results.json and rewrites the report with them
    checks = tmp_path / "c.yaml"
    checks.write_text("checks:\n  - videoreloc.closure.recall_1m_10deg >= 0.5\n"
                      "  - {check: 'appearance.causal.recall_1m_10deg >= 0.5', name: appearance works}\n")
    assert reloc_main(["check", str(checks), str(results_dir)]) == 1
    rec = json.loads((results_dir / "results.json").read_text())["checks"]
    assert [r["passed"] for r in rec["rows"]] == [True, False] and rec["file"] == str(checks)
    assert rec["rows"][1]["margin"] == pytest.approx(-0.5)  # appearance's 0 against 0.5: half a recall short
    md, h = md_path.read_text(), html_path.read_text()
    assert "1 passed, 1 failed" in md and "No checks were run" not in md
    assert "| appearance works | `appearance.causal.recall_1m_10deg >= 0.5` | 0 | 0.5 | \u2014 | **FAIL** (false) |" in md
    assert "<strong>FAIL</strong> (false)" in h
    # results written anew (a rerun of the experiment) carry no checks: the report does not show stale ones
    (results_dir / "results.json").write_text(json.dumps(res))
    assert "No checks were run on these results" in write_report(results_dir)[1].read_text()
    # while the experiment runs (its lock held) the checks are still printed, but not recorded
    from vrformats.lifetime import folder_lock

    with folder_lock(results_dir, "reloc experiment"):
        assert reloc_main(["check", str(checks), str(results_dir)]) == 1
    io = capsys.readouterr()
    assert "1 passed, 1 failed" in io.out and "the checks were not recorded" in io.err
    assert "checks" not in json.loads((results_dir / "results.json").read_text())

    # a results folder without a recorded environment: this machine's, said so
    del res["environment"]
    (results_dir / "results.json").write_text(json.dumps(res))
    md = write_report(results_dir)[1].read_text()
    assert "not recorded with the results" in md and f"{cpu_model() or 'unknown CPU'}" in md


def test_many_methods_wrap_into_rows_so_a_figure_keeps_a_page_width(tmp_path, captured):
    """Seven methods (the demo's rows) at most reloc.figures.MAX_COLUMNS side by side: the figure is
    as wide as two columns (readable in report.html without scaling), the methods in four rows."""
    gt = dict(enumerate(gt_poses(60)))
    est = {f"method {k}": dict(gt) for k in range(7)}
    out = plots.tour_figure(None, gt, est, tmp_path / "wide.png", title="seven")
    w, h = png_size(out)
    assert reloc.figures.MAX_COLUMNS == 2 and 900 <= w <= 1200 and h > w, (w, h)
    tops = [ax for ax in captured["wide.png"].axes if ax.get_title().startswith("method")]
    assert len(tops) == 7
    assert len({round(ax.get_position().x0, 3) for ax in tops}) == 2
    assert len({round(ax.get_position().y0, 3) for ax in tops}) == 4
