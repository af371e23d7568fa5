"""reloc's geometry, map, surface score, registration and refinement against known answers.

Every check builds its input from a transform or box chosen here and compares the result with
that choice (an independent computation), never with another output of the same code.
"""

from __future__ import annotations

import dataclasses
import json
import math

import numpy as np
import pytest

from reloc import geometry as G
from reloc.frontend.clips import ClipPolicy, Node, fuse
from reloc.config import ClipConfig, Config
from reloc.map.boxmap import BoxMap, circular_median_mod
from reloc.frontend.observations import Observation, observe
from reloc.detection.base import Detection
from reloc.frontend.refinement import Gravity, estimate_gravity, manhattan_correction, orientation_aware, tilt_deg
from reloc.frontend.registration import (anchor_candidate, anchors_for_clip, anchors_veto, fallback_candidates,
                                graph_candidate)
from reloc.frontend.surface import SurfaceScorer, kappa

from vrformats.errors import SceneFormatError, UserError

RNG = np.random.default_rng(1)


def random_T(rng, max_angle=math.pi, t_scale=3.0) -> np.ndarray:
    axis = rng.normal(size=3)
    axis /= np.linalg.norm(axis)
    return G.make_T(G.exp_so3(axis * rng.uniform(0, max_angle)), rng.normal(size=3) * t_scale)


def yaw_T(yaw, t) -> np.ndarray:
    return G.make_T(G.rot_z(yaw), t)


def box(i, cls, center, size, yaw=0.0, kind="object", movable=True) -> dict:
    return {"id": i, "class": cls, "kind": kind, "center": list(map(float, center)), "size": list(map(float, size)),
            "yaw": float(yaw), "movable": movable}


def doc(boxes) -> dict:
    return {"format": "videoreloc-boxes/1", "layout": "test", "classes": {}, "boxes": boxes}


def room_map(n_objects=24, seed=3, with_walls=True, manhattan=0.0) -> BoxMap:
    """A 10 x 8 m room (rotated by `manhattan`) with walls, a floor and scattered objects."""
    rng = np.random.default_rng(seed)
    classes = ["chair", "table", "lamp", "plant", "book", "sofa"]
    boxes = []
    R = G.rot_z(manhattan)
    for i in range(n_objects):
        c = R @ np.array([rng.uniform(-4.5, 4.5), rng.uniform(-3.5, 3.5), 0])
        size = rng.uniform(0.3, 1.2, 3)
        c[2] = size[2] / 2
        boxes.append(box(i + 1, classes[i % len(classes)], c, size, manhattan + rng.uniform(-0.3, 0.3),
                         movable=(i % 4 != 0)))
    if with_walls:
        for k, (c, s, yaw) in enumerate([((0, 4, 1.3), (10, 0.2, 2.6), 0.0), ((0, -4, 1.3), (10, 0.2, 2.6), 0.0),
                                         ((5, 0, 1.3), (8, 0.2, 2.6), math.pi / 2),
                                         ((-5, 0, 1.3), (0.2, 8, 2.6), 0.0)]):
            boxes.append(box(1000 + k, "wall", R @ np.array(c), s, yaw + manhattan, kind="wall", movable=False))
        boxes.append(box(2000, "floor", (0, 0, -0.05), (10, 8, 0.1), manhattan, kind="floor", movable=False))
    return BoxMap(doc(boxes))


def surface_samples(bmap: BoxMap, j: int, n: int, rng, top_only=False) -> np.ndarray:
    """Points on the surface of map box j (map frame)."""
    c, s, yaw = bmap.box(j)
    local = rng.uniform(-0.5, 0.5, (n, 3)) * s
    ax = rng.integers(0, 3, n)
    sign = rng.choice([-1, 1], n)
    local[np.arange(n), ax] = sign * s[ax] / 2
    return G.from_box_frame(local, c, yaw)


def nodes_from_map(bmap: BoxMap, S_true: np.ndarray, rng, noise=0.02, ids=None, samples=12) -> list[Node]:
    """Nodes as a clip would see the map's boxes when the clip->map transform is S_true."""
    Sinv = G.inv_T(S_true)
    out = []
    ids = range(len(bmap)) if ids is None else ids
    for j in ids:
        if bmap.kinds[j] != "object":
            continue
        P = surface_samples(bmap, j, samples, rng)
        c = bmap.centers[j] + rng.normal(scale=noise, size=3)
        out.append(Node(cls=bmap.classes[j], center=G.apply(Sinv, c), samples=G.apply(Sinv, P), n_obs=3, frames=[0]))
    return out


def assert_pose_close(A, B, t_tol, r_tol_deg):
    dt, dr = G.pose_distance(A, B)
    assert dt <= t_tol, f"translation off by {dt:.3f} m"
    assert math.degrees(dr) <= r_tol_deg, f"rotation off by {math.degrees(dr):.2f} deg"


# --------------------------------------------------------------------------------------------
# geometry


def test_rigid_fit_recovers_known_transform():
    rng = np.random.default_rng(0)
    for _ in range(5):
        T = random_T(rng)
        x = rng.normal(size=(10, 3))
        y = G.apply(T, x)
        assert np.allclose(G.rigid_fit(x, y), T, atol=1e-9)
        assert np.allclose(G.rigid_fit_batch(x[None, :3], y[None, :3])[0], T, atol=1e-9)


