"""``reloc experiment SPEC.yaml``: VideoReloc and the baselines over a rendered controlled-change design.

An experiment spec names the render job whose tours it reads (``render: demo.yaml``), the mapping
tour, the query path, the unchanged layout, the methods and the optional tables::

    name: demo
    render: demo.yaml                  # render job spec, relative to this file
    out: out/demo/experiment           # results folder
    mapping: {layout: apt_0, lighting: day, path: mapping}
    query: query                       # every layout x lighting tour of this path is a query tour
    unchanged: apt_0                   # the reference layout for Delta_R and kept
    map: build                         # VideoReloc's box map: build (from the mapping tour) | ground-truth
    methods: [videoreloc, videoreloc_oracle, fpfh_icp, appearance, one_frame]
    tables: [units, ablation]          # optional: Tables III and IV (Tables I and II, main and factors, always)
    one_frame_stride: 15               # one-frame units on every k-th frame (one registration each)
    detector: learned                  # the default: the shipped model (models/detector_160x120.onnx)
    # detector: {kind: learned, model: ../models/mine.onnx}   (a path relative to this file)
    # detector: {kind: oracle, miss_rate: 0.1}   (the rendered labels, optionally corrupted:
    #                                             reloc.frontend.detection.Corruption)
    config: {}                         # VideoReloc threshold overrides (reloc/config.py sections)
    appearance: {}                     # AppearanceConfig overrides
    fpfh_icp: {}                       # FpfhConfig overrides
    sensors: [ideal]                   # the RGB-D cameras the tours are read through (formats.sensors):
                                       # presets (ideal, structured_light, tof) or sensor YAML files
                                       # (relative to this file); a design factor like lighting and layout
    map_sensor: same                   # the mapping tour through the query's sensor (same) or one sensor
    seed: 0                            # VideoReloc's RANSAC seed and the sensors' noise seed
    workers: 2

Methods and the rows they give (``key`` = method.mode, used by ``reloc check``):

* ``videoreloc``: ``videoreloc.causal`` and ``videoreloc.closure`` (paper Sec. IV-A), with the spec's
  detector on the queries and a map built with it;
* ``videoreloc_oracle``: the same with oracle detections (the rendered labels) on the queries and
  a map built from the oracle's (or the ground-truth map with ``map: ground-truth``): the upper
  bound, ``VideoReloc (oracle detections)``, so the gap a real detector leaves is a reported figure;
* ``appearance``: ORB (or SIFT) + retrieval + PnP-RANSAC per frame (``appearance.causal``; only frames
  with RGB are localized and evaluated) and its clip-rigid variant (``appearance.closure``);
* ``fpfh_icp``: clip-rigid FPFH + RANSAC + ICP against a 5 cm point map (``fpfh_icp.closure``);
* ``one_frame``: the one-frame object-based unit (``one_frame.causal``; every k-th frame);
* external methods (mappings in ``methods``: another relocalizer as a command on exported tours, or a
  folder of its trajectories): ``NAME.causal`` (or ``NAME.closure``), see :mod:`reloc.experiments.external`.

A detector that sees images (``learned``, ``onnx``) looks only at frames with RGB: every
``config.observation.stride``-th query frame (the paper's every fifth frame) and every
``one_frame_stride``-th for the one-frame unit, so the render job's query designs must render RGB
there (``rgb_every`` dividing both), which the spec check says before anything runs; the map is
built from the mapping tour's RGB frames.

Sensors (``formats.sensors``): every query tour is read through every sensor of ``sensors``, seeded
per (tour, frame, sensor, ``seed``), so every method sees the same noisy frames (external command
methods through exports read with the same sensor). A query tour read through a sensor other than
``ideal`` is named ``TOUR@SENSOR`` (its runs are ``runs/METHOD/TOUR@SENSOR``). The map is built from
the mapping tour read through the query's own sensor (``map_sensor: same``: the same camera maps
and queries, as on real data; maps of sensor S go to ``maps/S/``) or through one named sensor for
every query (``map_sensor: ideal``: clean maps, noisy queries). Tables I and II's lighting and layout
columns use the reference sensor's tours (``ideal`` when listed, else the first); Table II gains a
column per sensor and its difference to the reference, and a sensor table (``tables/sensors.md``)
gives VideoReloc's odometry drift and clip end reasons per sensor (``tables.sensor_table``).

The clip-rigid controls reuse VideoReloc's clip partition and within-clip odometry
(``clip_poses.npz`` of its run), as the paper's dagger rows do.

Resumable: every (method, tour) result and every map is written atomically and marked done with
a key of what it depends on: its input files' content, its settings and the code that computes it
(``code_fingerprint``); a rerun does only what is missing or changed. Results, tables, plots and
the report go to ``out`` (layout in ``results.json``, see :mod:`reloc.experiments.tables`).
"""

from __future__ import annotations

import ast
import concurrent.futures as cf
import dataclasses
import functools
import hashlib
import json
import math
import multiprocessing as mp
import os
import platform
import sys
import time
from importlib import metadata
from pathlib import Path

from formats.atomic import write_json_atomic, write_text_atomic
from formats.camera import write_tum
from formats.design import DESIGN_FILE, list_tours, read_design, tour_name
from formats.errors import SceneFormatError, UserError, check_output_folder
from formats.sensors import load_sensor
from formats.tour import Tour
from formats.yamlfile import read_yaml

from . import tables
from .tables import ABLATIONS, ablation_name, reading_name
from .units import DEFAULT_LENGTHS

SPEC_KEYS = {"name", "description", "render", "tours", "out", "mapping", "query", "unchanged", "map", "methods",
             "tables", "one_frame_stride", "detector", "config", "appearance", "fpfh_icp", "workers", "seed",
             "sensors", "map_sensor"}
METHODS = ("videoreloc", "videoreloc_oracle", "fpfh_icp", "appearance", "one_frame")
DETECTORS = ("learned", "oracle", "onnx")
ORACLE = {"kind": "oracle", "model": None, "corruption": {}}  # a spec's detector: the rendered labels
TABLES = ("units", "ablation")
DONE = "done.json"


