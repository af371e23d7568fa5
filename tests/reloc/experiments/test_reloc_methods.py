"""The methods of ``reloc experiment`` are registered by name (reloc.experiments.methods): a method
defined in one module outside the package, registering a new name, is used by an experiment spec
with nothing else changed (spec, tasks, runner and tables ask the registry), in worker processes
too; an unknown name is one line listing the registered ones."""

from __future__ import annotations

import json
import sys
import uuid

import pytest
import yaml

from reloc.cli import main as reloc_main
from reloc.experiments import methods, tables

IN_TREE = ("videoreloc", "videoreloc_oracle", "fpfh_icp", "appearance", "one_frame")

# A whole method in one module: a map kind built from the mapping tour (its frame count) and a
# "relocalizer" that returns the ground-truth pose of every other frame, one Table I row.
PLUGIN = '''
from vrformats.atomic import write_json_atomic
from vrformats.camera import write_tum
from vrformats.yamlfile import read_json

from reloc.experiments.methods import MapKind, Method, Row, register, register_map
from reloc.experiments.methods.common import load_map


def build(task, tour, out):
    write_json_atomic(out, {"frames": len(tour), "every": task["options"]["every"]})


def run(task, tour, d):
    m = load_map("frame_count", task["count_map"])
    every = m["every"]
    frames = [int(i) for i in tour.frame_indices][::every]
    poses = dict(zip((int(i) for i in tour.frame_indices), tour.poses))
    write_tum(d / "causal.txt", [poses[i] for i in frames], fps=tour.fps, frames=frames)
    return {"map_frames": m["frames"]}


register_map(MapKind("frame_count", "frame_count.json", build=build, load=lambda path, cfg: read_json(path),
                     options=lambda spec: {"every": 2}))
register(Method("every_other", "Every other frame (test)", rows=(Row("causal", "Every other frame, ground truth"),),
                run=run, primary="causal", maps=("frame_count",), uses="frame_count",
                task_args=lambda spec, files: {"count_map": str(files["frame_count"])}))
'''


@pytest.fixture
def plugin(tmp_path, monkeypatch):
    """The module above, importable (also by the experiment's spawned workers) and imported: it
    registers ``every_other``; unregistered afterwards."""
    name = f"every_other_{uuid.uuid4().hex[:8]}"
    d = tmp_path / "plugin"
    d.mkdir()
    (d / f"{name}.py").write_text(PLUGIN)
    monkeypatch.syspath_prepend(str(d))
    __import__(name)
    yield name
    methods.unregister("every_other")
    methods.unregister_map("frame_count")
    sys.modules.pop(name, None)


@pytest.fixture(scope="module")
def fast_tours(tmp_path_factory):
    """Two 150-frame geometry-only query tours (apt_0, apt_1) and a 30-frame mapping tour, 64x48."""
    from synth.jobs import load_spec, run_job

    root = tmp_path_factory.mktemp("methods_design")
    render = {"name": "fast", "out": str(root / "tours"), "renderer": "fast", "size": [64, 48], "chunk_size": 600,
              "designs": [{"layouts": ["apt_0", "apt_1"], "path": {"name": "query", "frames": 150}},
                          {"layouts": ["apt_0"], "path": {"name": "mapping", "frames": 30}}]}
    (root / "render.yaml").write_text(yaml.safe_dump(render))
    assert run_job(load_spec(root / "render.yaml"), progress=False)["failed"] == {}
    return root


def _spec(root, tmp_path, **changes):
    exp = {"name": "plugin", "render": str(root / "render.yaml"), "out": str(tmp_path / "exp"), "query": "query",
           "unchanged": "apt_0", "mapping": {"layout": "apt_0", "lighting": "geometry", "path": "mapping"},
           "map": "ground-truth", "methods": ["every_other"], "workers": 2, "detector": "oracle", **changes}
    p = tmp_path / "exp.yaml"
    p.write_text(yaml.safe_dump(exp))
    return p


def test_in_tree_methods_are_registered_in_run_order():
    assert methods.names()[:5] == IN_TREE
    assert [(m, r.mode) for m, r in methods.rows(IN_TREE)] == [
        ("appearance", "causal"), ("one_frame", "causal"), ("fpfh_icp", "closure"), ("appearance", "closure"),
        ("videoreloc", "causal"), ("videoreloc", "closure"), ("videoreloc_oracle", "causal"),
        ("videoreloc_oracle", "closure")]
    with pytest.raises(KeyError, match="unknown method 'nosuch'; registered: videoreloc, videoreloc_oracle"):
        methods.get("nosuch")


def test_a_method_from_one_module_runs_in_an_experiment(plugin, fast_tours, tmp_path, capsys):
    assert "every_other" in methods.names()
    assert reloc_main(["experiment", str(_spec(fast_tours, tmp_path)), "--quiet", "--no-plots"]) == 0
    out = capsys.readouterr().out
    assert "| Every other frame, ground truth |" in out
    exp = tmp_path / "exp"
    res = json.loads((exp / "results.json").read_text())
    m = res["methods"]["every_other"]
    assert m["label"] == "Every other frame (test)" and m["primary"] == "causal"
    assert m["map_bytes"] == (exp / "maps" / "frame_count.json").stat().st_size
    assert [r["key"] for r in res["rows"]] == ["every_other.causal"]
    a = m["modes"]["causal"]["all"]
    assert a["recall_1m_10deg"] == pytest.approx(0.5, abs=0.01) and a["median_pos_m"] == pytest.approx(0.0, abs=1e-6)
    assert json.loads((exp / "runs" / "every_other" / "apt_1__geometry__query" / "done.json").read_text())[
        "map_frames"] == 30  # ran (in a spawned worker) with the map its map kind built
    assert (exp / "tables" / "main.md").read_text() == tables.make_tables(res)["main"][0] + "\n"
    # rerun: nothing is recomputed, the results stand
    assert reloc_main(["experiment", str(_spec(fast_tours, tmp_path)), "--no-plots"]) == 0
    assert "0 runs and 0 maps computed now" in capsys.readouterr().out


@pytest.mark.parametrize("registered", [False, True])
def test_an_unknown_method_is_one_line_listing_the_registered_ones(request, tmp_path, capsys, registered):
    if registered:
        request.getfixturevalue("plugin")
    from jobspecs import write_experiment_spec

    spec = write_experiment_spec(tmp_path, methods=["videoreloc", "hloc"])
    assert reloc_main(["experiment", str(spec), "--quiet"]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1, err
    known = ", ".join(methods.names())
    assert err.endswith(f"methods[1]: unknown method 'hloc'; known: {known}, or a mapping with name and command "
                        "(or trajectories)"), err
    assert ("every_other" in err) == registered
    assert not (tmp_path / "exp").exists()