def test_so3_log_exp_round_trip_and_angle():
    rng = np.random.default_rng(2)
    for ang in (1e-8, 0.3, 2.0, math.pi - 1e-3):
        w = rng.normal(size=3)
        w = w / np.linalg.norm(w) * ang
        R = G.exp_so3(w)
        assert abs(G.rot_angle(R) - ang) < 1e-6
        assert np.allclose(G.exp_so3(G.log_so3(R)), R, atol=1e-6)


# boxes of several yaws (one a quarter turn, one past pi), checked all at once
BOX_CENTERS = np.array([[1.0, -2.0, 0.5], [-3.0, 0.5, 1.2], [0.2, 4.0, -0.7], [2.5, 2.5, 0.0]])
BOX_SIZES = np.array([[2.0, 1.0, 0.6], [0.4, 1.8, 1.1], [1.2, 1.2, 0.3], [0.7, 2.5, 1.6]])
BOX_YAWS = np.array([0.7, -2.3, math.pi / 2, 3.6])


def test_point_box_distance_matches_brute_force():
    """The production BoxSet (surface score, refinement) against the nearest of dense samples of
    each solid box (surface and interior), every point against every box in one call."""
    rng = np.random.default_rng(5)
    boxes = G.BoxSet(BOX_CENTERS, BOX_SIZES, BOX_YAWS)
    g = np.stack(np.meshgrid(*[np.linspace(-0.5, 0.5, 31)] * 3, indexing="ij"), -1).reshape(-1, 3)
    pts = np.concatenate([c + rng.normal(scale=1.5, size=(40, 3)) for c in BOX_CENTERS]
                         + [(rng.uniform(-0.45, 0.45, (5, 3)) * s) @ G.rot_z(yaw).T + c
                            for c, s, yaw in zip(BOX_CENTERS, BOX_SIZES, BOX_YAWS)])  # and some inside
    brute = np.empty((len(pts), len(boxes)))
    for j, (c, s, yaw) in enumerate(zip(BOX_CENTERS, BOX_SIZES, BOX_YAWS)):
        solid = (g * s) @ G.rot_z(yaw).T + c  # rotation matrix, not the box code's cos/sin
        brute[:, j] = np.min(np.linalg.norm(pts[:, None] - solid[None], axis=2), axis=1)
    d = boxes.distance(pts[:, None, :])  # (P, B)
    assert d.shape == brute.shape
    spacing = np.linalg.norm(BOX_SIZES / 30 / 2, axis=1)  # farthest any box point is from a sample
    assert np.all(d <= brute + 1e-12) and np.all(brute - d <= spacing + 1e-12)
    assert (d == 0).sum() >= 20 and (d > 0).sum() >= 100  # inside and outside points were drawn
    assert np.array_equal(G.point_boxes_distance(pts, BOX_CENTERS, BOX_SIZES, BOX_YAWS), d)
    assert np.allclose(boxes.sq_distance(pts[:, None, :]), d**2, rtol=1e-12, atol=1e-15)
    # the refinement's excess: leads back to a point of the box at exactly that distance
    e = boxes.excess(pts[:, None, :])  # (P, B, 3) box frame
    q = pts[:, None, :] - np.einsum("bij,pbj->pbi", boxes.rotation(), e)
    assert np.allclose(np.linalg.norm(e, axis=2), d, rtol=1e-12, atol=1e-12)
    assert np.all(boxes.distance(q) < 1e-9)
    # element-wise pairing with a batch (the scorer's (H, E) layout), and single boxes
    idx = rng.integers(0, len(boxes), (3, 25))
    X = rng.normal(scale=3.0, size=(3, 25, 3))
    dd = boxes[idx].distance(X)
    for h in range(3):
        for i in range(25):
            j = idx[h, i]
            assert np.isclose(dd[h, i], boxes[j].distance(X[h, i]), rtol=1e-12, atol=1e-12)
            brute1 = np.min(np.linalg.norm((g * BOX_SIZES[j]) @ G.rot_z(BOX_YAWS[j]).T + BOX_CENTERS[j] - X[h, i], axis=1))
            assert dd[h, i] <= brute1 + 1e-12 and brute1 - dd[h, i] <= spacing[j] + 1e-12


def test_point_box_distance_closed_form_inside_faces_corners():
    """Points built from a known closest box point q plus an offset in q's outward normal cone are
    at exactly |offset|: inside (0), on faces (0), off faces, off edges, off and near corners."""
    rng = np.random.default_rng(6)
    boxes = G.BoxSet(BOX_CENTERS, BOX_SIZES, BOX_YAWS)
    for j, (c, s, yaw) in enumerate(zip(BOX_CENTERS, BOX_SIZES, BOX_YAWS)):
        h = s / 2
        local, offsets = [], []
        for _ in range(60):  # strictly inside and on a face
            p = rng.uniform(-0.99, 0.99, 3) * h
            local.append(p.copy()), offsets.append(np.zeros(3))
            a = rng.integers(3)
            p[a] = rng.choice([-1, 1]) * h[a]
            local.append(p), offsets.append(np.zeros(3))
        for _ in range(200):  # q on a face, an edge or a corner; offset along its outward normals
            n_ext = rng.integers(1, 4)  # 1 face, 2 edge, 3 corner
            axes = rng.permutation(3)[:n_ext]
            sign = rng.choice([-1.0, 1.0], 3)
            q = rng.uniform(-1, 1, 3) * h
            q[axes] = sign[axes] * h[axes]
            off = np.zeros(3)
            off[axes] = sign[axes] * rng.choice([1e-6, 1e-3, 0.05, 0.7, 3.0], n_ext)
            local.append(q + off), offsets.append(off)
        local, offsets = np.array(local), np.array(offsets)
        want = np.sqrt(np.sum(offsets**2, axis=1))
        pts = local @ G.rot_z(yaw).T + c
        d = boxes[j].distance(pts)
        assert np.allclose(d, want, rtol=1e-9, atol=1e-12)
        assert np.all(d[want == 0] <= 1e-12)
        # the same points through the all-boxes call, column j
        assert np.array_equal(boxes.distance(pts[:, None, :])[:, j], d)
        # the refinement's per-axis excess in the box frame: the offset itself
        assert np.allclose(boxes[j].excess(pts), offsets, rtol=1e-9, atol=1e-12)


