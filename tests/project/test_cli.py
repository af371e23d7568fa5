"""Command line: what a user types and sees, and the architecture rule that bpy stays out of the model."""

from __future__ import annotations

import json
import subprocess
import sys

import matplotlib.image as mpimg
import pytest

from synth.cli import main as synth_main
from synth.resources import REPO_ROOT as REPO


def test_list_and_show(capsys):
    assert synth_main(["scene", "list"]) == 0
    out = capsys.readouterr().out
    for n in range(6):
        assert f"apt_{n}" in out
    assert synth_main(["scene", "show", "apt_0", "--json"]) == 0
    s = json.loads(capsys.readouterr().out)
    assert s["objects"] >= 90 and len(s["classes"]) >= 25 and len(s["rooms"]) >= 5
    assert synth_main(["scene", "show", "apt_2"]) == 0
    assert "rearranged from apt_0" in capsys.readouterr().out


def test_a_bare_name_is_a_shipped_spec_and_a_file_wins(tmp_path, monkeypatch, capsys):
    """synth render NAME, synth trainset render NAME: a bare name is a spec of render_jobs, a file of
    that name wins, and an unknown name is one line listing the shipped ones of that kind (exit 2)."""
    import yaml

    from synth.trainset.trainset import load_trainset
    from synth.jobs import load_spec
    from synth.resources import SPECS_DIR, render_specs

    monkeypatch.chdir(tmp_path)
    assert load_spec("smoke").source == str(SPECS_DIR / "smoke.yaml")
    assert load_trainset("detector_train").name == "detector_train"
    assert {"demo", "smoke", "replicacad_6x3"} <= set(render_specs()) and "detector_train" not in render_specs()
    doc = yaml.safe_load((SPECS_DIR / "smoke.yaml").read_text())
    (tmp_path / "smoke").write_text(yaml.safe_dump({**doc, "name": "mine"}))
    assert load_spec("smoke").name == "mine"
    for argv, shipped in ((["render", "nosuch", "--dry-run"], "demo, detector_eval, quickstart, reference, replicacad_6x3, "
                                                             "replicacad_apt_6x3, replicacad_demo, replicacad_stages, smoke, sweep_rearrangement ("),
                          (["trainset", "render", "nosuch"], "shipped: detector_train, detector_train_replicacad, detector_train_v2 (")):
        assert synth_main(argv) == 2
        err = capsys.readouterr().err.strip()
        assert len(err.splitlines()) == 1 and err.startswith("synth: error: nosuch: no such file") and shipped in err, err


def test_a_user_scenes_folder_overrides_the_shipped_one(tmp_path, monkeypatch, capsys):
    """SYNTH_SCENES_DIR replaces scenes as a whole (class table included): its layouts are the
    ones listed and found by name."""
    import shutil

    from synth.resources import DATA_DIR, layouts_dir

    (tmp_path / "layouts").mkdir()
    shutil.copy(DATA_DIR / "layouts" / "apt_0.yaml", tmp_path / "layouts" / "mine.yaml")
    shutil.copy(DATA_DIR / "classes.yaml", tmp_path / "classes.yaml")  # the whole folder is replaced
    monkeypatch.setenv("SYNTH_SCENES_DIR", str(tmp_path))
    assert layouts_dir() == tmp_path / "layouts"
    assert synth_main(["scene", "list"]) == 0
    out = capsys.readouterr().out
    assert "mine" in out and "apt_1" not in out
    assert synth_main(["scene", "show", "mine"]) == 0 and "apt_0" in capsys.readouterr().out  # the file's own name


def test_preview_cli_writes_png(tmp_path, capsys):
    out = tmp_path / "sub" / "d.png"
    assert synth_main(["scene", "preview", "apt_2", "--diff", "apt_0", "--out", str(out)]) == 0
    img = mpimg.imread(out)
    assert img.shape[0] > 500 and img.shape[1] > 500
    assert not list(out.parent.glob(".*"))  # no temporary file left behind


def test_check_exit_status_on_problems(tmp_path, capsys):
    from synth.scene.model import load_layout, save_layout

    lay = load_layout("apt_0")
    a, b = [o for o in lay.objects if o.cls == "chair"][:2]
    b.position = a.position
    p = save_layout(lay, tmp_path / "bad.yaml")
    assert synth_main(["scene", "check", str(p)]) == 1
    assert "collision" in capsys.readouterr().out


