"""Detector training data (``synth trainset render SPEC``): apartments the experiments never see.

A trainset spec (``render_jobs/detector_train.yaml``, shipped as ``detector_train``) names generator seeds, how many rearranged
variants of each apartment, the lighting presets and how many seeded jitters of each, and how many
random views per (layout, lighting)::

    name: detector_train
    out: out/detector_train
    seeds: [101, 102, 103, 104, 105, 106, 107, 108]   # apartment generator seeds (7 is apt_0's: refused)
    variants: 1                 # rearranged variants per apartment (the paper's change ranges)
    lightings: [day, evening, night]
    jitter: 2                   # jittered copies of each preset per layout (synth.scene.lighting.jitter_preset)
    views: 40                   # random views per layout x jittered lighting (synth.paths.views)
    size: [160, 120]
    quality: preview
    seed: 0                     # views and jitter seeds derive from it
    appearance: 0.0             # optional: per object (and per layout's finishes), the chance that
                                # colours and materials are redrawn (synth.trainset.appearance)
    lighting_jitter: {}         # optional: LightingJitter fields to override (strength_log2: 1.0, ...)

A trainset from a ReplicaCAD folder names scenes instead of seeds (``render_jobs/detector_train_replicacad.yaml``)::

    replicacad:
      root: null                # the dataset folder; null: --replicacad-root, else $REPLICACAD_ROOT
      scenes: ["v3_sc*_staging_*"]   # scene names or fnmatch patterns: the layouts to train on
      templates: [apt_0, apt_1, apt_2, apt_3, apt_4, apt_5]   # scenes whose movable objects' *templates*
                                # (mesh, scale, class, support kind) clutter the layouts; their poses are never used
      clutter: [20, 40]         # objects added per layout (synth.layout.rearrange.clutter), drawn in this range
      lamps: 3                  # of them at least this many lamps (night needs a light source), on open tops
    lightings_per_layout: 1     # each layout gets this many of the lightings, in turn (default: all)

The experiments' ReplicaCAD scenes (``HELD_OUT_SCENES``: apt_0..apt_5) are refused as training scenes.

``prepare`` writes, into ``OUT/scenes/``, the layouts (``train_<seed>`` and its variants
``train_<seed>_v<k>``), one jittered preset per (layout, preset, k) and one views path per
(layout, preset, k) (``lighting/<layout>/<preset>_j<k>.yaml``, ``paths/<layout>/views_<preset>_j<k>``), then ``OUT/render.yaml``: an ordinary render job (Cycles RGB, fast
geometry, every frame with RGB, instance and semantic ids) over them, one tour each. ``render``
prepares and runs that job, resumable like every render job: preparing again writes identical
files, so a killed job resumes where it stopped.

The experiments' layouts are apt_0 (generator seed 7) and its variants apt_1..apt_5: a seed
that generates apt_0, or a layout whose shell equals a shipped layout's, is refused.
"""

from __future__ import annotations

import sys
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import yaml

from vrformats.atomic import write_text_atomic
from vrformats import fields
from vrformats.errors import SceneFormatError, UserError
from vrformats.fields import integer
from vrformats.yamlfile import read_yaml
from vrformats.cli import add_quiet, add_workers

from ..layout.apartment import DEFAULT_SEED, generate_apartment
from ..scene.lighting import LightingJitter, jitter_preset, load_lighting, preset_document
from .appearance import randomize_appearance
from ..paths.files import save_path
from ..paths.views import plan_views
from ..layout.rearrange import NoVariantFound, RearrangePlan, VariantSpec, make_variant
from ..resources import layouts_dir, trainset_spec
from ..scene.model import dump_yaml, layout_to_dict, load_layout

SPEC_KEYS = {"name", "description", "out", "seeds", "variants", "lightings", "jitter", "views", "size", "quality",
             "seed", "chunk_size", "workers", "appearance", "lighting_jitter", "replicacad", "lightings_per_layout"}
RC_KEYS = {"root", "scenes", "templates", "clutter", "lamps", "allow_unknown"}
# the ReplicaCAD scenes of the experiments (replicacad_demo, replicacad_apt_6x3): never training data
HELD_OUT_SCENES = ("apt_0", "apt_1", "apt_2", "apt_3", "apt_4", "apt_5")
# rearranged variants of a training apartment: the paper's ranges, like apt_1..apt_5's plans
VARIANT_PLANS = (RearrangePlan(removed=4, added=9), RearrangePlan(removed=7, added=9, other_room=0.25))


