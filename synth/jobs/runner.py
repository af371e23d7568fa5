"""Running a render job: ``run_job`` renders everything a spec asks for that is not on disk yet,
locally (``synth.jobs.chunk_queue``) or on a Ray cluster (``synth.jobs.ray_backend``), into a folder or
onto a storage URI (``synth.jobs.storage``), and writes each tour's ``meta.json`` and the job's
``job_summary.json``. Killed, it loses nothing: ``--resume`` finishes what is missing
(``synth.jobs.state``)."""

from __future__ import annotations

import json
import os
import sys
import time
from pathlib import Path

from vrformats.atomic import write_json_atomic
from vrformats.design import write_design
from vrformats.environment import cpu_model
from vrformats.errors import UserError, check_output_folder
from vrformats.lifetime import folder_lock

from ..tour.render import make_output_folder, tour_meta, write_static_files
from ..render.settings import resolve_quality
from .plan import Chunk, Plan, expand, out_error
from .chunk_queue import ProgressBar, run_local
from .estimate import LiveEta
from .spec import JobSpec, spec_difference, spec_document
from .state import DONE, FAILED, STATE_FILE, JobState, load_stored_state


def run_ray(plan: Plan, state: JobState, todo: list[Chunk], bar: ProgressBar, work: Path) -> dict:
    """Ray backend, on the cluster ``run_job`` connected to (``synth.jobs.ray_backend.connect``): each chunk is
    a Ray task (CPU or GPU request) that gets everything it reads in its arguments, renders in a
    node-local scratch folder and sends its frames home, where they are written atomically into the
    job folder; progress advances per frame (``synth.jobs.ray_backend``)."""
    from . import ray_backend

    return ray_backend.run(plan, state, todo, bar, work)


def run_job(spec: JobSpec, out: Path | str | None = None, workers: int = 1, backend: str = "local",
            ray_address: str | None = None, resume: bool = False, progress: bool = True,
            allow_clearance_breach: bool = False, replicacad_root: str | None = None, check_light: bool = False,
            ray_runtime_env: str = "auto", geometry_from: str | Path | None = None) -> dict:
    """Render everything the spec asks for that is not on disk yet. Returns a summary.

    A spec with ``replicacad:`` first imports its scenes and plans its paths into ``OUT/replicacad``
    (its scene source's ``prepare``, ``synth.sources``; ``replicacad_root`` overrides the spec's dataset folder).

    ``backend="ray"``: the cluster at ``ray_address`` (default: a local instance on loopback, or the
    connection this process already has) is connected to and checked (a CPU; a GPU for ``device:
    gpu``) before anything is written; ``ray_runtime_env`` is ``synth.jobs.ray_backend.runtime_env``'s mode.

    ``out`` (else the spec's ``out``) may be a storage URI (``synth.jobs.storage``): ``file://PATH`` is the
    folder PATH for the local backend; with the Ray backend any fsspec URI (``file://``, ``memory://``,
    ...) puts the job folder on that file system, written by the driver.

    ``geometry_from``: another job folder of the same design (another seed or Cycles settings, say):
    its geometry caches are hard-linked (``link_geometry``) so that only the RGB passes render."""
    t0 = time.time()
    if workers <= 0:
        raise UserError(f"--workers must be positive, got {workers}")
    if backend not in ("local", "ray"):
        raise UserError(f"unknown backend '{backend}'; use local or ray")
    if geometry_from is not None and backend != "local":
        raise UserError("--geometry-from: the geometry caches are linked into a local job folder; use --backend local")
    from_cli = out is not None
    out, store = job_folder(spec, out, backend)
    from ..sources import spec_source

    scene_source = spec_source(spec)
    if scene_source is not None:
        target = Path(out or spec.out)
        try:
            check_output_folder(target)
        except UserError as e:
            out_error(spec, from_cli, e)
        spec = scene_source.prepare(spec, target, replicacad_root,
                                  progress=(lambda m: print(m, file=sys.stderr)) if progress else (lambda m: None))
    staging = None
    session = None
    lock = None
    links = None
    try:
        if store is None:
            plan = expand(spec, out, check_clearance=not allow_clearance_breach, check_light=check_light)
            for w in plan.warnings:  # before hours of rendering, not after
                print(f"warning: {w}", file=sys.stderr)
            try:
                check_output_folder(plan.out)
            except UserError as e:
                out_error(spec, from_cli, e)
            links = geometry_links(plan, Path(geometry_from)) if geometry_from is not None else None
            if (plan.out / "results.json").is_file() and not (plan.out / STATE_FILE).is_file():
                out_error(spec, from_cli, UserError(f"{plan.out} holds an experiment's results (results.json); "
                                                    "render into another folder"))
            # one run per job folder (with or without --resume); the kernel drops the lock with the process.
            # A folder that does not exist yet is made and locked only once the run can start (below), so that
            # a refused run (an unreachable cluster, say) writes nothing
            lock = folder_lock(plan.out, "synth render")
            if plan.out.is_dir():
                lock.acquire()
            state_path = plan.out / STATE_FILE
            old = JobState.load(state_path)
            shown = str(state_path)
        else:  # the job's small files are staged here and copied up; its frames go straight to the storage
            import tempfile

            staging = Path(tempfile.mkdtemp(prefix="synth_stage_")).resolve()  # chunk jobs hold resolved paths
            plan = expand(spec, staging / "job", check_clearance=not allow_clearance_breach, check_light=check_light)
            for w in plan.warnings:  # before hours of rendering, not after
                print(f"warning: {w}", file=sys.stderr)
            plan.use_storage(store)
            old = load_stored_state(store)
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
        if lock is not None and not lock.held:
            lock.acquire()
        if links is not None:
            n = link_geometry(links)
            if progress:
                print(f"{n} geometry frames linked from {geometry_from}", file=sys.stderr)
        return _run_plan(plan, old, backend, workers, progress, t0, from_cli=from_cli)
    finally:
        if session is not None:
            session.close()
        if lock is not None:
            lock.release()
        if staging is not None:
            import shutil

            shutil.rmtree(staging, ignore_errors=True)


