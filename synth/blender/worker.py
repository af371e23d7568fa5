"""Render one chunk of frames in this (fresh) Blender process: ``python -m synth.blender.worker JOB.json``.

A job is a JSON file (``synth.render.chunks.chunk_job`` writes it)::

    {"pass": "geometry" | "rgb", "layout": "<layout file>", "lighting": "<preset name or file>",
     "poses": "<TUM file>", "frames": [i, ...], "intrinsics": {...}, "quality": "preview",
     "cycles": null (or settings of the preset replaced), "seed": 0, "device": "cpu", "out_dir": "<where frames go>", "geometry_dir": "<geometry cache>",
     "previews_dir": null, "threads": 0}

The geometry pass writes depth, instance and semantic EXRs into ``out_dir``. The RGB pass renders
linear RGB and writes the tour's frame EXR, taking depth and ids from ``geometry_dir`` (rendered
once per layout and path, shared by every lighting). Frames whose output already exists are
skipped, so a killed chunk resumes where it stopped. Progress goes to stdout as JSON lines:
``{"event": "frame", "frame": i, "seconds": s}``; the first line reports the Blender version.
"""

from __future__ import annotations

import os
import sys
import shutil
import tempfile
import time
from pathlib import Path

import numpy as np

from vrformats import frames as fr
from vrformats.color import srgb8
from vrformats.atomic import replacing

from ..render.chunks import emit, worker_main


def read_blender_exr(path: str) -> dict[str, np.ndarray]:
    """Passes of Blender's multilayer EXR by pass name: {"Combined": (H,W,4), "Depth": (H,W), "IndexOB": (H,W)}."""
    ch = fr.read_channels(path)
    passes: dict[str, dict[str, np.ndarray]] = {}
    for name, arr in ch.items():
        parts = name.split(".")
        pas, comp = (parts[-2], parts[-1]) if len(parts) >= 2 else (parts[0], "")
        passes.setdefault(pas, {})[comp] = arr
    out = {}
    for pas, comps in passes.items():
        if len(comps) == 1:
            out[pas] = next(iter(comps.values()))
        else:
            order = [c for c in "RGBA" if c in comps] or sorted(comps)
            out[pas] = np.stack([comps[c] for c in order], axis=-1)
    return out


def run(job: dict) -> int:
    t_import = time.time()
    import bpy

    stages = {"import_bpy": time.time() - t_import}  # the chunk's start-up, by stage (the ready event reports it)
    clock = [time.time()]

    def lap(name: str) -> None:
        now = time.time()
        stages[name] = stages.get(name, 0.0) + now - clock[0]
        clock[0] = now

    from vrformats.camera import Intrinsics, read_tum
    from ..scene.lighting import load_lighting, resolve_lighting
    from ..render.meshes import instance_classes, layout_parts
    from ..render.settings import resolve_quality
    from ..scene.model import load_layout
    from . import scene_builder as sb

    lap("import_toolkit")
    mode = job["pass"]
    layout = load_layout(job["layout"])
    intr = Intrinsics.from_dict(job["intrinsics"])
    frame_ids, poses = read_tum(job["poses"], fps=float(job.get("fps", 30.0)))
    pose_of = dict(zip(frame_ids.tolist(), poses))
    out_dir = Path(job["out_dir"])
    todo = [int(i) for i in job["frames"] if not (out_dir / fr.frame_name(int(i))).exists()]
    emit(event="start", blender=bpy.app.version_string, pass_=mode, frames=len(job["frames"]), todo=len(todo))
    if not todo:
        return 0
    lap("read_layout")

    scene = sb.reset_scene()
    parts = layout_parts(layout)
    lap("layout_meshes")
    emitters = sb.add_parts(scene, parts, with_materials=(mode == "rgb"))
    lap("blender_scene")
    cam = sb.set_camera(scene, intr)
    device = sb.choose_device(scene, job.get("device", "cpu"))
    threads = int(job.get("threads") or 0)
    if threads > 0:
        scene.render.threads_mode = "FIXED"
        scene.render.threads = threads
    if mode == "geometry":
        sb.configure_geometry(scene)
        lut = np.zeros(4096, np.uint32)
        for iid, sid in instance_classes(layout).items():
            lut[iid] = sid
    else:
        sb.configure_rgb(scene, resolve_quality(job.get("quality", "preview"), job.get("cycles")), int(job.get("seed", 0)))
        sb.add_lighting(scene, resolve_lighting(load_lighting(job["lighting"]), layout), emitters)
        geom_dir = Path(job["geometry_dir"])
        previews = Path(job["previews_dir"]) if job.get("previews_dir") else None
    lap("device_and_lighting")
    emit(event="ready", device=device, parts=len(parts), setup={k: round(v, 3) for k, v in stages.items()})

    tmpdir = tempfile.mkdtemp(prefix="synth_render_")  # removed when the chunk ends (a SIGKILL leaves it to the OS)
    tmp_exr = os.path.join(tmpdir, "render.exr")
    sb.configure_output(scene, tmp_exr)
    try:
        for i in todo:
            t0, c0 = time.time(), time.process_time()
            sb.place_camera(cam, pose_of[i])
            bpy.ops.render.render(write_still=True)
            t_render = time.time() - t0
            p = read_blender_exr(tmp_exr)
            target = out_dir / fr.frame_name(i)
            if mode == "geometry":
                inst = np.rint(p["IndexOB"]).astype(np.uint32)
                depth = p["Depth"].astype(np.float32)
                miss = (inst == 0) | ~np.isfinite(depth) | (depth > 1e5)
                depth[miss] = 0.0
                inst[miss] = 0
                fr.write_frame(target, depth=depth, instance=inst, semantic=lut[np.minimum(inst, len(lut) - 1)])
            else:
                rgb = p["Combined"][..., :3].astype(np.float32)
                g = fr.read_frame(geom_dir / fr.frame_name(i), rgb=False, require=("depth", "instance", "semantic"))
                if previews is not None:
                    import cv2

                    previews.mkdir(parents=True, exist_ok=True)
                    ok, png = cv2.imencode(".png", srgb8(rgb)[..., ::-1])
                    if not ok:
                        raise RuntimeError(f"frame {i}: the preview could not be encoded as PNG")
                    with replacing(previews / f"{i:06d}.png") as tmp:
                        tmp.write_bytes(png.tobytes())
                fr.write_frame(target, rgb=rgb, depth=g.depth, instance=g.instance, semantic=g.semantic)
            emit(event="frame", frame=i, seconds=round(time.time() - t0, 4), cpu=round(time.process_time() - c0, 4),
                 render_s=round(t_render, 4))
    finally:
        shutil.rmtree(tmpdir, ignore_errors=True)
    return 0


def main(argv=None) -> int:
    return worker_main("synth.blender.worker", run, argv)


if __name__ == "__main__":
    sys.exit(main())
