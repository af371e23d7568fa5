"""The Ray backend of render jobs (``synth render SPEC --backend ray``): chunks on a cluster whose
nodes share no disk with the driver.

- **Connecting** (``connect``): to the cluster at ``--ray-address`` (a TCP check with a short timeout
  first: an unreachable address is one line, not minutes of retries) or to a local instance on
  127.0.0.1. The cluster must have a CPU, and a GPU when the spec says ``device: gpu``; all of this
  is checked before the job writes anything. ``--ray-runtime-env`` ships the toolkit to the nodes:
  ``code`` (the checkout as the ``working_dir``: the packages with their shipped data), ``full`` (that,
  plus ``pip`` requirements pinned to the driver's versions, so a node needs only Python 3.11 and
  Ray), ``none``; ``auto`` is ``full`` for a remote address and ``none`` for the local instance.
- **Frames come home** (``pack_chunk``, ``chunk_task``): the driver packs everything a chunk reads
  into the task's arguments (the job, with paths relative to a scratch folder; the layout, poses,
  lighting preset and class table as bytes; for an RGB chunk the geometry-cache frames it takes
  depth and ids from). The task materialises them in a node-local temporary folder, runs the chunk
  there with ``synth.render.chunks.run_chunk_process`` and streams the finished frame files back (a Ray
  streaming generator) in batches: what finished within ``BATCH_SECONDS``, at most ``BATCH_BYTES``.
  The driver writes each file atomically into the job folder, whose frames stay the truth for
  ``--resume``. ``copy`` chunks need no rendering and only the driver's geometry cache: the driver
  runs them itself (hard links, as with the local backend).
- **A job folder on a storage URI** (``--out file://...``, ``memory://...``: ``synth.jobs.storage``): the
  driver writes the frames that come home, and the chunks' logs, to the storage; RGB chunks are
  packed with geometry frames read from it, and ``copy`` chunks copy frames within it.
- **Progress per frame**: each task reports every finished frame to a small actor on the driver's
  node (``ProgressBox``); the driver drains it and advances the bar per frame.
- **Retries**: the tasks run with Ray's ``max_retries=0``; a task that fails (its process or node
  died) is retried by the job's own ``retries``, recorded in ``job_state.json``, and a retry renders
  only the frames that have not come home.
"""

from __future__ import annotations

import os
import queue
import re
import shutil
import socket
import tempfile
import threading
import time
from pathlib import Path

from vrformats import frames as fr
from vrformats.atomic import replacing, write_bytes_atomic, write_text_atomic
from vrformats.errors import UserError, one_line
from vrformats.lifetime import reclaim_signals, start_reaper

from ..render.chunks import run_chunk_process
from .chunk_queue import ChunkQueue, chunk_files

BATCH_BYTES = 32 * 1024 * 1024  # a batch of frame files sent home at once (one object in the object store)
BATCH_SECONDS = 1.0  # ... or what finished within this long, whichever comes first
CONNECT_TIMEOUT_S = 5.0  # the TCP check of --ray-address
RUNTIME_ENV_MODES = ("auto", "full", "code", "none")
# gitignore patterns; the checkout's data folder is anchored ("/data"): the packages' shipped data
# (scenes) travels
_EXCLUDES = [".git", ".venv", "**/__pycache__", "*.egg-info", ".pytest_cache", "build", "dist", "out", "renders",
             "/data", ".gl", ".whl", "tests"]
_FRAME = re.compile(r"^\d{6,}\.exr$")  # synth frame names (vrformats.frames.frame_name)
_PREVIEW = re.compile(r"^\d{6,}\.png$")
LOG_TAIL = 64 * 1024


def _ray():
    os.environ.setdefault("RAY_USAGE_STATS_ENABLED", "0")
    try:
        import ray
    except ImportError:
        raise UserError("the ray backend needs Ray: pip install 'videoreloc-synth[ray]'") from None
    return ray


# ---------------------------------------------------------------------------------------------
# connecting