@dataclasses.dataclass
class ExperimentSpec:
    name: str
    source: Path
    render: Path
    tours_root: Path
    out: Path
    mapping: dict
    query: str
    unchanged: str
    map: str = "build"
    methods: tuple = METHODS
    tables: tuple = ()
    one_frame_stride: int = 15
    detector: dict = dataclasses.field(default_factory=lambda: dict(ORACLE))
    config: dict = dataclasses.field(default_factory=dict)
    appearance: dict = dataclasses.field(default_factory=dict)
    fpfh_icp: dict = dataclasses.field(default_factory=dict)
    workers: int = 2
    seed: int = 0
    description: str = ""
    externals: tuple = ()  # external.ExternalMethod, named in methods too
    # the sensors queries are read through: {"name", "spec" (preset name or absolute file), "params"}
    sensors: tuple = ()
    map_sensor: dict | None = None  # None: the query's own sensor (map_sensor: same)

    def __post_init__(self):
        if not self.sensors:
            self.sensors = (_sensor_entry("ideal", None, "sensors[0]"),)

    @property
    def sensor_names(self) -> list[str]:
        return [s["name"] for s in self.sensors]

    @property
    def reference_sensor(self) -> str:
        """The sensor of Tables I and II's lighting and layout columns: ideal when listed, else the first."""
        names = self.sensor_names
        return "ideal" if "ideal" in names else names[0]

    def sensor(self, name: str) -> dict:
        for s in self.sensors:
            if s["name"] == name:
                return s
        if self.map_sensor is not None and self.map_sensor["name"] == name:
            return self.map_sensor
        raise KeyError(name)

    def map_sensor_of(self, name: str) -> str:
        """The sensor the map used by queries read through sensor ``name`` is built with."""
        return name if self.map_sensor is None else self.map_sensor["name"]

    @property
    def detector_label(self) -> str:
        """How tables name the detector: ``learned (detector_160x120.onnx)``, ``oracle``, ..."""
        d = self.detector
        if d.get("model"):
            return f"{d['kind']} ({Path(d['model']).name})"
        corr = {k: v for k, v in d.get("corruption", {}).items() if v and k != "seed"}
        return d["kind"] + (" (corrupted: " + ", ".join(f"{k} {v}" for k, v in corr.items()) + ")" if corr else "")


def _fail(src, field, msg):
    raise SceneFormatError(src, field, msg)


def _sensor_entry(value, src, field) -> dict:
    """One sensor of a spec's ``sensors``: a preset name or a YAML file relative to the spec. Loaded
    here, so that an unknown preset or a bad parameter stops the experiment before anything runs."""
    from formats.sensors import PRESET_DIR

    if not isinstance(value, str) or not value:
        _fail(src, field, f"expected a sensor preset name or a sensor YAML file, got {value!r}")
    is_file = value.lower().endswith((".yaml", ".yml", ".json")) or "/" in value or "\\" in value
    spec = str((Path(src).parent / value).resolve()) if is_file and src is not None else value
    if is_file and not Path(spec).is_file():
        _fail(src, field, f"sensor file {spec} not found")
    try:
        s = load_sensor(spec)
    except SceneFormatError as e:
        if not is_file and str(PRESET_DIR) in str(e):  # an unknown preset: name the spec's field
            _fail(src, field, str(e).split(": ", 2)[-1])
        raise
    if s.name == "ideal" and not s.is_ideal:
        _fail(src, field, f"{spec}: the name 'ideal' is the preset without effects; give this sensor another name")
    params = {"depth": dataclasses.asdict(s.depth), "color": dataclasses.asdict(s.color)}
    return {"name": s.name, "spec": spec, "params": json.loads(json.dumps(params, default=str))}


def _sensors_of(doc: dict, src) -> tuple[tuple, dict | None]:
    v = doc.get("sensors", ["ideal"])
    if isinstance(v, str):
        v = [v]
    if not isinstance(v, list) or not v:
        _fail(src, "sensors", f"expected a non-empty list of sensor presets or files, got {v!r}")
    out = []
    for i, x in enumerate(v):
        e = _sensor_entry(x, src, f"sensors[{i}]")
        if e["name"] in [o["name"] for o in out]:
            _fail(src, f"sensors[{i}]", f"sensor {e['name']!r} is listed twice")
        out.append(e)
    m = doc.get("map_sensor", "same")
    if m == "same":
        return tuple(out), None
    ms = _sensor_entry(m, src, "map_sensor")
    same_name = [o for o in out if o["name"] == ms["name"]]
    if same_name and same_name[0]["params"] != ms["params"]:
        _fail(src, "map_sensor", f"{ms['name']!r} differs from the sensor of that name in sensors")
    return tuple(out), ms


def _mapping_of(v, src, field) -> dict:
    if v is None:
        return {}
    if not isinstance(v, dict):
        _fail(src, field, f"expected a mapping, got {v!r}")
    return dict(v)


def _check_overrides(cls, d: dict, src, field) -> None:
    known = {f.name for f in dataclasses.fields(cls)}
    for k in d:
        if k not in known:
            _fail(src, f"{field}.{k}", f"unknown setting; allowed: {', '.join(sorted(known))}")


