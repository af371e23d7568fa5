"""Camera paths: the shipped query and mapping paths, checked against geometry computed here.

Every check recomputes what it needs from the layouts (boxes, room rects, doors) with its own small
geometry helpers, not with the planner's grid or ``path_clearance``.
"""

from __future__ import annotations

import math

import matplotlib.image as mpimg
import numpy as np
import pytest

from vrformats.errors import SceneFormatError, UnknownNameError, UserError
from synth.cli import main as synth_main
from synth.paths.clearance import path_clearance
from synth.paths.files import load_path, save_path
from synth.paths.mapping import plan_mapping_path
from synth.paths.model import CameraPath
from synth.paths.query import plan_query_path
from synth.paths.shipped import replan
from synth.scene.model import load_layout, object_box


BUILTIN = [f"apt_{i}" for i in range(6)]
ROOMS = {"living", "kitchen", "bedroom", "bathroom", "hallway"}


@pytest.fixture(scope="module")
def layouts():
    return [load_layout(n) for n in BUILTIN]


@pytest.fixture(scope="module")
def query():
    return load_path("query")


@pytest.fixture(scope="module")
def mapping():
    return load_path("mapping")


# ---------------------------------------------------------------------------------------------
# independent geometry


def footprint_dist(p: np.ndarray, box) -> np.ndarray:
    """Horizontal distance of points (N, 2) to a box's rotated footprint rectangle (0 inside)."""
    c, s = math.cos(box.yaw), math.sin(box.yaw)
    d = p - np.asarray(box.center[:2])
    lx = d[:, 0] * c + d[:, 1] * s  # into the box frame
    ly = -d[:, 0] * s + d[:, 1] * c
    ex = np.maximum(np.abs(lx) - box.size[0] / 2, 0.0)
    ey = np.maximum(np.abs(ly) - box.size[1] / 2, 0.0)
    return np.hypot(ex, ey)


def box_dist_3d(P: np.ndarray, box) -> np.ndarray:
    h = footprint_dist(P[:, :2], box)
    v = np.maximum(np.maximum(box.zmin - P[:, 2], P[:, 2] - box.zmax), 0.0)
    return np.hypot(h, v)


def door_gaps(stage):
    """(axis, fixed coordinate, lo, hi, half depth) of every door joining two rooms."""
    out = []
    for op in stage.openings:
        if op.kind != "door" or len(op.rooms) < 2:
            continue
        w = stage.wall(op.wall)
        (x0, y0), (x1, y1) = w.start, w.end
        L = math.hypot(x1 - x0, y1 - y0)
        cx, cy = x0 + (x1 - x0) * op.offset / L, y0 + (y1 - y0) * op.offset / L
        if abs(y1 - y0) < 1e-9:  # wall along x
            out.append((0, cy, cx - op.width / 2, cx + op.width / 2, w.thickness / 2))
        else:
            out.append((1, cx, cy - op.width / 2, cy + op.width / 2, w.thickness / 2))
    return out


def wall_dist(p: np.ndarray, stage) -> np.ndarray:
    """Distance to the room rect edges, without the stretches where a door joins two rooms."""
    gaps = door_gaps(stage)
    best = np.full(len(p), np.inf)
    for r in stage.rooms:
        x0, y0, x1, y1 = r.rect
        for axis, fixed, lo, hi in ((0, y0, x0, x1), (0, y1, x0, x1), (1, x0, y0, y1), (1, x1, y0, y1)):
            pieces = [(lo, hi)]
            for g_axis, g_fixed, g_lo, g_hi, half in gaps:
                if g_axis == axis and abs(g_fixed - fixed) <= half + 0.05:
                    pieces = [q for a, b in pieces for q in ((a, min(b, g_lo)), (max(a, g_hi), b)) if q[1] > q[0]]
            for a, b in pieces:
                along = np.clip(p[:, axis], a, b)
                d = np.hypot(p[:, axis] - along, p[:, 1 - axis] - fixed)
                best = np.minimum(best, d)
    return best


