"""Generated files do not depend on last-bit floating point.

Another processor or maths library (FMA, libm's SIMD sin/cos/atan2, BLAS kernels) can change the
last bit of a computed value. These tests make that happen on purpose: the generators run with
every trigonometric result and every random draw moved by one ulp, and the stored layout must
come out byte for byte the same as the shipped file.
"""

from __future__ import annotations

import json
import math
import types

import numpy as np
import pytest

import vrformats.camera
import vrformats.yamlfile
import synth.layout.apartment
import synth.scene.geometry
import synth.layout.placement
import synth.layout.rearrange
import synth.scene.model
from synth.layout.apartment import DEFAULT_SEED, generate_apartment
from synth.layout.rearrange import BUILTIN_VARIANTS, make_variant, reference_walkway
from synth.resources import layouts_dir
from synth.scene.model import (
    ObjectInstance,
    boxes_document,
    load_layout,
    dump_yaml,
    layout_from_dict,
    layout_to_dict,
    quantize,
    quantize_quat,
)


def _up(x):
    """``x`` moved one ulp towards +inf (scalars, tuples and arrays alike)."""
    if isinstance(x, tuple):
        return tuple(_up(v) for v in x)
    if isinstance(x, np.ndarray):
        return np.nextafter(x, np.inf)
    if isinstance(x, (float, np.floating)):
        return float(np.nextafter(float(x), math.inf))
    return x


class _Counter:
    calls = 0


def _nudged(fn):
    def wrapped(*a, **k):
        _Counter.calls += 1
        return _up(fn(*a, **k))

    return wrapped


class _NudgedRng:
    """A numpy Generator whose continuous draws come out one ulp larger."""

    def __init__(self, rng):
        self._rng = rng

    def __getattr__(self, name):
        attr = getattr(self._rng, name)
        return _nudged(attr) if name in ("uniform", "normal", "random") else attr


@pytest.fixture
def one_ulp_off(monkeypatch):
    """Call it to put every sin/cos/atan2/hypot/sqrt in the generators, every geometry helper and
    every continuous random draw one ulp off, for the rest of the test."""

    def apply():
        fake_math = types.SimpleNamespace(**{k: getattr(math, k) for k in dir(math) if not k.startswith("_")})
        for name in ("sin", "cos", "atan2", "hypot", "sqrt"):
            setattr(fake_math, name, _nudged(getattr(math, name)))
        for mod in (synth.layout.apartment, synth.layout.placement, synth.layout.rearrange, synth.scene.geometry, synth.scene.model, vrformats.camera):
            monkeypatch.setattr(mod, "math", fake_math)
        for name in ("yaw_to_quat", "matrix_to_quat", "rot_z", "quat_to_matrix", "quat_yaw"):
            monkeypatch.setattr(synth.scene.geometry, name, _nudged(getattr(synth.scene.geometry, name)))
        real_rng = np.random.default_rng
        monkeypatch.setattr(np.random, "default_rng", lambda *a, **k: _NudgedRng(real_rng(*a, **k)))
        _Counter.calls = 0

    yield apply
    assert _Counter.calls > 100, "the perturbation never reached the code under test"


@pytest.mark.slow
def test_one_ulp_changes_no_stored_layout(one_ulp_off):
    one_ulp_off()
    ref = generate_apartment(DEFAULT_SEED, "apt_0")
    assert dump_yaml(layout_to_dict(ref)) == (layouts_dir() / "apt_0.yaml").read_text()
    spec = next(v for v in BUILTIN_VARIANTS if v.name == "apt_2")  # the one the other CPU changed first
    var = make_variant(ref, spec, walkway=reference_walkway(ref))
    assert dump_yaml(layout_to_dict(var)) == (layouts_dir() / "apt_2.yaml").read_text()


def test_one_ulp_changes_no_box_file(one_ulp_off):
    clean = [json.dumps(boxes_document(load_layout(n))) for n in ("apt_0", "apt_2")]
    one_ulp_off()
    assert [json.dumps(boxes_document(load_layout(n))) for n in ("apt_0", "apt_2")] == clean


def test_the_model_holds_what_the_file_holds():
    noisy = ObjectInstance(1, "chair", "proc:chair", (1.5878279167280076, 6.356190352350183, 0.417),
                           (0.40381331100472, -0.0, -0.0, -0.9148414124073119), (0.5, 0.5, 0.9), (0.0, 0.0, 0.45))
    clean = ObjectInstance(1, "chair", "proc:chair", (1.587827916728008, 6.356190352350183, 0.417),
                           (0.40381331100471995, -0.0, -0.0, -0.914841412407312), (0.5, 0.5, 0.9), (0.0, 0.0, 0.45))
    assert noisy == clean  # the pair the other processor wrote (issue 12) is one value now
    assert noisy.position == (1.5878, 6.3562, 0.417)
    assert noisy.rotation == (0.403813311, 0.0, 0.0, -0.914841412)
    assert not any(math.copysign(1.0, v) < 0 for v in noisy.rotation[1:3])  # no -0.0 in files


def test_quantising_is_idempotent_and_keeps_rotations_unit():
    rng = np.random.default_rng(0)
    for q in rng.normal(size=(2000, 4)):
        a = quantize_quat(q)
        assert quantize_quat(a) == a
        assert abs(math.sqrt(sum(v * v for v in a)) - 1.0) < 1e-8
    for x in rng.uniform(-20, 20, 2000):
        assert quantize(quantize(x)) == quantize(x) and abs(quantize(x) - x) <= 0.5e-4 + 1e-12


def test_shipped_layouts_are_stored_quantised():
    for p in sorted(layouts_dir().glob("apt_*.yaml")):
        doc = vrformats.yamlfile.read_yaml(p)
        again = dump_yaml(layout_to_dict(layout_from_dict(doc, source=str(p))))
        assert again == p.read_text(), p.name
        for o in doc["objects"]:
            assert all(round(v, 4) == v for v in o["position"] + o["size"]), (p.name, o["id"])
            assert all(round(v, 9) == v for v in o["rotation"]), (p.name, o["id"])
