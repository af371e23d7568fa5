"""Render jobs: YAML experiment specs (``synth/specs/*.yaml``, or a shipped name: ``synth render demo``) and a resumable chunk runner.

A spec names one or more *designs* (layouts x lightings x one camera path), the renderer, the
quality, the image size, the seed and the output folder. It expands into tours
(``OUT/<layout>__<lighting>__<path>/``, lighting ``geometry`` for geometry-only tours) and each
tour into chunks of frames:

- ``geometry`` chunks, one set per layout + path, shared by every lighting (Blender);
- ``rgb`` chunks, per tour, which take depth and ids from the geometry chunks (Blender);
- ``copy`` chunks, which copy geometry frames into a tour without rendering RGB: every frame of a
  geometry-only tour, and the frames between RGB frames of a design with ``rgb_every: k``;
- ``fast`` chunks, per tour, for the fast Open3D renderer (geometry only).

With ``geometry: fast`` a Blender job renders its geometry cache with the fast Open3D renderer
(about 100x faster than a Cycles geometry pass; the depth and ids agree, see the renderer
cross-check tests) and only RGB with Blender. A design's ``rgb_every: k`` renders RGB on frames
0, k, 2k, ... only; every frame still has depth and ids (long tours for odometry and clips,
RGB where an appearance method or a detector needs it).

The job state file ``OUT/job_state.json`` records each chunk's state (pending, running, done,
failed with its error and attempts). The frames on disk are the truth about what is done: a chunk
is done when all its frame files exist, and they appear only once complete. So after the runner is
killed, ``--resume`` renders exactly what is missing. A failing chunk is retried up to
``retries`` times, then reported, while the other chunks go on.
"""

from __future__ import annotations

import json
import os
import sys
import time
from dataclasses import asdict, dataclass, field
from pathlib import Path

from formats import frames as fr
from formats.atomic import write_json_atomic, write_text_atomic
from formats.design import tour_name, write_design
from formats.errors import SceneFormatError, UserError, check_output_file, check_output_folder
from formats.fields import fail, names, positive_int
from formats.yamlfile import read_yaml

from ..render.chunks import chunk_job, run_chunk_process
from .estimate import fmt_duration
from ..render.settings import DEVICES, quality
from ..render.render_tour import TourSpec, make_output_folder, prepare, tour_meta, write_static_files

STATE_FILE = "job_state.json"
SPEC_KEYS = {"name", "description", "out", "renderer", "geometry", "quality", "size", "hfov_deg", "seed", "device",
             "chunk_size", "retries", "previews", "designs", "replicacad"}
DESIGN_KEYS = {"layouts", "lightings", "path", "rgb_every"}
PATH_KEYS = {"name", "frames"}


@dataclass
class Design:
    layouts: list[str]
    lightings: list[str] | None  # None: geometry only
    path: str
    frames: int | None
    rgb_every: int = 1  # RGB on frames 0, k, 2k, ...; depth and ids on every frame


@dataclass
class JobSpec:
    name: str
    out: str
    designs: list[Design]
    renderer: str = "blender"
    geometry: str = "blender"  # renderer of the geometry cache of Blender jobs: blender | fast
    quality: str = "preview"
    width: int = 640
    height: int = 480
    hfov_deg: float = 75.0
    seed: int = 0
    device: str = "cpu"
    chunk_size: int = 50
    retries: int = 2
    previews: bool = False
    description: str = ""
    source: str = ""
    replicacad: dict | None = None  # layouts are scenes of a ReplicaCAD folder (synth.replicacad.job)


def parse_spec(doc, source: str) -> JobSpec:
    """Validate a spec document; every error names the file and the key."""
    if not isinstance(doc, dict):
        fail(source, None, "expected a mapping at the top level")
    unknown = sorted(map(str, set(doc) - SPEC_KEYS))
    if unknown:
        fail(source, unknown[0], f"unknown key; allowed: {', '.join(sorted(SPEC_KEYS))}")
    for k in ("name", "out", "designs"):
        if k not in doc:
            fail(source, k, "missing")
    renderer = doc.get("renderer", "blender")
    if renderer not in ("blender", "fast"):
        fail(source, "renderer", f"expected blender or fast, got {renderer!r}")
    geometry = doc.get("geometry", "blender" if renderer == "blender" else "fast")
    if geometry not in ("blender", "fast"):
        fail(source, "geometry", f"expected blender or fast, got {geometry!r}")
    if renderer == "fast" and geometry != "fast":
        fail(source, "geometry", "the fast renderer makes its own geometry: leave geometry out")
    q = doc.get("quality", "preview")
    try:
        quality(q)
    except UserError as e:
        fail(source, "quality", str(e))
    size = doc.get("size", [640, 480])
    if not isinstance(size, list) or len(size) != 2:
        fail(source, "size", f"expected [width, height], got {size!r}")
    w, h = (positive_int(source, v, "size") for v in size)
    device = doc.get("device", "cpu")
    if device not in DEVICES:
        fail(source, "device", f"expected one of {', '.join(DEVICES)}, got {device!r}")
    seed = doc.get("seed", 0)
    if isinstance(seed, bool) or not isinstance(seed, int) or seed < 0:
        fail(source, "seed", f"expected a non-negative integer, got {seed!r}")
    retries = doc.get("retries", 2)
    if isinstance(retries, bool) or not isinstance(retries, int) or retries < 0:
        fail(source, "retries", f"expected a non-negative integer, got {retries!r}")
    hfov = doc.get("hfov_deg", 75.0)
    if isinstance(hfov, bool) or not isinstance(hfov, (int, float)) or not 1.0 <= hfov <= 170.0:
        fail(source, "hfov_deg", f"expected degrees in [1, 170], got {hfov!r}")
    designs_doc = doc["designs"]
    if not isinstance(designs_doc, list) or not designs_doc:
        fail(source, "designs", "expected a non-empty list")
    designs = []
    for i, d in enumerate(designs_doc):
        f = f"designs[{i}]"
        if not isinstance(d, dict):
            fail(source, f, "expected a mapping with layouts, lightings, path")
        unknown = sorted(map(str, set(d) - DESIGN_KEYS))
        if unknown:
            fail(source, f"{f}.{unknown[0]}", f"unknown key; allowed: {', '.join(sorted(DESIGN_KEYS))}")
        if "layouts" not in d or "path" not in d:
            fail(source, f, "needs layouts and path")
        layouts = names(source, d["layouts"], f + ".layouts")
        lightings = None if d.get("lightings") is None else names(source, d["lightings"], f + ".lightings")
        if renderer == "blender" and lightings is None:
            pass  # geometry-only tours rendered with Blender
        if renderer == "fast" and lightings is not None:
            fail(source, f + ".lightings", "the fast renderer makes geometry only: leave lightings out")
        p = d["path"]
        if isinstance(p, str):
            p = {"name": p}
        if not isinstance(p, dict) or "name" not in p:
            fail(source, f + ".path", f"expected a path name or {{name, frames}}, got {p!r}")
        unknown = sorted(map(str, set(p) - PATH_KEYS))
        if unknown:
            fail(source, f"{f}.path.{unknown[0]}", "unknown key; allowed: name, frames")
        frames = None if p.get("frames") is None else positive_int(source, p["frames"], f + ".path.frames")
        rgb_every = positive_int(source, d.get("rgb_every", 1), f + ".rgb_every")
        if rgb_every > 1 and lightings is None:
            fail(source, f + ".rgb_every", "a geometry-only design renders no RGB: leave rgb_every out")
        designs.append(Design(layouts, lightings, str(p["name"]), frames, rgb_every))
    return JobSpec(
        name=str(doc["name"]), out=str(doc["out"]), designs=designs, renderer=renderer, geometry=geometry, quality=q,
        width=w, height=h,
        hfov_deg=float(hfov), seed=seed, device=device,
        chunk_size=positive_int(source, doc.get("chunk_size", 50), "chunk_size"), retries=retries,
        previews=bool(doc.get("previews", False)), description=str(doc.get("description", "")), source=source,
        replicacad=_replicacad_section(doc, source),
    )


