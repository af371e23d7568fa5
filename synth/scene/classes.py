"""The class table (``scenes/classes.yaml``): class names, semantic ids, support and mobility."""

from __future__ import annotations

import functools
import re
from dataclasses import dataclass
from pathlib import Path


from vrformats import fields
from vrformats.errors import SceneFormatError, UnknownNameError
from vrformats.yamlfile import read_yaml

from ..resources import classes_file, replicacad_lexicon_file

SUPPORTS = ("floor", "surface", "wall", "ceiling")


@dataclass(frozen=True)
class ClassInfo:
    name: str
    id: int
    support: str
    movable: bool
    structure: bool = False
    imported: bool = False  # only imported datasets have it: synth.assets.registry has no generator for it


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
        unknown = set(props) - {"id", "support", "movable", "structure", "imported"}
        if unknown:
            raise SceneFormatError(source, field, f"unknown key(s) {sorted(unknown)}")
        cid = fields.positive_int(source, props.get("id"), f"{field}.id")
        if cid in seen_ids:
            raise SceneFormatError(source, f"{field}.id", f"id {cid} already used by '{seen_ids[cid]}'")
        seen_ids[cid] = name
        support = props.get("support")
        if support not in SUPPORTS:
            raise SceneFormatError(source, f"{field}.support", f"expected one of {SUPPORTS}, got {support!r}")
        movable = fields.boolean(source, props.get("movable"), f"{field}.movable")
        for flag in ("structure", "imported"):
            fields.boolean(source, props.get(flag, False), f"{field}.{flag}")
        classes[name] = ClassInfo(name, cid, support, movable, bool(props.get("structure", False)), bool(props.get("imported", False)))
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
    return parse_class_table(read_yaml(p), str(p))


def class_table(path: str | Path | None = None) -> ClassTable:
    """The class table, loaded once per path."""
    return _load(str(path or classes_file()))


LEXICON_FORMAT = "synth-replicacad-lexicon/1"


@dataclass(frozen=True)
class LexiconTable:
    """``scenes/replicacad_lexicon.yaml``: ReplicaCAD lexicon names and template overrides -> classes."""

    lexicon: dict[str, str]  # lexicon class name -> toolkit class
    templates: dict[str, str]  # template base name -> toolkit class (lexicon errors, articulated objects)
    source: str
    soft: frozenset = frozenset()  # lexicon names of soft furnishings (they compress: synth.layout.validity)

    def class_of(self, template_name: str, lexicon_name: str | None) -> tuple[str | None, str]:
        """(class, rule) of an object: its template override, else its lexicon name's class; None when
        neither applies. ``rule`` says which: ``"template"``, ``"lexicon"`` or ``""``."""
        base = template_base(template_name)
        if base in self.templates:
            return self.templates[base], "template"
        if lexicon_name is not None and lexicon_name in self.lexicon:
            return self.lexicon[lexicon_name], "lexicon"
        return None, ""


def template_base(template_name: str) -> str:
    """``objects/frl_apartment_chair_01.object_config.json`` -> ``frl_apartment_chair_01``."""
    base = template_name.replace("\\", "/").rsplit("/", 1)[-1]
    return re.sub(r"\.(object_config\.json|ao_config\.json|urdf|glb)$", "", base)


def parse_lexicon_table(data, source: str, classes: ClassTable) -> LexiconTable:
    if not isinstance(data, dict):
        raise SceneFormatError(source, None, "expected a mapping with format, templates, lexicon")
    unknown = set(data) - {"format", "templates", "lexicon", "soft"}
    if unknown:
        raise SceneFormatError(source, sorted(unknown)[0], "unknown key")
    if data.get("format") != LEXICON_FORMAT:
        raise SceneFormatError(source, "format", f"expected '{LEXICON_FORMAT}', got {data.get('format')!r}")
    out = {}
    for key in ("templates", "lexicon"):
        m = data.get(key) or {}
        if not isinstance(m, dict):
            raise SceneFormatError(source, key, "expected a mapping of name -> class")
        for name, cls in m.items():
            if not isinstance(cls, str) or cls not in classes.classes:
                raise SceneFormatError(source, f"{key}.{name}", f"maps to unknown class {cls!r} (not in {classes.source})")
            if classes.classes[cls].structure:
                raise SceneFormatError(source, f"{key}.{name}", f"maps to structure class '{cls}'; objects need an object class")
        out[key] = {str(k): v for k, v in m.items()}
    soft = data.get("soft") or []
    if not isinstance(soft, list) or not all(isinstance(x, str) for x in soft):
        raise SceneFormatError(source, "soft", "expected a list of lexicon names")
    bad = sorted(set(soft) - set(out["lexicon"]))
    if bad:
        raise SceneFormatError(source, "soft", f"names not in lexicon: {', '.join(bad)}")
    return LexiconTable(out["lexicon"], out["templates"], source, frozenset(soft))


@functools.lru_cache(maxsize=8)
def _read_lexicon(path: str):
    p = Path(path)
    if not p.exists():
        raise SceneFormatError(p, None, "ReplicaCAD lexicon table not found")
    return read_yaml(p)


def lexicon_table(path: str | Path | None = None, classes: ClassTable | None = None) -> LexiconTable:
    """The ReplicaCAD lexicon table (read once per path), checked against ``classes`` (default: the class table)."""
    p = str(path or replicacad_lexicon_file())
    default = class_table()
    if classes is None or classes.source == default.source:
        return parse_lexicon_table(_read_lexicon(p), p, default)
    # a user's own class table: the rules whose class it lacks do not apply (its name rules do)
    data = dict(_read_lexicon(p) or {})
    for key in ("templates", "lexicon"):
        if isinstance(data.get(key), dict):
            data[key] = {k: v for k, v in data[key].items() if v in classes.classes}
    if isinstance(data.get("soft"), list) and isinstance(data.get("lexicon"), dict):
        data["soft"] = [n for n in data["soft"] if n in data["lexicon"]]
    return parse_lexicon_table(data, p, classes)
