"""``synth render SPEC``: a render job from the command line, and its dry run (the plan, a
calibration render and the estimates, locally or on a Ray cluster of a given shape)."""

from __future__ import annotations

import dataclasses
import os
import sys
from pathlib import Path

from vrformats.atomic import write_json_atomic
from vrformats.errors import UserError, check_output_file
from vrformats.cli import add_quiet, add_workers, bounded_int

from .calibration import estimate, measure_calibration
from .estimate import fmt_duration
from .plan import describe, expand
from .runner import job_folder, run_job
from .spec import JobSpec, load_spec


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
    out, store = job_folder(spec, args.out, args.backend)
    with tempfile.TemporaryDirectory(prefix="synth_dry_run_") as tmp:  # a dry run leaves nothing behind
        from ..sources import spec_source

        scene_source = spec_source(spec)
        if scene_source is not None:
            spec = scene_source.prepare(spec, Path(tmp), args.replicacad_root, progress=lambda m: print(m, file=sys.stderr))
        if store is None:
            plan = expand(spec, out, check_clearance=not args.allow_clearance_breach, check_light=True)
        else:  # what is still to render is read from the storage
            plan = expand(spec, Path(tmp).resolve() / "job", check_clearance=not args.allow_clearance_breach,
                          check_light=True)
            plan.use_storage(store)
        work = ce.plan_work(plan)
        if cal is not None:
            ce.check_fits(cal, spec, work, args.calibration)
        print(describe(plan))
        for w in plan.warnings:
            print(f"  WARNING: {w}")
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
    here = os.cpu_count() or 1
    if where != "measured here" and str(cal.get("device", "cpu")).lower() != "cpu":
        print(f"  no estimate for this machine: the calibration was measured on {cal.get('device')} (measure one "
              "here without --calibration)")
    else:
        # a calibration from a file is one process on its machine's cores: scaled to this machine's
        # cores (rendering scales about linearly with them), and said so
        scale = 1.0 if where == "measured here" else float(cal.get("cpu_count") or here) / here
        eta = estimate(plan, {k: v * scale for k, v in per.items()}, args.workers, setup=ce.setup_seconds(cal))
        how = "" if scale == 1.0 else f", the file's {cal.get('cpu_count')}-CPU figures x {scale:g} for {here} CPUs"
        print(f"  estimate with {args.workers} worker(s): {fmt_duration(eta)} on this machine "
              f"({here} CPUs{how}); on a Ray cluster: --nodes N --cpus-per-node C")
    if clusters:
        link = float(args.link_gbps) if args.link_gbps is not None else ce.DEFAULT_LINK_GBPS
        best = [ce.estimate_cluster(work, cal, c, "longest", link_gbps=link) for c in clusters]
        driver = [ce.estimate_cluster(work, cal, c, "plan", link_gbps=link) for c in clusters]
        print("  " + ce.describe_estimate(best, cal, where, plan_order=driver).replace("\n", "\n  "))
        if clusters[0].gpus_per_node and spec.device == "cpu":
            print("  note: the spec says device: cpu, so its chunks would not ask Ray for GPUs: set device: gpu (or auto) "
                  "to render on them")
    return 0


def with_overrides(spec, args):
    """``spec`` with the render settings given on the command line (``--seed``, ``--threads``,
    ``--cycles KEY=VALUE``) in place of its own; the job folder records them (a resume needs the same)."""
    import dataclasses

    from vrformats.yamlfile import safe_load
    from ..render.settings import cycles_overrides

    changes = {}
    if args.seed is not None:
        changes["seed"] = args.seed
    if args.threads is not None:
        changes["threads"] = args.threads
    if args.cycles:
        d = dict(spec.cycles or {})
        for item in args.cycles:
            key, eq, value = item.partition("=")
            if not eq or not key:
                raise UserError(f"--cycles {item}: expected KEY=VALUE (e.g. denoise_prefilter=ACCURATE)")
            try:
                d[key] = safe_load(value)  # 16 -> 16, true -> True, ACCURATE -> 'ACCURATE'
            except Exception:  # noqa: BLE001 - not a YAML scalar: the text itself, refused below if it is wrong
                d[key] = value
        if spec.renderer != "blender":
            raise UserError("--cycles: the fast renderer has no Cycles settings")
        changes["cycles"] = cycles_overrides("--cycles", d, field=None)
    return dataclasses.replace(spec, **changes) if changes else spec


