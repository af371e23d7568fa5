"""The class table (``scenes/classes.yaml``): class names, semantic ids, support and mobility."""

from __future__ import annotations

import functools
import re
from dataclasses import dataclass
from pathlib import Path

import yaml

from formats.errors import SceneFormatError, UnknownNameError

from .resources import classes_file

SUPPORTS = ("floor", "surface", "wall", "ceiling")


@dataclass(frozen=True)
class ClassInfo:
    name: str
    id: int
    support: str
    movable: bool
    structure: bool = False


@dataclass(frozen=True)
class ClassTable:
    classes: dict[str, ClassInfo]
    replicacad_aliases: dict[str, str]
    source: str

    def __contains__(self, name: str) -> bool:
        return name in self.classes

    def get(self, name: str) -> ClassInfo:
        try:
            return self.classes[name]
        except KeyError:
            raise UnknownNameError(
                f"unknown class '{name}' (not in {self.source}); known: {', '.join(sorted(self.classes))}"
            ) from None

    def id_of(self, name: str) -> int:
        return self.get(name).id

    def by_id(self) -> dict[int, str]:
        return {c.id: c.name for c in self.classes.values()}

    def object_classes(self) -> list[str]:
        return [c.name for c in self.classes.values() if not c.structure]

    def replicacad_class(self, template_name: str) -> str | None:
        """Class of a ReplicaCAD template name, or None when no rule maps it.

        ``objects/frl_apartment_chair_01`` -> strip folder, ``frl_apartment_`` prefix and the
        trailing ``_NN`` -> ``chair`` -> aliases / class names.
        """
        base = template_name.replace("\\", "/").rsplit("/", 1)[-1]
        base = re.sub(r"\.(object_config\.json|glb)$", "", base)
        base = re.sub(r"^frl_apartment_", "", base)
        candidates = [base, re.sub(r"(_\d+)+$", "", base)]
        for cand in candidates:
            if cand in self.replicacad_aliases:
                return self.replicacad_aliases[cand]
            if cand in self.classes and not self.classes[cand].structure:
                return cand
        return None


def parse_class_table(data, source: str) -> ClassTable:
    if not isinstance(data, dict) or not isinstance(data.get("classes"), dict):
        raise SceneFormatError(source, "classes", "expected a mapping of class name -> properties")
    classes: dict[str, ClassInfo] = {}
    seen_ids: dict[int, str] = {}
    for name, props in data["classes"].items():
        field = f"classes.{name}"
        if not isinstance(props, dict):
            raise SceneFormatError(source, field, "expected a mapping with id, support, movable")
        unknown = set(props) - {"id", "support", "movable", "structure"}
        if unknown:
            raise SceneFormatError(source, field, f"unknown key(s) {sorted(unknown)}")
        cid = props.get("id")
        if not isinstance(cid, int) or isinstance(cid, bool) or cid <= 0:
            raise SceneFormatError(source, f"{field}.id", f"expected a positive integer, got {cid!r}")
        if cid in seen_ids:
            raise SceneFormatError(source, f"{field}.id", f"id {cid} already used by '{seen_ids[cid]}'")
        seen_ids[cid] = name
        support = props.get("support")
        if support not in SUPPORTS:
            raise SceneFormatError(source, f"{field}.support", f"expected one of {SUPPORTS}, got {support!r}")
        movable = props.get("movable")
        if not isinstance(movable, bool):
            raise SceneFormatError(source, f"{field}.movable", f"expected true or false, got {movable!r}")
        classes[name] = ClassInfo(name, cid, support, movable, bool(props.get("structure", False)))
    aliases = (data.get("replicacad") or {}).get("aliases") or {}
    for key, target in aliases.items():
        if target not in classes:
            raise SceneFormatError(source, f"replicacad.aliases.{key}", f"maps to unknown class '{target}'")
    return ClassTable(classes, dict(aliases), source)


@functools.lru_cache(maxsize=8)
def _load(path: str) -> ClassTable:
    p = Path(path)
    if not p.exists():
        raise SceneFormatError(p, None, "class table not found")
    try:
        data = yaml.safe_load(p.read_text())
    except yaml.YAMLError as e:
        raise SceneFormatError(p, None, f"malformed YAML: {e}".replace("\n", " ")) from None
    return parse_class_table(data, str(p))


def class_table(path: str | Path | None = None) -> ClassTable:
    """The class table, loaded once per path."""
    return _load(str(path or classes_file()))