def _check_reachable(address: str) -> None:
    """A host:port (or ray://host:port) address answers a TCP connect within CONNECT_TIMEOUT_S."""
    a = address.split("://", 1)[1] if "://" in address else address
    host, sep, port = a.rpartition(":")
    if not sep or not port.isdigit():
        if address == "auto":
            return  # ray.init finds the local cluster or says at once that there is none
        raise UserError(f"--ray-address: expected HOST:PORT (or auto), got {address!r}")
    try:
        socket.create_connection((host.strip("[]"), int(port)), timeout=CONNECT_TIMEOUT_S).close()
    except OSError as e:
        why = "timed out" if isinstance(e, socket.timeout) else (e.strerror or str(e))
        raise UserError(f"--ray-address {address}: cannot reach a Ray cluster there ({why}); "
                        f"start one with `ray start --head` (docs/cluster.md)") from None


def _repo_root() -> Path:
    """The folder above the package: the source checkout when run from one (``checkout_root``)."""
    from ..resources import REPO_ROOT

    return REPO_ROOT


def _checkout_root() -> Path | None:
    from ..resources import checkout_root

    return checkout_root()


def _requirement_name(req: str) -> str:
    """``bpy>=4.5,<4.6`` -> ``bpy``."""
    return re.split(r"[<>=!~ \[;]", req, maxsplit=1)[0]


def requirements(renderer: str = "blender") -> list[str]:
    """The toolkit's requirements (pyproject.toml), pinned to the versions installed here: a node then
    renders with the same libraries as the driver (bpy only for Blender jobs)."""
    import tomllib
    from importlib import metadata

    doc = tomllib.loads((_repo_root() / "pyproject.toml").read_text())
    out = []
    for req in doc["project"]["dependencies"]:
        name = _requirement_name(req)
        if name == "bpy" and renderer != "blender":
            continue
        try:
            out.append(f"{name}=={metadata.version(name)}")
        except metadata.PackageNotFoundError:
            out.append(req)
    return out


def resolve_mode(mode: str, address: str | None) -> str:
    """``auto`` is ``full`` for a cluster address and ``none`` for the local instance."""
    return ("full" if address else "none") if mode == "auto" else mode


def runtime_env(mode: str, address: str | None, out: Path | None = None, renderer: str = "blender") -> dict | None:
    """The Ray ``runtime_env`` the driver connects with (``--ray-runtime-env``)."""
    if mode not in RUNTIME_ENV_MODES:
        raise UserError(f"--ray-runtime-env: expected one of {', '.join(RUNTIME_ENV_MODES)}, got {mode!r}")
    mode = resolve_mode(mode, address)
    if mode == "none":
        return None
    root = _checkout_root()
    if root is None:
        raise UserError(f"--ray-runtime-env {mode}: the toolkit at {_repo_root()} is installed, not a source checkout "
                        "(no pyproject.toml beside synth/), so its sources cannot be shipped as the working_dir; install "
                        "it on every node and use --ray-runtime-env none")
    excludes = list(_EXCLUDES)
    if out is not None:  # never upload the job's own output folder when it lies inside the checkout
        try:
            excludes.append("/" + Path(out).resolve().relative_to(root.resolve()).as_posix())
        except ValueError:
            pass
    env: dict = {"working_dir": str(root), "excludes": excludes}
    if mode == "full":
        env["pip"] = {"packages": requirements(renderer), "pip_check": False}
    return env


class Session:
    """A connection to Ray for one job; ``close`` shuts down only what ``connect`` started."""

    def __init__(self, ray, started: bool, address: str | None):
        self.ray, self.started, self.address = ray, started, address

    def close(self) -> None:
        if self.started and self.ray.is_initialized():
            self.ray.shutdown()