@dataclass(frozen=True)
class TrainsetSpec:
    name: str
    out: str
    seeds: tuple[int, ...]
    variants: int = 1
    lightings: tuple[str, ...] = ("day", "evening", "night")
    jitter: int = 2
    views: int = 40
    size: tuple[int, int] = (160, 120)
    quality: str = "preview"
    seed: int = 0
    chunk_size: int = 40
    description: str = ""
    source: str | None = None
    appearance: float = 0.0
    lighting_jitter: LightingJitter = LightingJitter()
    replicacad: dict | None = None  # scenes of a ReplicaCAD folder instead of generator seeds
    lightings_per_layout: int | None = None  # None: every lighting on every layout

    @property
    def layouts(self) -> int:
        """Layouts named by the spec (ReplicaCAD: patterns count once each until resolved)."""
        if self.replicacad is not None:
            return len(self.replicacad["scenes"])
        return len(self.seeds) * (1 + self.variants)

    def tours_per_layout(self) -> int:
        return min(self.lightings_per_layout or len(self.lightings), len(self.lightings)) * self.jitter

    @property
    def frames(self) -> int:
        return self.layouts * self.tours_per_layout() * self.views


def parse_trainset(doc, source: str) -> TrainsetSpec:
    """Validate a trainset spec; every error names the file and the key."""
    if not isinstance(doc, dict):
        raise SceneFormatError(source, None, "expected a mapping at the top level")
    unknown = sorted(map(str, set(doc) - SPEC_KEYS))
    if unknown:
        raise SceneFormatError(source, unknown[0], f"unknown key; allowed: {', '.join(sorted(SPEC_KEYS))}")
    rc = _replicacad_section(doc.get("replicacad"), source) if "replicacad" in doc else None
    for k in ("name", "out") + (() if rc else ("seeds",)):
        if doc.get(k) in (None, "", []):
            raise SceneFormatError(source, k, "missing (or a replicacad: section)" if k == "seeds" else "missing")
    if rc is not None and doc.get("seeds"):
        raise SceneFormatError(source, "seeds", "a ReplicaCAD trainset names scenes (replicacad.scenes), not generator seeds")
    seeds = doc.get("seeds") or []
    if not isinstance(seeds, list) or any(not fields.is_integer(s) or s < 0 for s in seeds):
        raise SceneFormatError(source, "seeds", f"expected a list of non-negative integers, got {seeds!r}")
    if len(set(seeds)) != len(seeds):
        raise SceneFormatError(source, "seeds", "a seed is listed twice")
    if DEFAULT_SEED in seeds:
        raise SceneFormatError(source, f"seeds[{seeds.index(DEFAULT_SEED)}]",
                               f"{DEFAULT_SEED} generates apt_0, an experiment layout: training data must come from other apartments")
    lightings = doc.get("lightings", ["day", "evening", "night"])
    if not isinstance(lightings, list) or not lightings or not all(isinstance(x, str) for x in lightings):
        raise SceneFormatError(source, "lightings", f"expected a list of preset names, got {lightings!r}")
    for i, name in enumerate(lightings):
        try:
            load_lighting(name)
        except UserError as e:
            raise SceneFormatError(source, f"lightings[{i}]", str(e)) from None
    size = fields.frame_size(source, doc.get("size", [160, 120]), "size")
    appearance = fields.number(source, doc.get("appearance", 0.0), "appearance", lo=0.0)
    if appearance > 1.0:
        raise SceneFormatError(source, "appearance", f"expected a probability in [0, 1], got {appearance}")
    if rc is not None and appearance > 0:
        raise SceneFormatError(source, "appearance", "redraws procedural colours and materials only; a ReplicaCAD "
                               "layout renders with its own glTF materials (use 0)")
    lj = doc.get("lighting_jitter") or {}
    if not isinstance(lj, dict):
        raise SceneFormatError(source, "lighting_jitter", "expected a mapping of LightingJitter fields")
    known = LightingJitter.__dataclass_fields__
    for k, v in lj.items():
        if k not in known:
            raise SceneFormatError(source, f"lighting_jitter.{k}", f"unknown key; allowed: {', '.join(sorted(known))}")
        if k in ("lamps_extra", "lamps_fewer"):
            integer(source, v, f"lighting_jitter.{k}", lo=0)
        else:
            fields.number(source, v, f"lighting_jitter.{k}", lo=0.0)
    return TrainsetSpec(
        name=fields.string(source, doc["name"], "name"), out=fields.out_folder(source, doc["out"]), seeds=tuple(seeds),
        variants=integer(source, doc.get("variants", 1), "variants", lo=0), lightings=tuple(lightings), jitter=integer(source, doc.get("jitter", 2), "jitter", lo=1),
        views=integer(source, doc.get("views", 40), "views", lo=1), size=(size[0], size[1]), quality=fields.text(source, doc.get("quality", "preview"), "quality"),
        seed=integer(source, doc.get("seed", 0), "seed", lo=0), chunk_size=integer(source, doc.get("chunk_size", 40), "chunk_size", lo=1),
        description=fields.text(source, doc.get("description", ""), "description"), source=source,
        appearance=float(appearance), lighting_jitter=LightingJitter(**lj), replicacad=rc,
        lightings_per_layout=(None if doc.get("lightings_per_layout") is None else
                              integer(source, doc["lightings_per_layout"], "lightings_per_layout", lo=1)))