def in_rooms_or_doors(p: np.ndarray, stage) -> np.ndarray:
    ok = np.zeros(len(p), bool)
    for r in stage.rooms:
        x0, y0, x1, y1 = r.rect
        ok |= (p[:, 0] >= x0) & (p[:, 0] <= x1) & (p[:, 1] >= y0) & (p[:, 1] <= y1)
    for axis, fixed, lo, hi, half in door_gaps(stage):
        ok |= (p[:, axis] >= lo) & (p[:, axis] <= hi) & (np.abs(p[:, 1 - axis] - fixed) <= half + 0.01)
    return ok


def rooms_of(p: np.ndarray, stage) -> list[str | None]:
    out = []
    for x, y in p[:, :2]:
        name = None
        for r in stage.rooms:
            if r.rect[0] <= x <= r.rect[2] and r.rect[1] <= y <= r.rect[3]:
                name = r.name
                break
        out.append(name)
    return out


def headings(path) -> tuple[np.ndarray, np.ndarray]:
    """Yaw and elevation (radians) of the optical axis (camera +z, OpenCV) of every pose."""
    z = path.poses[:, :3, 2]
    return np.arctan2(z[:, 1], z[:, 0]), np.arcsin(np.clip(z[:, 2], -1.0, 1.0))


def pitch_of(path) -> np.ndarray:
    return headings(path)[1]


def check_clearance(path, lays, clearance: float) -> float:
    """Assert the clearance rule in every layout: ``clearance`` metres horizontally from every wall
    and from the footprint of every object that is not ceiling-mounted (a person walking on the
    floor passes over nothing); returns the smallest clearance seen."""
    P = path.positions
    worst = np.inf
    for lay in lays:
        assert in_rooms_or_doors(P[:, :2], lay.stage).all(), f"camera outside the rooms in {lay.name}"
        wd = wall_dist(P[:, :2], lay.stage)
        assert wd.min() >= clearance, f"{lay.name}: {wd.min():.3f} m from a wall"
        worst = min(worst, wd.min())
        for o in lay.objects:
            if o.support == "ceiling":
                continue
            b = object_box(o)
            h = footprint_dist(P[:, :2], b)
            assert h.min() >= clearance, f"{lay.name}: {h.min():.3f} m from object {o.id} ({o.cls})"
            worst = min(worst, h.min())
            assert box_dist_3d(P, b).min() >= clearance
    return worst


def check_motion(path, speed=1.0):
    R = path.poses[:, :3, :3]
    assert np.allclose(np.einsum("nji,njk->nik", R, R), np.eye(3), atol=1e-6)
    assert np.allclose(np.linalg.det(R), 1.0, atol=1e-6)
    assert np.allclose(path.poses[:, 3, :], [0, 0, 0, 1])
    P = path.positions
    assert P[:, 2].min() >= 1.2 and P[:, 2].max() <= 1.7
    step = np.linalg.norm(np.diff(P, axis=0), axis=1)
    mean_speed = step.mean() * path.fps
    assert abs(mean_speed - speed) <= 0.1 * speed
    assert step.max() <= 2 * step.mean()
    yaw, elev = headings(path)
    rate = np.abs(np.diff(np.unwrap(yaw))) * path.fps
    assert np.degrees(rate.max()) <= 90.0 + 1e-6
    assert np.degrees(elev).min() >= -20.0 and np.degrees(elev).max() <= 10.0  # pitch of the optical axis
    assert np.degrees(elev).max() <= 30.0  # never looking steeply up
    # roll: the image x axis stays nearly level
    x = path.poses[:, :3, 0]
    assert np.degrees(np.abs(np.arcsin(np.clip(x[:, 2], -1, 1)))).max() <= 3.0


# ---------------------------------------------------------------------------------------------
# the shipped query path


def test_query_shape_and_motion(query):
    assert query.name == "query" and len(query) == 4000 and query.fps == 30.0
    assert query.meta["layouts"] == BUILTIN and query.meta["seed"] == 0
    check_motion(query)


def test_query_clear_of_objects_and_walls_in_every_layout(query, layouts):
    c = query.meta["planner"]["clearance_m"]
    assert c == 0.3 and query.meta["planner"]["obstacles"] == "all"
    worst = check_clearance(query, layouts, c)
    assert worst < c + 0.1  # the check is not vacuous: the path does get close to things
    for lay in layouts:  # the module's own measure agrees it is clear
        assert path_clearance(query, lay).min() >= c