def connect(address: str | None, env_mode: str = "auto", device: str = "cpu", out: Path | None = None,
            renderer: str = "blender", progress=None) -> Session:
    """Connect (or use the connection this process already has) and check the cluster can run the job.

    Writes nothing; every problem is a one-line UserError."""
    ray = _ray()
    if ray.is_initialized():
        session = Session(ray, False, address)
    else:
        env = runtime_env(env_mode, address, out, renderer)
        if address:
            _check_reachable(address)
            try:
                ray.init(address=address, runtime_env=env, log_to_driver=False, configure_logging=False)
            except (ConnectionError, TimeoutError) as e:
                raise UserError(f"--ray-address {address}: {str(e).splitlines()[0] if str(e) else type(e).__name__}") from None
            except Exception as e:  # e.g. the working_dir could not be packed or uploaded
                raise UserError(f"--ray-address {address}: cannot start the job there: {failure_cause(e)}") from None
        else:  # a local instance on loopback only
            ray.init(_node_ip_address="127.0.0.1", include_dashboard=False, log_to_driver=False, runtime_env=env,
                     configure_logging=False)
        session = Session(ray, True, address)
        reclaim_signals()  # SIGTERM stops the driver in order (its tasks cancelled), not by Ray's handler
        if not address:  # a local instance's agents outlive a kill -9 of the driver: a reaper stops them then
            start_reaper()
    try:
        res = ray.cluster_resources()
        where = f"the cluster at {address}" if address else "the local Ray instance"
        if res.get("CPU", 0) < 1:
            raise UserError(f"{where} has no CPU to run chunks on")
        if device == "gpu" and res.get("GPU", 0) < 1:
            raise UserError(f"{where} has no GPU; the spec asks for device: gpu (add GPU nodes, or use device: cpu or auto)")
        if session.started and address:  # a real cluster: every node builds the runtime env before a chunk is sent
            preflight(ray, resolve_mode(env_mode, address), renderer, progress=progress)
    except BaseException:
        session.close()
        raise
    return session


PREFLIGHT_TIMEOUT_S = 1800.0  # a bare node pip-installs the requirements first (docs/cluster.md: minutes)
_MODULES = {"opencv-python-headless": "cv2", "pyyaml": "yaml", "pillow": "PIL"}  # requirement -> module, where they differ
_ERROR_LINE = re.compile(r"^(?:[\w]+\.)*(\w*(?:Error|Exception|Exit|Interrupt))\b:?\s*(.*)$")


def failure_cause(e: BaseException) -> str:
    """One line for a Ray error: the exception Ray wrapped (its last ``SomeError: message`` line, where
    a ``RuntimeEnvSetupError`` carries the node's traceback), the node, and the last line of output
    when it says more. ``str(e)`` whole goes into the chunk's log."""
    text = str(e)
    lines = [ln.strip() for ln in text.splitlines() if ln.strip()]
    node = re.search(r"\[Node ([^\]]+)\]", text)
    where = f" on node {node.group(1)}" if node else ""
    cause = None
    for ln in reversed(lines[1:]):
        m = _ERROR_LINE.match(ln)
        if m and m.group(2):
            cause = f"{m.group(1)}: {m.group(2)}"
            break
    head = lines[0] if lines else ""
    out = f"{type(e).__name__}{where}: {head}"
    if cause:
        out += f" ({cause}"
        if lines and lines[-1] not in cause and not lines[-1].startswith(("File ", "^")):
            out += f"; last output: {lines[-1]}"
        out += ")"
    return out[:600]


def _module_names(renderer: str) -> list[str]:
    names = ["synth", "vrformats"]
    for req in requirements(renderer):
        name = _requirement_name(req)
        names.append(_MODULES.get(name.lower(), name))
    return names


def _hint(mode: str, cause: str) -> str:
    if "virtualenv" in cause:
        return ("Ray's pip runtime env needs the virtualenv package on every node: `python -m pip install virtualenv` "
                "with the Python that runs Ray there, then `ray stop` and `ray start` again; or install the toolkit's "
                "requirements on the nodes and use --ray-runtime-env code (docs/cluster.md)")
    if mode == "full":
        return "see the node's runtime env log (/tmp/ray/session_latest/logs/runtime_env_setup-*.log) and docs/cluster.md"
    return "install them there, or use --ray-runtime-env full (docs/cluster.md)"