def _replicacad_section(doc, source: str) -> dict:
    """The ``replicacad:`` mapping of a trainset spec, checked; errors name the file and the key."""
    from fnmatch import fnmatch

    d = fields.mapping(source, doc, "replicacad")
    unknown = sorted(map(str, set(d) - RC_KEYS))
    if unknown:
        raise SceneFormatError(source, f"replicacad.{unknown[0]}", f"unknown key; allowed: {', '.join(sorted(RC_KEYS))}")
    root = d.get("root")
    if root is not None:
        root = fields.string(source, root, "replicacad.root")
    scenes = fields.names(source, d.get("scenes"), "replicacad.scenes")
    if not scenes:
        raise SceneFormatError(source, "replicacad.scenes", "missing: scene names or patterns (v3_sc*_staging_*)")
    for i, pat in enumerate(scenes):
        held = [h for h in HELD_OUT_SCENES if fnmatch(h, pat)]
        if held:
            raise SceneFormatError(source, f"replicacad.scenes[{i}]",
                                   f"'{pat}' names {held[0]}, a scene of the experiments: training data must come from other scenes")
    templates = fields.names(source, d["templates"], "replicacad.templates") if d.get("templates") else []
    clutter = d.get("clutter", 0)
    if isinstance(clutter, list):
        if len(clutter) != 2:
            raise SceneFormatError(source, "replicacad.clutter", f"expected a count or [lo, hi], got {clutter!r}")
        lo, hi = (integer(source, v, f"replicacad.clutter[{k}]", lo=0) for k, v in enumerate(clutter))
        if lo > hi:
            raise SceneFormatError(source, "replicacad.clutter", f"expected lo <= hi, got {clutter!r}")
    else:
        lo = hi = integer(source, clutter, "replicacad.clutter", lo=0)
    if hi > 500:
        raise SceneFormatError(source, "replicacad.clutter", f"at most 500 objects per layout, got {hi}")
    if hi and not templates:
        raise SceneFormatError(source, "replicacad.templates", "clutter needs scenes to draw object templates from")
    lamps = integer(source, d.get("lamps", 0), "replicacad.lamps", lo=0)
    if lamps > lo and hi:
        raise SceneFormatError(source, "replicacad.lamps", f"{lamps} lamps do not fit in a clutter of {lo}")
    return {"root": root, "scenes": scenes, "templates": templates, "clutter": [lo, hi], "lamps": lamps,
            "allow_unknown": fields.boolean(source, d.get("allow_unknown", False), "replicacad.allow_unknown")}


def load_trainset(path) -> TrainsetSpec:
    """A trainset spec: a file, or the name of a shipped one (``detector_train``: render_jobs)."""
    p = trainset_spec(path)
    if not p.is_file():
        raise UserError(f"{p}: trainset spec not found")
    return parse_trainset(read_yaml(p), str(p))


def _write_if_changed(path: Path, text: str) -> bool:
    """Write atomically unless the file already holds exactly ``text`` (resume rewrites nothing)."""
    if path.is_file() and path.read_text() == text:
        return False
    write_text_atomic(path, text)
    return True


