#!/usr/bin/env python3
"""Calibrate the paper's 6x3 designs on a GPU, and check the GPU's frames against the CPU's.

The design's calibration frames (``synth render SPEC --dry-run`` renders them on the CPU) rendered
with Cycles on the GPU, for both apartments (``replicacad_6x3``: the built-in apartment;
``replicacad_apt_6x3``: the ReplicaCAD scenes), every lighting and every quality preset, at the
specs' 640x480. Three steps, so that the GPU machine needs only Blender's worker, not the planner:

    # 1. here: plan the designs and write the render jobs (layouts, poses, lightings; no rendering)
    python tools/gpu_calibration.py prepare PREP --replicacad-root DATASET
    # 2. on the GPU machine (PREP and the dataset files it lists travel with it)
    python tools/gpu_calibration.py run PREP OUT --device gpu [--budget-s S]
    #    and the same frames on the CPU, here, for the comparison (any subset: --only)
    python tools/gpu_calibration.py run PREP CPU_OUT --device cpu --only 'paper/*/day' ...
    # 3. here: the calibration files the dry run reads, and GPU frames against CPU frames
    python tools/gpu_calibration.py report OUT --cpu CPU_OUT --calibration-dir DIR

``run`` renders each job in a fresh worker process (``synth.blender.worker``, as a render chunk),
the geometry pass once per apartment, then RGB per lighting and preset. The first frame of each
job pays for loading the kernels (on a GPU: compiling them, once per machine) and is left out of
the per-frame time, as ``synth.jobs.calibration`` leaves it out. Results are written after every
job, so a run cut short keeps what it measured, and a second run skips what is done.
"""

from __future__ import annotations

import argparse
import fnmatch
import json
import shutil
import statistics
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

SPECS = {"builtin": "replicacad_6x3", "replicacad": "replicacad_apt_6x3"}
PRESETS = ("preview", "standard", "paper")


# ------------------------------------------------------------------------------------------- prepare


def cmd_prepare(args) -> int:
    import tempfile

    from synth.jobs.plan import expand
    from synth.jobs.spec import load_spec
    from synth.sources import spec_source
    from vrformats.camera import write_tum

    prep = Path(args.prep).resolve()
    prep.mkdir(parents=True, exist_ok=True)
    manifest = {"frames": args.frames, "apartments": {}, "dataset_files": []}
    for apt, spec_name in SPECS.items():
        if apt == "replicacad" and not args.replicacad_root:
            print("replicacad: skipped (no --replicacad-root)", file=sys.stderr)
            continue
        spec = load_spec(spec_name)
        d = prep / apt
        d.mkdir(exist_ok=True)
        with tempfile.TemporaryDirectory(prefix="gpu_cal_") as tmp:
            src = spec_source(spec)
            if src is not None:
                spec = src.prepare(spec, d / "scene", args.replicacad_root, progress=lambda m: print(m, file=sys.stderr))
            plan = expand(spec, Path(tmp) / "job")
            tour_name, first = next(iter(plan.tours.items()))  # the tour measure_calibration renders
            tours = [p for p in plan.tours.values() if p.layout_file == first.layout_file and p.path_name == first.path_name
                     and p.lighting_name]
            n = len(first.frame_ids)
            idx = [round(k * (n - 1) / (args.frames + 1)) for k in range(1, args.frames + 1)]  # spread along the path
            layout = d / "layout.yaml"
            shutil.copyfile(first.layout_file, layout)
            write_tum(d / "poses.txt", first.poses[idx], fps=first.path_fps)
            lightings = {}
            for p in tours:
                lt = p.spec.lighting
                if lt and Path(str(lt)).is_file():  # a lighting file: it travels with the jobs
                    dst = d / f"lighting_{Path(lt).name}"
                    shutil.copyfile(lt, dst)
                    lt = dst.name
                lightings[p.lighting_name] = lt
            intr = first.intr.scaled(*args.size) if args.size else first.intr
            manifest["apartments"][apt] = {"spec": spec_name, "tour": tour_name,
                                           "layout": layout.relative_to(prep).as_posix(), "poses": (d / "poses.txt").relative_to(prep).as_posix(),
                                           "path_frames": idx, "fps": first.path_fps, "intrinsics": intr.to_dict(),
                                           "lightings": lightings, "seed": spec.seed, "width": intr.width, "height": intr.height,
                                           "design_quality": spec.quality}
        if apt == "replicacad":
            manifest["dataset_files"] = sorted(set(manifest["dataset_files"]) | set(_dataset_files(layout, args.replicacad_root)))
            manifest["replicacad_root"] = str(Path(args.replicacad_root).resolve())
    (prep / "manifest.json").write_text(json.dumps(manifest, indent=1))
    print(f"{prep}/manifest.json: {len(manifest['apartments'])} apartments, {args.frames} frames each, "
          f"{len(manifest['dataset_files'])} dataset files")
    return 0


