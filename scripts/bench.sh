#!/usr/bin/env bash
# Runs the benchmark studies the READMEs quote (bench/README.md says what each shows) and prints,
# in one run, the headline tables: equal error against Cycles on the Sapling trees (bake only and
# whole process), live AO per frame, and the forest. Figures and tables go to bench/results/.
#
# Usage: scripts/bench.sh [--quick] [--full] [--cycles] [--scaling] [--real] [--foliage]
#                        [--no-build]
#   --quick     the three headline tables alone, small: equal error on two Sapling trees (aspen,
#               callistemon), live AO at 100k vertices, the forest to 1000 trees on a 1e5-vertex
#               ground (4.5 CPU-minutes once the Sapling exports and their Cycles bakes exist;
#               making them adds ~4 CPU-minutes)
#   (default)   also the synthetic study (accuracy, chart, stability, bent normals), the whole
#               bake against Blender's floor, the scene plan, texel anti-aliasing; equal error
#               on every Sapling scene (the first run bakes each scene's Cycles ladder up to
#               1024 samples twice: hours); live AO at 100k and 1M; the forest to 10,000 trees;
#               the foliage scenes (leaf cards, a joined tree, ivy, scattered cards: every rung,
#               all/unburied, and our rays on the card tree against Cycles' samples)
#   --foliage   the foliage scenes also with --quick (~3 CPU-minutes, the first Cycles
#               reference ~1 more)
#   --full      realistic synthetic scene sizes (20k-60k leaves per tree) instead of quick ones
#   --cycles    bake the missing Cycles references of the synthetic scenes (minutes per scene)
#   --scaling   also time every method from 1e4 to 1e7 vertices (1e6 without --full)
#   --real      also the real-tree study: every rung on the Sapling exports, its chart and
#               rays against Cycles' samples
#   --no-build  use the module already in addon/canopy_ao/
set -euo pipefail
cd "$(dirname "$0")/.."

headline=0 full=0 cycles=0 scaling=0 real=0 foliage=0 build=1
for a in "$@"; do
  case "$a" in
    --quick) headline=1 ;;
    --full) full=1 ;;
    --cycles) cycles=1 ;;
    --scaling) scaling=1 ;;
    --real) real=1 ;;
    --foliage) foliage=1 ;;
    --no-build) build=0 ;;
    -h|--help) sed -n '2,25p' "$0" | sed 's/^# \{0,1\}//'; exit 0 ;;
    *) echo "bench.sh: unknown option $a" >&2; exit 2 ;;
  esac
done
quick=(--quick); ((full)) && quick=()
py=/usr/bin/python3
start=$SECONDS
mkdir -p bench/out/real bench/results

if ((build)); then
  scripts/install_deps.sh --with-bench
  scripts/build.sh
fi

# The add-on as Blender finds it, for the studies that run inside Blender.
us=$(mktemp -d)
trap 'rm -rf "$us"' EXIT
mkdir -p "$us/addons"
ln -s "$PWD/addon/canopy_ao" "$us/addons/canopy_ao"
in_blender() {  # in_blender SCRIPT ARGS...: a bench script inside Blender with the add-on
  local script=$1; shift
  BLENDER_USER_SCRIPTS=$us blender -b --factory-startup --python-exit-code 1 --python "$script" \
    -- "$@"
}

# === Equal error against Cycles (Sapling exports, their .blend, Cycles' ladder) ===============
if ((headline)); then
  equal_scenes=(sap_quaking_aspen sap_callistemon)
else
  mapfile -t equal_scenes < <(blender -b --factory-startup --python-exit-code 1 \
    --python examples/sapling_scenes.py -- --list 2>/dev/null | grep -E '^(sap_|grass_)')
fi
sapling() {  # sapling ARGS...: examples/sapling_scenes.py for the equal-error scenes, quick sizes
  blender -b --factory-startup --python-exit-code 1 --python examples/sapling_scenes.py -- \
    --scenes "${equal_scenes[@]}" --quick "$@" 2>&1 | grep "^sapling_scenes" || {
      echo "bench.sh: examples/sapling_scenes.py $* failed" >&2; exit 1; }
}
echo "== Sapling exports, .blend files and Cycles bakes for the equal-error table"
missing_blend=0
for s in "${equal_scenes[@]}"; do
  [[ -e bench/out/real/blend/${s}_quick.blend ]] || missing_blend=1
done
((missing_blend)) && sapling --blend bench/out/real/blend
sapling --bake-cycles 1024 --cycles-seed 1         # the reference (noise independent of seed 0's)
sapling --bake-cycles 4 8 16 32 64 128 256 512 1024  # seed 0's ladder

echo "== equal error against Cycles (bake only and whole process, one run)"
eq=(); ((headline)) && eq=(--quick)
$py bench/equal_error.py "${eq[@]}" --scenes "${equal_scenes[@]}" --md bench/out/equal_error_cycles.md

echo "== live AO per frame (bench/live_speed.py)"
if ((headline)); then
  in_blender bench/live_speed.py --vertices 100000 --frames 4 | tee bench/out/live_speed.txt
else
  in_blender bench/live_speed.py | tee bench/out/live_speed.txt
fi

echo "== forest (bench/forest.py)"
if ((headline)); then
  $py bench/forest.py --vertices 1e5 --counts 10,100,1000 | tee bench/out/forest.txt
else
  $py bench/forest.py --check | tee bench/out/forest.txt
fi
cp bench/out/equal_error_cycles.md bench/out/live_speed.txt bench/out/forest.txt bench/results/

if ((foliage || !headline)); then
  echo "== foliage (bench/foliage.py, bench/foliage_cycles.py)"
  in_blender bench/foliage.py --out bench/out/foliage.md --csv bench/out/foliage.csv \
    --png bench/out/chart_foliage.png
  in_blender bench/foliage_cycles.py --samples 16 64 256 --out bench/out/foliage_cycles.md
  cp bench/out/foliage.md bench/out/chart_foliage.png bench/out/foliage_cycles.md bench/results/
fi

if ((headline)); then
  echo "bench.sh: done in $((SECONDS - start)) s; tables in bench/results/"
  exit 0
fi

# === The synthetic scenes' study =============================================================
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
echo "== whole bake against Blender's floor (bench/blender_bake_speed.py)"
in_blender bench/blender_bake_speed.py | tee bench/out/blender_bake_speed.txt
echo "== the scene plan (bench/scene_plan_speed.py)"
$py bench/scene_plan_speed.py | tee bench/out/scene_plan_speed.txt
echo "== texel anti-aliasing (bench/texel_aa.py)"
in_blender bench/texel_aa.py | tee bench/out/texel_aa.txt
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
  $py bench/real_rays.py | tee bench/out/real/real_rays.txt
fi

cp bench/out/chart.png bench/out/summary.md bench/out/stability.md bench/out/bent_normals.md \
   bench/out/blender_bake_speed.txt bench/out/scene_plan_speed.txt bench/out/texel_aa.txt \
   bench/results/
for f in bench/out/chart_cycles.png bench/out/summary_cycles.md bench/out/scaling.png \
         bench/out/scaling.csv bench/out/results.csv bench/out/strip_*.png \
         bench/out/chart_real.png bench/out/real/real_assets.txt bench/out/real/real_assets.md \
         bench/out/real/equal_error.md \
         bench/out/real/real_rays.txt; do
  [[ -e $f ]] && cp "$f" bench/results/
done
echo "bench.sh: done in $((SECONDS - start)) s; figures and tables in bench/results/"
