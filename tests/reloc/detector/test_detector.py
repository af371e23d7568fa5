"""The learned detector: packing renders, a tiny training run, ONNX export, and instance cutting.

The training path runs for real on a set rendered here (tiny images, a few steps); the ONNX model
is checked against PyTorch on the same input; instance cutting is checked on constructed class,
boundary and depth maps whose instances are known by construction.
"""

from __future__ import annotations

import json

import numpy as np
import pytest
import yaml

from vrformats.errors import UserError
from vrformats.tour import Tour, tonemap
from reloc.cli import main as reloc_main
from reloc.detection.base import FrameData
from reloc.detection.learned import LearnedDetector, depth_edges
from synth.cli import main as synth_main

torch = pytest.importorskip("torch")  # the [train] extra; make test installs it

from reloc.detector.data import boundaries, load  # noqa: E402
from reloc.detector.model import FastSeg, SegNet  # noqa: E402


@pytest.fixture(scope="module")
def tiny(tmp_path_factory):
    """Two tours (day, night) of 3 random views at 64x48 of a training apartment, packed."""
    root = tmp_path_factory.mktemp("detector")
    spec = root / "t.yaml"
    spec.write_text(yaml.safe_dump({"name": "t", "out": str(root / "renders"), "seeds": [103], "variants": 0,
                                    "lightings": ["day", "night"], "jitter": 1, "views": 3, "size": [64, 48]}))
    assert synth_main(["trainset", "render", str(spec), "--quiet"]) == 0
    assert reloc_main(["detector", "pack", str(root / "renders"), "--out", str(root / "set.npz"), "--quiet"]) == 0
    assert reloc_main(["detector", "train", str(root / "set.npz"), "--out", str(root / "run"), "--epochs", "15",
                       "--batch", "2", "--width", "8", "--lr", "0.01", "--quiet"]) == 0
    assert reloc_main(["detector", "train", str(root / "set.npz"), "--out", str(root / "fast"), "--epochs", "15",
                       "--batch", "2", "--width", "8", "--lr", "0.01", "--arch", "fastseg", "--augment", "camera",
                       "--quiet"]) == 0
    return root


@pytest.mark.slow
@pytest.mark.blender
def test_pack_round_trip_against_the_renders(tiny):
    ds = load(tiny / "set.npz")
    assert len(ds) == 6 and ds.rgb.shape == (6, 48, 64, 3) and ds.classes[0] == "background"
    assert sorted({lt.rsplit("/", 1)[-1] for lt in ds.lightings}) == ["day_j0", "night_j0"]
    for k, name in enumerate(ds.tours):
        tour = Tour(tiny / "renders" / name)
        i = [j for j, t in enumerate(ds.tours) if t == name].index(k)
        f = tour.frame(int(tour.frame_indices[i]))
        srgb, _ = tonemap(f.rgb)
        assert np.abs(ds.rgb[k].astype(float) - srgb * 255).mean() < 3.0  # JPEG, quality 92
        assert np.array_equal(ds.instance[k], f.instance.astype(np.int32))  # lossless
        by_id = {int(v): c for c, v in tour.objects()["classes"].items()}
        expect = np.vectorize(lambda s: ds.classes.index(by_id[s]) if s else 0)(f.semantic)
        assert np.array_equal(ds.semantic[k], expect)


def test_boundaries_cut_touching_instances():
    inst = np.zeros((6, 8), int)
    inst[1:5, 1:4], inst[1:5, 4:7] = 3, 4  # two instances side by side
    b = boundaries(inst)
    assert b[2, 3] and b[2, 4] and not b[2, 2] and not b[2, 5]  # the seam, both sides
    assert b[0, 2] and b[1, 2] and not b[3, 2]  # the border with the background


