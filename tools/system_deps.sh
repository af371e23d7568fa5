#!/usr/bin/env bash
# Install the Debian shared libraries that the bpy and open3d wheels link against, when missing.
#
# Usage: tools/system_deps.sh VENV
# open3d's wheel needs libusb-1.0-0, libegl1 and libgl1 (Debian names); bpy needs a few X11
# client libraries even headless. We ask ldd which libraries the installed wheels cannot find and
# install exactly the packages that provide them. Nothing happens when everything is there.
set -euo pipefail
venv=${1:-.venv}
site=$("$venv/bin/python" -c 'import sysconfig; print(sysconfig.get_paths()["purelib"])')

declare -A pkg_of=(
  [libusb-1.0.so.0]=libusb-1.0-0 [libEGL.so.1]=libegl1 [libGL.so.1]=libgl1 [libOpenGL.so.0]=libopengl0
  [libGLX.so.0]=libglx0 [libGLdispatch.so.0]=libglvnd0 [libgomp.so.1]=libgomp1
  [libX11.so.6]=libx11-6 [libXrender.so.1]=libxrender1 [libXfixes.so.3]=libxfixes3 [libXi.so.6]=libxi6
  [libxkbcommon.so.0]=libxkbcommon0 [libSM.so.6]=libsm6 [libICE.so.6]=libice6 [libXext.so.6]=libxext6
  [libXxf86vm.so.1]=libxxf86vm1 [libxcb.so.1]=libxcb1 [libXau.so.6]=libxau6 [libXdmcp.so.6]=libxdmcp6
  [libwayland-client.so.0]=libwayland-client0 [libtinfo.so.6]=libtinfo6
)

missing_libs() {
  local f
  for f in "$site"/open3d/pybind*.so "$site"/open3d/libOpen3D.so* "$site"/bpy/__init__*.so "$site"/cv2/cv2*.so; do
    [ -e "$f" ] || continue
    ldd "$f" 2>/dev/null | awk '/not found/ {print $1}'
  done | sort -u
}

# the three the open3d wheel is known to need are checked by name as well
wanted=()
for lib in libusb-1.0.so.0 libEGL.so.1 libGL.so.1; do
  ldconfig -p | grep -q "$lib" || wanted+=("${pkg_of[$lib]}")
done
unknown=()
for lib in $(missing_libs); do
  case "$lib" in
    # bpy ships MaterialX Python modules that only resolve inside its own package: not system libraries
    *MaterialX*) continue ;;
  esac
  if [ -n "${pkg_of[$lib]:-}" ]; then wanted+=("${pkg_of[$lib]}"); else unknown+=("$lib"); fi
done
if [ ${#unknown[@]} -gt 0 ]; then
  echo "system_deps: no Debian package known for: ${unknown[*]} (the import may still work)" >&2
fi
if [ ${#wanted[@]} -eq 0 ]; then
  echo "system libraries: all present"
  exit 0
fi
pkgs=$(printf '%s\n' "${wanted[@]}" | sort -u | tr '\n' ' ')
echo "system libraries: installing $pkgs"
sudo=""
if [ "$(id -u)" -ne 0 ]; then
  command -v sudo >/dev/null || { echo "system_deps: need root (or sudo) to apt-get install $pkgs" >&2; exit 1; }
  sudo="sudo"
fi
export DEBIAN_FRONTEND=noninteractive
$sudo apt-get install -y -qq --no-install-recommends $pkgs >/dev/null 2>&1 || {
  $sudo apt-get update -qq >/dev/null
  $sudo apt-get install -y -qq --no-install-recommends $pkgs >/dev/null
}
echo "system libraries: installed $pkgs"
