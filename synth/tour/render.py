"""``synth tour render``: one tour (a layout x a lighting x a camera path) into a tour directory. No bpy here.

This is the tour's side of rendering: what to render (``prepare``), the tour's static files and
meta.json (also written by a render job, ``synth.jobs``), and rendering its passes. The renderer's
pieces it drives (chunks of frames in worker processes, the fast renderer, quality settings) are
``synth.render``.

Tour directory (documented in docs/conventions.md, "The tour folder")::

    TOUR/camera.json  poses.txt  objects.json  meta.json  frames/NNNNNN.exr  [previews/NNNNNN.png]

With the Blender renderer the geometry passes (depth, instance, semantic) are rendered once per
layout + path + camera into a shared cache (``<tour parent>/_geometry/<key>/``) and every lighting
takes them from there; the RGB pass runs per lighting. With the fast renderer (Open3D) a tour has
geometry only. Work is cut into chunks of frames, each rendered by a fresh Blender process
(``synth.blender.worker``); frames that already exist are skipped, so re-running a killed render
finishes it without re-rendering anything. Every file appears only once complete.
"""

from __future__ import annotations

import hashlib
import json
import os
import platform
import shutil
import tempfile
import time
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np

from vrformats.fields import size_problem, terminal_safe
from vrformats import frames as fr
from vrformats.atomic import replacing, write_json_atomic
from vrformats.camera import Intrinsics, camera_document, write_tum
from vrformats.tour import CAMERA_FILE
from vrformats.errors import UserError, check_output_folder
from vrformats.lifetime import folder_lock

from ..version import __version__
from ..render.chunks import chunk_job, missing_frames, run_chunk_process, split, stopping_workers
from ..render.settings import DEFAULTS, DEVICES, cycles_overrides, quality, resolve_quality
from ..scene.model import boxes_document, load_layout, resolve_layout_path


class RenderError(UserError):
    """A chunk failed to render; the message names the chunk's log file."""


@dataclass
class TourSpec:
    layout: str  # layout name or file
    path: str  # camera path name or file
    out: str  # tour directory
    lighting: str | None = None  # preset name or file; None = geometry only
    renderer: str = DEFAULTS.renderer  # blender | fast
    quality: str = DEFAULTS.quality
    width: int = DEFAULTS.width
    height: int = DEFAULTS.height
    hfov_deg: float = DEFAULTS.hfov_deg
    frames: int | None = None  # the first N frames of the path (default: all)
    seed: int = DEFAULTS.seed
    device: str = DEFAULTS.device  # cpu | gpu | auto
    previews: bool = DEFAULTS.previews
    chunk_size: int = DEFAULTS.chunk_size
    workers: int = 1
    threads: int = 0  # Cycles threads per worker (0 = all)
    cycles: dict | None = None  # settings of the quality preset replaced (synth.render.settings.cycles_overrides)
    geometry_cache: str | None = None  # default: <out parent>/_geometry
    # refuse a path whose declared clearance the layout breaks (layouts the path was not planned
    # on only; synth.paths.clearance.render_clearance_problem); False: --allow-clearance-breach
    check_clearance: bool = True


@dataclass
class Prepared:
    spec: TourSpec
    layout_file: Path
    layout_name: str
    path_name: str
    path_fps: float
    poses: np.ndarray
    frame_ids: list[int]
    intr: Intrinsics
    out: Path
    geometry_dir: Path | None
    lighting_name: str | None
    extra: dict = field(default_factory=dict)


def make_output_folder(d: Path) -> None:
    """Create the output folder ``d`` and prove a file can be written in it (a one-line UserError if not)."""
    try:
        d.mkdir(parents=True, exist_ok=True)
        with tempfile.NamedTemporaryFile(dir=d, prefix=".write_test_"):
            pass
    except OSError as e:
        raise UserError(f"cannot write to output folder {d}: {e.strerror or e}") from None


def _hash(*chunks: bytes) -> str:
    h = hashlib.sha256()
    for c in chunks:
        h.update(c)
        h.update(b"\0")
    return h.hexdigest()[:10]