def preflight(ray, mode: str, renderer: str = "blender", progress=None, timeout: float = PREFLIGHT_TIMEOUT_S) -> list[dict]:
    """Before any chunk is scheduled: on every node with a CPU, a tiny task in the job's runtime env.
    The node builds the env (``full``: Ray's virtualenv and pip install; cached for later tasks) and
    the task checks that the toolkit and its requirements import with the driver's Python version.
    Any node that cannot is a one-line ``UserError``: the node, the cause, what to install."""
    import platform
    from ray.util.scheduling_strategies import NodeAffinitySchedulingStrategy

    names = _module_names(renderer)

    def probe(modules):  # runs on the node (pickled by value: nothing of the toolkit's needed to unpickle it)
        import importlib.util
        import platform as pf
        import socket as so
        import sys as sy

        return {"python": pf.python_version(), "executable": sy.executable, "host": so.gethostname(),
                "missing": [m for m in modules if importlib.util.find_spec(m) is None]}

    task = ray.remote(num_cpus=0, max_retries=0)(probe)
    nodes = [n for n in ray.nodes() if n.get("Alive") and n.get("Resources", {}).get("CPU", 0) >= 1]
    refs = {task.options(scheduling_strategy=NodeAffinitySchedulingStrategy(n["NodeID"], soft=False)).remote(names):
            n.get("NodeManagerAddress", n["NodeID"][:8]) for n in nodes}
    t0, said, results, problems = time.monotonic(), time.monotonic(), [], []
    waiting = list(refs)
    while waiting:
        ready, waiting = ray.wait(waiting, num_returns=len(waiting), timeout=5.0)
        for r in ready:
            ip = refs[r]
            try:
                got = ray.get(r)
            except ray.exceptions.RayError as e:
                cause = failure_cause(e)
                problems.append(f"node {ip} cannot set up the runtime env: {cause}; {_hint(mode, cause)}")
                continue
            results.append({"node": ip, **got})
            if got["python"].rsplit(".", 1)[0] != platform.python_version().rsplit(".", 1)[0]:
                problems.append(f"node {ip} runs Python {got['python']}, the driver {platform.python_version()} "
                                "(bpy 4.5 is built for Python 3.11; docs/cluster.md)")
            elif got["missing"]:
                problems.append(f"node {ip} lacks {', '.join(got['missing'])} (Python {got['executable']}); "
                                f"{_hint(mode, '')}")
        if problems:
            for r in waiting:
                ray.cancel(r, force=True)
            raise UserError(f"--ray-runtime-env {mode}: " + problems[0] +
                            (f" (and {len(problems) - 1} more node(s))" if len(problems) > 1 else ""))
        if waiting and time.monotonic() - t0 > timeout:
            raise UserError(f"--ray-runtime-env {mode}: {len(waiting)} node(s) did not set up the runtime env within "
                            f"{timeout:.0f} s ({', '.join(refs[r] for r in waiting)}); see docs/cluster.md")
        if waiting and progress and time.monotonic() - said >= 30.0:
            said = time.monotonic()
            progress(f"ray: runtime env ({mode}) ready on {len(results)} of {len(refs)} node(s) after "
                     f"{time.monotonic() - t0:.0f} s (a bare node pip-installs the requirements once: minutes)")
    return results


# ---------------------------------------------------------------------------------------------
# the task's side


def pack_chunk(c) -> dict:
    """Everything chunk ``c`` (``synth.jobs.plan.Chunk``) reads, as bytes, and its job with paths relative to
    the scratch folder the task makes: no path of the driver's travels. Only the frames still
    missing are asked for (a retry renders what has not come home)."""
    from ..scene.lighting import lighting_file
    from ..resources import classes_file

    job = dict(c.job)
    todo = c.missing()
    files: dict[str, bytes] = {}
    store = getattr(c, "store", None)  # the job folder on a storage URI (synth.jobs.storage): frames are read there

    def ship(rel: str, path, stored: bool = False) -> str:
        files[rel] = store.read_bytes(path) if stored and store is not None else Path(path).read_bytes()
        return rel

    job["frames"] = todo
    job["layout"] = ship(f"scenes/layouts/{Path(c.job['layout']).name}", c.job["layout"])
    job["poses"] = ship("poses.txt", c.job["poses"])
    ship("scenes/classes.yaml", classes_file())
    if job.get("lighting"):
        lf = lighting_file(job["lighting"])
        job["lighting"] = ship(f"scenes/lighting/{lf.name}", lf)
    if c.kind in ("rgb", "copy"):  # they take depth and ids from the geometry cache
        for i in todo:
            ship(f"geometry/{fr.frame_name(i)}", Path(c.job["geometry_dir"]) / fr.frame_name(i), stored=True)
    job["geometry_dir"] = "geometry"
    job["out_dir"] = "out"
    if job.get("previews_dir"):
        job["previews_dir"] = "previews"
    return {"id": c.id, "kind": c.kind, "job": job, "files": files}