def _replicacad_section(doc: dict, source: str) -> dict | None:
    if "replicacad" not in doc:
        return None
    from ..replicacad.job import parse_section

    return parse_section(doc["replicacad"], source)


def load_spec(path) -> JobSpec:
    """A render job spec: a file, or the name of a shipped one (``demo``: synth/specs/demo.yaml)."""
    from ..resources import render_spec

    p = render_spec(path)
    if not p.exists():
        raise UserError(f"{p}: job spec not found")
    return parse_spec(read_yaml(p), str(p))


# ---------------------------------------------------------------------------------------------
# expansion into tours and chunks


@dataclass
class Chunk:
    id: str  # e.g. "geometry/apt_0__query/0003", "rgb/apt_0__day__query/0003"
    kind: str  # geometry | rgb | fast
    tour: str  # tour directory name (geometry chunks: the first tour that uses them)
    frames: list[int]
    job: dict  # what the worker gets
    out_dir: str
    needs: str | None = None  # id of the geometry chunk an rgb chunk waits for
    store: object = field(default=None, repr=False, compare=False)  # synth.jobs.storage.Storage: the job folder is there

    def missing(self) -> list[int]:
        if self.store is not None:  # out_dir is in the driver's staging folder; the frames are in the storage
            return self.store.missing(self.out_dir, self.frames)
        d = Path(self.out_dir)
        return [i for i in self.frames if not (d / fr.frame_name(i)).exists()]


@dataclass
class Plan:
    spec: JobSpec
    out: Path
    tours: dict  # tour name -> synth.render.render_tour.Prepared
    chunks: list[Chunk] = field(default_factory=list)
    store: object = None  # synth.jobs.storage.Storage bound to ``out`` (a staging folder), or None: out is the job folder

    def use_storage(self, store) -> None:
        """Put the job folder on ``store`` (``synth.jobs.storage``); ``out`` becomes the driver's staging folder."""
        self.store = store.bind(self.out)
        for c in self.chunks:
            c.store = self.store

    @property
    def where(self) -> str:
        return self.store.uri if self.store is not None else str(self.out)

    @property
    def frames_total(self) -> int:
        return sum(len(c.frames) for c in self.chunks)


def _out_error(spec: JobSpec, from_cli: bool, e: UserError):
    """An unusable output folder, named as the spec's ``out`` or as the ``--out`` that overrides it."""
    if from_cli:
        raise UserError(f"--out: {e}") from None
    raise SceneFormatError(spec.source or "<spec>", "out", str(e)) from None


def validate_names(spec: JobSpec, check_clearance: bool = False) -> None:
    """Every layout, lighting and path of the spec exists and loads, and every path has the frames
    asked for; a UserError names the spec file and the field (``designs[0].layouts[1]``).

    With ``check_clearance``, a path rendered through a layout it was not planned on must keep its
    declared clearance there (``synth.paths.clearance.render_clearance_problem``)."""
    from ..paths.clearance import render_clearance_problem
    from ..paths.files import load_path
    from ..scene.lighting import load_lighting
    from ..scene.model import load_layout, resolve_layout_path

    src = spec.source or "<spec>"
    layouts: dict[str, tuple] = {}
    paths: dict[str, object] = {}
    checked: set = set()

    def named(field: str, load, name):
        try:
            return load(name)
        except UserError as e:
            raise SceneFormatError(src, field, str(e)) from None

    for i, d in enumerate(spec.designs):
        f = f"designs[{i}]"
        for k, name in enumerate(d.lightings or []):
            named(f"{f}.lightings[{k}]", load_lighting, name)
        if d.path not in paths:
            paths[d.path] = named(f"{f}.path", load_path, d.path)
        cpath = paths[d.path]
        n = len(cpath.poses)
        if n == 0:
            fail(src, f"{f}.path", f"camera path '{d.path}' has no poses")
        if d.frames is not None and d.frames > n:
            fail(src, f"{f}.path.frames", f"{d.frames} exceeds the {n} frames of camera path '{cpath.name}'")
        for k, name in enumerate(d.layouts):
            field = f"{f}.layouts[{k}]"
            if name not in layouts:
                layouts[name] = (named(field, resolve_layout_path, name), named(field, load_layout, name))
            lfile, lay = layouts[name]
            key = (name, d.path, d.frames)
            if check_clearance and key not in checked:
                checked.add(key)
                why = render_clearance_problem(cpath, lay, lfile, name, d.frames)
                if why:
                    fail(src, field, why)


