"""Planning at scale: the wall time of a job's plan on a Ray cluster, from a calibration render.

``synth render SPEC --dry-run --nodes N[,N...] --cpus-per-node C [--gpus-per-node G]`` (``synth.jobs.cli``)
prints the estimate; everything here but ``measure_environment`` is pure (plan work + calibration +
cluster shape -> figures), so the tests check it against schedules worked out by hand.

The model (every assumption is printed with the estimate, ``describe_estimate``):

- **Calibration**: seconds per frame of each pass kind (``geometry``, ``rgb``, ``fast``), measured by
  one chunk process that uses every core of the calibration machine (``cpu_count`` cores; Cycles
  and Open3D's ray caster both start one thread per core). The first frame of a calibration chunk
  (kernel loading) is left out. ``--save-calibration FILE`` writes it; ``--calibration FILE`` reads
  one measured elsewhere, e.g. on a GPU node.
- **Core-seconds per frame**: the CPU time the calibration process spent per frame over all its
  threads (``cpu_seconds_per_frame``). Unlike wall time it is not inflated when other jobs share the
  calibration machine. A calibration without it falls back to ``seconds_per_frame * cpu_count``.
- **A CPU node** with ``C`` cores runs ``K`` chunks at a time (Ray's ``--num-cpus`` of the node;
  the docs advise ``K = 1`` for Blender jobs) and each chunk gets ``C / K`` cores: a frame takes
  ``core-seconds / (C / K)`` seconds, i.e. rendering scales linearly with cores (an optimistic
  assumption: per-frame scene updates, memory bandwidth and denoising scale less).
- **A GPU node** runs one chunk per GPU (the Ray task asks for one GPU). A kind calibrated on a GPU
  takes the calibration's time per frame as it is: each GPU of the cluster is assumed to be as fast
  as the calibration's. There is no CPU-to-GPU factor: a GPU estimate needs a GPU calibration.
  Kinds calibrated on the CPU (the fast renderer) get ``C / G`` cores each, as on a CPU node.
- **Start-up**: each chunk pays a fixed start-up (a fresh Blender or Python process, the scene built,
  the first frame's kernel loading), not scaled with cores: the calibration's ``startup_s``, measured
  on its chunk (its wall time less its frames at the steady rate), else ``SETUP_S``.
- **Scheduling**: list scheduling of the chunks on the ``N * K`` (``N * G``) slots: whenever a slot
  is free it takes the ready chunk of highest priority; an ``rgb`` chunk is ready once its
  ``geometry`` chunk has finished. Priority ``longest``: the longest path to the end of the job
  first (a chunk's own time plus its longest dependent), which for independent chunks is the
  classic longest-processing-time-first rule; ``plan``: the plan's order, which is what the Ray
  driver does today (``synth.jobs.chunk_queue.ChunkQueue`` hands out ready chunks in plan order).
- ``copy`` chunks (the frames between RGB frames with ``rgb_every``) run on the driver (hard links
  to the geometry cache) and take no node time.
- **The driver's link**: every rendered frame comes home to the driver, and an ``rgb`` chunk takes
  the geometry frames it reads with it; with the frame sizes of the calibration render, the bytes
  through the driver's network link at ``link_gbps`` give a second floor on the wall time.

Not modelled: Ray installing the runtime environment on a node's first task (minutes with
``--ray-runtime-env full``), retries, node failures and stragglers, the driver's disk.
"""

from __future__ import annotations

import heapq
from dataclasses import dataclass
from pathlib import Path

from vrformats import fields
from vrformats.errors import SceneFormatError, UserError
from vrformats.yamlfile import read_json

SETUP_S = {"geometry": 3.0, "rgb": 4.0, "fast": 1.0}  # start-up per chunk (a fresh process, the scene built)
RENDER_KINDS = ("geometry", "rgb", "fast")  # kinds rendered on the nodes; copy runs on the driver
BLENDER_KINDS = ("geometry", "rgb")
CALIBRATION_FORMAT = "synth-calibration"
CALIBRATION_VERSION = 1
DEFAULT_LINK_GBPS = 1.0