_PATH_KEYS = ("layout", "poses", "geometry_dir", "out_dir", "previews_dir", "lighting")


def materialise(packed: dict, scratch: Path) -> dict:
    """Write a packed chunk's files under ``scratch``; its job with absolute paths there."""
    root = Path(scratch).resolve()
    for rel, data in packed["files"].items():
        p = root / rel
        if Path(rel).is_absolute() or not p.resolve().is_relative_to(root):
            raise UserError(f"chunk {packed.get('id')}: file '{rel}' lies outside the chunk's scratch folder")
        p.parent.mkdir(parents=True, exist_ok=True)
        write_bytes_atomic(p, data)
    job = dict(packed["job"])
    for k in _PATH_KEYS:
        if job.get(k) and (k != "lighting" or job[k] in packed["files"]):
            job[k] = str(scratch / job[k])
    for k in ("out_dir", "geometry_dir"):
        Path(job[k]).mkdir(parents=True, exist_ok=True)
    return job


def _node_id() -> str | None:
    try:
        import ray

        # only inside a Ray worker: asking for the runtime context elsewhere would start a Ray instance
        return ray.get_runtime_context().get_node_id() if ray.is_initialized() else None
    except Exception:
        return None


def _frame_files(job: dict, i: int) -> list[tuple[str, str, bytes]]:
    out = [("out", fr.frame_name(i), (Path(job["out_dir"]) / fr.frame_name(i)).read_bytes())]
    if job.get("previews_dir"):
        png = Path(job["previews_dir"]) / f"{i:06d}.png"
        if png.exists():
            out.append(("previews", png.name, png.read_bytes()))
    return out


def chunk_task(packed: dict, box, token: str, batch_bytes: int = BATCH_BYTES, batch_seconds: float = BATCH_SECONDS):
    """A Ray task (a streaming generator): run a packed chunk in a node-local scratch folder.

    Yields ``{"files": [(dest, name, bytes), ...]}`` batches as frames finish (dest ``out``: the
    chunk's frames folder, ``previews``: the tour's previews), then ``{"end": [rc, error, info,
    log tail, node id]}``. Each finished frame is reported to the ``box`` actor at once."""
    node = _node_id()
    scratch = Path(tempfile.mkdtemp(prefix="synth_chunk_"))
    try:
        job = materialise(packed, scratch)
        env = {**os.environ, "SYNTH_SCENES_DIR": str(scratch / "scenes")}
        events: queue.Queue = queue.Queue()
        result: dict = {}

        def work():
            try:
                result["r"] = run_chunk_process(packed["kind"], job, str(scratch / "job.json"), str(scratch / "chunk.log"),
                                                on_frame=events.put, env=env)
            except BaseException as e:  # reported in the end item
                result["r"] = (1, f"{type(e).__name__}: {e}", {})
            finally:
                events.put(None)

        t = threading.Thread(target=work, name="synth-chunk", daemon=True)
        t.start()
        batch: list = []
        size, first = 0, 0.0
        while True:
            try:
                ev = events.get(timeout=batch_seconds)
            except queue.Empty:
                ev = ()
            if ev is None:
                break
            if ev:
                i = int(ev["frame"])
                if box is not None:
                    box.report.remote(token, i, node)
                files = _frame_files(job, i)
                if not batch:
                    first = time.monotonic()
                batch += files
                size += sum(len(b) for _, _, b in files)
            if batch and (size >= batch_bytes or time.monotonic() - first >= batch_seconds):
                yield {"files": batch}
                batch, size = [], 0
        t.join()
        if batch:
            yield {"files": batch}
        rc, err, info = result["r"]
        log = scratch / "chunk.log"
        tail = log.read_bytes()[-LOG_TAIL:].decode("utf-8", "replace") if log.exists() else ""
        yield {"end": [rc, err, info, tail, node]}
    except Exception as e:
        yield {"end": [1, f"{type(e).__name__}: {e}", {}, "", node]}
    finally:
        shutil.rmtree(scratch, ignore_errors=True)