def load_experiment(path) -> ExperimentSpec:
    """Read and validate an experiment spec; every error names the file and the key."""
    from ..config import Config

    src = Path(path)
    if not src.is_file():
        raise UserError(f"{src}: experiment spec not found")
    doc = read_yaml(src)
    if not isinstance(doc, dict):
        _fail(src, None, "expected a mapping at the top level")
    unknown = sorted(map(str, set(doc) - SPEC_KEYS))
    if unknown:
        _fail(src, unknown[0], f"unknown key; allowed: {', '.join(sorted(SPEC_KEYS))}")
    for k in ("name", "render", "out", "mapping", "query", "unchanged"):
        if doc.get(k) in (None, ""):
            _fail(src, k, "missing")
    render = (src.parent / str(doc["render"])).resolve()
    if not render.is_file():
        _fail(src, "render", f"render job spec {render} not found")
    render_doc = read_yaml(render)
    job_out = render_doc.get("out") if isinstance(render_doc, dict) else None
    if not doc.get("tours") and not isinstance(job_out, str):
        raise SceneFormatError(render, "out", "expected the render job's output folder (or give tours: in the experiment spec)")
    mapping = _mapping_of(doc["mapping"], src, "mapping")
    for k in ("layout", "lighting", "path"):
        if not isinstance(mapping.get(k), str):
            _fail(src, f"mapping.{k}", "expected a name")
    methods = doc.get("methods", list(METHODS))
    if isinstance(methods, str):
        methods = [methods]
    if not isinstance(methods, list) or not methods:
        _fail(src, "methods", f"expected a non-empty list of {', '.join(METHODS)} or external methods")
    externals = []
    for i, m in enumerate(methods):
        if isinstance(m, dict):  # another relocalizer: a command on exported tours, or trajectories (external.py)
            from .external import parse_external

            externals.append(parse_external(m, src, f"methods[{i}]", METHODS))
            if externals[-1].name in [e.name for e in externals[:-1]]:
                _fail(src, f"methods[{i}].name", f"{externals[-1].name!r} is used twice")
        elif m not in METHODS:
            _fail(src, f"methods[{i}]", f"unknown method {m!r}; known: {', '.join(METHODS)}, or a mapping with name and "
                                        "command (or trajectories)")
    methods = [m["name"] if isinstance(m, dict) else m for m in methods]
    if "videoreloc" not in methods and {"fpfh_icp", "appearance"} & set(methods):
        _fail(src, "methods", "the clip-rigid controls reuse VideoReloc's clips: add videoreloc")
    tables = doc.get("tables") or []
    if not isinstance(tables, list) or any(t not in TABLES for t in tables):
        _fail(src, "tables", f"expected a list of {', '.join(TABLES)} (main and factors are always made), got {tables!r}")
    if "ablation" in tables and "videoreloc" not in methods:
        _fail(src, "tables", "the ablation table needs the videoreloc method")
    if doc.get("map", "build") not in ("build", "ground-truth"):
        _fail(src, "map", f"expected build or ground-truth, got {doc.get('map')!r}")
    for k in ("one_frame_stride", "workers"):
        v = doc.get(k, 1)
        if isinstance(v, bool) or not isinstance(v, int) or v <= 0:
            _fail(src, k, f"expected a positive integer, got {v!r}")
    cfg = _mapping_of(doc.get("config"), src, "config")
    try:
        config = Config.from_dict(cfg, source=str(src))
    except (ValueError, TypeError) as e:
        raise UserError(str(e) if str(src) in str(e) else f"{src}: config: {e}") from None
    det = _detector_spec(doc.get("detector", "learned"), src)
    if det["kind"] == "oracle" and "videoreloc_oracle" in methods:
        _fail(src, "methods", "videoreloc_oracle is the oracle row beside another detector; "
                              "with detector: oracle it would repeat videoreloc")
    if det["kind"] != "oracle":
        strides = {"config.observation.stride": config.observation.stride}
        if "one_frame" in methods or "units" in tables:
            strides["one_frame_stride"] = int(doc.get("one_frame_stride", 15))
        _check_render_rgb(render, render_doc, str(doc["query"]), mapping, strides, det["kind"])
    app = _mapping_of(doc.get("appearance"), src, "appearance")
    fp = _mapping_of(doc.get("fpfh_icp"), src, "fpfh_icp")
    if app:
        from ..baselines.appearance import AppearanceConfig

        _check_overrides(AppearanceConfig, app, src, "appearance")
    if fp:
        from ..baselines.fpfh_icp import FpfhConfig

        _check_overrides(FpfhConfig, fp, src, "fpfh_icp")
    tours_root = Path(doc["tours"]) if doc.get("tours") else Path(job_out)
    sensors, map_sensor = _sensors_of(doc, src)
    seed = doc.get("seed", 0)
    if isinstance(seed, bool) or not isinstance(seed, int) or seed < 0:
        _fail(src, "seed", f"expected a non-negative integer, got {seed!r}")
    return ExperimentSpec(
        name=str(doc["name"]), source=src, render=render, tours_root=tours_root, out=Path(doc["out"]),
        mapping=mapping, query=str(doc["query"]), unchanged=str(doc["unchanged"]), map=doc.get("map", "build"),
        methods=tuple(methods), tables=tuple(tables), one_frame_stride=int(doc.get("one_frame_stride", 15)),
        detector=det, config=cfg, appearance=app, fpfh_icp=fp, workers=int(doc.get("workers", 2)),
        seed=seed, description=str(doc.get("description", "")), externals=tuple(externals),
        sensors=sensors, map_sensor=map_sensor,
    )


def _detector_spec(v, src) -> dict:
    """The spec's ``detector``: ``learned`` (the shipped model), ``oracle`` or a mapping with ``kind``,
    ``model`` (relative to the spec file) and, for the oracle, corruption settings. Returns
    ``{"kind", "model" (absolute path or None), "corruption" (dict)}``; a model file is opened here,
    so that a missing or corrupt one stops the experiment before anything runs."""
    from ..frontend.detection import Corruption
    from ..frontend.detection_learned import SHIPPED_MODEL

    d = {"kind": v} if isinstance(v, str) else _mapping_of(v, src, "detector")
    kind = d.pop("kind", "learned")
    if kind not in DETECTORS:
        _fail(src, "detector" if isinstance(v, str) else "detector.kind",
              f"expected one of {', '.join(DETECTORS)}, got {kind!r}")
    model = d.pop("model", None)
    class_map = d.pop("class_map", None)
    if kind == "oracle":
        if model is not None:
            _fail(src, "detector.model", "the oracle detector reads the rendered labels; it takes no model")
        _check_overrides(Corruption, d, src, "detector")
        try:
            Corruption(**d)
        except (TypeError, ValueError) as e:
            _fail(src, "detector", str(e))
        return {"kind": kind, "model": None, "corruption": dict(d)}
    fields = {f.name for f in dataclasses.fields(Corruption)}
    for k in d:
        _fail(src, f"detector.{k}", "corrupts the oracle's detections (add kind: oracle)" if k in fields
              else "unknown setting; allowed: kind, model" + (", class_map" if kind == "onnx" else ""))
    if model is None:
        if kind == "onnx":
            _fail(src, "detector.model", "the onnx detector needs a model file")
        path = SHIPPED_MODEL
    else:
        path = (src.parent / str(model)).resolve()
    if not path.is_file():
        _fail(src, "detector.model", f"model file {path} not found")
    out = {"kind": kind, "model": str(path), "corruption": {}}
    if class_map is not None:
        if kind != "onnx":
            _fail(src, "detector.class_map", "only the onnx detector takes a class map")
        out["class_map"] = str((src.parent / str(class_map)).resolve())
    try:  # a corrupt or foreign model: one line naming the spec's field and the model file
        _open_detector(out, vocabulary=None)
    except UserError as e:
        raise UserError(f"{src}: detector.model: {e}") from None
    return out


def _open_detector(det: dict, vocabulary, classes=None, cfg=None):
    """The detector a spec's ``detector`` names (``_detector_spec``'s dict)."""
    from ..frontend.detection import Corruption, DetectorSpec, build_detector

    spec = DetectorSpec(kind=det["kind"], corruption=Corruption(**det.get("corruption", {})), model=det.get("model"),
                        class_map=det.get("class_map"))
    return build_detector(spec, classes or {}, vocabulary=vocabulary, config=cfg)


