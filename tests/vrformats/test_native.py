"""A missing system library under open3d is one line naming the package to install
(vrformats.native), checked on the loader's real messages: once by hiding libGL.so.1 from a real
process (a private mount namespace binds /dev/null over it), once on the message text."""

from __future__ import annotations

import re
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from vrformats.native import DEBIAN_PACKAGES, missing_library_error

REPO = Path(__file__).resolve().parents[2]


def test_the_table_is_the_one_make_setup_installs_from():
    text = (REPO / "tools" / "system_deps.sh").read_text()
    table = dict(re.findall(r"\[([\w.+-]+\.so[.\d]*)\]=([\w.+-]+)", text))
    assert table == DEBIAN_PACKAGES


@pytest.mark.parametrize("message, lib, pkg", [
    ("libGL.so.1: cannot open shared object file: No such file or directory", "libGL.so.1", "libgl1"),
    ("/lib/x86_64-linux-gnu/libEGL.so.1: file too short", "libEGL.so.1", "libegl1"),
    ("libusb-1.0.so.0: cannot open shared object file: No such file or directory", "libusb-1.0.so.0", "libusb-1.0-0"),
])
def test_the_loader_messages_name_the_package(message, lib, pkg):
    err = missing_library_error("open3d", ImportError(message))
    assert f"system library {lib}" in str(err) and f"apt-get install {pkg}" in str(err) and "\n" not in str(err)


def test_other_import_errors_are_not_disguised():
    assert missing_library_error("open3d", ImportError("No module named 'open3d'")) is None
    assert missing_library_error("open3d", ImportError("numpy.core.multiarray failed to import")) is None


def test_a_real_process_without_libgl_says_which_package_in_one_line(tmp_path):
    lib = next((Path(p) for p in ("/lib/x86_64-linux-gnu/libGL.so.1", "/usr/lib/x86_64-linux-gnu/libGL.so.1")
                if Path(p).exists()), None)
    if lib is None or shutil.which("unshare") is None:
        pytest.skip("needs libGL.so.1 and unshare")
    if subprocess.run(["unshare", "-m", "true"], capture_output=True).returncode != 0:
        pytest.skip("no private mount namespace here (needs root)")
    cmd = (f"mount --bind /dev/null {lib} && exec {sys.executable} -m synth.cli tour render apt_0 query "
           f"--renderer fast --frames 2 --size 32x24 --out {tmp_path / 't'}")
    r = subprocess.run(["unshare", "-m", "sh", "-c", cmd], capture_output=True, text=True, cwd=REPO, timeout=120)
    assert r.returncode == 2, r.stderr
    lines = r.stderr.strip().splitlines()
    assert len(lines) == 1 and "libGL.so.1" in lines[0] and "apt-get install libgl1" in lines[0], r.stderr
    assert not (tmp_path / "t").exists()  # refused before any file
