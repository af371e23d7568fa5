"""A render job's plan: its spec expanded into tours (``OUT/<layout>__<lighting>__<path>/``,
lighting ``geometry`` for geometry-only tours) and each tour into chunks of frames:

- ``geometry`` chunks, one set per layout + path, shared by every lighting (Blender);
- ``rgb`` chunks, per tour, which take depth and ids from the geometry chunks (Blender);
- ``copy`` chunks, which copy geometry frames into a tour without rendering RGB: every frame of a
  geometry-only tour, and the frames between RGB frames of a design with ``rgb_every: k``;
- ``fast`` chunks, per tour, for the fast Open3D renderer (geometry only).

With ``geometry: fast`` a Blender job renders its geometry cache with the fast Open3D renderer
(about 100x faster than a Cycles geometry pass; the depth and ids agree, see the renderer
cross-check tests) and only RGB with Blender. A design's ``rgb_every: k`` renders RGB on frames
0, k, 2k, ... only; every frame still has depth and ids (long tours for odometry and clips,
RGB where an appearance method or a detector needs it). Expanding writes nothing.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

from vrformats import frames as fr
from vrformats.design import tour_name
from vrformats.errors import SceneFormatError, UserError, check_output_folder
from vrformats.fields import fail

from ..render.chunks import chunk_job
from ..tour.render import TourSpec, prepare
from .spec import JobSpec


@dataclass
class Chunk:
    id: str  # e.g. "geometry/apt_0__query/0003", "rgb/apt_0__day__query/0003"
    kind: str  # geometry | rgb | fast
    tour: str  # tour directory name (geometry chunks: the first tour that uses them)
    frames: list[int]
    job: dict  # what the worker gets
    out_dir: str
    needs: str | None = None  # id of the geometry chunk an rgb chunk waits for
    store: object = field(default=None, repr=False, compare=False)  # synth.jobs.storage.Storage: the job folder is there

    def missing(self) -> list[int]:
        if self.store is not None:  # out_dir is in the driver's staging folder; the frames are in the storage
            return self.store.missing(self.out_dir, self.frames)
        d = Path(self.out_dir)
        return [i for i in self.frames if not (d / fr.frame_name(i)).exists()]


@dataclass
class Plan:
    spec: JobSpec
    out: Path
    tours: dict  # tour name -> synth.tour.render.Prepared
    chunks: list[Chunk] = field(default_factory=list)
    store: object = None  # synth.jobs.storage.Storage bound to ``out`` (a staging folder), or None: out is the job folder
    warnings: list = field(default_factory=list)  # one line each: tours that would render nearly black (check_light)

    def use_storage(self, store) -> None:
        """Put the job folder on ``store`` (``synth.jobs.storage``); ``out`` becomes the driver's staging folder."""
        self.store = store.bind(self.out)
        for c in self.chunks:
            c.store = self.store

    @property
    def where(self) -> str:
        return self.store.uri if self.store is not None else str(self.out)

    @property
    def frames_total(self) -> int:
        return sum(len(c.frames) for c in self.chunks)


def out_error(spec: JobSpec, from_cli: bool, e: UserError):
    """An unusable output folder, named as the spec's ``out`` or as the ``--out`` that overrides it."""
    if from_cli:
        raise UserError(f"--out: {e}") from None
    raise SceneFormatError(spec.source or "<spec>", "out", str(e)) from None


def validate_names(spec: JobSpec, check_clearance: bool = False, check_light: bool = False) -> list[str]:
    """Every layout, lighting and path of the spec exists and loads, and every path has the frames
    asked for; a UserError names the spec file and the field (``designs[0].layouts[1]``).

    With ``check_clearance``, a path rendered through a layout it was not planned on must keep its
    declared clearance there (``synth.paths.clearance.render_clearance_problem``). With
    ``check_light``, a tour lit by lamps alone should have one in sight (``synth.scene.lighting.dark_tour_problem``):
    returns one warning line per tour that would render nearly black, before anything renders (a
    warning, not a refusal: dark frames can be what an experiment wants)."""
    from ..paths.clearance import render_clearance_problem
    from ..paths.files import load_path
    from ..scene.lighting import dark_tour_problem, load_lighting
    from ..scene.model import load_layout, resolve_layout_path

    src = spec.source or "<spec>"
    layouts: dict[str, tuple] = {}
    paths: dict[str, object] = {}
    checked: set = set()
    warnings: list[str] = []

    def named(field: str, load, name):
        try:
            return load(name)
        except UserError as e:
            raise SceneFormatError(src, field, str(e)) from None

    for i, d in enumerate(spec.designs):
        f = f"designs[{i}]"
        presets = [named(f"{f}.lightings[{k}]", load_lighting, name) for k, name in enumerate(d.lightings or [])]
        if d.path not in paths:
            paths[d.path] = named(f"{f}.path", load_path, d.path)
        cpath = paths[d.path]
        n = len(cpath.poses)
        if n == 0:
            fail(src, f"{f}.path", f"camera path '{d.path}' has no poses")
        if d.frames is not None and d.frames > n:
            fail(src, f"{f}.path.frames", f"{d.frames} exceeds the {n} frames of camera path '{cpath.name}'")
        for k, name in enumerate(d.layouts):
            field = f"{f}.layouts[{k}]"
            if name not in layouts:
                layouts[name] = (named(field, resolve_layout_path, name), named(field, load_layout, name))
            lfile, lay = layouts[name]
            key = (name, d.path, d.frames)
            if check_clearance and key not in checked:
                checked.add(key)
                why = render_clearance_problem(cpath, lay, lfile, name, d.frames)
                if why:
                    fail(src, field, why)
            if check_light:
                poses = cpath.poses[: d.frames] if d.frames else cpath.poses
                for k2, preset in enumerate(presets):
                    if (name, d.path, d.frames, preset.name) in checked:
                        continue
                    checked.add((name, d.path, d.frames, preset.name))
                    why = dark_tour_problem(preset, lay, poses)
                    if why:
                        warnings.append(f"{src}: {f}.lightings[{k2}]: {why} in {name} on path '{cpath.name}'")
    return warnings


