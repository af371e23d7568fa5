"""Render specs whose layouts come from a ReplicaCAD folder: the ``replicacad:`` key of a job spec.

A spec with this key names ReplicaCAD scenes as its layouts and camera-path *kinds* as its paths::

    replicacad:
      root: null           # the dataset folder (holds configs/); null: --replicacad-root, else $REPLICACAD_ROOT
      allow_unknown: false # templates without a class rule load as class 'other' instead of failing
    designs:
      - layouts: [apt_0, apt_1, apt_2, apt_3, apt_4, apt_5]
        lightings: [day, evening, night]
        path: {name: query, frames: 4000}
      - layouts: [apt_0]
        lightings: [day]
        path: {name: mapping, frames: 6000}

Before anything is planned, ``prepare`` imports every named scene (``synth.sources.replicacad.importer.load_replicacad``:
structure from the stage mesh, articulated objects, supports, light fixtures) into
``OUT/replicacad/layouts/<scene>.yaml`` and plans each path on the imported layouts into
``OUT/replicacad/paths/<name>.txt`` (+ ``.yaml``): a ``query`` path once on all the layouts of its
design (one shared path, as for the built-in apartment), a ``mapping`` path on its one layout, with
the largest ``frames`` any design asks of that path (default: the paper's 4,000 and 6,000) and the
spec's seed. The spec is then rewritten to those files and runs like any other; tour names stay
``<scene>__<lighting>__<path>``.

What is done is not redone: a layout file is rewritten only when the import gives other bytes, and
a path is replanned only when its inputs (kind, frames, seed, the layout files' content hashes,
recorded in ``OUT/replicacad/prepared.json``) changed. ``paths_from: DIR`` (or ``synth render
--paths-from DIR``) takes the paths planned by another job (its output folder) instead of planning:
the same camera path on another stage variant of the flat, so that the stage is the only factor that
changes; such a path was not planned on these layouts, so the render checks its clearance in them. Files appear atomically. A dry run prepares
into a temporary folder and leaves nothing behind.
"""

from __future__ import annotations

import hashlib
import json
import os
from dataclasses import replace
from pathlib import Path

from vrformats.atomic import write_json_atomic, write_text_atomic
from vrformats.errors import SceneFormatError, UserError
from vrformats.fields import boolean
from ...paths.model import DEFAULTS

ENV_ROOT = "REPLICACAD_ROOT"
KEYS = {"root", "allow_unknown", "obstacles", "paths_from"}
OBSTACLES = ("all", "band")  # synth.paths: what the planned paths keep their clearance from
PATH_KINDS = {"query": DEFAULTS.query_frames, "mapping": DEFAULTS.mapping_frames}  # default frames (the paper's tours)
PREPARED = "prepared.json"


def parse_section(doc, source: str) -> dict:
    """The ``replicacad:`` mapping of a spec, checked; errors name the spec file and the key."""
    if doc is None:
        doc = {}
    if not isinstance(doc, dict):
        raise SceneFormatError(source, "replicacad", f"expected a mapping with root (and allow_unknown), got {doc!r}")
    unknown = sorted(map(str, set(doc) - KEYS))
    if unknown:
        raise SceneFormatError(source, f"replicacad.{unknown[0]}", f"unknown key; allowed: {', '.join(sorted(KEYS))}")
    root = doc.get("root")
    if root is not None and (not isinstance(root, str) or not root):
        raise SceneFormatError(source, "replicacad.root", f"expected a folder or null, got {root!r}")
    allow = boolean(source, doc.get("allow_unknown", False), "replicacad.allow_unknown")
    obstacles = doc.get("obstacles", "all")
    if obstacles not in OBSTACLES:
        raise SceneFormatError(source, "replicacad.obstacles", f"expected one of {', '.join(OBSTACLES)}, got {obstacles!r}")
    paths_from = doc.get("paths_from")
    if paths_from is not None and (not isinstance(paths_from, str) or not paths_from):
        raise SceneFormatError(source, "replicacad.paths_from", f"expected a folder or null, got {paths_from!r}")
    out = {"root": root, "allow_unknown": allow, "obstacles": obstacles}
    if paths_from is not None:  # only when set: a job's state document (which a resume compares) stays as it was
        out["paths_from"] = paths_from
    return out


