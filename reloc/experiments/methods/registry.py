"""The registry of relocalization methods: what an experiment asks of a method, found by its name.

A method is a ``Method`` registered once, by the module that defines it (``register``); the
experiment spec (:mod:`reloc.experiments.spec`), its tasks (:mod:`reloc.experiments.tasks`), the
runner (:mod:`reloc.experiments.runner`) and the tables (:mod:`reloc.experiments.tables`) ask the
registry (``get``, ``names``, ``active``, ``rows``, ...) instead of switching on names. A map a
method needs is a ``MapKind`` registered the same way (``register_map``); maps are built once per
experiment (and map sensor) from the mapping tour, in the order their kinds were registered.

The in-tree methods are the modules of this package, imported (and so registered) by its
``__init__``; a method outside it registers itself when its module is imported (a worker process
imports it again from ``Method.module``).
"""

from __future__ import annotations

import dataclasses
from typing import Callable

# Table I rows of a method registered without an ``order``: after the in-tree rows, in
# registration order (external command methods come after every registered row).
LAST = 1000


@dataclasses.dataclass(frozen=True)
class Row:
    """One row of Table I: the method's poses of one ``mode`` (``causal.txt`` / ``closure.txt`` of its
    runs), its ``label`` (``{feature}`` and other ``Method.label_fields`` filled in), ``dagger``: a
    clip-rigid control. ``order``: the row's place in Table I among every method's rows."""
    mode: str
    label: str
    dagger: bool = False
    order: float = LAST


@dataclasses.dataclass(frozen=True)
class MapKind:
    """A map built from the mapping tour: ``file`` (its name in ``maps/``), ``build(task, tour, out)``
    (writes ``out``; ``task``: ``runner``'s map task dict), ``load(path, map_config)`` (what a run
    reads; cached per worker process). ``builds_as``: another kind's builder and loader (the oracle's
    box map is a box map). ``options(spec)``: its settings (part of its key); ``detector(spec)``: the
    detector spec it is built with (None: none); ``spec_map``: it follows the spec's ``map``
    (build | ground-truth); ``always``: built whatever the methods (the box map)."""
    name: str
    file: str
    build: Callable | None = None
    load: Callable | None = None
    builds_as: str | None = None
    options: Callable = lambda spec: {}
    detector: Callable = lambda spec: None
    spec_map: bool = False
    always: bool = False
    module: str = ""


@dataclasses.dataclass(frozen=True)
class Method:
    """A relocalization method run by ``reloc experiment`` on every query tour.

    * ``name``: its name in a spec's ``methods`` and its runs' folder (``runs/NAME/TOUR``);
    * ``label``: its name in results.json (``{feature}``-style fields from ``label_fields``);
      ``rows``: its Table I rows (``Row``), in the order of its modes; ``primary``: the mode
      ``reloc check`` reads for ``NAME.KEY``;
    * ``run(task, tour, out_dir) -> dict``: one query tour (a ``vrformats.tour.Tour`` read through the
      query's sensor): writes ``MODE.txt`` trajectories into ``out_dir`` and returns extras for the
      done marker; ``task``: the runner's task dict (``map``, ``config``, ``detector``, ``seed``, ...,
      plus what ``task_args`` adds);
    * ``maps``: the map kinds it needs (``MapKind``); ``uses``: the one its results' key depends on
      (and its map size in Table I);
    * ``task_args(spec, files) -> dict``: its settings in the task (part of the key); ``files``:
      {map kind: path} of the query's map sensor;
    * ``clips_from``: a method whose clips it reuses (clip-rigid controls: VideoReloc); it runs after
      that method's run of the same tour and the spec must list it;
    * ``clips``: its runs leave clips (``clips.json``, ``clip_poses.npz``) and ``run.json``, which the
      sensor table's odometry and the degenerate-frame notes read;
    * ``frames(mode, frames, rgb_every, stride) -> frames``: the frames a row is evaluated on (None:
      all); ``stride_key``: the spec key of the stride it looks at frames with (its detector's frames
      must have RGB there);
    * ``options_key`` and ``options_class()``: the spec key of its settings and their dataclass
      (unknown settings are refused); ``label_fields(spec) -> dict``: fields of its labels;
    * ``oracle_of``: it is that method on the rendered labels (refused with ``detector: oracle``);
    * ``tables``: optional tables (a spec's ``tables``) made of its runs; ``runs_for_tables``: it runs
      when one of them is asked even if not listed (else the table needs it listed);
    * ``default``: in the methods of a spec that lists none.
    """
    name: str
    label: str
    rows: tuple
    run: Callable
    primary: str = "closure"
    maps: tuple = ("boxes",)
    uses: str = "boxes"
    task_args: Callable = lambda spec, files: {}
    clips_from: str | None = None
    clips: bool = False
    frames: Callable | None = None
    stride_key: str | None = None
    options_key: str | None = None
    options_class: Callable | None = None
    label_fields: Callable = lambda spec: {}
    oracle_of: str | None = None
    tables: tuple = ()
    runs_for_tables: bool = False
    default: bool = False
    module: str = ""

    @property
    def modes(self) -> list[str]:
        return [r.mode for r in self.rows]


