"""reloc bench stability with render perturbations: the design's RGB re-rendered with another Cycles seed
(synth render in a child process, geometry linked from the unperturbed job), the experiment rerun on it,
the checks evaluated under every perturbation with their margins, and a rerun that renders nothing."""

from __future__ import annotations

import json
import os

import pytest
import yaml

from reloc.cli import main as reloc_main


@pytest.fixture(scope="module")
def one_tour_design(tmp_path_factory):
    """The smallest design VideoReloc with the learned detector runs on: apt_0 by night on 300 frames of
    the query path (RGB on 2), the mapping tour of apt_0 by day on 1,800 frames (RGB on 15); 160x120, the
    shipped detector's size."""
    from synth.jobs import load_spec, run_job

    root = tmp_path_factory.mktemp("stab")
    render = {"name": "one", "out": str(root / "tours"), "renderer": "blender", "geometry": "fast",
              "quality": "preview", "size": [160, 120], "chunk_size": 2000, "designs": [
                  {"layouts": ["apt_0"], "lightings": ["night"], "path": {"name": "query", "frames": 300},
                   "rgb_every": 150},
                  {"layouts": ["apt_0"], "lightings": ["day"], "path": {"name": "mapping", "frames": 1800},
                   "rgb_every": 120}]}
    (root / "render.yaml").write_text(yaml.safe_dump(render))
    assert run_job(load_spec(root / "render.yaml"), progress=False)["failed"] == {}
    exp = {"name": "one", "render": "render.yaml", "out": str(root / "exp"), "query": "query", "unchanged": "apt_0",
           "mapping": {"layout": "apt_0", "lighting": "day", "path": "mapping"}, "map": "build",
           "detector": "learned", "methods": ["videoreloc", "videoreloc_oracle"], "workers": 2,
           "config": {"observation": {"stride": 150}}}
    (root / "exp.yaml").write_text(yaml.safe_dump(exp))
    (root / "checks.yaml").write_text(yaml.safe_dump({"checks": [
        "videoreloc_oracle.closure.recall_1m_10deg.lo >= 0.0",
        "map.matched >= 1",
        {"check": "videoreloc_oracle.closure.recall_1m_10deg >= videoreloc.closure.recall_1m_10deg", "name": "upper"}]}))
    return root


@pytest.mark.slow
@pytest.mark.blender
def test_render_perturbation_rerenders_rgb_reruns_and_reports_check_margins(one_tour_design, capsys):
    root = one_tour_design
    st = root / "st"
    argv = ["bench", "stability", str(root / "exp.yaml"), "--perturbation", "render-seed:3", "--checks",
            str(root / "checks.yaml"), "--out", str(st), "--quiet", "--json"]
    assert reloc_main(argv) == 0
    rep = json.loads(capsys.readouterr().out)
    assert rep["perturbations"] == {"none": {}, "render-seed-3": {"render": {"seed": 3}}}
    # the checks name videoreloc_oracle: it is rerun beside --methods' videoreloc
    assert rep["methods"] == ["videoreloc", "videoreloc_oracle"]
    job = st / "renders" / "render-seed-3"
    r = rep["renders"]["render-seed-3"]
    assert r["job"] == str(job) and r["frames"] == 2 + 15
    assert 0 < r["frames_changed"] <= r["frames"] and 0 < r["pixels_changed"] <= 1  # another seed, another noise
    assert r["psnr_db_median"] > 10  # the same view: a little noise, not another picture
    base_geo = sorted((root / "tours" / "_geometry").rglob("*.exr"))
    geo = sorted((job / "_geometry").rglob("*.exr"))
    assert len(geo) == len(base_geo) == 300 + 1800
    assert all(os.stat(a).st_ino == os.stat(b).st_ino for a, b in zip(base_geo, geo))  # linked, not rendered again
    meta = json.loads((job / "apt_0__night__query" / "meta.json").read_text())
    assert meta["seed"] == 3
    res = json.loads((st / "render-seed-3" / "results.json").read_text())
    assert res["tours"]["apt_0__night__query"]["dir"] == str((job / "apt_0__night__query").resolve())
    fig = next(f for f in rep["figures"] if f["method"] == "videoreloc" and f["figure"] == "closure 1 m/10°")
    assert set(fig["values"]) == {"none", "render-seed-3"} and len(fig["interval"]) == 2
    assert fig["inside"] == all(fig["interval"][0] - 1e-12 <= v <= fig["interval"][1] + 1e-12 for v in fig["values"].values())
    # every check under every run, with its margin; the map's is the matched count minus the bound
    assert [c["check"] for c in rep["checks"]][-1] == "upper" and rep["checks_failed"] == []
    matched = {n: json.loads((st / n / "results.json").read_text())["maps"]["boxes"]["matched"] for n in ("none", "render-seed-3")}
    mc = next(c for c in rep["checks"] if c["expression"] == "map.matched >= 1")
    assert mc["margins"] == {n: matched[n] - 1 for n in matched}
    assert mc["largest_move"] == abs(matched["render-seed-3"] - matched["none"])
    assert mc["toward_bound"] == max(0, matched["none"] - matched["render-seed-3"])
    md = (st / "stability.md").read_text()
    assert "Render perturbations" in md and "| render-seed-3 | 17 |" in md and "margin >= largest move" in md

    # a rerun renders nothing and computes nothing: the render job and the experiments resume
    assert reloc_main(argv) == 0
    assert json.loads(capsys.readouterr().out)["figures"] == rep["figures"]
    assert json.loads((job / "job_summary.json").read_text())["frames_rendered_now"] == 0

    # a check that fails under a perturbation fails the benchmark, naming the runs
    (root / "strict.yaml").write_text(yaml.safe_dump({"checks": ["map.matched >= 100000"]}))
    argv_strict = ["bench", "stability", str(root / "exp.yaml"), "--perturbation", "render-seed:3", "--checks",
                   str(root / "strict.yaml"), "--out", str(st), "--quiet"]
    assert reloc_main(argv_strict) == 1
    io = capsys.readouterr()
    assert "unstable: checks fail under none, render-seed-3" in io.err and "**FAIL**" in io.out


@pytest.mark.slow
@pytest.mark.blender
def test_render_perturbations_need_the_job_folder(one_tour_design, tmp_path, capsys):
    """--tours pointing at a folder of tours that is no render job: render perturbations are refused in
    one line before anything renders (the detector's still run there)."""
    root = one_tour_design
    links = tmp_path / "links"
    links.mkdir()
    for name in ("apt_0__night__query", "apt_0__day__mapping"):
        (links / name).symlink_to(root / "tours" / name, target_is_directory=True)
    code = reloc_main(["bench", "stability", str(root / "exp.yaml"), "--tours", str(links), "--perturbation",
                       "render-seed:1", "--out", str(tmp_path / "st"), "--quiet"])
    assert code == 2
    err = capsys.readouterr().err.strip()
    assert "holds no render job (no job_state.json)" in err and len(err.splitlines()) == 1, err
    assert not (tmp_path / "st" / "renders").exists()
