"""The job folder on a storage URI (``synth render SPEC --out URI --backend ray``, ``synth.jobs.storage``):
file:// and memory://, atomic writes, resume from what is stored, and refusals that write nothing."""

from __future__ import annotations

import json
import os
from pathlib import Path

import pytest


from jobspecs import write_spec

from vrformats.errors import UserError
from synth import jobs
from synth.jobs import ray_backend
from synth.jobs import storage
from synth.cli import main as synth_main
from cli_errors import one_line_error

SKIP = {"job_state.json", "job_summary.json"}  # the job's bookkeeping: times, backend, paths




def fast_spec(tmp_path, name="spec.yaml", frames=6, **changes) -> Path:
    return write_spec(tmp_path, name, renderer="fast", chunk_size=3,
                      designs=[{"layouts": ["apt_0"], "path": {"name": "query", "frames": frames}}], **changes)


@pytest.fixture
def mem(tmp_path):
    """A fresh memory:// folder, removed afterwards (the memory file system lives as long as the process)."""
    import fsspec

    fs = fsspec.filesystem("memory")
    root = f"/synth_test/{tmp_path.name}"
    yield f"memory://{root}", fs, root
    if fs.exists(root):
        fs.rm(root, recursive=True)


def stored_tree(fs, root: str) -> dict[str, bytes]:
    return {p[len(root) + 1:]: fs.cat_file(p) for p in sorted(fs.find(root))}


def disk_tree(root: Path) -> dict[str, bytes]:
    return {p.relative_to(root).as_posix(): p.read_bytes() for p in sorted(root.rglob("*")) if p.is_file()}


def job_files(tree: dict) -> dict:
    return {k: v for k, v in tree.items() if Path(k).name not in SKIP and not k.startswith(".work")}


def one_line_exit_2(argv, capsys, *parts):
    assert synth_main(argv) == 2
    return one_line_error(capsys, *parts, prog=("synth",))


# ---------------------------------------------------------------------------------------------
# the storage layer


def test_uri_or_path():
    assert storage.is_uri("memory://x") and storage.is_uri("file:///tmp/x") and storage.is_uri("s3://b/k")
    assert not storage.is_uri("/tmp/x") and not storage.is_uri("out/ref") and not storage.is_uri("C:/x")
    assert storage.local_path("file:///tmp/a/b") == Path("/tmp/a/b") and storage.local_path("memory://a") is None


@pytest.mark.parametrize("kind", ["file", "memory"])
def test_writes_are_atomic_and_listed(tmp_path, mem, kind, monkeypatch):
    uri = f"file://{tmp_path / 'job'}" if kind == "file" else mem[0]
    st = storage.Storage(uri).bind(tmp_path / "staging")
    frames = tmp_path / "staging" / "t" / "frames"
    assert st.missing(frames, [0, 1, 2]) == [0, 1, 2]  # a folder that does not exist yet: nothing there
    seen = []
    real_pipe = st.fs.pipe_file
    monkeypatch.setattr(st.fs, "pipe_file", lambda path, data, **kw: (seen.append(path), real_pipe(path, data, **kw))[1])
    import vrformats.atomic

    real_replace = os.replace
    monkeypatch.setattr(vrformats.atomic.os, "replace", lambda a, b: (seen.append(a), real_replace(a, b))[1])
    st.write_bytes(frames / "000001.exr", b"one")
    assert st.missing(frames, [0, 1, 2]) == [0, 2]  # the listing follows the driver's own writes
    assert st.read_bytes(frames / "000001.exr") == b"one" and st.url(frames / "000001.exr") == f"{uri}/t/frames/000001.exr"
    if kind == "file":  # a temporary name in the same folder, then a rename (vrformats.atomic)
        assert [Path(p).name for p in seen] == [f".000001.exr.{os.getpid()}.tmp"]
        assert sorted(os.listdir(tmp_path / "job" / "t" / "frames")) == ["000001.exr"]
    else:  # one put: memory:// stores the bytes once the write is complete
        assert seen == [f"{mem[2]}/t/frames/000001.exr"]
    fresh = storage.Storage(uri).bind(tmp_path / "staging")  # a resumed driver lists the folder afresh
    assert fresh.missing(frames, [0, 1, 2]) == [0, 2]
    (tmp_path / "staging" / "t" / ".work").mkdir(parents=True)
    (tmp_path / "staging" / "t" / "camera.json").write_text("{}")
    (tmp_path / "staging" / ".work").mkdir()
    (tmp_path / "staging" / ".work" / "x.log").write_text("log")
    assert st.push_tree(tmp_path / "staging") == 1 and st.read_text(tmp_path / "staging" / "t" / "camera.json") == "{}"
    with pytest.raises(FileNotFoundError, match="no such file"):
        st.read_bytes(frames / "000000.exr")