class ProgressBox:
    """A Ray actor the tasks report finished frames to; the driver drains it."""

    def __init__(self):
        self.events: list = []

    def report(self, token: str, frame: int, node: str | None) -> None:
        self.events.append((token, frame, node))

    def drain(self) -> list:
        out, self.events = self.events, []
        return out


# ---------------------------------------------------------------------------------------------
# the driver's side


def on_frame_reported(chunk_id: str, frame: int, node: str | None) -> None:
    """Called by the driver for every frame a task reports (a hook for tests and tools)."""


class _Attempt:
    def __init__(self, c, token: str, log: str):
        self.c, self.token, self.log = c, token, log
        self.counted: set[int] = set()
        self.landed: set[int] = set()
        self.end: list | None = None


def copy_stored(c, store, bar) -> tuple[int, str | None]:
    """A ``copy`` chunk when the job folder is on a storage URI: its missing frames copied from the
    geometry cache there (read, then an atomic write: no hard links across a file system API)."""
    try:
        for i in c.missing():
            store.copy(Path(c.job["geometry_dir"]) / fr.frame_name(i), Path(c.out_dir) / fr.frame_name(i))
            bar.update()
    except (OSError, UserError) as e:
        return 1, one_line(e, limit=300, with_type=True)
    return 0, None


