"""The Ray backend on a cluster whose nodes do not share the driver's disk: frames come home, a
node lost mid-job, progress per frame, the runtime environment, and bad input."""

from __future__ import annotations

import json
import os
import re
import threading
import time
from pathlib import Path

import pytest

from jobspecs import write_spec

from vrformats import frames as fr
from vrformats.errors import UserError
from synth import jobs
from synth.jobs import ray_backend
from synth.cli import main as synth_main
from synth.resources import REPO_ROOT

from jobspecs import SMOKE  # noqa: E402  (one home: tests/jobspecs.py)
FRAME = re.compile(r"^\d{6}\.exr$")

# Imported by every Python process whose PYTHONPATH starts with its folder (the tasks' workers and
# the chunk processes they start): any open, listing or write under $SYNTH_TEST_FORBIDDEN fails.
FORBID_HOOK = '''
import os
import sys

_ROOT = os.environ.get("SYNTH_TEST_FORBIDDEN")
_EVENTS = {"open", "os.listdir", "os.scandir", "os.mkdir", "os.rename", "os.remove", "os.rmdir", "os.link",
           "os.symlink", "shutil.copyfile", "os.chmod", "os.truncate", "os.utime"}


def _hook(event, args):
    if event not in _EVENTS:
        return
    for a in args[:2]:
        if isinstance(a, (str, bytes, os.PathLike)):
            p = os.path.abspath(os.fsdecode(a))
            if p == _ROOT or p.startswith(_ROOT + os.sep):
                raise PermissionError(f"{event} {p}: the job folder is not visible on this node")


if _ROOT:
    _ROOT = os.path.abspath(_ROOT)
    sys.addaudithook(_hook)
'''




def _tree(root: Path) -> dict[str, bytes]:
    """Every file of a job folder but the job's own bookkeeping (state, summary: times and backend)."""
    skip = {"job_state.json", "job_summary.json"}
    return {p.relative_to(root).as_posix(): p.read_bytes() for p in sorted(root.rglob("*"))
            if p.is_file() and p.name not in skip and ".work" not in p.parts}


def _strings(obj):
    if isinstance(obj, dict):
        for k, v in obj.items():
            yield from _strings(k)
            yield from _strings(v)
    elif isinstance(obj, (list, tuple)):
        for v in obj:
            yield from _strings(v)
    elif isinstance(obj, (str, bytes)):
        yield obj if isinstance(obj, str) else obj.decode("latin-1")


@pytest.fixture(scope="module")
def cluster():
    """Two nodes on this machine, one CPU each; the second one can be removed."""
    ray = pytest.importorskip("ray")
    from ray.cluster_utils import Cluster

    os.environ.setdefault("RAY_USAGE_STATS_ENABLED", "0")
    c = Cluster(initialize_head=True, head_node_args={"num_cpus": 1})
    worker = c.add_node(num_cpus=1)
    c.wait_for_nodes()
    yield c, worker
    if ray.is_initialized():
        ray.shutdown()
    c.shutdown()


# ---------------------------------------------------------------------------------------------
# without a cluster