def prepare(spec: TourSpec, create: bool = True) -> Prepared:
    """Validate everything before anything is written; raise a UserError naming what is wrong.

    With ``create`` the output and geometry-cache folders are created (and proven writable)."""
    from ..paths.files import load_path
    from ..scene.lighting import load_lighting

    if spec.renderer not in ("blender", "fast"):
        raise UserError(f"unknown renderer '{spec.renderer}'; use blender or fast")
    if spec.device not in DEVICES:
        raise UserError(f"unknown device '{spec.device}'; use one of {', '.join(DEVICES)}")
    quality(spec.quality)
    cycles_overrides("the tour's settings", spec.cycles)
    if spec.width <= 0 or spec.height <= 0:
        raise UserError(f"image size must be positive, got {spec.width}x{spec.height}")
    too_large = size_problem(spec.width, spec.height)
    if too_large:
        raise UserError(f"image size {too_large}")
    if spec.renderer == "blender":
        from ..blender import require_python

        require_python()
    from vrformats.native import import_open3d

    import_open3d()  # geometry and clearance need it: a missing system library is one line, before any file
    if spec.chunk_size <= 0 or spec.workers <= 0:
        raise UserError("chunk size and workers must be positive")
    layout_file = resolve_layout_path(spec.layout)
    layout = load_layout(layout_file)
    lighting_name = None
    if spec.lighting is not None:
        if spec.renderer == "fast":
            raise UserError("the fast renderer makes geometry only (depth, instance, semantic); drop --lighting or use --renderer blender")
        lighting_name = load_lighting(spec.lighting).name
    cpath = load_path(spec.path)
    n = len(cpath.poses)
    if n == 0:
        raise UserError(f"camera path '{spec.path}' has no poses")
    if spec.frames is not None:
        if spec.frames <= 0:
            raise UserError(f"--frames must be positive, got {spec.frames}")
        if spec.frames > n:
            raise UserError(f"--frames {spec.frames} exceeds the {n} frames of camera path '{cpath.name}'")
        n = spec.frames
    if spec.check_clearance:
        from ..paths.clearance import render_clearance_problem

        why = render_clearance_problem(cpath, layout, layout_file, spec.layout, n)
        if why:
            raise UserError(why)
    out = Path(spec.out)
    (make_output_folder if create else check_output_folder)(out)
    intr = Intrinsics.from_fov(spec.width, spec.height, spec.hfov_deg)
    poses = cpath.poses[:n]
    geometry_dir = None
    if spec.renderer == "blender":
        root = Path(spec.geometry_cache) if spec.geometry_cache else out.parent / "_geometry"
        key = _hash(layout_file.read_bytes(), np.ascontiguousarray(poses, dtype=np.float64).tobytes(),
                    json.dumps(intr.to_dict(), sort_keys=True).encode())
        geometry_dir = root / f"{layout.name}__{cpath.name}__{spec.width}x{spec.height}__{key}"
        (make_output_folder if create else check_output_folder)(geometry_dir)
    return Prepared(spec, layout_file, layout.name, cpath.name, cpath.fps, poses, list(range(n)), intr, out,
                    geometry_dir, lighting_name, {"path_meta": cpath.meta})


def write_static_files(p: Prepared) -> None:
    """camera.json, poses.txt, objects.json (atomically; identical on every re-run)."""
    write_json_atomic(p.out / CAMERA_FILE, camera_document(p.intr, p.path_fps, p.spec.hfov_deg), indent=1)
    write_tum(p.out / "poses.txt", p.poses, fps=p.path_fps, frames=p.frame_ids,
              header=f"camera-to-world poses (OpenCV camera axes) of path '{p.path_name}'\nt tx ty tz qx qy qz qw, t = frame / {p.path_fps:g}")
    write_json_atomic(p.out / "objects.json", boxes_document(load_layout(p.layout_file)), indent=1)


def package_versions() -> dict:
    from importlib import metadata

    out = {"synth": __version__, "python": platform.python_version()}
    for pkg in ("numpy", "open3d", "trimesh", "OpenEXR", "bpy", "scipy"):
        try:
            out[pkg] = metadata.version(pkg)
        except metadata.PackageNotFoundError:
            pass
    return out


def tour_meta(p: Prepared, *, renderer: str, seed: int, settings: dict, blender: str | None = None, **extra) -> dict:
    """meta.json of a tour, whichever command rendered it (``synth tour render`` or a render job):
    what was rendered and how, then ``extra`` (a job's name, a single tour's timing). Paths inside
    the tour are relative to it, so a tour folder can be moved."""
    return {
        "toolkit": package_versions(),
        "blender": blender,
        "layout": p.layout_name,
        "layout_file": str(p.layout_file),
        "lighting": p.lighting_name,
        "path": p.path_name,
        "renderer": renderer,
        "seed": seed,
        "settings": settings,
        "frames": [p.frame_ids[0], p.frame_ids[-1]],
        "n_frames": len(p.frame_ids),
        "geometry_cache": os.path.relpath(p.geometry_dir, p.out) if p.geometry_dir else None,
        "complete": not missing_frames(p.out / "frames", p.frame_ids),
        **extra,
    }


class _Progress:
    """frames done/total, frames/s and ETA on a tqdm bar."""

    def __init__(self, total: int, desc: str, enabled: bool):
        from tqdm import tqdm

        self.bar = tqdm(total=total, desc=terminal_safe(desc), unit="frame", disable=not enabled, dynamic_ncols=True)

    def frame(self, n: int = 1) -> None:
        self.bar.update(n)

    def close(self) -> None:
        self.bar.close()