# ---------------------------------------------------------------------------------------------
# refusals: one line, exit 2, nothing written (no cluster is needed: they come first)


def test_unknown_scheme_one_line_nothing_written(tmp_path, capsys):
    spec = fast_spec(tmp_path)
    for backend in ("ray", "local"):
        one_line_exit_2(["render", str(spec), "--out", "nosuch://x/job", "--backend", backend, "--quiet"], capsys,
                        "--out nosuch://x/job: unknown storage scheme 'nosuch://'")
    one_line_exit_2(["render", str(spec), "--out", "nosuch://x/job", "--dry-run"], capsys, "unknown storage scheme")
    assert not list(tmp_path.glob("*job*")) and not Path("nosuch:").exists()
    # the spec's own out: may be a URI too; its error names the spec's field
    bad = fast_spec(tmp_path, "bad_out.yaml", out="nosuch://y")
    one_line_exit_2(["render", str(bad), "--backend", "ray", "--quiet"], capsys, f"{bad}: out: nosuch://y: unknown storage scheme")


def test_a_non_local_uri_needs_the_ray_backend(tmp_path, mem, capsys):
    uri, fs, root = mem
    one_line_exit_2(["render", str(fast_spec(tmp_path)), "--out", uri, "--quiet"], capsys,
                    f"--out {uri}: a job folder on memory:// storage needs --backend ray")
    assert not fs.exists(root)


@pytest.mark.parametrize("kind", ["file", "memory"])
def test_a_folder_holding_another_spec_is_refused(tmp_path, mem, capsys, kind, monkeypatch):
    uri, fs, root = mem
    if kind == "file":
        uri, root = f"file://{tmp_path / 'job'}", str(tmp_path / "job")
        import fsspec

        fs = fsspec.filesystem("file")
    other = jobs.load_spec(fast_spec(tmp_path, "other.yaml", quality="paper"))
    fs.makedirs(root, exist_ok=True)
    fs.pipe_file(f"{root}/job_state.json", json.dumps({"spec": jobs.spec_document(other), "chunks": {}}).encode())
    before = stored_tree(fs, root)
    connected = []
    monkeypatch.setattr(ray_backend, "connect", lambda *a, **k: connected.append(a))
    spec = fast_spec(tmp_path)
    one_line_exit_2(["render", str(spec), "--out", uri, "--backend", "ray", "--resume", "--quiet"], capsys,
                    f"{uri}/job_state.json: quality: 'paper' there, 'preview' in this spec: the job in this folder was "
                    "started from a different spec")
    one_line_exit_2(["render", str(spec), "--out", uri, "--backend", "ray", "--quiet"], capsys,
                    f"{uri} already holds a job (its job_state.json); add --resume")
    assert stored_tree(fs, root) == before and not connected  # refused before the cluster and before any write


@pytest.mark.slow
def test_a_plain_folder_names_the_field_that_differs(tmp_path, capsys):
    a = fast_spec(tmp_path, "a.yaml")
    assert synth_main(["render", str(a), "--out", str(tmp_path / "o"), "--quiet"]) == 0
    b = fast_spec(tmp_path, "b.yaml", frames=3)
    one_line_exit_2(["render", str(b), "--out", str(tmp_path / "o"), "--resume", "--quiet"], capsys,
                    f"{tmp_path / 'o' / 'job_state.json'}: designs[0].frames: 6 there, 3 in this spec")


@pytest.mark.slow
def test_file_uri_with_the_local_backend_is_the_folder(tmp_path, capsys):
    spec = fast_spec(tmp_path)
    assert synth_main(["render", str(spec), "--out", str(tmp_path / "plain"), "--quiet"]) == 0
    assert synth_main(["render", str(spec), "--out", f"file://{tmp_path / 'uri'}", "--quiet"]) == 0
    a, b = disk_tree(tmp_path / "plain"), disk_tree(tmp_path / "uri")
    assert job_files(a) == job_files(b) and len([k for k in a if k.endswith(".exr")]) == 6


@pytest.mark.slow
def test_dry_run_reads_what_is_stored(tmp_path, mem, capsys):
    uri, fs, root = mem
    spec = fast_spec(tmp_path)
    assert synth_main(["render", str(spec), "--out", uri, "--backend", "ray", "--dry-run"]) == 0
    out = capsys.readouterr().out
    assert f"-> {uri}" in out and "6 still to render" in out and not fs.exists(root)


# ---------------------------------------------------------------------------------------------
# on a local Ray instance: frames come home into the storage