def expand(spec: JobSpec, out: Path | None = None, check_clearance: bool = False) -> Plan:
    """Validate every name and expand the spec into tours and chunks. Writes nothing.

    ``check_clearance`` (what ``synth render`` does unless ``--allow-clearance-breach``): refuse a
    path that breaks its declared clearance in a layout it was not planned on. Readers of rendered
    tours (``reloc experiment``) expand without it."""
    from_cli = out is not None
    out = Path(out or spec.out)
    try:
        check_output_folder(out)
    except UserError as e:
        _out_error(spec, from_cli, e)
    validate_names(spec, check_clearance)
    plan = Plan(spec, out, {})
    seen_geo: dict[str, list[Chunk]] = {}
    for d in spec.designs:
        for layout in d.layouts:
            for lighting in (d.lightings or [None]):
                name = tour_name(layout, lighting, d.path)
                if name in plan.tours:
                    continue
                ts = TourSpec(layout=layout, path=d.path, out=str(out / name), lighting=lighting, renderer=spec.renderer,
                              quality=spec.quality, width=spec.width, height=spec.height, hfov_deg=spec.hfov_deg,
                              frames=d.frames, seed=spec.seed, device=spec.device, previews=spec.previews,
                              chunk_size=spec.chunk_size, geometry_cache=str(out / "_geometry"),
                              check_clearance=False)  # validate_names did, once per layout + path
                p = prepare(ts, create=False)
                if spec.renderer == "blender" and spec.geometry == "fast":  # never mixed with a Cycles cache
                    p.geometry_dir = p.geometry_dir.with_name(p.geometry_dir.name + "__fast")
                p.extra["rgb_every"] = d.rgb_every if lighting is not None else None
                plan.tours[name] = p
                ids = p.frame_ids
                groups = [ids[k : k + spec.chunk_size] for k in range(0, len(ids), spec.chunk_size)]
                if spec.renderer == "fast":
                    for k, g in enumerate(groups):
                        plan.chunks.append(Chunk(f"fast/{name}/{k:04d}", "fast", name, g, chunk_job(p, "fast", g), str(p.out / "frames")))
                    continue
                gkey = p.geometry_dir.name
                if gkey not in seen_geo:
                    seen_geo[gkey] = []
                    gkind = "fast" if spec.geometry == "fast" else "geometry"
                    for k, g in enumerate(groups):
                        c = Chunk(f"geometry/{gkey}/{k:04d}", gkind, name, g, chunk_job(p, gkind, g, p.geometry_dir),
                                  str(p.geometry_dir))
                        seen_geo[gkey].append(c)
                        plan.chunks.append(c)
                every = d.rgb_every if lighting is not None else 0
                for k, g in enumerate(groups):
                    need = seen_geo[gkey][k].id
                    rgb = [i for i in g if every and i % every == 0]
                    copy = [i for i in g if not (every and i % every == 0)]
                    if rgb:
                        plan.chunks.append(Chunk(f"rgb/{name}/{k:04d}", "rgb", name, rgb, chunk_job(p, "rgb", rgb),
                                                 str(p.out / "frames"), needs=need))
                    if copy:
                        plan.chunks.append(Chunk(f"copy/{name}/{k:04d}", "copy", name, copy, chunk_job(p, "copy", copy),
                                                 str(p.out / "frames"), needs=need))
    return plan


# ---------------------------------------------------------------------------------------------
# state


class JobState:
    """``job_state.json``: chunk id -> {state, attempts, error, frames}; rewritten atomically."""

    def __init__(self, path: Path, chunks: list[Chunk], spec_doc: dict, store=None):
        self.path = path
        self.store = store  # synth.jobs.storage.Storage: every save is copied up
        self.doc = {"spec": spec_doc, "chunks": {c.id: {"state": "pending", "attempts": 0, "error": None,
                                                        "frames": [c.frames[0], c.frames[-1]], "devices": []}
                                                 for c in chunks}}

    @staticmethod
    def load(path: Path) -> dict | None:
        if not path.exists():
            return None
        try:
            return json.loads(path.read_text())
        except (OSError, json.JSONDecodeError) as e:
            raise UserError(f"{path}: unreadable job state ({e}); delete it to start the job afresh") from None

    def merge(self, old: dict) -> None:
        for cid, st in (old or {}).get("chunks", {}).items():
            if cid in self.doc["chunks"]:
                self.doc["chunks"][cid]["attempts"] = st.get("attempts", 0)
                self.doc["chunks"][cid]["devices"] = sorted(set(st.get("devices") or []))

    def set(self, cid: str, state: str, error: str | None = None, attempt: bool = False, device: str | None = None) -> None:
        c = self.doc["chunks"][cid]
        if device:  # the device a worker reported rendering on (``ready`` event), over every attempt
            c["devices"] = sorted(set(c.get("devices") or []) | {device})
        c["state"] = state
        c["error"] = error
        if attempt:
            c["attempts"] += 1
        self.save()

    def save(self) -> None:
        text = json.dumps(self.doc, indent=1)
        write_text_atomic(self.path, text)
        if self.store is not None:
            self.store.write_text(self.path, text)

    def devices(self, chunks: list[Chunk]) -> dict:
        """Pass -> the devices its chunks reported (sorted), for the passes that rendered anything."""
        out: dict[str, set] = {}
        for c in chunks:
            devs = self.doc["chunks"][c.id].get("devices") or []
            if devs:
                out.setdefault(c.kind, set()).update(devs)
        return {k: sorted(v) for k, v in sorted(out.items())}

    def counts(self) -> dict:
        out: dict[str, int] = {}
        for c in self.doc["chunks"].values():
            out[c["state"]] = out.get(c["state"], 0) + 1
        return out


