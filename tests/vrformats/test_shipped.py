"""The shipped-name lookup of the spec arguments (vrformats.shipped): a path wins, a bare name is the
shipped spec of its kind, a broken shipped spec says what is wrong with it."""

from __future__ import annotations

import pytest

from vrformats.errors import SceneFormatError, UnknownNameError
from vrformats.shipped import resolve_spec, shipped_names
from vrformats.yamlfile import read_yaml


def _folder(tmp_path):
    d = tmp_path / "specs"
    d.mkdir()
    (d / "job.yaml").write_text("name: job\ndesigns: []\n")
    (d / "exp.yaml").write_text("name: exp\nrender: job\n")
    (d / "broken.yaml").write_text("name: broken\ndesigns: [\n")
    return d


def test_a_bare_name_is_the_shipped_spec_of_its_kind(tmp_path, monkeypatch):
    d = _folder(tmp_path)
    monkeypatch.chdir(tmp_path)
    assert resolve_spec("job", d, "render job spec", "designs") == d / "job.yaml"
    assert shipped_names(d, "designs") == ["job"] and shipped_names(d, "render") == ["exp"]
    with pytest.raises(UnknownNameError, match=r"^exp: no such file, and no shipped render job spec of that name; "
                                               r"shipped: job \(in "):
        resolve_spec("exp", d, "render job spec", "designs")  # a spec of another kind is not one of these
    (tmp_path / "job").write_text("name: mine\n")
    assert resolve_spec("job", d, "render job spec", "designs").resolve() == (tmp_path / "job").resolve()  # a file wins


def test_a_broken_shipped_spec_is_reported_as_broken_not_as_missing(tmp_path):
    d = _folder(tmp_path)
    p = resolve_spec("broken", d, "render job spec", "designs")
    assert p == d / "broken.yaml"
    with pytest.raises(SceneFormatError, match=r"broken\.yaml: malformed YAML"):
        read_yaml(p)