def reused_path_file(paths_from: str, name: str, source: str) -> Path:
    """The planned ``name`` path of another job (``paths_from``: its output folder, or a folder of path
    files): the same camera path on another stage variant, the stage then being the only factor."""
    d = Path(os.path.expandvars(paths_from)).expanduser()
    for cand in (d / "replicacad" / "paths" / f"{name}.txt", d / f"{name}.txt"):
        if cand.is_file() and cand.with_suffix(".yaml").is_file():
            return cand.resolve()
    raise SceneFormatError(source, "replicacad.paths_from", f"no planned '{name}' path in {d} (looked for "
                                                            f"replicacad/paths/{name}.txt and {name}.txt, each with its .yaml)")


def resolve_root(section: dict, source: str, cli_root: str | None = None) -> Path:
    """The dataset folder: ``--replicacad-root``, else the spec's ``replicacad.root``, else $REPLICACAD_ROOT."""
    given = cli_root or section.get("root") or os.environ.get(ENV_ROOT)
    if not given:
        raise SceneFormatError(source, "replicacad.root",
                               f"no ReplicaCAD folder: set it here, pass --replicacad-root DIR or set {ENV_ROOT}")
    root = Path(os.path.expandvars(str(given))).expanduser()
    if not (root / "configs" / "scenes").is_dir():
        what = "--replicacad-root" if cli_root else ("replicacad.root" if section.get("root") else ENV_ROOT)
        raise SceneFormatError(source, "replicacad.root", f"{root} is not a ReplicaCAD folder (no configs/scenes in it; from {what})")
    return root.resolve()


