"""Render job specs for the job tests: the shipped smoke spec with some keys changed."""

from __future__ import annotations

from pathlib import Path

import yaml

SMOKE = Path(__file__).resolve().parents[1] / "synth" / "specs" / "smoke.yaml"


def write_spec(tmp_path, name="spec.yaml", **changes) -> Path:
    """synth/specs/smoke.yaml with ``changes`` applied, written to ``tmp_path / name``."""
    doc = yaml.safe_load(SMOKE.read_text())
    doc.update(changes)
    p = Path(tmp_path) / name
    p.write_text(yaml.safe_dump(doc))
    return p