def _check_render_rgb(render: Path, doc, query: str, mapping: dict, strides: dict, kind: str) -> None:
    """A detector that sees images needs RGB where it looks: in the render job's query designs on
    every frame a multiple of each of ``strides`` ({setting: frames}), in the mapping design at all.
    One line naming the render spec and the design's field otherwise."""
    designs = doc.get("designs") if isinstance(doc, dict) else None
    if not isinstance(designs, list):
        return  # the render job's own check names what is wrong with it
    for i, d in enumerate(designs):
        if not isinstance(d, dict):
            continue
        p = d.get("path")
        name = p.get("name") if isinstance(p, dict) else p
        is_query, is_map = name == query, name == mapping.get("path")
        if not (is_query or is_map):
            continue
        if not d.get("lightings"):
            raise SceneFormatError(render, f"designs[{i}].lightings",
                                   f"a geometry-only design renders no RGB, and the {kind} detector sees only RGB "
                                   f"frames; give it lightings")
        k = d.get("rgb_every", 1)
        if is_query and isinstance(k, int) and k > 0:
            for what, n in strides.items():
                if n % k:
                    raise SceneFormatError(render, f"designs[{i}].rgb_every",
                                           f"RGB on every {k}th frame, but the {kind} detector looks at every "
                                           f"{n}th query frame ({what}); use an rgb_every that divides {n}")


# ---------------------------------------------------------------------------------------------
# the design on disk


def design_tours(spec: ExperimentSpec) -> tuple[dict, dict]:
    """(query tours {name: info}, mapping tour info) of the design in ``spec.tours_root``, read from
    its files (``formats.design``): the planned tours from design.json, each tour from its meta.json
    (without design.json, the tours found there). Checks that they are rendered.

    Every query tour is there once per sensor of the spec, named ``reading_name(tour, sensor)``,
    with ``tour`` (the tour's name) and ``sensor`` in its info."""
    root = spec.tours_root
    found = list_tours(root)
    planned = read_design(root)
    if planned is None:
        planned = {n: {k: m.get(k) for k in ("layout", "lighting", "path")} for n, m in found.items()}
    where = f"the design in {root}"
    if not planned:
        raise UserError(f"{root}: no rendered design here (no {DESIGN_FILE}, no tour with a meta.json); "
                        f"run: synth render {spec.render}")
    missing = []

    def info(name, p) -> dict | None:
        d = root / name
        meta = found.get(name)
        if meta is None or not (d / "poses.txt").is_file():
            missing.append(name)
            return None
        if meta.get("complete") is False:
            missing.append(name + " (incomplete)")
            return None
        t = Tour(d)
        for s in spec.sensors + ((spec.map_sensor,) if spec.map_sensor else ()):  # before anything runs
            load_sensor(s["spec"]).check_resolution(t.intrinsics.width, t.intrinsics.height, str(d))
        return {"dir": str(d.resolve()), "layout": p["layout"], "lighting": p["lighting"], "path": p["path"],
                "rearranged": p["layout"] != spec.unchanged, "frames": len(t), "fps": t.fps, "rgb_every": t.rgb_every}

    m = spec.mapping
    mname = tour_name(m["layout"], m["lighting"], m["path"])
    if mname not in planned:
        _fail(spec.source, "mapping", f"{where} has no tour {mname}")
    queries = {n: p for n, p in planned.items() if p["path"] == spec.query and n != mname}
    if not queries:
        _fail(spec.source, "query", f"{where} has no tours of path {spec.query!r}")
    if spec.unchanged not in {p["layout"] for p in queries.values()}:
        _fail(spec.source, "unchanged", f"layout {spec.unchanged!r} has no query tour in {where}")
    out = {n: info(n, p) for n, p in queries.items()}
    mapping = info(mname, planned[mname])
    if missing:
        raise UserError(f"{root}: {len(missing)} tour(s) not rendered: {', '.join(missing[:4])}"
                        f"{' ...' if len(missing) > 4 else ''}; run: synth render {spec.render} --resume")
    read = {reading_name(n, s): {**t, "tour": n, "sensor": s} for s in spec.sensor_names for n, t in out.items()}
    return read, {**mapping, "tour": mname}


def _check_detector_inputs(spec: ExperimentSpec, queries: dict, mapping: dict) -> None:
    """Before anything is written: a detector that sees images has RGB where it looks in every
    rendered tour (their meta.json), and its model knows the classes of a ground-truth map."""
    det = spec.detector
    if det["kind"] == "oracle":
        return
    from ..config import Config
    from ..frontend.detector_base import check_rgb_schedule

    detector = _open_detector(det, None)
    stride = Config.from_dict(spec.config).observation.stride
    for t in {t["dir"]: t for t in queries.values()}.values():  # once per tour, whatever the sensors
        tour = Tour(t["dir"])
        check_rgb_schedule(tour, stride, detector, "observation.stride")
        if "one_frame" in spec.methods or "units" in spec.tables:
            check_rgb_schedule(tour, spec.one_frame_stride, detector, "one_frame_stride")
    mtour = Tour(mapping["dir"])
    if spec.map == "ground-truth":
        _open_detector(det, {b["class"] for b in mtour.objects()["boxes"]})
    else:
        check_rgb_schedule(mtour, None, detector, "mapping")


# ---------------------------------------------------------------------------------------------
# the code a result depends on

# The project's top-level packages (pyproject.toml's tool.setuptools.packages.find). A new one must
# be added here for the fingerprint to follow imports into it (tests check this list).
PROJECT_PACKAGES = ("formats", "reloc", "synth")
# Distributions whose version changes numbers: the numeric and image libraries reloc computes with.
LIBRARIES = ("numpy", "scipy", "open3d", "opencv-python-headless", "opencv-python", "OpenEXR", "onnxruntime")
SOURCE_ROOT = Path(__file__).resolve().parents[2]  # the folder holding the project's packages


def _module_file(root: Path, name: str) -> Path | None:
    """The source file of module ``name`` under ``root`` (a package's ``__init__.py``), or None."""
    p = root.joinpath(*name.split("."))
    for f in (p.with_suffix(".py"), p / "__init__.py"):
        if f.is_file():
            return f
    return None


