"""``reloc experiment SPEC.yaml``: VideoReloc and the baselines over a rendered controlled-change design.

The spec (its keys, methods and sensors) is :mod:`reloc.experiments.spec`. A run: the design's
tours (``design_tours``), the maps from the mapping tour (once per map sensor), every method on
every query tour reading (:mod:`reloc.experiments.tasks`, in a process pool with dependencies:
the clip-rigid controls wait for VideoReloc's clips), external methods
(:mod:`reloc.experiments.external`), then evaluation and tables (:mod:`reloc.experiments.tables`),
plots and the report.

Resumable: every (method, tour) result and every map is written atomically and marked done with
a key of what it depends on: its input files' content, its settings and the code that computes it
(``code_fingerprint``); a rerun does only what is missing or changed. Results, tables, plots and
the report go to ``out`` (layout in ``results.json``, see :mod:`reloc.experiments.tables`).
"""

from __future__ import annotations

import concurrent.futures as cf
import json
import math
import multiprocessing as mp
import os
import sys
import time
from pathlib import Path

from vrformats.fields import terminal_safe
from vrformats.atomic import write_json_atomic
from vrformats.design import DESIGN_FILE, list_tours, read_design, tour_name
from vrformats.errors import SceneFormatError, UserError, check_output_folder
from vrformats.yamlfile import read_json
from vrformats.lifetime import folder_lock, stop_processes, worker_init
from vrformats.sensors import load_sensor
from vrformats.tour import META_FILE, POSES_FILE, Tour
from vrformats.cli import add_quiet, add_workers

from . import methods as registry
from . import tables
from .fingerprint import code_fingerprint, file_key, ground_truth_key, key_of
from .methods.common import open_detector
from .spec import ExperimentSpec, load_experiment, replicate_spec
from .tables import ABLATIONS, ablation_name, reading_name
from .tasks import DONE, is_done, run_map_task, run_tour_task


# ---------------------------------------------------------------------------------------------
# the design on disk


def design_tours(spec: ExperimentSpec) -> tuple[dict, dict]:
    """(query tours {name: info}, mapping tour info) of the design in ``spec.tours_root``, read from
    its files (``vrformats.design``): the planned tours from design.json, each tour from its meta.json
    (without design.json, the tours found there). Checks that they are rendered.

    Every query tour is there once per sensor of the spec, named ``reading_name(tour, sensor)``,
    with ``tour`` (the tour's name) and ``sensor`` in its info."""
    root = spec.tours_root
    found = list_tours(root)
    planned = read_design(root)
    if planned is None:
        planned = {n: {k: m.get(k) for k in ("layout", "lighting", "path")} for n, m in found.items()}
    where = f"the design in {root}"
    if not planned:
        raise UserError(f"{root}: no rendered design here (no {DESIGN_FILE}, no tour with a meta.json); "
                        f"run: synth render {spec.render}")
    missing = []

    def info(name, p) -> dict | None:
        d = root / name
        meta = found.get(name)
        if meta is None or not (d / "poses.txt").is_file():
            missing.append(name)
            return None
        if meta.get("complete") is False:
            missing.append(name + " (incomplete)")
            return None
        t = Tour(d)
        for s in spec.sensors + ((spec.map_sensor,) if spec.map_sensor else ()):  # before anything runs
            load_sensor(s["spec"]).check_resolution(t.intrinsics.width, t.intrinsics.height, str(d))
        return {"dir": str(d.resolve()), "layout": p["layout"], "lighting": p["lighting"], "path": p["path"],
                "rearranged": p["layout"] != spec.unchanged, "frames": len(t), "fps": t.fps, "rgb_every": t.rgb_every}

    m = spec.mapping
    mname = tour_name(m["layout"], m["lighting"], m["path"])
    if mname not in planned:
        raise SceneFormatError(spec.source, "mapping", f"{where} has no tour {mname}")
    queries = {n: p for n, p in planned.items() if p["path"] == spec.query and n != mname}
    if not queries:
        raise SceneFormatError(spec.source, "query", f"{where} has no tours of path {spec.query!r}")
    if spec.unchanged not in {p["layout"] for p in queries.values()}:
        raise SceneFormatError(spec.source, "unchanged", f"layout {spec.unchanged!r} has no query tour in {where}")
    out = {n: info(n, p) for n, p in queries.items()}
    mapping = info(mname, planned[mname])
    if missing:
        raise UserError(f"{root}: {len(missing)} tour(s) not rendered: {', '.join(missing[:4])}"
                        f"{' ...' if len(missing) > 4 else ''}; run: synth render {spec.render} --resume")
    read = {reading_name(n, s): {**t, "tour": n, "sensor": s} for s in spec.sensor_names for n, t in out.items()}
    if spec.sweep is not None:
        from .sweep import missing_levels

        miss = missing_levels(read, spec.sweep, spec.reference_sensor)
        if miss:
            raise SceneFormatError(spec.source, miss[0].split(" ")[0],
                                   f"no query tour of {spec.sweep.field} {miss[0].split(' ', 1)[1][1:-1]} in {where}")
    return read, {**mapping, "tour": mname}


