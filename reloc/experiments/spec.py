"""The experiment spec (``reloc experiment SPEC.yaml``): its keys, their checks, and ``ExperimentSpec``.

Read and validated here before anything runs (every error names the file and the key); run by
:mod:`reloc.experiments.runner`. An experiment spec names the render job whose tours it reads
(``render: demo``), the mapping tour, the query path, the unchanged layout, the methods and
the optional tables::

    name: demo
    render: demo                       # render job spec: a file relative to this one, or a shipped name (render_jobs)
    out: out/demo/experiment           # results folder
    mapping: {layout: apt_0, lighting: day, path: mapping}   # lighting left out: a geometry-only design
    query: query                       # every layout x lighting tour of this path is a query tour
    unchanged: apt_0                   # the reference layout for Delta_R and kept
    map: build                         # VideoReloc's box map: build (from the mapping tour) | ground-truth
    methods: [videoreloc, videoreloc_oracle, fpfh_icp, appearance, one_frame]
    tables: [units, ablation]          # optional: Tables III and IV (Tables I and II, main and factors, always)
    one_frame_stride: 15               # one-frame units on every k-th frame (one registration each)
    detector: learned                  # the default: the shipped model (reloc/models/detector_v2_160x120.onnx)
    # detector: {kind: learned, model: ../models/mine.onnx}   (a path relative to this file)
    # detector: {kind: oracle, miss_rate: 0.1}   (the rendered labels, optionally corrupted:
    #                                             reloc.detection.oracle.Corruption)
    config: {}                         # VideoReloc threshold overrides (reloc/config.py sections)
    appearance: {}                     # AppearanceConfig overrides
    fpfh_icp: {}                       # FpfhConfig overrides
    sensors: [ideal]                   # the RGB-D cameras the tours are read through (vrformats.sensors):
                                       # presets (ideal, structured_light, tof) or sensor YAML files
                                       # (relative to this file); a design factor like lighting and layout
    map_sensor: same                   # the mapping tour through the query's sensor (same) or one sensor
    seed: 0                            # VideoReloc's RANSAC seed and the sensors' noise seed
    replicates: 1                      # N > 1: the experiment N times, reseeded (replicate_spec); the spread
                                       # of every figure across them beside its interval
    intervals: {level: 0.95, resamples: 2000, segment_frames: 100, seed: 0}
                                       # the figures' intervals (reloc.experiments.intervals): the defaults
    sweep: {factor: rearrangement, levels: {0: apt_0, 0.5: apt_0_g050, 1.0: apt_0_g100}, fraction: 0.8}
                                       # optional: one graded factor, its levels' recall, ratios and breaking
                                       # points (reloc.experiments.sweep; tables/sweep.md, plots/sweep.png)
    workers: 2

Methods and the rows they give (``key`` = method.mode, used by ``reloc check``); each is one module of
:mod:`reloc.experiments.methods`, registered by name, and a spec may name any registered method:

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

Sensors (``vrformats.sensors``): every query tour is read through every sensor of ``sensors``, seeded
per (tour, frame, sensor, ``seed``), so every method sees the same noisy frames (external command
methods through exports read with the same sensor). A query tour read through a sensor other than
``ideal`` is named ``TOUR@SENSOR`` (its runs are ``runs/METHOD/TOUR@SENSOR``). The map is built from
the mapping tour read through the query's own sensor (``map_sensor: same``: the same camera maps
and queries, as on real data; maps of sensor S go to ``maps/S/``) or through one named sensor for
every query (``map_sensor: ideal``: clean maps, noisy queries). Tables I and II's lighting and layout
columns use the reference sensor's tours (``ideal`` when listed, else the first); Table II gains a
column per sensor and its difference to the reference, and a sensor table (``tables/sensors.md``)
gives VideoReloc's odometry drift and clip end reasons per sensor (``tables.sensor_table``).
"""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path

from vrformats import fields
from vrformats.errors import SceneFormatError, UserError
from vrformats.sensors import load_sensor
from vrformats.yamlfile import read_yaml

from . import methods as registry
from .intervals import IntervalSettings
from .methods.common import ORACLE, open_detector  # noqa: F401  (ORACLE: a spec's detector, the rendered labels)