def _shipped_shells() -> dict:
    out = {}
    for p in sorted(layouts_dir().glob("*.yaml")):
        lay = load_layout(p)
        out[lay.name] = [r.rect for r in lay.stage.rooms]
    return out


def _seed_layouts(spec: TrainsetSpec, progress: bool):
    """(key, layouts) per generator seed: the apartment and its rearranged variants."""
    shells = _shipped_shells()
    for s in spec.seeds:
        base = generate_apartment(seed=s, name=f"train_{s}")
        rooms = [r.rect for r in base.stage.rooms]
        same = [n for n, r in shells.items() if r == rooms]
        if same:
            raise SceneFormatError(spec.source or "<trainset>", "seeds",
                                   f"seed {s} gives the shell of {same[0]}, an experiment layout")
        layouts = [base]
        for k in range(spec.variants):
            plan = VARIANT_PLANS[k % len(VARIANT_PLANS)]
            try:
                layouts.append(make_variant(base, VariantSpec(f"train_{s}_v{k + 1}", s * 10 + k + 1, plan)))
            except NoVariantFound as e:
                raise UserError(f"seed {s}: no rearranged variant {k + 1} within the paper's ranges ({e})") from None
        if spec.appearance > 0:
            layouts = [randomize_appearance(lay, spec.seed * 1_000_003 + s * 1009 + 7 + k, spec.appearance)
                       for k, lay in enumerate(layouts)]
        yield s, layouts
        if progress:
            print(f"prepared train_{s}: {len(layouts)} layout(s)", file=sys.stderr)


def replicacad_scenes(spec: TrainsetSpec, root: Path) -> list[str]:
    """The dataset's scenes that ``replicacad.scenes`` names, in name order; a pattern that matches
    nothing is an error naming it."""
    from fnmatch import fnmatch

    from ..sources import get_source

    known = get_source("replicacad").list_scenes(root)
    out = []
    for i, pat in enumerate(spec.replicacad["scenes"]):
        hit = [n for n in known if fnmatch(n, pat)]
        if not hit:
            raise SceneFormatError(spec.source or "<trainset>", f"replicacad.scenes[{i}]", f"no scene of {root} matches '{pat}'")
        out += [n for n in hit if n not in out]
    held = [n for n in out if n in HELD_OUT_SCENES]
    if held:
        raise SceneFormatError(spec.source or "<trainset>", "replicacad.scenes", f"{held[0]} is a scene of the experiments")
    return sorted(out)


def _replicacad_layouts(spec: TrainsetSpec, root: Path, progress: bool):
    """(key, [layout]) per ReplicaCAD scene: imported, then cluttered with the templates' objects."""
    from ..layout.rearrange import clutter, template_pool
    from ..sources import get_source

    source = get_source("replicacad")
    rc = spec.replicacad
    src = spec.source or "<trainset>"
    known = set(source.list_scenes(root))
    pool = []
    for i, name in enumerate(rc["templates"]):
        if name not in known:
            raise SceneFormatError(src, f"replicacad.templates[{i}]", f"no scene '{name}' in {root}")
        pool += template_pool(source.load_scene(root, name, allow_unknown=rc["allow_unknown"]), distinct=False)
    lo, hi = rc["clutter"]
    for k, name in enumerate(replicacad_scenes(spec, root)):
        lay = source.load_scene(root, name, allow_unknown=rc["allow_unknown"])
        if hi:
            rng = np.random.default_rng([spec.seed, k, 5])
            n = int(rng.integers(lo, hi + 1))
            lay = clutter(lay, pool, n, seed=spec.seed * 1_000_003 + k, lamps=rc["lamps"], name=name)
        if progress:
            print(f"prepared {name}: {len(lay.objects)} objects ({lay.meta.get('clutter', {}).get('added', 0)} added), "
                  f"{sum(f.kind == 'lamp' for f in lay.fixtures)} lamps", file=sys.stderr)
        yield k, [lay]


