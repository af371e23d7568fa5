"""The Python API: docs/api.md's examples run as they are, in an empty working folder, and what
they print is checked; ``import synth, reloc`` loads no heavy library; every API name resolves,
has a docstring and is the code path of a command."""

from __future__ import annotations

import contextlib
import io
import re
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
PAGE = ROOT / "docs" / "api.md"


def python_blocks(page: Path = PAGE) -> list[str]:
    return re.findall(r"```python\n(.*?)```", page.read_text(), flags=re.S)


def run_blocks(blocks, namespace) -> str:
    out = io.StringIO()
    with contextlib.redirect_stdout(out):
        for b in blocks:
            exec(compile(b, str(PAGE), "exec"), namespace)
    return out.getvalue()


@pytest.fixture(scope="module")
def page_run(tmp_path_factory):
    """docs/api.md's blocks, in order, in one namespace, in an empty folder: (printed text, namespace)."""
    import os

    here = os.getcwd()
    work = tmp_path_factory.mktemp("api_page")
    os.chdir(work)
    try:
        ns: dict = {}
        text = run_blocks(python_blocks(), ns)
    finally:
        os.chdir(here)
    return text, ns, work


def test_the_page_has_the_examples_the_tests_run():
    blocks = python_blocks()
    assert len(blocks) == 4 and blocks[0].strip() == "import synth\nimport reloc"


def test_a_tour_a_map_a_run_and_its_recall(page_run):
    text, ns, work = page_run
    assert "300 query frames, 1200 mapping frames" in text
    assert re.search(r"BoxMap\('out/api/map.json', \d+ boxes, \d+ objects\)", text), text
    for traj in ("causal", "closure"):
        m = re.search(rf"{traj}: recall at 1 m/10 deg ([\d.]+) %", text)
        assert m and 0.0 <= float(m.group(1)) <= 100.0, text
        assert ns["scores"][traj]["recall_1m_10deg"] == pytest.approx(float(m.group(1)) / 100, abs=1e-3)
    # what the API wrote is what the commands read: the map file and the run's trajectories
    assert (work / "out/api/map.json").is_file() and (work / "out/api/run/closure.txt").is_file()
    assert ns["summary"]["frames"] == 300


def test_layouts_and_paths(page_run):
    text, ns, work = page_run
    assert re.search(r"apt_0 \d+ objects in \d+ rooms", text) and "apt_api moved from apt_0" in text
    assert "walk 600 poses" in text and "apt_api walk 60 frames" in text
    assert (work / "out/api/apt_api.yaml").is_file() and (work / "out/api/walk.yaml").is_file()


def test_the_quickstart_experiment_and_its_checks(page_run):
    text, ns, work = page_run
    m = re.search(r"VideoReloc, clip closure: ([\d.]+) \[([\d.]+), ([\d.]+)\] %", text)
    assert m, text
    point, lo, hi = map(float, m.groups())
    assert lo <= point <= hi
    rows = ns["rows"]
    assert f"{sum(r['passed'] for r in rows)} of {len(rows)} checks pass" in text
    assert all(r["passed"] for r in rows), rows  # the shipped checks hold on the shipped quickstart
    assert (work / "out/quickstart/checks.xml").is_file()
    assert (work / "out/quickstart/experiment/report.html").is_file()


def test_importing_the_packages_loads_no_heavy_library():
    code = ("import sys, synth, reloc; heavy = ('bpy', 'open3d', 'onnxruntime', 'torch', 'cv2', 'matplotlib', 'numpy');"
            "print(sorted(m for m in sys.modules if m.split('.')[0] in heavy))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=ROOT, check=True).stdout
    assert out.strip() == "[]"


@pytest.mark.parametrize("package", ["synth", "reloc"])
def test_every_api_name_resolves_and_says_what_it_does(package):
    import importlib
    import inspect

    pkg = importlib.import_module(package)
    api = importlib.import_module(f"{package}.api")
    assert sorted(pkg.__all__) == sorted(api.__all__)
    documented = PAGE.read_text()
    for name in api.__all__:
        fn = getattr(pkg, name)
        assert fn is getattr(api, name) and callable(fn)
        assert fn.__doc__ and len(fn.__doc__.split()) >= 8, name
        assert f"`{name}(" in documented, f"docs/api.md has no reference row for {package}.{name}"
        for p in inspect.signature(fn).parameters.values():
            assert p.annotation is not inspect.Parameter.empty, f"{package}.{name}({p.name}) has no type"


def test_bad_input_is_the_commands_one_line_error(tmp_path):
    import reloc
    import synth
    from vrformats.errors import UserError

    cases = [
        (lambda: synth.load_layout("apt_99"), "apt_99"),
        (lambda: synth.plan_path("query", []), "at least one layout"),
        (lambda: synth.plan_path("spiral", ["apt_0"]), "spiral"),
        (lambda: synth.read_tour(tmp_path), str(tmp_path)),
        (lambda: reloc.load_map(tmp_path / "none.json"), "none.json"),
        (lambda: reloc.build_map(tmp_path, detector="magic"), str(tmp_path)),
        (lambda: reloc.check("no_such_checks", tmp_path), "no_such_checks"),
    ]
    (tmp_path / "notamap.json").write_text("{}")
    cases.append((lambda: reloc.load_map(tmp_path / "notamap.json"), "notamap.json"))
    for call, says in cases:
        with pytest.raises(UserError) as e:
            call()
        msg = str(e.value)
        assert says in msg and "\n" not in msg, msg