@dataclass(frozen=True)
class Work:
    """One chunk to schedule: its kind, frames still to render, and the chunk it waits for."""

    id: str
    kind: str
    frames: int
    needs: str | None = None


@dataclass(frozen=True)
class Cluster:
    nodes: int
    cpus_per_node: int
    gpus_per_node: int = 0
    chunks_per_node: int = 1  # CPU nodes: chunks at a time (the node's ray start --num-cpus)

    @property
    def slots_per_node(self) -> int:
        return self.gpus_per_node if self.gpus_per_node else self.chunks_per_node

    @property
    def slots(self) -> int:
        return self.nodes * self.slots_per_node


def plan_work(plan, missing_only: bool = True) -> list[Work]:
    """The chunks of a ``synth.jobs.plan.Plan`` as ``Work`` (only the frames still missing by default; a
    chunk with none left is dropped and counts as done for the chunks that wait for it)."""
    out = []
    for c in plan.chunks:
        n = len(c.missing()) if missing_only else len(c.frames)
        if n:
            out.append(Work(c.id, c.kind, n, c.needs))
    return out


# ---------------------------------------------------------------------------------------------
# the cluster's shape


def parse_count(text, option: str, allow_zero: bool = False) -> int:
    """A count given on the command line; a UserError naming the option otherwise."""
    try:
        v = int(str(text).strip())
    except ValueError:
        v = None
    if v is None or v < 0 or (v == 0 and not allow_zero):
        kind = "a non-negative" if allow_zero else "a positive"
        raise UserError(f"{option}: expected {kind} integer, got {text!r}")
    return v


def parse_nodes(text) -> list[int]:
    """``--nodes 8`` or ``--nodes 1,8,32``."""
    parts = str(text).split(",")
    try:
        return [parse_count(p, "--nodes") for p in parts]
    except UserError:
        raise UserError(f"--nodes: expected positive integers (8, or 1,8,32), got {text!r}") from None


# ---------------------------------------------------------------------------------------------
# the calibration document


def _seconds_by_kind(source: str, doc: dict, field: str, spf: dict, what: str, zero_ok: bool) -> None:
    """An optional mapping of pass kind (one of ``seconds_per_frame``'s) to seconds (positive, or with
    ``zero_ok`` non-negative)."""
    d = doc.get(field, {})
    if not isinstance(d, dict):
        fields.fail(source, field, f"expected a mapping of pass kind to {what}, got {d!r}")
    for k, v in d.items():
        if k not in spf:
            fields.fail(source, f"{field}.{k}", "a pass kind without seconds_per_frame")
        if not fields.is_number(v) or (v < 0 if zero_ok else v <= 0):
            fields.fail(source, f"{field}.{k}", f"expected a {'non-negative' if zero_ok else 'positive'} number of seconds, got {v!r}")


