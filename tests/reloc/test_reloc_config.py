"""reloc's config: every number the method uses is a key, each key changes what it names, and
unknown keys are refused naming file and key."""

from __future__ import annotations

import dataclasses
import math
import re
from pathlib import Path

import numpy as np
import pytest

from reloc import geometry as G
from reloc.frontend.clip_rigid import fit_clip_transform
from reloc.frontend.clips import Node, fuse
from reloc.config import Config, load_config
from reloc.detection.base import Detection, FrameData
from reloc.detection.factory import DetectorSpec, build_detector
from reloc.detection.oracle import Corruption
from reloc.frontend.observations import Observation, observe
from reloc.frontend.refinement import estimate_gravity, wall_yaws

from vrformats.errors import UserError


RELOC = Path(__file__).resolve().parents[2] / "reloc"


def _load(tmp_path, text: str) -> Config:
    p = tmp_path / "cfg.yaml"
    p.write_text(text)
    return load_config(p)


@pytest.mark.parametrize("text, key", [
    ("registration:\n  seed: 3\n", "registration.seed"),  # accepted once, read by nothing: removed
    ("clips:\n  nope: 1\n", "clips.nope"),
    ("nosuch:\n  x: 1\n", "nosuch"),
    ("nosuch: 3\n", "nosuch"),
    ("odometry:\n  iterations: 5\n", "odometry.iterations"),
    ("registration:\n  center_match_m: .nan\n", "registration.center_match_m: expected a finite number"),
    ("clips:\n  max_frames: 2.5\n", "clips.max_frames: expected an integer"),
    ("clips:\n  adaptive: 1\n", "clips.adaptive: expected true or false"),
])
def test_unknown_or_malformed_key_is_one_line_naming_file_and_key(tmp_path, text, key):
    with pytest.raises(UserError) as e:
        _load(tmp_path, text)
    msg = str(e.value)
    assert "\n" not in msg
    assert msg.startswith(str(tmp_path / "cfg.yaml") + ": " + key), msg


def test_every_key_name_is_read_outside_the_config():
    """A key that no module reads would be accepted and silently ignored. (A textual guard: it
    catches a key whose name no module reads as an attribute, not one read under another object.)"""
    src = "\n".join(p.read_text() for p in RELOC.rglob("*.py") if p.name != "config.py")
    unread = [f"{s.name}.{f.name}" for s in dataclasses.fields(Config)
              for f in dataclasses.fields(getattr(Config(), s.name))
              if not re.search(r"\." + f.name + r"\b", src)]
    assert unread == []


def test_min_mask_pixels_drops_small_masks(tmp_path):
    K = np.array([[50.0, 0, 39.5], [0, 50.0, 29.5], [0, 0, 1]])
    depth = np.full((60, 80), 2.0, np.float32)
    mask = np.zeros((60, 80), bool)
    mask[20:30, 30:40] = True  # 100 pixels
    det = [Detection("chair", mask)]
    assert len(observe(0, depth, K, det, det_cfg=Config().detection)) == 1
    cfg = _load(tmp_path, "detection:\n  min_mask_pixels: 101\n")
    assert observe(0, depth, K, det, det_cfg=cfg.detection) == []
    # the oracle detector built with the config reports no smaller instance either
    inst = mask.astype(np.uint32) * 7
    frame = FrameData(0, depth, K, instance=inst, semantic=mask.astype(np.uint32) * 3)
    spec = DetectorSpec(corruption=Corruption())
    assert len(build_detector(spec, {3: "chair"}).detect(frame)) == 1
    assert build_detector(spec, {3: "chair"}, config=cfg.detection).detect(frame) == []


def test_max_points_per_mask_bounds_back_projection(tmp_path):
    K = np.array([[50.0, 0, 39.5], [0, 50.0, 29.5], [0, 0, 1]])
    depth = np.full((60, 80), 2.0, np.float32)
    mask = np.zeros((60, 80), bool)
    mask[10:50, 10:70] = True  # 2400 pixels
    assert observe(0, depth, K, [Detection("chair", mask)])[0].n_points == 2400
    cfg = _load(tmp_path, "observation:\n  max_points_per_mask: 500\n")
    assert observe(0, depth, K, [Detection("chair", mask)], cfg.observation)[0].n_points == 480  # every 5th


def _obs(cls, center, normal=None) -> Observation:
    c = np.asarray(center, float)
    return Observation(frame=0, cls=cls, center=c, samples=c[None], n_points=100,
                       normal=None if normal is None else np.asarray(normal, float))


def test_structure_fusion_radii(tmp_path):
    walls = [_obs("wall", (0, 0, 0), (0, 1, 0)), _obs("wall", (3, 0, 0), (0, 1, 0))]  # one plane, 3 m apart
    floors = [_obs("floor", (0, 0, 0)), _obs("floor", (1.5, 0, 0))]
    assert len(fuse(walls + floors)) == 2
    cfg = _load(tmp_path, "observation:\n  wall_fusion_radius_m: 2.5\n  floor_fusion_radius_m: 1.0\n")
    assert len(fuse(walls + floors, cfg.observation)) == 4
    tilted = [_obs("wall", (0, 0, 0), (0, 1, 0)), _obs("wall", (0, 0, 0.5), G.rot_z(math.radians(25)) @ [0, 1, 0])]
    assert len(fuse(tilted)) == 2
    cfg = _load(tmp_path, "observation:\n  wall_fusion_normal_deg: 30\n")
    assert len(fuse(tilted, cfg.observation)) == 1