def test_farthest_point_sample_spreads_out():
    pts = np.concatenate([np.zeros((100, 3)), np.array([[5.0, 0, 0], [0, 5.0, 0], [0, 0, 5.0]])])
    idx = G.farthest_point_sample(pts, 4)
    assert {100, 101, 102} <= set(idx.tolist()) and len(set(idx.tolist())) == 4


# --------------------------------------------------------------------------------------------
# map


def test_map_triangle_index_matches_brute_force():
    m = room_map(n_objects=10, with_walls=True)
    cfg = m.config
    obj = list(m.object_nodes)
    expected = {}
    for a in range(len(obj)):
        for b in range(a + 1, len(obj)):
            for c in range(b + 1, len(obj)):
                i, j, k = obj[a], obj[b], obj[c]
                P = m.centers[[i, j, k]]
                e = [np.linalg.norm(P[0] - P[1]), np.linalg.norm(P[0] - P[2]), np.linalg.norm(P[1] - P[2])]
                if min(e) < cfg.triangle_edge_min_m or max(e) > cfg.triangle_edge_max_m:
                    continue
                # smallest angle via the law of cosines
                angs = []
                for (x, y, z) in ((e[0], e[1], e[2]), (e[0], e[2], e[1]), (e[1], e[2], e[0])):
                    angs.append(math.degrees(math.acos(np.clip((x * x + y * y - z * z) / (2 * x * y), -1, 1))))
                if min(angs) < cfg.triangle_min_angle_deg:
                    continue
                expected[frozenset((i, j, k))] = sorted(e)
    got = {}
    for key, ts in m.triangles.items():
        assert list(key) == sorted(key)
        for v, e in zip(ts.verts, ts.edges):
            assert [m.classes[x] for x in v] == list(key)  # vertex order follows the class key
            P = m.centers[v]
            assert np.allclose(e, [np.linalg.norm(P[0] - P[1]), np.linalg.norm(P[0] - P[2]), np.linalg.norm(P[1] - P[2])])
            got[frozenset(v.tolist())] = sorted(e)
    assert set(got) == set(expected)
    assert m.triangle_count() == len(expected)
    assert all(np.allclose(got[k], expected[k]) for k in expected)
    assert all(m.kinds[i] == "object" and m.kinds[j] == "object" for i, j in m.edges)


@pytest.mark.parametrize("yaw_deg", [0.0, 17.0, -30.0, 44.0])
def test_manhattan_yaw_of_rotated_room(yaw_deg):
    m = room_map(manhattan=math.radians(yaw_deg))
    got = math.degrees(m.manhattan_yaw)
    diff = (got - yaw_deg + 45) % 90 - 45
    assert abs(diff) < 1e-6


def test_manhattan_is_extent_weighted():
    # one long wall at 10 deg outweighs two short walls at 30 deg
    boxes = [box(1, "wall", (0, 0, 1), (8, 0.2, 2), math.radians(10), kind="wall"),
             box(2, "wall", (3, 3, 1), (1, 0.2, 2), math.radians(30), kind="wall"),
             box(3, "wall", (3, -3, 1), (0.2, 1, 2), math.radians(30), kind="wall")]
    assert abs(math.degrees(BoxMap(doc(boxes)).manhattan_yaw) - 10) < 1e-6
    assert abs(math.degrees(circular_median_mod(np.radians([89.0, 1.0, 2.0]), period=math.pi / 2)) - 1.0) < 1e-6


def test_gt_map_of_apt0_is_small_and_complete(tmp_path):
    from synth.scene.model import boxes_document, load_layout

    d = boxes_document(load_layout("apt_0"))
    p = tmp_path / "map.json"
    p.write_text(json.dumps(d))
    m = BoxMap.load(p)
    assert m.size_bytes <= 150_000
    s = m.summary()
    assert s["kinds"]["wall"] > 0 and s["kinds"]["floor"] > 0 and s["kinds"]["object"] >= 90
    assert s["triangles"] > 1000


