"""Where the toolkit's data lives. ``SYNTH_SCENES_DIR`` overrides the shipped ``scenes/`` folder."""

from __future__ import annotations

import os
from pathlib import Path

REPO_ROOT = Path(__file__).resolve().parent.parent


def scenes_dir() -> Path:
    return Path(os.environ.get("SYNTH_SCENES_DIR", REPO_ROOT / "scenes"))


def layouts_dir() -> Path:
    return scenes_dir() / "layouts"


def classes_file() -> Path:
    return scenes_dir() / "classes.yaml"


def replicacad_lexicon_file() -> Path:
    return scenes_dir() / "replicacad_lexicon.yaml"
