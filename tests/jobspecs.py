"""Spec writers for the tests: the shipped smoke render job and the shipped demo experiment, with
some keys changed."""

from __future__ import annotations

from pathlib import Path

import yaml

REPO = Path(__file__).resolve().parents[1]
SMOKE = REPO / "render_jobs" / "smoke.yaml"
DEMO_EXPERIMENT = REPO / "reloc" / "specs" / "demo_experiment.yaml"


def write_spec(tmp_path, name="spec.yaml", **changes) -> Path:
    """render_jobs/smoke.yaml with ``changes`` applied, written to ``tmp_path / name``."""
    doc = yaml.safe_load(SMOKE.read_text())
    doc.update(changes)
    p = Path(tmp_path) / name
    p.write_text(yaml.safe_dump(doc))
    return p


def write_experiment_spec(tmp_path, file="exp.yaml", **changes) -> Path:
    """reloc/specs/demo_experiment.yaml reading render_jobs/demo.yaml, its tours in ``tmp_path/tours``
    and its results in ``tmp_path/exp``, with ``changes`` applied (a value of None removes the key),
    written to ``tmp_path / file``."""
    doc = yaml.safe_load(DEMO_EXPERIMENT.read_text())
    doc.update(render=str(REPO / "render_jobs" / "demo.yaml"), out=str(Path(tmp_path) / "exp"),
               tours=str(Path(tmp_path) / "tours"))
    doc.update(changes)
    for k in [k for k, v in changes.items() if v is None]:
        del doc[k]
    p = Path(tmp_path) / file
    p.write_text(yaml.safe_dump(doc))
    return p
