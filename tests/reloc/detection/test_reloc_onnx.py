"""OnnxDetector: decoding of YOLO-style segmentation outputs, checked against hand-computed pixels.

The test models are built here with ``onnx.helper``: their outputs are constants (known boxes,
classes, mask coefficients and prototypes) plus a term computed from the image, so the image
input is wired and one box's score tells what image the detector fed the model.

Model input 64x64, prototypes 16x16 (4 input pixels per prototype pixel), nm = 2:
prototype 0 is all ones, prototype 1 is ones on the left half (input x < 32). Boxes (input pixels,
x1 y1 x2 y2), class, score, coefficients:

    A  8 20 24 36   0 chair  0.9     (10, 0)    -> mask = the box
    B  9 21 25 37   0 chair  0.8     (10, 0)    duplicate of A (IoU 225/287 = 0.78)
    C  8 20 24 36   1 couch  0.7     (10, 0)    same box as A, other class
    D 28 24 60 44   2 tv     image   (-10, 20)  -> mask = box and input x < 32
    E  0 16 10 26   2 tv     0.1     (10, 0)    weak

D's score is the mean of the model input's channel 0: for a frame of linear RGB (0.25, 0, 0)
whose content covers half the input, 0.5 * q + 0.5 * 114/255 with q = 8-bit sRGB of 0.25.
"""

from __future__ import annotations

import numpy as np
import onnx
import pytest
from onnx import TensorProto, helper, numpy_helper

from reloc.detection.base import FrameData
from reloc.detection.onnx_yolo import OnnxDetector

from vrformats.errors import UserError


NAMES = {0: "chair", 1: "couch", 2: "tv"}
NM, MH, MW = 2, 16, 16
BOXES = [  # x1, y1, x2, y2, class, score (None: from the image), coefficients
    (8, 20, 24, 36, 0, 0.9, (10, 0)),
    (9, 21, 25, 37, 0, 0.8, (10, 0)),
    (8, 20, 24, 36, 1, 0.7, (10, 0)),
    (28, 24, 60, 44, 2, None, (-10, 20)),
    (0, 16, 10, 26, 2, 0.1, (10, 0)),
]
D_INDEX = 3


def _srgb(v: float) -> float:
    return 12.92 * v if v <= 0.0031308 else 1.055 * v ** (1 / 2.4) - 0.055


Q = round(_srgb(0.25) * 255) / 255  # 137/255
D_SCORE = 0.5 * Q + 0.5 * 114 / 255  # content covers half of the 64x64 input


def _preds(boxes=BOXES, nc=3):
    P = np.zeros((4 + nc + NM, len(boxes)), np.float32)
    for n, (x1, y1, x2, y2, c, s, co) in enumerate(boxes):
        P[:4, n] = ((x1 + x2) / 2, (y1 + y2) / 2, x2 - x1, y2 - y1)
        P[4 + c, n] = 0.0 if s is None else s
        P[4 + nc:, n] = co
    return P


