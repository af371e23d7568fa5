"""The paper's selection rules (Secs. III-D, III-E) on constructed repeated layouts.

* S_g is the hypothesis with the most one-to-one same-class center pairs, then the lowest RMS,
  over all hypotheses (not over a shortlist ranked by a count that lets several clip objects
  match one map object);
* the orientation fallback takes the translation with the most one-to-one inliers;
* a frame anchor's "at least six inliers" counts objects, not walls, floors or ceilings;
* the Manhattan yaw cue needs five distinct walls, not one wall seen five times.

Each layout is built here so that the shortcut and the rule disagree, and the expected answer is
the transform the layout was built with.
"""

from __future__ import annotations

import math

import numpy as np

from reloc import geometry as G
from reloc.frontend.clips import Node
from reloc.config import Config
from reloc.map.boxmap import BoxMap
from reloc.frontend.observations import Observation
from reloc.frontend.refinement import Gravity, orientation_aware
from reloc.frontend.registration import anchors_for_clip, fallback_candidates, frame_anchor, graph_candidate

SINGLETONS = {"sofa": (-3.0, 2.0), "table": (2.5, -1.5), "lamp": (-1.0, -2.5), "plant": (3.5, 2.5),
              "tv": (0.0, 3.5)}


def _box(i, cls, center, size, kind="object", yaw=0.0, movable=True) -> dict:
    return {"id": i, "class": cls, "kind": kind, "center": [float(x) for x in center],
            "size": [float(x) for x in size], "yaw": float(yaw), "movable": movable}


def _map(boxes) -> BoxMap:
    return BoxMap({"format": "videoreloc-boxes/1", "layout": "test", "classes": {}, "boxes": boxes})


def _node(cls, center_map, S_true, rng, size=0.3) -> Node:
    """A fused node whose center is ``center_map`` when the clip is placed by S_true."""
    c = np.asarray(center_map, float)
    P = c + rng.uniform(-size / 2, size / 2, (12, 3))
    Sinv = G.inv_T(S_true)
    return Node(cls=cls, center=G.apply(Sinv, c), samples=G.apply(Sinv, P), n_obs=2, frames=[0])


def _pile(center, radius, n, phase=0.0) -> np.ndarray:
    a = phase + 2 * math.pi * np.arange(n) / n
    return np.asarray(center, float) + radius * np.column_stack([np.cos(a), np.sin(a), np.zeros(n)])