def _check_detector_inputs(spec: ExperimentSpec, queries: dict, mapping: dict) -> None:
    """Before anything is written: a detector that sees images has RGB where it looks in every
    rendered tour (their meta.json), and its model knows the classes of a ground-truth map."""
    det = spec.detector
    if det["kind"] == "oracle":
        return
    from ..config import Config
    from ..detection.base import check_rgb_schedule

    detector = open_detector(det, None)
    stride = Config.from_dict(spec.config).observation.stride
    for t in {t["dir"]: t for t in queries.values()}.values():  # once per tour, whatever the sensors
        tour = Tour(t["dir"])
        check_rgb_schedule(tour, stride, detector, "observation.stride")
        for m in registry.active(spec.methods, spec.tables):  # the methods that look at every k-th frame
            if m.stride_key:
                check_rgb_schedule(tour, getattr(spec, m.stride_key), detector, m.stride_key)
    mtour = Tour(mapping["dir"])
    if spec.map == "ground-truth":
        open_detector(det, {b["class"] for b in mtour.objects()["boxes"]})
    else:
        check_rgb_schedule(mtour, None, detector, "mapping")


# ---------------------------------------------------------------------------------------------
# the experiment


def _pool(workers: int):
    if workers <= 1:
        return None
    # spawn: Open3D and OpenCV keep thread pools that a fork would copy mid-state; the workers die with
    # the driver and leave Ctrl-C to it (vrformats.lifetime)
    return cf.ProcessPoolExecutor(max_workers=workers, mp_context=mp.get_context("spawn"), initializer=worker_init,
                                  initargs=(os.getpid(),))


class _Runner:
    """Runs tasks in a process pool (or inline), with dependencies and a progress bar."""

    def __init__(self, workers: int, progress: bool, total: int, desc: str):
        from tqdm import tqdm

        self.pool = _pool(workers)
        self.bar = tqdm(total=total, desc=terminal_safe(desc), unit="task", file=sys.stderr, disable=not progress)
        self.failed: dict[str, str] = {}
        self.seconds: dict[str, float] = {}

    def run(self, tasks: list[tuple[str, callable, dict, list[str]]]) -> None:
        """tasks: (id, function, argument, ids it waits for). A task whose dependency failed is skipped."""
        waiting = list(tasks)
        done: set[str] = set()
        running: dict = {}

        def ready():
            nonlocal waiting
            keep = []
            for t in waiting:
                if any(x in self.failed for x in t[3]):
                    self.failed[t[0]] = "skipped: " + next(x for x in t[3] if x in self.failed) + " failed"
                    self.bar.update(1)
                elif all(x in done for x in t[3]):
                    yield t
                else:
                    keep.append(t)
            waiting = keep

        try:
            while waiting or running:
                for tid, fn, arg, _ in list(ready()):
                    if self.pool is None:
                        self._finish(tid, lambda: fn(arg), done)
                    else:
                        running[self.pool.submit(fn, arg)] = tid
                if not running:
                    continue
                finished, _ = cf.wait(running, return_when=cf.FIRST_COMPLETED)
                for f in finished:
                    self._finish(running.pop(f), f.result, done)
        except BaseException:  # Ctrl-C, SIGTERM, SIGHUP (vrformats.lifetime) or a bug: stop the workers now
            self.abort()
            raise

    def abort(self) -> None:
        """Cancel what has not started and stop the workers (SIGTERM, then SIGKILL after 3 s): a task cut
        short leaves nothing half-written (every output is renamed into place) and reruns next time."""
        if self.pool is None:
            return
        procs = list((getattr(self.pool, "_processes", None) or {}).values())
        self.pool.shutdown(wait=False, cancel_futures=True)
        stop_processes(procs)
        self.pool = None

    def _finish(self, tid, get, done) -> None:
        try:
            r = get()
            self.seconds[tid] = r["seconds"]
            done.add(tid)
        except Exception as e:  # one failure must not lose the others (a BrokenProcessPool is a RuntimeError)
            msg = str(e) if isinstance(e, UserError) else f"{type(e).__name__}: {e}"
            self.failed[tid] = msg.splitlines()[0] if msg else type(e).__name__
        self.bar.update(1)

    def close(self) -> None:
        self.bar.close()
        if self.pool is not None:
            self.pool.shutdown()


