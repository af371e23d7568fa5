"""Reading the YAML (and JSON) files users write: specs, layouts, lighting presets, configs.

Every reader bounds what a file can make it do (a file may come from someone else):

* size: at most ``MAX_BYTES`` (a larger file is refused before it is parsed);
* text: UTF-8, or one line naming the byte that is not;
* depth: nesting deeper than ``MAX_DEPTH`` levels is refused (the parsers recurse; 100,000 levels
  would end in a RecursionError);
* YAML aliases: a document that expands to more than ``MAX_VALUES`` values (a "billion laughs" of
  anchors and aliases) is refused before any code walks it.

Error messages show bounded excerpts of values (``vrformats.fields.shown``), never a whole value.
"""

from __future__ import annotations

import json
from pathlib import Path

import yaml

from .errors import SceneFormatError

MAX_BYTES = 256 * 2**20  # 256 MiB: the largest file the toolkit writes (a map, results.json) is far below
MAX_DEPTH = 64  # levels of nesting; the toolkit's own files use at most ~8
MAX_VALUES = 2_000_000  # values in a YAML document once its aliases are expanded


def read_text(path, what: str = "file") -> str:
    """A file's text: SceneFormatError naming the file when it is missing, larger than
    ``MAX_BYTES``, unreadable or not UTF-8 (with the offset of the first bad byte)."""
    path = Path(path)
    try:
        size = path.stat().st_size
    except FileNotFoundError:
        raise SceneFormatError(path, None, f"{what} not found") from None
    except OSError as e:
        raise SceneFormatError(path, None, f"cannot read: {e.strerror or e}") from None
    if size > MAX_BYTES:
        raise SceneFormatError(path, None, f"{size / 2**20:.0f} MiB; files larger than {MAX_BYTES // 2**20} MiB are refused")
    try:
        data = path.read_bytes()
    except OSError as e:
        raise SceneFormatError(path, None, f"cannot read: {e.strerror or e}") from None
    return decode_text(path, data)


def decode_text(path, data: bytes) -> str:
    try:
        return data.decode("utf-8")
    except UnicodeDecodeError as e:
        raise SceneFormatError(path, None, f"not UTF-8 text: byte 0x{data[e.start]:02X} at offset {e.start} "
                                           "(save the file as UTF-8)") from None


def parse_json(path, text: str):
    """``json.loads`` with the depth bound; SceneFormatError naming the file (and the line)."""
    try:
        data = json.loads(text)
    except json.JSONDecodeError as e:
        raise SceneFormatError(path, f"line {e.lineno}", f"not valid JSON ({e.msg})") from None
    except RecursionError:
        raise SceneFormatError(path, None, f"nested more than {MAX_DEPTH} levels deep") from None
    check_shape(path, data)
    return data


def check_shape(path, data) -> None:
    """Refuse a parsed document nested more than ``MAX_DEPTH`` levels or (through YAML aliases)
    holding more than ``MAX_VALUES`` values. Iterative: a hostile document cannot make it recurse."""
    stack = [(data, 0)]
    seen = 0
    while stack:
        v, d = stack.pop()
        seen += 1
        if seen > MAX_VALUES:
            raise SceneFormatError(path, None, f"expands to more than {MAX_VALUES:,} values (YAML anchors and aliases?)")
        if d > MAX_DEPTH:
            raise SceneFormatError(path, None, f"nested more than {MAX_DEPTH} levels deep")
        if isinstance(v, dict):
            stack.extend((x, d + 1) for x in v.values())
        elif isinstance(v, list):
            stack.extend((x, d + 1) for x in v)


def read_json(path, missing: str = "file not found", expect_object: bool = True):
    """The value in a JSON file the toolkit writes (tour metadata, export manifests, design.json,
    an experiment's results.json); a missing, unreadable or malformed file is a SceneFormatError
    naming the file (and the line), ``missing`` saying what was expected there. With
    ``expect_object`` anything but a JSON object is one too. Every reader of such a file uses this."""
    path = Path(path)
    if not path.is_file():
        raise SceneFormatError(path, None, missing)
    data = parse_json(path, read_text(path))
    if expect_object and not isinstance(data, dict):
        raise SceneFormatError(path, None, f"expected a JSON object, got {type(data).__name__}")
    return data


def read_yaml(path) -> object:
    """The document in a YAML (or JSON) file; a missing, unreadable or malformed file is a
    SceneFormatError naming the file (and the parser's line and column)."""
    path = Path(path)
    if not path.exists():
        raise SceneFormatError(path, None, "file not found")
    return parse_yaml(path, read_text(path))


# libyaml's parser when PyYAML was built with it (the same constructor, so the same values; a layout
# file parses about ten times faster, and every render worker reads one)
_FAST_LOADER = getattr(yaml, "CSafeLoader", None)


def safe_load(text: str) -> object:
    """``yaml.safe_load(text)``, through libyaml's parser where PyYAML has it. A document that parser
    refuses is parsed again by PyYAML's own, whose error (or RecursionError) is the one raised: what a
    malformed file is told does not depend on how PyYAML was built."""
    if _FAST_LOADER is not None:
        try:
            return yaml.load(text, Loader=_FAST_LOADER)
        except yaml.YAMLError:
            pass
    return yaml.safe_load(text)


def parse_yaml(path, text: str) -> object:
    """YAML text (JSON when ``path`` ends in .json) parsed with the bounds above."""
    path = Path(path)
    if path.suffix == ".json":
        return parse_json(path, text)
    try:
        data = safe_load(text)
    except yaml.YAMLError as e:
        raise SceneFormatError(path, None, "malformed YAML: " + str(e).replace("\n", " ")[:500]) from None
    except (RecursionError, MemoryError):
        raise SceneFormatError(path, None, f"nested more than {MAX_DEPTH} levels deep") from None
    except ValueError as e:  # a constructor's complaint (e.g. a timestamp out of range)
        raise SceneFormatError(path, None, "malformed YAML: " + str(e).replace("\n", " ")[:500]) from None
    check_shape(path, data)
    return data