def spec_document(spec: JobSpec) -> dict:
    d = asdict(spec)
    d.pop("source", None)
    if d.get("replicacad") is None:  # a spec without it reads as before: jobs started earlier still resume
        d.pop("replicacad", None)
    return d


# ---------------------------------------------------------------------------------------------
# running chunks


class _Bar:
    def __init__(self, total: int, done: int, enabled: bool, desc: str):
        from tqdm import tqdm

        self.bar = tqdm(total=total, initial=done, desc=desc, unit="frame", disable=not enabled, dynamic_ncols=True,
                        smoothing=0.1)
        self.failures = 0

    def update(self, n=1):
        self.bar.update(n)

    def fail(self):
        self.failures += 1
        self.bar.set_postfix(failures=self.failures, refresh=True)

    def close(self):
        self.bar.close()


class _Queue:
    """Chunk bookkeeping shared by both backends: what may start, and what a finished chunk means.

    rgb and copy chunks wait for their geometry chunk; a chunk that failed is put back until it has
    had ``retries`` more attempts, then reported failed, and whatever waits on it fails with it."""

    def __init__(self, plan: Plan, state: JobState, todo: list[Chunk], bar: _Bar):
        self.spec, self.state, self.bar = plan.spec, state, bar
        self.pending = list(todo)
        self.done = {c.id for c in plan.chunks if c not in todo}
        self.failed: set[str] = set()

    def take_ready(self, limit: int) -> list[Chunk]:
        for c in [c for c in self.pending if c.needs in self.failed]:
            self.pending.remove(c)
            self._fail(c, f"its geometry chunk {c.needs} failed")
        out = []
        for c in list(self.pending):
            if len(out) >= limit:
                break
            if c.needs is None or c.needs in self.done:
                self.pending.remove(c)
                self.state.set(c.id, "running", attempt=True)
                out.append(c)
        return out

    def finished(self, c: Chunk, rc: int, err: str | None, log: str, device: str | None = None) -> bool:
        """Record a chunk's end (and the device it rendered on); True when it is done, False when it
        will be retried or failed."""
        if rc == 0 and not c.missing():
            self.done.add(c.id)
            self.state.set(c.id, "done", device=device)
            return True
        msg = f"{err or 'frames missing after the chunk ended'} (log: {log})"
        if self.state.doc["chunks"][c.id]["attempts"] <= self.spec.retries:
            self.state.set(c.id, "pending", msg, device=device)
            self.pending.insert(0, c)
        else:
            self._fail(c, msg, device)
        return False

    def _fail(self, c: Chunk, msg: str, device: str | None = None) -> None:
        self.failed.add(c.id)
        self.state.set(c.id, "failed", msg, device=device)
        self.bar.fail()


def _files(work: Path, c: Chunk) -> tuple[str, str]:
    base = work / c.id.replace("/", "_")
    return str(base) + ".json", str(base) + ".log"


def run_local(plan: Plan, state: JobState, todo: list[Chunk], workers: int, bar: _Bar, work: Path) -> dict:
    """Local backend: ``workers`` chunk processes at a time, each a fresh (Blender) process."""
    import threading
    from concurrent.futures import FIRST_COMPLETED, ThreadPoolExecutor, wait

    info: dict = {}
    lock = threading.Lock()
    q = _Queue(plan, state, todo, bar)

    def on_frame(_ev):
        with lock:
            bar.update()

    with ThreadPoolExecutor(max_workers=workers) as pool:
        running = {}
        while True:
            for c in q.take_ready(workers - len(running)):
                jf, log = _files(work, c)
                running[pool.submit(run_chunk_process, c.kind, c.job, jf, log, on_frame)] = (c, log)
            if not running:
                break
            finished, _ = wait(running, return_when=FIRST_COMPLETED)
            for fut in finished:
                c, log = running.pop(fut)
                rc, err, inf = fut.result()
                info.update(inf)
                q.finished(c, rc, err, log, device=inf.get("device"))
    return info


def run_ray(plan: Plan, state: JobState, todo: list[Chunk], bar: _Bar, work: Path) -> dict:
    """Ray backend, on the cluster ``run_job`` connected to (``synth.jobs.ray_backend.connect``): each chunk is
    a Ray task (CPU or GPU request) that gets everything it reads in its arguments, renders in a
    node-local scratch folder and sends its frames home, where they are written atomically into the
    job folder; progress advances per frame (``synth.jobs.ray_backend``)."""
    from . import ray_backend

    return ray_backend.run(plan, state, todo, bar, work, _Queue, _files)