def shelf_library(n_piles=40):
    """Five distinct-class objects and a library of 3-book piles, 2 m apart: a repeated layout."""
    boxes = [_box(k + 1, cls, (x, y, 0.4), (0.6, 0.6, 0.8)) for k, (cls, (x, y)) in enumerate(SINGLETONS.items())]
    i = 100
    for p in range(n_piles):
        c = (-12.0 + 2.0 * (p % 10), 8.0 + 2.0 * (p // 10), 1.0)
        for b in _pile(c, 0.17, 3, phase=0.3 * p):
            boxes.append(_box(i, "book", b, (0.2, 0.15, 0.05)))
            i += 1
    return _map(boxes)


def test_graph_candidate_picks_most_one_to_one_matches_over_all_hypotheses():
    """Eight books lie in a tight heap on a table (moved off the shelves): every hypothesis that
    drops the heap onto one 3-book pile has 8 clip books within 0.5 m of a map book (the
    many-to-one count) but only 3 one-to-one pairs. The five singletons, placed right, give 5
    one-to-one pairs. Most one-to-one pairs must win."""
    m = shelf_library()
    rng = np.random.default_rng(5)
    S_true = G.make_T(G.rot_z(0.7), [0.4, -0.3, 0.0])
    nodes = [_node(cls, (x, y, 0.4), S_true, rng) for cls, (x, y) in SINGLETONS.items()]
    nodes += [_node("book", p, S_true, rng, size=0.1) for p in _pile((0.0, 0.0, 0.8), 0.2, 8)]
    c = graph_candidate(nodes, m, Config().registration, np.random.default_rng(0))
    assert c is not None
    assert c.matches == 5
    dt, dr = G.pose_distance(c.S, S_true)
    assert dt < 0.05 and math.degrees(dr) < 1.0, (dt, math.degrees(dr))


def test_fallback_translation_has_most_one_to_one_inliers():
    """The orientation fallback with the right yaw: four books in a heap, one book in the map.
    Pairing a clip book with the map book drops all four near it (many-to-one count 4, one
    pair); the sofa and table pairs give two one-to-one inliers and the true translation."""
    boxes = [_box(1, "sofa", (-3.0, 2.0, 0.4), (1.8, 0.9, 0.8)), _box(2, "table", (2.5, -1.5, 0.4), (1.2, 0.8, 0.8)),
             _box(3, "book", (4.0, 4.0, 1.0), (0.2, 0.15, 0.05)),
             _box(10, "wall", (0, 5, 1.3), (12, 0.2, 2.6), kind="wall", movable=False)]
    m = _map(boxes)
    rng = np.random.default_rng(1)
    yaw = 0.4
    S_true = G.make_T(G.rot_z(yaw), [1.0, -0.5, 0.0])
    nodes = [_node("sofa", (-3.0, 2.0, 0.4), S_true, rng, 0.8), _node("table", (2.5, -1.5, 0.4), S_true, rng, 0.6)]
    nodes += [_node("book", p, S_true, rng, 0.1) for p in _pile((-1.0, 0.0, 0.8), 0.15, 4)]
    # one wall direction seen in the clip frame: the map's x axis, rotated into the clip
    wall_dir = G.rot_z(-yaw) @ np.array([1.0, 0.0, 0.0])
    yaws = np.array([math.atan2(wall_dir[1], wall_dir[0])])
    cands = fallback_candidates(nodes, m, Config().registration, np.eye(3), yaws, yaw_prior=yaw)
    assert len(cands) == 1 and cands[0].matches == 2
    dt, dr = G.pose_distance(cands[0].S, S_true)
    assert dt < 0.05 and math.degrees(dr) < 1e-6


def _room_with_objects():
    objs = [("sofa", (-3.0, 2.0, 0.4)), ("table", (2.5, -1.5, 0.4)), ("lamp", (-1.0, -2.5, 0.4)),
            ("plant", (3.5, 2.5, 0.4))]
    boxes = [_box(k + 1, c, p, (0.6, 0.6, 0.8)) for k, (c, p) in enumerate(objs)]
    boxes += [_box(10, "wall", (0, 4, 1.3), (10, 0.2, 2.6), kind="wall", movable=False),
              _box(11, "wall", (5, 0, 1.3), (0.2, 8, 2.6), kind="wall", movable=False),
              _box(12, "floor", (0, 0, -0.05), (10, 8, 0.1), kind="floor", movable=False)]
    return _map(boxes), objs


def _obs(cls, center_map, samples_map, W, frame):
    Winv = G.inv_T(W)
    return Observation(frame=frame, cls=cls, center=G.apply(Winv, np.asarray(center_map, float)),
                       samples=G.apply(Winv, np.asarray(samples_map, float)), n_points=200)


def test_frame_anchor_counts_object_inliers_only():
    """Four objects and three room surfaces fit: seven box-surface inliers, but only four
    objects, fewer than the six an anchor needs."""
    m, objs = _room_with_objects()
    rng = np.random.default_rng(2)
    W = G.make_T(G.rot_z(0.3) @ np.array([[1.0, 0, 0], [0, 0, 1], [0, -1, 0]]), [0.5, 0.2, 1.4])
    obs = [_obs(c, p, np.asarray(p) + rng.uniform(-0.25, 0.25, (12, 3)), W, 0) for c, p in objs]
    wall_a = np.column_stack([rng.uniform(-4, 4, 12), np.full(12, 3.9), rng.uniform(0.2, 2.4, 12)])
    wall_b = np.column_stack([np.full(12, 4.9), rng.uniform(-3, 3, 12), rng.uniform(0.2, 2.4, 12)])
    floor = np.column_stack([rng.uniform(-4, 4, 12), rng.uniform(-3, 3, 12), np.zeros(12)])
    for cls, P in (("wall", wall_a), ("wall", wall_b), ("floor", floor)):
        obs.append(_obs(cls, P.mean(axis=0), P, W, 0))
    cfg = Config().registration
    r = frame_anchor(0, obs, m, cfg, np.random.default_rng(0))
    assert r is not None
    T, inliers, rmse = r
    assert inliers == 4
    assert G.pose_distance(T, W)[0] < 0.05
    assert anchors_for_clip({0: obs}, {0: np.eye(4)}, m, cfg, np.random.default_rng(0)) == []


def _wall_node(normals, center=(0.0, 0.0, 1.3)) -> Node:
    return Node(cls="wall", center=np.asarray(center, float), samples=np.empty((0, 3)), n_obs=len(normals),
                frames=[0], normals=np.asarray(normals, float))


def test_manhattan_yaw_counts_distinct_walls():
    """One wall seen five times is one wall, not five normals' worth of consensus: no yaw
    correction. Five distinct walls (fused wall nodes) do correct the yaw."""
    m, _ = _room_with_objects()
    S_off = G.make_T(G.rot_z(math.radians(6)), [0.0, 0.0, 0.0])
    rng = np.random.default_rng(3)
    cfg = Config()
    up = Gravity(np.array([0.0, 0.0, 1.0]), "structure")
    one_wall = [_wall_node([G.rot_z(rng.normal(0, 0.01)) @ [0.0, 1.0, 0.0] for _ in range(5)])]
    S1, info1 = orientation_aware(S_off, one_wall, m, cfg.refinement, cfg.registration, up)
    assert not info1["manhattan"]["accepted"]
    assert abs(math.degrees(G.yaw_of(S1[:3, :3])) - 6.0) < 0.01
    dirs = ([0.0, 1.0, 0.0], [1.0, 0.0, 0.0], [0.0, -1.0, 0.0], [-1.0, 0.0, 0.0], [0.0, 1.0, 0.0])
    walls = [_wall_node([v], center=(k, 0.0, 1.3)) for k, v in enumerate(dirs)]
    S5, info5 = orientation_aware(S_off, walls, m, cfg.refinement, cfg.registration, up)
    assert info5["manhattan"]["accepted"]
    assert abs(math.degrees(G.yaw_of(S5[:3, :3]))) < 0.01


def test_pruned_selection_equals_brute_force():
    """The many-to-one bound stops the evaluation early but never changes the winner."""
    from reloc.frontend.registration import CenterMatcher, _rmse, select_hypothesis

    rng = np.random.default_rng(11)
    classes = ["chair", "book", "lamp"]
    boxes = [_box(i + 1, classes[i % 3], rng.uniform(-3, 3, 3), (0.4, 0.4, 0.4)) for i in range(18)]
    m = _map(boxes)
    for trial in range(20):
        cls = [classes[k % 3] for k in range(9)]
        X = rng.uniform(-3, 3, (9, 3))
        matcher = CenterMatcher(m, cls, X)
        Ts = np.stack([G.make_T(G.rot_z(rng.uniform(-3, 3)), rng.uniform(-1, 1, 3)) for _ in range(300)])
        d = matcher.distances(Ts)
        h, pairs = select_hypothesis(matcher, d, 0.8)
        keys = [(len(p), -_rmse(p)) for p in (matcher.greedy(row, 0.8) for row in d)]
        assert (len(pairs), -_rmse(pairs)) == max(keys)
        assert keys[h] == max(keys)