def validate_calibration(doc, source: str) -> dict:
    """Check a calibration document (``--calibration FILE``); a SceneFormatError (a UserError) names the
    file and the field."""
    if not isinstance(doc, dict):
        raise UserError(f"{source}: expected a JSON object (a file written by --save-calibration)")
    if doc.get("format") != CALIBRATION_FORMAT:
        fields.fail(source, "format", f"expected {CALIBRATION_FORMAT!r}, got {doc.get('format')!r}")
    if doc.get("version") != CALIBRATION_VERSION:
        fields.fail(source, "version", f"expected {CALIBRATION_VERSION}, got {doc.get('version')!r}")
    spf = doc.get("seconds_per_frame")
    if not isinstance(spf, dict) or not spf:
        fields.fail(source, "seconds_per_frame", f"expected a mapping of pass kind to seconds, got {spf!r}")
    for k, v in spf.items():
        if k not in RENDER_KINDS:
            fields.fail(source, f"seconds_per_frame.{k}", f"unknown pass kind; known: {', '.join(RENDER_KINDS)}")
        if not fields.is_number(v) or v <= 0:
            fields.fail(source, f"seconds_per_frame.{k}", f"expected a positive number of seconds, got {v!r}")
    _seconds_by_kind(source, doc, "cpu_seconds_per_frame", spf, "CPU seconds", zero_ok=False)
    bpf = doc.get("bytes_per_frame", {})
    if not isinstance(bpf, dict):
        fields.fail(source, "bytes_per_frame", f"expected a mapping of pass kind to bytes, got {bpf!r}")
    for k, v in bpf.items():
        if k not in RENDER_KINDS or not fields.is_number(v) or v < 0:
            fields.fail(source, f"bytes_per_frame.{k}", f"expected a known pass kind and a non-negative number, got {v!r}")
    fields.positive_int(source, doc.get("cpu_count"), "cpu_count")
    dev = doc.get("device")
    if not isinstance(dev, str) or not dev:
        fields.fail(source, "device", f"expected the device rendered on (CPU, OPTIX, CUDA, ...), got {dev!r}")
    devs = doc.get("devices", {})
    if not isinstance(devs, dict) or not all(isinstance(v, str) and v for v in devs.values()):
        fields.fail(source, "devices", f"expected a mapping of pass kind to device, got {devs!r}")
    for k in devs:
        if k not in spf:
            fields.fail(source, f"devices.{k}", "a pass kind without seconds_per_frame")
    _seconds_by_kind(source, doc, "startup_s", spf, "seconds", zero_ok=True)
    spec = doc.get("spec")
    if not isinstance(spec, dict):
        fields.fail(source, "spec", f"expected a mapping (quality, width, height, ...), got {spec!r}")
    if not isinstance(spec.get("quality"), str):
        fields.fail(source, "spec.quality", f"expected a quality preset name, got {spec.get('quality')!r}")
    for k in ("width", "height"):
        fields.positive_int(source, spec.get(k), f"spec.{k}")
    for k in ("date", "toolkit_version"):
        if not isinstance(doc.get(k), str) or not doc.get(k):
            fields.fail(source, k, f"expected a string, got {doc.get(k)!r}")
    return doc


def load_calibration(path) -> dict:
    p = Path(path)
    if not p.is_file():
        raise UserError(f"--calibration {p}: no such file")
    try:
        doc = read_json(p, expect_object=False)  # validate_calibration says what a calibration holds
    except SceneFormatError as e:
        if e.field is None:  # it could not be read at all
            raise UserError(f"--calibration {p}: {e.message}") from None
        raise UserError(f"{p}: not a JSON calibration file ({e.field}: {e.message})") from None
    return validate_calibration(doc, str(p))


def check_fits(cal: dict, spec, work: list[Work], source: str) -> None:
    """The calibration was measured at the spec's quality and size and covers the plan's pass kinds."""
    s = cal["spec"]
    if s["quality"] != spec.quality:
        fields.fail(source, "spec.quality", f"measured at quality {s['quality']!r}, the spec renders at {spec.quality!r}")
    if (s["width"], s["height"]) != (spec.width, spec.height):
        fields.fail(source, "spec.width", f"measured at {s['width']}x{s['height']}, the spec renders at {spec.width}x{spec.height}")
    for k in sorted({w.kind for w in work if w.kind in RENDER_KINDS}):
        if k not in cal["seconds_per_frame"]:
            fields.fail(source, f"seconds_per_frame.{k}", f"missing; the plan has {k} chunks")


def is_gpu(device: str | None) -> bool:
    return bool(device) and device.upper() != "CPU"


def kind_device(cal: dict, kind: str) -> str:
    """The device a kind was calibrated on (``devices``, else ``device`` for Blender kinds, CPU for fast)."""
    devs = cal.get("devices") or {}
    if kind in devs:
        return devs[kind]
    return cal["device"] if kind in BLENDER_KINDS else "CPU"


def has_gpu_kinds(cal: dict) -> bool:
    return any(is_gpu(kind_device(cal, k)) for k in cal["seconds_per_frame"])


# ---------------------------------------------------------------------------------------------
# the schedule


def chunk_seconds(w: Work, cal: dict, cluster: Cluster, setup: dict | None = None) -> float:
    """Seconds one chunk takes on one slot of a node of ``cluster`` (start-up included)."""
    setup = setup_seconds(cal) if setup is None else setup
    return setup.get(w.kind, 0.0) + frame_seconds(w.kind, cal, cluster) * w.frames