def check_not_a_render_folder(out: Path, what: str = "the experiment") -> None:
    """Results written among a render job's tours would mix two kinds of folder: refused, one line.

    The folder that holds a rendered design (``design.json``) and every tour folder (and below) are
    refused; a folder of its own inside the design's folder is not (``make demo`` writes the
    experiment to ``out/demo/experiment``, beside the tours)."""
    out = Path(out)
    if (out / DESIGN_FILE).is_file():
        raise UserError(f"{out}: holds a rendered design ({DESIGN_FILE}); write {what} into another folder")
    for d in (out, *out.parents):
        if (d / META_FILE).is_file() and (d / POSES_FILE).is_file():
            raise UserError(f"{out}: lies inside a rendered tour ({d}); write {what} into another folder")


def run_experiment(spec: ExperimentSpec, out: Path | None = None, workers: int | None = None,
                   progress: bool = True, plots: bool = True) -> dict:
    """Maps, every method on every query tour, evaluation, tables, plots and the report."""
    t_start = time.time()
    out = Path(out or spec.out)
    check_output_folder(out)
    lock = folder_lock(out, "reloc experiment")
    try:
        return _run_experiment(spec, out, workers, progress, plots, t_start, lock)
    finally:
        lock.release()


def _run_experiment(spec: ExperimentSpec, out: Path, workers: int | None, progress: bool, plots: bool,
                    t_start: float, lock) -> dict:
    workers = workers or spec.workers
    queries, mapping = design_tours(spec)
    _check_detector_inputs(spec, queries, mapping)
    check_not_a_render_folder(out)
    lock.acquire()  # one experiment per folder; made and locked only once the inputs are known to be good
    out.mkdir(parents=True, exist_ok=True)
    maps_dir = out / "maps"
    maps_dir.mkdir(exist_ok=True)

    # 1. maps from the mapping tour, once per sensor a map is read through
    map_tasks = []
    map_sensors = list(dict.fromkeys(spec.map_sensor_of(s) for s in spec.sensor_names))
    map_files = {ms: _map_files(spec, maps_dir, ms) for ms in map_sensors}
    kinds = {k: registry.map_kind(k) for k in registry.map_names(spec.methods)}
    options = {k: mk.options(spec) for k, mk in kinds.items()}
    model_key = file_key(spec.detector["model"]) if spec.detector.get("model") else None
    code = code_fingerprint()  # every key below holds it: a change of the code recomputes
    for ms, files in map_files.items():
        for kind, f in files.items():
            mk = kinds[kind]
            source = det = None
            if mk.spec_map:  # built with a detector, or the mapping tour's ground truth (map: ground-truth)
                source = ground_truth_key(mapping["dir"]) if spec.map == "ground-truth" else spec.map
                det = None if spec.map == "ground-truth" else mk.detector(spec)
            sensor_key = None if spec.map == "ground-truth" and mk.spec_map else _sensor_key(spec, ms)
            key = key_of(kind, file_key(Path(mapping["dir"]) / "poses.txt"), mapping, source, options[kind], code,
                       det, model_key if det is spec.detector else None, sensor_key)
            try:
                done = read_json(f.with_name(f.name + ".done.json")).get("key") == key and f.is_file()
            except (SceneFormatError, OSError, ValueError):
                done = False
            if not done:
                f.parent.mkdir(parents=True, exist_ok=True)
                map_tasks.append((f"map/{kind}" + ("" if ms == "ideal" else f"@{ms}"), run_map_task,
                                  {"kind": mk.builds_as or kind, "file": str(f), "tour": mapping["dir"],
                                   "source": spec.map, "detector": det, "options": options[kind], "key": key,
                                   "code": code, "sensor": spec.sensor(ms)["spec"], "sensor_seed": spec.seed,
                                   "module": mk.module}, []))
    runner = _Runner(workers, progress, len(map_tasks), f"{spec.name}: maps")
    try:
        runner.run(map_tasks)
    finally:
        runner.close()
    if runner.failed:
        raise UserError("map building failed: " + "; ".join(f"{k}: {v}" for k, v in runner.failed.items()))
    map_seconds = dict(runner.seconds)

    # 2. every method on every query tour (read through every sensor)
    map_keys = {ms: {k: file_key(f) for k, f in files.items()} for ms, files in map_files.items()}
    tour_keys = {n: file_key(Path(t["dir"]) / "poses.txt") + file_key(Path(t["dir"]) / "meta.json")
                 + json.dumps(t, sort_keys=True) + json.dumps(_sensor_key(spec, t["sensor"]), sort_keys=True)
                 for n, t in queries.items()}
    tasks = []
    expected: dict[tuple[str, str], tuple[Path, str]] = {}
    methods = list(spec.methods)
    variants = [v for v in ABLATIONS if v != (True, True, True)] if "ablation" in spec.tables else []
    ablated = registry.table_method("ablation")  # the method whose variants Table IV compares (VideoReloc)
    for name, t in queries.items():
        ms = spec.map_sensor_of(t["sensor"])
        files = map_files[ms]
        common = {"map": str(files["boxes"]), "config": spec.config, "detector": spec.detector, "model": model_key,
                  "seed": spec.seed, "code": code, "sensor": spec.sensor(t["sensor"])["spec"]}

        def add(method, deps, run_as, uses="boxes", **kw) -> str:
            d = out / "runs" / method / name
            arg = {**common, "method": method, "tour": t["dir"], "tour_name": name, "dir": str(d), **kw}
            arg["key"] = key_of(arg, map_keys[ms][uses], tour_keys[name])
            arg.update(runs_as=run_as.name, module=run_as.module)  # which registered method runs it (not in the key)
            expected[(method, name)] = (d, arg["key"])
            if not is_done(d, arg["key"]):
                tasks.append((f"{method}/{name}", run_tour_task, arg, [x for x in deps if x in scheduled]))
                scheduled.add(f"{method}/{name}")
            return arg["key"]

        scheduled: set[str] = set()
        keys: dict[str, str] = {}
        for m in registry.active(methods, spec.tables):  # in registration order: a method before its controls
            kw = m.task_args(spec, files)
            deps = []
            if m.clips_from is not None:  # the controls reuse that method's clips: their key holds its key,
                deps = [f"{m.clips_from}/{name}"]  # so they rerun with it
                kw.update(clips=str(out / "runs" / m.clips_from / name), vr=keys.get(m.clips_from))
            keys[m.name] = add(m.name, deps, m, uses=m.uses, **kw)
        for v in variants:
            add(ablation_name(v), [], ablated, variant=list(v))
    if spec.externals:
        _external_tasks(spec, out, mapping, queries, tour_keys, tasks, expected, progress)
    files = map_files[spec.map_sensor_of(spec.reference_sensor)]
    runner = _Runner(workers, progress, len(tasks), f"{spec.name}: runs")
    try:
        runner.run(tasks)
    finally:
        runner.close()
    run_seconds = dict(runner.seconds)

    # 3. evaluation, tables, plots, report
    # only results whose done marker holds the current key count; a failed or stale run has no poses
    valid = {mt for mt, (d, key) in expected.items() if is_done(d, key)}
    results = tables.evaluate_experiment(spec, out, queries, files, methods, variants, valid, map_files=map_files)
    results["seconds"] = _seconds(out, queries, methods, variants, files)
    results["seconds"]["this_run_wall"] = round(time.time() - t_start, 1)
    results["failed"] = runner.failed
    results["degenerate_frames"] = _degenerate_frames(out, queries, methods)
    results["code"] = code
    from vrformats.environment import environment

    results["environment"] = environment()  # the commit, machine and libraries the report names
    ran = {"maps": map_seconds, "runs": run_seconds}
    if spec.replicates > 1:  # the same experiment reseeded, each in its own folder; their spread beside the intervals
        reps = [results]
        for k in range(1, spec.replicates):
            r = run_experiment(replicate_spec(spec, k), out=out / "replicates" / f"r{k}", workers=workers,
                               progress=progress, plots=False)
            for part in ("maps", "runs"):
                ran[part].update({f"r{k}/{name}": v for name, v in r["_ran"][part].items()})
            results["failed"].update({f"r{k}/{name}": v for name, v in r["failed"].items()})
            reps.append(r)
        results["replicates"] = tables.replicate_summary(reps, [replicate_spec(spec, k) for k in range(spec.replicates)])
        results["seconds"]["this_run_wall"] = round(time.time() - t_start, 1)
    write_json_atomic(out / "results.json", results)
    tables.write_tables(results, out)
    if plots:
        from .plots import plot_experiment
        from .report import write_report

        plot_experiment(out)
        write_report(out)
    results["_ran"] = ran
    return results


