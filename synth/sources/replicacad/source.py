"""ReplicaCAD as a scene source (``synth.sources``): the ``replicacad:`` section of a spec, its dataset
folder, the import of its scenes and the ``synth scene import-replicacad`` command. Each call imports
what it needs, so looking the source up costs nothing."""

from __future__ import annotations


class ReplicaCADSource:
    name = "replicacad"

    def parse_section(self, doc, source: str) -> dict:
        from .job import parse_section

        return parse_section(doc, source)

    def resolve_root(self, section: dict, source: str, cli_root: str | None = None):
        from .job import resolve_root

        return resolve_root(section, source, cli_root)

    def prepare(self, spec, out, cli_root: str | None = None, progress=print):
        from .job import prepare

        return prepare(spec, out, cli_root, progress=progress)

    def list_scenes(self, root) -> list[str]:
        from .importer import list_scenes

        return list_scenes(root)

    def load_scene(self, root, name: str, allow_unknown: bool = False, **kw):
        from .importer import load_replicacad

        return load_replicacad(root, name, allow_unknown=allow_unknown, **kw)

    def register_scene_cli(self, subparsers) -> None:
        from .commands import register_scene_cli

        register_scene_cli(subparsers)


SOURCE = ReplicaCADSource()