@pytest.mark.parametrize("mutate, field", [
    (lambda d: d.update(format="other"), "format"),
    (lambda d: d["boxes"][0].pop("center"), "boxes[0].center"),
    (lambda d: d["boxes"][1].update(id=d["boxes"][0]["id"]), "boxes[1].id"),
    (lambda d: d["boxes"][0].update(size=[1, -1, 1]), "boxes[0].size"),
    (lambda d: d["boxes"][0].update(kind="door"), "boxes[0].kind"),
    (lambda d: d["boxes"][0].update(yaw="north"), "boxes[0].yaw"),
])
def test_map_errors_name_file_and_field(tmp_path, mutate, field):
    d = doc([box(1, "chair", (0, 0, 0), (1, 1, 1)), box(2, "sofa", (2, 0, 0), (1, 1, 1))])
    mutate(d)
    p = tmp_path / "bad.json"
    p.write_text(json.dumps(d))
    with pytest.raises(UserError) as e:
        BoxMap.load(p)
    assert str(p) in str(e.value) and field in str(e.value)


def test_map_missing_and_not_json(tmp_path):
    with pytest.raises(UserError, match="not found"):
        BoxMap.load(tmp_path / "nope.json")
    (tmp_path / "x.json").write_text("{oops")
    with pytest.raises(UserError, match="not valid JSON"):
        BoxMap.load(tmp_path / "x.json")


def test_empty_map_loads():
    m = BoxMap(doc([]))
    assert len(m) == 0 and m.triangle_count() == 0 and m.manhattan_yaw == 0.0


# --------------------------------------------------------------------------------------------
# box-surface consistency (Eq. 2)


def test_rho_and_kappa_known_offsets():
    m = BoxMap(doc([box(1, "chair", (0, 0, 0.5), (1, 1, 1)), box(2, "chair", (5, 0, 0.5), (1, 1, 1)),
                    box(3, "sofa", (0, 5, 0.5), (2, 1, 1))]))
    inside = np.array([[0.1, 0.1, 0.5], [-0.2, 0.3, 0.2]])
    off = np.array([[5.8, 0.0, 0.5], [5.8, 0.2, 0.3]])  # 0.3 m outside the second chair's +x face
    far = np.array([[0.0, 9.0, 0.5]])  # a sofa sample 3.5 m beyond its box
    sc = SurfaceScorer(m, ["chair", "chair", "sofa", "table"], [inside, off, far, inside])
    rho, asg = sc.rho(np.eye(4)[None])
    assert rho[0, 0] == 0.0 and asg[0, 0] == 0
    assert abs(rho[0, 1] - 0.3) < 1e-9 and asg[0, 1] == 1
    assert abs(rho[0, 2] - 3.5) < 1e-9
    assert np.isinf(rho[0, 3]) and asg[0, 3] == -1  # no table in the map
    assert kappa(rho, 0.5)[0] == 0.5  # two of four instances pass
    # shifting everything by +1 m in x moves the inside chair out by 0.6 m (box half-size 0.5)
    rho2, _ = sc.rho(yaw_T(0.0, [1.0, 0, 0])[None])
    assert abs(rho2[0, 0] - math.sqrt((0.6 ** 2 + 0.3 ** 2) / 2)) < 1e-9


# --------------------------------------------------------------------------------------------
# registration


def test_graph_candidate_recovers_clip_placement():
    m = room_map(n_objects=30)
    rng = np.random.default_rng(7)
    S_true = yaw_T(1.1, [2.0, -1.0, 0.0]) @ G.make_T(G.exp_so3([0.02, -0.01, 0]), [0, 0, 0.1])
    nodes = nodes_from_map(m, S_true, rng, ids=list(m.object_nodes[:18]))
    c = graph_candidate(nodes, m, Config().registration, rng)
    assert c is not None and c.matches >= 15
    assert_pose_close(c.S, S_true, 0.05, 1.0)


def test_graph_candidate_survives_moved_objects():
    m = room_map(n_objects=30, seed=4)
    rng = np.random.default_rng(8)
    S_true = yaw_T(-2.0, [0.5, 3.0, 0.0])
    nodes = nodes_from_map(m, S_true, rng, ids=list(m.object_nodes[:20]))
    for n in nodes[:6]:  # 30 % moved by 1.5-3 m in the clip
        d = rng.normal(size=3)
        d[2] = 0
        n.center = n.center + d / np.linalg.norm(d) * rng.uniform(1.5, 3.0)
    c = graph_candidate(nodes, m, Config().registration, rng)
    assert c is not None and c.matches >= 12
    assert_pose_close(c.S, S_true, 0.08, 1.5)


def test_graph_candidate_needs_three_instances():
    m = room_map()
    rng = np.random.default_rng(0)
    nodes = nodes_from_map(m, np.eye(4), rng, ids=list(m.object_nodes[:2]))
    assert graph_candidate(nodes, m, Config().registration, rng) is None


def _frame_observations(m, W_true, ids, rng, frame):
    Winv = G.inv_T(W_true)
    out = []
    for j in ids:
        P = surface_samples(m, j, 12, rng)
        out.append(Observation(frame=frame, cls=m.classes[j], center=G.apply(Winv, m.centers[j]),
                               samples=G.apply(Winv, P), n_points=100))
    return out


def test_candidates_compare_by_identity():
    from reloc.frontend.registration import Candidate

    a, b = Candidate(S=np.eye(4), source="graph"), Candidate(S=np.eye(4), source="anchors")
    assert a in [a, b] and b not in [a] and [a, b].index(b) == 1  # no "truth value of an array" error