def run_job(spec: JobSpec, out: Path | str | None = None, workers: int = 1, backend: str = "local",
            ray_address: str | None = None, resume: bool = False, progress: bool = True,
            allow_clearance_breach: bool = False, replicacad_root: str | None = None,
            ray_runtime_env: str = "auto") -> dict:
    """Render everything the spec asks for that is not on disk yet. Returns a summary.

    A spec with ``replicacad:`` first imports its scenes and plans its paths into ``OUT/replicacad``
    (``synth.replicacad.job.prepare``; ``replicacad_root`` overrides the spec's dataset folder).

    ``backend="ray"``: the cluster at ``ray_address`` (default: a local instance on loopback, or the
    connection this process already has) is connected to and checked (a CPU; a GPU for ``device:
    gpu``) before anything is written; ``ray_runtime_env`` is ``synth.jobs.ray_backend.runtime_env``'s mode.

    ``out`` (else the spec's ``out``) may be a storage URI (``synth.jobs.storage``): ``file://PATH`` is the
    folder PATH for the local backend; with the Ray backend any fsspec URI (``file://``, ``memory://``,
    ...) puts the job folder on that file system, written by the driver."""
    t0 = time.time()
    if workers <= 0:
        raise UserError(f"--workers must be positive, got {workers}")
    if backend not in ("local", "ray"):
        raise UserError(f"unknown backend '{backend}'; use local or ray")
    from_cli = out is not None
    out, store = _job_folder(spec, out, backend)
    if spec.replicacad is not None:
        from ..replicacad.job import prepare as prepare_replicacad

        target = Path(out or spec.out)
        try:
            check_output_folder(target)
        except UserError as e:
            _out_error(spec, from_cli, e)
        spec = prepare_replicacad(spec, target, replicacad_root,
                                  progress=(lambda m: print(m, file=sys.stderr)) if progress else (lambda m: None))
    staging = None
    session = None
    try:
        if store is None:
            plan = expand(spec, out, check_clearance=not allow_clearance_breach)
            state_path = plan.out / STATE_FILE
            old = JobState.load(state_path)
            shown = str(state_path)
        else:  # the job's small files are staged here and copied up; its frames go straight to the storage
            import tempfile

            staging = Path(tempfile.mkdtemp(prefix="synth_stage_")).resolve()  # chunk jobs hold resolved paths
            plan = expand(spec, staging / "job", check_clearance=not allow_clearance_breach)
            plan.use_storage(store)
            old = _load_stored_state(store)
            shown = store.url(STATE_FILE)
        if old is not None and not resume:
            raise UserError(f"{plan.where} already holds a job (its {STATE_FILE}); add --resume to finish it, or use another --out")
        if old is not None and old.get("spec") != spec_document(spec):
            raise UserError(f"{shown}: {spec_difference(old.get('spec'), spec_document(spec))}: the job in this folder was "
                            "started from a different spec; use another --out")
        if backend == "ray":  # an unreachable cluster, or one without the GPUs asked for, is refused before any write
            from . import ray_backend
            from .storage import local_path

            session = ray_backend.connect(ray_address, ray_runtime_env, spec.device,  # out: kept out of the upload
                                          plan.out if store is None else local_path(store.uri), spec.renderer,
                                          progress=(lambda m: print(m, file=sys.stderr)) if progress else None)
        return _run_plan(plan, old, backend, workers, progress, t0, from_cli=from_cli)
    finally:
        if session is not None:
            session.close()
        if staging is not None:
            import shutil

            shutil.rmtree(staging, ignore_errors=True)


def _job_folder(spec: JobSpec, out, backend: str):
    """(local folder or None, ``synth.jobs.storage.Storage`` or None) of ``--out`` (else the spec's ``out``).
    An unknown scheme, or a non-local one with the local backend, is a one-line UserError."""
    from . import storage

    target = str(out) if out is not None else spec.out
    if not storage.is_uri(target):
        return (Path(out) if out is not None else None), None
    option = "--out" if out is not None else f"{spec.source or '<spec>'}: out:"
    store = storage.Storage(target, option)
    if backend == "local":
        path = storage.local_path(target)
        if path is None:
            raise UserError(f"{option} {target}: a job folder on {storage.scheme(target)}:// storage needs --backend ray "
                            "(its driver writes the frames that come home); the local backend writes to a folder "
                            "(a path or file://)")
        return path, None
    if spec.replicacad is not None:
        raise UserError(f"{option} {target}: a spec with a replicacad: section renders into a local folder (a path), "
                        "not a storage URI")
    store.check_writable()
    return None, store


def _load_stored_state(store) -> dict | None:
    try:
        text = store.read_text(STATE_FILE)
    except FileNotFoundError:
        return None
    try:
        doc = json.loads(text)
    except (json.JSONDecodeError, UnicodeDecodeError) as e:
        raise UserError(f"{store.url(STATE_FILE)}: unreadable job state ({e}); delete it to start the job afresh") from None
    return doc if isinstance(doc, dict) else {}


def spec_difference(old, new, where: str = "") -> str:
    """The first field in which two spec documents differ, and both values: ``quality: 'paper' there,
    'preview' in this spec`` (``designs[0].layouts[1]: ...``)."""
    def short(v) -> str:
        r = repr(v)
        return r if len(r) <= 80 else r[:77] + "..."

    if isinstance(old, dict) and isinstance(new, dict):
        for k in list(new) + [k for k in old if k not in new]:
            if old.get(k) != new.get(k):
                return spec_difference(old.get(k), new.get(k), f"{where}.{k}" if where else str(k))
    elif isinstance(old, list) and isinstance(new, list) and len(old) == len(new):
        for i, (a, b) in enumerate(zip(old, new)):
            if a != b:
                return spec_difference(a, b, f"{where}[{i}]")
    return f"{where or 'spec'}: {short(old)} there, {short(new)} in this spec"


def _run_plan(plan: Plan, old: dict | None, backend: str, workers: int, progress: bool, t0: float,
              from_cli: bool) -> dict:
    spec = plan.spec
    try:
        make_output_folder(plan.out)
    except UserError as e:
        _out_error(spec, from_cli, e)
    state_path = plan.out / STATE_FILE
    store = plan.store
    state = JobState(state_path, plan.chunks, spec_document(spec), store)
    state.merge(old)
    for p in plan.tours.values():
        make_output_folder(p.out)
        if p.geometry_dir:
            make_output_folder(p.geometry_dir)
        write_static_files(p)
    # the planned tours, before any frame: readers of the design know what is still missing
    write_design(plan.out, spec.name, spec.source, {
        name: {"layout": p.layout_name, "lighting": p.lighting_name, "path": p.path_name, "n_frames": len(p.frame_ids)}
        for name, p in plan.tours.items()})
    if store is not None:  # the static files and the design, before any frame
        store.push_tree(plan.out)
    todo, missing_before = [], 0
    for c in plan.chunks:
        if m := c.missing():
            todo.append(c)
            missing_before += len(m)
        else:
            state.doc["chunks"][c.id]["state"] = "done"
    state.save()
    done_frames = plan.frames_total - missing_before
    bar = _Bar(plan.frames_total, done_frames, progress, f"{spec.name}")
    work = plan.out / ".work"
    work.mkdir(parents=True, exist_ok=True)
    try:
        if backend == "local":
            run_local(plan, state, todo, workers, bar, work)
        else:
            run_ray(plan, state, todo, bar, work)
    finally:
        bar.close()
    counts = state.counts()
    wall = round(time.time() - t0, 2)
    # what is on disk now, not what was planned: a chunk that failed before it rendered counts nothing
    missing_after = {c.id: len(c.missing()) for c in todo}
    rendered = missing_before - sum(missing_after.values())
    failed_ids = [cid for cid, c in state.doc["chunks"].items() if c["state"] == "failed"]
    for name, p in plan.tours.items():
        mine = [c for c in plan.chunks if c.tour == name or (p.geometry_dir and c.out_dir == str(p.geometry_dir))]
        meta = job_tour_meta(p, spec, state.devices(mine))
        if store is not None:  # the frames are in the storage, not in the staging folder
            meta["complete"] = not store.missing(p.out / "frames", p.frame_ids)
        write_json_atomic(p.out / "meta.json", meta, indent=1)
        if store is not None:
            store.write_bytes(p.out / "meta.json", (p.out / "meta.json").read_bytes())
    summary = {"job": spec.name, "out": plan.where, "tours": len(plan.tours), "chunks": counts,
               "frames_total": plan.frames_total, "frames_rendered_now": rendered, "wall_time_s": wall,
               "frames_per_s": round(rendered / wall, 3) if wall > 0 else None, "backend": backend, "workers": workers,
               "frames_missing": sum(missing_after.values()),
               "frames_failed": sum(missing_after.get(cid, 0) for cid in failed_ids), "chunks_failed": len(failed_ids),
               "failed": {cid: state.doc["chunks"][cid]["error"] for cid in failed_ids}}
    write_json_atomic(plan.out / "job_summary.json", summary, indent=1)
    if store is not None:
        store.write_bytes(plan.out / "job_summary.json", (plan.out / "job_summary.json").read_bytes())
    if not summary["failed"]:
        import shutil

        shutil.rmtree(work, ignore_errors=True)
        if store is not None:
            store.remove_tree(work)  # the logs the driver copied up
    return summary