def prepare(spec: TrainsetSpec, out: Path | None = None, progress: bool = True, replicacad_root: str | None = None) -> Path:
    """Write the layouts, jittered presets, views paths and ``render.yaml`` of the trainset into
    ``out`` (default ``spec.out``); returns the render spec's path. Deterministic."""
    out = Path(out or spec.out)
    scenes = out / "scenes"
    presets = [load_lighting(name) for name in spec.lightings]
    designs = []
    if spec.replicacad is not None:
        from ..sources import get_source

        root = get_source("replicacad").resolve_root(spec.replicacad, spec.source or "<trainset>", replicacad_root)
        groups = _replicacad_layouts(spec, root, progress)
    else:
        groups = _seed_layouts(spec, progress)
    n_lit = min(spec.lightings_per_layout or len(presets), len(presets))
    n = 0
    for s, layouts in groups:
        for lay in layouts:
            lay_file = scenes / "layouts" / f"{lay.name}.yaml"
            _write_if_changed(lay_file, dump_yaml(layout_to_dict(lay)))
            chosen = sorted((n + i) % len(presets) for i in range(n_lit))  # every lighting in turn
            n += 1
            for li in chosen:
                preset = presets[li]
                for j in range(spec.jitter):
                    jseed = spec.seed * 1_000_003 + s * 1009 + li * 101 + j
                    lit = jitter_preset(preset, jseed, spec.lighting_jitter)
                    tag = f"{preset.name}_j{j}"  # tour: <layout>__<preset>_j<k>__views_<preset>_j<k>
                    lit_file = scenes / "lighting" / lay.name / f"{tag}.yaml"
                    doc = preset_document(lit)
                    doc["name"] = f"{lay.name}/{tag}"
                    _write_if_changed(lit_file, yaml.safe_dump(doc, sort_keys=False, default_flow_style=None))
                    path = plan_views([lay], spec.views, seed=jseed, name=f"views_{lay.name}_{tag}")
                    path.meta["layouts"] = [str(lay_file.resolve())]
                    path_file = save_path(path, scenes / "paths" / lay.name / f"views_{tag}.txt")  # atomic, deterministic
                    designs.append({"layouts": [str(lay_file.resolve())], "lightings": [str(lit_file.resolve())],
                                    "path": str(path_file.resolve()), "rgb_every": 1})
    job = {"name": spec.name, "description": spec.description or f"detector training data from {spec.source}",
           "out": str(out.resolve()), "renderer": "blender", "geometry": "fast", "quality": spec.quality,
           "size": list(spec.size), "seed": spec.seed, "chunk_size": spec.chunk_size, "retries": 2, "designs": designs}
    render = out / "render.yaml"
    _write_if_changed(render, yaml.safe_dump(job, sort_keys=False, default_flow_style=None, width=140))
    return render


def cmd_render(args) -> int:
    from ..jobs import load_spec, run_job

    spec = load_trainset(args.spec)
    out = Path(args.out) if args.out else Path(spec.out)
    render = prepare(spec, out, progress=not args.quiet, replicacad_root=getattr(args, "replicacad_root", None))
    job = load_spec(render)
    frames = sum(len(d.layouts) * len(d.lightings) * spec.views for d in job.designs)
    n_layouts = len({lay for d in job.designs for lay in d.layouts})
    print(f"{spec.name}: {n_layouts} layouts, {len(job.designs)} tours, "
          f"{frames} frames at {spec.size[0]}x{spec.size[1]} -> {out}", file=sys.stderr)
    if args.prepare_only:
        print(render)
        return 0
    summary = run_job(job, workers=args.workers, resume=True, progress=not args.quiet)
    print(f"{summary['frames_rendered_now']} frames rendered now in {summary['wall_time_s']:.0f} s; "
          f"failed chunks: {len(summary['failed'])}")
    return 1 if summary["failed"] else 0


def register_cli(subparsers) -> None:
    g = subparsers.add_parser("trainset", help="detector training data from apartments the experiments never use")
    ts = g.add_subparsers(dest="cmd", required=True)
    a = ts.add_parser("render", help="prepare layouts, jittered lights and random views, then render them (resumable)")
    a.add_argument("spec", metavar="SPEC.yaml", help="trainset spec, or a shipped name (detector_train: render_jobs/detector_train.yaml)")
    a.add_argument("--out", help="output folder (default: the spec's out)")
    add_workers(a, "chunk processes")
    a.add_argument("--prepare-only", action="store_true", help="write the scenes and render.yaml, render nothing")
    a.add_argument("--replicacad-root", metavar="DIR", help="the ReplicaCAD folder of a spec with replicacad: "
                   "(default: the spec's replicacad.root, else $REPLICACAD_ROOT)")
    add_quiet(a)
    a.set_defaults(fn=cmd_render)