# the spec's own keys; each registered method with settings adds its key (Method.options_key: appearance, fpfh_icp)
BASE_KEYS = {"name", "description", "render", "tours", "out", "mapping", "query", "unchanged", "map", "methods",
             "tables", "one_frame_stride", "detector", "config", "workers", "seed",
             "sensors", "map_sensor", "intervals", "replicates", "sweep"}
SPEC_KEYS = BASE_KEYS | {m.options_key for m in registry.all_methods() if m.options_key}
METHODS = registry.default_names()  # a spec's methods when it lists none: the in-tree methods
DETECTORS = ("learned", "oracle", "onnx")
TABLES = ("units", "ablation")


def spec_keys() -> set:
    """The keys an experiment spec may have: ``BASE_KEYS`` and every registered method's settings key."""
    return BASE_KEYS | {m.options_key for m in registry.all_methods() if m.options_key}


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
    intervals: IntervalSettings = IntervalSettings()  # how the figures' intervals are computed
    replicates: int = 1  # the experiment run this many times, its stochastic parts reseeded (replicate_spec)
    sweep: object = None  # reloc.experiments.sweep.Sweep: one graded factor (dose-response, breaking points)
    # every registered method's settings by its key (Method.options_key: {"appearance": {...}, "fpfh_icp": {...}});
    # the in-tree ones also as the fields appearance and fpfh_icp
    method_options: dict = dataclasses.field(default_factory=dict)

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
        """How tables name the detector: ``learned (detector_v2_160x120.onnx)``, ``oracle``, ..."""
        d = self.detector
        if d.get("model"):
            return f"{d['kind']} ({Path(d['model']).name})"
        corr = {k: v for k, v in d.get("corruption", {}).items() if v and k != "seed"}
        return d["kind"] + (" (corrupted: " + ", ".join(f"{k} {v}" for k, v in corr.items()) + ")" if corr else "")


_FIELDS = {f.name: f for f in dataclasses.fields(ExperimentSpec)}


def _fail(src, field, msg):
    raise SceneFormatError(src, field, msg)


