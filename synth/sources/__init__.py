"""Scene sources: datasets whose scenes become layouts (``synth.scene.model.Layout``), looked up by name.

A source is one package under ``synth/sources/`` that registers an object here (``SOURCES``). Its name is
the key of its section in a render job spec or a trainset spec (``replicacad:``), and what it offers
is what the jobs, the trainsets and the command line need of a dataset of scenes:

* ``parse_section(doc, source) -> dict``: the spec's section, checked (errors name the spec file and key);
* ``resolve_root(section, source, cli_root=None) -> Path``: the dataset folder the section, the command
  line (``cli_root``) or the environment names;
* ``prepare(spec, out, cli_root=None, progress=print) -> JobSpec``: import the spec's scenes and plan its
  paths under ``out``, returning the spec rewritten to those files;
* ``list_scenes(root) -> list[str]`` and ``load_scene(root, name, allow_unknown=False, **kw) -> Layout``;
* ``register_scene_cli(subparsers)``: its commands in the ``synth scene`` group (``import-replicacad``).

Sources sit above the mesh layer (``synth.mesh``: glTF, URDF, collision, support surfaces), ``paths``
and ``layout``; below the renderers, the jobs and the command line. Nothing below this layer imports a
source (tests/project/test_structure.py). A second source (HSSD, 3D-FRONT) is a package ``synth/sources/<name>/``
with a ``source.py`` giving such an object, added to ``SOURCES`` (docs/architecture.md).
"""

from __future__ import annotations

from vrformats.errors import UnknownNameError

from .replicacad.source import SOURCE as REPLICACAD

SOURCES = {REPLICACAD.name: REPLICACAD}


def get_source(name: str):
    """The scene source registered as ``name`` (the key of its spec section); UnknownNameError naming the known ones."""
    try:
        return SOURCES[name]
    except (KeyError, TypeError):
        raise UnknownNameError(f"unknown scene source {name!r}; known: {', '.join(sorted(SOURCES))}") from None


def spec_source(spec):
    """The scene source whose section ``spec`` (a job spec) has, or None: its layouts are files."""
    for name, src in SOURCES.items():
        if getattr(spec, name, None) is not None:
            return src
    return None
