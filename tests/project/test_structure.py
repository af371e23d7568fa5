"""The shape of the code: no import cycles between the toolkit's modules, at any level.

An import inside a function is still an import: a cycle dodged that way is a cycle. The graph is
read from the source (AST), so this needs no Blender and imports nothing.
"""

from __future__ import annotations

import ast
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parents[2]
PACKAGES = ("vrformats", "synth", "reloc")


def _modules() -> dict[str, Path]:
    mods = {}
    for pkg in PACKAGES:
        for p in sorted((REPO / pkg).rglob("*.py")):
            parts = p.relative_to(REPO).with_suffix("").parts
            mods[".".join(parts[:-1] if parts[-1] == "__init__" else parts)] = p
    return mods


def _imports(name: str, path: Path, mods: dict[str, Path]) -> set[str]:
    """Toolkit modules that ``name`` imports anywhere in its source (top level or in a function)."""
    package = name if path.name == "__init__.py" else name.rpartition(".")[0]
    out = set()
    for node in ast.walk(ast.parse(path.read_text(), str(path))):
        if isinstance(node, ast.ImportFrom):
            if node.level:
                base = package.split(".")[: len(package.split(".")) - node.level + 1]
                target = ".".join(base + ([node.module] if node.module else []))
            else:
                target = node.module or ""
            for alias in node.names:
                sub = f"{target}.{alias.name}"
                if sub in mods:
                    out.add(sub)
                elif target in mods:
                    out.add(target)
        elif isinstance(node, ast.Import):
            out |= {a.name for a in node.names if a.name in mods}
    out.discard(name)
    return out


def import_cycles() -> list[list[str]]:
    """Strongly connected components of more than one module (Tarjan), i.e. the import cycles."""
    mods = _modules()
    graph = {m: sorted(_imports(m, p, mods)) for m, p in mods.items()}
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    sccs: list[list[str]] = []

    def visit(v: str) -> None:
        index[v] = low[v] = len(index)
        stack.append(v)
        on_stack.add(v)
        for w in graph[v]:
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on_stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = []
            while True:
                w = stack.pop()
                on_stack.discard(w)
                comp.append(w)
                if w == v:
                    break
            if len(comp) > 1:
                sccs.append(sorted(comp))

    for m in graph:
        if m not in index:
            visit(m)
    return sccs


def test_the_scan_sees_imports():
    mods = _modules()
    assert "synth.scene.model" in mods and "reloc.cli" in mods
    # relative, absolute and function-level imports are all edges
    assert "synth.scene.geometry" in _imports("synth.scene.model", mods["synth.scene.model"], mods)
    assert "vrformats.cli" in _imports("reloc.cli", mods["reloc.cli"], mods)


def test_a_function_level_cycle_is_found(tmp_path, monkeypatch):
    pkg = tmp_path / "synth"
    pkg.mkdir()
    (pkg / "__init__.py").write_text("")
    (pkg / "a.py").write_text("from . import b\n")
    (pkg / "b.py").write_text("def f():\n    from .a import x\n")
    (tmp_path / "reloc").mkdir()
    (tmp_path / "reloc" / "__init__.py").write_text("")
    monkeypatch.setattr(sys.modules[__name__], "REPO", tmp_path)
    assert import_cycles() == [["synth.a", "synth.b"]]


def test_no_import_cycles():
    assert import_cycles() == []


# what each stage of reloc may import (besides the shared modules of test_stages_import_one_way, and synth)
MAY_IMPORT = {
    "reloc.map.boxmap": set(),
    "reloc.detection": {"reloc.detection"},  # frames -> detections, for map building and the front-end alike
    "reloc.frontend": {"reloc.map.boxmap", "reloc.detection", "reloc.frontend"},
    "reloc.map": {"reloc.map", "reloc.detection"},  # map building: all of reloc.map but boxmap; not the front-end
    "reloc.backend": {"reloc.map.boxmap", "reloc.detection", "reloc.frontend", "reloc.backend"},
    "reloc.baselines": {"reloc.map.boxmap", "reloc.detection", "reloc.frontend", "reloc.backend", "reloc.baselines"},
    "reloc.detector": {"reloc.detection", "reloc.detector"},  # training tools of the learned detector
}