def test_query_visits_every_room(query, layouts):
    seen = [r for r in rooms_of(query.positions, layouts[0].stage) if r]
    assert set(seen) == ROOMS
    counts = {r: seen.count(r) for r in ROOMS}
    assert min(counts.values()) >= 150, counts  # at least 5 s in each room


def test_infeasible_clearance_says_why(layouts):
    # 0.6 m from everything cannot pass 0.8 m doors: the error names the rooms and what is possible
    with pytest.raises(UserError, match=r"cannot be reached with 0.6 m clearance.*most these layouts allow is about 0\.[34]"):
        plan_query_path(layouts, frames=60, clearance=0.6)


def test_short_query_path(layouts):
    p = plan_query_path(layouts[:2], frames=60, seed=3)
    assert len(p) == 60
    check_motion(p)
    check_clearance(p, layouts[:2], 0.3)


# ---------------------------------------------------------------------------------------------
# the shipped mapping path


def test_mapping_covers_every_room_from_several_directions(mapping, layouts):
    apt0 = layouts[0]
    assert len(mapping) == 6000 and mapping.meta["layouts"] == ["apt_0"]
    check_motion(mapping)
    check_clearance(mapping, [apt0], 0.3)
    rooms = rooms_of(mapping.positions, apt0.stage)
    yaw, _ = headings(mapping)
    quadrant = np.round(yaw / (math.pi / 2)).astype(int) % 4  # +x, +y, -x, -y
    for room in ROOMS:
        m = np.array([r == room for r in rooms])
        assert m.sum() >= 300, f"{room}: {m.sum()} frames"
        q, n = np.unique(quadrant[m], return_counts=True)
        assert (n >= 30).sum() >= 3, f"{room}: heading quadrants {dict(zip(q.tolist(), n.tolist()))}"


@pytest.mark.slow
def test_mapping_keeps_all_rooms_when_short():
    apt0 = load_layout("apt_0")
    p = plan_mapping_path(apt0, frames=2700, seed=1)
    assert len(p) == 2700
    assert p.meta["planner"]["sweep_spacing_m"] > 1.0  # sparser sweeps instead of dropping rooms
    assert {r for r in rooms_of(p.positions, apt0.stage) if r} == ROOMS
    with pytest.raises(UserError, match="cannot cover every room"):
        plan_mapping_path(apt0, frames=300)


# ---------------------------------------------------------------------------------------------
# no drift: the shipped files are what the planner makes now


@pytest.mark.slow
def test_shipped_paths_are_what_the_planner_makes(query, mapping):
    for saved in (query, mapping):
        again = replan(saved)
        assert len(again) == len(saved)
        assert np.abs(again.poses[:, :3, 3] - saved.poses[:, :3, 3]).max() < 2e-6, saved.name
        assert np.abs(again.poses[:, :3, :3] - saved.poses[:, :3, :3]).max() < 1e-6, saved.name
        # stats are printed rounded (length mm, clearance 0.1 mm): last-bit noise on another
        # processor may move a value across a rounding boundary, so allow one unit of the last place
        sa, sb = again.meta["stats"], saved.meta["stats"]
        assert sa.keys() == sb.keys() and sa["rooms"] == sb["rooms"]
        for key, unit in (("length_m", 1e-3), ("duration_s", 1e-3), ("min_clearance_m", 1e-4)):
            assert sa[key] == pytest.approx(sb[key], abs=1.01 * unit), (saved.name, key)
        assert again.meta["planner"] == saved.meta["planner"]


# ---------------------------------------------------------------------------------------------
# files


def test_save_load_round_trip(tmp_path, query):
    short = CameraPath("q60", query.poses[:60].copy(), 30.0, dict(query.meta))
    f = save_path(short, tmp_path / "sub" / "q60.txt")
    assert f.exists() and f.with_suffix(".yaml").exists()
    back = load_path(f)
    assert back.name == "q60" and back.fps == 30.0 and len(back) == 60
    assert np.abs(back.poses - short.poses).max() < 1e-6
    assert back.meta["layouts"] == BUILTIN and back.meta["seed"] == 0
    assert back.meta["planner"] == query.meta["planner"]
    assert load_path(f.with_suffix(".yaml")).name == "q60"  # the sidecar names the same path
    # fps from the sidecar sets the timestamps
    p24 = CameraPath("p24", query.poses[:10].copy(), 24.0, {})
    back24 = load_path(save_path(p24, tmp_path / "p24.txt"))
    assert back24.fps == 24.0 and np.abs(back24.poses - p24.poses).max() < 1e-6


