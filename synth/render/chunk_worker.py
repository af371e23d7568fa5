"""Chunks that need no Blender: ``python -m synth.render.chunk_worker JOB.json``.

``fast``: render depth, instance and semantic with the Open3D renderer (``synth.render.fast_render``).
``copy``: copy shared geometry frames (the geometry cache) into a tour (hard links where possible).
Frames already on disk are skipped; progress goes to stdout as JSON lines (``synth.render.chunks``).
"""

from __future__ import annotations

import os
import shutil
import sys
import time
from pathlib import Path

from vrformats import frames as fr
from vrformats.atomic import replacing

from .chunks import emit, worker_main


def run(job: dict) -> int:
    out = Path(job["out_dir"])
    out.mkdir(parents=True, exist_ok=True)
    todo = [int(i) for i in job["frames"] if not (out / fr.frame_name(int(i))).exists()]
    emit(event="start", pass_=job["pass"], frames=len(job["frames"]), todo=len(todo))
    if job["pass"] == "copy":
        src = Path(job["geometry_dir"])
        for i in todo:
            t0, c0 = time.time(), time.process_time()
            dst = out / fr.frame_name(i)
            with replacing(dst) as tmp:
                try:  # a hard link: the same bytes, no second copy on disk
                    os.link(src / fr.frame_name(i), tmp)
                except OSError:  # another file system, or links not supported
                    shutil.copyfile(src / fr.frame_name(i), tmp)
            emit(event="frame", frame=i, seconds=round(time.time() - t0, 4), cpu=round(time.process_time() - c0, 4))
        return 0
    if job["pass"] != "fast":
        raise ValueError(f"unknown pass {job['pass']!r}")
    from vrformats.camera import Intrinsics, read_tum
    from .fast_render import FastRenderer
    from ..scene.model import load_layout

    intr = Intrinsics.from_dict(job["intrinsics"])
    ids, poses = read_tum(job["poses"], fps=float(job.get("fps", 30.0)))
    pose_of = dict(zip(ids.tolist(), poses))
    if todo:
        r = FastRenderer(load_layout(job["layout"]))
        emit(event="ready", device="CPU")
        for i in todo:
            t0, c0 = time.time(), time.process_time()
            d, ins, sem = r.render(pose_of[i], intr)
            fr.write_frame(out / fr.frame_name(i), depth=d, instance=ins, semantic=sem)
            emit(event="frame", frame=i, seconds=round(time.time() - t0, 4), cpu=round(time.process_time() - c0, 4))
    return 0


def main(argv=None) -> int:
    return worker_main("synth.render.chunk_worker", run, argv)


if __name__ == "__main__":
    sys.exit(main())