_METHODS: dict[str, Method] = {}
_MAPS: dict[str, MapKind] = {}


def register(method: Method) -> Method:
    """Register a method under its name (once; a second registration of a name is an error, unless it
    is the same module registering again)."""
    old = _METHODS.get(method.name)
    module = method.module or getattr(method.run, "__module__", "")
    if old is not None and old.module != module:
        raise ValueError(f"method {method.name!r} is registered twice ({old.module}, {module})")
    for k in method.maps:
        if k not in _MAPS:
            raise ValueError(f"method {method.name!r} needs map kind {k!r}, which is not registered")
    if method.clips_from is not None and method.clips_from not in _METHODS:
        raise ValueError(f"method {method.name!r} reuses the clips of {method.clips_from!r}, which is not registered")
    m = dataclasses.replace(method, module=module)
    _METHODS[m.name] = m
    return m


def unregister(name: str) -> None:
    """Remove a method (tests register methods of their own)."""
    _METHODS.pop(name, None)


def register_map(kind: MapKind) -> MapKind:
    """Register a map kind under its name (a kind that ``builds_as`` another needs that one registered)."""
    if kind.builds_as is not None and kind.builds_as not in _MAPS:
        raise ValueError(f"map kind {kind.name!r} builds as {kind.builds_as!r}, which is not registered")
    k = dataclasses.replace(kind, module=kind.module or getattr(kind.build or kind.options, "__module__", ""))
    _MAPS[k.name] = k
    return k


def unregister_map(name: str) -> None:
    _MAPS.pop(name, None)


def get(name: str) -> Method:
    """The method of that name; a KeyError naming the registered ones otherwise."""
    try:
        return _METHODS[name]
    except KeyError:
        raise KeyError(f"unknown method {name!r}; registered: {', '.join(names())}") from None


def names() -> tuple[str, ...]:
    """The registered methods' names, in registration order."""
    return tuple(_METHODS)


def all_methods() -> list[Method]:
    return list(_METHODS.values())


def default_names() -> tuple[str, ...]:
    """The methods of a spec that names none."""
    return tuple(m.name for m in _METHODS.values() if m.default)


def map_kind(name: str) -> MapKind:
    return _MAPS[name]


def map_kinds() -> list[MapKind]:
    return list(_MAPS.values())


def active(methods, tables=()) -> list[Method]:
    """The registered methods an experiment runs, in registration order: those it lists and those
    that run for one of its tables."""
    return [m for m in _METHODS.values()
            if m.name in methods or (m.runs_for_tables and set(m.tables) & set(tables))]


def table_method(table: str) -> Method | None:
    """The method whose runs make an optional table (``units``: one_frame, ``ablation``: videoreloc)."""
    return next((m for m in _METHODS.values() if table in m.tables), None)


def rows(methods) -> list[tuple[str, Row]]:
    """Table I's rows of the listed registered methods: (method name, row), in Table I's order."""
    got = [(m.name, r) for m in _METHODS.values() if m.name in methods for r in m.rows]
    return sorted(got, key=lambda x: x[1].order)  # stable: equal orders keep registration order


def map_names(methods) -> list[str]:
    """The map kinds an experiment builds, in registration order: those always built and those its
    methods need."""
    need = {k for m in _METHODS.values() if m.name in methods for k in m.maps}
    return [k.name for k in _MAPS.values() if k.always or k.name in need]


def clip_methods(methods) -> list[str]:
    """The listed methods whose runs leave clips, in registration order."""
    return [m.name for m in _METHODS.values() if m.clips and m.name in methods]