def _imported_names(path: Path, module: str) -> set[str]:
    """Every module name an import statement of ``path`` may load, function-level ones included
    (``from a import b`` gives a and a.b: b may be a module)."""
    package = module if path.name == "__init__.py" else module.rpartition(".")[0]
    names: set[str] = set()
    for node in ast.walk(ast.parse(path.read_bytes(), filename=str(path))):
        if isinstance(node, ast.Import):
            names.update(a.name for a in node.names)
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                parts = package.split(".")
                base = ".".join(parts[: len(parts) - node.level + 1] + ([node.module] if node.module else []))
            else:
                base = node.module or ""
            names.add(base)
            names.update(f"{base}.{a.name}" for a in node.names)
    return names


def code_files(root: Path | None = None) -> list[Path]:
    """The sources whose code can compute a result: every module of the ``reloc`` package, and every
    module of the project's other packages (``PROJECT_PACKAGES``: formats, synth) that reloc imports, directly
    or through other such modules, with the ``__init__.py`` of each package on the way; found by
    reading the import statements. Sorted by path relative to ``root`` (default ``SOURCE_ROOT``)."""
    root = Path(root or SOURCE_ROOT)
    todo = sorted((root / "reloc").rglob("*.py"))
    seen = set(todo)
    while todo:
        f = todo.pop()
        module = ".".join(f.relative_to(root).with_suffix("").parts)
        for name in _imported_names(f, module.removesuffix(".__init__")):
            parts = name.split(".")
            if parts[0] not in PROJECT_PACKAGES:
                continue
            for k in range(1, len(parts) + 1):  # importing a.b.c runs a and a.b first
                g = _module_file(root, ".".join(parts[:k]))
                if g is not None and g not in seen:
                    seen.add(g)
                    todo.append(g)
    return sorted(seen, key=lambda f: f.relative_to(root).as_posix())


def library_versions() -> dict[str, str]:
    out = {"python": platform.python_version()}
    for dist in LIBRARIES:
        try:
            out[dist] = metadata.version(dist)
        except metadata.PackageNotFoundError:
            pass
    return out


def source_fingerprint(root: Path | None = None, versions: dict | None = None) -> str:
    """sha256 over ``code_files(root)`` (relative path and bytes of each) and the library versions."""
    root = Path(root or SOURCE_ROOT)
    h = hashlib.sha256()
    for f in code_files(root):
        data = f.read_bytes()
        h.update(f"{f.relative_to(root).as_posix()}\0{len(data)}\0".encode())
        h.update(data)
    h.update(json.dumps(library_versions() if versions is None else versions, sort_keys=True).encode())
    return h.hexdigest()[:16]


@functools.lru_cache(maxsize=1)
def code_fingerprint() -> str:
    """The fingerprint of the code this process computes with; part of every done-key, so that a
    change of reloc, of the synth modules it imports or of a numeric library recomputes the results
    (once per process: a few tens of files parsed and hashed)."""
    return source_fingerprint()


# ---------------------------------------------------------------------------------------------
# tasks (run in worker processes)


def _key(*parts) -> str:
    return hashlib.sha1(json.dumps(parts, sort_keys=True, default=str).encode()).hexdigest()[:16]