def _sensor_entry(value, src, field) -> dict:
    """One sensor of a spec's ``sensors``: a preset name or a YAML file relative to the spec. Loaded
    here, so that an unknown preset or a bad parameter stops the experiment before anything runs."""
    from vrformats.sensors import PRESET_DIR

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
    from ..resources import experiment_spec, render_spec_of

    src = experiment_spec(path)  # a file, or a shipped name (reloc/specs: demo_experiment)
    if not src.is_file():
        raise UserError(f"{src}: experiment spec not found")
    doc = read_yaml(src)
    if not isinstance(doc, dict):
        _fail(src, None, "expected a mapping at the top level")
    keys = spec_keys()
    unknown = sorted(map(str, set(doc) - keys))
    if unknown:
        _fail(src, unknown[0], f"unknown key; allowed: {', '.join(sorted(keys))}")
    for k in ("name", "render", "out", "mapping", "query", "unchanged"):
        if doc.get(k) in (None, ""):
            _fail(src, k, "missing")
    render = render_spec_of(src, doc["render"])  # a file relative to the spec, or a shipped name (render_jobs)
    if not render.is_file():
        _fail(src, "render", f"render job spec {render} not found")
    render_doc = read_yaml(render)
    job_out = render_doc.get("out") if isinstance(render_doc, dict) else None
    if not doc.get("tours") and not isinstance(job_out, str):
        raise SceneFormatError(render, "out", "expected the render job's output folder (or give tours: in the experiment spec)")
    mapping = _mapping_of(doc["mapping"], src, "mapping")
    for k in ("layout", "lighting", "path"):
        if k == "lighting" and mapping.get(k) is None:  # a geometry-only design (renderer: fast)
            mapping[k] = None
        elif not isinstance(mapping.get(k), str):
            _fail(src, f"mapping.{k}", "expected a name" + (" (leave it out for a geometry-only design)"
                                                            if k == "lighting" else ""))
    known = registry.names()  # the registered methods (reloc.experiments.methods)
    methods = doc.get("methods", list(registry.default_names()))
    if isinstance(methods, str):
        methods = [methods]
    if not isinstance(methods, list) or not methods:
        _fail(src, "methods", f"expected a non-empty list of {', '.join(known)} or external methods")
    externals = []
    for i, m in enumerate(methods):
        if isinstance(m, dict):  # another relocalizer: a command on exported tours, or trajectories (external.py)
            from .external import parse_external

            externals.append(parse_external(m, src, f"methods[{i}]", known))
            if externals[-1].name in [e.name for e in externals[:-1]]:
                _fail(src, f"methods[{i}].name", f"{externals[-1].name!r} is used twice")
        elif m not in known:
            _fail(src, f"methods[{i}]", f"unknown method {m!r}; known: {', '.join(known)}, or a mapping with name and "
                                        "command (or trajectories)")
    methods = [m["name"] if isinstance(m, dict) else m for m in methods]
    listed = [registry.get(m) for m in methods if m in known]
    for m in listed:  # a clip-rigid control runs on the clips of another method's runs
        if m.clips_from is not None and m.clips_from not in methods:
            _fail(src, "methods", f"the clip-rigid controls reuse {registry.get(m.clips_from).label}'s clips: "
                                  f"add {m.clips_from}")
    tables = doc.get("tables") or []
    if not isinstance(tables, list) or any(t not in TABLES for t in tables):
        _fail(src, "tables", f"expected a list of {', '.join(TABLES)} (main and factors are always made), got {tables!r}")
    for t in tables:  # a table of a method's runs needs the method listed, unless the table runs it
        tm = registry.table_method(t)
        if tm is not None and not tm.runs_for_tables and tm.name not in methods:
            _fail(src, "tables", f"the {t} table needs the {tm.name} method")
    if doc.get("map", "build") not in ("build", "ground-truth"):
        _fail(src, "map", f"expected build or ground-truth, got {doc.get('map')!r}")
    for k in ("one_frame_stride", "workers", "replicates"):
        fields.positive_int(src, doc.get(k, 1), k)
    cfg = _mapping_of(doc.get("config"), src, "config")
    config = Config.from_dict(cfg, source=str(src), under="config")
    det = _detector_spec(doc.get("detector", "learned"), src)
    oracle_rows = [m for m in listed if m.oracle_of is not None]
    if det["kind"] == "oracle" and oracle_rows:
        m = oracle_rows[0]
        _fail(src, "methods", f"{m.name} is the oracle row beside another detector; "
                              f"with detector: oracle it would repeat {m.oracle_of}")
    if det["kind"] != "oracle":
        strides = {"config.observation.stride": config.observation.stride}
        for m in registry.active(methods, tables):  # the methods that look at every k-th frame
            if m.stride_key:
                strides[m.stride_key] = int(doc.get(m.stride_key, _FIELDS[m.stride_key].default))
        _check_render_rgb(render, render_doc, str(doc["query"]), mapping, strides, det["kind"])
    with_options = sorted((m for m in registry.all_methods() if m.options_key), key=lambda m: m.options_key)
    options = {m.options_key: _mapping_of(doc.get(m.options_key), src, m.options_key) for m in with_options}
    for m in with_options:  # each method's settings: its settings class's fields
        if options[m.options_key]:
            _check_overrides(m.options_class(), options[m.options_key], src, m.options_key)
    tours_root = Path(doc["tours"]) if doc.get("tours") else Path(job_out)
    sensors, map_sensor = _sensors_of(doc, src)
    seed = fields.nonneg_int(src, doc.get("seed", 0), "seed")
    return ExperimentSpec(
        name=fields.name_text(src, doc["name"], "name"), source=src, render=render, tours_root=tours_root,
        out=Path(fields.out_folder(src, doc["out"])), mapping=mapping, query=fields.string(src, doc["query"], "query"),
        unchanged=fields.string(src, doc["unchanged"], "unchanged"), map=doc.get("map", "build"),
        methods=tuple(methods), tables=tuple(tables), one_frame_stride=int(doc.get("one_frame_stride", 15)),
        detector=det, config=cfg, workers=int(doc.get("workers", 2)), method_options=options,
        **{k: v for k, v in options.items() if k in _FIELDS},
        seed=seed, description=fields.text(src, doc.get("description", ""), "description"), externals=tuple(externals),
        sensors=sensors, map_sensor=map_sensor, intervals=IntervalSettings.from_spec(src, doc.get("intervals")),
        replicates=int(doc.get("replicates", 1)), sweep=_sweep_of(doc, src, sensors),
    )


