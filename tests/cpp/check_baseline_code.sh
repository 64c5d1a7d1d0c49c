#!/usr/bin/env bash
# The core is built for the x86-64-v2 baseline; only the AVX2 canopy kernels (namespace avx2 in
# canopy_model.cpp, and fast_math.h's load8_aos), which run only where the CPU has AVX2 and FMA,
# may use 256- or 512-bit registers. Fails naming any other function that does, and fails if
# no AVX2 kernel is found at all (the dispatch would be gone).
#   check_baseline_code.sh LIBRARY_OR_OBJECT
set -euo pipefail
lib=$1
objdump -d -C --no-show-raw-insn "$lib" | awk '
  /^[0-9a-f]+ <.*>:$/ { fn = $0; next }
  /%[yz]mm/ {
    if (fn ~ /::avx2::/ || fn ~ /load8_aos/) kernels[fn] = 1; else bad[fn] = 1
  }
  END {
    nk = 0; for (f in kernels) nk++
    nb = 0; for (f in bad) { nb++; print "AVX code outside the AVX2 kernels: " f }
    printf "%d AVX2 kernel functions, %d others using AVX\n", nk, nb
    if (nk == 0) { print "no AVX2 kernel found"; exit 1 }
    exit nb > 0
  }'