def test_orientation_cue_thresholds(tmp_path):
    # a wall normal 50 degrees from horizontal: its horizontal part is cos(50) = 0.64
    n = np.array([[math.cos(math.radians(50)), 0.0, math.sin(math.radians(50))]])
    assert len(wall_yaws(np.eye(3), n, Config().refinement.wall_min_horizontal)) == 0
    cfg = _load(tmp_path, "refinement:\n  wall_min_horizontal: 0.6\n  gravity_max_from_camera_up_deg: 80\n")
    assert len(wall_yaws(np.eye(3), n, cfg.refinement.wall_min_horizontal)) == 1
    # a floor normal 70 degrees from the camera's up: implausible by default
    cam = G.make_T(np.array([[1.0, 0, 0], [0, 0, 1], [0, -1, 0]]), [0, 0, 0])  # camera up = +Z
    up = G.exp_so3([math.radians(70), 0, 0]) @ [0, 0, 1.0]
    floor = Node("floor", np.zeros(3), np.empty((0, 3)), 1, [0], normals=up[None])
    assert estimate_gravity([floor], {0: cam}).source == "camera_up"
    assert estimate_gravity([floor], {0: cam}, cfg.refinement).source == "structure"


def test_clip_rigid_tolerances(tmp_path):
    rng = np.random.default_rng(0)
    V = {i: G.make_T(G.rot_z(0.05 * i), [0.1 * i, 0, 0]) for i in range(10)}
    S = G.make_T(G.rot_z(1.0), [2.0, 1.0, 0.0])
    est = {i: G.make_T(S[:3, :3] @ V[i][:3, :3], (S @ V[i])[:3, 3] + rng.normal(0, 0.12, 3)) for i in V}
    _, n_default = fit_clip_transform(est, V)
    cfg = _load(tmp_path, "clip_rigid:\n  pos_tol_m: 1.0\n  min_support: 11\n")
    S2, n_wide = fit_clip_transform(est, V, cfg.clip_rigid)
    assert n_default < 10 and n_wide == 10 and S2 is None  # all ten support it, eleven are required


def test_detection_min_mask_pixels_reaches_the_oracle_everywhere():
    """detection.min_mask_pixels was accepted and ignored; now reloc run, units, experiments and the
    bench build their oracle with it (default_detector, build_detector)."""
    from reloc.detection.factory import DetectorSpec, build_detector
    from reloc.frontend.stream import default_detector

    class FakeTour:
        def class_names(self):
            return {1: "chair", 2: "wall"}

    class FakeMap:
        class_set = {"chair", "wall"}

    cfg = Config().replace("detection.min_mask_pixels", 3)
    assert default_detector(FakeTour(), FakeMap(), cfg).min_pixels == 3
    assert default_detector(FakeTour(), FakeMap()).min_pixels == Config().detection.min_mask_pixels == 20
    assert build_detector(DetectorSpec(), {1: "chair"}, config=cfg.detection).min_pixels == 3


def test_the_map_section_reaches_every_loaded_box_map(tmp_path, monkeypatch):
    """``Config.map`` (the triangle index of a loaded map) is what the experiment tasks and
    ``reloc run`` load the map with: a shorter edge range keeps fewer edges than the paper's."""
    import json

    from reloc.experiments.methods.common import load_map
    from reloc.map.boxmap import BoxMap
    from synth.scene.model import boxes_document, load_layout

    path = tmp_path / "map.json"
    path.write_text(json.dumps(boxes_document(load_layout("apt_0"))))
    cfg = _load(tmp_path, "map:\n  triangle_edge_max_m: 2.0\n")
    paper = load_map("boxes", str(path), Config().map)
    short = load_map("boxes", str(path), cfg.map)
    assert paper.config.triangle_edge_max_m == 8.0 and short.config.triangle_edge_max_m == 2.0
    assert 0 < len(short.edges) < len(paper.edges)
    # reloc run: the map is loaded with the --config's map section (stopped right after the load)
    seen = []

    class Stop(Exception):
        pass

    def load(p, config=None):
        seen.append(config)
        raise Stop

    monkeypatch.setattr(BoxMap, "load", staticmethod(load))
    import vrformats.tour
    import reloc.experiments.runner  # noqa: F401  imported by the run below: first imported here, not while
    import reloc.map.document  # noqa: F401  Tour is the stand-in (a module-level import would keep it)
    from reloc.cli import build_parser

    monkeypatch.setattr(vrformats.tour, "Tour", lambda *a, **k: None)  # cmd_run imports it when it runs
    (tmp_path / "cfg.yaml").write_text("map:\n  triangle_edge_max_m: 2.0\n")
    args = build_parser().parse_args(["run", "--tour", "T", "--map", str(path), "--out", str(tmp_path / "out"),
                                      "--config", str(tmp_path / "cfg.yaml")])
    with pytest.raises(Stop):
        args.fn(args)
    assert seen and seen[0].triangle_edge_max_m == 2.0