def _protos():
    p = np.zeros((NM, MH, MW), np.float32)
    p[0] = 1.0
    p[1][:, : MW // 2] = 1.0
    return p


def make_model(path, preds=None, protos=None, *, transposed=False, names=NAMES, image_score=(2, D_INDEX),
               input_dims=(1, 3, 64, 64), input_type=TensorProto.FLOAT, drop_batch=False, meta=None):
    """An ONNX file whose outputs are known constants plus (mean of input channel 0) at one place."""
    preds = _preds() if preds is None else preds
    protos = _protos() if protos is None else protos
    base = preds.copy()
    onehot = np.zeros_like(base)
    if image_score is not None:
        c, n = image_score
        base[4 + c, n] = 0.0
        onehot[4 + c, n] = 1.0
    if transposed:
        base, onehot = base.T, onehot.T
    if not drop_batch:
        base, onehot = base[None], onehot[None]
    inits = [
        numpy_helper.from_array(np.ascontiguousarray(base), "base"),
        numpy_helper.from_array(np.ascontiguousarray(onehot), "onehot"),
        numpy_helper.from_array(protos[None].astype(np.float32), "protos"),
        numpy_helper.from_array(np.array([0], np.int64), "c0"),
        numpy_helper.from_array(np.array([1], np.int64), "c1"),
        numpy_helper.from_array(np.array(0.0, np.float32), "zero"),
    ]
    nodes = []
    img = "images"
    if input_type != TensorProto.FLOAT:
        nodes.append(helper.make_node("Cast", ["images"], ["images_f"], to=TensorProto.FLOAT))
        img = "images_f"
    nodes += [
        helper.make_node("Slice", [img, "c0", "c1", "c1"], ["ch0"]),  # channel 0 (axis 1)
        helper.make_node("ReduceMean", ["ch0"], ["mean"], keepdims=0),  # a scalar
        helper.make_node("Mul", ["onehot", "mean"], ["term"]),
        helper.make_node("Add", ["base", "term"], ["output0"]),
        helper.make_node("Mul", ["mean", "zero"], ["nothing"]),
        helper.make_node("Add", ["protos", "nothing"], ["output1"]),
    ]
    graph = helper.make_graph(
        nodes, "tiny_seg",
        [helper.make_tensor_value_info("images", input_type, list(input_dims))],
        [helper.make_tensor_value_info("output0", TensorProto.FLOAT, list(base.shape)),
         helper.make_tensor_value_info("output1", TensorProto.FLOAT, [1, NM, MH, MW])],
        initializer=inits)
    model = helper.make_model(graph, opset_imports=[helper.make_opsetid("", 17)])
    model.ir_version = 8
    props = dict(meta or {})
    if names is not None:
        props["names"] = str(names)  # as Ultralytics writes it: "{0: 'chair', 1: 'couch', 2: 'tv'}"
    if props:
        helper.set_model_props(model, props)
    onnx.checker.check_model(model)
    onnx.save(model, str(path))
    return path


def frame(W, H, rgb=(0.25, 0.0, 0.0), index=0):
    img = np.empty((H, W, 3), np.float32)
    img[:] = rgb
    return FrameData(index=index, depth=np.ones((H, W), np.float32), K=np.eye(3), rgb=img)


def rect(H, W, x0, y0, x1, y1):
    """Boolean mask of the pixels x0..x1-1, y0..y1-1."""
    m = np.zeros((H, W), bool)
    m[y0:y1, x0:x1] = True
    return m


def by_class(dets):
    return {d.cls: d for d in dets}


@pytest.fixture(scope="module")
def model(tmp_path_factory):
    return make_model(tmp_path_factory.mktemp("onnx") / "tiny.onnx")


@pytest.fixture(scope="module")
def detector(model):
    return OnnxDetector(model)


# ---------------------------------------------------------------- decoding


def test_landscape_frame_masks_scores_and_classes(detector):
    # 128x64 frame -> scale 1/2, content rows 16..47 of the input: frame x = 2 xin, y = 2 (yin - 16)
    dets = detector.detect(frame(128, 64))
    assert [d.cls for d in dets] == ["chair", "couch", "tv"]  # by score; B suppressed, E too weak
    d = by_class(dets)
    assert d["chair"].score == pytest.approx(0.9) and d["couch"].score == pytest.approx(0.7)
    assert d["tv"].score == pytest.approx(D_SCORE, abs=1e-5)  # sRGB, 8-bit, RGB order, 114 padding
    for x in dets:
        assert x.mask.shape == (64, 128) and x.mask.dtype == bool and x.track_id is None
    # A: input x 8..24, y 20..36 -> frame x 16..47, y 8..39
    assert np.array_equal(d["chair"].mask, rect(64, 128, 16, 8, 48, 40))
    assert d["chair"].box2d == (16, 8, 47, 39)
    assert np.array_equal(d["couch"].mask, d["chair"].mask)
    # D: input x 28..60 but prototype 1 only left of input x 32 -> frame x 56..63; y 24..44 -> 16..55
    assert np.array_equal(d["tv"].mask, rect(64, 128, 56, 16, 64, 56))


def test_portrait_frame_pads_left_and_right(detector):
    # 64 wide x 128 high -> scale 1/2, content columns 16..47: frame x = 2 (xin - 16), y = 2 yin
    d = by_class(detector.detect(frame(64, 128)))
    assert set(d) == {"chair", "couch", "tv"}
    # A: input x 8..24 starts in the padding -> frame x 0..15; y 20..36 -> 40..71
    assert np.array_equal(d["chair"].mask, rect(128, 64, 0, 40, 16, 72))
    # D: input x 28..32 (prototype) -> frame 24..31; y 24..44 -> 48..87
    assert np.array_equal(d["tv"].mask, rect(128, 64, 24, 48, 32, 88))
    assert d["tv"].score == pytest.approx(D_SCORE, abs=1e-5)


def test_fractional_letterbox(detector):
    # 96x64 frame -> 64x43 content, padding 10 above and 11 below (as Ultralytics rounds it):
    # frame x = 1.5 xin, y = (yin - 10) * 64 / 43. A: x 12..36, y 14.88..38.70 (continuous edges)
    d = by_class(detector.detect(frame(96, 64)))
    a = d["chair"]
    edges = (12.0, 14.88, 36.0, 38.70)
    x0, y0, x1, y1 = a.box2d
    assert abs(x0 - edges[0]) <= 1 and abs(y0 - edges[1]) <= 1
    assert abs(x1 + 1 - edges[2]) <= 1 and abs(y1 + 1 - edges[3]) <= 1
    ideal = rect(64, 96, 12, 15, 36, 39)
    iou = (a.mask & ideal).sum() / (a.mask | ideal).sum()
    assert iou > 0.9
    # content is 43/64 of the input here
    assert d["tv"].score == pytest.approx(43 / 64 * Q + 21 / 64 * 114 / 255, abs=1e-5)


def test_transposed_layout_decodes_identically(tmp_path, detector):
    t = OnnxDetector(make_model(tmp_path / "t.onnx", transposed=True))
    f = frame(128, 64)
    a, b = detector.detect(f), t.detect(f)
    assert [x.cls for x in a] == [x.cls for x in b]
    for x, y in zip(a, b):
        assert x.score == pytest.approx(y.score) and np.array_equal(x.mask, y.mask)


def test_nms_threshold_and_max_detections(model):
    f = frame(128, 64)
    # a looser IoU threshold keeps the duplicate chair B: input 9..25 x 21..37 -> frame 18..49 x 10..41
    loose = OnnxDetector(model, iou_threshold=0.9).detect(f)
    chairs = [d for d in loose if d.cls == "chair"]
    assert [c.score for c in chairs] == pytest.approx([0.9, 0.8])
    assert np.array_equal(chairs[1].mask, rect(64, 128, 18, 10, 50, 42))
    # a lower score threshold keeps the weak tv E: input 0..10 x 16..26 -> frame 0..19 x 0..19
    low = OnnxDetector(model, score_threshold=0.05).detect(f)
    tvs = sorted((d for d in low if d.cls == "tv"), key=lambda d: d.score)
    assert len(tvs) == 2 and tvs[0].score == pytest.approx(0.1)
    assert np.array_equal(tvs[0].mask, rect(64, 128, 0, 0, 20, 20))
    assert len([d for d in low if d.cls == "chair"]) == 1
    # a score threshold above 0.7 leaves only the chair
    assert [d.cls for d in OnnxDetector(model, score_threshold=0.75).detect(f)] == ["chair"]
    assert [d.cls for d in OnnxDetector(model, max_detections=2).detect(f)] == ["chair", "couch"]


def test_class_maps_rename_and_drop(tmp_path, model):
    f = frame(128, 64)
    (tmp_path / "map.yaml").write_text("0: chair\n1: sofa\n2: null\n")
    (tmp_path / "map.json").write_text('{"0": "chair", "1": "sofa"}')
    (tmp_path / "data.yaml").write_text("path: x\nnames:\n  0: chair\n  1: sofa\n")
    for cm in ({0: "chair", 1: "sofa"}, {"couch": "sofa", "chair": "chair", "tv": None},
               tmp_path / "map.yaml", str(tmp_path / "map.json"), tmp_path / "data.yaml"):
        dets = OnnxDetector(model, class_map=cm).detect(f)
        assert [d.cls for d in dets] == ["chair", "sofa"], cm
    # an index-keyed map works without names metadata
    bare = make_model(tmp_path / "bare.onnx", names=None)
    assert [d.cls for d in OnnxDetector(bare, class_map={2: "monitor"}).detect(f)] == ["monitor"]


def test_vocabulary_filter(model):
    f = frame(128, 64)
    assert [d.cls for d in OnnxDetector(model, vocabulary={"chair", "lamp"}).detect(f)] == ["chair"]
    det = OnnxDetector(model, class_map={0: "chair", 1: "sofa", 2: "tv"}, vocabulary=["sofa", "tv"])
    assert [d.cls for d in det.detect(f)] == ["sofa", "tv"]
    assert OnnxDetector(model, vocabulary=set()).detect(f) == []


def test_names_metadata_dynamic_input_float16_threads(tmp_path, detector):
    assert detector.model_names == NAMES
    assert detector.input_size == (64, 64)
    assert detector.session.get_session_options().intra_op_num_threads == 1
    f = frame(128, 64)
    ref = detector.detect(f)
    dyn = make_model(tmp_path / "dyn.onnx", input_dims=("batch", 3, "height", "width"))
    for det in (OnnxDetector(dyn, imgsz=64, intra_op_num_threads=2),
                OnnxDetector(make_model(tmp_path / "meta.onnx", input_dims=("b", 3, "h", "w"),
                                        meta={"imgsz": "[64, 64]"})),
                OnnxDetector(make_model(tmp_path / "half.onnx", input_type=TensorProto.FLOAT16))):
        assert det.input_size == (64, 64)
        out = det.detect(f)
        assert [d.cls for d in out] == [d.cls for d in ref]
        assert all(np.array_equal(a.mask, b.mask) for a, b in zip(out, ref))
        assert out[-1].score == pytest.approx(ref[-1].score, abs=2e-3)  # float16 input rounds
    assert OnnxDetector(dyn, imgsz=64, intra_op_num_threads=2).session.get_session_options().intra_op_num_threads == 2


def test_camera_sized_frame(detector):
    # 640x480 -> scale 0.1, content rows 8..55: A (input 8..24 x 20..36) -> frame 80..239 x 120..279
    d = by_class(detector.detect(frame(640, 480)))
    assert d["chair"].mask.shape == (480, 640)
    assert np.array_equal(d["chair"].mask, rect(480, 640, 80, 120, 240, 280))

# ---------------------------------------------------------------- bad input


def test_missing_and_garbage_model(tmp_path):
    with pytest.raises(UserError, match="nope.onnx.*not found"):
        OnnxDetector(tmp_path / "nope.onnx")
    bad = tmp_path / "garbage.onnx"
    bad.write_bytes(b"this is not an ONNX model\x00\x01")
    with pytest.raises(UserError, match="garbage.onnx.*not a readable ONNX model") as e:
        OnnxDetector(bad)
    assert "\n" not in str(e.value)


def test_wrong_output_rank(tmp_path):
    m = make_model(tmp_path / "rank2.onnx", drop_batch=True)
    with pytest.raises(UserError, match="rank2.onnx.*expected two outputs") as e:
        OnnxDetector(m)
    assert "\n" not in str(e.value)


def test_wrong_output_shape_at_run_time(tmp_path):
    # 4 + nm rows: no class scores at all
    m = make_model(tmp_path / "noclass.onnx", preds=np.zeros((4 + NM, 3), np.float32), image_score=None)
    det = OnnxDetector(m)
    with pytest.raises(UserError, match="noclass.onnx.*predictions have shape"):
        det.detect(frame(64, 64))


@pytest.mark.parametrize("text, why", [
    ("0: chair\n1: [sofa\n", "malformed YAML"),
    ("0: [chair, sofa]\n", "expected a class name or null"),
    ("just a string\n", "expected a mapping"),
    ("0: chair\n'0': sofa\n", "given twice"),
    ("cuoch: sofa\n", "'cuoch' is not a class"),
    ("", "expected a mapping"),
])
def test_malformed_class_map(tmp_path, model, text, why):
    p = tmp_path / "classes.yaml"
    p.write_text(text)
    with pytest.raises(UserError, match=why) as e:
        OnnxDetector(model, class_map=p)
    assert str(p) in str(e.value) and "\n" not in str(e.value)


def test_class_names_needed(tmp_path, model):
    bare = make_model(tmp_path / "bare.onnx", names=None)
    with pytest.raises(UserError, match="bare.onnx.*no 'names' metadata"):
        OnnxDetector(bare)
    with pytest.raises(UserError, match="model class names"):
        OnnxDetector(bare, class_map={"couch": "sofa"})
    with pytest.raises(UserError, match="missing.yaml.*class map not found"):
        OnnxDetector(model, class_map=tmp_path / "missing.yaml")


def test_frame_without_rgb(detector):
    f = frame(64, 64)
    f.rgb = None
    with pytest.raises(UserError, match="tiny.onnx.*needs RGB frames"):
        detector.detect(f)
