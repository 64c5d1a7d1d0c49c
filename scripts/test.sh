#!/usr/bin/env bash
# Runs every test: installs what is missing, builds, then C++ (CTest), Python (pytest on the
# native module and the bpy-free add-on modules) and Blender (pytest inside blender -b).
set -euo pipefail
cd "$(dirname "$0")/.."
repo=$PWD

scripts/install_deps.sh
scripts/build.sh

echo "== C++ tests (CTest)"
(cd build && ctest --output-on-failure -j"$(nproc)")

echo "== Python tests (pytest, /usr/bin/python3 = Blender's Python)"
/usr/bin/python3 -m pytest tests/python -q -p no:cacheprovider

echo "== Blender tests (pytest inside blender -b --factory-startup)"
# A throw-away user-scripts folder: the add-on is found there, the user's own Blender
# configuration is never touched.
scripts_dir=$(mktemp -d)
trap 'rm -rf "$scripts_dir"' EXIT
mkdir -p "$scripts_dir/addons"
ln -s "$repo/addon/canopy_ao" "$scripts_dir/addons/canopy_ao"
BLENDER_USER_SCRIPTS="$scripts_dir" blender -b --factory-startup \
  --python tests/blender/run_pytest.py -- tests/blender -q -p no:cacheprovider
