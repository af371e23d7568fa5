"""The shipped learned detector (reloc/models/detector_160x120.onnx) against rendered ground truth.

Six random views of apt_0 (an experiment layout the model never trained on) are rendered here in
day and night light; the model's per-pixel classes and its instances are compared with the
frames' rendered labels. The floors sit below what was measured on three view seeds (pixel
accuracy 0.91-0.93 day, 0.85-0.87 night; mean best mask IoU of instances of at least 200 pixels
0.63-0.67 day, 0.54-0.56 night), with a margin; an untrained model scores near 0.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from formats.tour import Tour
from reloc.detection.base import FrameData
from reloc.detection.learned import LearnedDetector
from synth.paths.files import save_path
from synth.paths.views import plan_views
from synth.scene.model import load_layout
from synth.render.render_tour import TourSpec, render_tour

MODEL = Path(__file__).resolve().parents[1] / "reloc" / "models" / "detector_160x120.onnx"
FLOORS = {"day": (0.82, 0.52), "night": (0.76, 0.45)}  # pixel accuracy, mean best mask IoU


@pytest.fixture(scope="module")
def views(tmp_path_factory):
    root = tmp_path_factory.mktemp("shipped")
    return save_path(plan_views([load_layout("apt_0")], 6, seed=0), root / "views.txt")


@pytest.mark.slow
@pytest.mark.blender
@pytest.mark.parametrize("lighting", ["day", "night"])
def test_shipped_model_finds_apt_0_in_day_and_night(views, lighting):
    d = views.parent / lighting
    render_tour(TourSpec(layout="apt_0", path=str(views), lighting=lighting, out=str(d), width=160, height=120),
                progress=False)
    tour = Tour(d)
    det = LearnedDetector(MODEL, vocabulary=set(tour.objects()["classes"]))  # covers the map's classes
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
    floor_acc, floor_iou = FLOORS[lighting]
    assert len(ious) >= 30
    assert np.mean(acc) >= floor_acc, acc
    assert np.mean(ious) >= floor_iou, np.mean(ious)