def cmd_render(args) -> int:
    cluster = _cluster_args(args)  # bad options are refused before anything is read or rendered
    spec = with_overrides(load_spec(args.spec), args)
    if args.replicacad_root and spec.replicacad is None:
        raise UserError(f"--replicacad-root: {args.spec} has no replicacad: section (its layouts are not ReplicaCAD scenes)")
    if args.paths_from:
        if spec.replicacad is None:
            raise UserError(f"--paths-from: {args.spec} has no replicacad: section (its paths are not planned by the job)")
        spec = dataclasses.replace(spec, replicacad={**spec.replicacad, "paths_from": args.paths_from})
    if args.dry_run:
        return _dry_run(args, spec, cluster)
    s = run_job(spec, args.out, workers=args.workers, backend=args.backend,
                ray_address=args.ray_address, ray_runtime_env=args.ray_runtime_env, resume=args.resume, progress=not args.quiet,
                allow_clearance_breach=args.allow_clearance_breach, replicacad_root=args.replicacad_root,
                check_light=True, geometry_from=args.geometry_from)
    failed = (f", {s['frames_failed']} frames failed in {s['chunks_failed']} chunk(s)" if s["chunks_failed"] else "")
    print(f"{s['job']}: {s['tours']} tours, {s['frames_rendered_now']} frames rendered{failed} in {s['wall_time_s']:.1f} s "
          f"({s['frames_per_s']} frames/s), chunks {s['chunks']} -> {s['out']}")
    for cid, err in s["failed"].items():
        print(f"  FAILED {cid}: {err}", file=sys.stderr)
    return 1 if s["failed"] else 0


def register_cli(subparsers) -> None:
    a = subparsers.add_parser("render", help="render a job spec: every tour of its design")
    a.add_argument("spec", help="job spec YAML, or the name of a shipped one (render_jobs: demo, smoke, ...)")
    a.add_argument("--out", help="the job folder (default: the spec's out): a path, or with --backend ray a storage URI "
                   "(file://, memory://, or another fsspec scheme: the driver writes the job there; docs/cluster.md)")
    add_workers(a, "chunks rendered (local backend)")
    a.add_argument("--backend", choices=["local", "ray"], default="local")
    a.add_argument("--ray-address", help="address of a running Ray cluster, HOST:PORT (default: start a local one on loopback)")
    a.add_argument("--ray-runtime-env", choices=["auto", "full", "code", "none"], default="auto",
                   help="what the Ray nodes get from the driver: full (the toolkit's checkout, code and data, as the working_dir, "
                        "and its pip requirements pinned to the driver's versions), code (only the working_dir), none "
                        "(installed on every node); auto: full with --ray-address, else none (docs/cluster.md)")
    a.add_argument("--resume", action="store_true", help="finish a job that was stopped; renders only what is missing")
    g = a.add_argument_group("render settings in place of the spec's (recorded in the job folder; a --resume needs the same)")
    g.add_argument("--seed", type=bounded_int(2**31 - 1, lo=0), metavar="N", help="Cycles seed")
    g.add_argument("--threads", type=bounded_int(256, lo=0), metavar="N", help="Cycles threads per worker (0: all cores)")
    g.add_argument("--cycles", action="append", metavar="KEY=VALUE",
                   help="a setting of the quality preset, e.g. denoise_prefilter=ACCURATE or samples=16 (repeat for several)")
    g.add_argument("--geometry-from", metavar="JOBDIR",
                   help="hard-link the geometry caches of another job folder of the same design, so that only RGB renders")
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
    a.add_argument("--paths-from", metavar="OUT",
                   help="for a spec with a replicacad: section: reuse the camera paths another job planned (its output "
                        "folder) instead of planning them, e.g. the same path on another stage variant")
    add_quiet(a)
    a.set_defaults(fn=cmd_render)