def expand(spec: JobSpec, out: Path | None = None, check_clearance: bool = False, check_light: bool = False) -> Plan:
    """Validate every name and expand the spec into tours and chunks. Writes nothing.

    ``check_clearance`` (what ``synth render`` does unless ``--allow-clearance-breach``): refuse a
    path that breaks its declared clearance in a layout it was not planned on. Readers of rendered
    tours (``reloc experiment``) expand without it."""
    from_cli = out is not None
    out = Path(out or spec.out)
    try:
        check_output_folder(out)
    except UserError as e:
        out_error(spec, from_cli, e)
    warnings = validate_names(spec, check_clearance, check_light)
    plan = Plan(spec, out, {}, warnings=warnings)
    seen_geo: dict[str, list[Chunk]] = {}
    for d in spec.designs:
        for layout in d.layouts:
            for lighting in (d.lightings or [None]):
                name = tour_name(layout, lighting, d.path)
                if name in plan.tours:
                    continue
                ts = TourSpec(layout=layout, path=d.path, out=str(out / name), lighting=lighting, renderer=spec.renderer,
                              quality=spec.quality, width=spec.width, height=spec.height, hfov_deg=spec.hfov_deg,
                              frames=d.frames, seed=spec.seed, device=spec.device, previews=spec.previews,
                              threads=spec.threads, cycles=spec.cycles,
                              chunk_size=spec.chunk_size, geometry_cache=str(out / "_geometry"),
                              check_clearance=False)  # validate_names did, once per layout + path
                p = prepare(ts, create=False)
                if spec.renderer == "blender" and spec.geometry == "fast":  # never mixed with a Cycles cache
                    p.geometry_dir = p.geometry_dir.with_name(p.geometry_dir.name + "__fast")
                p.extra["rgb_every"] = d.rgb_every if lighting is not None else None
                plan.tours[name] = p
                ids = p.frame_ids
                groups = [ids[k : k + spec.chunk_size] for k in range(0, len(ids), spec.chunk_size)]
                if spec.renderer == "fast":
                    for k, g in enumerate(groups):
                        plan.chunks.append(Chunk(f"fast/{name}/{k:04d}", "fast", name, g, chunk_job(p, "fast", g), str(p.out / "frames")))
                    continue
                gkey = p.geometry_dir.name
                if gkey not in seen_geo:
                    seen_geo[gkey] = []
                    gkind = "fast" if spec.geometry == "fast" else "geometry"
                    for k, g in enumerate(groups):
                        c = Chunk(f"geometry/{gkey}/{k:04d}", gkind, name, g, chunk_job(p, gkind, g, p.geometry_dir),
                                  str(p.geometry_dir))
                        seen_geo[gkey].append(c)
                        plan.chunks.append(c)
                every = d.rgb_every if lighting is not None else 0
                for k, g in enumerate(groups):
                    need = seen_geo[gkey][k].id
                    rgb = [i for i in g if every and i % every == 0]
                    copy = [i for i in g if not (every and i % every == 0)]
                    if rgb:
                        plan.chunks.append(Chunk(f"rgb/{name}/{k:04d}", "rgb", name, rgb, chunk_job(p, "rgb", rgb),
                                                 str(p.out / "frames"), needs=need))
                    if copy:
                        plan.chunks.append(Chunk(f"copy/{name}/{k:04d}", "copy", name, copy, chunk_job(p, "copy", copy),
                                                 str(p.out / "frames"), needs=need))
    return plan


def describe(plan: Plan) -> str:
    spec = plan.spec
    lines = [f"job {spec.name}: {len(plan.tours)} tours, {plan.frames_total} chunk-frames in {len(plan.chunks)} chunks "
             f"({spec.renderer}, {spec.quality}, {spec.width}x{spec.height}, chunks of {spec.chunk_size}) -> {plan.where}"]
    by_kind: dict[str, list] = {}
    for c in plan.chunks:
        by_kind.setdefault(c.kind, []).append(c)
    for k, cs in by_kind.items():
        miss = sum(len(c.missing()) for c in cs)
        lines.append(f"  {k:<9} {len(cs):>5} chunks {sum(len(c.frames) for c in cs):>7} frames, {miss} still to render")
    for name, p in plan.tours.items():
        lines.append(f"  tour {name}: {len(p.frame_ids)} frames")
    return "\n".join(lines)
