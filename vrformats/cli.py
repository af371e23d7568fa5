"""Command-line options that both halves share, declared once so that they mean the same everywhere.

- ``--json``: print the command's result as JSON on stdout instead of its table (a flag, never a
  file name; a command that also writes a file takes ``--out FILE``);
- ``--quiet``: no progress bar or progress lines; the result line and errors still print;
- ``--workers N``: how many processes work at a time (a positive integer);
- ``--sensor NAME|FILE`` and ``--sensor-seed S``: read (or export) frames as an RGB-D camera
  measures them (``vrformats.sensors``);
- ``--out``: where the command writes, with the command's own description of what it writes.

Each ``add_*`` returns the argparse action, so a caller can still adjust it. ``ArgumentParser`` is
argparse's, with the toolkit's one-line errors: a bad option is one line on stderr and exit status 2,
like every other user error (``synth render: error: argument --workers: expected a positive integer,
got '0' (see synth render --help)``), not the usage block.
"""

from __future__ import annotations

import argparse
import errno


class ArgumentParser(argparse.ArgumentParser):
    """``argparse.ArgumentParser`` whose errors are one line (subcommand parsers inherit it)."""

    def error(self, message):
        self.exit(2, f"{self.prog}: error: {message} (see {self.prog} --help)\n")


def positive_int(text: str) -> int:
    """argparse ``type`` of a count: a positive integer, else an argparse error naming the option."""
    try:
        v = int(text)
    except ValueError:
        v = 0
    if v <= 0:
        raise argparse.ArgumentTypeError(f"expected a positive integer, got {text!r}")
    return v


MAX_WORKERS = 256  # processes or threads one option may ask for


def bounded_int(hi: int, lo: int = 1):
    """argparse ``type``: an integer from ``lo`` (1) to ``hi``, the bounds stated in the message."""

    def parse(text: str) -> int:
        try:
            v = int(text)
        except ValueError:
            v = lo - 1
        if not lo <= v <= hi:
            raise argparse.ArgumentTypeError(f"expected an integer from {lo} to {hi}, got {text[:40]!r}")
        return v

    return parse


def fraction(text: str) -> float:
    """argparse ``type`` of a share: a finite number from 0 to 1."""
    import math

    try:
        v = float(text)
    except ValueError:
        v = math.nan
    if not (math.isfinite(v) and 0.0 <= v <= 1.0):
        raise argparse.ArgumentTypeError(f"expected a fraction from 0 to 1, got {text[:40]!r}")
    return v


def add_json(p: argparse.ArgumentParser, what: str = "the result"):
    return p.add_argument("--json", action="store_true", help=f"print {what} as JSON on stdout instead of the table")


def add_quiet(p: argparse.ArgumentParser):
    return p.add_argument("--quiet", action="store_true",
                          help="no progress bar or progress lines (the result line and errors still print)")


def add_workers(p: argparse.ArgumentParser, what: str, default: int | None = 1):
    shown = f"default {default}" if default is not None else "default: the spec's workers"
    return p.add_argument("--workers", type=bounded_int(MAX_WORKERS), default=default, metavar="N",
                          help=f"{what} at a time ({shown})")


def add_out(p: argparse.ArgumentParser, what: str, required: bool = True, default: str | None = None):
    if default is not None:
        what = f"{what} (default {default})"
    return p.add_argument("--out", required=required, default=default, help=what)


def add_sensor(p: argparse.ArgumentParser, verb: str = "read the frames", default: str = "ideal: the render as it is"):
    """``--sensor`` and ``--sensor-seed``."""
    p.add_argument("--sensor", metavar="NAME|FILE",
                   help=f"{verb} as this RGB-D camera measures them: a vrformats/sensor_presets name (ideal, "
                        f"structured_light, tof) or a sensor YAML file (default: {default})")
    return p.add_argument("--sensor-seed", type=int, default=0, metavar="S",
                          help="seed of the sensor noise (per frame: vrformats.sensors.frame_seed; default 0)")


_WRITE_ERRNOS = {errno.ENOSPC, errno.EFBIG, errno.EDQUOT, errno.EROFS}


def run_command(prog: str, fn, args) -> int:
    """Run a CLI command function: a UserError prints one line and exits 2; Ctrl-C, SIGTERM and SIGHUP
    stop it in order (``vrformats.lifetime``: its workers are stopped, one line, exit 130 / 143 / 129);
    a reader that closed the pipe (``synth scene show apt_0 | head``) ends it quietly."""
    import os
    import sys

    from .errors import UserError
    from .lifetime import exit_status, signal_name, signals_interrupt

    try:
        with signals_interrupt():
            return int(fn(args) or 0)
    except UserError as e:
        _end_progress_line()
        from .fields import terminal_safe

        print(f"{prog}: error: {terminal_safe(e)}", file=sys.stderr)  # what a file says cannot drive the terminal
        return 2
    except KeyboardInterrupt as e:
        _end_progress_line()
        print(f"{prog}: interrupted ({signal_name(e)})", file=sys.stderr)
        return exit_status(e)
    except BrokenPipeError:
        if not _stdout_reader_gone():  # a broken pipe elsewhere is a real error
            raise
        # point stdout at /dev/null so that the interpreter's final flush is quiet too
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return 141
    except OSError as e:
        if e.errno not in _WRITE_ERRNOS:
            raise
        _end_progress_line()  # a full disk, a file size limit, a quota, a read-only file system: not a bug
        where = f" {e.filename}" if e.filename else ""
        print(f"{prog}: error: cannot write{where}: {e.strerror or e} ({errno.errorcode.get(e.errno, e.errno)}); "
              "rerun once it can be written (finished work is kept)", file=sys.stderr)
        return 2


def _end_progress_line() -> None:
    """Close any progress bar still drawn on stderr, so that a one-line message starts its own line."""
    import sys

    tqdm = sys.modules.get("tqdm")
    if tqdm is None:
        return
    for bar in list(getattr(tqdm.tqdm, "_instances", ())):
        try:
            bar.close()
        except Exception:  # noqa: BLE001 - a bar that cannot close must not hide the error
            pass


def _stdout_reader_gone() -> bool:
    """stdout is a pipe whose reading end is closed (``| head`` has exited): poll reports an error on it."""
    import select
    import sys

    try:
        poll = select.poll()
        poll.register(sys.stdout.fileno(), select.POLLOUT)
        return any(ev & select.POLLERR for _, ev in poll.poll(0))
    except (AttributeError, OSError, ValueError):  # no poll here, or stdout is not a file
        return False