def test_gravity_gate_rejects_a_tilted_candidate_without_crashing():
    from reloc.frontend.localize import localize_clip

    m = room_map(n_objects=30, seed=5)
    rng = np.random.default_rng(2)
    cam = G.make_T(np.array([[1.0, 0, 0], [0, 0, 1], [0, -1, 0]]), [0, 0, 0])
    tilt = G.make_T(G.exp_so3([math.radians(70), 0, 0]), [0, 0, 0])
    S_true = yaw_T(0.3, [0.5, 0.5, 0.0]) @ tilt  # the clip frame is tilted, its camera claims to be level
    nodes = nodes_from_map(m, S_true, rng, ids=list(m.object_nodes[:12]))
    p = localize_clip(nodes, {}, {0: cam}, m, Config(), rng)
    assert p.info["gravity_rejected"] == ["graph"] and p.S is None
    assert "gravity gate" in p.reason and "no wall normals" in p.reason


def test_anchors_give_consensus_and_veto_wrong_graph_placement():
    m = room_map(n_objects=30, seed=6)
    rng = np.random.default_rng(9)
    S_true = yaw_T(0.4, [1.0, 0.5, 0.0])
    V, fo = {}, {}
    for f in range(5):
        V[f] = yaw_T(0.3 * f, [0.4 * f, 0.1 * f, 1.5])
        W = S_true @ V[f]
        fo[f] = _frame_observations(m, W, list(m.object_nodes[4 * f: 4 * f + 8]), rng, f)
    cfg = Config().registration
    anc = anchors_for_clip(fo, V, m, cfg, rng)
    assert len(anc) >= 3
    for a in anc:
        assert_pose_close(a.W, S_true @ V[a.frame], 0.1, 2.0)
    S_a = anchor_candidate(anc, V, cfg)
    assert S_a is not None
    assert_pose_close(S_a.S, S_true, 0.1, 2.0)
    assert not anchors_veto(S_true, anc, V, cfg)
    assert anchors_veto(yaw_T(0.4 + math.radians(60), [1.0, 0.5, 0.0]), anc, V, cfg)
    assert anchors_veto(yaw_T(0.4, [3.5, 0.5, 0.0]), anc, V, cfg)


def test_fallback_uses_manhattan_yaw_and_center_votes():
    m = room_map(n_objects=20, seed=11, manhattan=math.radians(20))
    rng = np.random.default_rng(3)
    S_true = yaw_T(math.radians(20 + 90 + 8), [1.0, -0.5, 0.0])
    nodes = nodes_from_map(m, S_true, rng, ids=list(m.object_nodes[:2]))  # only two objects
    # the clip's walls: normals of two room walls, expressed in the clip frame
    Rinv = S_true[:3, :3].T
    wall_dirs = [G.rot_z(math.radians(20)) @ v for v in ([0, 1, 0], [1, 0, 0])]
    levelled_wall_yaws = np.array([math.atan2(*(Rinv @ d)[[1, 0]]) for d in wall_dirs])
    cands = fallback_candidates(nodes, m, Config().registration, np.eye(3), levelled_wall_yaws)
    assert cands
    assert_pose_close(cands[0].S, S_true, 0.1, 0.5)
    # an odometry prediction 90 degrees away leaves only other yaws
    prior = math.radians(20 + 8)
    cands2 = fallback_candidates(nodes, m, Config().registration, np.eye(3), levelled_wall_yaws, yaw_prior=prior)
    assert all(abs(((G.yaw_of(c.S[:3, :3]) - prior + math.pi) % (2 * math.pi)) - math.pi) <= math.radians(45.01)
               for c in cands2)


# --------------------------------------------------------------------------------------------
# refinement


def _wall_nodes(S_true, manhattan=0.0):
    """Wall nodes with plane normals in the clip frame (the camera sees the room's four walls)."""
    Rinv = S_true[:3, :3].T
    out = []
    for v in ([0, 1, 0], [0, -1, 0], [1, 0, 0], [-1, 0, 0], [0, 1, 0], [1, 0, 0]):
        n = Rinv @ (G.rot_z(manhattan) @ np.array(v, float))
        out.append(Node(cls="wall", center=np.zeros(3), samples=np.empty((0, 3)), n_obs=1, frames=[0],
                        normals=n[None]))
    return out


def test_refinement_pulls_a_perturbed_placement_back():
    m = room_map(n_objects=30, seed=12)
    rng = np.random.default_rng(4)
    S_true = yaw_T(0.8, [1.0, 2.0, 0.0])
    nodes = nodes_from_map(m, S_true, rng, ids=list(m.object_nodes[:20]), samples=40, noise=0.0)
    u = S_true[:3, :3].T @ np.array([0, 0, 1.0])
    S0 = S_true @ G.make_T(G.exp_so3([0.03, -0.03, 0.06]), [0.15, -0.1, 0.05])
    cfg = Config()
    S, info = orientation_aware(S0, nodes, m, cfg.refinement, cfg.registration, Gravity(u, "structure"))
    d0 = G.pose_distance(S0, S_true)
    d1 = G.pose_distance(S, S_true)
    assert d1[0] < 0.3 * d0[0] and d1[0] < 0.05
    assert math.degrees(d1[1]) < 1.0


class _Delegate:
    """A stand-in for a module: its attributes, except those given."""

    def __init__(self, base, **over):
        self._base = base
        self.__dict__.update(over)

    def __getattr__(self, name):
        return getattr(self._base, name)


