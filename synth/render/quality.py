"""``synth bench quality``: what each Cycles setting buys, against a reference image, beside its time.

For each view (one frame of a design's first tour, per lighting: the frame the calibration renders
is at the start of the path, this one in its middle), one Blender process
(``synth.blender.quality_worker``) builds the scene once and renders:

- the **reference**: the paper preset's scene at ``REFERENCE`` (many samples, twice the paper
  preset's bounces, no denoiser, which would bias it), twice, with seeds other than the settings'
  (the same seed would share the first samples' noise and flatter them). The two are averaged. Half
  of the squared difference of the two is the noise of one, a quarter is that of their average: it is
  taken out of each setting's squared error (the errors of independent renders add), which gives the
  PSNR against the converged image, ``psnr_db``; ``psnr_raw_db`` is against the average as it is
  (a lower bound). The reference's own PSNR against the converged image is reported too;
- the **presets** (``synth.render.settings.QUALITY``);
- the **sweep**: settings on top of the paper preset (samples, denoiser, adaptive threshold,
  bounces, light tree, clamping, caustics).

Each row gives the seconds of one render (wall and CPU, the kernels already loaded and the BVH
built), the PSNR and SSIM against the first reference (8-bit sRGB, ``vrformats.image_quality``),
and the time over a one-sample geometry frame of the same view (``synth bench render``'s
``geometry`` pass, timed in the same run). Nothing here imports Blender; the views of a design and
the command are ``synth.jobs.quality_bench``'s.
"""

from __future__ import annotations

import statistics
from pathlib import Path

import numpy as np

from vrformats import image_quality
from vrformats.errors import UserError

from .chunks import run_chunk_process
from .settings import QUALITY, cycles_overrides

# The reference: the paper preset's scene converged further. Twice its bounces; no denoiser; adaptive
# sampling stops only where a pixel is well converged.
REFERENCE = {"samples": 2048, "adaptive_threshold": 0.002, "denoise": False, "max_bounces": 16, "diffuse_bounces": 8,
             "glossy_bounces": 8, "transmission_bounces": 16}
PAPER_DB = 35.0  # paper quality: at least this PSNR against the reference (issue 47)

# The sweep, each on top of the paper preset; "extra" are scene.cycles attributes no preset sets.
SWEEP = (
    [{"cycles": {"samples": n}} for n in (1, 2, 4, 8, 16, 32, 64, 128, 256)]
    + [{"cycles": {"samples": n, "denoise": False}} for n in (16, 128)]
    + [{"cycles": {"samples": 16, "denoise_prefilter": "FAST"}}, {"cycles": {"samples": 16, "adaptive_threshold": 0.05}},
       {"cycles": {"samples": 128, "adaptive_threshold": 0.05}},
       {"cycles": {"samples": 16, "max_bounces": 4, "diffuse_bounces": 2, "glossy_bounces": 2, "transmission_bounces": 4}},
       {"cycles": {"samples": 16, "max_bounces": 2, "diffuse_bounces": 1, "glossy_bounces": 1, "transmission_bounces": 2}},
       {"cycles": {"samples": 16}, "extra": {"use_light_tree": False}},
       {"cycles": {"samples": 16}, "extra": {"sample_clamp_indirect": 1.0}},
       {"cycles": {"samples": 16}, "extra": {"sample_clamp_indirect": 0.0}},
       {"cycles": {"samples": 16}, "extra": {"caustics_reflective": False, "caustics_refractive": False}}]
)


def setting_name(s: dict) -> str:
    parts = [f"{k}={v}" for k, v in (s.get("cycles") or {}).items()] + [f"{k}={v}" for k, v in (s.get("extra") or {}).items()]
    return "paper, " + ", ".join(parts) if parts else "paper"


def settings_list(quick: bool = False, reference_samples: int | None = None) -> list[dict]:
    """Reference (two seeds), the presets, then the sweep (``quick``: the samples ladder only)."""
    ref = {**REFERENCE, **({"samples": reference_samples} if reference_samples else {})}
    out = [{"name": "reference (seed + 1)", "role": "reference", "cycles": dict(ref), "seed_offset": 1},
           {"name": "reference (seed + 2)", "role": "reference", "cycles": dict(ref), "seed_offset": 2}]
    out += [{"name": f"preset {p}", "role": "preset", "preset": p, "cycles": dict(QUALITY[p])} for p in QUALITY]
    sweep = [s for s in SWEEP if not quick or (set(s["cycles"]) == {"samples"} and not s.get("extra"))]
    out += [{"name": setting_name(s), "role": "sweep", **s} for s in sweep]
    for s in out:
        cycles_overrides("synth bench quality", s["cycles"], "cycles")  # the settings' one validator
    return out


# ------------------------------------------------------------------------------------------ measure


