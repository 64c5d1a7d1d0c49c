#!/usr/bin/env bash
# The README's leaf-card picture: builds examples/foliage_scenes.py's card_birch (a Sapling
# white birch whose leaves are alpha-textured cards, over a ground), bakes it per vertex by rays
# with the add-on's command line, and renders the AO itself (examples/render_preview.py: the
# cards' alpha cuts the leaves out as in any Cycles render).
#   examples/card_picture.sh [OUT_DIR]    # → OUT_DIR/card_birch_ao.png (default out/)
# Needs the native module built (scripts/build.sh or scripts/run_example.sh) and Blender ≤ 4.1
# (Sapling is bundled up to 4.1).
set -euo pipefail
out=$(realpath -m "${1:-out}")
cd "$(dirname "$0")/.."
repo=$PWD
if ! ls addon/canopy_ao/_core*.so >/dev/null 2>&1; then
  echo "card_picture.sh: no native module in addon/canopy_ao: run scripts/build.sh first" >&2
  exit 1
fi
mkdir -p "$out"
# The add-on through a throw-away user-scripts folder: your Blender configuration is untouched.
scripts_dir=$(mktemp -d)
trap 'rm -rf "$scripts_dir"' EXIT
mkdir -p "$scripts_dir/addons"
ln -s "$repo/addon/canopy_ao" "$scripts_dir/addons/canopy_ao"
export BLENDER_USER_SCRIPTS="$scripts_dir"

blend="$out/card_birch.blend"
blender -b --factory-startup --python-exit-code 1 --python examples/foliage_scenes.py -- \
  --scene card_birch --blend "$blend" | grep '^foliage_scenes'
blender -b "$blend" --addons canopy_ao --python-exit-code 1 --python-expr \
  "import canopy_ao.cli; canopy_ao.cli.main()" -- --all --method raytrace --samples 128 \
  --save | grep -E '^[A-Za-z_]+: role|^canopy_ao: raytrace'
blender -b "$blend" --python-exit-code 1 --python examples/render_preview.py -- \
  --out "$out/card_birch_ao.png" --size 900 600 --samples 16 --frame Tree_branches \
  --view 1 -1.4 0.7 --margin 0.85 --background 0.2 0.2 0.2 --raw --grey | grep '^render_preview'