def test_refinement_jacobian_matches_finite_differences(monkeypatch):
    """Each Gauss-Newton step of ``refine`` solves (J^T J) delta = -J^T r. Both sides are rebuilt here
    from Eq. 3's residuals (written in the map frame: S(p) - q_p for exterior samples, q_p the closest
    point of the assigned solid box; the tilt residual, the horizontal part of R u; the prior on the
    rotation and on the mapped centroid) with J by central finite differences over the step's own
    parametrization (a left rotation about the mapped centroid, then a translation of it), holding the
    iteration's assignments fixed, as a Gauss-Newton step does."""
    from reloc.frontend import refinement
    from reloc.frontend.refinement import refine

    m = room_map(n_objects=30, seed=12)
    rng = np.random.default_rng(4)
    S_true = yaw_T(0.8, [1.0, 2.0, 0.0])
    nodes = nodes_from_map(m, S_true, rng, ids=list(m.object_nodes[:20]), samples=40, noise=0.0)
    u = S_true[:3, :3].T @ np.array([0, 0, 1.0])
    u = G.exp_so3([0.01, -0.02, 0.0]) @ u  # a slightly wrong vertical: the tilt residual is not zero
    S0 = S_true @ G.make_T(G.exp_so3([0.03, -0.03, 0.06]), [0.15, -0.1, 0.05])
    cfg = Config()
    rc, reg = cfg.refinement, cfg.registration
    # record what each iteration sees (its transform and assignments) and the system it solves
    scorer = SurfaceScorer(m, [n.cls for n in nodes], [n.samples for n in nodes])
    seen, solves = [], []

    class Recording:
        def rho(self, Ss):
            rho, asg = scorer.rho(Ss)
            seen.append((Ss[0].copy(), rho[0].copy(), asg[0].copy()))
            return rho, asg

    def solve(A, b):
        solves.append((np.array(A), np.array(b)))
        return np.linalg.solve(A, b)

    monkeypatch.setattr(refinement, "np", _Delegate(np, linalg=_Delegate(np.linalg, solve=solve)))
    refine(S0, nodes, m, rc, reg, Gravity(u, "structure"), scorer=Recording())
    monkeypatch.undo()
    assert len(solves) >= 2 and len(seen) == len(solves)

    centroid = np.mean([n.center for n in nodes], axis=0)
    sig_f, sig_g = rc.sigma_f_m, math.radians(rc.sigma_g_deg)
    sig_r, sig_t = math.radians(rc.prior_rotation_deg), rc.prior_translation_m
    R0, c0 = S0[:3, :3], S0[:3, :3] @ centroid + S0[:3, 3]

    def residuals(S, consistent, asg):
        r = []
        for k in consistent:
            c, size, yaw = m.box(int(asg[k]))
            P = G.apply(S, nodes[k].samples)
            Rb = G.rot_z(yaw)
            local = (P - c) @ Rb
            q = np.clip(local, -size / 2, size / 2) @ Rb.T + c  # closest point of the solid box
            r.append(((P - q) / (sig_f * math.sqrt(len(P)))).reshape(-1))  # zero for interior samples
        g = S[:3, :3] @ u
        r.append(g[:2] / sig_g)
        r.append(G.log_so3(S[:3, :3] @ R0.T) / sig_r)
        r.append((S[:3, :3] @ centroid + S[:3, 3] - c0) / sig_t)
        return np.concatenate(r)

    for it in (0, 1):
        S, rho, asg = seen[it]
        consistent = np.flatnonzero(rho < reg.kappa_tau_m)
        assert len(consistent) >= 10
        c_map = S[:3, :3] @ centroid + S[:3, 3]

        def perturbed(d):
            R = G.exp_so3(d[:3]) @ S[:3, :3]
            return G.make_T(R, c_map + d[3:] - R @ centroid)

        r0 = residuals(S, consistent, asg)
        assert np.count_nonzero(r0[:-8]) > 100  # many exterior samples: the data term is exercised
        eps = 1e-6
        J = np.column_stack([(residuals(perturbed(e), consistent, asg) - residuals(perturbed(-e), consistent, asg))
                             / (2 * eps) for e in np.eye(6) * eps])
        A, b = solves[it]
        scale = np.abs(J.T @ J).max()
        # the gradient J^T r is exact at every iteration
        np.testing.assert_allclose(b, J.T @ r0, rtol=1e-5, atol=1e-6 * np.abs(b).max())
        # J^T J: exact at the first iteration (S = S0); later the rotation prior's Jacobian, the inverse
        # left Jacobian of log(R R0^T), is taken as the identity, equal to second order in the
        # rotation already made (a few degrees here)
        tol = 1e-8 if it == 0 else 1e-4  # measured: 3e-11 and 1.5e-6 of the largest entry
        np.testing.assert_allclose(A, J.T @ J + 1e-9 * np.eye(6), rtol=0, atol=tol * scale)


def test_point_to_point_ablation_also_refines_but_ignores_gravity():
    m = room_map(n_objects=30, seed=12)
    rng = np.random.default_rng(4)
    S_true = yaw_T(0.8, [1.0, 2.0, 0.0])
    nodes = nodes_from_map(m, S_true, rng, ids=list(m.object_nodes[:20]), noise=0.0)
    S0 = S_true @ G.make_T(G.exp_so3([0.0, 0.0, 0.05]), [0.15, -0.1, 0.0])
    cfg = Config().replace("refinement.orientation_aware", False)
    S, info = orientation_aware(S0, nodes, m, cfg.refinement, cfg.registration, Gravity(np.array([0, 0, 1.0]), "x"))
    assert "manhattan" not in info
    assert G.pose_distance(S, S_true)[0] < 0.02


