"""The toolkit built as a wheel and installed outside the checkout finds its shipped data.

The wheel is built offline (``pip wheel --no-deps --no-build-isolation``) from a copy of the
packaging files (pyproject.toml, README.md, vrformats/, synth/, reloc/: nothing the checkout's
``build/`` may hold goes in), and installed into a fresh venv in tmp_path. That venv sees the
dependencies through a ``.pth`` line naming the main venv's site-packages: a path line adds the
folder to ``sys.path`` without running the ``.pth`` files there, so the editable install of the
checkout (``__editable__*.pth`` and its finder) is not picked up. Every command runs from
tmp_path with ``SYNTH_SCENES_DIR`` unset, and the test asserts that ``synth``, ``reloc`` and
``vrformats`` are imported from the venv. Run with ``-s`` to see the commands and their output.
"""

from __future__ import annotations

import json
import os
import shutil
import site
import subprocess
import sys
import sysconfig
import time
import zipfile
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[2]
PACKAGES = ("vrformats", "synth", "reloc")
# the design card's top-level data folders, shipped inside synth (pyproject.toml's package-dir)
DATA_FOLDERS = {"scenes": "synth/scenes", "render_jobs": "synth/render_jobs"}
# the shipped files that must be in the wheel, as they lie in the checkout (besides every file under scenes/)
SHIPPED = ("render_jobs/demo.yaml", "render_jobs/smoke.yaml", "render_jobs/detector_train.yaml", "render_jobs/README.md",
           "reloc/models/detector_v2_160x120.onnx", "reloc/models/detector_v2_160x120.md",
           "reloc/models/detector_160x120.onnx", "reloc/models/detector_160x120.md", "reloc/specs/demo_experiment.yaml",
           "reloc/specs/demo_checks.yaml", "reloc/specs/README.md", "vrformats/sensor_presets/tof.yaml")

pytestmark = [pytest.mark.slow, pytest.mark.blender]


def _say(log: list, text: str) -> None:
    print(text, flush=True)
    log.append(text)


def _run(log, argv, cwd, env, timeout=300) -> str:
    t0 = time.time()
    r = subprocess.run([str(a) for a in argv], cwd=cwd, env=env, capture_output=True, text=True, timeout=timeout)
    shown = " ".join(Path(a).name if i == 0 else str(a) for i, a in enumerate(argv)).replace("\n", "; ")
    _say(log, f"$ {shown}   (rc {r.returncode}, {time.time() - t0:.1f} s)")
    for line in (r.stdout + r.stderr).strip().splitlines():
        _say(log, "  " + line)
    assert r.returncode == 0, f"{shown} failed:\n{r.stdout}\n{r.stderr}"
    return r.stdout


def _copy_sources(dst: Path) -> None:
    for name in ("pyproject.toml", "README.md", "LICENSE"):
        shutil.copy2(REPO / name, dst / name)
    for pkg in PACKAGES + tuple(DATA_FOLDERS):
        shutil.copytree(REPO / pkg, dst / pkg, ignore=shutil.ignore_patterns("__pycache__", "*.pyc"))


def in_wheel(checkout_path: str) -> str:
    """Where a checkout file lies in the wheel: scenes/x is synth/scenes/x, render_jobs/x synth/render_jobs/x."""
    top, _, rest = checkout_path.partition("/")
    return f"{DATA_FOLDERS[top]}/{rest}" if top in DATA_FOLDERS else checkout_path


@pytest.fixture(scope="module")
def installed(tmp_path_factory):
    """(venv folder, environment, log): the wheel built and installed into a fresh venv."""
    root = tmp_path_factory.mktemp("wheel")
    log: list[str] = []
    src = root / "src"
    src.mkdir()
    _copy_sources(src)
    env = {k: v for k, v in os.environ.items()
           if k not in ("PYTHONPATH", "PYTHONHOME", "SYNTH_SCENES_DIR", "VIRTUAL_ENV", "PYTHONSTARTUP")}
    env["PIP_NO_INDEX"] = "1"  # offline: nothing is downloaded
    env["PIP_DISABLE_PIP_VERSION_CHECK"] = "1"
    _run(log, [sys.executable, "-m", "pip", "wheel", "--no-deps", "--no-build-isolation", "-q", "-w", root / "dist", src],
         cwd=root, env=env)
    wheels = sorted((root / "dist").glob("videoreloc_synth-*.whl"))
    assert len(wheels) == 1, wheels
    venv = root / "venv"
    _run(log, [sys.executable, "-m", "venv", "--without-pip", venv], cwd=root, env=env)
    py = venv / "bin" / "python"
    purelib = Path(subprocess.run([py, "-c", "import sysconfig; print(sysconfig.get_paths()['purelib'])"],
                                  capture_output=True, text=True, check=True, env=env).stdout.strip())
    # the dependencies: the main venv's site-packages as a plain sys.path entry (its .pth files do not run)
    deps = [p for p in {*site.getsitepackages(), sysconfig.get_paths()["purelib"], sysconfig.get_paths()["platlib"]}
            if Path(p).is_dir()]
    (purelib / "_main_venv_deps.pth").write_text("".join(f"{p}\n" for p in sorted(deps)))
    _run(log, [sys.executable, "-m", "pip", "--python", py, "install", "--no-deps", "-q", wheels[0]], cwd=root, env=env)
    env["PATH"] = f"{venv / 'bin'}{os.pathsep}{env.get('PATH', '')}"
    return venv, env, log, wheels[0]