def geometry_links(plan: Plan, source: Path) -> list[tuple[Path, Path]]:
    """(cache folder in ``source``, the same cache of ``plan``) for each of ``plan``'s geometry caches that
    the job folder ``source`` holds (as a folder, not a link; its frame files that are links are skipped
    by ``link_geometry``); refuses (writing nothing) a folder that is no job or holds none. A
    cache's folder name keys its content (layout, path, size, renderer: ``synth.tour.render``), so a
    cache of the same name holds the same frames."""
    if not (source / STATE_FILE).is_file():
        raise UserError(f"--geometry-from {source}: not a job folder (no {STATE_FILE})")
    if plan.spec.renderer != "blender":
        raise UserError("--geometry-from: the fast renderer has no geometry cache to take (it renders geometry only)")
    caches = sorted({p.geometry_dir for p in plan.tours.values() if p.geometry_dir is not None})
    # a cache folder (or _geometry) that is a link may lead anywhere: only real folders of the job are taken
    found = [(source / "_geometry" / c.name, c) for c in caches
             if not (source / "_geometry").is_symlink() and not (source / "_geometry" / c.name).is_symlink()
             and (source / "_geometry" / c.name).is_dir()]
    if not found:
        raise UserError(f"--geometry-from {source}: it has none of this design's geometry caches "
                        f"({', '.join(c.name for c in caches[:3])}{' ...' if len(caches) > 3 else ''})")
    return found


def link_geometry(links: list[tuple[Path, Path]]) -> int:
    """Hard-link (copy across file systems) the frames of each ``geometry_links`` pair's source cache
    that its target lacks; returns how many. Only plain files are taken (a link in the source is
    skipped), each made visible whole (``replacing``)."""
    import shutil

    from vrformats.atomic import replacing

    n = 0
    for src, dst_dir in links:
        dst_dir.mkdir(parents=True, exist_ok=True)
        for f in sorted(src.iterdir()):
            dst = dst_dir / f.name
            if f.is_symlink() or not f.is_file() or f.name.startswith(".") or dst.exists():
                continue
            with replacing(dst) as tmp:
                tmp.unlink()
                try:
                    os.link(f, tmp)
                except OSError:  # another file system: a copy
                    shutil.copyfile(f, tmp)
            n += 1
    return n


def job_folder(spec: JobSpec, out, backend: str):
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


