"""Errors a user can act on. The CLIs print them as one line and exit with status 2."""

from __future__ import annotations


class UserError(Exception):
    """Bad input from the user: a file, a field, a name. Printed as one line, exit status 2."""


class SceneFormatError(UserError):
    """A layout, class table or dataset file that does not parse or validate.

    The message always starts with the file and the field, e.g.
    ``scenes/layouts/apt_0.yaml: objects[3].position: expected 3 numbers, got 'abc'``.
    """

    def __init__(self, file, field: str | None, message: str):
        self.file = str(file) if file is not None else "<memory>"
        self.field = field
        self.message = message
        where = f"{self.file}: {field}: " if field else f"{self.file}: "
        super().__init__(where + message)


class UnknownNameError(UserError):
    """A layout, class, asset or preset name that does not exist."""


def run_command(prog: str, fn, args) -> int:
    """Run a CLI command function: a UserError prints one line and exits 2, Ctrl-C exits 130."""
    import sys

    try:
        return int(fn(args) or 0)
    except UserError as e:
        print(f"{prog}: error: {e}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print(f"{prog}: interrupted", file=sys.stderr)
        return 130