def _dataset_files(layout: Path, root: str) -> list[str]:
    """The dataset files (relative to the root) a layout's meshes come from: its stage's and objects'
    GLBs (``replicacad:``) and, for an articulated object (``replicacad-urdf:``), its URDF's folder
    (the meshes it names lie beside it), plus the scene dataset config that marks the root and the
    dataset's licence."""
    from synth.mesh.roots import dataset_config_path
    from synth.scene.model import GLB_ASSET_PREFIX, URDF_ASSET_PREFIX, load_layout

    root = Path(root).resolve()
    lay = load_layout(layout)
    out = {dataset_config_path(root).name} | {f.name for f in root.glob("LICENSE*") if f.is_file()}  # its licence travels too
    for a in [lay.stage.asset] + [o.asset for o in lay.objects]:
        if a and a.startswith(GLB_ASSET_PREFIX):
            out.add(a[len(GLB_ASSET_PREFIX):])
        elif a and a.startswith(URDF_ASSET_PREFIX):
            folder = (root / a[len(URDF_ASSET_PREFIX):]).parent
            out.update(str(f.relative_to(root)) for f in folder.iterdir() if f.is_file())
    return sorted(out)


# ------------------------------------------------------------------------------------------------ run


def job_names(manifest: dict) -> list[tuple[str, str, str | None, str | None]]:
    """(name, apartment, preset, lighting) of every job, geometry first."""
    out = []
    for apt, a in manifest["apartments"].items():
        out.append((f"geometry/{apt}", apt, None, None))
    for preset in ("paper", "preview", "standard"):  # the designs' preset first
        for apt, a in manifest["apartments"].items():
            for lt in a["lightings"]:
                out.append((f"{preset}/{apt}/{lt}", apt, preset, lt))
    return out


def cmd_run(args) -> int:
    prep = Path(args.prep).resolve()
    manifest = json.loads((prep / "manifest.json").read_text())
    out = Path(args.out).resolve()
    out.mkdir(parents=True, exist_ok=True)
    res_file = out / "results.json"
    results = json.loads(res_file.read_text()) if res_file.exists() else {"jobs": {}}
    results.update(machine=_machine(args.device), device_asked=args.device)
    if args.dataset_root and manifest.get("replicacad_root"):
        _relink_dataset(prep, manifest, args.dataset_root)
    t_start = time.time()
    for name, apt, preset, lt in job_names(manifest):
        if args.only and not any(fnmatch.fnmatch(name, pat) or fnmatch.fnmatch(name, pat + "/*") for pat in args.only + ["geometry/*"]):
            continue
        if name in results["jobs"] and results["jobs"][name].get("ok"):
            continue
        if args.budget_s and time.time() - t_start > args.budget_s:
            print(f"budget of {args.budget_s} s spent: {name} and the rest left out", flush=True)
            break
        a = manifest["apartments"][apt]
        geom = out / f"geometry_{apt}"
        # poses.txt holds the path's frames a["path_frames"] in order: frames 0, 1, 2 of the job
        job = {"pass": "geometry" if preset is None else "rgb", "layout": str(prep / a["layout"]), "poses": str(prep / a["poses"]),
               "fps": a["fps"], "frames": [1] if args.middle_only else list(range(len(a["path_frames"]))),
               "intrinsics": a["intrinsics"], "quality": preset or "preview", "cycles": None, "seed": a["seed"], "device": args.device, "geometry_dir": str(geom), "previews_dir": None,
               "threads": 0, "lighting": None if lt is None else _lighting(prep / apt, a["lightings"][lt]),
               "out_dir": str(geom if preset is None else out / f"rgb_{preset}_{apt}_{lt}")}
        jf = out / f"job_{name.replace('/', '_')}.json"
        jf.write_text(json.dumps(job))
        t0 = time.time()
        proc = subprocess.run([sys.executable, "-m", "synth.blender.worker", str(jf)], capture_output=True, text=True, cwd=ROOT)
        wall = time.time() - t0
        evs = [json.loads(x) for x in proc.stdout.splitlines() if x.startswith("{")]
        frames = [e for e in evs if e.get("event") == "frame"]
        ready = next((e for e in evs if e.get("event") == "ready"), {})
        secs = [e["seconds"] for e in frames]
        steady = secs[1:] or secs
        row = {"ok": proc.returncode == 0 and len(frames) == len(job["frames"]), "apartment": apt, "preset": preset,
               "lighting": lt, "kind": job["pass"], "device": ready.get("device"), "wall_s": round(wall, 3),
               "frame_s": [round(s, 4) for s in secs], "median_s_per_frame": round(statistics.median(steady), 4) if steady else None,
               # start-up: the chunk's wall time less its frames at the steady rate (as synth.jobs.calibration)
               "startup_s": round(wall - statistics.median(steady) * len(secs), 3) if secs else None,
               "first_frame_extra_s": round(secs[0] - statistics.median(steady), 3) if len(secs) > 1 else None,
               "setup": ready.get("setup"), "render_s": [e.get("render_s") for e in frames]}
        if not row["ok"]:
            row["error"] = (proc.stderr[-1500:] + proc.stdout[-500:]).strip()
        results["jobs"][name] = row
        res_file.write_text(json.dumps(results, indent=1))
        print(f"{name:<34} {row['device'] or '?':<28} {'ok' if row['ok'] else 'FAILED'} wall {wall:6.1f} s, "
              f"s/frame {row['median_s_per_frame']}, start-up {row['startup_s']}", flush=True)
        if not row["ok"]:
            print(row["error"][-800:], flush=True)
    return 0 if all(r.get("ok") for r in results["jobs"].values()) else 1


