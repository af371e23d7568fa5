"""Complete a ReplicaCAD folder that lacks its stage GLBs (and a few object GLBs) with stand-ins.

    python tools/replicacad_standin.py SRC OUT [--stage NAME_OR_YAML] [--seed N] [--no-windows]
        [--ceiling 2.8] [--no-hold-objects] [--no-structure-report] [--force] [--report FILE]

Copies SRC to OUT (files are copied, not linked: OUT may be edited without touching SRC) and builds a
stand-in stage from the navmeshes for every stage config whose GLB is missing, under the rules of a
stage variant (``--stage``: a shipped name from ``scenes/stages/`` or a YAML file; default
``standin``, the stand-in as this tool always built it), a box for every missing object GLB, a stage
card beside each stage GLB (``stages/<stem>.stage_card.json``: the variant, rules, seed, toolkit
version, what was built and what the importer's structure detection finds in it) and
``OUT/STANDIN.md``. The library, and what the rules mean: ``synth.sources.replicacad.stages``.

``--ceiling``, ``--no-windows`` and ``--no-hold-objects`` (``footprint: navmesh``) override the
variant's rules (the card records them as overrides); ``--seed`` its seed. Prints one table row per
file built. Bad input (an unknown variant, a bad rule in a variant file) is one line, exit status 2,
nothing written.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
from dataclasses import replace
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from vrformats.atomic import write_text_atomic  # noqa: E402
from vrformats.errors import UserError  # noqa: E402
from synth.sources.replicacad.stages import (  # noqa: E402
    CEILING_RANGE, DEFAULT_VARIANT, MAX_SEED, build, load_stage_variant, print_table,
)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("src", type=Path, help="ReplicaCAD folder (replica_cad/ of the SAPIEN copy)")
    ap.add_argument("out", type=Path, help="output folder (a complete dataset root)")
    ap.add_argument("--stage", default=DEFAULT_VARIANT, metavar="NAME_OR_YAML",
                    help=f"stage variant: a shipped name (scenes/stages/) or a YAML file (default {DEFAULT_VARIANT})")
    ap.add_argument("--seed", type=int, help="seed of the variant's random choices (default: the variant's)")
    ap.add_argument("--ceiling", type=float, help="ceiling height above the floor, m (default: the variant's, 2.8 for standin)")
    ap.add_argument("--no-windows", action="store_true", help="no window openings")
    ap.add_argument("--no-hold-objects", action="store_true",
                    help="walls from the navmesh alone (not moved out around the scenes' objects): footprint navmesh")
    ap.add_argument("--no-structure-report", action="store_true",
                    help="leave out what the importer's structure detection finds in each stage (about a second a stage)")
    ap.add_argument("--force", action="store_true", help="replace OUT if it exists")
    ap.add_argument("--report", type=Path, help="write the rows as JSON here")
    a = ap.parse_args(argv)
    try:
        variant = load_stage_variant(a.stage)
        over: dict = {}
        if a.ceiling is not None:
            lo, hi = CEILING_RANGE
            if not (math.isfinite(a.ceiling) and lo <= a.ceiling <= hi):
                raise UserError(f"--ceiling: expected a height from {lo:g} to {hi:g} m, got {a.ceiling:g}")
            over["ceiling"] = a.ceiling
        if a.no_windows:
            over["windows"] = False
        if a.no_hold_objects:
            over["footprint"] = "navmesh"
        if a.seed is not None:
            if not 0 <= a.seed <= MAX_SEED:
                raise UserError(f"--seed: expected an integer from 0 to {MAX_SEED}, got {a.seed}")
            over["seed"] = a.seed
        if over:
            variant = replace(variant, rules=replace(variant.rules, **over))
        rows = build(a.src, a.out, variant, a.force, structure_report=not a.no_structure_report,
                     overrides={k: v for k, v in over.items() if k != "seed"})
    except UserError as e:
        print(f"error: {e}", file=sys.stderr)
        return 2
    print_table(rows)
    if a.report:
        write_text_atomic(a.report, json.dumps(rows, indent=1) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