def run_view(view: dict, settings: list[dict], work: Path, device: str = "cpu", threads: int = 0, progress=None) -> dict:
    """Render one view under every setting (one worker process per seed) and measure each image
    against the reference. Returns {"view", "device", "setup_s", "geometry_s", "rows"}."""
    out = work / "images"
    work.mkdir(parents=True, exist_ok=True)
    by_seed: dict[int, list[int]] = {}
    for k, s in enumerate(settings):
        by_seed.setdefault(int(s.get("seed_offset", 0)), []).append(k)
    seconds: dict[int, tuple[float, float]] = {}
    info: dict = {}
    for off, ks in sorted(by_seed.items()):
        job = {"layout": view["layout"], "lighting": view["lighting"], "pose": view["pose"], "intrinsics": view["intrinsics"],
               "seed": int(view["seed"]) + off, "device": device, "threads": threads, "out_dir": str(out / f"seed{off}"),
               "base": dict(QUALITY["paper"]),
               "settings": [{"cycles": settings[k]["cycles"], "extra": settings[k].get("extra") or {}} for k in ks]}

        def on_frame(ev, ks=ks):
            k = ks[ev["frame"]]
            seconds[k] = (ev["seconds"], ev.get("cpu"))
            if progress:
                progress(f"  {view['name']}: {settings[k]['name']}: {ev['seconds']:.2f} s")

        log = work / f"quality_job_seed{off}.log"
        rc, err, inf = run_chunk_process("rgb", job, str(work / f"quality_job_seed{off}.json"), str(log), on_frame=on_frame,
                                         worker="synth.blender.quality_worker")
        if rc != 0:
            raise UserError(f"quality render of {view['name']} failed: {err}")
        info.setdefault("setup_s", sum((inf.get("setup") or {}).values()))
        info["device"] = inf.get("device")
    geometry_s = geometry_seconds(view, work, device, threads)
    images = {}
    for off, ks in by_seed.items():
        for j, k in enumerate(ks):
            images[k] = np.load(out / f"seed{off}" / f"{j}.npy")
    refs = [k for k, s in enumerate(settings) if s["role"] == "reference"]
    a8, b8 = (image_quality.as_srgb8(images[k]) for k in refs)
    avg = image_quality.as_srgb8((images[refs[0]] + images[refs[1]]) / 2.0)
    ref_noise = image_quality.mse(a8, b8) / 4.0  # the noise of the average of two (each: half of their squared difference)
    rows = []
    for k, s in enumerate(settings):
        sec, cpu = seconds.get(k, (None, None))
        row = {"setting": s["name"], "role": s["role"], "cycles": s["cycles"], "extra": s.get("extra") or {},
               "seconds": sec, "cpu_seconds": cpu, "over_geometry": round(sec / geometry_s, 1) if sec and geometry_s else None}
        if k not in refs:
            m = image_quality.mse(image_quality.as_srgb8(images[k]), avg)
            row["psnr_raw_db"] = round(image_quality.db(m), 2)
            row["psnr_db"] = round(image_quality.db(m - ref_noise), 2) if m > 2 * ref_noise else None  # None: within the reference's noise
            row["ssim"] = round(image_quality.ssim(images[k], avg), 4)
        rows.append(row)
    reference = {"cycles": settings[refs[0]]["cycles"], "seconds": [seconds.get(k, (None,))[0] for k in refs],
                 "psnr_db": round(image_quality.db(ref_noise), 2), "psnr_one_against_other_db": round(image_quality.db(4 * ref_noise), 2)}
    return {"view": {k: v for k, v in view.items() if k not in ("poses_around",)}, "device": info.get("device"),
            "setup_s": info.get("setup_s"), "geometry_s": geometry_s, "reference": reference, "rows": rows}


def geometry_seconds(view: dict, work: Path, device: str, threads: int) -> float | None:
    """Median seconds of a one-sample geometry frame (depth and ids) around the view: the unit the
    issue's goal is stated in (paper-quality RGB at most 60 such frames)."""
    from vrformats.camera import Intrinsics

    from .bench import bench_blender

    poses = np.asarray(view["poses_around"], dtype=np.float64)
    r = bench_blender(Path(view["layout"]), "geometry", poses, Intrinsics.from_dict(view["intrinsics"]), "preview",
                      work, threads=threads, device=device)
    steady = r["per_frame_s"][1:] or r["per_frame_s"]
    return round(statistics.median(steady), 4) if steady else None


# ------------------------------------------------------------------------------------------ report


def passes(r: dict, reference_db: float, target_db: float = PAPER_DB) -> bool | None:
    """Whether a row reaches ``target_db`` against the converged image; None when it cannot be told (its
    error is within the reference's noise, and that noise is itself above the target)."""
    if r["psnr_db"] is not None:
        return r["psnr_db"] >= target_db
    return True if reference_db >= target_db else None


def cheapest(view: dict, target_db: float = PAPER_DB) -> dict | None:
    """The fastest setting known to reach ``target_db`` against the converged image."""
    ok = [r for r in view["rows"] if r["role"] != "reference" and passes(r, view["reference"]["psnr_db"], target_db)]
    return min(ok, key=lambda r: r["seconds"]) if ok else None