def _sweep_of(doc: dict, src, sensors) -> object:
    from .sweep import parse_sweep

    sw = parse_sweep(doc.get("sweep"), src)
    if sw is not None and sw.factor == "sensor":
        names = [s["name"] for s in sensors]
        for lv, name in sw.levels:
            if name not in names:
                _fail(src, f"sweep.levels.{lv:g}", f"sensor {name!r} is not one of the experiment's sensors ({', '.join(names)})")
    return sw


def replicate_spec(spec: ExperimentSpec, k: int) -> ExperimentSpec:
    """Replicate ``k`` of an experiment (0: the experiment itself): every stochastic part reseeded.
    ``seed`` + k (VideoReloc's and the baselines' random draws, the sensors' noise), the oracle's
    corruption seed + k, and for the learned detector an input jitter of one 8-bit level seeded k
    (``reloc.detection.learned.Perturbation``: what another processor amounts to)."""
    if k == 0:
        return spec
    det = dict(spec.detector)
    if det["kind"] == "learned":
        det["perturbation"] = {**det.get("perturbation", {}), "input_jitter": max(1, det.get("perturbation", {})
                                                                                   .get("input_jitter", 0)), "seed": k}
    elif det["kind"] == "oracle" and det.get("corruption"):
        det["corruption"] = {**det["corruption"], "seed": det["corruption"].get("seed", 0) + k}
    return dataclasses.replace(spec, name=f"{spec.name} r{k}", seed=spec.seed + k, detector=det, replicates=1)


def _detector_spec(v, src) -> dict:
    """The spec's ``detector``: ``learned`` (the shipped model), ``oracle`` or a mapping with ``kind``,
    ``model`` (relative to the spec file) and, for the oracle, corruption settings. Returns
    ``{"kind", "model" (absolute path or None), "corruption" (dict)}``; a model file is opened here,
    so that a missing or corrupt one stops the experiment before anything runs."""
    from ..detection.oracle import Corruption
    from ..detection.learned import SHIPPED_MODEL

    d = {"kind": v} if isinstance(v, str) else _mapping_of(v, src, "detector")
    kind = d.pop("kind", "learned")
    if kind not in DETECTORS:
        _fail(src, "detector" if isinstance(v, str) else "detector.kind",
              f"expected one of {', '.join(DETECTORS)}, got {kind!r}")
    model = d.pop("model", None)
    class_map = d.pop("class_map", None)
    perturbation = d.pop("perturbation", None)
    if perturbation is not None:
        if kind != "learned":
            _fail(src, "detector.perturbation", "only the learned detector takes a perturbation "
                  "(the oracle has corruption settings instead)")
        perturbation = _perturbation(perturbation, src)
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
              else "unknown setting; allowed: kind, model" + (", class_map" if kind == "onnx" else ", perturbation"))
    if model is None:
        if kind == "onnx":
            _fail(src, "detector.model", "the onnx detector needs a model file")
        path = SHIPPED_MODEL
    else:
        path = (src.parent / str(model)).resolve()
    if not path.is_file():
        _fail(src, "detector.model", f"model file {path} not found")
    out = {"kind": kind, "model": str(path), "corruption": {}}
    if perturbation:
        out["perturbation"] = perturbation
    if class_map is not None:
        if kind != "onnx":
            _fail(src, "detector.class_map", "only the onnx detector takes a class map")
        out["class_map"] = str((src.parent / str(class_map)).resolve())
    try:  # a corrupt or foreign model: one line naming the spec's field and the model file
        open_detector(out, vocabulary=None)
    except UserError as e:
        raise UserError(f"{src}: detector.model: {e}") from None
    return out


def _perturbation(v, src) -> dict:
    """``detector.perturbation`` (``reloc.detection.learned.Perturbation``) as a dict of its
    non-default settings; one line naming the key on error."""
    from ..detection.learned import Perturbation

    d = _mapping_of(v, src, "detector.perturbation")
    _check_overrides(Perturbation, d, src, "detector.perturbation")
    try:
        p = Perturbation(**d)
    except ValueError as e:
        _fail(src, "detector.perturbation", str(e))
    return {k: v for k, v in dataclasses.asdict(p).items() if v != getattr(Perturbation(), k)}


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

