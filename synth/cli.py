"""``synth``: build, inspect and check scene layouts, render, check and export tours, run render jobs.

Command groups register themselves (``register_cli``) from the module of their stage, as in
``reloc.cli``. Every user error (bad file, unknown name) is one line on stderr and exit status 2.
"""

from __future__ import annotations

import argparse
import sys

from vrformats.cli import ArgumentParser, run_command

from .version import __version__


def build_parser() -> argparse.ArgumentParser:
    # one module per command group, imported when the parser is built
    from .trainset import trainset
    from .jobs import cli as jobs
    from .jobs import quality_bench
    from .paths import cli as paths_cli
    from .render import bench
    from .layout import cli as scene_cli
    from .sources import SOURCES
    from .tour import cli as tour_cli

    p = ArgumentParser(prog="synth", description="Build, check and render controlled-change indoor scenes.")
    p.add_argument("--version", action="version", version=f"synth {__version__}")
    sub = p.add_subparsers(dest="group", required=True)
    scene_cmds = scene_cli.register_cli(sub)  # synth scene list|show|check|stats|preview|export-boxes|generate|build|rearrange|...
    for source in SOURCES.values():
        source.register_scene_cli(scene_cmds)  # synth scene import-replicacad
    tour_cli.register_cli(sub)  # synth tour render|check|show|export
    paths_cli.register_cli(sub)  # synth path plan|show|check|preview|generate
    jobs.register_cli(sub)  # synth render SPEC.yaml
    trainset.register_cli(sub)  # synth trainset render SPEC.yaml (detector training data)
    bench_cmds = bench.register_cli(sub)  # synth bench render
    quality_bench.register_cli(bench_cmds)  # synth bench quality
    tour_cli.register_old_names(sub)  # synth dataset check|show|export: old names of synth tour ..., warn
    return p


def main(argv=None) -> int:
    args = build_parser().parse_args(argv)
    return run_command("synth", args.fn, args)


if __name__ == "__main__":
    sys.exit(main())