def _stage(module: str) -> str | None:
    for s in sorted(MAY_IMPORT, key=len, reverse=True):
        if module == s or module.startswith(s + "."):
            return s
    return None


def test_stages_import_one_way():
    """map format <- detection <- {map building, front-end} <- back-end <- baselines <- experiments.

    Map building and the front-end are siblings: each may import the map format (``reloc.map.boxmap``)
    and detection (``reloc.detection``, which imports neither of them), never the other. The
    detector's training tools (``reloc.detector``) import detection only. Nothing imports the
experiments but the two front doors, the command line and the Python API.
    """
    mods = _modules()
    # resources: shipped files; evaluation: pose errors and recall; figures: the trajectory-over-map figure
    shared = {"reloc", "reloc.version", "reloc.config", "reloc.geometry", "reloc.io", "reloc.resources", "reloc.evaluation",
              "reloc.figures"}
    bad = []
    for m, p in mods.items():
        if not m.startswith("reloc."):
            continue
        stage = _stage(m)
        for t in _imports(m, p, mods):
            if not t.startswith("reloc") or t in shared:
                continue
            if t.startswith("reloc.experiments") and not (m.startswith("reloc.experiments") or m in ("reloc.cli", "reloc.api")):
                bad.append((m, t))
            elif stage is not None and not any(t == a or t.startswith(a + ".") for a in MAY_IMPORT[stage]):
                bad.append((m, t))
    assert bad == []
    assert _stage("reloc.frontend.odometry") == "reloc.frontend" and _stage("reloc.map.build") == "reloc.map"
    assert _stage("reloc.map.boxmap") == "reloc.map.boxmap" and _stage("reloc.detection.oracle") == "reloc.detection"


def test_the_format_layer_is_the_only_bridge():
    """vrformats imports neither half; reloc imports nothing of synth (it reads tours, maps and
    designs through vrformats)."""
    mods = _modules()
    graph = {m: _imports(m, p, mods) for m, p in mods.items()}
    assert [m for m in mods if m.startswith("vrformats.")], "the scan must see the vrformats package"
    assert {(m, t) for m, ts in graph.items() if m.startswith("vrformats") for t in ts
            if not t.startswith("vrformats")} == set()
    assert {(m, t) for m, ts in graph.items() if m.startswith("reloc") for t in ts if t.startswith("synth")} == set()


# synth's layers, lowest first: a module may import its own layer and the layers below it, never
# one above. ``synth.resources`` (where the shipped data lives) and the package root (its version)
# are below everything; every command-line module (``synth.cli``, ``synth.<layer>.cli``) is the top.
# The mesh layer (``synth.mesh``: glTF, URDF, collision, support surfaces) reads standard formats for every
# dataset; the scene sources (``synth.sources.<name>``: ReplicaCAD) sit above layout and below the renderers.
SYNTH_LAYERS = ("scene", "assets", "mesh", "paths", "layout", "sources", "render", "blender", "tour", "jobs", "trainset", "cli",
                "api")
SYNTH_BASE = {"synth", "synth.resources", "synth.version"}


def synth_layer(module: str) -> int | None:
    """Index of ``module``'s layer in SYNTH_LAYERS (None: the base modules)."""
    if module in SYNTH_BASE:
        return None
    parts = module.split(".")
    if parts[-1] in ("cli", "api"):  # the command line and the Python API: the top, side by side
        return SYNTH_LAYERS.index(parts[-1])
    if parts[1] not in SYNTH_LAYERS:
        raise AssertionError(f"{module}: not in any of synth's layers; add its package to SYNTH_LAYERS")
    return SYNTH_LAYERS.index(parts[1])