def job_tour_meta(p, spec: JobSpec, render_devices: dict | None = None) -> dict:
    """meta.json of a job's tour (``synth.render.render_tour.tour_meta``). Deterministic (a resumed job writes the
    same file); timing and progress of the job are in ``job_summary.json``.

    ``render_devices``: pass -> the devices its chunks reported rendering on (``CPU``, ``OPTIX``,
    ``CUDA``...), kept per chunk in ``job_state.json`` so a resumed job writes the same."""
    return tour_meta(
        p, renderer=spec.renderer, seed=spec.seed, blender=_blender_version() if spec.renderer == "blender" else None,
        settings={"quality": spec.quality, "quality_settings": quality(spec.quality) if p.lighting_name else None,
                  "width": spec.width, "height": spec.height, "hfov_deg": spec.hfov_deg, "device": spec.device,
                  "chunk_size": spec.chunk_size, "previews": spec.previews, "rgb_every": p.extra.get("rgb_every")},
        geometry_renderer=spec.geometry, job=spec.name, render_devices=render_devices or {},
    )


def _blender_version() -> str | None:
    from importlib import metadata

    try:
        return metadata.version("bpy")
    except metadata.PackageNotFoundError:
        return None


# ---------------------------------------------------------------------------------------------
# dry run: the plan and an estimate from a short calibration render


def measure_calibration(plan: Plan, frames: int = 1) -> dict:
    """A calibration document (``synth.jobs.estimate``): seconds per frame of each chunk kind of the
    plan, measured here on ``frames`` frames (after one left out: it pays for loading the kernels) of
    the first tour by one chunk process using every core, with the CPU seconds that process spent on
    them (over all its threads: core-seconds, which another job on the machine does not inflate
    the way it does wall time), the device each kind rendered on, the size
    of a frame file, and this machine (CPU count and model, load average, date, toolkit version)."""
    import tempfile

    from formats.camera import write_tum

    from .estimate import CALIBRATION_FORMAT, CALIBRATION_VERSION, is_gpu, measure_environment

    spec = plan.spec
    name, p = next(iter(plan.tours.items()))
    per, cpu, size, devices = {}, {}, {}, {}
    load = [round(x, 2) for x in os.getloadavg()] if hasattr(os, "getloadavg") else None
    with tempfile.TemporaryDirectory(prefix="synth_calib_") as tmp:
        tmp = Path(tmp)
        idx = list(range(min(frames + 1, len(p.frame_ids))))
        write_tum(tmp / "poses.txt", p.poses[idx], fps=p.path_fps)
        base = {"layout": str(p.layout_file.resolve()), "poses": str(tmp / "poses.txt"), "fps": p.path_fps, "frames": idx,
                "intrinsics": p.intr.to_dict(), "quality": spec.quality, "seed": spec.seed, "device": spec.device,
                "geometry_dir": str(tmp / "geom"), "previews_dir": None, "threads": 0}
        geo = "fast" if spec.geometry == "fast" else "geometry"
        kinds = [geo] + (["rgb"] if spec.renderer == "blender" and any(t.lighting_name for t in plan.tours.values()) else [])
        for kind in kinds:
            out_dir = tmp / ("geom" if kind == geo else kind)
            job = {**base, "pass": kind, "out_dir": str(out_dir),
                   "lighting": next((t.spec.lighting for t in plan.tours.values() if t.lighting_name), None)}
            events = []
            rc, err, inf = run_chunk_process(kind, job, str(tmp / f"{kind}.json"), str(tmp / f"{kind}.log"),
                                             on_frame=events.append)
            if rc != 0:
                raise UserError(f"calibration render ({kind}) failed: {err}")
            steady = events[1:] or events  # the first frame pays for kernel loading
            per[kind] = sum(ev["seconds"] for ev in steady) / len(steady)
            if all("cpu" in ev for ev in steady):
                cpu[kind] = sum(ev["cpu"] for ev in steady) / len(steady)
            files = [out_dir / fr.frame_name(i) for i in idx if (out_dir / fr.frame_name(i)).exists()]
            if files:
                size[kind] = round(sum(f.stat().st_size for f in files) / len(files))
            devices[kind] = inf.get("device") or "CPU"
    if hasattr(os, "getloadavg"):
        load = [round(max(a, b), 2) for a, b in zip(load, os.getloadavg())]
    env = measure_environment()
    return {"format": CALIBRATION_FORMAT, "version": CALIBRATION_VERSION, "seconds_per_frame": per,
            "cpu_seconds_per_frame": cpu, "bytes_per_frame": size, "devices": devices,
            "device": next((d for d in devices.values() if is_gpu(d)), "CPU"),
            "frames_measured": len(idx) - 1 if len(idx) > 1 else len(idx), "tour": name,
            "spec": {"name": spec.name, "source": spec.source, "renderer": spec.renderer, "geometry": spec.geometry,
                     "quality": spec.quality, "width": spec.width, "height": spec.height, "device": spec.device},
            "load_avg": load, **env}