def test_unknown_name_lists_known_paths():
    with pytest.raises(UnknownNameError) as e:
        load_path("no_such_path")
    msg = str(e.value)
    assert "no_such_path" in msg and "query" in msg and "mapping" in msg


def test_malformed_files_name_file_and_line(tmp_path, query):
    f = save_path(CameraPath("bad", query.poses[:5].copy(), 30.0, {}), tmp_path / "bad.txt")
    lines = f.read_text().splitlines()
    lines[4] = "0.1 1.0 2.0 oops 0 0 0 1"  # the third pose (after two comment lines)
    f.write_text("\n".join(lines) + "\n")
    with pytest.raises(SceneFormatError) as e:
        load_path(f)
    assert "bad.txt" in str(e.value) and "line 5" in str(e.value)
    f.with_suffix(".yaml").write_text("format: synth-camera-path/1\nname: bad\nfps: fast\n")
    with pytest.raises(SceneFormatError, match=r"bad\.yaml: fps"):
        load_path(f)


# ---------------------------------------------------------------------------------------------
# command line


def test_cli_show_and_preview(tmp_path, capsys):
    assert synth_main(["path", "show", "query"]) == 0
    out = capsys.readouterr().out
    assert "4000" in out and "133.3 s" in out
    for room in ROOMS:
        assert room in out
    png = tmp_path / "q.png"
    assert synth_main(["path", "preview", "query", "--layout", "apt_0", "--out", str(png)]) == 0
    img = mpimg.imread(png)
    assert img.shape[0] > 500 and img.shape[1] > 500
    assert synth_main(["path", "show", "nope"]) == 2
    assert "known paths" in capsys.readouterr().err


def test_cli_plan(tmp_path, capsys):
    out = tmp_path / "m.txt"
    assert synth_main(["path", "plan", "query", "--layouts", "apt_0", "apt_3", "--frames", "90", "--clearance", "0.25",
                       "--seed", "2", "--out", str(out)]) == 0
    p = load_path(out)
    assert len(p) == 90 and p.meta["layouts"] == ["apt_0", "apt_3"] and p.meta["seed"] == 2
    assert synth_main(["path", "plan", "mapping", "--layout", "apt_0", "--frames", "100", "--out", str(out)]) == 2
    assert "cannot cover every room" in capsys.readouterr().err


def test_deterministic_given_seed(layouts):
    a = plan_query_path(layouts[:1], frames=120, seed=5)
    b = plan_query_path(layouts[:1], frames=120, seed=5)
    c = plan_query_path(layouts[:1], frames=120, seed=6)
    assert np.array_equal(a.poses, b.poses)
    assert not np.allclose(a.poses, c.poses)


def test_planner_defaults_have_one_home():
    """synth.paths.model.DEFAULTS is what the planners, synth path plan and the shipped paths use."""
    import inspect

    from synth.cli import build_parser
    from synth.paths.model import DEFAULTS
    from synth.paths.shipped import SHIPPED, plan_path
    from synth.paths.views import plan_views

    d = DEFAULTS
    want = {"seed": d.seed, "fps": d.fps, "speed": d.speed, "clearance": d.clearance, "obstacles": d.obstacles}
    for fn, frames in ((plan_query_path, d.query_frames), (plan_mapping_path, d.mapping_frames), (plan_path, None),
                       (plan_views, d.views_frames)):
        ps = inspect.signature(fn).parameters
        for k, v in want.items():
            assert k not in ps or ps[k].default == v, (fn.__name__, k)
        if frames is not None:
            assert ps["frames"].default == frames, fn.__name__
    p = build_parser()
    for kind, frames, lay in (("query", d.query_frames, ["--layouts", "apt_0"]), ("mapping", d.mapping_frames, ["--layout", "apt_0"])):
        a = p.parse_args(["path", "plan", kind, *lay, "--out", "x.txt"])
        assert (a.frames, a.seed, a.fps, a.speed, a.clearance, a.obstacles) == (frames, d.seed, d.fps, d.speed, d.clearance,
                                                                                d.obstacles)
    assert SHIPPED["query"]["frames"] == d.query_frames and SHIPPED["mapping"]["frames"] == d.mapping_frames