def test_import_replicacad_errors_are_one_line(tmp_path, capsys):
    assert synth_main(["scene", "import-replicacad", str(tmp_path / "missing"), "apt_0", "--out", str(tmp_path / "x.yaml")]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("synth: error: ") and "missing" in err and len(err.splitlines()) == 1
    assert not (tmp_path / "x.yaml").exists()


def test_console_script_reports_errors_with_status_2(tmp_path):
    bad = tmp_path / "bad.yaml"
    bad.write_text("format: synth-layout/1\nname: x\nstage: {ceiling_height: -2}\n")
    r = subprocess.run([sys.executable, "-m", "synth.cli", "scene", "check", str(bad)], capture_output=True, text=True)
    assert r.returncode == 2
    assert r.stderr.strip() == f"synth: error: {bad}: stage.ceiling_height: must be > 0, got -2"


@pytest.mark.slow
def test_model_and_reloc_do_not_import_bpy():
    code = (
        "import sys, pkgutil, importlib, vrformats, synth, reloc\n"
        "n = 0\n"
        "for pkg in (vrformats, synth, reloc):\n"
        "    for m in pkgutil.walk_packages(pkg.__path__, pkg.__name__ + '.'):\n"
        "        if not m.name.startswith('synth.blender'):\n"
        "            importlib.import_module(m.name)\n"
        "            n += 1\n"
        "print('bpy' in sys.modules, n)\n"
    )
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    imported, n = r.stdout.split()
    assert imported == "False" and int(n) > 80  # every module but synth.blender's, subpackages included


@pytest.mark.blender
def test_pinned_bpy_wheel_imports():
    r = subprocess.run([sys.executable, "-c", "import bpy; print(bpy.app.version_string)"], capture_output=True, text=True, timeout=120)
    assert r.returncode == 0, r.stderr
    assert r.stdout.strip().startswith("4.5")


@pytest.mark.slow
def test_scene_build_is_the_main_job(tmp_path, capsys):
    out = tmp_path / "scenes"
    assert synth_main(["scene", "build", "--out", str(out)]) == 0
    text = capsys.readouterr().out
    assert "paper" in text and "apt_5" in text and "FAIL" not in text
    for n in range(6):
        assert (out / "layouts" / f"apt_{n}.yaml").read_bytes() == (REPO / "scenes" / "layouts" / f"apt_{n}.yaml").read_bytes()
        assert (out / "previews" / f"apt_{n}.png").stat().st_size > 10_000
        assert json.loads((out / "boxes" / f"apt_{n}.json").read_text())["layout"] == f"apt_{n}"


def test_a_closed_stdout_pipe_ends_a_command_quietly():
    """``synth scene list | head -0``: the reader is gone before anything is written; the command ends
    with 141 (SIGPIPE's status) and no traceback. A broken pipe that is not stdout stays an error."""
    import os
    import subprocess
    import sys

    from vrformats.cli import run_command

    r, w = os.pipe()
    os.close(r)  # the reading end closed before the command writes
    try:
        p = subprocess.run([sys.executable, "-m", "synth.cli", "scene", "list"], stdout=w, stderr=subprocess.PIPE,
                           text=True, timeout=120)
    finally:
        os.close(w)
    assert p.returncode == 141 and p.stderr == "", p.stderr

    def elsewhere(_args):
        raise BrokenPipeError(32, "Broken pipe")  # e.g. a child's stdin

    with pytest.raises(BrokenPipeError):
        run_command("synth", elsewhere, None)


@pytest.mark.parametrize("argv, part", [
    (["synth", "render", "smoke", "--workers", "0"], "synth render: error: argument --workers: expected an integer from 1 to 256, got '0'"),
    (["synth", "tour", "render", "apt_0", "query", "--out", "x", "--device", "tpu"], "argument --device: invalid choice: 'tpu'"),
    (["synth", "rendr"], "synth: error: argument group: invalid choice: 'rendr'"),
    (["reloc", "experiment", "demo_experiment", "--workers", "-2"], "reloc experiment: error: argument --workers"),
    (["reloc", "run", "--tour", "T"], "reloc run: error: the following arguments are required"),
])
def test_a_bad_option_is_one_line_exit_2(argv, part, capsys, tmp_path, monkeypatch):
    from reloc.cli import main as reloc_main

    monkeypatch.chdir(tmp_path)
    with pytest.raises(SystemExit) as e:
        (synth_main if argv[0] == "synth" else reloc_main)(argv[1:])
    err = capsys.readouterr().err
    assert e.value.code == 2 and len(err.strip().splitlines()) == 1 and part in err and "--help)" in err, err
    assert list(tmp_path.iterdir()) == []


def test_generate_writes_the_working_folder_when_installed_and_quiet_keeps_the_result(tmp_path, monkeypatch, capsys):
    """Installed from a wheel (no checkout), the generate commands must not write into
    site-packages: their default is ./scenes/... of the working folder. ``--quiet`` drops the
    progress bar, not the line saying what was written."""
    import synth.resources as resources

    monkeypatch.delenv("SYNTH_SCENES_DIR", raising=False)
    monkeypatch.setattr(resources, "checkout_root", lambda: None)
    monkeypatch.chdir(tmp_path)
    assert resources.generated_dir("layouts") == tmp_path / "scenes" / "layouts"
    assert synth_main(["scene", "generate", "--only", "apt_1", "--quiet"]) == 0
    out = capsys.readouterr().out
    assert f"wrote apt_0 and 1 variants to {tmp_path / 'scenes' / 'layouts'}" in out, out
    assert sorted(p.name for p in (tmp_path / "scenes" / "layouts").iterdir()) == ["apt_0.yaml", "apt_1.yaml"]
    assert resources.generated_dir("paths") == tmp_path / "scenes" / "paths"
    assert synth_main(["scene", "generate", "--only", "apt_9", "--quiet"]) == 2  # was: silently no variant
    assert "--only apt_9" in capsys.readouterr().err
    monkeypatch.setattr(resources, "checkout_root", lambda: REPO)  # a checkout rewrites its own scenes/
    assert resources.generated_dir("paths") == resources.scenes_dir() / "paths"


def test_synth_has_a_version_like_reloc(capsys):
    import synth

    with pytest.raises(SystemExit) as e:
        synth_main(["--version"])
    assert e.value.code == 0 and capsys.readouterr().out.strip() == f"synth {synth.__version__}"
