"""Camera paths on imported ReplicaCAD apartments: planned, saved, checked with ``synth path check``.

CI runs this on the real-format fixture (``tests/replicacad_fixture.py``). With
``SYNTH_REPLICACAD_ROOT`` set to a full ReplicaCAD folder (``.../replica_cad``) the last test plans
the query path over apt_0..apt_5 and a mapping path on apt_0 from the real files.

The wall geometry the assertions use (wall rectangles from ``Stage.walls`` minus door openings) is
computed here, not with ``synth.paths.clearance``.
"""

from __future__ import annotations

import json
import math
import os
from pathlib import Path

import numpy as np
import pytest

from replicacad_fixture import make_fixture
from synth.cli import main as synth_main
from synth.paths.clearance import clearance_report
from synth.paths.files import load_path
from synth.paths.mapping import plan_mapping_path
from synth.paths.query import plan_query_path
from synth.sources.replicacad.importer import load_replicacad
from synth.scene.model import save_layout

CLEARANCE = 0.3


@pytest.fixture(scope="module")
def fixture_root(tmp_path_factory):
    return make_fixture(tmp_path_factory.mktemp("rcad") / "replica_cad")


@pytest.fixture(scope="module")
def apartments(fixture_root):
    return [load_replicacad(fixture_root, f"apt_{i}", allow_unknown=True) for i in (0, 1)]


def wall_pieces(stage):
    """(centre xy, half size along / across, direction) of every wall piece between door openings."""
    out = []
    for w in stage.walls:
        d = np.asarray(w.direction)
        cuts = sorted((op.offset - op.width / 2, op.offset + op.width / 2) for op in stage.openings
                      if op.kind == "door" and op.wall == w.id and len(op.rooms) >= 2)
        s, pieces = 0.0, []
        for a, b in cuts:
            pieces.append((s, a))
            s = b
        pieces.append((s, w.length))
        for a, b in pieces:
            if b - a > 1e-6:
                c = np.asarray(w.start) + d * (a + b) / 2
                out.append((c, (b - a) / 2, w.thickness / 2, d))
    return out


def wall_dist(xy: np.ndarray, stage) -> np.ndarray:
    best = np.full(len(xy), np.inf)
    for c, hl, ht, d in wall_pieces(stage):
        rel = xy - c
        u = np.abs(rel @ d) - hl
        v = np.abs(rel @ np.array([-d[1], d[0]])) - ht
        best = np.minimum(best, np.hypot(np.maximum(u, 0), np.maximum(v, 0)))
    return best


def crossings(xy: np.ndarray, stage) -> int:
    """Steps between consecutive frames that pass through a wall piece."""
    n = 0
    for c, hl, ht, d in wall_pieces(stage):
        nrm = np.array([-d[1], d[0]])
        side = (xy - c) @ nrm
        along = np.abs((xy - c) @ d)
        flip = np.nonzero(np.sign(side[:-1]) != np.sign(side[1:]))[0]
        n += int((np.minimum(along[flip], along[flip + 1]) < hl).sum())
    return n


def test_query_path_on_imported_apartments_keeps_off_the_stage_walls(apartments):
    p = plan_query_path(apartments, frames=300, seed=0)
    xy = p.positions[:, :2]
    st = apartments[0].stage
    assert st.asset is not None and st.walls
    assert wall_dist(xy, st).min() >= CLEARANCE - 1e-3
    assert crossings(xy, st) == 0
    for lay in apartments:
        rep = clearance_report(p, lay)
        assert rep["ok"] and rep["frames_outside"] == 0, rep
    assert min(clearance_report(p, lay)["min_clearance_m"] for lay in apartments) == pytest.approx(
        p.meta["stats"]["min_clearance_m"], abs=1e-4)


def test_mapping_path_on_an_imported_apartment(apartments):
    lay = apartments[0]
    p = plan_mapping_path(lay, frames=1200, seed=0)
    xy = p.positions[:, :2]
    assert wall_dist(xy, lay.stage).min() >= CLEARANCE - 1e-3
    assert crossings(xy, lay.stage) == 0
    rep = clearance_report(p, lay)
    assert rep["ok"] and rep["min_clearance_m"] == pytest.approx(p.meta["stats"]["min_clearance_m"], abs=1e-4)
    assert set(p.meta["stats"]["rooms"]) == {r.name for r in lay.stage.rooms} - set(p.meta["stats"].get("rooms_skipped", []))


def test_cli_plan_then_check_an_imported_apt_0(tmp_path, apartments, capsys):
    # the imported layout is named apt_0, like the built-in one: check must read the file planned on
    f = save_layout(apartments[0], tmp_path / "apt_0.yaml")
    out = tmp_path / "q.txt"
    assert synth_main(["path", "plan", "query", "--layouts", str(f), "--frames", "300", "--out", str(out)]) == 0
    reported = load_path(out).meta["stats"]["min_clearance_m"]
    capsys.readouterr()
    rc = synth_main(["path", "check", str(out), "--json"])
    rep = json.loads(capsys.readouterr().out)
    assert rc == 0 and rep["ok"], rep
    assert rep["layouts"][0]["min_clearance_m"] == pytest.approx(reported, abs=0.01)


REAL = os.environ.get("SYNTH_REPLICACAD_ROOT")


@pytest.mark.skipif(not REAL or not Path(REAL).is_dir(), reason="SYNTH_REPLICACAD_ROOT (a full ReplicaCAD folder) not set")
def test_real_apartments_query_and_mapping():
    # as render_jobs/replicacad_apt_6x3.yaml plans them (replicacad.obstacles: band): keeping 0.3 m from
    # every object of all six authored flats leaves too little shared floor for a walk
    lays = [load_replicacad(REAL, f"apt_{i}") for i in range(6)]
    q = plan_query_path(lays, frames=400, seed=0, obstacles="band")
    m = plan_mapping_path(lays[0], frames=2000, seed=0, obstacles="band")
    for p, on in ((q, lays), (m, lays[:1])):
        for lay in on:
            rep = clearance_report(p, lay)
            assert rep["ok"] and rep["frames_outside"] == 0, (p.name, lay.name, rep["min_clearance_m"], rep["frames_below"])
            assert crossings(p.positions[:, :2], lay.stage) == 0
        assert p.meta["stats"]["min_clearance_m"] >= CLEARANCE - 1e-4
        assert not math.isnan(p.meta["stats"]["min_clearance_m"])
