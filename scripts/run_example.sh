#!/usr/bin/env bash
# The main job: installs what is missing, builds, generates the example scene (a broadleaf tree
# over a ground plane), bakes Canopy AO headless with the add-on's CLI (auto mode, checked
# against Cycles), and renders the result to out/example_ao.png.
#   scripts/run_example.sh [--scene NAME] [--method METHOD] [--quick]
set -euo pipefail
cd "$(dirname "$0")/.."
repo=$PWD
scene=round_tree
method=auto
quick=()
while (($#)); do
  case "$1" in
    --scene) scene=$2; shift 2 ;;
    --method) method=$2; shift 2 ;;
    --quick) quick=(--quick); shift ;;
    *) echo "run_example.sh: unknown argument '$1' (use --scene NAME, --method M, --quick)" >&2; exit 2 ;;
  esac
done

scripts/install_deps.sh
scripts/build.sh

mkdir -p out
# Blender finds the add-on through a throw-away user-scripts folder: your own Blender
# configuration is left alone (scripts/install_addon.sh installs it for everyday use).
scripts_dir=$(mktemp -d)
trap 'rm -rf "$scripts_dir"' EXIT
mkdir -p "$scripts_dir/addons"
ln -s "$repo/addon/canopy_ao" "$scripts_dir/addons/canopy_ao"
export BLENDER_USER_SCRIPTS="$scripts_dir"

# Runs a Blender step; shows only our own lines, or everything (and stops) if it fails.
step() {
  local log
  log=$(mktemp)
  if ! "$@" >"$log" 2>&1; then
    cat "$log" >&2
    echo "run_example.sh: step failed: $*" >&2
    exit 1
  fi
  grep -vE '^(Blender [0-9]|Read blend|Info:|Warning: .*(addon|Unable)|Fra:|Saved:|Time:|Blender quit|OIIO DEBUG|$)' "$log" || true
  rm -f "$log"
}

echo "== Generating the example scene '$scene'"
step blender -b --factory-startup --python examples/make_scene.py -- \
  --scene "$scene" --out "out/$scene.blend" "${quick[@]}"

echo "== Baking Canopy AO headless (method: $method), checked against Cycles"
# --python-exit-code 1: a failing expression (say, the add-on not found) must fail the step;
# Blender alone would exit 0.
step blender -b "out/$scene.blend" --addons canopy_ao --python-exit-code 1 --python-expr \
  "import canopy_ao.cli; canopy_ao.cli.main()" -- \
  --all --method "$method" --wire-material --check-cycles --save \
  --report "out/$scene.report.json"

echo "== Rendering the baked AO"
step blender -b "out/$scene.blend" --python examples/render_preview.py -- \
  --out "out/${scene}_ao.png"
echo "Done: out/$scene.blend (baked), out/$scene.report.json, out/${scene}_ao.png"
