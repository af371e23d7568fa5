"""``reloc``: the VideoReloc relocalizer's command line.

Its subcommands (map, run, eval, experiment, check) arrive with the reloc issues; for now it only
reports its version, so that the console script exists and installs.
"""

from __future__ import annotations

import argparse
import sys

from . import __version__


def main(argv=None) -> int:
    p = argparse.ArgumentParser(prog="reloc", description="VideoReloc: relocalization against a map of class-labelled boxes.")
    p.add_argument("--version", action="version", version=f"reloc {__version__}")
    p.parse_args(argv)
    p.print_help()
    return 0


if __name__ == "__main__":
    sys.exit(main())