def calibrate(plan: Plan, frames: int = 1) -> dict:
    """Seconds per frame of each chunk kind, measured on ``frames`` frames of the first tour."""
    return measure_calibration(plan, frames)["seconds_per_frame"]


def estimate(plan: Plan, per_frame: dict, workers: int) -> float:
    """Seconds on this machine. The calibration ran one process using every core, so running more
    local workers hides per-chunk start-up (about 3-4 s each) rather than dividing the frame time.
    (A Ray cluster: ``synth.jobs.estimate``.)"""
    from .estimate import SETUP_S

    work = 0.0
    for c in plan.chunks:
        if c.kind in per_frame:
            work += per_frame[c.kind] * len(c.missing())
    work += sum(SETUP_S.get(c.kind, 0.0) for c in plan.chunks if c.missing()) / max(1, min(workers, os.cpu_count() or 1))
    return work


def describe(plan: Plan) -> str:
    spec = plan.spec
    lines = [f"job {spec.name}: {len(plan.tours)} tours, {plan.frames_total} chunk-frames in {len(plan.chunks)} chunks "
             f"({spec.renderer}, {spec.quality}, {spec.width}x{spec.height}, chunks of {spec.chunk_size}) -> {plan.where}"]
    by_kind: dict[str, list] = {}
    for c in plan.chunks:
        by_kind.setdefault(c.kind, []).append(c)
    for k, cs in by_kind.items():
        miss = sum(len(c.missing()) for c in cs)
        lines.append(f"  {k:<9} {len(cs):>5} chunks {sum(len(c.frames) for c in cs):>7} frames, {miss} still to render")
    for name, p in plan.tours.items():
        lines.append(f"  tour {name}: {len(p.frame_ids)} frames")
    return "\n".join(lines)


def _cluster_args(args) -> list:
    """The cluster shapes of ``--nodes`` etc. (``synth.jobs.estimate.Cluster``), checked; [] without
    ``--nodes``. Each bad value is a one-line UserError naming the option."""
    from .estimate import Cluster, parse_count, parse_nodes

    given = [o for o, v in (("--nodes", args.nodes), ("--cpus-per-node", args.cpus_per_node),
                            ("--gpus-per-node", args.gpus_per_node), ("--chunks-per-node", args.chunks_per_node),
                            ("--calibration", args.calibration), ("--save-calibration", args.save_calibration),
                            ("--link-gbps", args.link_gbps)) if v is not None]
    if given and not args.dry_run:
        raise UserError(f"{given[0]}: only with --dry-run (it estimates, it renders nothing)")
    if args.calibration is not None and args.save_calibration is not None:
        raise UserError("--save-calibration: nothing is measured with --calibration FILE (it is read instead)")
    if args.nodes is None:
        extra = [o for o in given if o not in ("--calibration", "--save-calibration")]
        if extra:
            raise UserError(f"{extra[0]}: needs --nodes N (the cluster's size)")
        return []
    nodes = parse_nodes(args.nodes)
    if args.cpus_per_node is None:
        raise UserError("--nodes: needs --cpus-per-node C (the cores of each node)")
    cpus = parse_count(args.cpus_per_node, "--cpus-per-node")
    gpus = parse_count(args.gpus_per_node, "--gpus-per-node", allow_zero=True) if args.gpus_per_node is not None else 0
    per = parse_count(args.chunks_per_node, "--chunks-per-node") if args.chunks_per_node is not None else 1
    if gpus and args.chunks_per_node is not None:
        raise UserError("--chunks-per-node: GPU nodes run one chunk per GPU; leave it out with --gpus-per-node")
    if per > cpus:
        raise UserError(f"--chunks-per-node: {per} chunks at a time on {cpus} cores leaves a chunk less than one core")
    if args.link_gbps is not None:
        try:
            link = float(args.link_gbps)
        except ValueError:
            link = float("nan")
        if not link > 0 or link == float("inf"):
            raise UserError(f"--link-gbps: expected a positive number of Gbit/s, got {args.link_gbps!r}")
    if gpus and args.calibration is None:
        raise UserError("--gpus-per-node: no GPU calibration exists (this machine renders on its CPU, and no speed-up "
                        "is assumed); measure one on a GPU node: synth render SPEC --dry-run --save-calibration "
                        "gpu.json (the spec with device: gpu), then add --calibration gpu.json")
    return [Cluster(n, cpus, gpus, per) for n in nodes]