def synth_upward_imports(mods) -> list[tuple[str, str]]:
    bad = []
    for m, p in mods.items():
        if not m.startswith("synth."):
            continue
        lm = synth_layer(m)
        for t in _imports(m, p, mods):
            if not t.startswith("synth"):
                continue
            lt = synth_layer(t)
            if lt is not None and (lm is None or lt > lm):
                bad.append((m, t))
    return sorted(bad)


def test_synth_layers_import_downwards():
    """scene < assets < mesh < paths < layout < sources < render < blender < tour < jobs < trainset < cli."""
    mods = _modules()
    assert synth_upward_imports(mods) == []
    # every synth module is in a layer, and the layers are the subpackages on disk
    on_disk = {p.name for p in (REPO / "synth").iterdir() if (p / "__init__.py").exists()}
    assert on_disk == set(SYNTH_LAYERS) - {"cli", "api"}
    flat = sorted(m for m in mods if m.count(".") == 1 and m not in SYNTH_BASE and m.startswith("synth.")
                  and mods[m].name != "__init__.py")
    assert flat == ["synth.api", "synth.cli"], f"modules at synth's top level besides api, cli, resources and version: {flat}"


def test_an_upward_synth_import_is_found(tmp_path, monkeypatch):
    for pkg in ("synth", "synth/scene", "synth/layout", "vrformats", "reloc"):
        (tmp_path / pkg).mkdir()
        (tmp_path / pkg / "__init__.py").write_text("")
    (tmp_path / "synth" / "layout" / "apartment.py").write_text("from ..scene import model\n")
    (tmp_path / "synth" / "scene" / "model.py").write_text("def f():\n    from ..layout.apartment import g\n")
    monkeypatch.setattr(sys.modules[__name__], "REPO", tmp_path)
    assert synth_upward_imports(_modules()) == [("synth.scene.model", "synth.layout.apartment")]


# packages that work on any layout, whatever dataset it came from: they import no scene source (what they
# need of meshes is the mesh layer's, synth.mesh), so a second source plugs in without touching them
SOURCE_FREE = ("synth.layout", "synth.render", "synth.blender")
SCENE_SOURCES = ("synth.sources", "synth.replicacad")


def scene_source_imports(mods) -> list[tuple[str, str]]:
    """(module, imported scene-source module) for every module of SOURCE_FREE, top level or in a function."""
    def under(m, prefixes):
        return any(m == s or m.startswith(s + ".") for s in prefixes)

    return sorted((m, t) for m, p in mods.items() if under(m, SOURCE_FREE)
                  for t in _imports(m, p, mods) if under(t, SCENE_SOURCES))


def test_layout_render_and_blender_import_no_scene_source():
    mods = _modules()
    assert [m for m in mods if m.startswith("synth.sources.replicacad.")], "the scan must see the ReplicaCAD source"
    assert scene_source_imports(mods) == []


def test_a_scene_source_import_is_found(tmp_path, monkeypatch):
    for pkg in ("synth", "synth/render", "synth/sources", "synth/sources/replicacad", "synth/mesh", "vrformats", "reloc"):
        (tmp_path / pkg).mkdir()
        (tmp_path / pkg / "__init__.py").write_text("")
    (tmp_path / "synth" / "mesh" / "gltf.py").write_text("")
    (tmp_path / "synth" / "sources" / "replicacad" / "importer.py").write_text("from ...mesh import gltf\n")
    (tmp_path / "synth" / "render" / "meshes.py").write_text(
        "from ..mesh.gltf import x\n\ndef f():\n    from ..sources.replicacad.importer import load_replicacad\n")
    monkeypatch.setattr(sys.modules[__name__], "REPO", tmp_path)
    mods = _modules()
    assert scene_source_imports(mods) == [("synth.render.meshes", "synth.sources.replicacad.importer")]
    # the layer test sees it too (render is above sources), but a layout CLI module would pass it: this one does not
    (tmp_path / "synth" / "layout").mkdir()
    (tmp_path / "synth" / "layout" / "__init__.py").write_text("")
    (tmp_path / "synth" / "layout" / "cli.py").write_text("from ..sources import replicacad\n")
    mods = _modules()
    assert ("synth.layout.cli", "synth.sources.replicacad") in scene_source_imports(mods)
    assert ("synth.layout.cli", "synth.sources.replicacad") not in synth_upward_imports(mods)


