#!/usr/bin/env bash
# One leg of the test matrix: installs what is missing, builds, then C++ (CTest), Python (pytest
# on the native module and the bpy-free add-on modules, under the Python Blender runs), Blender
# (pytest inside blender -b) and, where Blender has extensions (4.2+), the extension zip built,
# installed and baked through. Run directly for this machine only; scripts/test.sh runs it on
# this machine and inside the Debian chroots.
#   CANOPY_AO_BUILD_DIR   build folder (default build; the chroot legs use build-<suite>)
set -euo pipefail
cd "$(dirname "$0")/.."
repo=$PWD
build=${CANOPY_AO_BUILD_DIR:-build}

scripts/install_deps.sh
scripts/build.sh

# Every stage runs even when an earlier one failed (one leg reports all its failures); the
# leg fails if any did.
failed=()
stage() {
  local name=$1
  shift
  "$@" || failed+=("$name")
}

echo "== C++ tests (CTest)"
stage ctest bash -c "cd '$build' && ctest --output-on-failure -j$(nproc)"

python=$(cat "$build/python_executable")
echo "== Python tests (pytest, $python = Blender's Python)"
stage pytest "$python" -m pytest tests/python -q -p no:cacheprovider

echo "== Blender tests (pytest inside blender -b --factory-startup)"
# A throw-away user-scripts folder: the add-on is found there, the user's own Blender
# configuration is never touched.
scripts_dir=$(mktemp -d)
trap 'rm -rf "$scripts_dir"' EXIT
mkdir -p "$scripts_dir/addons"
ln -s "$repo/addon/canopy_ao" "$scripts_dir/addons/canopy_ao"
stage blender env BLENDER_USER_SCRIPTS="$scripts_dir" blender -b --factory-startup \
  --python tests/blender/run_pytest.py -- tests/blender -q -p no:cacheprovider

stage extension scripts/test_extension.sh

if ((${#failed[@]})); then
  echo "test_suite.sh: failed: ${failed[*]}" >&2
  exit 1
fi