def _external_tasks(spec: ExperimentSpec, out: Path, mapping: dict, queries: dict, tour_keys: dict, tasks: list,
                    expected: dict, progress: bool) -> None:
    """Exports (now, in this process: once per format, tour and sensor, cached), then a ``map_command``
    task per external method that has one (and map sensor) and a run task per method and query tour
    (``external.py``). A command reads exports of the tour read through the query's sensor; a folder
    of trajectories holds one file per query reading (``{tour}`` is ``TOUR@SENSOR`` beside ideal)."""
    from .external import export_dir, fill_path, prepare_exports, run_external_map_task, run_external_task

    mtour = mapping["tour"]
    mappings = {reading_name(mtour, ms): {**mapping, "sensor": ms}
                for ms in dict.fromkeys(spec.map_sensor_of(s) for s in spec.sensor_names)}
    sensors = {n: (spec.sensor(n)["spec"] if n != "ideal" else None) for n in
               {t["sensor"] for t in list(queries.values()) + list(mappings.values())}}
    export_keys = prepare_exports(out, list(spec.externals), mappings, queries, progress, sensors=sensors,
                                  sensor_seed=spec.seed, mapping_of=lambda t: reading_name(mtour, spec.map_sensor_of(t["sensor"])))
    for m in spec.externals:
        md = m.to_dict()
        map_keys: dict = {}
        map_ids: dict = {}
        for mname in mappings:
            if not (m.kind == "command" and m.map_command):
                continue
            ms = mappings[mname]["sensor"]
            suffix = "" if ms == "ideal" else f"@{ms}"
            map_out = out / "maps" / (m.name + suffix)
            map_keys[mname] = key_of("external-map", md, export_keys[(m.export, str(m.exposure), mname)])
            map_ids[mname] = f"map/{m.name}{suffix}"
            done = out / "maps" / f"{m.name}{suffix}.done.json"
            try:
                fresh = read_json(done).get("key") == map_keys[mname]
            except (SceneFormatError, OSError, ValueError):
                fresh = False
            if not fresh:
                tasks.append((map_ids[mname], run_external_map_task, {"method": md, "dir": str(map_out),
                                                                      "key": map_keys[mname],
                                                                      "mapping": str(export_dir(out, m, mname))}, []))
            else:
                map_ids[mname] = None
        for name, t in queries.items():
            d = out / "runs" / m.name / name
            arg = {"method": md, "tour": t["dir"], "tour_name": name, "dir": str(d), "code": None}
            mname = reading_name(mtour, spec.map_sensor_of(t["sensor"]))
            map_id = map_ids.get(mname)
            if m.kind == "command":
                ms = mappings[mname]["sensor"]
                map_out = out / "maps" / (m.name + ("" if ms == "ideal" else f"@{ms}")) if m.map_command else None
                arg.update(mapping_export=str(export_dir(out, m, mname)), query_export=str(export_dir(out, m, name)),
                           scene=str(out / "exports" / export_dir(out, m, name).parent.name / "scenes" / name),
                           map_out=str(map_out) if map_out else None)
                inputs = (export_keys[(m.export, str(m.exposure), mname)], export_keys[(m.export, str(m.exposure), name)],
                          map_keys.get(mname))
            else:
                f = Path(m.trajectories) / fill_path(m.file, {"tour": name, "name": m.name})
                names = None
                if m.names:
                    names = file_key(Path(m.names) / "export.json" if Path(m.names).is_dir() else m.names,
                                     missing="missing")
                inputs = (file_key(f, missing="missing"), names)
            arg["key"] = key_of("external", md, inputs, tour_keys[name])
            expected[(m.name, name)] = (d, arg["key"])
            if not is_done(d, arg["key"]):
                tasks.append((f"{m.name}/{name}", run_external_task, arg, [map_id] if map_id else []))