def test_manhattan_correction_fixes_yaw_only_with_consensus():
    m = room_map(manhattan=math.radians(12))
    S_true = yaw_T(0.5, [0.0, 0.0, 0.0])
    walls = _wall_nodes(S_true, manhattan=math.radians(12))
    normals = np.concatenate([w.normals for w in walls])
    S_off = yaw_T(0.5 + math.radians(7), [0.0, 0.0, 0.0])
    cfg = Config().refinement
    S, info = manhattan_correction(S_off, normals, m, cfg, np.zeros(3))
    assert info["accepted"]
    assert abs(math.degrees(G.rot_angle(S[:3, :3].T @ S_true[:3, :3]))) < 1e-6
    # four normals are not enough
    S2, info2 = manhattan_correction(S_off, normals[:4], m, cfg, np.zeros(3))
    assert not info2["accepted"] and np.allclose(S2, S_off)
    # scattered normals (MAD > 12 deg) are refused
    scattered = np.array([G.rot_z(math.radians(a)) @ [1.0, 0, 0] for a in (0, 20, 40, 60, 75, 5)])
    _, info3 = manhattan_correction(np.eye(4), scattered, m, cfg, np.zeros(3))
    assert not info3["accepted"]


def test_gravity_from_floor_and_walls_and_camera_fallback():
    R = G.exp_so3([0.3, -0.2, 0.5])  # clip frame = rotated world frame
    up_clip = R.T @ np.array([0, 0, 1.0])
    floor = Node("floor", np.zeros(3), np.empty((0, 3)), 1, [0], normals=(up_clip)[None])
    walls = [Node("wall", np.zeros(3), np.empty((0, 3)), 1, [0], normals=(R.T @ v)[None])
             for v in ([1.0, 0, 0], [0, 1.0, 0], [-1.0, 0, 0])]
    V = {0: G.make_T(R.T @ G.rot_z(0.0) @ np.array([[1, 0, 0], [0, 0, 1], [0, -1, 0]], float), [0, 0, 0])}
    g = estimate_gravity([floor] + walls, V)
    assert g.source == "structure" and np.allclose(g.u, up_clip, atol=1e-9)
    # without structure: the camera's -y axis (level camera) gives the same vertical
    g2 = estimate_gravity([], V)
    assert g2.source == "camera_up" and np.allclose(g2.u, up_clip, atol=1e-9)
    assert g2.gate_deg(Config().refinement) == 60.0 and g.gate_deg(Config().refinement) == 30.0
    assert abs(tilt_deg(R, up_clip)) < 1e-6


# --------------------------------------------------------------------------------------------
# observations, fusion, clip policy


def test_observe_back_projects_a_known_plane():
    H, W = 60, 80
    K = np.array([[50.0, 0, 39.5], [0, 50.0, 29.5], [0, 0, 1]])
    depth = np.full((H, W), 2.0, np.float32)
    mask = np.zeros((H, W), bool)
    mask[20:40, 30:50] = True
    obs = observe(0, depth, K, [Detection("chair", mask)])
    assert len(obs) == 1
    o = obs[0]
    ys, xs = np.nonzero(mask)
    expect = np.array([((xs - 39.5) * 2 / 50).mean(), ((ys - 29.5) * 2 / 50).mean(), 2.0])
    assert np.allclose(o.center, expect, atol=1e-6)
    assert len(o.samples) == 12 and np.allclose(o.samples[:, 2], 2.0)
    # a wall facing the camera gets a normal towards the camera
    wall = observe(0, depth, K, [Detection("wall", mask)])[0]
    assert np.allclose(wall.normal, [0, 0, -1], atol=1e-6)


def test_3d_box_replaces_mask_center_only_when_iou_and_depth_agree():
    from reloc.frontend.observations import Box3D

    H, W = 60, 80
    K = np.array([[50.0, 0, 39.5], [0, 50.0, 29.5], [0, 0, 1]])
    depth = np.full((H, W), 2.0, np.float32)
    mask = np.zeros((H, W), bool)
    mask[20:40, 30:50] = True
    det = Detection("chair", mask)
    good = Box3D(np.array([0.0, 0.0, 2.3]), (29, 19, 50, 40))  # IoU ~0.83, depth within 0.4 z + 0.5
    far = Box3D(np.array([0.0, 0.0, 4.0]), (30, 20, 49, 39))  # same rectangle, 2 m behind: fails the depth check
    off = Box3D(np.array([0.0, 0.0, 2.0]), (0, 0, 15, 15))  # no overlap
    assert np.allclose(observe(0, depth, K, [det], boxes3d=[off, good])[0].center, good.center)
    plain = observe(0, depth, K, [det])[0].center
    assert np.allclose(observe(0, depth, K, [det], boxes3d=[far])[0].center, plain)
    assert np.allclose(observe(0, depth, K, [det], boxes3d=[off])[0].center, plain)
    # a box is used once: the second detection of the same place keeps its mask center
    two = observe(0, depth, K, [det, Detection("chair", mask)], boxes3d=[good])
    assert np.allclose(two[0].center, good.center) and np.allclose(two[1].center, plain)


