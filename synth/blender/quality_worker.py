"""Render one view under many Cycles settings in this (fresh) Blender process, for the
quality-versus-time benchmark (``synth.render.quality``): ``python -m synth.blender.quality_worker JOB.json``.

A job is a JSON file::

    {"layout": "<layout file>", "lighting": "<preset name or file>", "pose": [[4x4 camera-to-world]],
     "intrinsics": {...}, "seed": 0, "device": "cpu", "threads": 0, "out_dir": "<where images go>",
     "base": {<the Cycles settings every setting starts from>},
     "settings": [{"name": "...", "cycles": {<preset keys replaced>}, "extra": {<scene.cycles attributes>}}, ...]}

The scene is built once; a one-sample render first loads the kernels and builds the BVH (not
timed). Then each setting is rendered, fewest samples first (so that each image is the one a fresh
process would render: see ``run``), and written to ``out_dir/<k>.npy`` (linear RGB, float32), with an
event ``{"event": "frame", "frame": k, "seconds": s, "cpu": c}`` (as a render chunk's, so that
``synth.render.chunks.run_chunk_process`` runs it). Settings whose image exists are
skipped, so a killed run resumes where it stopped.
"""

from __future__ import annotations

import os
import shutil
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from vrformats.atomic import replacing

from ..render.chunks import emit, worker_main

# scene.cycles attributes a setting may change beyond the quality presets' keys (``extra``)
EXTRA_ATTRIBUTES = ("use_light_tree", "sample_clamp_direct", "sample_clamp_indirect", "caustics_reflective",
                    "caustics_refractive", "blur_glossy", "use_guiding")


def run(job: dict) -> int:
    import bpy

    from vrformats.camera import Intrinsics

    from ..render.meshes import layout_parts
    from ..scene.lighting import load_lighting, resolve_lighting
    from ..scene.model import load_layout
    from . import scene_builder as sb
    from .worker import read_blender_exr

    out = Path(job["out_dir"])
    out.mkdir(parents=True, exist_ok=True)
    todo = [k for k in range(len(job["settings"])) if not (out / f"{k}.npy").exists()]
    emit(event="start", blender=bpy.app.version_string, settings=len(job["settings"]), todo=len(todo))
    if not todo:
        return 0
    t0 = time.time()
    layout = load_layout(job["layout"])
    scene = sb.reset_scene()
    emitters = sb.add_parts(scene, layout_parts(layout), with_materials=True)
    cam = sb.set_camera(scene, Intrinsics.from_dict(job["intrinsics"]))
    device = sb.choose_device(scene, job.get("device", "cpu"))
    if int(job.get("threads") or 0) > 0:
        scene.render.threads_mode = "FIXED"
        scene.render.threads = int(job["threads"])
    base = dict(job["base"])
    seed = int(job.get("seed", 0))
    sb.configure_rgb(scene, base, seed)
    sb.add_lighting(scene, resolve_lighting(load_lighting(job["lighting"]), layout), emitters)
    sb.place_camera(cam, np.asarray(job["pose"], dtype=np.float64))
    defaults = {a: getattr(scene.cycles, a) for a in EXTRA_ATTRIBUTES}
    tmpdir = tempfile.mkdtemp(prefix="synth_quality_")
    tmp_exr = os.path.join(tmpdir, "render.exr")
    sb.configure_output(scene, tmp_exr)

    def render(cycles: dict, extra: dict) -> tuple[np.ndarray, float, float]:
        unknown = set(extra) - set(EXTRA_ATTRIBUTES)
        if unknown:
            raise ValueError(f"unknown Cycles attribute(s) {sorted(unknown)}; known: {', '.join(EXTRA_ATTRIBUTES)}")
        sb.configure_rgb(scene, {**base, **cycles}, seed)
        for a, v in defaults.items():
            setattr(scene.cycles, a, extra.get(a, v))
        t, c = time.time(), time.process_time()
        bpy.ops.render.render(write_still=True)
        sec, cpu = time.time() - t, time.process_time() - c
        return read_blender_exr(tmp_exr)["Combined"][..., :3].astype(np.float32), sec, cpu

    try:
        render({"samples": 1, "denoise": False}, {})  # kernels and BVH: not timed
        emit(event="ready", device=device, setup={"scene_and_kernels": round(time.time() - t0, 3)})
        # fewest samples first: with persistent data Cycles keeps the sampling pattern sized for the most
        # samples rendered so far, so a setting rendered after a larger one would get other (equally
        # valid) noise than in a fresh process; in this order each image is the one a fresh render gives
        for k in sorted(todo, key=lambda k: int({**base, **(job["settings"][k].get("cycles") or {})}["samples"])):
            s = job["settings"][k]
            img, sec, cpu = render(s.get("cycles") or {}, s.get("extra") or {})
            with replacing(out / f"{k}.npy") as tmp:
                with open(tmp, "wb") as f:
                    np.save(f, img)
            emit(event="frame", frame=k, seconds=round(sec, 4), cpu=round(cpu, 4))  # one image: setting k
    finally:
        shutil.rmtree(tmpdir, ignore_errors=True)
    return 0


def main(argv=None) -> int:
    return worker_main("synth.blender.quality_worker", run, argv)


if __name__ == "__main__":
    sys.exit(main())