def _dry_run(args, spec: JobSpec, clusters: list) -> int:
    """The plan, a calibration (measured here, or read from --calibration) and the estimates."""
    import tempfile

    from . import estimate as ce

    cal = ce.load_calibration(args.calibration) if args.calibration else None
    if cal is not None and clusters:
        gpu = clusters[0].gpus_per_node > 0
        if gpu and not ce.has_gpu_kinds(cal):
            raise UserError(f"{args.calibration}: device: measured on {cal['device']}, not a GPU: no GPU calibration "
                            "exists for --gpus-per-node (measure one on a GPU node with --save-calibration)")
    if args.save_calibration:
        check_output_file(args.save_calibration)
    out, store = _job_folder(spec, args.out, args.backend)
    with tempfile.TemporaryDirectory(prefix="synth_dry_run_") as tmp:  # a dry run leaves nothing behind
        if spec.replicacad is not None:
            from ..replicacad.job import prepare as prepare_replicacad

            spec = prepare_replicacad(spec, Path(tmp), args.replicacad_root, progress=lambda m: print(m, file=sys.stderr))
        if store is None:
            plan = expand(spec, out, check_clearance=not args.allow_clearance_breach)
        else:  # what is still to render is read from the storage
            plan = expand(spec, Path(tmp).resolve() / "job", check_clearance=not args.allow_clearance_breach)
            plan.use_storage(store)
        work = ce.plan_work(plan)
        if cal is not None:
            ce.check_fits(cal, spec, work, args.calibration)
        print(describe(plan))
        if cal is None:
            cal = measure_calibration(plan)
            where = "measured here"
        else:
            where = f"from {args.calibration}"
    if args.save_calibration:
        write_json_atomic(args.save_calibration, cal, indent=1)
    per = cal["seconds_per_frame"]
    print("  calibration (s/frame, one process on every core): " + ", ".join(f"{k} {v:.3f}" for k, v in per.items())
          + f" [{where}: {cal['cpu_count']} CPUs, {cal['device']}]")
    if args.save_calibration:
        print(f"  calibration saved to {args.save_calibration}")
    if where == "measured here":
        eta = estimate(plan, per, args.workers)
        print(f"  estimate with {args.workers} worker(s): {fmt_duration(eta)} on this machine "
              f"({os.cpu_count()} CPUs); on a Ray cluster: --nodes N --cpus-per-node C")
    if clusters:
        link = float(args.link_gbps) if args.link_gbps is not None else ce.DEFAULT_LINK_GBPS
        best = [ce.estimate_cluster(work, cal, c, "longest", link_gbps=link) for c in clusters]
        driver = [ce.estimate_cluster(work, cal, c, "plan", link_gbps=link) for c in clusters]
        print("  " + ce.describe_estimate(best, cal, where, plan_order=driver).replace("\n", "\n  "))
        if clusters[0].gpus_per_node and spec.device == "cpu":
            print("  note: the spec says device: cpu, so its chunks would not ask Ray for GPUs: set device: gpu (or auto) "
                  "to render on them")
    return 0


def cmd_render(args) -> int:
    cluster = _cluster_args(args)  # bad options are refused before anything is read or rendered
    spec = load_spec(args.spec)
    if args.replicacad_root and spec.replicacad is None:
        raise UserError(f"--replicacad-root: {args.spec} has no replicacad: section (its layouts are not ReplicaCAD scenes)")
    if args.dry_run:
        return _dry_run(args, spec, cluster)
    s = run_job(spec, args.out, workers=args.workers, backend=args.backend,
                ray_address=args.ray_address, ray_runtime_env=args.ray_runtime_env, resume=args.resume, progress=not args.quiet,
                allow_clearance_breach=args.allow_clearance_breach, replicacad_root=args.replicacad_root)
    failed = (f", {s['frames_failed']} frames failed in {s['chunks_failed']} chunk(s)" if s["chunks_failed"] else "")
    print(f"{s['job']}: {s['tours']} tours, {s['frames_rendered_now']} frames rendered{failed} in {s['wall_time_s']:.1f} s "
          f"({s['frames_per_s']} frames/s), chunks {s['chunks']} -> {s['out']}")
    for cid, err in s["failed"].items():
        print(f"  FAILED {cid}: {err}", file=sys.stderr)
    return 1 if s["failed"] else 0


def register_cli(subparsers) -> None:
    a = subparsers.add_parser("render", help="render a job spec: every tour of its design")
    a.add_argument("spec", help="job spec YAML, or the name of a shipped one (synth/specs: demo, smoke, ...)")
    a.add_argument("--out", help="the job folder (default: the spec's out): a path, or with --backend ray a storage URI "
                   "(file://, memory://, or another fsspec scheme: the driver writes the job there; docs/cluster.md)")
    a.add_argument("--workers", type=int, default=1, help="chunks rendered at a time (local backend)")
    a.add_argument("--backend", choices=["local", "ray"], default="local")
    a.add_argument("--ray-address", help="address of a running Ray cluster, HOST:PORT (default: start a local one on loopback)")
    a.add_argument("--ray-runtime-env", choices=["auto", "full", "code", "none"], default="auto",
                   help="what the Ray nodes get from the driver: full (the toolkit's checkout, code and data, as the working_dir, "
                        "and its pip requirements pinned to the driver's versions), code (only the working_dir), none "
                        "(installed on every node); auto: full with --ray-address, else none (docs/cluster.md)")
    a.add_argument("--resume", action="store_true", help="finish a job that was stopped; renders only what is missing")
    a.add_argument("--dry-run", action="store_true", help="print the plan and an estimate from a short calibration render")
    g = a.add_argument_group("planning at scale (with --dry-run; docs/cluster.md)")
    g.add_argument("--nodes", metavar="N[,N...]", help="estimate the wall time on a Ray cluster of N nodes (a list: one row each)")
    g.add_argument("--cpus-per-node", metavar="C", help="cores of each node")
    g.add_argument("--gpus-per-node", metavar="G", help="GPUs of each node: one chunk per GPU; needs --calibration "
                   "measured on a GPU node")
    g.add_argument("--chunks-per-node", metavar="K", help="CPU nodes: chunks at a time per node, i.e. the node's "
                   "ray start --num-cpus (default 1, as the docs advise for Blender jobs)")
    g.add_argument("--link-gbps", metavar="GBPS", help="the driver's network link, for the time frames take to come home "
                   "(default 1)")
    g.add_argument("--save-calibration", metavar="FILE", help="write the calibration measured here (JSON)")
    g.add_argument("--calibration", metavar="FILE", help="use this calibration (--save-calibration's JSON, e.g. from a "
                   "GPU node) instead of rendering one here")
    a.add_argument("--allow-clearance-breach", action="store_true",
                   help="render even where a path comes closer to an object than its declared clearance "
                        "(checked for layouts the path was not planned on)")
    a.add_argument("--replicacad-root", metavar="DIR",
                   help="ReplicaCAD folder for a spec with a replicacad: section (default: its root, else $REPLICACAD_ROOT)")
    a.add_argument("--quiet", action="store_true")
    a.set_defaults(fn=cmd_render)