@pytest.mark.parametrize("bad", ["zeros", "nan", "inf"])
def test_observe_bad_depth_gives_nothing(bad):
    depth = {"zeros": np.zeros((10, 10)), "nan": np.full((10, 10), np.nan), "inf": np.full((10, 10), np.inf)}[bad]
    mask = np.ones((10, 10), bool)
    assert observe(0, depth.astype(np.float32), np.eye(3), [Detection("chair", mask)]) == []


def test_fuse_joins_nearby_same_class_and_keeps_classes_apart():
    def ob(cls, c, normal=None):
        c = np.asarray(c, float)
        return Observation(0, cls, c, c[None] + np.zeros((3, 3)), 10, normal=None if normal is None else np.asarray(normal, float))
    obs = [ob("chair", [0, 0, 0]), ob("chair", [0.3, 0, 0]), ob("chair", [0.6, 0, 0]),  # chained
           ob("chair", [3, 0, 0]), ob("table", [0.1, 0, 0]),
           ob("wall", [0, 2, 1], [0, -1, 0]), ob("wall", [2, 2, 1], [0, -1, 0]),  # one wall plane
           ob("wall", [2, 1, 1], [1, 0, 0])]  # another plane
    nodes = fuse(obs)
    by = {}
    for n in nodes:
        by.setdefault(n.cls, []).append(n)
    assert sorted(n.n_obs for n in by["chair"]) == [1, 3]
    assert len(by["table"]) == 1
    assert sorted(n.n_obs for n in by["wall"]) == [1, 2]
    big = [n for n in by["chair"] if n.n_obs == 3][0]
    assert np.allclose(big.center, [0.3, 0, 0])


class _NoDetections:
    name = "none"

    def detect(self, frame):
        return []


def _clip_schedule(clip_cfg: ClipConfig, frames: int) -> tuple[list[int], list[tuple[int, str]]]:
    """Stream ``frames`` frames without evidence (no detections, no camera travel) through the
    front-end: the clip lengths at which it asked the policy whether to close, and each clip's
    (length, end reason)."""
    from reloc.detection.base import FrameData
    from reloc.frontend.stream import FrontEnd, StaticPoses

    cfg = dataclasses.replace(Config(), clips=clip_cfg)
    K = np.array([[40.0, 0, 8], [0, 40.0, 6], [0, 0, 1]])
    fe = FrontEnd(room_map(), K, _NoDetections(), StaticPoses(), config=cfg)
    asked = []
    real = fe.policy.should_close

    def should_close(length, n_nodes, path_m):
        asked.append(length)
        return real(length, n_nodes, path_m)

    fe.policy.should_close = should_close
    results = []
    for i in range(frames):
        results += fe.add(FrameData(i, np.full((12, 16), 2.0, np.float32), K))
    results += fe.finish()
    return asked, [(len(r.clip), r.clip.end_reason) for r in results]


def test_clip_policy_schedule():
    """Sec. IV-A: "Clips begin at 100 frames, grow by 50 to at most 600, and close once |K_c| >= 20
    and the camera path reaches 2 m." A clip is checked at 100, 150, ..., 600 frames and never grows
    past 600."""
    pol = ClipPolicy(ClipConfig())
    assert [n for n in range(1, 601) if pol.is_checkpoint(n)] == list(range(100, 601, 50))
    assert not pol.should_close(100, 19, 5.0)
    assert not pol.should_close(100, 25, 1.5)
    assert pol.should_close(150, 20, 2.0)
    assert not pol.should_close(151, 30, 9.0)  # only at checkpoints
    assert pol.should_close(600, 0, 0.0)  # the maximum length
    # in the front-end: a clip that never meets the criteria is asked at 100, 150, ..., 600 and closes
    # at 600, so no clip is ever asked about (or reaches) a length past the maximum
    asked, clips = _clip_schedule(ClipConfig(), 1300)
    assert asked == list(range(100, 601, 50)) * 2 + [100]
    assert clips == [(600, "max length"), (600, "max length"), (100, "end of tour")]
    # a maximum off the 50-frame grid still ends the clip there
    asked, clips = _clip_schedule(ClipConfig(max_frames=625), 700)
    assert asked == list(range(100, 601, 50)) + [625]
    assert clips == [(625, "max length"), (75, "end of tour")]
    fixed = ClipPolicy(ClipConfig(adaptive=False, start_frames=30))
    assert fixed.should_close(30, 0, 0.0) and not fixed.should_close(29, 99, 99.0)


def test_config_overrides_and_errors():
    c = Config.from_dict({"registration": {"center_match_m": 0.4}, "clips": {"adaptive": False}})
    assert c.registration.center_match_m == 0.4 and not c.clips.adaptive
    assert Config().registration.center_match_m == 0.5  # paper default untouched
    with pytest.raises(SceneFormatError, match="registration.nope: unknown setting"):
        Config.from_dict({"registration": {"nope": 1}})
    with pytest.raises(SceneFormatError, match="registration.center_match_m: expected a finite number"):
        Config.from_dict({"registration": {"center_match_m": "far"}})
    with pytest.raises(SceneFormatError, match="clips.adaptive: expected true or false"):
        Config.from_dict({"clips": {"adaptive": 1}})
    with pytest.raises(SceneFormatError, match="registration.center_match_m: expected a finite number"):
        Config.from_dict({"registration": {"center_match_m": float("nan")}})
    assert Config.from_dict(Config().to_dict()) == Config()
