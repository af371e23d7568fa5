"""Other people's relocalizers in an experiment: a command run on exported tours, or a folder of
precomputed trajectories. Their results go into the same tables, plots, report and ``reloc check``
keys as the built-in methods.

An experiment spec's ``methods`` list takes, beside the built-in names, mappings::

    methods:
      - videoreloc
      - name: my_ace                                   # a row name and check key: my_ace.causal
        command: "python run_ace.py {scene} {out}"     # run once per query tour
        export: ace                                    # synth tour export format the command reads
        poses: ace                                     # the convention of the pose file it writes
        poses_file: "{out}/poses.txt"                  # where (default)
        map_command: "python train_ace.py {mapping} {map_out}"   # optional: once, before the queries
        mode: causal                                   # the row it fills: causal (default) or closure
        label: "ACE (mine)"                            # the tables' label (default: the name)
        exposure: auto                                 # the export's exposure: auto | fixed | a factor
        version: 1                                     # bump to rerun (the command's code is not fingerprinted)
        timeout_s: 3600
      - name: their_slam                               # precomputed: one file per query tour
        trajectories: results/slam                     # relative to the spec file
        file: "{tour}.txt"                             # default
        poses: tum
        names: null                                    # named conventions: an export folder whose frames the names follow

Placeholders (``PLACEHOLDERS``): ``{mapping}`` and ``{query}``, the exports of the mapping tour and of
this query tour (``vrformats.export``; exported once, cached under ``OUT/exports/<format>/``);
``{scene}``, one folder holding both (the mapping export's and the query export's top-level entries,
linked: ACE's ``train/`` and ``test/``); ``{out}``, this run's folder (``OUT/runs/<name>/<tour>/``,
empty before the command runs); ``{map_out}``, the folder ``map_command`` writes (``OUT/maps/<name>/``);
``{tour}``, the query tour's name; ``{name}``, the method's. Paths are substituted shell-quoted and the
command is split like a shell would (``shlex``) but run without a shell: use a script for pipes.

A command that exits with another status than 0, times out, or writes no pose file is a failed run
(its stderr's last lines are the reason); the other runs go on. Poses are read in the stated
convention (``vrformats.poses``), mapped to tour frames by the export's names, and written as the
run's ``<mode>.txt`` (TUM), so evaluation is the built-in methods'. Image exports leave out frames
without RGB; such a method is evaluated on the frames its export holds. Runs are resumable and
invalidated like the built-in ones: the done-key holds the command, the conventions, the exports'
manifests (hence the tours and the exporter's settings), ``version``, and for a folder of
trajectories the file's content.
"""

from __future__ import annotations

import hashlib
import json
import os
import re
import shlex
import string
import subprocess
import time
from dataclasses import asdict, dataclass
from pathlib import Path

from vrformats.errors import SceneFormatError, UserError
from vrformats.fields import is_number
from vrformats.atomic import write_text_atomic

PLACEHOLDERS = ("mapping", "query", "scene", "out", "map_out", "tour", "name")
MAP_PLACEHOLDERS = ("mapping", "map_out", "name")
FILE_PLACEHOLDERS = ("tour", "name")
MODES = ("causal", "closure")
NAME = re.compile(r"^[A-Za-z][A-Za-z0-9_\-]*$")
KEYS_COMMAND = {"name", "command", "export", "poses", "poses_file", "map_command", "mode", "label", "exposure", "version",
                "timeout_s"}
KEYS_FOLDER = {"name", "trajectories", "file", "poses", "names", "mode", "label", "version"}
STDERR_TAIL = 5  # lines of a failed command's stderr in its failure message


@dataclass(frozen=True)
class ExternalMethod:
    name: str
    kind: str  # command | folder
    poses: str  # the pose-file convention (vrformats.poses.CONVENTIONS)
    mode: str = "causal"
    label: str = ""
    command: str | None = None
    map_command: str | None = None
    export: str | None = None  # vrformats.export format
    poses_file: str = "{out}/poses.txt"
    exposure: str | float = "auto"
    timeout_s: float | None = None
    trajectories: str | None = None  # absolute folder (kind folder)
    file: str = "{tour}.txt"
    names: str | None = None  # kind folder: an export folder or manifest whose frame names the files use
    version: str = ""

    def to_dict(self) -> dict:
        return asdict(self)


def _fields_of(template: str, src, field: str) -> list[str]:
    try:
        return [f for _, f, _, _ in string.Formatter().parse(template) if f is not None]
    except ValueError as e:
        raise SceneFormatError(src, field, f"malformed template {template!r}: {e}") from None