def format_report(views: list[dict], target_db: float = PAPER_DB) -> str:
    lines = []
    for v in views:
        w, h = v["view"]["intrinsics"]["width"], v["view"]["intrinsics"]["height"]
        lines.append(f"## {v['view']['name']} ({v['view']['spec']}, frame {v['view']['frame']} of the {v['view']['path']} path, "
                     f"{w}x{h}, {v['device']}); one-sample geometry frame {v['geometry_s']} s")
        ref = v["reference"]
        lines.append(f"reference: the average of two renders of {ref['cycles']['samples']} samples ("
                     f"{' s, '.join(f'{x:.1f}' for x in ref['seconds'])} s); one lies at {ref['psnr_one_against_other_db']} dB "
                     f"from the other, so the average is at about {ref['psnr_db']} dB from the converged image")
        lines.append("| setting | s/frame | x geometry | PSNR dB (reference noise out) | PSNR dB (raw) | SSIM |")
        lines.append("|---|---:|---:|---:|---:|---:|")
        for r in v["rows"]:
            if r["role"] == "reference":
                continue
            p = f"{r['psnr_db']:.2f}" if r["psnr_db"] is not None else f">{ref['psnr_db']:.0f} (within the reference's noise)"
            lines.append(f"| {r['setting']} | {r['seconds']:.3f} | {r['over_geometry']} | {p} | {r['psnr_raw_db']:.2f} | {r['ssim']:.4f} |")
        c = cheapest(v, target_db)
        lines.append(f"fastest at >= {target_db:g} dB: " + (f"{c['setting']} ({c['seconds']:.3f} s, {c['over_geometry']}x geometry, "
                                                            f"{c['psnr_db'] or 'within the reference noise'} dB)" if c
                                                           else "none known (none measured above it, or the reference is too noisy to tell)"))
        lines.append("")
    return "\n".join(lines)


def _db(r: dict, reference_db: float) -> tuple[float, bool]:
    """The row's PSNR against the converged image and whether it is only a bound: a row within the
    reference's noise is at least about as close as the reference itself."""
    return (r["psnr_db"], False) if r["psnr_db"] is not None else (reference_db, True)


def plot(views: list[dict], file, target_db: float = PAPER_DB) -> None:
    """PSNR against seconds per frame, one panel per view: the samples ladder as a line, the presets
    and the other settings as points (a triangle: within the reference's noise, at least that close),
    the paper-quality line and the reference's own PSNR."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    n = len(views)
    cols = min(3, n)
    rows_ = (n + cols - 1) // cols
    fig, axes = plt.subplots(rows_, cols, figsize=(4.8 * cols, 3.8 * rows_), squeeze=False)
    for ax, v in zip(axes.flat, views):
        ref_db = v["reference"]["psnr_db"]
        ladder = sorted((r for r in v["rows"] if r["role"] == "sweep" and set(r["cycles"]) == {"samples"} and not r["extra"]),
                        key=lambda r: r["seconds"])
        pts = [(r["seconds"], *_db(r, ref_db)) for r in ladder]
        ax.plot([p[0] for p in pts], [p[1] for p in pts], "-", color="0.5", lw=1, label="paper preset, 1..256 samples")
        for r, (x, y, bound) in zip(ladder, pts):
            ax.plot(x, y, "^" if bound else "o", color="0.4", ms=4)
            ax.annotate(str(r["cycles"]["samples"]), (x, y), fontsize=6, color="0.3", xytext=(3, -9), textcoords="offset points")
        for r in v["rows"]:
            y, bound = _db(r, ref_db) if r["role"] != "reference" else (None, False)
            if r["role"] == "preset":
                ax.plot(r["seconds"], y, "^" if bound else "s", ms=8, label=r["setting"])
            elif r["role"] == "sweep" and r not in ladder:
                ax.plot(r["seconds"], y, "x", color="0.6", ms=4)
        ax.axhline(target_db, color="tab:red", lw=0.8, ls="--", label=f"paper quality ({target_db:g} dB)")
        ax.axhline(ref_db, color="0.6", lw=0.8, ls=":", label="the reference's own")
        ax.set_xscale("log")
        ax.set_xlabel(f"seconds per RGB frame ({v['device']}, {v['view']['intrinsics']['width']}x{v['view']['intrinsics']['height']})")
        ax.set_ylabel("PSNR against the converged image (dB)")
        ax.set_title(v["view"]["name"] + (f" ({v['view']['spec']})" if v["view"].get("spec") else ""), fontsize=9)
        ax.grid(alpha=0.3)
    for ax in list(axes.flat)[n:]:
        ax.axis("off")
    axes.flat[0].legend(fontsize=6, loc="lower right")
    fig.text(0.01, 0.005, "x: other settings (docs/rendering.md); triangle: within the reference's noise (at least that close)",
             fontsize=6, color="0.4")
    fig.tight_layout(rect=(0, 0.02, 1, 1))
    fig.savefig(file, dpi=110)
    plt.close(fig)
