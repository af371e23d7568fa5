"""Path files: ``scenes/paths/NAME.txt`` (TUM, ``t = frame / fps``) plus the ``NAME.yaml`` sidecar
(``format: synth-camera-path/1``: name, kind, fps, frames, seed, layouts, planner parameters,
summary stats); saving, loading (by name or file) and listing them.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import yaml

from vrformats import camera
from vrformats.atomic import write_text_atomic
from vrformats.errors import SceneFormatError, UnknownNameError, UserError
from vrformats.fields import integer, is_number
from vrformats.yamlfile import MAX_DEPTH, check_shape, read_text, safe_load

from ..resources import paths_dir  # $SYNTH_SCENES_DIR/paths, else scenes/paths
from .model import FORMAT, CameraPath

__all__ = ["paths_dir", "list_paths", "save_path", "load_path"]


def list_paths() -> list[str]:
    d = paths_dir()
    return sorted(p.stem for p in d.glob("*.txt")) if d.is_dir() else []


def _plain(v):
    if isinstance(v, dict):
        return {str(k): _plain(x) for k, x in v.items()}
    if isinstance(v, (list, tuple)):
        return [_plain(x) for x in v]
    if isinstance(v, (np.floating, float)):
        return float(v)
    if isinstance(v, (np.integer, int)) and not isinstance(v, bool):
        return int(v)
    return v


def save_path(path: CameraPath, file) -> Path:
    """Write ``file`` (TUM poses) and its sidecar ``<stem>.yaml``; returns the TUM file's path."""
    file = Path(file)
    if file.suffix.lower() == ".yaml":
        raise UserError(f"{file}: give the trajectory file (.txt); the .yaml sidecar is written next to it")
    if file.suffix == "":
        file = file.with_suffix(".txt")
    header = (f"camera path {path.name}: {len(path.poses)} frames at {path.fps:g} fps, camera-to-world, OpenCV axes "
              f"(x right, y down, z forward)\nt tx ty tz qx qy qz qw   (t = frame / fps); see {file.stem}.yaml")
    camera.write_tum(file, path.poses, fps=path.fps, header=header)
    meta = dict(path.meta)
    doc = {"format": FORMAT, "name": path.name, "kind": meta.pop("kind", None), "fps": float(path.fps),
           "frames": int(len(path.poses)), "poses": file.name}
    for key in ("seed", "layouts", "planner", "stats"):
        if key in meta:
            doc[key] = meta.pop(key)
    if meta:
        doc["meta"] = meta
    side = file.with_suffix(".yaml")
    write_text_atomic(side, yaml.safe_dump(_plain(doc), sort_keys=False, default_flow_style=None, width=110))
    return file


def _resolve(name_or_file) -> Path:
    s = str(name_or_file)
    p = Path(s)
    if p.suffix.lower() in (".txt", ".yaml", ".tum") or "/" in s or "\\" in s or p.exists():
        return p.with_suffix(".txt") if p.suffix.lower() == ".yaml" else p
    f = paths_dir() / f"{s}.txt"
    if not f.exists():
        known = list_paths()
        raise UnknownNameError(f"unknown camera path '{s}'; known paths: {', '.join(known) if known else '(none)'} "
                               f"(in {paths_dir()}), or give a file")
    return f


def load_path(name_or_file) -> CameraPath:
    """A saved path: a name (``scenes/paths/<name>.txt`` + ``.yaml``) or a file."""
    txt = _resolve(name_or_file)
    side = txt.with_suffix(".yaml")
    fps, meta, name, n_expect = camera.DEFAULT_FPS, {}, txt.stem, None
    if side.exists():
        text = read_text(side)
        try:
            doc = safe_load(text)
        except yaml.YAMLError as e:
            mark = getattr(e, "problem_mark", None)
            where = f"line {mark.line + 1}" if mark is not None else None
            raise SceneFormatError(side, where, f"not valid YAML ({getattr(e, 'problem', e)})") from None
        except RecursionError:
            raise SceneFormatError(side, None, f"nested more than {MAX_DEPTH} levels deep") from None
        check_shape(side, doc)
        if not isinstance(doc, dict):
            raise SceneFormatError(side, None, "expected a mapping")
        if doc.get("format", FORMAT) != FORMAT:
            raise SceneFormatError(side, "format", f"expected '{FORMAT}', got {doc.get('format')!r}")
        fps = doc.get("fps", fps)
        if not is_number(fps) or not fps > 0:
            raise SceneFormatError(side, "fps", f"expected a number > 0, got {fps!r}")
        fps = float(fps)
        n_expect = doc.get("frames")
        if n_expect is not None:
            integer(side, n_expect, "frames")
        name = str(doc.get("name") or name)
        meta = {k: v for k, v in doc.items() if k not in ("format", "name", "fps", "frames", "poses")}
        meta.update(meta.pop("meta", None) or {})
    idx, poses = camera.read_tum(txt, fps=fps)
    if n_expect is not None and n_expect != len(poses):
        raise SceneFormatError(txt, None, f"{len(poses)} poses, but {side.name} says frames: {n_expect}")
    if side.exists() and len(idx) and not np.array_equal(idx, np.arange(len(idx))):
        bad = int(np.nonzero(idx != np.arange(len(idx)))[0][0])
        raise SceneFormatError(txt, f"pose {bad + 1}", f"timestamp gives frame {idx[bad]}, expected {bad} (t = frame / fps at {fps:g} fps)")
    return CameraPath(name, poses, fps, meta)
