"""Imports of the wheels that link system libraries: a missing one is one line naming the package.

open3d's wheel links ``libGL``, ``libEGL`` and ``libusb`` from the system; without them ``import
open3d`` fails deep inside its loader with a long traceback that names a ``.so`` file and no
package. :func:`import_open3d` turns that into a UserError naming the Debian package to install
(``DEBIAN_PACKAGES``: the same table as ``tools/system_deps.sh``, which ``make setup`` runs; a test
keeps the two equal).
"""

from __future__ import annotations

import re

from .errors import UserError

# shared library -> the Debian/Ubuntu package that provides it
DEBIAN_PACKAGES = {
    "libusb-1.0.so.0": "libusb-1.0-0", "libEGL.so.1": "libegl1", "libGL.so.1": "libgl1", "libOpenGL.so.0": "libopengl0",
    "libGLX.so.0": "libglx0", "libGLdispatch.so.0": "libglvnd0", "libgomp.so.1": "libgomp1",
    "libX11.so.6": "libx11-6", "libXrender.so.1": "libxrender1", "libXfixes.so.3": "libxfixes3", "libXi.so.6": "libxi6",
    "libxkbcommon.so.0": "libxkbcommon0", "libSM.so.6": "libsm6", "libICE.so.6": "libice6", "libXext.so.6": "libxext6",
    "libXxf86vm.so.1": "libxxf86vm1", "libxcb.so.1": "libxcb1", "libXau.so.6": "libxau6", "libXdmcp.so.6": "libxdmcp6",
    "libwayland-client.so.0": "libwayland-client0", "libtinfo.so.6": "libtinfo6",
}
_SO = re.compile(r"(lib[\w.+-]*?\.so(?:\.\d+)*)")
# what the dynamic loader says of a library it cannot use: missing, or not a library (a broken install)
_LOADER_ERRORS = ("cannot open shared object file", "file too short", "invalid ELF header", "wrong ELF class")


def missing_library_error(module: str, err: BaseException) -> UserError | None:
    """The one-line error for ``module`` failing to import because a system library is missing
    (``err``'s message names a ``.so``), or None when that is not why it failed."""
    text = str(err)
    m = _SO.search(text)
    if not m or not any(why in text for why in _LOADER_ERRORS):
        return None
    lib = m.group(1)
    pkg = DEBIAN_PACKAGES.get(lib)
    fix = (f"install it: sudo apt-get install {pkg} (or make setup, which runs tools/system_deps.sh)" if pkg
           else "install the package that provides it (tools/system_deps.sh lists the known ones)")
    why = next(w for w in _LOADER_ERRORS if w in text)
    return UserError(f"{module} cannot load the system library {lib} ({why}): {fix}")


def import_open3d():
    """``import open3d``, or a one-line UserError naming the missing system library and its package."""
    try:
        import open3d
    except (ImportError, OSError) as e:
        err = missing_library_error("open3d", e)
        if err is None:
            raise
        raise err from None
    return open3d
