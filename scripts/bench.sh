#!/usr/bin/env bash
# Regenerates the speed-against-accuracy study (bench/README.md): builds the core, runs every
# method on every scene against the Embree reference (and Cycles' bake, when cached or with
# --cycles), draws the chart, tabulates the stability study and the scaling, and copies the
# figures and tables the README shows into bench/results/.
#
# Usage: scripts/bench.sh [--full] [--cycles] [--scaling] [--real] [--no-build]
#   --full      realistic scene sizes (20k-60k leaves per tree) instead of the quick ones
#   --cycles    bake the missing Cycles references in Blender (slow: minutes per scene)
#   --scaling   also time every method from 1e4 to 1e7 vertices (1e6 without --full)
#   --real      also the real-tree study: every rung on the Sapling exports (bench/out/real,
#               examples/sapling_scenes.py; Cycles where cached), its chart and the hybrid study
#   --no-build  use the module already in addon/canopy_ao/
set -euo pipefail
cd "$(dirname "$0")/.."

full=0 cycles=0 scaling=0 real=0 build=1
for a in "$@"; do
  case "$a" in
    --full) full=1 ;;
    --cycles) cycles=1 ;;
    --scaling) scaling=1 ;;
    --real) real=1 ;;
    --no-build) build=0 ;;
    -h|--help) sed -n '2,13p' "$0"; exit 0 ;;
    *) echo "bench.sh: unknown option $a" >&2; exit 2 ;;
  esac
done
quick=(--quick); ((full)) && quick=()
py=/usr/bin/python3
start=$SECONDS

if ((build)); then
  scripts/install_deps.sh --with-bench
  scripts/build.sh
fi

if ((cycles)); then
  echo "== Cycles references (Blender)"
  for s in ideal_sphere ideal_ellipsoid round_tree columnar_tree weeping_tree conifer grass_field grove; do
    samples=(1 4 16 64 256)
    [[ $s == ideal_* ]] && samples+=(1024)   # convergence check where it is cheap
    blender -b --factory-startup --python-exit-code 1 --python bench/cycles_reference.py -- \
      --scene "$s" "${quick[@]}" --samples "${samples[@]}" 2>&1 | grep "cycles_reference" || {
        echo "bench.sh: Cycles bake of $s failed" >&2; exit 1; }
  done
fi

echo "== accuracy (every method, every scene)"
$py bench/accuracy.py "${quick[@]}"
echo "== chart"
$py bench/chart.py "${quick[@]}"
if grep -q ",cycles," bench/out/results.csv; then
  $py bench/chart.py "${quick[@]}" --reference cycles
fi
echo "== stability"
$py bench/stability.py
echo "== bent normals (rays at 16/64, the grid, the normal against 256 rays)"
$py bench/bent_normals.py "${quick[@]}" | tee bench/out/bent_normals.md
if ((scaling)); then
  echo "== scaling"
  if ((full)); then $py bench/scaling.py --max 1e7; else $py bench/scaling.py --quick; fi
fi
if ((real)); then
  echo "== real trees (Sapling exports)"
  size=(); ((full)) && size=(--full)
  $py bench/real_assets.py "${size[@]}" --csv bench/out/real/real_assets.csv \
    | tee bench/out/real/real_assets.txt
  $py bench/real_assets.py --csv bench/out/real/real_assets.csv \
    --markdown bench/out/real/real_assets.md >/dev/null
  $py bench/chart_real.py --csv bench/out/real/real_assets.csv --png bench/out/chart_real.png \
    --md bench/out/real/equal_error.md
  $py bench/hybrid_study.py "${size[@]}" | tee bench/out/real/hybrid_study.txt
fi

mkdir -p bench/results
cp bench/out/chart.png bench/out/summary.md bench/out/stability.md bench/out/bent_normals.md \
   bench/results/
for f in bench/out/chart_cycles.png bench/out/summary_cycles.md bench/out/scaling.png \
         bench/out/scaling.csv bench/out/results.csv bench/out/strip_*.png \
         bench/out/chart_real.png bench/out/real/real_assets.txt bench/out/real/real_assets.md \
         bench/out/real/equal_error.md bench/out/real/hybrid_study.txt; do
  [[ -e $f ]] && cp "$f" bench/results/
done
echo "bench.sh: done in $((SECONDS - start)) s; figures and tables in bench/results/"