def test_the_wheel_ships_the_data_and_specs(installed):
    venv, env, log, wheel = installed
    names = set(zipfile.ZipFile(wheel).namelist())
    data = {p.relative_to(REPO).as_posix() for p in (REPO / "scenes").rglob("*") if p.is_file()}
    assert {"scenes/layouts/apt_0.yaml", "scenes/lighting/day.yaml", "scenes/paths/query.txt",
            "scenes/classes.yaml", "scenes/replicacad_lexicon.yaml"} <= data
    missing = sorted({in_wheel(f) for f in data | set(SHIPPED)} - names)
    assert missing == [], missing
    specs = {p.relative_to(REPO).as_posix() for d in ("render_jobs", "reloc/specs") for p in (REPO / d).glob("*.yaml")}
    assert {in_wheel(f) for f in specs} <= names
    # the data folders are package data, not packages; nothing lands at the wheel's top level but the packages
    assert {n.split("/")[0] for n in names} == set(PACKAGES) | {wheel.name.split("-")[0] + "-" + wheel.name.split("-")[1] + ".dist-info"}
    assert not any(n.startswith(tuple(DATA_FOLDERS.values()) + ("reloc/models/", "reloc/specs/")) and n.endswith(".py")
                   for n in names)
    dist_info = wheel.name.split("-")[0] + "-" + wheel.name.split("-")[1] + ".dist-info"
    assert f"{dist_info}/licenses/LICENSE" in names  # the MIT text travels with the wheel
    meta = zipfile.ZipFile(wheel).read(f"{dist_info}/METADATA").decode()
    assert "License-Expression: MIT" in meta and "Requires-Python: <3.12,>=3.11" in meta
    _say(log, f"{wheel.name}: {len(names)} files, {len(data)} under scenes, {len(specs)} specs, "
              f"reloc/models/detector_v2_160x120.onnx {zipfile.ZipFile(wheel).getinfo('reloc/models/detector_v2_160x120.onnx').file_size} bytes")


def test_installed_commands_find_the_shipped_data_outside_the_checkout(installed, tmp_path):
    venv, env, log, _ = installed
    py = venv / "bin" / "python"
    where = _run(log, [py, "-c", "import vrformats, synth, reloc\nfor m in (vrformats, synth, reloc): print(m.__name__, m.__file__)"],
                 cwd=tmp_path, env=env)
    for line in where.splitlines():
        f = Path(line.split(" ", 1)[1]).resolve()
        assert f.is_relative_to(venv.resolve()) and not f.is_relative_to(REPO / line.split()[0]), line

    out = _run(log, [venv / "bin" / "synth", "scene", "list"], cwd=tmp_path, env=env)
    assert all(f"apt_{n}" in out for n in range(6)) and "no layouts" not in out
    out = _run(log, [venv / "bin" / "synth", "scene", "show", "apt_0"], cwd=tmp_path, env=env)
    assert "apt_0" in out

    # the shipped names resolve inside the install; a bare unknown name lists them
    r = subprocess.run([venv / "bin" / "synth", "render", "nosuch"], check=False, cwd=tmp_path, env=env, capture_output=True, text=True)
    _say(log, f"$ synth render nosuch   (rc {r.returncode})\n  {r.stderr.strip()}")
    assert r.returncode == 2 and "shipped: demo, detector_eval" in r.stderr and str(venv) in r.stderr
    code = ("from reloc.resources import SHIPPED_MODEL\n"
            "from reloc.detection.learned import SHIPPED_MODEL as default, LearnedDetector\n"
            "from reloc.experiments.spec import load_experiment\n"
            "from synth.jobs import load_spec\n"
            "print('model', SHIPPED_MODEL, SHIPPED_MODEL.is_file(), default == SHIPPED_MODEL)\n"
            "print('opens', type(LearnedDetector(SHIPPED_MODEL)).__name__)\n"
            "e = load_experiment('demo_experiment')\n"
            "print('experiment', e.source, '->', e.render)\n"
            "print('render', load_spec('smoke').source)\n")
    out = _run(log, [py, "-c", code], cwd=tmp_path, env=env)
    model = out.splitlines()[0].split()
    assert Path(model[1]).resolve().is_relative_to(venv.resolve()) and model[2:] == ["True", "True"], out
    assert out.count(str(venv)) >= 4 and str(REPO) not in out.replace(str(venv), ""), out

    # a tiny render of the shipped layout, lighting preset and camera path: 6 frames, 32x24, preview
    spec = tmp_path / "wheel_smoke.yaml"
    spec.write_text("name: wheel_smoke\nout: out/wheel_smoke\nrenderer: blender\nquality: preview\nsize: [32, 24]\n"
                    "seed: 0\nchunk_size: 6\nretries: 0\n"
                    "designs:\n  - {layouts: [apt_0], lightings: [day], path: {name: query, frames: 6}}\n")
    out = _run(log, [venv / "bin" / "synth", "render", spec.name, "--quiet"], cwd=tmp_path, env=env, timeout=240)
    assert out.startswith("wheel_smoke: 1 tours, ") and "failed" not in out, out  # a geometry and an RGB chunk
    tour = tmp_path / "out" / "wheel_smoke" / "apt_0__day__query"
    frames = sorted((tour / "frames").glob("*.exr"))
    meta = json.loads((tour / "meta.json").read_text())
    assert len(frames) == 6 and meta["complete"] and meta["lighting"] == "day", meta
    assert Path(meta["layout_file"]).is_relative_to(venv) and meta["layout_file"].endswith("synth/scenes/layouts/apt_0.yaml")
    _say(log, f"rendered: {len(frames)} frames in {tour.relative_to(tmp_path)}; layout_file {meta['layout_file']}")
    (tmp_path / "wheel_test.log").write_text("\n".join(log) + "\n")