def test_bpy_is_imported_only_by_the_blender_package():
    bad = []
    for m, p in _modules().items():
        for node in ast.walk(ast.parse(p.read_text(), str(p))):
            names = [a.name for a in node.names] if isinstance(node, ast.Import) else \
                [node.module or ""] if isinstance(node, ast.ImportFrom) and not node.level else []
            if any(n == "bpy" or n.startswith("bpy.") for n in names) and not m.startswith("synth.blender"):
                bad.append(m)
    assert bad == []


def test_pyproject_lists_every_package_on_disk():
    """pyproject.toml lists its packages by hand (``synth.scenes`` and ``synth.render_jobs`` are the root
    folders ``scenes/`` and ``render_jobs/``, mapped by package-dir): a new subpackage missing from the
    list would be left out of the wheel."""
    import tomllib

    conf = tomllib.loads((REPO / "pyproject.toml").read_text())["tool"]["setuptools"]
    on_disk = {p.parent.relative_to(REPO).as_posix().replace("/", ".") for pkg in PACKAGES
               for p in (REPO / pkg).rglob("__init__.py")}
    mapped = conf["package-dir"]
    assert mapped == {"synth.scenes": "scenes", "synth.render_jobs": "render_jobs"}
    assert all((REPO / d).is_dir() and not (REPO / d / "__init__.py").exists() for d in mapped.values())
    assert set(conf["packages"]) == on_disk | set(mapped)


def test_tests_mirror_the_packages():
    """tests/<package>/<subpackage>/test_*.py tests that subpackage (tests/project: the toolkit as a whole:
    structure, docs, wheel, command line, faults); shared helpers and factories sit at tests/ (conftest.py)."""
    tests = REPO / "tests"
    folders = {p.parent.relative_to(tests).as_posix() for p in tests.rglob("test_*.py") if "data" not in p.parts}
    not_a_package = sorted(f for f in folders if f != "project" and not (REPO / f / "__init__.py").is_file())
    assert not_a_package == [], f"test folders that mirror no package: {not_a_package}"
    assert not list(tests.glob("test_*.py")), "a test file at tests/ itself: put it in the folder of what it tests"


def test_license_and_citation_say_what_the_project_is():
    """LICENSE is the MIT text pyproject names; CITATION.cff cites the toolkit and, as the preferred
    citation, the paper it implements (validated once with cffconvert --validate: schema 1.2.0)."""
    import yaml

    root = Path(__file__).resolve().parents[2]
    assert (root / "LICENSE").read_text().startswith("MIT License")
    cff = yaml.safe_load((root / "CITATION.cff").read_text())
    assert cff["cff-version"] == "1.2.0" and cff["license"] == "MIT"
    import synth

    assert cff["version"] == synth.__version__
    paper = cff["preferred-citation"]
    assert paper["title"].startswith("VideoReloc: Long-Term Indoor Video Relocalization")
    assert len(paper["authors"]) == 9 and paper["url"] == "https://videoreloc.github.io"


def test_one_version_everywhere():
    import tomllib

    import reloc
    import synth

    root = Path(__file__).resolve().parents[2]
    version = tomllib.loads((root / "pyproject.toml").read_text())["project"]["version"]
    assert synth.__version__ == reloc.__version__ == version