@pytest.mark.slow
@pytest.mark.blender
def test_training_learns_and_onnx_matches_pytorch(tiny):
    log = json.loads((tiny / "run" / "train_log.json").read_text())
    losses = [e["loss"] for e in log["epochs"]]
    assert len(losses) == 15 and losses[-1] < 0.8 * losses[0]  # it learns (on its own frames)
    state = torch.load(tiny / "run" / "checkpoint.pt", map_location="cpu")
    model = SegNet(len(log["classes"]), 8)
    model.load_state_dict(state["model"])
    model.eval()
    det = LearnedDetector(tiny / "run" / "model.onnx")
    assert det.classes == log["classes"]
    for h, w in ((48, 64), (120, 160)):  # dynamic size
        x = np.random.default_rng(h).random((1, 3, h, w)).astype(np.float32)
        with torch.no_grad():
            ts, tb = (t.numpy() for t in model(torch.from_numpy(x)))
        os_, ob = det.session.run(None, {"image": x})
        assert np.abs(ts - os_).max() < 1e-4 and np.abs(tb - ob).max() < 1e-4


@pytest.mark.slow
@pytest.mark.blender
def test_fastseg_with_camera_augmentation_learns_exports_and_refuses_other_sizes(tiny):
    """The issue-28 path: the stride-16 network, trained through the camera augmentation, exports
    its stride and training resolution; the detector pads frames to the stride and refuses a tour
    of another size in one line naming the model and both sizes."""
    log = json.loads((tiny / "fast" / "train_log.json").read_text())
    losses = [e["loss"] for e in log["epochs"]]
    assert log["config"]["arch"] == "fastseg" and log["augment_config"]["electrons_per_ms"] > 0
    assert losses[-1] < 0.85 * losses[0]
    state = torch.load(tiny / "fast" / "checkpoint.pt", map_location="cpu")
    model = FastSeg(len(log["classes"]), 8)
    model.load_state_dict(state["model"])
    model.eval()
    det = LearnedDetector(tiny / "fast" / "model.onnx")
    assert det.stride == 16 and det.resolution == (64, 48)
    x = np.random.default_rng(0).random((1, 3, 48, 64)).astype(np.float32)
    with torch.no_grad():
        ts, tb = (t.numpy() for t in model(torch.from_numpy(x)))
    os_, ob = det.session.run(None, {"image": x})
    assert np.abs(ts - os_).max() < 1e-4 and np.abs(tb - ob).max() < 1e-4
    rgb = np.random.default_rng(1).random((48, 64, 3)).astype(np.float32)
    cls, conf, bnd = det.predict(rgb)
    assert cls.shape == (48, 64) and bnd.shape == (48, 64)
    with pytest.raises(UserError, match=r"model\.onnx: the model was trained on 64x48 frames, but this tour is 160x120"):
        det.predict(np.zeros((120, 160, 3), np.float32))


@pytest.mark.blender
def test_learned_detector_bad_models_are_one_line(tiny, tmp_path):
    with pytest.raises(UserError, match="detector model not found"):
        LearnedDetector(tmp_path / "none.onnx")
    (tmp_path / "bad.onnx").write_bytes(b"not a model")
    with pytest.raises(UserError, match="not a readable ONNX model"):
        LearnedDetector(tmp_path / "bad.onnx")
    with pytest.raises(UserError, match="does not know the map's classes unicorn"):
        LearnedDetector(tiny / "run" / "model.onnx", vocabulary={"chair", "unicorn"})
    import onnx

    m = onnx.load(str(tiny / "run" / "model.onnx"))
    del m.metadata_props[:]
    onnx.save(m, str(tmp_path / "plain.onnx"))
    with pytest.raises(UserError, match="format: expected a videoreloc-segnet/1 model"):
        LearnedDetector(tmp_path / "plain.onnx")


# ---------------------------------------------------------------------------------------------
# instance cutting, on maps built here


class _Fixed(LearnedDetector):
    """The cutting of LearnedDetector with a prediction given by the test."""

    def __init__(self, cls, conf, bnd, classes):
        self.classes, self.vocabulary = classes, set(classes[1:])
        self.min_pixels, self.boundary_threshold, self.score_threshold = 20, 0.5, 0.3
        self.depth_edge_rel, self.depth_edge_abs_m = 0.04, 0.03
        self._pred = (cls, conf, bnd)

    def predict(self, rgb_linear, index=None):
        return self._pred


