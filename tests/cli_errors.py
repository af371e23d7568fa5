"""How the tests read a user error: one line on stderr, ``synth: error: ...`` or ``reloc: error: ...``,
no traceback, naming what it is about."""

from __future__ import annotations


def one_line_error(err, *names, prog: tuple[str, ...] = ("synth", "reloc")) -> str:
    """The one stderr line of a user error (``err`` is the captured stderr, or pytest's ``capsys``,
    whose stderr is read); it names every one of ``names``."""
    if hasattr(err, "readouterr"):
        err = err.readouterr().err
    lines = err.strip().splitlines()
    assert len(lines) == 1, err
    assert "Traceback" not in err and lines[0].startswith(tuple(f"{p}: error: " for p in prog)), err
    for n in names:
        assert str(n) in lines[0], (n, err)
    return lines[0]


def nothing_left(folder, keep=()) -> None:
    """No output and no temporary file appeared in ``folder`` (besides ``keep``)."""
    left = sorted(p.name for p in folder.iterdir() if p.name not in keep)
    assert left == [], left


def exit_code(main, argv) -> int:
    """The exit status of ``main(argv)``, argparse's own refusals (its SystemExit) included."""
    try:
        return main(argv)
    except SystemExit as e:
        return e.code