def run(plan, state, todo: list, bar, work: Path) -> dict:
    """Run ``todo`` on the connected cluster (``connect``), handed out by ``synth.jobs.chunk_queue.ChunkQueue``;
    each chunk's job and log files on the driver are ``chunk_files(work, c)``."""
    ray = _ray()
    from ray.util.scheduling_strategies import NodeAffinitySchedulingStrategy

    store = plan.store  # synth.jobs.storage.Storage, or None: the job folder is on the driver's disk
    gpu = plan.spec.device == "gpu"
    task = ray.remote(num_cpus=1, num_gpus=1 if gpu else 0, max_retries=0, num_returns="streaming")(chunk_task)
    box_cls = ray.remote(num_cpus=0)(ProgressBox)
    try:  # on the driver's node: it lives as long as the driver, whichever worker node goes away
        box = box_cls.options(scheduling_strategy=NodeAffinitySchedulingStrategy(
            ray.get_runtime_context().get_node_id(), soft=True)).remote()
    except Exception:
        box = box_cls.remote()
    limits = [float("-inf"), 1]  # when the cluster was last asked, how many chunks may be in flight

    def limit() -> int:
        """Every CPU (GPU) of the cluster busy plus two packed chunks waiting: nodes never wait for the
        driver, and the packed inputs (geometry frames of RGB chunks) in the object store stay few.
        Asked again every 10 s: nodes that join are used."""
        if time.monotonic() - limits[0] > 10.0:
            slots = int(ray.cluster_resources().get("GPU" if gpu else "CPU", 0))
            limits[:] = [time.monotonic(), max(1, slots) + 2]
        return limits[1]

    info: dict = {}
    q = ChunkQueue(plan, state, todo, bar)
    running: dict = {}  # generator -> _Attempt
    by_token: dict[str, _Attempt] = {}  # the attempts running now
    chunk_of: dict[str, str] = {}  # every token handed out -> chunk id
    pending_drain = None  # the box's answer still on its way: the loop never waits for the actor

    def count(a: _Attempt, i: int) -> None:
        if i not in a.counted:
            a.counted.add(i)
            bar.update()

    def drain(wait: float = 0.0) -> None:
        """Frames the tasks reported: each advances the bar once, unless its attempt already ended
        (then the frame either came home and was counted, or was lost with its node)."""
        nonlocal box, pending_drain
        if box is None:
            return
        if pending_drain is None:
            pending_drain = box.drain.remote()
        if not ray.wait([pending_drain], timeout=wait)[0]:
            return
        try:
            events = ray.get(pending_drain)
        except ray.exceptions.RayError:  # the actor is gone: frames are counted as they land
            box = None
            return
        finally:
            pending_drain = None
        for token, i, node in events:
            if token in chunk_of:
                on_frame_reported(chunk_of[token], i, node)
            a = by_token.get(token)
            if a is not None:
                count(a, i)

    def land(a: _Attempt, files: list) -> None:
        c = a.c
        for dest, name, data in files:
            if dest == "out" and _FRAME.match(name):
                path = Path(c.out_dir) / name
            elif dest == "previews" and _PREVIEW.match(name):
                path = plan.tours[c.tour].out / "previews" / name
            else:
                raise RuntimeError(f"chunk {c.id} sent an unexpected file {dest}/{name}")
            if store is not None:
                store.write_bytes(path, data)  # atomically, as the storage allows
            else:
                with replacing(path) as tmp:
                    tmp.write_bytes(data)
            if dest == "out":
                i = int(name[: -len(".exr")])
                a.landed.add(i)
                count(a, i)

    def end(gen, a: _Attempt, rc: int, err: str | None, inf: dict, log_text: str) -> None:
        running.pop(gen, None)
        by_token.pop(a.token, None)
        lost = a.counted - a.landed  # reported, but lost with its node before it came home
        if lost:
            bar.update(-len(lost))
        write_text_atomic(a.log, log_text)
        shown = a.log
        if store is not None:  # the log goes with the job folder
            store.write_text(a.log, log_text)
            shown = store.url(a.log)
        info.update(inf)
        q.finished(a.c, rc, err, shown, device=inf.get("device"))

    try:
        while True:
            for c in q.take_ready(max(0, limit() - len(running))):
                jf, log = chunk_files(work, c)
                if c.kind == "copy":  # no rendering: the driver links the frames of its own geometry cache
                    if store is not None:
                        rc, err = copy_stored(c, store, bar)
                        q.finished(c, rc, err, store.url(log))
                        continue
                    rc, err, inf = run_chunk_process(c.kind, c.job, jf, log, on_frame=lambda _ev: bar.update())
                    q.finished(c, rc, err, log, device=inf.get("device"))
                    continue
                token = f"{c.id}#{state.doc['chunks'][c.id]['attempts']}"
                a = _Attempt(c, token, log)
                try:
                    packed = pack_chunk(c)
                except OSError as e:  # e.g. a geometry frame that went missing
                    write_text_atomic(log, f"cannot pack the chunk: {e}\n")
                    q.finished(c, 1, f"cannot pack the chunk: {one_line(e, limit=300, with_type=True)}", log)
                    continue
                gen = task.remote(packed, box, token, BATCH_BYTES, BATCH_SECONDS)
                running[gen] = a
                by_token[token] = a
                chunk_of[token] = c.id
            if not running:
                if q.pending and any(c.needs is None or c.needs in q.done or c.needs in q.failed for c in q.pending):
                    continue
                break
            ready, _ = ray.wait(list(running), num_returns=1, timeout=0.5)
            for gen in ready:
                a = running[gen]
                try:
                    item = ray.get(next(gen))
                except StopIteration:
                    end(gen, a, 1, "the task ended without a result", {}, "")
                    continue
                except ray.exceptions.RayError as e:  # its runtime env, worker or node failed, or its objects were lost
                    end(gen, a, 1, f"the task failed: {failure_cause(e)}", {}, f"the task failed:\n{e}\n")
                    continue
                if "files" in item:
                    land(a, item["files"])
                else:
                    rc, err, inf, log_text, _node = item["end"]
                    end(gen, a, rc, err, inf, log_text)
            drain()
        drain(wait=5.0)  # late reports, for on_frame_reported (the bar counted their frames as they landed)
    finally:
        for gen in list(running):
            try:
                ray.cancel(gen, force=True)
            except Exception:
                pass
        if box is not None:
            try:
                ray.kill(box)
            except Exception:
                pass
    return info