def test_unreachable_address_one_line_exit_2_nothing_written(tmp_path, capsys):
    pytest.importorskip("ray")
    out = tmp_path / "out"
    t0 = time.time()
    assert synth_main(["render", str(SMOKE), "--out", str(out), "--backend", "ray", "--ray-address", "127.0.0.1:1",
                       "--quiet"]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("synth: error: --ray-address 127.0.0.1:1: cannot reach") and len(err.splitlines()) == 1, err
    assert not out.exists() and time.time() - t0 < 30


def test_runtime_env_ships_code_scenes_and_pinned_requirements(tmp_path):
    from importlib import metadata

    assert ray_backend.runtime_env("auto", None) is None  # the local instance: the code is here
    assert ray_backend.runtime_env("none", "10.0.0.1:6379") is None
    env = ray_backend.runtime_env("auto", "10.0.0.1:6379", out=REPO_ROOT / "out" / "x", renderer="blender")
    assert env["working_dir"] == str(REPO_ROOT) and (REPO_ROOT / "scenes" / "layouts").is_dir()
    assert ".git" in env["excludes"] and "tests" in env["excludes"] and "/out/x" in env["excludes"]
    assert "data" not in env["excludes"] and "/data" in env["excludes"]  # scenes travels with the code
    pins = env["pip"]["packages"]
    assert f"numpy=={metadata.version('numpy')}" in pins and any(p.startswith("bpy") for p in pins)
    fast = ray_backend.runtime_env("full", "10.0.0.1:6379", renderer="fast")
    assert not any(p.startswith("bpy") for p in fast["pip"]["packages"])  # the fast renderer needs no Blender
    assert "pip" not in ray_backend.runtime_env("code", "10.0.0.1:6379")
    with pytest.raises(UserError, match="--ray-runtime-env"):
        ray_backend.runtime_env("sometimes", None)


def test_runtime_env_of_an_installed_toolkit_is_one_clear_error(monkeypatch):
    """Installed from a wheel there is no checkout to ship: code and full say so; none still works."""
    monkeypatch.setattr(ray_backend, "_checkout_root", lambda: None)
    for mode in ("code", "full"):
        with pytest.raises(UserError, match=f"--ray-runtime-env {mode}: .* not a source checkout"):
            ray_backend.runtime_env(mode, "10.0.0.1:6379")
    assert ray_backend.runtime_env("none", "10.0.0.1:6379") is None


@pytest.mark.slow
def test_a_packed_chunk_renders_anywhere_and_sends_its_frames_home(tmp_path):
    """The task's side without Ray: pack a chunk, run it in a scratch folder, get its files back."""
    spec = jobs.load_spec(write_spec(tmp_path, renderer="fast", chunk_size=4,
                                     designs=[{"layouts": ["apt_0"], "path": {"name": "query", "frames": 4}}]))
    ref = jobs.run_job(spec, tmp_path / "ref", progress=False)
    assert ref["failed"] == {}
    plan = jobs.expand(spec, tmp_path / "ref")
    (c,) = plan.chunks
    want = {}
    for f in sorted((tmp_path / "ref" / "apt_0__geometry__query" / "frames").glob("00000[13].exr")):
        want[f.name] = f.read_bytes()
        f.unlink()  # a chunk half done: only the missing frames are asked for
    packed = ray_backend.pack_chunk(c)
    assert packed["job"]["frames"] == [1, 3]
    assert not [s for s in _strings(packed) if str(tmp_path) in s]
    items = list(ray_backend.chunk_task(packed, None, "t", batch_seconds=60.0))
    assert [list(i) for i in items] == [["files"], ["end"]]  # one batch: everything finished within a minute
    rc, err, info, _log, _node = items[-1]["end"]
    assert rc == 0 and err is None and info["device"] == "CPU"
    assert {name: data for dest, name, data in items[0]["files"]} == want


# ---------------------------------------------------------------------------------------------
# on a two-node cluster


@pytest.mark.slow
def test_gpu_spec_on_a_cpu_cluster_one_line_exit_2_before_any_task(cluster, tmp_path, capsys, monkeypatch):
    c, _ = cluster
    packed = []
    monkeypatch.setattr(ray_backend, "pack_chunk", lambda ch: packed.append(ch) or {})
    spec = write_spec(tmp_path, device="gpu")
    out = tmp_path / "out"
    assert synth_main(["render", str(spec), "--out", str(out), "--backend", "ray", "--ray-address", c.address,
                       "--ray-runtime-env", "none", "--quiet"]) == 2
    err = capsys.readouterr().err.strip()
    assert f"synth: error: the cluster at {c.address} has no GPU; " in err and len(err.splitlines()) == 1, err
    assert not out.exists() and not packed


@pytest.mark.blender
@pytest.mark.slow
def test_two_nodes_that_cannot_see_the_job_folder_render_what_the_local_backend_renders(cluster, tmp_path, monkeypatch):
    """Fast geometry, Cycles RGB on every 2nd frame with previews, copied frames between: the frames
    come home through Ray and equal the local backend's, file for file, byte for byte."""
    import ray

    c, _ = cluster
    spec = jobs.load_spec(write_spec(tmp_path, geometry="fast", chunk_size=3, previews=True, designs=[
        {"layouts": ["apt_0"], "lightings": ["night"], "path": {"name": "query", "frames": 6}, "rgb_every": 2}]))
    local = tmp_path / "local"
    assert jobs.run_job(spec, local, workers=2, progress=False)["failed"] == {}

    out = tmp_path / "ray"
    hook = tmp_path / "hook"
    hook.mkdir()
    (hook / "sitecustomize.py").write_text(FORBID_HOOK)
    env = ray_backend.runtime_env("code", c.address, out)  # the tasks run from an uploaded copy of the toolkit
    env["env_vars"] = {"PYTHONPATH": f"{hook}:{os.environ.get('PYTHONPATH', '')}", "SYNTH_TEST_FORBIDDEN": str(tmp_path),
                       "TMPDIR": str(tmp_path.parent / f"{tmp_path.name}_node_tmp")}
    Path(env["env_vars"]["TMPDIR"]).mkdir()
    ray.init(address=c.address, runtime_env=env, log_to_driver=False, configure_logging=False)
    try:
        @ray.remote(num_cpus=1)
        def probe(path):
            import subprocess
            import sys

            errors = []
            for code in (f"open({path!r}).read()", f"import os; os.listdir({str(Path(path).parent)!r})"):
                try:
                    exec(code)
                except PermissionError as e:
                    errors.append(str(e))
                r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
                errors.append(r.returncode != 0 and "PermissionError" in r.stderr)
            return os.getcwd(), errors

        cwd, errors = ray.get(probe.remote(str(local / "design.json")))
        assert len(errors) == 4 and all(errors), errors  # a task, and the chunk process it starts, see nothing there
        assert not cwd.startswith(str(REPO_ROOT))

        packs, updates, reported = [], [], []
        real_pack = ray_backend.pack_chunk
        monkeypatch.setattr(ray_backend, "pack_chunk", lambda ch: packs.append(real_pack(ch)) or packs[-1])
        real_update = jobs.chunk_queue.ProgressBar.update
        monkeypatch.setattr(jobs.chunk_queue.ProgressBar, "update", lambda self, n=1: (updates.append(n), real_update(self, n)))
        monkeypatch.setattr(ray_backend, "on_frame_reported", lambda cid, i, node: reported.append((cid, i, node)))
        t0 = time.time()
        s = jobs.run_job(spec, out, backend="ray", progress=False)
        wall = time.time() - t0
    finally:
        ray.shutdown()
    assert s["failed"] == {}, s["failed"]
    assert s["frames_rendered_now"] == 12  # 6 fast (geometry cache) + 3 rgb + 3 copied
    # no path of the driver's in any task's arguments: the job, the layout, poses, preset, class table
    # and geometry frames travel as bytes
    assert {p["kind"] for p in packs} == {"fast", "rgb"}
    assert not [x for p in packs for x in _strings(p) if str(tmp_path) in x]
    assert any(k.startswith("geometry/") for p in packs if p["kind"] == "rgb" for k in p["files"])
    # progress advanced per frame, once per frame rendered (frames reported by the tasks through the
    # actor, or landed first); the tasks ran on both nodes
    assert updates == [1] * 12, updates
    assert reported and len({node for _, _, node in reported}) == 2
    # the frames in the job folder equal the local backend's, byte for byte, with the same files around them
    a, b = _tree(local), _tree(out)
    assert sorted(a) == sorted(b)
    assert [k for k in a if a[k] != b[k]] == []
    assert len([k for k in a if k.endswith(".exr") and "/frames/" in k]) == 6
    assert len([k for k in a if k.endswith(".png")]) == 3
    meta = json.loads((out / "apt_0__night__query" / "meta.json").read_text())
    assert meta["render_devices"] == {"fast": ["CPU"], "rgb": ["CPU"]}
    state = json.loads((out / "job_state.json").read_text())
    assert all(ch["devices"] == (["CPU"] if not cid.startswith("copy/") else []) for cid, ch in state["chunks"].items())
    print(f"ray backend, 2 nodes: {wall:.1f} s")


@pytest.mark.slow
def test_a_node_lost_mid_chunk_loses_nothing_and_no_half_file_is_ever_seen(cluster, tmp_path, monkeypatch):
    """The worker node is removed while its chunk renders: the chunk's attempt fails, the job's
    retry runs on the head node and renders only the frames that had not come home."""
    import ray

    c, worker = cluster
    spec = jobs.load_spec(write_spec(tmp_path, renderer="fast", size=[640, 480], chunk_size=30, retries=1,
                                     designs=[{"layouts": ["apt_0"], "path": {"name": "query", "frames": 60}}]))
    monkeypatch.setattr(ray_backend, "BATCH_SECONDS", 0.25)  # frames come home soon after they are rendered
    node_tmp = tmp_path / "node_tmp"  # the scratch folders, also the one the removed node leaves behind
    node_tmp.mkdir()
    real_env = ray_backend.runtime_env
    monkeypatch.setattr(ray_backend, "runtime_env", lambda *a, **k: {**real_env(*a, **k), "env_vars": {"TMPDIR": str(node_tmp)}})
    local = tmp_path / "local"
    assert jobs.run_job(spec, local, progress=False)["failed"] == {}
    out = tmp_path / "ray"
    frames_dir = out / "apt_0__geometry__query" / "frames"

    plan = jobs.expand(spec, out)
    killed, packs, ends, bad, checked = [], [], [], [], set()

    def on_report(cid, i, node):
        if node != worker.node_id or killed:
            return
        mine = next(ch.frames for ch in plan.chunks if ch.id == cid)
        home = [n for n in (os.listdir(frames_dir) if frames_dir.is_dir() else []) if FRAME.match(n) and int(n[:6]) in mine]
        if 0 < len(home) < len(mine):  # some of its frames came home, others are still to render
            killed.append(cid)
            c.remove_node(worker)  # its raylet, its workers and the chunk process they ran

    real_pack = ray_backend.pack_chunk
    monkeypatch.setattr(ray_backend, "pack_chunk", lambda ch: packs.append((ch.id, real_pack(ch))) or packs[-1][1])
    monkeypatch.setattr(ray_backend, "on_frame_reported", on_report)
    real_finished = jobs.chunk_queue.ChunkQueue.finished
    monkeypatch.setattr(jobs.chunk_queue.ChunkQueue, "finished", lambda self, ch, rc, err, log, device=None: (
        ends.append((ch.id, rc, err)), real_finished(self, ch, rc, err, log, device))[1])
    stop = threading.Event()

    def watch():  # every visible file in the frames folder has its final name and reads completely
        while not stop.is_set():
            names = os.listdir(frames_dir) if frames_dir.is_dir() else []
            for n in names:
                if n.startswith(".") or n in checked:
                    continue  # a temporary name, renamed into place once complete
                if not FRAME.match(n):
                    bad.append(n)
                    continue
                try:
                    fr.read_frame(frames_dir / n, rgb=False, require=("depth", "instance", "semantic"))
                    checked.add(n)
                except Exception as e:
                    bad.append(f"{n}: {e}")
            time.sleep(0.02)

    t = threading.Thread(target=watch, daemon=True)
    t.start()
    try:
        s = jobs.run_job(spec, out, backend="ray", ray_address=c.address, ray_runtime_env="code", progress=False)
    finally:
        stop.set()
        t.join()
        if ray.is_initialized():
            ray.shutdown()
    assert killed, "no chunk ran on the worker node"
    assert s["failed"] == {}, s["failed"]
    assert not bad, bad
    assert len(checked) == 60
    assert not list(out.rglob("*.tmp"))
    # the killed attempt failed and was retried (the job's retries, not Ray's), asking only for
    # the frames that had not come home
    failed = [e for e in ends if e[0] == killed[0] and e[1] != 0]
    assert len(failed) == 1 and "the task failed" in failed[0][2], ends
    state = json.loads((out / "job_state.json").read_text())
    assert state["chunks"][killed[0]]["attempts"] == 2 and state["chunks"][killed[0]]["state"] == "done"
    asked = [p["job"]["frames"] for cid, p in packs if cid == killed[0]]
    chunk_frames = next(ch.frames for ch in plan.chunks if ch.id == killed[0])
    assert len(asked) == 2 and asked[0] == chunk_frames and set(asked[1]) < set(chunk_frames), asked
    print(f"killed {killed[0]} ({failed[0][2][:120]}); the retry asked for {len(asked[1])} of {len(chunk_frames)} frames")
    a, b = _tree(local), _tree(out)
    assert sorted(a) == sorted(b) and [k for k in a if a[k] != b[k]] == []