def _sha(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()[:16]


def prepare(spec, out: Path, cli_root: str | None = None, progress=print):
    """Import the spec's scenes and plan its paths under ``out/replicacad``; return the rewritten spec.

    ``spec`` is a ``synth.jobs.spec.JobSpec`` with ``replicacad`` set. Raises SceneFormatError naming the
    spec file and the field for an unknown scene, a bad dataset file (the dataset file and field), a
    path name that is not a kind, or a path that cannot be planned on the imported layouts."""
    from ...paths.files import load_path, save_path
    from ...paths.shipped import plan_path
    from .importer import list_scenes, load_replicacad
    from ...scene.model import dump_yaml, layout_to_dict, load_layout

    src = spec.source or "<spec>"
    section = spec.replicacad
    root = resolve_root(section, src, cli_root)
    known = set(list_scenes(root))
    prep = Path(out) / "replicacad"
    (prep / "layouts").mkdir(parents=True, exist_ok=True)
    (prep / "paths").mkdir(parents=True, exist_ok=True)
    state_file = prep / PREPARED
    try:
        state = json.loads(state_file.read_text()) if state_file.exists() else {}
    except (ValueError, RecursionError):
        state = {}  # a damaged record only costs a replan
    if state.get("root") != str(root):
        state = {"root": str(root), "paths": {}}

    # every name first: a typo costs no import
    for i, d in enumerate(spec.designs):
        for k, name in enumerate(d.layouts):
            if name not in known:
                raise SceneFormatError(src, f"designs[{i}].layouts[{k}]",
                                       f"no ReplicaCAD scene '{name}' in {root}; scenes: {', '.join(sorted(known)) or 'none'}")
        if d.path not in PATH_KINDS:
            raise SceneFormatError(src, f"designs[{i}].path.name",
                                   f"a ReplicaCAD spec plans its paths: expected one of {', '.join(PATH_KINDS)}, got {d.path!r}")
    files: dict[str, Path] = {}
    for d in spec.designs:
        for name in d.layouts:
            if name in files:
                continue
            lay = load_replicacad(root, name, allow_unknown=section.get("allow_unknown", False))
            f = prep / "layouts" / f"{name}.yaml"
            text = dump_yaml(layout_to_dict(lay))
            if not f.exists() or f.read_text() != text:
                write_text_atomic(f, text)
                progress(f"imported {name}: {len(lay.objects)} objects, {len(lay.stage.walls)} walls, "
                         f"{len(lay.stage.rooms)} rooms, {len(lay.stage.openings)} openings, {len(lay.fixtures)} fixtures -> {f}")
            files[name] = f

    # paths: one per path name, on the layouts of every design that uses it, with the most frames asked
    wants: dict[str, dict] = {}
    for i, d in enumerate(spec.designs):
        w = wants.setdefault(d.path, {"layouts": [], "frames": 0, "field": f"designs[{i}].path"})
        w["layouts"] += [n for n in d.layouts if n not in w["layouts"]]
        w["frames"] = max(w["frames"], d.frames or PATH_KINDS[d.path])
    path_files: dict[str, Path] = {}
    for name, w in wants.items():
        if name == "mapping" and len(w["layouts"]) != 1:
            raise SceneFormatError(src, w["field"], f"a mapping path is planned on one layout, but designs use it with {w['layouts']}")
        obstacles = section.get("obstacles", "all")
        key = {"kind": name, "frames": w["frames"], "seed": spec.seed,
               "layouts": {n: _sha(files[n]) for n in w["layouts"]},
               **({"obstacles": obstacles} if obstacles != "all" else {})}
        reuse = reused_path_file(section["paths_from"], name, src) if section.get("paths_from") else None
        if reuse is not None:  # another job's path: not planned here, so the render checks its clearance in these layouts
            key = {"kind": name, "frames": w["frames"], "from": str(reuse), "sha": _sha(reuse)}
        txt = prep / "paths" / f"{name}.txt"
        if state["paths"].get(name) == key and txt.exists() and txt.with_suffix(".yaml").exists():
            path_files[name] = txt
            continue
        if reuse is not None:
            try:
                path = load_path(reuse)
            except UserError as e:
                raise SceneFormatError(src, "replicacad.paths_from", str(e)) from None
            if len(path) < w["frames"]:
                raise SceneFormatError(src, w["field"], f"the reused {name} path {reuse} has {len(path)} frames, "
                                                        f"fewer than the {w['frames']} asked")
            progress(f"reusing the {name} path of {reuse} (planned on {', '.join(map(str, path.meta.get('layouts') or []))})")
            # meta['layouts'] keeps naming the layouts it was planned on: these are not among them
        else:
            progress(f"planning the {name} path ({w['frames']} frames) on {', '.join(w['layouts'])} ...")
            try:
                path = plan_path(name, [load_layout(files[n]) for n in w["layouts"]], w["frames"], seed=spec.seed, name=name,
                                 obstacles=obstacles)
            except UserError as e:
                raise SceneFormatError(src, w["field"], f"cannot plan a {name} path on {', '.join(w['layouts'])}: {e}") from None
            # the layouts by file: an imported apt_0 is not the built-in apt_0 (synth path check reads these)
            path.meta["layouts"] = [str(files[n].resolve()) for n in w["layouts"]]
        tmp = prep / "paths" / ".tmp" / f"{name}.txt"  # same names, then moved: the sidecar names its poses file
        tmp.parent.mkdir(exist_ok=True)
        try:
            save_path(path, tmp)
            txt.unlink(missing_ok=True)  # the poses file appears last: it marks a complete path
            os.replace(tmp.with_suffix(".yaml"), txt.with_suffix(".yaml"))
            os.replace(tmp, txt)
        finally:  # a failed write leaves no temporary behind
            tmp.unlink(missing_ok=True)
            tmp.with_suffix(".yaml").unlink(missing_ok=True)
        load_path(txt)  # readable as written
        state["paths"][name] = key
        write_json_atomic(state_file, state, indent=1)
        path_files[name] = txt

    designs = [replace(d, layouts=[str(files[n]) for n in d.layouts], path=str(path_files[d.path])) for d in spec.designs]
    return replace(spec, designs=designs, replicacad={**section, "root": str(root)})
