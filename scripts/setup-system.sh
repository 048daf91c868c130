#!/usr/bin/env bash
# Debian packages the tests need, installed only when missing:
#   libclang-dev  bindgen (the `fmi` crate for tests/second_importer.rs, and thermovia-mujoco) dlopens libclang.so or
#                 libclang-<ver>.so. The image ships libclang-cpp.so.14, a different library that
#                 bindgen cannot use, so the check looks for the very file bindgen loads.
#   libtbb12      ecospy's native library links it (tests/python/test_importers.py).
#   valgrind      memcheck over 1,000 FMU life cycles and a cross-process state round trip
#                 (crates/fuzz/tests/reliability.rs); the check looks for the valgrind command and
#                 its memcheck tool, which the tests run.
#   libosmesa6    MuJoCo's off-screen software renderer (MUJOCO_GL=osmesa) for the robot example's
#                 frames (examples/mujoco); without it the example skips its frames and says so.
#
# Usage: scripts/setup-system.sh [--dry-run]
#   --dry-run  print what would be installed and why, install nothing; exit 0 either way.
set -euo pipefail

dry_run=0
case "${1:-}" in
  "") ;;
  --dry-run) dry_run=1 ;;
  -h|--help) sed -n '2,12p' "$0" | sed 's/^# \{0,1\}//'; exit 0 ;;
  *) echo "setup-system.sh: unknown argument '$1' (expected --dry-run or nothing)" >&2; exit 2 ;;
esac

# bindgen (clang-sys) searches LIBCLANG_PATH, then llvm-config's libdir, then the usual library
# folders, for libclang.so or libclang-<version>.so (not libclang-cpp).
has_libclang() {
  local dirs=()
  [[ -n "${LIBCLANG_PATH:-}" ]] && dirs+=("$LIBCLANG_PATH")
  # SETUP_SYSTEM_LIBDIRS (space-separated) replaces the system folders: the tests use it.
  # shellcheck disable=SC2206
  dirs+=(${SETUP_SYSTEM_LIBDIRS:-/usr/lib/llvm-*/lib /usr/lib/x86_64-linux-gnu /usr/lib/aarch64-linux-gnu /usr/lib /usr/local/lib})
  local d f
  for d in "${dirs[@]}"; do
    for f in "$d"/libclang.so "$d"/libclang.so.* "$d"/libclang-[0-9]*.so "$d"/libclang-[0-9]*.so.*; do
      [[ -e "$f" ]] && return 0
    done
  done
  return 1
}

has_shared_lib() { ldconfig -p 2>/dev/null | grep -q "^[[:space:]]*$1[[:space:]]"; }

# The valgrind launcher alone is not enough: memcheck is a separate tool binary under its libexec
# folder (SETUP_SYSTEM_VALGRIND_DIRS, space-separated, replaces the system folders: the tests use it).
has_valgrind() {
  command -v valgrind >/dev/null 2>&1 || return 1
  local d
  # shellcheck disable=SC2206
  local dirs=(${SETUP_SYSTEM_VALGRIND_DIRS:-/usr/libexec/valgrind /usr/lib/x86_64-linux-gnu/valgrind /usr/lib/valgrind})
  for d in "${dirs[@]}"; do
    compgen -G "$d/memcheck-*-linux" >/dev/null && return 0
  done
  return 1
}

missing=()
reasons=()
if ! has_libclang; then
  missing+=(libclang-dev)
  reasons+=("libclang-dev: no libclang.so / libclang-<ver>.so for bindgen (the fmi crate, second importer)")
fi
if ! has_shared_lib libtbb.so.12; then
  missing+=(libtbb12)
  reasons+=("libtbb12: no libtbb.so.12 for ecospy (third-party importer test)")
fi
if ! has_valgrind; then
  missing+=(valgrind)
  reasons+=("valgrind: no valgrind with its memcheck tool (leak test over 1,000 life cycles)")
fi

if ! has_shared_lib libOSMesa.so.8; then
  missing+=(libosmesa6)
  reasons+=("libosmesa6: no libOSMesa.so.8 for MuJoCo's off-screen frames (examples/mujoco)")
fi

if ((${#missing[@]} == 0)); then
  echo "setup-system: nothing to install (libclang, libtbb12, valgrind and libOSMesa present)"
  exit 0
fi
for r in "${reasons[@]}"; do echo "setup-system: would install $r"; done
if ((dry_run)); then
  echo "setup-system: dry run, installed nothing: apt-get install -y ${missing[*]}"
  exit 0
fi

SUDO=""
[[ "$(id -u)" == 0 ]] || SUDO="sudo"
$SUDO apt-get update -qq
DEBIAN_FRONTEND=noninteractive $SUDO apt-get install -y -qq "${missing[@]}"
has_libclang || { echo "setup-system: libclang-dev installed but no libclang.so found" >&2; exit 1; }
has_valgrind || { echo "setup-system: valgrind installed but no memcheck tool found" >&2; exit 1; }
