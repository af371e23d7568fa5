"""Blender (bpy) side of the toolkit: the only package allowed to import bpy.

Importing this package itself does not import bpy; its modules (e.g. ``synth.blender.materials``) do,
after :func:`require_python`: the bpy wheel exists for one Python version only, and on another one
``import bpy`` fails with a ModuleNotFoundError that does not say why.
"""

from __future__ import annotations

import sys

PYTHON = (3, 11)  # the bpy 4.5 wheel (Blender 4.5 LTS) is built for this Python only


def python_problem(version=None) -> str | None:
    """Why Blender cannot render under this interpreter (``version``: default the running one), or None."""
    v = tuple((version or sys.version_info)[:2])
    if v == PYTHON:
        return None
    return (f"Blender rendering needs Python {PYTHON[0]}.{PYTHON[1]} (the bpy 4.5 wheel is built for it only); "
            f"this is Python {v[0]}.{v[1]}: set up with make PY=/path/to/python{PYTHON[0]}.{PYTHON[1]} "
            "(docs/troubleshooting.md)")


def require_python() -> None:
    """Raise a one-line UserError when Blender cannot run under this Python (before any work)."""
    problem = python_problem()
    if problem:
        from vrformats.errors import UserError

        raise UserError(problem)