def check_template(template, src, field: str, allowed: tuple) -> str:
    """A command or file template: a non-empty string whose ``{placeholders}`` are all known."""
    if not isinstance(template, str) or not template.strip():
        raise SceneFormatError(src, field, f"expected a command template string, got {template!r}")
    for f in _fields_of(template, src, field):
        if f not in allowed:
            raise SceneFormatError(src, field, f"unknown placeholder {{{f}}}; known: "
                                               + ", ".join("{" + p + "}" for p in allowed))
    return template


def parse_external(doc, src, field: str, builtin: tuple) -> ExternalMethod:
    """One ``methods`` entry that is a mapping; every error names the spec file and the field."""
    from vrformats.poses import CONVENTIONS

    if not isinstance(doc, dict):
        raise SceneFormatError(src, field, f"expected a built-in method name or a mapping with name and command or "
                                           f"trajectories, got {doc!r}")
    name = doc.get("name")
    if not isinstance(name, str) or not NAME.match(name):
        raise SceneFormatError(src, f"{field}.name", f"expected a name of letters, digits, _ and - (a row and check key), "
                                                     f"got {name!r}")
    if name in builtin or name.startswith("ablation_") or name in ("map", "map_oracle"):
        raise SceneFormatError(src, f"{field}.name", f"{name!r} is a built-in name; choose another")
    if ("command" in doc) == ("trajectories" in doc):
        raise SceneFormatError(src, field, "give either command (run on exported tours) or trajectories (a folder)")
    kind = "command" if "command" in doc else "folder"
    allowed = KEYS_COMMAND if kind == "command" else KEYS_FOLDER
    unknown = sorted(map(str, set(doc) - allowed))
    if unknown:
        raise SceneFormatError(src, f"{field}.{unknown[0]}", f"unknown key; allowed: {', '.join(sorted(allowed))}")
    poses = doc.get("poses")
    if poses not in CONVENTIONS:
        raise SceneFormatError(src, f"{field}.poses", f"expected the pose convention, one of {', '.join(CONVENTIONS)}; "
                                                      f"got {poses!r} (it is never guessed)")
    mode = doc.get("mode", "causal")
    if mode not in MODES:
        raise SceneFormatError(src, f"{field}.mode", f"expected causal or closure, got {mode!r}")
    label = doc.get("label", name)
    if not isinstance(label, str) or not label:
        raise SceneFormatError(src, f"{field}.label", f"expected a string, got {label!r}")
    version = doc.get("version", "")
    if not (isinstance(version, str) or is_number(version)):
        raise SceneFormatError(src, f"{field}.version", f"expected a string or number, got {version!r}")
    common = {"name": name, "kind": kind, "poses": poses, "mode": mode, "label": label, "version": str(version)}
    if kind == "command":
        from vrformats.export import FORMATS

        export = doc.get("export")
        if export not in FORMATS:
            raise SceneFormatError(src, f"{field}.export", f"expected the export format the command reads, one of "
                                                           f"{', '.join(FORMATS)}; got {export!r}")
        command = check_template(doc["command"], src, f"{field}.command", PLACEHOLDERS)
        map_command = None
        if doc.get("map_command") is not None:
            map_command = check_template(doc["map_command"], src, f"{field}.map_command", MAP_PLACEHOLDERS)
        if map_command is None and "map_out" in _fields_of(command, src, f"{field}.command"):
            raise SceneFormatError(src, f"{field}.command", "{map_out} is what map_command writes: add a map_command")
        poses_file = check_template(doc.get("poses_file", "{out}/poses.txt"), src, f"{field}.poses_file", PLACEHOLDERS)
        exposure = doc.get("exposure", "auto")
        if not (exposure in ("auto", "fixed") or (is_number(exposure) and exposure > 0)):
            raise SceneFormatError(src, f"{field}.exposure", f"expected auto, fixed or a positive factor, got {exposure!r}")
        timeout = doc.get("timeout_s")
        if timeout is not None and (not is_number(timeout) or timeout <= 0):
            raise SceneFormatError(src, f"{field}.timeout_s", f"expected a positive number of seconds, got {timeout!r}")
        return ExternalMethod(**common, command=command, map_command=map_command, export=export, poses_file=poses_file,
                              exposure=exposure, timeout_s=None if timeout is None else float(timeout))
    folder = (Path(src).parent / str(doc["trajectories"])).resolve()
    if not folder.is_dir():
        raise SceneFormatError(src, f"{field}.trajectories", f"folder {folder} not found")
    file = check_template(doc.get("file", "{tour}.txt"), src, f"{field}.file", FILE_PLACEHOLDERS)
    names = doc.get("names")
    if names is not None:
        names = str((Path(src).parent / str(names)).resolve())
        if not Path(names).exists():
            raise SceneFormatError(src, f"{field}.names", f"{names} not found (an export folder or its export.json)")
    elif poses != "tum":
        raise SceneFormatError(src, f"{field}.names", f"the {poses} convention names frames: give the export folder "
                                                      "(or export.json) whose frame names the files use")
    return ExternalMethod(**common, trajectories=str(folder), file=file, names=names)