def _lighting(d: Path, lt: str) -> str:
    return str(d / lt) if (d / lt).is_file() else lt


def _relink_dataset(prep: Path, manifest: dict, root: str) -> None:
    """The layout names dataset files under the root it was imported from: point it at ``root``."""
    for apt, a in manifest["apartments"].items():
        f = prep / a["layout"]
        t = f.read_text()
        if manifest["replicacad_root"] in t:
            f.write_text(t.replace(manifest["replicacad_root"], str(Path(root).resolve())))
    manifest["replicacad_root"] = str(Path(root).resolve())
    (prep / "manifest.json").write_text(json.dumps(manifest, indent=1))


def _machine(device: str) -> dict:
    """What a calibration records about the machine (synth.jobs.estimate.measure_environment: CPU, GPUs
    by nvidia-smi, date, toolkit version)."""
    from synth.jobs.estimate import measure_environment

    return measure_environment()


# ---------------------------------------------------------------------------------------------- sweep


def cmd_sweep(args) -> int:
    """The quality-versus-time benchmark (``synth bench quality``'s renders and measures) on one view
    of the prepared design: the job's frame 1, in one lighting, at the design's size."""
    from synth.render.quality import run_view, settings_list

    prep = Path(args.prep).resolve()
    manifest = json.loads((prep / "manifest.json").read_text())
    a = manifest["apartments"][args.apartment]
    from vrformats.camera import read_tum

    _, poses = read_tum(prep / a["poses"], fps=a["fps"])
    view = {"name": f"{args.apartment} {args.lighting}", "spec": a["spec"], "layout": str(prep / a["layout"]),
            "lighting": _lighting(prep / args.apartment, a["lightings"][args.lighting]), "lighting_name": args.lighting,
            "pose": poses[1].tolist(), "poses_around": poses.tolist(), "path": "query", "frame": a["path_frames"][1],
            "intrinsics": a["intrinsics"], "seed": a["seed"], "fps": a["fps"]}
    out = Path(args.out).resolve()
    res = run_view(view, settings_list(quick=args.quick, reference_samples=args.reference_samples),
                   out / f"sweep_{args.apartment}_{args.lighting}", device=args.device,
                   progress=lambda m: print(m, flush=True))
    (out / f"sweep_{args.apartment}_{args.lighting}.json").write_text(json.dumps(res, indent=1))
    return 0


# ----------------------------------------------------------------------------------------------- pack


