"""The render cache (synth.render.cache): a value is computed once per key, a changed input is a new
key, and a damaged, linked or unwritable cache costs only the computation. Then the one value cached
today, the structure ids of a mesh stage's triangles, on the ReplicaCAD-shaped fixture: the second
build reads them (face_ids is not called) and gives the same parts."""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))
import replicacad_fixture as F  # noqa: E402

from synth.render import cache  # noqa: E402


@pytest.fixture
def cdir(tmp_path, monkeypatch):
    d = tmp_path / "cache"
    monkeypatch.setenv(cache.ENV, str(d))
    return d


def counting(value):
    calls = []

    def compute():
        calls.append(1)
        return np.asarray(value, dtype=np.int64)

    return compute, calls


def test_computed_once_per_key(cdir):
    compute, calls = counting([1, 2, 3])
    a = cache.cached_array("k", ["x"], compute)
    b = cache.cached_array("k", ["x"], compute)
    assert calls == [1] and a.tolist() == b.tolist() == [1, 2, 3]
    cache.cached_array("k", ["y"], compute)  # another input: another entry
    cache.cached_array("other", ["x"], compute)  # another kind of value
    assert calls == [1, 1, 1]
    assert len(list((cdir / "k").glob("*.npy"))) == 2 and not list(cdir.rglob("*.tmp*"))


def test_an_entry_the_validator_refuses_is_computed_again(cdir):
    compute, calls = counting([1, 2, 3])
    cache.cached_array("k", ["x"], compute)
    out = cache.cached_array("k", ["x"], compute, validate=lambda a: a.shape == (4,))
    assert calls == [1, 1] and out.tolist() == [1, 2, 3]


def test_a_damaged_entry_is_computed_again_and_rewritten(cdir):
    compute, calls = counting([5, 6])
    cache.cached_array("k", ["x"], compute)
    (entry,) = (cdir / "k").glob("*.npy")
    entry.write_bytes(b"not an array")
    assert cache.cached_array("k", ["x"], compute).tolist() == [5, 6] and calls == [1, 1]
    assert np.load(entry).tolist() == [5, 6]
    # a pickled object array is never loaded (allow_pickle=False): computed again
    np.save(entry, np.array([{"a": 1}], dtype=object), allow_pickle=True)
    assert cache.cached_array("k", ["x"], compute).tolist() == [5, 6] and calls == [1, 1, 1]


def test_a_linked_entry_is_not_followed(cdir, tmp_path):
    compute, calls = counting([7])
    cache.cached_array("k", ["x"], compute)
    (entry,) = (cdir / "k").glob("*.npy")
    elsewhere = tmp_path / "elsewhere.npy"
    np.save(elsewhere, np.array([99], dtype=np.int64))
    entry.unlink()
    entry.symlink_to(elsewhere)
    assert cache.cached_array("k", ["x"], compute).tolist() == [7] and calls == [1, 1]
    assert np.load(elsewhere).tolist() == [99]  # the link's target is left alone
    assert not entry.is_symlink()  # replaced by a real entry


def test_off_unwritable_and_unknown_code(cdir, monkeypatch, tmp_path):
    compute, calls = counting([1])
    monkeypatch.setenv(cache.ENV, "")
    assert cache.cache_dir() is None
    cache.cached_array("k", ["x"], compute)
    cache.cached_array("k", ["x"], compute)
    assert calls == [1, 1]
    blocker = tmp_path / "a_file"
    blocker.write_text("")
    monkeypatch.setenv(cache.ENV, str(blocker / "cache"))  # cannot be made: computed, nothing raised
    assert cache.cached_array("k", ["x"], compute).tolist() == [1] and calls == [1, 1, 1]
    monkeypatch.setenv(cache.ENV, str(cdir))
    cache.cached_array("k", ["x", None], compute)  # a key part that cannot be told: never cached
    cache.cached_array("k", ["x", None], compute)
    assert calls == [1, 1, 1, 1, 1] and not cdir.exists()


def test_default_folder_follows_xdg(monkeypatch, tmp_path):
    monkeypatch.delenv(cache.ENV, raising=False)
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path))
    assert cache.cache_dir() == tmp_path / "videoreloc-synth"


def test_code_digest_changes_with_the_source_and_refuses_stand_ins(monkeypatch):
    import types

    d = cache.code_digest("synth.render.cache")
    assert d and d == cache.code_digest("synth.render.cache")
    assert d != cache.code_digest("synth.render.cache", "synth.render.settings")
    monkeypatch.setitem(sys.modules, "some_stand_in", types.SimpleNamespace())
    assert cache.code_digest("synth.render.cache", "some_stand_in") is None


def test_stage_face_ids_are_read_back_on_the_second_build(cdir, tmp_path, monkeypatch):
    import synth.mesh.stage_structure as ss
    from synth.render.meshes import stage_parts
    from synth.sources.replicacad.importer import load_replicacad

    root = F.make_fixture(tmp_path / "rcad")
    lay = load_replicacad(root, "apt_0", allow_unknown=False)
    assert lay.stage.walls and lay.stage.rooms  # the split (and so face_ids) is used
    first = stage_parts(lay)
    assert len(list((cdir / "stage_face_ids").glob("*.npy"))) == 1

    def boom(*a, **k):
        raise AssertionError("face_ids called: the cached ids were not used")

    monkeypatch.setattr(ss, "face_ids", boom)
    second = stage_parts(lay)
    assert [(p.name, p.instance_id, p.semantic_id) for p in first] == [(p.name, p.instance_id, p.semantic_id) for p in second]
    for p, q in zip(first, second):
        assert np.array_equal(p.mesh.faces, q.mesh.faces) and np.array_equal(p.mesh.vertices, q.mesh.vertices)
    # another stage structure (a wall moved) is another key: computed again
    lay2 = lay.copy()
    w = lay2.stage.walls[0]
    lay2.stage.walls[0] = type(w)(w.id, (w.start[0] + 0.01, w.start[1]), w.end, w.thickness, w.height)
    with pytest.raises(AssertionError, match="face_ids called"):
        stage_parts(lay2)
