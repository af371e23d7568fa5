"""``reloc``: the VideoReloc relocalizer's command line.

Command groups register themselves (``register_cli``) from the module of their pipeline stage.
User errors (missing files, malformed maps or configs) print one line and exit with status 2.
"""

from __future__ import annotations

import argparse
import sys

from vrformats.cli import ArgumentParser, run_command

from .version import __version__


def build_parser() -> argparse.ArgumentParser:
    # one module per command group, imported when the parser is built (``reloc --version`` stays fast)
    from .backend import run
    from .detector import cli as detector_cli
    from .experiments import bench, checks, localization_units, runner
    from .experiments import cli as eval_cli
    from .map import cli as map_cli

    p = ArgumentParser(prog="reloc", description="VideoReloc: relocalization against a map of class-labelled boxes.")
    p.add_argument("--version", action="version", version=f"reloc {__version__}")
    sub = p.add_subparsers(dest="group")
    map_cli.register_cli(sub)
    localization_units.register_cli(sub)
    run.register_cli(sub)
    eval_cli.register_cli(sub)
    eval_cli.register_stages_cli(sub)
    bench.register_cli(sub)
    runner.register_cli(sub)
    checks.register_cli(sub)
    detector_cli.register_cli(sub)
    return p


def main(argv=None) -> int:
    p = build_parser()
    args = p.parse_args(argv)
    if not getattr(args, "fn", None):
        p.print_help()
        return 0
    return run_command("reloc", args.fn, args)


if __name__ == "__main__":
    sys.exit(main())
