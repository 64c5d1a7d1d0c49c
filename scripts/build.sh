#!/usr/bin/env bash
# Configures and builds the native core, its Python module (copied into addon/canopy_ao/),
# the C++ tests and the benchmarks, in build/.
set -euo pipefail
cd "$(dirname "$0")/.."
cmake -S . -B build -DCMAKE_BUILD_TYPE=Release >/dev/null
cmake --build build -j"$(nproc)"