def core_seconds(kind: str, cal: dict) -> tuple[float, str]:
    """Core-seconds per frame of a CPU kind, and where they come from: the CPU time the calibration
    process spent (over all its threads), else its wall time times the calibration's cores."""
    cps = (cal.get("cpu_seconds_per_frame") or {}).get(kind)
    if cps is not None:
        return float(cps), "cpu"
    return float(cal["seconds_per_frame"][kind]) * cal["cpu_count"], "wall"


def frame_seconds(kind: str, cal: dict, cluster: Cluster) -> float:
    """Seconds per frame of one chunk of ``kind`` on a node of ``cluster``."""
    if cluster.gpus_per_node and is_gpu(kind_device(cal, kind)):
        return float(cal["seconds_per_frame"][kind])  # one GPU per chunk, as fast as the calibration's
    cores = cluster.cpus_per_node / cluster.slots_per_node
    return core_seconds(kind, cal)[0] / cores


def list_schedule(durations: dict, needs: dict, slots: int, priority: list) -> dict:
    """List scheduling: whenever a slot is free (the earliest first, then the lowest index) it takes
    the first chunk of ``priority`` whose prerequisite (``needs[id]``, absent or not in ``durations``:
    done before) has finished; with none ready it waits for the next chunk to finish.

    Returns id -> (start, end, slot)."""
    if slots <= 0:
        raise ValueError("slots must be positive")
    free = [(0.0, s) for s in range(slots)]  # (free from, slot)
    heapq.heapify(free)
    out: dict = {}
    todo = list(priority)
    while todo:
        t, s = heapq.heappop(free)
        pick = None
        for k, cid in enumerate(todo):
            dep = needs.get(cid)
            if dep is None or dep not in durations or (dep in out and out[dep][1] <= t):
                pick = k
                break
        if pick is None:  # nothing ready: wait for the next chunk to finish
            later = [e for _, e, _ in out.values() if e > t]
            if not later:
                raise ValueError(f"chunk {todo[0]} waits for a chunk that is never scheduled")
            heapq.heappush(free, (min(later), s))
            continue
        cid = todo.pop(pick)
        end = t + durations[cid]
        out[cid] = (t, end, s)
        heapq.heappush(free, (end, s))
    return out


def priority_order(work: list[Work], durations: dict, order: str) -> list[str]:
    ids = [w.id for w in work]
    if order == "plan":
        return ids
    if order != "longest":
        raise ValueError(f"unknown order {order!r}")
    children: dict[str, list[str]] = {}
    for w in work:
        if w.needs in durations:
            children.setdefault(w.needs, []).append(w.id)
    level: dict[str, float] = {}

    def bottom(cid: str) -> float:  # the chunk's time plus its longest chain of dependents
        if cid not in level:
            level[cid] = durations[cid] + max((bottom(k) for k in children.get(cid, [])), default=0.0)
        return level[cid]

    index = {cid: k for k, cid in enumerate(ids)}
    return sorted(ids, key=lambda cid: (-bottom(cid), index[cid]))


