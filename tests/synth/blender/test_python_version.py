"""Blender on the wrong Python: one line naming the version it needs, before any work (the bpy wheel
exists for Python 3.11 only; on another one ``import bpy`` says only "No module named 'bpy'")."""

from __future__ import annotations

import pytest

from synth.cli import main as synth_main
from tests.cli_errors import nothing_left, one_line_error


def test_the_python_check_names_the_version_needed_and_the_one_running():
    from synth.blender import PYTHON, python_problem

    assert python_problem(PYTHON) is None
    why = python_problem((3, 12))
    assert "Python 3.11" in why and "this is Python 3.12" in why and "make PY=" in why


def test_a_blender_render_on_another_python_is_one_line_and_writes_nothing(tmp_path, monkeypatch, capsys):
    import synth.blender as blender

    real = blender.python_problem
    monkeypatch.setattr(blender, "python_problem", lambda version=None: real(version or (3, 12, 1)))  # as on 3.12
    assert synth_main(["tour", "render", "apt_0", "query", "--frames", "2", "--size", "32x24",
                       "--out", str(tmp_path / "t")]) == 2
    one_line_error(capsys, "Python 3.11", "this is Python 3.12")
    nothing_left(tmp_path)
    # the fast renderer needs no bpy: the same command with it is not refused for the version
    assert synth_main(["tour", "render", "apt_0", "query", "--frames", "2", "--size", "32x24", "--renderer", "fast",
                       "--out", str(tmp_path / "f")]) == 0


def test_every_module_that_imports_bpy_checks_the_python_first():
    from pathlib import Path

    import synth.blender as pkg

    for f in sorted(Path(pkg.__file__).parent.glob("*.py")):
        lines = f.read_text().splitlines()
        if "import bpy" in lines or "import bpy  # noqa: E402" in lines:
            first_bpy = next(i for i, line in enumerate(lines) if line.startswith("import bpy"))
            assert any(line.startswith("require_python()") for line in lines[:first_bpy]), f.name


@pytest.mark.parametrize("size", ["99999x99999", "8193x10", "5000x5000"])
def test_a_frame_too_large_to_render_is_one_line_before_any_work(size, tmp_path, capsys):
    assert synth_main(["tour", "render", "apt_0", "query", "--frames", "1", "--size", size, "--renderer", "fast",
                       "--out", str(tmp_path / "t")]) == 2
    one_line_error(capsys, size, "too large")
    nothing_left(tmp_path)
