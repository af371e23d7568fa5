"""The shipped learned detectors against rendered ground truth: the default,
reloc/models/detector_v2_160x120.onnx, and the first model, reloc/models/detector_160x120.onnx, which
stays loadable by path.

Six random views of apt_0 (an experiment layout neither model trained on) are rendered here in
day and night light; each model's per-pixel classes and its instances are compared with the
frames' rendered labels. The floors sit below what was measured on three view seeds, with a margin
(FLOORS: the measured ranges beside them); an untrained model scores near 0.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from vrformats.tour import Tour
from reloc.detection.base import FrameData
from reloc.detection.learned import LearnedDetector
from reloc.resources import MODELS_DIR, SHIPPED_MODEL
from synth.paths.files import save_path
from synth.paths.views import plan_views
from synth.scene.model import load_layout
from synth.tour.render import TourSpec, render_tour

MODEL = SHIPPED_MODEL
FIRST_MODEL = MODELS_DIR / "detector_160x120.onnx"
# (pixel accuracy, mean best mask IoU of instances of at least 200 pixels) floors per model and lighting
FLOORS = {
    # measured on view seeds 0, 1, 2: day accuracy 0.91-0.93, IoU 0.63-0.67; night 0.85-0.87, 0.54-0.56
    "detector_160x120.onnx": {"day": (0.82, 0.52), "night": (0.76, 0.45)},
    # measured on view seeds 0, 1, 2: day accuracy 0.92-0.94, IoU 0.63-0.70; night 0.87-0.89, 0.53-0.64
    "detector_v2_160x120.onnx": {"day": (0.84, 0.55), "night": (0.79, 0.46)},
}


@pytest.fixture(scope="module")
def views(tmp_path_factory):
    root = tmp_path_factory.mktemp("shipped")
    return save_path(plan_views([load_layout("apt_0")], 6, seed=0), root / "views.txt")


@pytest.fixture(scope="module")
def rendered(views):
    """The six views in a lighting, rendered once for both models."""
    done = {}

    def get(lighting: str) -> Path:
        if lighting not in done:
            d = views.parent / lighting
            render_tour(TourSpec(layout="apt_0", path=str(views), lighting=lighting, out=str(d), width=160,
                                 height=120), progress=False)
            done[lighting] = d
        return done[lighting]
    return get


@pytest.mark.slow
@pytest.mark.blender
@pytest.mark.parametrize("lighting", ["day", "night"])
@pytest.mark.parametrize("model", [MODEL, FIRST_MODEL], ids=["v2", "first"])
def test_shipped_model_finds_apt_0_in_day_and_night(rendered, lighting, model):
    tour = Tour(rendered(lighting))
    det = LearnedDetector(model, vocabulary=set(tour.objects()["classes"]))  # covers the map's classes
    index = {c: k for k, c in enumerate(det.classes)}
    sem = np.zeros(65536, int)
    for sid, name in tour.class_names().items():
        sem[sid] = index[name]
    acc, ious = [], []
    for f in tour:
        cls, _, _ = det.predict(f.rgb)
        gt = sem[f.semantic.astype(int)]
        acc.append(float((cls == gt).mean()))
        dets = det.detect(FrameData(0, f.depth, tour.K, rgb=f.rgb))
        for iid in np.unique(f.instance):
            m = f.instance == iid
            if iid == 0 or m.sum() < 200:
                continue
            c = det.classes[int(np.bincount(gt[m]).argmax())]
            ious.append(max([(x.mask & m).sum() / (x.mask | m).sum() for x in dets if x.cls == c] or [0.0]))
    floor_acc, floor_iou = FLOORS[model.name][lighting]
    assert len(ious) >= 30
    assert np.mean(acc) >= floor_acc, acc
    assert np.mean(ious) >= floor_iou, np.mean(ious)


def test_a_perturbation_jitters_the_8_bit_input_by_one_level_seeded_per_frame():
    from reloc.detection.learned import Perturbation

    img = np.full((12, 16, 3), 128.0)
    img[0, 0] = 0.0
    img[0, 1] = 255.0
    p = Perturbation(input_jitter=1, seed=3)
    a, b = p.jitter(img, 7), p.jitter(img, 7)
    assert np.array_equal(a, b)  # the same frame gets the same jitter in every run
    assert not np.array_equal(a, p.jitter(img, 8)) and not np.array_equal(a, Perturbation(1, seed=4).jitter(img, 7))
    assert set(np.unique(a[1:] - img[1:])) == {-1.0, 0.0, 1.0}
    assert 0.0 <= a.min() and a.max() <= 255.0  # clipped to the 8-bit range
    assert Perturbation().jitter(img, 7) is img and not Perturbation().active and p.active
    assert p.label() == "jitter 1 (seed 3)" and Perturbation(threads=2, graph_optimization=False).label() == \
        "2 threads, no graph optimisation"
    for bad in ({"input_jitter": -1}, {"threads": 0}, {"graph_optimization": "no"}, {"seed": True}):
        with pytest.raises(ValueError, match="perturbation"):
            Perturbation(**bad)


def test_perturbed_sessions_run_the_model_with_other_kernels_and_agree_closely():
    """threads and graph_optimization reach onnxruntime's session; the model's output moves in its last
    bits at most (what another processor does), while a jittered input moves it more."""
    import onnxruntime as ort

    from reloc.detection.learned import Perturbation

    rng = np.random.default_rng(0)
    rgb = rng.random((120, 160, 3)).astype(np.float32) ** 2
    base = LearnedDetector(MODEL)
    other = LearnedDetector(MODEL, perturbation=Perturbation(threads=2, graph_optimization=False))
    opts = other.session.get_session_options()
    assert opts.intra_op_num_threads == 2
    assert opts.graph_optimization_level == ort.GraphOptimizationLevel.ORT_DISABLE_ALL
    assert base.session.get_session_options().graph_optimization_level != ort.GraphOptimizationLevel.ORT_DISABLE_ALL
    c0, p0, b0 = base.predict(rgb, 5)
    c1, p1, b1 = other.predict(rgb, 5)
    assert np.abs(p0 - p1).max() < 1e-3 and np.abs(b0 - b1).max() < 1e-3 and (c0 != c1).mean() < 0.01
    c2, p2, _ = LearnedDetector(MODEL, perturbation=Perturbation(input_jitter=1, seed=1)).predict(rgb, 5)
    assert np.abs(p0 - p2).max() > np.abs(p0 - p1).max()