def estimate_cluster(work: list[Work], cal: dict, cluster: Cluster, order: str = "longest",
                     setup: dict | None = None, link_gbps: float | None = DEFAULT_LINK_GBPS) -> dict:
    """The figures of one cluster shape: makespan (s), node-hours, utilisation, lower bound, and the
    data through the driver's link. Pure: no clock, no disk."""
    if cluster.nodes <= 0 or cluster.cpus_per_node <= 0 or cluster.gpus_per_node < 0 or cluster.chunks_per_node <= 0:
        raise ValueError(f"bad cluster shape {cluster}")
    nodes_work = [w for w in work if w.kind in RENDER_KINDS]
    durations = {w.id: chunk_seconds(w, cal, cluster, setup) for w in nodes_work}
    needs = {w.id: w.needs for w in nodes_work}
    sched = list_schedule(durations, needs, cluster.slots, priority_order(nodes_work, durations, order))
    makespan = max((e for _, e, _ in sched.values()), default=0.0)
    total = sum(durations.values())
    k = cluster.slots_per_node
    busy = [0.0] * cluster.nodes
    for cid, (s, e, slot) in sched.items():
        busy[slot // k] += e - s
    chain = max((durations[w.id] + (durations.get(w.needs, 0.0)) for w in nodes_work), default=0.0)
    longest = max(durations.values(), default=0.0)
    lower = max(total / cluster.slots, longest, chain)
    bpf = cal.get("bytes_per_frame") or {}
    home = sum(w.frames * bpf.get(w.kind, 0.0) for w in nodes_work)
    geo_kind = next((w.kind for w in nodes_work if w.kind in ("geometry", "fast") and w.kind in bpf), None)
    out_bytes = sum(w.frames * bpf.get(geo_kind, 0.0) for w in nodes_work if w.kind == "rgb") if geo_kind else 0.0
    link_s = (home + out_bytes) * 8 / (link_gbps * 1e9) if link_gbps and bpf else None
    cap = makespan * k
    return {
        "nodes": cluster.nodes, "cpus_per_node": cluster.cpus_per_node, "gpus_per_node": cluster.gpus_per_node,
        "chunks_per_node": cluster.chunks_per_node, "slots": cluster.slots, "order": order,
        "chunks": len(nodes_work), "frames": sum(w.frames for w in nodes_work),
        "copy_frames": sum(w.frames for w in work if w.kind == "copy"),
        "work_s": total, "makespan_s": makespan, "node_hours": cluster.nodes * makespan / 3600.0,
        "busy_node_hours": total / 3600.0,
        "busiest_node_utilisation": max(busy) / cap if cap > 0 else 0.0,
        "mean_utilisation": total / (cluster.slots * makespan) if makespan > 0 else 0.0,
        "lower_bound_s": lower, "lower_bound": {"work_per_slot_s": total / cluster.slots, "longest_chunk_s": longest,
                                                 "longest_chain_s": chain},
        "bytes_home": home, "bytes_out": out_bytes, "link_gbps": link_gbps, "link_s": link_s,
        "wall_s": max(makespan, link_s or 0.0),
        "chunk_seconds": {kind: sorted({round(durations[w.id], 3) for w in nodes_work if w.kind == kind})
                          for kind in sorted({w.kind for w in nodes_work})},
    }


# ---------------------------------------------------------------------------------------------
# printing


def fmt_duration(s: float) -> str:
    if s < 120:
        return f"{s:.0f} s"
    if s < 7200:
        return f"{s / 60:.1f} min"
    if s < 2 * 86400:
        return f"{s / 3600:.1f} h"
    return f"{s / 86400:.1f} days"


def _gb(b: float) -> str:
    return f"{b / 1e9:.1f} GB"


def describe_calibration(cal: dict, where: str) -> str:
    s = cal["spec"]
    cps = cal.get("cpu_seconds_per_frame") or {}
    kinds = ", ".join(f"{k} {v:.3f}" + (f" (CPU {cps[k]:.3f})" if k in cps else "") for k, v in cal["seconds_per_frame"].items())
    devs = ", ".join(f"{k} on {kind_device(cal, k)}" for k in cal["seconds_per_frame"])
    extra = []
    if cal.get("cpu_model"):
        extra.append(cal["cpu_model"])
    if cal.get("load_avg") is not None:
        extra.append(f"load average {cal['load_avg']} while measuring")
    if cal.get("gpus"):
        extra.append("GPUs: " + ", ".join(cal["gpus"]))
    return (f"calibration ({where}, {cal['date']}, toolkit {cal['toolkit_version']}): s/frame {kinds} "
            f"({devs}; one process, {cal['cpu_count']} CPUs{'; ' + '; '.join(extra) if extra else ''}; "
            f"{s['quality']}, {s['width']}x{s['height']}{', tour ' + cal['tour'] if cal.get('tour') else ''})")


def setup_seconds(cal: dict) -> dict:
    """Start-up per chunk kind: the calibration's measured ``startup_s`` where it has one, else ``SETUP_S``."""
    return {**SETUP_S, **(cal.get("startup_s") or {})}


def describe_estimate(results: list[dict], cal: dict, where: str, setup: dict | None = None,
                      plan_order: list[dict] | None = None) -> str:
    """The assumptions, then a table: one row per cluster shape."""
    measured = set(cal.get("startup_s") or {}) if setup is None else set()
    setup = setup_seconds(cal) if setup is None else setup
    r0 = results[0]
    gpu = r0["gpus_per_node"] > 0
    k = r0["chunks_per_node"]
    c = r0["cpus_per_node"]
    lines = []
    if gpu:
        lines.append(f"cluster estimate: GPU nodes of {r0['gpus_per_node']} GPU(s) and {c} cores, one chunk per GPU at a time")
    else:
        lines.append(f"cluster estimate: CPU nodes of {c} cores, {k} chunk(s) at a time per node "
                     f"(ray start --num-cpus={k}), {c / k:g} cores per chunk")
    lines.append("  assumptions:")
    lines.append("  - " + describe_calibration(cal, where))
    for kind in sorted({kk for r in results for kk in r["chunk_seconds"]}):
        per = cal["seconds_per_frame"][kind]
        if gpu and is_gpu(kind_device(cal, kind)):
            lines.append(f"  - {kind}: {per:.3f} s/frame on each GPU, as on the calibration's GPU (no CPU-to-GPU factor)")
        else:
            slots = r0["gpus_per_node"] or k
            core, how = core_seconds(kind, cal)
            if how == "cpu":
                src = (f"{core:.3f} core-seconds/frame (the CPU time of the calibration process; its wall time, "
                       f"{per:.3f} s on {cal['cpu_count']} CPUs, is {core / (per * cal['cpu_count']):.0%} of its cores)")
            else:
                src = f"{per:.3f} s/frame x {cal['cpu_count']} CPUs = {core:.3f} core-seconds/frame (no CPU time recorded)"
            lines.append(f"  - {kind}: {src} / {c / slots:g} cores = {core / (c / slots):.3f} s/frame per chunk "
                         f"(rendering scales linearly with cores: optimistic)")
    lines.append("  - start-up per chunk (a fresh process, the scene built, the kernels loaded; not scaled): "
                 + ", ".join(f"{kk} {v:g} s" + (" (measured by the calibration)" if kk in measured else "")
                             for kk, v in setup.items()))
    lines.append("  - list scheduling, longest path first (an rgb chunk starts once its geometry chunk has finished); "
                 "'driver order' is the same in the plan's order, what the Ray driver does today")
    if r0["copy_frames"]:
        lines.append(f"  - copy chunks ({r0['copy_frames']} frames) run on the driver (hard links): no node time")
    lines.append("  - frames still missing in the job folder are counted (all of them for a new job)")
    if r0["link_s"] is not None:
        lines.append(f"  - the driver's link: {_gb(r0['bytes_home'])} of frames come home, {_gb(r0['bytes_out'])} of geometry "
                     f"frames go out with rgb chunks (frame sizes of the calibration render), at {r0['link_gbps']:g} "
                     f"Gbit/s: {fmt_duration(r0['link_s'])}, a floor on the wall time whatever the nodes")
    lines.append("  - not modelled: the runtime environment's install on each node's first task (minutes with "
                 "--ray-runtime-env full), retries, failing or slow nodes, the driver's disk")
    head = f"  {'nodes':>5} {'slots':>5} {'makespan':>10} {'node-hours':>10} {'busiest':>8} {'mean':>6} {'lower bound':>11} {'driver order':>12}"
    lines.append(head)
    for i, r in enumerate(results):
        drv = plan_order[i]["makespan_s"] if plan_order else None
        lines.append(f"  {r['nodes']:>5} {r['slots']:>5} {fmt_duration(r['makespan_s']):>10} {r['node_hours']:>10.1f} "
                     f"{r['busiest_node_utilisation']:>7.0%} {r['mean_utilisation']:>6.0%} "
                     f"{fmt_duration(r['lower_bound_s']):>11} {fmt_duration(drv) if drv is not None else '-':>12}")
    lines.append(f"  ({r0['chunks']} chunks, {r0['frames']} frames on the nodes, {r0['busy_node_hours']:.1f} busy "
                 f"node-hours; busiest: the busiest node's share of the makespan spent rendering; "
                 f"lower bound: max(work / slots, longest chunk, longest geometry + rgb chain))")
    return "\n".join(lines)


# ---------------------------------------------------------------------------------------------
# the machine a calibration is measured on


def measure_environment() -> dict:
    """What a calibration document records about this machine and toolkit (not pure: reads the system)."""
    import datetime
    import os
    import platform
    import subprocess

    from vrformats.environment import cpu_model, git_commit, toolkit_version

    env: dict = {"cpu_count": os.cpu_count() or 1, "platform": platform.platform(),
                 "date": datetime.datetime.now(datetime.timezone.utc).isoformat(timespec="seconds"),
                 "toolkit_version": toolkit_version()}
    commit = git_commit()
    if commit:
        env["toolkit_version"] += f"+g{commit}"
    if cpu_model():
        env["cpu_model"] = cpu_model()
    try:
        r = subprocess.run(["nvidia-smi", "--query-gpu=name", "--format=csv,noheader"], capture_output=True, text=True,
                           timeout=10)
        if r.returncode == 0:
            env["gpus"] = [x.strip() for x in r.stdout.splitlines() if x.strip()]
    except (OSError, subprocess.SubprocessError):
        pass
    return env


class LiveEta:
    """The remaining time of a running local job, from what its frames and chunks cost so far, per pass
    kind: ``sum over kinds (frames left x seconds per frame + chunks not started x start-up) / slots``.

    A kind's seconds per frame is the mean of its frames' own times (what the chunk processes report).
    A kind not timed yet has no price: the cost of an RGB frame against a geometry frame ranges from
    about 1x (preview at 160x120) to over 200x (paper quality), so no ratio would do. ``seconds``
    then gives the time of the timed kinds and ``untimed`` names the others. A chunk's start-up is its
    wall time less its frames' times, ``SETUP_S`` until one has finished. Pure: no clock."""

    def __init__(self, frames_left: dict[str, int], chunks_left: dict[str, int], slots: int):
        self.frames_left = {k: int(v) for k, v in frames_left.items()}
        self.chunks_left = {k: int(v) for k, v in chunks_left.items()}
        self.slots = max(1, int(slots))
        self.timed: dict[str, list[float]] = {}  # kind -> [seconds, frames]
        self.startup: dict[str, list[float]] = {}  # kind -> [seconds, chunks]

    def chunk_started(self, kind: str) -> None:
        self.chunks_left[kind] = max(0, self.chunks_left.get(kind, 0) - 1)

    def frame(self, kind: str, seconds: float | None) -> None:
        self.frames_left[kind] = max(0, self.frames_left.get(kind, 0) - 1)
        if seconds is not None and seconds >= 0:
            t = self.timed.setdefault(kind, [0.0, 0])
            t[0] += float(seconds)
            t[1] += 1

    def chunk_finished(self, kind: str, wall_s: float, frame_s: float) -> None:
        t = self.startup.setdefault(kind, [0.0, 0])
        t[0] += max(0.0, float(wall_s) - float(frame_s))
        t[1] += 1

    def frame_seconds(self, kind: str) -> float | None:
        t = self.timed.get(kind)
        return t[0] / t[1] if t and t[1] else None

    @property
    def untimed(self) -> list[str]:
        """The kinds with frames left that no frame has timed yet."""
        return sorted(k for k, n in self.frames_left.items() if n > 0 and self.frame_seconds(k) is None)

    def seconds(self) -> float | None:
        """Seconds left for the timed kinds' frames and every chunk's start-up (None before any frame was
        timed); the ``untimed`` kinds come on top."""
        if not any(t[1] for t in self.timed.values()):
            return None
        total = sum(n * self.frame_seconds(k) for k, n in self.frames_left.items()
                    if n > 0 and self.frame_seconds(k) is not None)
        for kind, n in self.chunks_left.items():
            t = self.startup.get(kind)
            total += n * (t[0] / t[1] if t and t[1] else SETUP_S.get(kind, 0.0))
        return total / self.slots