def _frame(depth):
    return FrameData(0, depth.astype(np.float32), np.eye(3), rgb=np.zeros(depth.shape + (3,), np.float32))


def test_cutting_splits_same_class_neighbours_at_boundaries_and_depth_jumps():
    H, W = 40, 60
    classes = ["background", "wall", "chair", "book"]
    cls = np.zeros((H, W), int)
    cls[5:25, 5:25], cls[5:25, 25:45] = 2, 2  # two chairs touching, one class region
    cls[30:36, 5:55] = 3  # a row of books
    cls[2, 50:54] = 2  # a chair speck: too small
    conf = np.full((H, W), 0.9)
    bnd = np.zeros((H, W))
    bnd[5:25, 24:26] = 0.9  # the predicted seam between the chairs
    depth = np.full((H, W), 3.0)
    depth[30:36, 30:55] = 2.0  # the books split by a depth jump only
    dets = _Fixed(cls, conf, bnd, classes).detect(_frame(depth))
    chairs = sorted((d for d in dets if d.cls == "chair"), key=lambda d: d.box2d[0])
    books = sorted((d for d in dets if d.cls == "book"), key=lambda d: d.box2d[0])
    assert len(chairs) == 2 and len(books) == 2 and len(dets) == 4
    # the masks reach back over the cut pixels: together they are the class region (minus the speck)
    assert chairs[0].mask[5:25, 5:24].all() and chairs[1].mask[5:25, 26:45].all()
    assert np.array_equal(chairs[0].mask | chairs[1].mask, (cls == 2) & ~np.pad(np.ones((1, 4), bool), ((2, H - 3), (50, W - 54))))
    assert not (chairs[0].mask & chairs[1].mask).any()
    assert books[0].mask[30:36, 5:29].all() and books[1].mask[30:36, 31:55].all()
    # a weak region is dropped by the score threshold, a confident one kept
    conf[5:25, 25:45] = 0.2
    dets = _Fixed(cls, conf, bnd, classes).detect(_frame(depth))
    assert len([d for d in dets if d.cls == "chair"]) == 1


def test_depth_edges_mark_jumps_and_holes():
    d = np.full((10, 10), 2.0, np.float32)
    d[:, 5:] = 2.5
    d[0, 0] = 0.0
    e = depth_edges(d, 0.04, 0.03)
    assert e[:, 4].all() and e[:, 5].all() and not e[3, 2] and not e[3, 7] and e[0, 0]
    d2 = d.copy()
    d2[:, 5:] = 2.05  # within 4 % + 3 cm: a sloped surface, not an edge
    assert not depth_edges(d2, 0.04, 0.03)[3, 4]