def _map_files(spec: ExperimentSpec, maps_dir: Path, sensor: str) -> dict[str, Path]:
    """The map files of one map sensor (every map kind its methods need, ``methods.map_names``):
    ``maps/`` for the ideal sensor, ``maps/SENSOR/`` for another."""
    d = maps_dir if sensor == "ideal" else maps_dir / sensor
    return {k: d / registry.map_kind(k).file for k in registry.map_names(spec.methods)}


def _sensor_key(spec: ExperimentSpec, name: str) -> dict | None:
    """What a result depends on in the sensor it was read through (None: the ideal sensor)."""
    s = spec.sensor(name)
    return None if name == "ideal" else {"name": name, "params": s["params"], "seed": spec.seed}


def _degenerate_frames(out: Path, queries: dict, methods: list) -> dict:
    """Per query tour with any, its degenerate frames as VideoReloc's run counted them (``run.json``:
    no usable depth, no RGB where the detector reads it; ``reloc.backend.run.Degenerate``)."""
    found: dict = {}
    for m in registry.clip_methods(methods):
        for name in queries:
            try:
                dg = read_json(out / "runs" / m / name / "run.json").get("degenerate_frames")
            except (SceneFormatError, OSError, ValueError):
                continue
            if dg and dg.get("frames") and name not in found:
                found[name] = dg
    return found


