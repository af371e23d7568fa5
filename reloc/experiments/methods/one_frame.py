"""The one-frame object-based localization unit (``one_frame.causal``, every ``one_frame_stride``-th
frame, one registration each) against VideoReloc's box map; with ``tables: [units]`` it also runs
the longer units of Table III (:mod:`reloc.experiments.localization_units`)."""

from __future__ import annotations

from vrformats.atomic import write_json_atomic
from vrformats.camera import write_tum

from .common import config_of, detector_for, load_map, unit_file
from .registry import Method, Row, register


def task_args(spec, files) -> dict:
    from ..localization_units import DEFAULT_LENGTHS

    return {"stride": spec.one_frame_stride, "lengths": list(DEFAULT_LENGTHS if "units" in spec.tables else (1,))}


def run_one_frame(task: dict, tour, d) -> dict:
    from ..localization_units import run_units

    cfg = config_of(task["config"])
    bmap = load_map("boxes", task["map"], cfg.map)
    lengths = tuple(task["lengths"])
    est: dict = {}
    rep = run_units(tour, bmap, lengths=lengths, detector=detector_for(task["detector"], tour, bmap, cfg),
                    cfg=cfg, one_frame_stride=task["stride"], seed=task["seed"],
                    progress=False, estimates=est)
    one = est.get(1, {})
    fr = sorted(one)
    write_tum(d / "causal.txt", [one[i] for i in fr], fps=tour.fps, frames=fr,
              header=f"one-frame object units on every {task['stride']}th frame of {tour.root}")
    for L in lengths:  # each longer unit's poses, for Table III's intervals (unit_file)
        if L > 1:
            e = est.get(L, {})
            fr = sorted(e)
            write_tum(d / unit_file(L), [e[i] for i in fr], fps=tour.fps, frames=fr,
                      header=f"{L}-frame clip units, each registered independently, of {tour.root}")
    write_json_atomic(d / "units.json", rep)
    return {}


def evaluated_frames(mode: str, frames: list, rgb_every: int, stride: int) -> list:
    return frames[::stride]


register(Method(
    "one_frame", "One-frame object unit", rows=(Row("causal", "One-frame object unit", order=20),),
    run=run_one_frame, primary="causal", maps=("boxes",), uses="boxes", task_args=task_args,
    frames=evaluated_frames, stride_key="one_frame_stride", tables=("units",), runs_for_tables=True, default=True,
))
