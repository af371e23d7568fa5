"""Render job specs: the YAML a ``synth render`` reads, validated into a ``JobSpec``.

A spec names one or more *designs* (layouts x lightings x one camera path), the renderer, the
quality, the image size, the seed and the output folder (docs/render_jobs.md). Every error names
the file and the key. What a spec leaves out is ``synth.render.settings.DEFAULTS``.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass

from vrformats import fields
from vrformats.errors import UserError
from vrformats.fields import fail, names, positive_int
from vrformats.yamlfile import read_yaml

from ..render.settings import DEFAULTS, DEVICES, cycles_overrides, quality

RETRIES = 2  # a failing chunk is retried this many times before it is reported failed
SPEC_KEYS = {"name", "description", "out", "renderer", "geometry", "quality", "cycles", "size", "hfov_deg", "seed",
             "device", "threads", "chunk_size", "retries", "previews", "designs", "replicacad"}
DESIGN_KEYS = {"layouts", "lightings", "path", "rgb_every"}
PATH_KEYS = {"name", "frames"}


@dataclass
class Design:
    layouts: list[str]
    lightings: list[str] | None  # None: geometry only
    path: str
    frames: int | None
    rgb_every: int = 1  # RGB on frames 0, k, 2k, ...; depth and ids on every frame


@dataclass
class JobSpec:
    name: str
    out: str
    designs: list[Design]
    renderer: str = DEFAULTS.renderer
    geometry: str = "blender"  # renderer of the geometry cache of Blender jobs: blender | fast
    quality: str = DEFAULTS.quality
    width: int = DEFAULTS.width
    height: int = DEFAULTS.height
    hfov_deg: float = DEFAULTS.hfov_deg
    seed: int = DEFAULTS.seed
    device: str = DEFAULTS.device
    chunk_size: int = DEFAULTS.chunk_size
    retries: int = RETRIES
    previews: bool = DEFAULTS.previews
    description: str = ""
    source: str = ""
    replicacad: dict | None = None  # layouts are scenes of a ReplicaCAD folder (a scene source: synth.sources)
    cycles: dict | None = None  # settings of the quality preset replaced for this job (synth.render.settings.cycles_overrides)
    threads: int = 0  # Cycles threads per Blender worker (0: all the machine's cores)


def parse_spec(doc, source: str) -> JobSpec:
    """Validate a spec document; every error names the file and the key."""
    if not isinstance(doc, dict):
        fail(source, None, "expected a mapping at the top level")
    unknown = sorted(map(str, set(doc) - SPEC_KEYS))
    if unknown:
        fail(source, unknown[0], f"unknown key; allowed: {', '.join(sorted(SPEC_KEYS))}")
    for k in ("name", "out", "designs"):
        if k not in doc:
            fail(source, k, "missing")
    renderer = doc.get("renderer", DEFAULTS.renderer)
    if renderer not in ("blender", "fast"):
        fail(source, "renderer", f"expected blender or fast, got {renderer!r}")
    geometry = doc.get("geometry", "blender" if renderer == "blender" else "fast")
    if geometry not in ("blender", "fast"):
        fail(source, "geometry", f"expected blender or fast, got {geometry!r}")
    if renderer == "fast" and geometry != "fast":
        fail(source, "geometry", "the fast renderer makes its own geometry: leave geometry out")
    q = doc.get("quality", DEFAULTS.quality)
    try:
        quality(q)
    except UserError as e:
        fail(source, "quality", str(e))
    w, h = fields.frame_size(source, doc.get("size", [DEFAULTS.width, DEFAULTS.height]), "size")
    device = doc.get("device", DEFAULTS.device)
    if device not in DEVICES:
        fail(source, "device", f"expected one of {', '.join(DEVICES)}, got {device!r}")
    seed = fields.nonneg_int(source, doc.get("seed", DEFAULTS.seed), "seed")
    retries = fields.nonneg_int(source, doc.get("retries", RETRIES), "retries")
    hfov = doc.get("hfov_deg", DEFAULTS.hfov_deg)
    if not fields.is_number(hfov) or not 1.0 <= hfov <= 170.0:
        fail(source, "hfov_deg", f"expected degrees in [1, 170], got {hfov!r}")
    designs_doc = doc["designs"]
    if not isinstance(designs_doc, list) or not designs_doc:
        fail(source, "designs", "expected a non-empty list")
    designs = []
    for i, d in enumerate(designs_doc):
        f = f"designs[{i}]"
        if not isinstance(d, dict):
            fail(source, f, "expected a mapping with layouts, lightings, path")
        unknown = sorted(map(str, set(d) - DESIGN_KEYS))
        if unknown:
            fail(source, f"{f}.{unknown[0]}", f"unknown key; allowed: {', '.join(sorted(DESIGN_KEYS))}")
        if "layouts" not in d or "path" not in d:
            fail(source, f, "needs layouts and path")
        layouts = names(source, d["layouts"], f + ".layouts")
        lightings = None if d.get("lightings") is None else names(source, d["lightings"], f + ".lightings")
        if renderer == "blender" and lightings is None:
            pass  # geometry-only tours rendered with Blender
        if renderer == "fast" and lightings is not None:
            fail(source, f + ".lightings", "the fast renderer makes geometry only: leave lightings out")
        p = d["path"]
        if isinstance(p, str):
            p = {"name": p}
        if not isinstance(p, dict) or "name" not in p:
            fail(source, f + ".path", f"expected a path name or {{name, frames}}, got {p!r}")
        unknown = sorted(map(str, set(p) - PATH_KEYS))
        if unknown:
            fail(source, f"{f}.path.{unknown[0]}", "unknown key; allowed: name, frames")
        frames = None if p.get("frames") is None else positive_int(source, p["frames"], f + ".path.frames")
        rgb_every = positive_int(source, d.get("rgb_every", 1), f + ".rgb_every")
        if rgb_every > 1 and lightings is None:
            fail(source, f + ".rgb_every", "a geometry-only design renders no RGB: leave rgb_every out")
        designs.append(Design(layouts, lightings, str(p["name"]), frames, rgb_every))
    return JobSpec(
        name=fields.name_text(source, doc["name"], "name"), out=fields.out_folder(source, doc["out"]), designs=designs, renderer=renderer, geometry=geometry, quality=q,
        width=w, height=h,
        hfov_deg=float(hfov), seed=seed, device=device,
        chunk_size=positive_int(source, doc.get("chunk_size", DEFAULTS.chunk_size), "chunk_size"), retries=retries,
        previews=fields.boolean(source, doc.get("previews", DEFAULTS.previews), "previews"),
        description=fields.text(source, doc.get("description", ""), "description"), source=source,
        replicacad=_replicacad_section(doc, source),
        cycles=_cycles_section(doc, source, renderer), threads=fields.nonneg_int(source, doc.get("threads", 0), "threads"),
    )


def _cycles_section(doc: dict, source: str, renderer: str) -> dict | None:
    if doc.get("cycles") is not None and renderer != "blender":
        fail(source, "cycles", "the fast renderer has no Cycles settings: leave cycles out")
    return cycles_overrides(source, doc.get("cycles"))


def _replicacad_section(doc: dict, source: str) -> dict | None:
    if "replicacad" not in doc:
        return None
    from ..sources import get_source

    return get_source("replicacad").parse_section(doc["replicacad"], source)


def load_spec(path) -> JobSpec:
    """A render job spec: a file, or the name of a shipped one (``demo``: render_jobs/demo.yaml)."""
    from ..resources import render_spec

    p = render_spec(path)
    if not p.exists():
        raise UserError(f"{p}: job spec not found")
    return parse_spec(read_yaml(p), str(p))


def spec_document(spec: JobSpec) -> dict:
    d = asdict(spec)
    d.pop("source", None)
    for k, default in (("replicacad", None), ("cycles", None), ("threads", 0)):
        if d.get(k) == default:  # a spec without it reads as before: jobs started earlier still resume
            d.pop(k, None)
    return d


def spec_difference(old, new, where: str = "") -> str:
    """The first field in which two spec documents differ, and both values: ``quality: 'paper' there,
    'preview' in this spec`` (``designs[0].layouts[1]: ...``)."""
    def short(v) -> str:
        r = repr(v)
        return r if len(r) <= 80 else r[:77] + "..."

    if isinstance(old, dict) and isinstance(new, dict):
        for k in list(new) + [k for k in old if k not in new]:
            if old.get(k) != new.get(k):
                return spec_difference(old.get(k), new.get(k), f"{where}.{k}" if where else str(k))
    elif isinstance(old, list) and isinstance(new, list) and len(old) == len(new):
        for i, (a, b) in enumerate(zip(old, new)):
            if a != b:
                return spec_difference(a, b, f"{where}[{i}]")
    return f"{where or 'spec'}: {short(old)} there, {short(new)} in this spec"