def cmd_pack(args) -> int:
    """The run's frames in a few compressed files small enough to carry home: geometry (every frame:
    depth float32, instance ids uint16) and RGB (the job's frame 1, float16), one file per kind and
    apartment, beside results.json."""
    import numpy as np

    from vrformats import frames as fr

    out, dest = Path(args.out), Path(args.dest)
    dest.mkdir(parents=True, exist_ok=True)
    res = json.loads((out / "results.json").read_text())
    groups: dict[str, dict] = {}
    for name, r in res["jobs"].items():
        if not r.get("ok"):
            continue
        sub = _frames_dir(r)
        if r["preset"] is None:
            for i in sorted(int(p.stem) for p in (out / sub).glob("*.exr")):
                f = fr.read_frame(out / sub / fr.frame_name(i), rgb=False, require=("depth", "instance"))
                g = groups.setdefault(f"geometry_{r['apartment']}", {})
                g[f"{sub}__{i}__depth"] = f.depth.astype(np.float32)
                g[f"{sub}__{i}__instance"] = f.instance.astype(np.uint16)
        else:
            f = fr.read_frame(out / sub / fr.frame_name(1), require=("rgb",))
            groups.setdefault(f"rgb_{r['apartment']}", {})[f"{sub}__1__rgb"] = f.rgb.astype(np.float16)
    sweeps = {f.stem: json.loads(f.read_text()) for f in sorted(out.glob("sweep_*.json"))}
    if sweeps:
        (dest / "sweeps.json").write_text(json.dumps(sweeps, indent=1))
    for k, arrays in groups.items():
        np.savez_compressed(dest / f"{k}.npz", **arrays)
    shutil.copyfile(out / "results.json", dest / "results.json")
    for f in sorted(dest.iterdir()):
        print(f"{f.name}: {f.stat().st_size / 1e6:.1f} MB")
    return 0


def _frames_dir(r: dict) -> str:
    return f"geometry_{r['apartment']}" if r["preset"] is None else f"rgb_{r['preset']}_{r['apartment']}_{r['lighting']}"


# --------------------------------------------------------------------------------------------- report


def psnr(a, b) -> float:
    """PSNR in 8-bit sRGB (the images the methods read), as the stability benchmark measures it."""
    import numpy as np

    from vrformats.color import srgb8

    d = srgb8(a).astype(np.float64) - srgb8(b).astype(np.float64)
    mse = float(np.mean(d * d))
    return float("inf") if mse == 0 else 10 * np.log10(255.0**2 / mse)