def _render_pass(p: Prepared, kind: str, out_dir: Path, work: Path, desc: str, progress: bool) -> tuple[dict, int]:
    """Render the frames of one pass (geometry or rgb) that ``out_dir`` lacks, in chunks, each in a
    fresh worker process (``synth.render.chunks``), ``spec.workers`` at a time.

    Returns (worker info, frames rendered); raises RenderError naming the log of a failed chunk
    after the other chunks finished."""
    import threading
    from concurrent.futures import ThreadPoolExecutor

    todo = missing_frames(out_dir, p.frame_ids)
    if not todo:
        return {}, 0
    work.mkdir(parents=True, exist_ok=True)
    bar = _Progress(len(p.frame_ids), desc, progress)
    bar.frame(len(p.frame_ids) - len(todo))
    lock = threading.Lock()

    def on_frame(_ev):
        with lock:
            bar.frame()

    def one(k_frames):
        k, frames = k_frames
        jf, log = work / f"{kind}_{k:05d}.json", work / f"{kind}_{k:05d}.log"
        job = chunk_job(p, kind, frames, out_dir)
        return run_chunk_process(kind, job, str(jf), str(log), on_frame) + (log,)

    try:
        with ThreadPoolExecutor(max_workers=p.spec.workers) as pool, stopping_workers(pool):
            results = list(pool.map(one, enumerate(split(todo, p.spec.chunk_size))))
    finally:
        bar.close()
    info: dict = {}
    failed = []
    for rc, err, inf, log in results:
        info.update(inf)
        if rc != 0:
            failed.append((err, log))
    if failed:
        err, log = failed[0]
        raise RenderError(f"{len(failed)} chunk(s) failed; first: {err} (log: {log})")
    return info, len(todo)


def render_tour(spec: TourSpec, progress: bool = True) -> dict:
    """Render (or finish rendering) one tour; returns its meta.json content. One run per tour folder
    (``vrformats.lifetime.folder_lock``)."""
    t0 = time.time()
    p = prepare(spec)
    with folder_lock(p.out, "synth tour render"):
        return _render_prepared(spec, p, progress, t0)


def _render_prepared(spec: TourSpec, p, progress: bool, t0: float) -> dict:
    write_static_files(p)
    frames_dir = p.out / "frames"
    frames_dir.mkdir(parents=True, exist_ok=True)
    info: dict = {}
    geometry_rendered = 0
    if spec.renderer == "fast":
        from ..render.fast_render import FastRenderer

        todo = missing_frames(frames_dir, p.frame_ids)
        bar = _Progress(len(p.frame_ids), f"{p.layout_name} geometry (fast)", progress)
        bar.frame(len(p.frame_ids) - len(todo))
        if todo:
            r = FastRenderer(load_layout(p.layout_file))
            for i in todo:
                d, ins, sem = r.render(p.poses[i], p.intr)
                fr.write_frame(frames_dir / fr.frame_name(i), depth=d, instance=ins, semantic=sem)
                bar.frame()
        bar.close()
        geometry_rendered = len(todo)
    else:
        gdir = p.geometry_dir
        work = Path(tempfile.mkdtemp(prefix=".jobs_", dir=p.out))
        ok = False
        try:
            inf, geometry_rendered = _render_pass(p, "geometry", gdir, work, f"{p.layout_name} geometry", progress)
            info.update(inf)
            if p.lighting_name is None:  # geometry-only tour: the cached frames are the tour's frames
                for i in missing_frames(frames_dir, p.frame_ids):
                    src, dst = gdir / fr.frame_name(i), frames_dir / fr.frame_name(i)
                    with replacing(dst) as tmp:
                        shutil.copyfile(src, tmp)
            else:
                inf, _ = _render_pass(p, "rgb", frames_dir, work, f"{p.layout_name} {p.lighting_name} rgb", progress)
                info.update(inf)
            ok = True
        finally:
            if ok:  # a failed chunk's job and log stay for the user to read
                shutil.rmtree(work, ignore_errors=True)
    meta = tour_meta(
        p, renderer=spec.renderer, seed=spec.seed, blender=info.get("blender"),
        settings={**asdict(spec), "quality_settings": resolve_quality(spec.quality, spec.cycles) if spec.lighting else None},
        device=info.get("device", "CPU" if spec.renderer == "blender" else None),
        geometry_frames_rendered_now=geometry_rendered, wall_time_s=round(time.time() - t0, 3),
        host={"platform": platform.platform(), "cpus": os.cpu_count()},
    )
    write_json_atomic(p.out / "meta.json", meta, indent=1)
    if spec.previews:  # the Blender worker previews its RGB frames; the fast renderer's and the geometry frames' here
        from .show import write_previews

        write_previews(p.out)
    return meta