# ---------------------------------------------------------------------------------------------
# exports (in the main process, before the runs)


def _short(x) -> str:
    return str(x).replace("/", "_")


def export_dir(out: Path, m: ExternalMethod, tour_name: str) -> Path:
    return out / "exports" / f"{m.export}__{_short(m.exposure)}" / tour_name


def prepare_exports(out: Path, methods: list[ExternalMethod], mappings: dict, queries: dict, progress: bool = True,
                    sensors: dict | None = None, sensor_seed: int = 0, mapping_of=None) -> dict:
    """Export the mapping tour (once per map sensor: ``mappings`` {reading name: info}) and every query
    tour reading once per (format, exposure) the command methods read, each read through its info's
    ``sensor`` (``sensors``: sensor name -> preset name or file, None for ideal; ``sensor_seed``);
    link a ``scene`` folder per query reading with the mapping export ``mapping_of(query info)``
    names (default: the only mapping). Returns {(format, exposure, reading name): manifest key}."""
    from vrformats.export import export_tour

    sensors = sensors or {}
    if mapping_of is None:
        only = next(iter(mappings))
        mapping_of = lambda t: only  # noqa: E731
    keys: dict = {}
    wanted = sorted({(m.export, m.exposure) for m in methods if m.kind == "command"}, key=str)
    for fmt, exposure in wanted:
        probe = ExternalMethod(name="x", kind="command", poses="tum", export=fmt, exposure=exposure)
        for name, t, role in [(n, mp, "mapping") for n, mp in mappings.items()] + [(n, q, "query") for n, q in queries.items()]:
            d = export_dir(out, probe, name)
            manifest = export_tour(t["dir"], fmt, d, role=role, exposure=exposure, progress=progress,
                                   sensor=sensors.get(t.get("sensor", "ideal")), sensor_seed=sensor_seed)
            keys[(fmt, str(exposure), name)] = _manifest_key(manifest)
        users = [m for m in methods if m.kind == "command" and (m.export, m.exposure) == (fmt, exposure)]
        if any("scene" in _fields_of(m.command, None, "command") + _fields_of(m.poses_file, None, "poses_file")
               for m in users):  # only where a command asks for it: not every format has one scene folder
            for name, q in queries.items():
                _link_scene(export_dir(out, probe, mapping_of(q)), export_dir(out, probe, name),
                            out / "exports" / f"{fmt}__{_short(exposure)}" / "scenes" / name)
    return keys


def _manifest_key(manifest: dict) -> str:
    """What a run depends on in an export: its manifest (tour key, format, exposure factors, frames),
    without the counts of this export call (``run``: written now / kept)."""
    kept = {k: v for k, v in manifest.items() if k != "run"}
    return hashlib.sha1(json.dumps(kept, sort_keys=True, default=str).encode()).hexdigest()[:16]


def _link_scene(mapping_dir: Path, query_dir: Path, scene: Path) -> None:
    """``scene``: the top-level entries of both exports, linked (relative links): ACE's ``train/`` and
    ``test/``; 7-Scenes' ``seq-01``, ``seq-02`` and both split files. A name both exports hold is
    linked once when the two files are equal, to the non-empty one when the other is empty (a
    7-Scenes export writes the other role's split file empty); otherwise the format has no shared
    scene folder and the commands use ``{mapping}`` and ``{query}``."""
    scene.mkdir(parents=True, exist_ok=True)
    chosen: dict[str, Path] = {}
    for src in (mapping_dir, query_dir):
        for entry in sorted(src.iterdir()):
            if entry.name == "export.json" or entry.name.startswith("."):
                continue
            prev = chosen.get(entry.name)
            if prev is None:
                chosen[entry.name] = entry
            elif prev.is_file() and entry.is_file():
                a, b = prev.read_bytes(), entry.read_bytes()
                if a != b and a.strip() and b.strip():
                    raise UserError(f"{scene}: the mapping and the query export both hold a different {entry.name}; "
                                    "use {mapping} and {query} instead of {scene} for this format")
                if not a.strip():
                    chosen[entry.name] = entry
            else:
                raise UserError(f"{scene}: the mapping and the query export both hold {entry.name}/; "
                                "use {mapping} and {query} instead of {scene} for this format")
    for name, entry in chosen.items():
        link = scene / name
        target = os.path.relpath(entry, scene)
        if link.is_symlink() and os.readlink(link) == target:
            continue
        if link.is_symlink() or link.exists():
            link.unlink()
        link.symlink_to(target)


# ---------------------------------------------------------------------------------------------
# runs (in worker processes)


