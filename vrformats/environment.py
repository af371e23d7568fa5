"""What produced a result: the toolkit's version and commit, the machine and the library versions.

``environment()`` is the one record both halves write beside what they measure (a render job's
calibration, an experiment's results and report), so that a figure names the machine and the code
that produced it. Reading the system is best-effort: what cannot be found is left out, never an
error.
"""

from __future__ import annotations

import os
import platform
import subprocess
from importlib import metadata
from pathlib import Path

DISTRIBUTION = "videoreloc-synth"
# the libraries whose versions change numbers or pictures
LIBRARIES = ("numpy", "scipy", "open3d", "opencv-python-headless", "OpenEXR", "onnxruntime", "matplotlib", "pillow",
             "bpy")
SOURCE_ROOT = Path(__file__).resolve().parents[1]  # the folder holding the project's packages


def toolkit_version() -> str:
    """The installed distribution's version, or "unknown"."""
    try:
        return metadata.version(DISTRIBUTION)
    except metadata.PackageNotFoundError:
        return "unknown"


def git_commit(root: Path | None = None) -> str | None:
    """The short commit of the checkout the code runs from, with ``-dirty`` when it has uncommitted
    changes; None for an installed wheel (no ``pyproject.toml`` beside the packages) or without git."""
    root = Path(root or SOURCE_ROOT)
    if not (root / "pyproject.toml").is_file() or not (root / "vrformats").is_dir():
        return None  # installed: site-packages may lie inside some other git tree
    try:
        r = subprocess.run(["git", "-C", str(root), "rev-parse", "--short", "HEAD"], capture_output=True, text=True,
                           timeout=5)
        if r.returncode != 0 or not r.stdout.strip():
            return None
        commit = r.stdout.strip()
        d = subprocess.run(["git", "-C", str(root), "status", "--porcelain", "--untracked-files=no"],
                           capture_output=True, text=True, timeout=10)
        return commit + ("-dirty" if d.returncode == 0 and d.stdout.strip() else "")
    except (OSError, subprocess.SubprocessError):
        return None


def cpu_model() -> str | None:
    """The CPU's model name (``/proc/cpuinfo``; ``platform.processor()`` elsewhere), or None."""
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or None


def library_versions(names=LIBRARIES) -> dict[str, str]:
    """Python's and each installed library's version (a missing one is left out)."""
    out = {"python": platform.python_version()}
    for dist in names:
        try:
            out[dist] = metadata.version(dist)
        except metadata.PackageNotFoundError:
            pass
    return out


def environment() -> dict:
    """{"toolkit", "commit" (None when installed), "cpu_model", "cpu_count", "platform", "libraries"}."""
    return {"toolkit": toolkit_version(), "commit": git_commit(), "cpu_model": cpu_model(),
            "cpu_count": os.cpu_count() or 1, "platform": platform.platform(), "libraries": library_versions()}


def describe(env: dict) -> list[tuple[str, str]]:
    """(what, value) lines of an ``environment()`` record for a report."""
    code = f"commit {env['commit']}" if env.get("commit") else f"version {env.get('toolkit', 'unknown')} (no git checkout)"
    cpu = env.get("cpu_model") or "unknown CPU"
    libs = ", ".join(f"{k} {v}" for k, v in (env.get("libraries") or {}).items())
    return [("code", f"videoreloc-synth {code}"), ("machine", f"{cpu}, {env.get('cpu_count', '?')} cores; "
                                                              f"{env.get('platform', '')}".rstrip("; ")),
            ("libraries", libs or "unknown")]