@pytest.mark.blender
def test_checkpoints_are_read_as_weights_only(tiny, tmp_path, capsys):
    """export and train --resume read a checkpoint with weights_only=True: the real one loads (and a
    resumed training goes on from it), a pickle that would run code when unpickled is refused with
    one line naming the file (and the code never runs), a checkpoint without a model is refused."""
    from reloc.detector.train import load_checkpoint

    assert set(load_checkpoint(tiny / "run" / "checkpoint.pt")) >= {"model", "opt", "sched", "log"}
    train = ["detector", "train", str(tiny / "set.npz"), "--out", str(tmp_path / "run"), "--batch", "2", "--width", "8",
             "--quiet"]
    assert reloc_main([*train, "--epochs", "2"]) == 0
    assert reloc_main([*train, "--epochs", "2", "--resume"]) == 0  # loads model, optimiser and schedule
    assert len(json.loads((tmp_path / "run" / "train_log.json").read_text())["epochs"]) == 2
    assert reloc_main([*train, "--epochs", "3", "--resume"]) == 2
    assert "started for 2 epochs; resume it with --epochs 2" in capsys.readouterr().err
    marker = tmp_path / "ran"

    class Evil:
        def __reduce__(self):
            return (open, (str(marker), "w"))

    evil = tmp_path / "evil.pt"
    torch.save({"model": Evil(), "log": {}}, evil)
    assert reloc_main(["detector", "export", str(evil), "--out", str(tmp_path / "m.onnx")]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith(f"reloc: error: {evil}: not a checkpoint of reloc detector train") and len(err.splitlines()) == 1
    assert not marker.exists() and not (tmp_path / "m.onnx").exists()
    torch.save({"weights": torch.zeros(2)}, tmp_path / "other.pt")
    with pytest.raises(UserError, match="no model and log in it"):
        load_checkpoint(tmp_path / "other.pt")


def test_map_rule_benchmark_variants_name_real_settings():
    """reloc.map.bench_rules relaxes rules by name: each must be a MapBuildSettings field or a
    LearnedDetector keyword, and its table puts the defaults first."""
    import inspect
    from dataclasses import fields as dc_fields

    from reloc.map.bench_rules import VARIANTS, format_rows
    from reloc.map.settings import MapBuildSettings

    names = {f.name for f in dc_fields(MapBuildSettings)}
    det = set(inspect.signature(LearnedDetector.__init__).parameters)
    assert VARIANTS[0] == ("defaults", {}, {})
    for label, det_kw, map_kw in VARIANTS:
        assert set(map_kw) <= names and set(det_kw) <= det, label
        for k, v in map_kw.items():
            assert v != getattr(MapBuildSettings(), k), label  # a variant changes something
    rows = [{"variant": "defaults", "built": 10, "gt": 12, "matched": 8, "missing": 4, "extra": 2,
             "missing_classes": {"book": 3, "bowl": 1}},
            {"variant": "x", "built": 14, "gt": 12, "matched": 9, "missing": 3, "extra": 5, "missing_classes": {}}]
    text = format_rows(rows)
    assert "book 3, bowl 1" in text and "| x | 14 | 9 / 12 | 3 | 5 | +1 | +3 |" in text


def test_held_out_intervals_bracket_the_estimate_and_vanish_for_identical_frames():
    from reloc.detector.evaluate import _miou, bootstrap_intervals

    good = np.diag([100, 50, 50])
    bad = np.array([[100, 0, 0], [0, 10, 40], [0, 40, 10]])
    same = bootstrap_intervals(np.stack([good] * 20), np.full(20, 4.0), np.full(20, 3.0))
    assert same["miou_ci"] == [1.0, 1.0] and same["instance_recall_ci"] == [0.75, 0.75]
    mixed = np.stack([good] * 10 + [bad] * 10)
    gt, found = np.full(20, 4.0), np.array([4.0] * 10 + [0.0] * 10)
    ci = bootstrap_intervals(mixed, gt, found)
    point = _miou(mixed.sum(0))
    assert ci["miou_ci"][0] < point < ci["miou_ci"][1] and ci["instance_recall_ci"][0] < 0.5 < ci["instance_recall_ci"][1]
    assert ci == bootstrap_intervals(mixed, gt, found)  # seeded


@pytest.mark.slow
@pytest.mark.blender
def test_detector_eval_reports_intervals_and_reads_through_a_sensor(tiny, capsys):
    args = ["detector", "eval", str(tiny / "renders"), "--model", str(tiny / "run" / "model.onnx"), "--json", "--quiet"]
    assert reloc_main(args) == 0
    rep = json.loads(capsys.readouterr().out)
    assert rep["sensor"] == "ideal" and set(rep["lightings"]) == {"day", "night"}
    for r in rep["lightings"].values():
        lo, hi = r["miou_ci"]
        assert lo <= r["miou"] <= hi and r["frames"] == 3
    assert reloc_main(args + ["--sensor", "structured_light"]) == 0
    noisy = json.loads(capsys.readouterr().out)
    assert noisy["sensor"] == "structured_light"
    assert noisy["lightings"]["night"]["pixel_acc"] != rep["lightings"]["night"]["pixel_acc"]  # other frames seen
    assert reloc_main(args + ["--sensor", "kinect9"]) == 2
    err = capsys.readouterr().err.strip()
    assert "kinect9" in err and len(err.splitlines()) == 1


def test_init_from_the_shipped_model_is_exact_in_eval_mode():
    """``--init``: the export folded batch norm into the convolutions; loading it back must give the
    exported model's logits (onnxruntime) for every class it had, with new classes added."""
    from reloc.detector.model import build
    from reloc.detector.train import init_from_onnx, onnx_init
    from reloc.resources import MODELS_DIR

    path = MODELS_DIR / "detector_v2_160x120.onnx"
    ini = onnx_init(path)
    classes = ini["classes"][:5] + ["kitchen_utensil", "new_thing"] + ini["classes"][5:]
    model = build(ini["arch"], len(classes), ini["width"])
    g = torch.Generator().manual_seed(0)
    info = init_from_onnx(model, ini, classes, torch.rand(6, 3, 40, 60, generator=g))  # padded to the stride
    assert info["new_classes"] == [c for c in ("kitchen_utensil", "new_thing") if c not in ini["classes"]]
    assert info["kept_classes"] == ini["classes"]
    x = torch.rand(2, 3, 128, 160, generator=g)
    model.eval()
    with torch.no_grad():
        ts, tb = (t.numpy() for t in model(x))
    os_, ob = LearnedDetector(path).session.run(None, {"image": x.numpy()})
    idx = [classes.index(c) for c in ini["classes"]]
    assert np.abs(ts[:, idx] - os_).max() < 1e-3 and np.abs(tb - ob).max() < 1e-3
    new = [classes.index(c) for c in info["new_classes"]]
    assert (ts[:, new].max(1) > ts[:, idx].max(1)).mean() < 0.01  # a new class starts rarely winning
    with pytest.raises(UserError, match="is not the one being trained; pass --arch fastseg --width 40"):
        init_from_onnx(build("fastseg", len(classes), 8), ini, classes, torch.rand(1, 3, 48, 64))


@pytest.mark.slow
@pytest.mark.blender
def test_fine_tuning_starts_from_the_given_model(tiny, capsys):
    """A fine-tune run from the tiny fastseg model: the network is the model's own (its width, not
    the option's default), its first epoch's validation is close to the model it started from."""
    out = tiny / "tuned"
    assert reloc_main(["detector", "train", str(tiny / "set.npz"), "--out", str(out), "--epochs", "2", "--batch", "2",
                       "--lr", "0.001", "--augment", "camera", "--init", str(tiny / "fast" / "model.onnx")]) == 0
    log = json.loads((out / "train_log.json").read_text())
    assert log["config"]["arch"] == "fastseg" and log["config"]["width"] == 8
    assert log["init"]["model"] == str(tiny / "fast" / "model.onnx") and log["init"]["new_classes"] == []
    base = json.loads((tiny / "fast" / "train_log.json").read_text())["epochs"][-1]["val_miou"]
    assert log["epochs"][0]["val_miou"] >= base - 0.15
    assert "initialised from" in capsys.readouterr().err
    assert reloc_main(["detector", "train", str(tiny / "set.npz"), "--out", str(tiny / "t2"), "--init", str(tiny / "nope.onnx")]) == 2
    assert "nope.onnx: model not found" in capsys.readouterr().err


def test_detector_eval_on_a_geometry_only_tour_is_one_line(tmp_path, capsys):
    """A tour rendered without RGB (the fast renderer's geometry) has nothing a detector can see:
    one line naming the tour, not numpy's "need at least one array to stack"."""
    from tests.conftest import make_tour
    from vrformats.camera import Intrinsics
    from reloc.resources import SHIPPED_MODEL
    from tests.cli_errors import one_line_error

    depth = np.full((48, 64), 2.0, np.float32)
    ids = np.zeros((48, 64), np.uint16)
    tour = make_tour(tmp_path / "geo", [np.eye(4)] * 2, {i: dict(depth=depth, instance=ids, semantic=ids) for i in range(2)},
                     intrinsics=Intrinsics.from_fov(64, 48, 75.0), layout="apt_0", lighting="day", path="query")
    args = ["detector", "eval", str(tour), "--model", str(SHIPPED_MODEL), "--quiet"]
    assert reloc_main(args) == 2
    one_line_error(capsys, "geo", "RGB")
