"""Reading the YAML (and JSON) files users write: specs, layouts, lighting presets, configs."""

from __future__ import annotations

import json
from pathlib import Path

import yaml

from .errors import SceneFormatError


def read_json(path, missing: str = "file not found", expect_object: bool = True):
    """The value in a JSON file the toolkit writes (tour metadata, export manifests, design.json,
    an experiment's results.json); a missing, unreadable or malformed file is a SceneFormatError
    naming the file (and the line), ``missing`` saying what was expected there. With
    ``expect_object`` anything but a JSON object is one too. Every reader of such a file uses this."""
    path = Path(path)
    if not path.is_file():
        raise SceneFormatError(path, None, missing)
    try:
        data = json.loads(path.read_text())
    except json.JSONDecodeError as e:
        raise SceneFormatError(path, f"line {e.lineno}", f"not valid JSON ({e.msg})") from None
    except OSError as e:
        raise SceneFormatError(path, None, f"cannot read: {e.strerror or e}") from None
    except UnicodeDecodeError as e:
        raise SceneFormatError(path, None, f"cannot read: not UTF-8 text ({e.reason})") from None
    if expect_object and not isinstance(data, dict):
        raise SceneFormatError(path, None, f"expected a JSON object, got {type(data).__name__}")
    return data


def read_yaml(path) -> object:
    """The document in a YAML (or JSON) file; a missing, unreadable or malformed file is a
    SceneFormatError naming the file (and the parser's line and column)."""
    path = Path(path)
    if not path.exists():
        raise SceneFormatError(path, None, "file not found")
    try:
        text = path.read_text()
    except OSError as e:
        raise SceneFormatError(path, None, f"cannot read: {e.strerror}") from None
    try:
        if path.suffix == ".json":
            return json.loads(text)
        return yaml.safe_load(text)
    except (yaml.YAMLError, ValueError) as e:
        raise SceneFormatError(path, None, "malformed " + ("JSON" if path.suffix == ".json" else "YAML") + ": " + str(e).replace("\n", " ")) from None