def _file_key(path) -> str:
    """What a result depends on in a file: its content (a rebuilt identical map changes nothing)."""
    h = hashlib.sha1()
    with open(path, "rb") as f:
        for block in iter(lambda: f.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()[:16]


def _ground_truth_key(tour_dir) -> str:
    """What a ground-truth map depends on: the content of the tour's objects.json."""
    return "ground-truth:" + _file_key(Path(tour_dir) / "objects.json")


def is_done(d: Path, key: str) -> bool:
    try:
        return json.loads((d / DONE).read_text()).get("key") == key
    except (OSError, ValueError):
        return False


def _mark_done(d: Path, key: str, seconds: float, extra: dict | None = None) -> None:
    write_json_atomic(d / DONE, {"key": key, "seconds": round(seconds, 2), **(extra or {})})


def _config(spec_config: dict, variant=None):
    from ..config import Config

    cfg = Config.from_dict(spec_config)
    if variant is not None:
        orient, run_level, adaptive = variant
        if not orient:
            cfg = cfg.replace("refinement.orientation_aware", False)
        if not run_level:
            cfg = cfg.replace("backend.run_level", False)
        if not adaptive:
            cfg = cfg.replace("clips.adaptive", False).replace("clips.start_frames", 100)
    return cfg


def _detector(det: dict, tour, bmap, cfg):
    """The spec's detector for one query tour, asked for the map's classes."""
    return _open_detector(det, bmap.class_set, tour.class_names(), cfg.detection)


_CACHE: dict = {}


def _load(kind: str, path: str):
    k = (kind, path, os.stat(path).st_mtime_ns)
    if k not in _CACHE:
        if kind == "boxes":
            from ..map.boxmap import BoxMap

            _CACHE[k] = BoxMap.load(path)
        elif kind == "appearance":
            from ..baselines.appearance import AppearanceMap

            _CACHE[k] = AppearanceMap.load(path)
        else:
            from ..baselines.fpfh_icp import PointMap

            _CACHE[k] = PointMap.load(path)
    return _CACHE[k]


def run_map_task(task: dict) -> dict:
    """Build one map (box map, FPFH point map or appearance keyframe map) from the mapping tour."""
    t0 = time.perf_counter()
    out = Path(task["file"])
    out.with_name(out.name + ".done.json").unlink(missing_ok=True)
    tour = Tour(task["tour"], sensor=task.get("sensor"), sensor_seed=task.get("sensor_seed", 0))
    if task["kind"] == "boxes":
        from ..map.build import build_map
        from ..map.document import dumps_map, map_from_tour

        if task["source"] == "ground-truth":
            doc = map_from_tour(tour.root)
        else:
            det = task["detector"]
            detector = None if det["kind"] == "oracle" else _open_detector(det, None, tour.class_names())
            doc, report = build_map(tour, detector=detector, progress=False)  # the Tour: read through its sensor
            if not doc["boxes"]:
                raise UserError(report["warnings"][0] if report["warnings"] else f"{tour.root}: no boxes built")
            from ..map.scoring import errors_against_ground_truth

            write_json_atomic(tables.map_report_path(out),
                              {"build": report, "errors": errors_against_ground_truth(tour, doc)})
        write_text_atomic(out, dumps_map(doc))
    elif task["kind"] == "appearance":
        from ..baselines.appearance import AppearanceConfig, AppearanceMap

        AppearanceMap.build(tour, cfg=AppearanceConfig(**task["options"])).save(out)
    else:
        from ..baselines.fpfh_icp import FpfhConfig, PointMap

        PointMap.build(tour, cfg=FpfhConfig(**task["options"])).save(out)
    s = time.perf_counter() - t0
    write_json_atomic(out.with_name(out.name + ".done.json"),
                      {"key": task["key"], "seconds": round(s, 2), "code": task["code"]})
    return {"kind": task["kind"], "seconds": s}


def run_tour_task(task: dict) -> dict:
    """One method on one query tour; writes its trajectories into ``task['dir']`` and marks it done."""
    from ..backend.run import load_clip_poses, relocalize

    t0 = time.perf_counter()
    d = Path(task["dir"])
    d.mkdir(parents=True, exist_ok=True)
    (d / DONE).unlink(missing_ok=True)  # from here until done, this run's files are not a result
    tour = Tour(task["tour"], sensor=task.get("sensor"), sensor_seed=task["seed"])
    method = task["method"]
    extra: dict = {}
    if method in ("videoreloc", "videoreloc_oracle") or method.startswith("ablation_"):
        bmap = _load("boxes", task["map"])
        cfg = _config(task["config"], task.get("variant"))
        s = relocalize(tour, bmap, d, cfg=cfg, detector=_detector(task["detector"], tour, bmap, cfg), seed=task["seed"],
                       progress=False)
        extra = {"fps": s["fps"], "clips": s["clips"]}
    elif method == "fpfh_icp":
        from ..baselines.fpfh_icp import FpfhConfig, run_fpfh_icp

        s = run_fpfh_icp(tour, _load("fpfh", task["fpfh_map"]), load_clip_poses(task["clips"]), d,
                         cfg=FpfhConfig(**task["options"]), progress=False)
        extra = {k: s[k] for k in ("clips", "registered") if k in s}
    elif method == "appearance":
        from ..baselines.appearance import AppearanceConfig, run_appearance

        s = run_appearance(tour, _load("appearance", task["appearance_map"]), d,
                           clip_poses=load_clip_poses(task["clips"]), cfg=AppearanceConfig(**task["options"]),
                           clip_rigid=_config(task["config"]).clip_rigid, progress=False)
    elif method == "one_frame":
        from .units import run_units

        bmap = _load("boxes", task["map"])
        lengths = tuple(task["lengths"])
        est: dict = {}
        cfg = _config(task["config"])
        rep = run_units(tour, bmap, lengths=lengths, detector=_detector(task["detector"], tour, bmap, cfg),
                        cfg=cfg, one_frame_stride=task["stride"], seed=task["seed"],
                        progress=False, estimates=est)
        one = est.get(1, {})
        fr = sorted(one)
        write_tum(d / "causal.txt", [one[i] for i in fr], fps=tour.fps, frames=fr,
                  header=f"one-frame object units on every {task['stride']}th frame of {tour.root}")
        write_json_atomic(d / "units.json", rep)
    else:
        raise ValueError(f"unknown method {method!r}")
    seconds = time.perf_counter() - t0
    _mark_done(d, task["key"], seconds, {**extra, "code": task["code"]})
    return {"method": method, "tour": task["tour_name"], "seconds": seconds}


# ---------------------------------------------------------------------------------------------
# the experiment


def _pool(workers: int):
    if workers <= 1:
        return None
    # spawn: Open3D and OpenCV keep thread pools that a fork would copy mid-state
    return cf.ProcessPoolExecutor(max_workers=workers, mp_context=mp.get_context("spawn"))


class _Runner:
    """Runs tasks in a process pool (or inline), with dependencies and a progress bar."""

    def __init__(self, workers: int, progress: bool, total: int, desc: str):
        from tqdm import tqdm

        self.pool = _pool(workers)
        self.bar = tqdm(total=total, desc=desc, unit="task", file=sys.stderr, disable=not progress)
        self.failed: dict[str, str] = {}
        self.seconds: dict[str, float] = {}

    def run(self, tasks: list[tuple[str, callable, dict, list[str]]]) -> None:
        """tasks: (id, function, argument, ids it waits for). A task whose dependency failed is skipped."""
        waiting = list(tasks)
        done: set[str] = set()
        running: dict = {}

        def ready():
            nonlocal waiting
            keep = []
            for t in waiting:
                if any(x in self.failed for x in t[3]):
                    self.failed[t[0]] = "skipped: " + next(x for x in t[3] if x in self.failed) + " failed"
                    self.bar.update(1)
                elif all(x in done for x in t[3]):
                    yield t
                else:
                    keep.append(t)
            waiting = keep

        while waiting or running:
            for tid, fn, arg, _ in list(ready()):
                if self.pool is None:
                    self._finish(tid, lambda: fn(arg), done)
                else:
                    running[self.pool.submit(fn, arg)] = tid
            if not running:
                continue
            finished, _ = cf.wait(running, return_when=cf.FIRST_COMPLETED)
            for f in finished:
                self._finish(running.pop(f), f.result, done)

    def _finish(self, tid, get, done) -> None:
        try:
            r = get()
            self.seconds[tid] = r["seconds"]
            done.add(tid)
        except Exception as e:  # one failure must not lose the others (a BrokenProcessPool is a RuntimeError)
            msg = str(e) if isinstance(e, UserError) else f"{type(e).__name__}: {e}"
            self.failed[tid] = msg.splitlines()[0] if msg else type(e).__name__
        self.bar.update(1)

    def close(self) -> None:
        self.bar.close()
        if self.pool is not None:
            self.pool.shutdown()


def run_experiment(spec: ExperimentSpec, out: Path | None = None, workers: int | None = None,
                   progress: bool = True, plots: bool = True) -> dict:
    """Maps, every method on every query tour, evaluation, tables, plots and the report."""
    t_start = time.time()
    out = Path(out or spec.out)
    check_output_folder(out)
    workers = workers or spec.workers
    queries, mapping = design_tours(spec)
    _check_detector_inputs(spec, queries, mapping)
    out.mkdir(parents=True, exist_ok=True)
    maps_dir = out / "maps"
    maps_dir.mkdir(exist_ok=True)

    # 1. maps from the mapping tour, once per sensor a map is read through
    map_tasks = []
    map_sensors = list(dict.fromkeys(spec.map_sensor_of(s) for s in spec.sensor_names))
    map_files = {ms: _map_files(spec, maps_dir, ms) for ms in map_sensors}
    options = {"boxes": {}, "boxes_oracle": {}, "fpfh": spec.fpfh_icp, "appearance": spec.appearance}
    detectors = {"boxes": spec.detector, "boxes_oracle": ORACLE}
    model_key = _file_key(spec.detector["model"]) if spec.detector.get("model") else None
    code = code_fingerprint()  # every key below holds it: a change of the code recomputes
    for ms, files in map_files.items():
        for kind, f in files.items():
            source = det = None
            if kind.startswith("boxes"):
                source = _ground_truth_key(mapping["dir"]) if spec.map == "ground-truth" else spec.map
                det = None if spec.map == "ground-truth" else detectors[kind]
            sensor_key = None if spec.map == "ground-truth" and kind.startswith("boxes") else _sensor_key(spec, ms)
            key = _key(kind, _file_key(Path(mapping["dir"]) / "poses.txt"), mapping, source, options[kind], code,
                       det, model_key if det is spec.detector else None, sensor_key)
            try:
                done = json.loads(f.with_name(f.name + ".done.json").read_text()).get("key") == key and f.is_file()
            except (OSError, ValueError):
                done = False
            if not done:
                f.parent.mkdir(parents=True, exist_ok=True)
                map_tasks.append((f"map/{kind}" + ("" if ms == "ideal" else f"@{ms}"), run_map_task,
                                  {"kind": kind.removesuffix("_oracle"), "file": str(f), "tour": mapping["dir"],
                                   "source": spec.map, "detector": det, "options": options[kind], "key": key,
                                   "code": code, "sensor": spec.sensor(ms)["spec"], "sensor_seed": spec.seed}, []))
    runner = _Runner(workers, progress, len(map_tasks), f"{spec.name}: maps")
    try:
        runner.run(map_tasks)
    finally:
        runner.close()
    if runner.failed:
        raise UserError("map building failed: " + "; ".join(f"{k}: {v}" for k, v in runner.failed.items()))
    map_seconds = dict(runner.seconds)

    # 2. every method on every query tour (read through every sensor)
    map_keys = {ms: {k: _file_key(f) for k, f in files.items()} for ms, files in map_files.items()}
    tour_keys = {n: _file_key(Path(t["dir"]) / "poses.txt") + _file_key(Path(t["dir"]) / "meta.json")
                 + json.dumps(t, sort_keys=True) + json.dumps(_sensor_key(spec, t["sensor"]), sort_keys=True)
                 for n, t in queries.items()}
    tasks = []
    expected: dict[tuple[str, str], tuple[Path, str]] = {}
    methods = list(spec.methods)
    variants = [v for v in ABLATIONS if v != (True, True, True)] if "ablation" in spec.tables else []
    for name, t in queries.items():
        vr_dir = out / "runs" / "videoreloc" / name
        ms = spec.map_sensor_of(t["sensor"])
        files = map_files[ms]
        common = {"map": str(files["boxes"]), "config": spec.config, "detector": spec.detector, "model": model_key,
                  "seed": spec.seed, "code": code, "sensor": spec.sensor(t["sensor"])["spec"]}

        def add(method, deps, uses="boxes", **kw) -> str:
            d = out / "runs" / method / name
            arg = {**common, "method": method, "tour": t["dir"], "tour_name": name, "dir": str(d), **kw}
            arg["key"] = _key(arg, map_keys[ms][uses], tour_keys[name])
            expected[(method, name)] = (d, arg["key"])
            if not is_done(d, arg["key"]):
                tasks.append((f"{method}/{name}", run_tour_task, arg, [x for x in deps if x in scheduled]))
                scheduled.add(f"{method}/{name}")
            return arg["key"]

        scheduled: set[str] = set()
        # the controls reuse VideoReloc's clips: their key holds VideoReloc's, so they rerun with it
        vr_key = add("videoreloc", []) if "videoreloc" in methods else None
        if "videoreloc_oracle" in methods:
            add("videoreloc_oracle", [], uses="boxes_oracle", map=str(files["boxes_oracle"]), detector=ORACLE, model=None)
        vr_dep = [f"videoreloc/{name}"]
        if "fpfh_icp" in methods:
            add("fpfh_icp", vr_dep, uses="fpfh", fpfh_map=str(files["fpfh"]), clips=str(vr_dir), options=spec.fpfh_icp,
                vr=vr_key)
        if "appearance" in methods:
            add("appearance", vr_dep, uses="appearance", appearance_map=str(files["appearance"]), clips=str(vr_dir),
                options=spec.appearance, vr=vr_key)
        if "one_frame" in methods or "units" in spec.tables:
            add("one_frame", [], stride=spec.one_frame_stride,
                lengths=list(DEFAULT_LENGTHS if "units" in spec.tables else (1,)))
        for v in variants:
            add(ablation_name(v), [], variant=list(v))
    if spec.externals:
        _external_tasks(spec, out, mapping, queries, tour_keys, tasks, expected, progress)
    files = map_files[spec.map_sensor_of(spec.reference_sensor)]
    runner = _Runner(workers, progress, len(tasks), f"{spec.name}: runs")
    try:
        runner.run(tasks)
    finally:
        runner.close()
    run_seconds = dict(runner.seconds)

    # 3. evaluation, tables, plots, report
    # only results whose done marker holds the current key count; a failed or stale run has no poses
    valid = {mt for mt, (d, key) in expected.items() if is_done(d, key)}
    results = tables.evaluate_experiment(spec, out, queries, files, methods, variants, valid, map_files=map_files)
    results["seconds"] = _seconds(out, queries, methods, variants, files)
    results["seconds"]["this_run_wall"] = round(time.time() - t_start, 1)
    results["failed"] = runner.failed
    results["code"] = code
    write_json_atomic(out / "results.json", results)
    tables.write_tables(results, out)
    if plots:
        from .plots import plot_experiment
        from .report import write_report

        plot_experiment(out)
        write_report(out)
    results["_ran"] = {"maps": map_seconds, "runs": run_seconds}
    return results


def _external_tasks(spec: ExperimentSpec, out: Path, mapping: dict, queries: dict, tour_keys: dict, tasks: list,
                    expected: dict, progress: bool) -> None:
    """Exports (now, in this process: once per format, tour and sensor, cached), then a ``map_command``
    task per external method that has one (and map sensor) and a run task per method and query tour
    (``external.py``). A command reads exports of the tour read through the query's sensor; a folder
    of trajectories holds one file per query reading (``{tour}`` is ``TOUR@SENSOR`` beside ideal)."""
    from .external import export_dir, file_key, prepare_exports, run_external_map_task, run_external_task

    mtour = mapping["tour"]
    mappings = {reading_name(mtour, ms): {**mapping, "sensor": ms}
                for ms in dict.fromkeys(spec.map_sensor_of(s) for s in spec.sensor_names)}
    sensors = {n: (spec.sensor(n)["spec"] if n != "ideal" else None) for n in
               {t["sensor"] for t in list(queries.values()) + list(mappings.values())}}
    export_keys = prepare_exports(out, list(spec.externals), mappings, queries, progress, sensors=sensors,
                                  sensor_seed=spec.seed, mapping_of=lambda t: reading_name(mtour, spec.map_sensor_of(t["sensor"])))
    for m in spec.externals:
        md = m.to_dict()
        map_keys: dict = {}
        map_ids: dict = {}
        for mname in mappings:
            if not (m.kind == "command" and m.map_command):
                continue
            ms = mappings[mname]["sensor"]
            suffix = "" if ms == "ideal" else f"@{ms}"
            map_out = out / "maps" / (m.name + suffix)
            map_keys[mname] = _key("external-map", md, export_keys[(m.export, str(m.exposure), mname)])
            map_ids[mname] = f"map/{m.name}{suffix}"
            done = out / "maps" / f"{m.name}{suffix}.done.json"
            try:
                fresh = json.loads(done.read_text()).get("key") == map_keys[mname]
            except (OSError, ValueError):
                fresh = False
            if not fresh:
                tasks.append((map_ids[mname], run_external_map_task, {"method": md, "dir": str(map_out),
                                                                      "key": map_keys[mname],
                                                                      "mapping": str(export_dir(out, m, mname))}, []))
            else:
                map_ids[mname] = None
        for name, t in queries.items():
            d = out / "runs" / m.name / name
            arg = {"method": md, "tour": t["dir"], "tour_name": name, "dir": str(d), "code": None}
            mname = reading_name(mtour, spec.map_sensor_of(t["sensor"]))
            map_id = map_ids.get(mname)
            if m.kind == "command":
                ms = mappings[mname]["sensor"]
                map_out = out / "maps" / (m.name + ("" if ms == "ideal" else f"@{ms}")) if m.map_command else None
                arg.update(mapping_export=str(export_dir(out, m, mname)), query_export=str(export_dir(out, m, name)),
                           scene=str(out / "exports" / export_dir(out, m, name).parent.name / "scenes" / name),
                           map_out=str(map_out) if map_out else None)
                inputs = (export_keys[(m.export, str(m.exposure), mname)], export_keys[(m.export, str(m.exposure), name)],
                          map_keys.get(mname))
            else:
                from .external import _fill_path

                f = Path(m.trajectories) / _fill_path(m.file, {"tour": name, "name": m.name})
                names = None
                if m.names:
                    names = file_key(Path(m.names) / "export.json" if Path(m.names).is_dir() else m.names)
                inputs = (file_key(f), names)
            arg["key"] = _key("external", md, inputs, tour_keys[name])
            expected[(m.name, name)] = (d, arg["key"])
            if not is_done(d, arg["key"]):
                tasks.append((f"{m.name}/{name}", run_external_task, arg, [map_id] if map_id else []))


def _map_files(spec: ExperimentSpec, maps_dir: Path, sensor: str) -> dict[str, Path]:
    """The map files of one map sensor: ``maps/`` for the ideal sensor, ``maps/SENSOR/`` for another."""
    d = maps_dir if sensor == "ideal" else maps_dir / sensor
    files = {"boxes": d / "videoreloc_map.json"}
    if "videoreloc_oracle" in spec.methods:
        files["boxes_oracle"] = d / "videoreloc_oracle_map.json"
    if "fpfh_icp" in spec.methods:
        files["fpfh"] = d / "fpfh_map.npz"
    if "appearance" in spec.methods:
        files["appearance"] = d / "appearance_map.npz"
    return files


def _sensor_key(spec: ExperimentSpec, name: str) -> dict | None:
    """What a result depends on in the sensor it was read through (None: the ideal sensor)."""
    s = spec.sensor(name)
    return None if name == "ideal" else {"name": name, "params": s["params"], "seed": spec.seed}


def _seconds(out: Path, queries: dict, methods: list, variants: list, files: dict) -> dict:
    """Compute time of each method summed over tours (from the done markers), and of each map."""
    s: dict = {}
    for kind, f in files.items():
        try:
            s[f"map_{kind}"] = json.loads(f.with_name(f.name + ".done.json").read_text())["seconds"]
        except (OSError, ValueError, KeyError):
            s[f"map_{kind}"] = None
    for m in list(methods) + [ablation_name(v) for v in variants]:
        tot = 0.0
        for name in queries:
            try:
                tot += json.loads((out / "runs" / m / name / DONE).read_text())["seconds"]
            except (OSError, ValueError, KeyError):
                tot = math.nan
        s[m] = None if math.isnan(tot) else round(tot, 1)
    return s


# ---------------------------------------------------------------------------------------------
# CLI


def cmd_experiment(args) -> int:
    spec = load_experiment(args.spec)
    if args.tours:
        spec.tours_root = Path(args.tours)
    r = run_experiment(spec, out=Path(args.out) if args.out else None, workers=args.workers,
                       progress=not args.quiet, plots=not args.no_plots)
    out = Path(args.out or spec.out)
    print(tables.format_all(out))
    ran = r["_ran"]
    print(f"\n{len(ran['runs'])} runs and {len(ran['maps'])} maps computed now "
          f"({r['seconds']['this_run_wall']:.0f} s wall); results, tables"
          f"{', plots and report' if not args.no_plots else ''} in {out}")
    if r["failed"]:
        for k, v in r["failed"].items():
            print(f"failed: {k}: {v}", file=sys.stderr)
        return 1
    return 0


def register_cli(subparsers) -> None:
    p = subparsers.add_parser("experiment", help="VideoReloc and the baselines over a rendered design: tables, plots, report")
    p.add_argument("spec", metavar="SPEC.yaml", help="experiment spec (see reloc/experiment.py)")
    p.add_argument("--out", help="results folder (default: the spec's out)")
    p.add_argument("--tours", help="folder of the rendered tours (default: the render spec's out)")
    p.add_argument("--workers", type=int, help="processes at a time (default: the spec's workers)")
    p.add_argument("--no-plots", action="store_true", help="tables only")
    p.add_argument("--quiet", action="store_true")
    p.set_defaults(fn=cmd_experiment)
