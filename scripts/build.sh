#!/usr/bin/env bash
# Configures and builds the native core, its Python module (copied into addon/canopy_ao/),
# the C++ tests and the benchmarks, in build/ (or $CANOPY_AO_BUILD_DIR). The module is built for
# the Python the installed Blender runs (CMakeLists.txt asks Blender).
set -euo pipefail
cd "$(dirname "$0")/.."
build=${CANOPY_AO_BUILD_DIR:-build}
cmake -S . -B "$build" -DCMAKE_BUILD_TYPE=Release >/dev/null
cmake --build "$build" -j"$(nproc)"
