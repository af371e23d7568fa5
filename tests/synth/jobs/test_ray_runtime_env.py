"""The Ray backend's runtime environments on a real multi-node cluster (two nodes on loopback, each
running a Python of its own, ``ray_loopback``): the default (``full``: Ray's virtualenv and pip on
every node) and ``code`` render the smoke spec as the local backend does; a node that cannot build
the runtime env is refused in one line before anything is scheduled, and a chunk that fails there
has the cause in its log and its failure line; the summary counts what is on disk."""

from __future__ import annotations

import json
import re
from pathlib import Path

import pytest

import ray_loopback
from synth import jobs
from synth.jobs import ray_backend
from synth.cli import main as synth_main

from jobspecs import SMOKE  # noqa: E402  (one home: tests/jobspecs.py)

# Imported at the start of every Python process of the nodes (on their PYTHONPATH): virtualenv cannot
# be imported there, as on a node where only Ray was installed.
NO_VIRTUALENV = '''
import importlib.abc
import sys


class _NoVirtualenv(importlib.abc.MetaPathFinder):
    def find_spec(self, name, path=None, target=None):
        if name == "virtualenv" or name.startswith("virtualenv."):
            raise ModuleNotFoundError(f"No module named {name!r}", name=name)
        return None


sys.meta_path.insert(0, _NoVirtualenv())
'''

# the text of a RuntimeEnvSetupError as Ray 2.60 raises it for a node without virtualenv (shortened)
SETUP_ERROR = """Failed to set up runtime environment.
[Node 10.1.2.3] Traceback (most recent call last):
  File "/opt/venv/lib/python3.11/site-packages/ray/_private/runtime_env/pip.py", line 132, in __init__
    import virtualenv  # noqa: F401 ensure virtualenv exists.
    ^^^^^^^^^^^^^^^^^
ModuleNotFoundError: No module named 'virtualenv'

During handling of the above exception, another exception occurred:

Traceback (most recent call last):
  File "/opt/venv/lib/python3.11/site-packages/ray/_private/runtime_env/pip.py", line 134, in __init__
    raise RuntimeError(
RuntimeError: Please install virtualenv `/opt/venv/bin/python -m pip install virtualenv`to enable pip runtime env.
"""


def _fast(spec: str) -> str:
    """The smoke spec with the fast renderer (geometry only, no lightings)."""
    out = spec.replace("renderer: blender", "renderer: fast").replace("    lightings: [day, night]\n", "")
    assert out != spec and "lightings" not in out.split("designs:")[1]
    return out


def _tree(root: Path) -> dict[str, bytes]:
    skip = {"job_state.json", "job_summary.json"}
    return {p.relative_to(root).as_posix(): p.read_bytes() for p in sorted(root.rglob("*"))
            if p.is_file() and p.name not in skip and ".work" not in p.parts}


def test_failure_cause_names_the_node_and_the_wrapped_error():
    ray = pytest.importorskip("ray")
    e = ray.exceptions.RuntimeEnvSetupError(SETUP_ERROR)
    line = ray_backend.failure_cause(e)
    assert "\n" not in line
    assert line.startswith("RuntimeEnvSetupError on node 10.1.2.3: Failed to set up runtime environment")
    assert "RuntimeError: Please install virtualenv" in line
    hint = ray_backend._hint("full", line)
    assert "python -m pip install virtualenv" in hint and "--ray-runtime-env code" in hint


def test_summary_counts_frames_on_disk_not_planned(tmp_path, monkeypatch, capsys):
    """A chunk that fails before it renders counts no frame rendered; the line says what failed."""
    spec = tmp_path / "spec.yaml"
    spec.write_text(_fast(SMOKE.read_text()).replace("layouts: [apt_0, apt_1]", "layouts: [apt_0]"))
    def broken(kind, job, job_file, log, on_frame=None, env=None):
        Path(log).write_text("no renderer here\n")
        return 1, "the renderer could not start", {}

    monkeypatch.setattr(jobs.chunk_queue, "run_chunk_process", broken)
    rc = synth_main(["render", str(spec), "--out", str(tmp_path / "out"), "--quiet"])
    out, err = capsys.readouterr()
    s = json.loads((tmp_path / "out" / "job_summary.json").read_text())
    assert rc == 1
    assert s["frames_rendered_now"] == 0 and s["frames_failed"] == 6 and s["chunks_failed"] == 2, s
    assert "0 frames rendered, 6 frames failed in 2 chunk(s)" in out
    assert err.count("FAILED") == 2 and "the renderer could not start" in err