def cmd_report(args) -> int:
    import numpy as np

    from synth.jobs.estimate import CALIBRATION_FORMAT, CALIBRATION_VERSION
    from vrformats import frames as fr

    out = Path(args.out)
    res = json.loads((out / "results.json").read_text())
    prep = json.loads((Path(args.prep) / "manifest.json").read_text())
    rows = res["jobs"]
    cal_dir = Path(args.calibration_dir) if args.calibration_dir else None
    cals = {}
    for apt, a in prep["apartments"].items():
        g = rows.get(f"geometry/{apt}")
        for preset in PRESETS:
            rgb = [r for r in rows.values() if r["apartment"] == apt and r["preset"] == preset and r["ok"]]
            if not g or not g.get("ok") or len(rgb) < len(a["lightings"]):
                continue
            by_l = {r["lighting"]: r["median_s_per_frame"] for r in rgb}
            doc = {"format": CALIBRATION_FORMAT, "version": CALIBRATION_VERSION,
                   "seconds_per_frame": {"geometry": g["median_s_per_frame"], "rgb": round(statistics.mean(by_l.values()), 4)},
                   "rgb_seconds_per_frame_by_lighting": by_l,
                   "startup_s": {"geometry": g["startup_s"], "rgb": round(statistics.median(r["startup_s"] for r in rgb), 3)},
                   "devices": {"geometry": g["device"], "rgb": rgb[0]["device"]}, "device": rgb[0]["device"],
                   "frames_measured": len(a["path_frames"]) - 1, "tour": a.get("tour"),
                   "spec": {"name": a["spec"], "source": f"render_jobs/{a['spec']}.yaml", "renderer": "blender",
                            "geometry": "blender", "quality": preset, "width": a["width"], "height": a["height"], "device": "gpu"},
                   **res["machine"], "note": "measured by tools/gpu_calibration.py run (rgb: the mean over the design's lightings)"}
            cals[(apt, preset)] = doc
            if cal_dir:
                cal_dir.mkdir(parents=True, exist_ok=True)
                (cal_dir / f"calibration_{a['spec']}_{preset}_gpu.json").write_text(json.dumps(doc, indent=1) + "\n")
    print("| apartment | preset | geometry s/frame | RGB s/frame day / evening / night | start-up s (geometry, RGB) | device |")
    print("|---|---|---:|---:|---:|---|")
    for (apt, preset), c in cals.items():
        bl = c["rgb_seconds_per_frame_by_lighting"]
        print(f"| {apt} | {preset} | {c['seconds_per_frame']['geometry']:.3f} | {' / '.join(f'{v:.3f}' for v in bl.values())} "
              f"| {c['startup_s']['geometry']:.1f}, {c['startup_s']['rgb']:.1f} | {c['device']} |")
    if args.cpu:
        cpu = Path(args.cpu)
        print("\nGPU frames against CPU frames (same settings, seed and views)")
        print("| job | frames | RGB PSNR dB (8-bit sRGB), min / median | depth max abs diff m | ids equal (share of pixels) |")
        print("|---|---:|---:|---:|---:|")
        comp = {}
        for name, r in rows.items():
            a = prep["apartments"][r["apartment"]]
            sub = f"geometry_{r['apartment']}" if r["preset"] is None else f"rgb_{r['preset']}_{r['apartment']}_{r['lighting']}"
            ps, dd, ideq, n = [], [], [], 0
            for i in range(len(a["path_frames"])):
                fg, fc = out / sub / fr.frame_name(i), cpu / sub / fr.frame_name(i)
                if not (fg.exists() and fc.exists()):
                    continue
                n += 1
                if r["preset"] is None:
                    G, C = (fr.read_frame(f, rgb=False, require=("depth", "instance")) for f in (fg, fc))
                    dd.append(float(np.max(np.abs(G.depth - C.depth))))
                    ideq.append(float(np.mean(G.instance == C.instance)))
                else:
                    G, C = (fr.read_frame(f, require=("rgb",)) for f in (fg, fc))
                    ps.append(psnr(G.rgb, C.rgb))
            if not n:
                continue
            comp[name] = {"frames": n, "psnr": ps, "depth_max_abs_m": dd, "ids_equal": ideq}
            print(f"| {name} | {n} | " + (f"{min(ps):.1f} / {statistics.median(ps):.1f}" if ps else "") + " | "
                  + (f"{max(dd):.2e}" if dd else "") + " | " + (f"{min(ideq):.6f}" if ideq else "") + " |")
        (out / "comparison.json").write_text(json.dumps(comp, indent=1))
    return 0


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    sub = ap.add_subparsers(dest="cmd", required=True)
    a = sub.add_parser("prepare")
    a.add_argument("prep")
    a.add_argument("--frames", type=int, default=3, help="frames per job, spread along the query path (the first is warm-up)")
    a.add_argument("--replicacad-root")
    a.add_argument("--size", type=lambda t: tuple(int(x) for x in t.split("x")), help="WxH in place of the specs' (a quick try)")
    a.set_defaults(fn=cmd_prepare)
    a = sub.add_parser("run")
    a.add_argument("prep")
    a.add_argument("out")
    a.add_argument("--device", choices=["cpu", "gpu", "auto"], default="gpu")
    a.add_argument("--only", action="append", default=[], help="jobs to run (glob over preset/apartment/lighting)")
    a.add_argument("--budget-s", type=float, help="start no job after this many seconds")
    a.add_argument("--middle-only", action="store_true", help="render only the job's frame 1 (the one compared), no timing")
    a.add_argument("--dataset-root", help="where the ReplicaCAD files the layout names are on this machine")
    a.set_defaults(fn=cmd_run)
    a = sub.add_parser("sweep")
    a.add_argument("prep")
    a.add_argument("out")
    a.add_argument("--apartment", required=True)
    a.add_argument("--lighting", required=True)
    a.add_argument("--device", choices=["cpu", "gpu", "auto"], default="gpu")
    a.add_argument("--reference-samples", type=int)
    a.add_argument("--quick", action="store_true", help="the presets and the samples ladder only")
    a.set_defaults(fn=cmd_sweep)
    a = sub.add_parser("pack")
    a.add_argument("out")
    a.add_argument("dest")
    a.set_defaults(fn=cmd_pack)
    a = sub.add_parser("report")
    a.add_argument("prep")
    a.add_argument("out")
    a.add_argument("--cpu", help="a run's OUT on the CPU, for the comparison")
    a.add_argument("--calibration-dir", help="write one calibration file per apartment and preset here")
    a.set_defaults(fn=cmd_report)
    args = ap.parse_args(argv)
    return args.fn(args)


if __name__ == "__main__":
    sys.exit(main())
