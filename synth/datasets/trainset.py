"""Detector training data (``synth trainset render SPEC``): apartments the experiments never see.

A trainset spec (``synth/specs/detector_train.yaml``, shipped as ``detector_train``) names generator seeds, how many rearranged
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
                                # colours and materials are redrawn (synth.datasets.appearance)
    lighting_jitter: {}         # optional: LightingJitter fields to override (strength_log2: 1.0, ...)

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

import yaml

from formats.atomic import write_text_atomic
from formats import fields
from formats.errors import SceneFormatError, UserError
from formats.fields import integer
from formats.yamlfile import read_yaml
from formats.cli import add_quiet, add_workers

from ..layout.apartment import DEFAULT_SEED, generate_apartment
from ..scene.lighting import LightingJitter, jitter_preset, load_lighting, preset_document
from .appearance import randomize_appearance
from ..paths.files import save_path
from ..paths.views import plan_views
from ..layout.rearrange import NoVariantFound, RearrangePlan, VariantSpec, make_variant
from ..resources import layouts_dir, trainset_spec
from ..scene.model import dump_yaml, layout_to_dict, load_layout

SPEC_KEYS = {"name", "description", "out", "seeds", "variants", "lightings", "jitter", "views", "size", "quality",
             "seed", "chunk_size", "workers", "appearance", "lighting_jitter"}
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

    @property
    def frames(self) -> int:
        return len(self.seeds) * (1 + self.variants) * len(self.lightings) * self.jitter * self.views


def parse_trainset(doc, source: str) -> TrainsetSpec:
    """Validate a trainset spec; every error names the file and the key."""
    if not isinstance(doc, dict):
        raise SceneFormatError(source, None, "expected a mapping at the top level")
    unknown = sorted(map(str, set(doc) - SPEC_KEYS))
    if unknown:
        raise SceneFormatError(source, unknown[0], f"unknown key; allowed: {', '.join(sorted(SPEC_KEYS))}")
    for k in ("name", "out", "seeds"):
        if doc.get(k) in (None, "", []):
            raise SceneFormatError(source, k, "missing")
    seeds = doc["seeds"]
    if not isinstance(seeds, list) or any(isinstance(s, bool) or not isinstance(s, int) or s < 0 for s in seeds):
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
        appearance=float(appearance), lighting_jitter=LightingJitter(**lj))


def load_trainset(path) -> TrainsetSpec:
    """A trainset spec: a file, or the name of a shipped one (``detector_train``: synth/specs)."""
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


def prepare(spec: TrainsetSpec, out: Path | None = None, progress: bool = True) -> Path:
    """Write the layouts, jittered presets, views paths and ``render.yaml`` of the trainset into
    ``out`` (default ``spec.out``); returns the render spec's path. Deterministic."""
    out = Path(out or spec.out)
    scenes = out / "scenes"
    shells = _shipped_shells()
    presets = [load_lighting(name) for name in spec.lightings]
    designs = []
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
        for lay in layouts:
            lay_file = scenes / "layouts" / f"{lay.name}.yaml"
            _write_if_changed(lay_file, dump_yaml(layout_to_dict(lay)))
            for li, preset in enumerate(presets):
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
        if progress:
            print(f"prepared train_{s}: {len(layouts)} layout(s)", file=sys.stderr)
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
    render = prepare(spec, out, progress=not args.quiet)
    job = load_spec(render)
    print(f"{spec.name}: {len(spec.seeds) * (1 + spec.variants)} layouts, {len(job.designs)} tours, "
          f"{spec.frames} frames at {spec.size[0]}x{spec.size[1]} -> {out}", file=sys.stderr)
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
    a.add_argument("spec", metavar="SPEC.yaml", help="trainset spec, or a shipped name (detector_train: synth/specs/detector_train.yaml)")
    a.add_argument("--out", help="output folder (default: the spec's out)")
    add_workers(a, "chunk processes")
    a.add_argument("--prepare-only", action="store_true", help="write the scenes and render.yaml, render nothing")
    add_quiet(a)
    a.set_defaults(fn=cmd_render)