@pytest.mark.cluster
@pytest.mark.slow
@pytest.mark.blender
def test_default_and_code_runtime_envs_render_the_smoke_spec_as_the_local_backend(tmp_path, smoke_reference):
    pytest.importorskip("ray")
    pytest.importorskip("virtualenv")
    import ray

    local = smoke_reference
    spec = jobs.load_spec(SMOKE)
    c = ray_loopback.start(tmp_path / "cluster")
    try:
        for mode in ("auto", "code"):  # auto, with an address: full
            out = tmp_path / f"ray_{mode}"
            try:
                s = jobs.run_job(spec, out, backend="ray", ray_address=c.address, ray_runtime_env=mode, progress=False)
            finally:
                if ray.is_initialized():
                    ray.shutdown()
            assert s["failed"] == {}, s["failed"]
            assert s["frames_rendered_now"] == s["frames_total"] == 36 and s["frames_failed"] == 0
            a, b = _tree(local), _tree(out)
            assert sorted(a) == sorted(b)
            assert [k for k in a if a[k] != b[k]] == []
            assert len([k for k in b if k.endswith(".exr") and "/frames/" in k]) == 24
            print(f"{mode}: {s['wall_time_s']} s")
        # the default built Ray's pip env (a clone of the node's Python, the pinned requirements) on both nodes
        for d in c.runtime_env_dirs():
            envs = list((d / "pip").glob("*/virtualenv/bin/python"))
            assert len(envs) == 1, (d, envs)
    finally:
        c.stop()


@pytest.mark.cluster
@pytest.mark.slow
def test_a_node_without_virtualenv_is_refused_in_one_line_and_chunks_that_fail_there_say_why(tmp_path, monkeypatch, capsys):
    pytest.importorskip("ray")
    import ray

    hook = tmp_path / "hook"
    hook.mkdir()
    (hook / "sitecustomize.py").write_text(NO_VIRTUALENV)
    spec = tmp_path / "spec.yaml"  # the fast renderer: what fails here is the runtime env, not a render
    spec.write_text(_fast(SMOKE.read_text()))
    c = ray_loopback.start(tmp_path / "cluster", env={"PYTHONPATH": str(hook)})
    try:
        out = tmp_path / "out"
        rc = synth_main(["render", str(spec), "--out", str(out), "--backend", "ray", "--ray-address", c.address, "--quiet"])
        err = capsys.readouterr().err.strip()
        assert ray.is_initialized() is False
        assert rc == 2, err
        line = err.splitlines()[-1]
        print(line)
        assert re.search(r"--ray-runtime-env full: node [\d.]+ cannot set up the runtime env: RuntimeEnvSetupError", line)
        assert "Please install virtualenv" in line and "python -m pip install virtualenv" in line
        assert not out.exists()  # refused before anything was written

        # past the check (a node that joined later, say): every chunk fails with the cause in its log
        monkeypatch.setattr(ray_backend, "preflight", lambda *a, **k: [])
        rc = synth_main(["render", str(spec), "--out", str(out), "--backend", "ray", "--ray-address", c.address, "--quiet"])
        o, err = capsys.readouterr()
        assert rc == 1
        s = json.loads((out / "job_summary.json").read_text())
        assert s["frames_rendered_now"] == 0 and s["frames_failed"] == s["frames_total"] == 12, s
        assert s["chunks_failed"] == 4
        assert "0 frames rendered, 12 frames failed in 4 chunk(s)" in o
        fails = [ln for ln in err.splitlines() if "FAILED" in ln]
        assert len(fails) == 4 and all("Please install virtualenv" in ln for ln in fails), fails
        logs = sorted((out / ".work").glob("*.log"))
        assert logs and all("ModuleNotFoundError: No module named 'virtualenv'" in p.read_text() for p in logs)
    finally:
        if ray.is_initialized():
            ray.shutdown()
        c.stop()