def _run_plan(plan: Plan, old: dict | None, backend: str, workers: int, progress: bool, t0: float,
              from_cli: bool) -> dict:
    spec = plan.spec
    try:
        make_output_folder(plan.out)
    except UserError as e:
        out_error(spec, from_cli, e)
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
    frames_left: dict[str, int] = {}
    chunks_left: dict[str, int] = {}
    for c in plan.chunks:
        if m := c.missing():
            todo.append(c)
            missing_before += len(m)
            frames_left[c.kind] = frames_left.get(c.kind, 0) + len(m)
            chunks_left[c.kind] = chunks_left.get(c.kind, 0) + 1
        else:
            state.doc["chunks"][c.id]["state"] = DONE
    state.save()
    done_frames = plan.frames_total - missing_before
    # the local backend knows its slots: its bar shows the time left per pass kind (LiveEta)
    eta = LiveEta(frames_left, chunks_left, workers) if backend == "local" else None
    bar = ProgressBar(plan.frames_total, done_frames, progress, f"{spec.name}", eta=eta)
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
    failed_ids = [cid for cid, c in state.doc["chunks"].items() if c["state"] == FAILED]
    for name, p in plan.tours.items():
        mine = [c for c in plan.chunks if c.tour == name or (p.geometry_dir and c.out_dir == str(p.geometry_dir))]
        meta = job_tour_meta(p, spec, state.devices(mine))
        if store is not None:  # the frames are in the storage, not in the staging folder
            meta["complete"] = not store.missing(p.out / "frames", p.frame_ids)
        write_json_atomic(p.out / "meta.json", meta, indent=1)
        if store is not None:
            store.write_bytes(p.out / "meta.json", (p.out / "meta.json").read_bytes())
        elif spec.previews and spec.renderer == "fast" and meta.get("complete", True):  # nothing else previews them
            from ..tour.show import write_previews

            write_previews(p.out)
    summary = {"job": spec.name, "out": plan.where, "tours": len(plan.tours), "chunks": counts,
               "frames_total": plan.frames_total, "frames_rendered_now": rendered, "wall_time_s": wall,
               "frames_per_s": round(rendered / wall, 3) if wall > 0 else None, "backend": backend, "workers": workers,
               "frames_missing": sum(missing_after.values()),
               "frames_failed": sum(missing_after.get(cid, 0) for cid in failed_ids), "chunks_failed": len(failed_ids),
               "failed": {cid: state.doc["chunks"][cid]["error"] for cid in failed_ids}}
    # every run's times, the earlier ones first: a resumed job keeps what its first runs cost
    this_run = {"started": time.strftime("%Y-%m-%dT%H:%M:%S%z", time.localtime(t0)),
                **{k: summary[k] for k in RUN_KEYS if k in summary}, "cpu_model": cpu_model(), "cpus": os.cpu_count()}
    summary["runs"] = previous_runs(plan) + [this_run]
    summary["wall_time_s_all_runs"] = round(sum(r.get("wall_time_s") or 0.0 for r in summary["runs"]), 2)
    write_json_atomic(plan.out / SUMMARY_FILE, summary, indent=1)
    if store is not None:
        store.write_bytes(plan.out / SUMMARY_FILE, (plan.out / SUMMARY_FILE).read_bytes())
    if not summary["failed"]:
        import shutil

        shutil.rmtree(work, ignore_errors=True)
        if store is not None:
            store.remove_tree(work)  # the logs the driver copied up
    return summary


SUMMARY_FILE = "job_summary.json"
# what job_summary.json keeps of each run (its "runs"), besides when it started and on which CPU
RUN_KEYS = ("wall_time_s", "frames_rendered_now", "frames_per_s", "backend", "workers", "frames_missing", "chunks_failed")


def previous_runs(plan: Plan) -> list[dict]:
    """The earlier runs recorded in the job folder's job_summary.json (a summary written before runs
    were kept counts as one run); none when it is missing or unreadable."""
    try:
        text = plan.store.read_text(SUMMARY_FILE) if plan.store is not None else (plan.out / SUMMARY_FILE).read_text()
        old = json.loads(text)
    except (OSError, ValueError, UnicodeDecodeError):
        return []
    if not isinstance(old, dict):
        return []
    if isinstance(old.get("runs"), list):
        return [r for r in old["runs"] if isinstance(r, dict)]
    return [{k: old[k] for k in RUN_KEYS if k in old}]


def job_tour_meta(p, spec: JobSpec, render_devices: dict | None = None) -> dict:
    """meta.json of a job's tour (``synth.tour.render.tour_meta``). Deterministic (a resumed job writes the
    same file); timing and progress of the job are in ``job_summary.json``.

    ``render_devices``: pass -> the devices its chunks reported rendering on (``CPU``, ``OPTIX``,
    ``CUDA``...), kept per chunk in ``job_state.json`` so a resumed job writes the same."""
    settings = {"quality": spec.quality, "quality_settings": resolve_quality(spec.quality, spec.cycles) if p.lighting_name else None,
                "width": spec.width, "height": spec.height, "hfov_deg": spec.hfov_deg, "device": spec.device,
                "chunk_size": spec.chunk_size, "previews": spec.previews, "rgb_every": p.extra.get("rgb_every")}
    if spec.cycles:  # only when set: the meta of a job without them is as before (readers key on its content)
        settings["cycles"] = spec.cycles
    if spec.threads:
        settings["threads"] = spec.threads
    return tour_meta(
        p, renderer=spec.renderer, seed=spec.seed, blender=_blender_version() if spec.renderer == "blender" else None,
        settings=settings,
        geometry_renderer=spec.geometry, job=spec.name, render_devices=render_devices or {},
    )


def _blender_version() -> str | None:
    from importlib import metadata

    try:
        return metadata.version("bpy")
    except metadata.PackageNotFoundError:
        return None