def _seconds(out: Path, queries: dict, methods: list, variants: list, files: dict) -> dict:
    """Compute time of each method summed over tours (from the done markers), and of each map."""
    s: dict = {}
    for kind, f in files.items():
        try:
            s[f"map_{kind}"] = read_json(f.with_name(f.name + ".done.json"))["seconds"]
        except (SceneFormatError, OSError, ValueError, KeyError):
            s[f"map_{kind}"] = None
    for m in list(methods) + [ablation_name(v) for v in variants]:
        tot = 0.0
        for name in queries:
            try:
                tot += read_json(out / "runs" / m / name / DONE)["seconds"]
            except (SceneFormatError, OSError, ValueError, KeyError):
                tot = math.nan
        s[m] = None if math.isnan(tot) else round(tot, 1)
    return s


# ---------------------------------------------------------------------------------------------
# CLI


def cmd_experiment(args) -> int:
    spec = load_experiment(args.spec)
    if args.tours:
        spec.tours_root = Path(args.tours)
    r = run_experiment(spec, out=Path(args.out) if args.out else None, workers=args.workers,
                       progress=not args.quiet, plots=not args.no_plots)
    out = Path(args.out or spec.out)
    print(tables.format_all(out))
    ran = r["_ran"]
    print(f"\n{len(ran['runs'])} runs and {len(ran['maps'])} maps computed now "
          f"({r['seconds']['this_run_wall']:.0f} s wall); results, tables"
          f"{', plots and report' if not args.no_plots else ''} in {out}")
    for name, dg in (r.get("degenerate_frames") or {}).items():
        print(f"note: {name}: {dg['frames']} degenerate frame(s) ({dg['no_usable_depth']} without usable depth, "
              f"{dg['no_rgb']} without RGB), first {', '.join(map(str, dg['first'][:5]))}", file=sys.stderr)
    if r["failed"]:
        for k, v in r["failed"].items():
            print(f"failed: {k}: {v}", file=sys.stderr)
        return 1
    return 0


def register_cli(subparsers) -> None:
    p = subparsers.add_parser("experiment", help="VideoReloc and the baselines over a rendered design: tables, plots, report")
    p.add_argument("spec", metavar="SPEC.yaml", help="experiment spec (see reloc/experiments/spec.py), or a shipped name "
                   "(reloc/specs: demo_experiment, ...)")
    p.add_argument("--out", help="results folder (default: the spec's out)")
    p.add_argument("--tours", help="folder of the rendered tours (default: the render spec's out)")
    add_workers(p, "processes", default=None)
    p.add_argument("--no-plots", action="store_true", help="tables only")
    add_quiet(p)
    p.set_defaults(fn=cmd_experiment)
