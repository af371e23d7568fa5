"""Errors a user can act on. The CLIs print them as one line and exit with status 2
(``vrformats.cli.run_command``)."""

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


def check_output_folder(path) -> None:
    """Fail now, before any work, if the output folder ``path`` could not be created or written later.

    Creates nothing: its nearest existing ancestor must be a folder in which a folder can be made
    (proved by making and removing one, which also catches read-only file systems and /proc, where
    permission bits say yes to root)."""
    _check_output(path, "folder")


def check_output_file(path) -> None:
    """Fail now, before any work, if the output file ``path`` could not be written (atomically) later."""
    _check_output(path, "file")


def _check_output(path, kind: str) -> None:
    import os
    import tempfile
    from pathlib import Path

    what = f"cannot write to output {kind} {path}"
    p = Path(path).absolute()
    if kind == "file":
        if p.is_symlink():  # the atomic rename would replace the link, not write where it points
            raise UserError(f"{what}: it is a symbolic link (to {os.readlink(p)}); give the path itself")
        if p.is_dir():
            raise UserError(f"{what}: it is a folder")
        if p.exists() and not p.is_file():  # a device, a pipe, a socket: the atomic rename would replace it
            raise UserError(f"{what}: it is not a regular file (a device or pipe); give a new path or a file")
        if p.exists() and not os.access(p, os.W_OK):
            raise UserError(f"{what}: it is not writable")
        p = p.parent  # written under a temporary name next to it, then renamed
    anc = p
    while not anc.exists() and not anc.is_symlink():
        anc = anc.parent
    if not anc.is_dir():
        raise UserError(f"{what}: {anc} is not a folder")
    try:
        os.rmdir(tempfile.mkdtemp(prefix=".write_test_", dir=anc))
    except OSError as e:
        raise UserError(f"{what}: cannot create anything in {anc} ({e.strerror or e})") from None


def one_line(e: BaseException, limit: int = 240, with_type: bool = False) -> str:
    """An exception as one line of at most ``limit`` characters (whitespace and newlines collapsed),
    optionally prefixed with its type (``OSError: ...``), for the one-line errors and failure logs."""
    s = " ".join(str(e).split())
    if with_type:
        s = f"{type(e).__name__}: {s}".rstrip(": ")
    return s if len(s) <= limit else s[: limit - 3] + "..."