@pytest.fixture(scope="module")
def ray_local():
    ray = pytest.importorskip("ray")
    os.environ.setdefault("RAY_USAGE_STATS_ENABLED", "0")
    ray.init(num_cpus=2, _node_ip_address="127.0.0.1", include_dashboard=False, log_to_driver=False,
             configure_logging=False)
    yield ray
    ray.shutdown()


@pytest.mark.slow
def test_memory_storage_holds_what_a_local_folder_holds_and_resumes(ray_local, tmp_path, mem, monkeypatch):
    uri, fs, root = mem
    spec = jobs.load_spec(fast_spec(tmp_path))
    ref = jobs.run_job(spec, tmp_path / "ref", progress=False)
    assert ref["failed"] == {}
    s = jobs.run_job(spec, uri, backend="ray", progress=False)
    assert s["failed"] == {} and s["out"] == uri and s["frames_rendered_now"] == 6
    a, b = disk_tree(tmp_path / "ref"), stored_tree(fs, root)
    assert job_files(a) == job_files(b)  # frames, camera, poses, objects, meta, design: byte for byte
    assert json.loads(b["job_summary.json"])["out"] == uri and not [k for k in b if k.startswith(".work")]
    state = json.loads(b["job_state.json"])
    assert all(c["state"] == "done" for c in state["chunks"].values())
    assert not [k for k in b if Path(k).name.startswith(".")]  # no temporary names
    # a lost frame and a stopped job: --resume asks the cluster only for what is not stored
    fs.rm_file(f"{root}/apt_0__geometry__query/frames/000004.exr")
    packs = []
    real_pack = ray_backend.pack_chunk
    monkeypatch.setattr(ray_backend, "pack_chunk", lambda ch: packs.append(real_pack(ch)) or packs[-1])
    with pytest.raises(UserError, match="already holds a job"):
        jobs.run_job(spec, uri, backend="ray", progress=False)
    s2 = jobs.run_job(spec, uri, backend="ray", resume=True, progress=False)
    assert s2["failed"] == {} and [p["job"]["frames"] for p in packs] == [[4]]
    assert job_files(stored_tree(fs, root)) == job_files(a)


@pytest.mark.blender
@pytest.mark.slow
def test_file_storage_with_rgb_and_copied_frames(ray_local, tmp_path):
    """Fast geometry, Cycles RGB on every 2nd frame with previews, copied frames between: the RGB chunks
    take their geometry frames from the storage, the copies are made there; the job folder equals the
    local backend's, and no temporary file is left."""
    spec = jobs.load_spec(write_spec(tmp_path, geometry="fast", chunk_size=3, previews=True, designs=[
        {"layouts": ["apt_0"], "lightings": ["night"], "path": {"name": "query", "frames": 6}, "rgb_every": 2}]))
    local = tmp_path / "local"
    assert jobs.run_job(spec, local, workers=2, progress=False)["failed"] == {}
    out = tmp_path / "stored"
    import tempfile

    staged = set(Path(tempfile.gettempdir()).glob("synth_stage_*"))
    s = jobs.run_job(spec, f"file://{out}", backend="ray", progress=False)
    assert set(Path(tempfile.gettempdir()).glob("synth_stage_*")) == staged  # the staging folder is gone
    assert s["failed"] == {}, s["failed"]
    assert s["frames_rendered_now"] == 12  # 6 fast + 3 rgb + 3 copied
    a, b = disk_tree(local), disk_tree(out)
    assert job_files(a) == job_files(b)
    assert len([k for k in b if k.endswith(".png")]) == 3
    assert not [k for k in b if Path(k).name.startswith(".")]


@pytest.mark.slow
def test_a_job_started_in_a_folder_resumes_through_file_uri(ray_local, tmp_path, monkeypatch):
    """The job folder's layout is the same either way: a job the local backend started in a folder is
    finished through file:// on the Ray backend, which asks only for the missing frame."""
    spec = jobs.load_spec(fast_spec(tmp_path))
    out = tmp_path / "job"
    assert jobs.run_job(spec, out, progress=False)["failed"] == {}
    ref = disk_tree(out)
    (out / "apt_0__geometry__query" / "frames" / "000001.exr").unlink()
    packs = []
    real_pack = ray_backend.pack_chunk
    monkeypatch.setattr(ray_backend, "pack_chunk", lambda ch: packs.append(real_pack(ch)) or packs[-1])
    s = jobs.run_job(spec, f"file://{out}", backend="ray", resume=True, progress=False)
    assert s["failed"] == {} and [p["job"]["frames"] for p in packs] == [[1]]
    assert job_files(disk_tree(out)) == job_files(ref)