def _fill(template: str, values: dict) -> str:
    return template.format(**{k: shlex.quote(str(v)) for k, v in values.items()})


def fill_path(template: str, values: dict) -> str:
    return template.format(**{k: str(v) for k, v in values.items()})


def _stderr_tail(text: str) -> str:
    lines = [ln.strip() for ln in text.strip().splitlines() if ln.strip()]
    return " | ".join(lines[-STDERR_TAIL:]) if lines else "(no output on stderr)"


def _run_command(cmd: str, cwd: Path, log: Path, timeout: float | None, what: str) -> float:
    """Run ``cmd`` (no shell); its stdout and stderr go to ``log``. UserError on failure."""
    t0 = time.perf_counter()
    try:
        argv = shlex.split(cmd)
    except ValueError as e:
        raise UserError(f"{what}: cannot split the command {cmd!r}: {e}") from None
    try:
        p = subprocess.run(argv, cwd=cwd, capture_output=True, text=True, timeout=timeout, check=False)
    except FileNotFoundError:
        raise UserError(f"{what}: command not found: {argv[0]}") from None
    except subprocess.TimeoutExpired as e:
        write_text_atomic(log, f"$ {cmd}\n[timed out after {timeout} s]\n{e.stdout or ''}\n{e.stderr or ''}")
        raise UserError(f"{what}: timed out after {timeout:g} s") from None
    write_text_atomic(log, f"$ {cmd}\n[exit status {p.returncode}]\n--- stdout\n{p.stdout}\n--- stderr\n{p.stderr}")
    if p.returncode != 0:
        raise UserError(f"{what}: exit status {p.returncode}: {_stderr_tail(p.stderr)}")
    return time.perf_counter() - t0


def run_external_map_task(task: dict) -> dict:
    """``map_command`` once: writes into ``OUT/maps/<name>/``."""
    m = ExternalMethod(**task["method"])
    d = Path(task["dir"])
    done = d.parent / f"{d.name}.done.json"
    done.unlink(missing_ok=True)
    d.mkdir(parents=True, exist_ok=True)
    values = {"mapping": task["mapping"], "map_out": d, "name": m.name}
    s = _run_command(_fill(m.map_command, values), d, d.parent / f"{d.name}.log", m.timeout_s, f"{m.name} map_command")
    from vrformats.atomic import write_json_atomic

    write_json_atomic(done, {"key": task["key"], "seconds": round(s, 2)})
    return {"method": m.name, "seconds": s}


def run_external_task(task: dict) -> dict:
    """One external method on one query tour: run the command (or take the precomputed file), read its
    poses, write ``<mode>.txt`` (TUM, camera-to-world) and mark the run done."""
    from vrformats.atomic import write_json_atomic
    from vrformats.camera import write_tum
    from vrformats.poses import load_names, read_poses
    from vrformats.tour import Tour

    t0 = time.perf_counter()
    m = ExternalMethod(**task["method"])
    d = Path(task["dir"])
    (d / "done.json").unlink(missing_ok=True)
    tour = Tour(task["tour"])
    what = f"{m.name} on {task['tour_name']}"
    if m.kind == "command":
        work = d / "out"
        if work.exists():  # a rerun starts from an empty {out}
            import shutil

            shutil.rmtree(work)
        work.mkdir(parents=True)
        values = {"mapping": task["mapping_export"], "query": task["query_export"], "scene": task["scene"], "out": work,
                  "map_out": task.get("map_out") or "", "tour": task["tour_name"], "name": m.name}
        _run_command(_fill(m.command, values), work, d / "command.log", m.timeout_s, what)
        pose_file = Path(fill_path(m.poses_file, values))
        names = load_names(task["query_export"])
    else:
        pose_file = Path(m.trajectories) / fill_path(m.file, {"tour": task["tour_name"], "name": m.name})
        names = None if m.names is None else load_names(m.names)
    if not pose_file.is_file() or pose_file.stat().st_size == 0:
        raise UserError(f"{what}: wrote no poses ({pose_file} {'is empty' if pose_file.is_file() else 'not found'})")
    poses = read_poses(pose_file, m.poses, names=names, fps=tour.fps, frames={int(i) for i in tour.frame_indices})
    if not poses:
        raise UserError(f"{what}: {pose_file} holds no pose")
    idx = sorted(poses)
    write_tum(d / f"{m.mode}.txt", [poses[i] for i in idx], fps=tour.fps, frames=idx,
              header=f"{m.label}: {pose_file} ({m.poses} convention), camera-to-world")
    seconds = time.perf_counter() - t0
    write_json_atomic(d / "done.json", {"key": task["key"], "seconds": round(seconds, 2), "poses": len(idx),
                                        "file": str(pose_file), "code": task.get("code")})
    return {"method": m.name, "tour": task["tour_name"], "seconds": seconds}

