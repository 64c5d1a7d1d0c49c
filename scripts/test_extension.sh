#!/usr/bin/env bash
# Extension test (Blender 4.2+): builds the extension zip, installs it with Blender's own
# `extension install-file` into a throw-away user configuration, and bakes an example scene
# through the installed package (bl_ext.user_default.canopy_ao) from --factory-startup.
# Skipped, saying so, where Blender has no extensions (before 4.2).
set -euo pipefail
cd "$(dirname "$0")/.."
repo=$PWD

version=$(scripts/blender_version.sh)
if [[ $(printf '%s\n' "$version" 4.2 | sort -V | head -n1) != 4.2 ]]; then
  echo "== Extension test skipped: Blender $version has no extensions (4.2+)"
  exit 0
fi

echo "== Extension test (Blender $version): build, install-file, bake through bl_ext"
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT
zip=$(scripts/build_extension.sh --out "$tmp/dist" | tail -n1)
echo "built $(basename "$zip")"
# Everything Blender writes (preferences, extensions) goes to the throw-away folder.
export BLENDER_USER_RESOURCES="$tmp/user"
unset BLENDER_USER_SCRIPTS BLENDER_USER_CONFIG BLENDER_USER_EXTENSIONS
blender --factory-startup --command extension install-file -r user_default -e "$zip" \
  >"$tmp/install.log" 2>&1 || { cat "$tmp/install.log" >&2; echo "install-file failed" >&2; exit 1; }
installed=$(find "$tmp/user" -path '*/extensions/user_default/canopy_ao/blender_manifest.toml' | head -n1)
[[ -n $installed ]] || { cat "$tmp/install.log" >&2; echo "the extension is not where Blender installs it" >&2; exit 1; }
ls "$(dirname "$installed")"/_core*.so >/dev/null

# The example scene, then a bake with the installed extension's CLI (not the repository's).
blender -b --factory-startup --python examples/make_scene.py -- \
  --scene round_tree --quick --out "$tmp/scene.blend" >"$tmp/scene.log" 2>&1 ||
  { cat "$tmp/scene.log" >&2; exit 1; }
cd "$tmp"  # nothing of the repository on sys.path
blender -b --factory-startup "$tmp/scene.blend" --python-exit-code 1 --python-expr \
  "import bl_ext.user_default.canopy_ao.cli as cli; cli.main()" -- \
  --all --method sphere --report "$tmp/report.json" >"$tmp/bake.log" 2>&1 ||
  { cat "$tmp/bake.log" >&2; echo "bake through the extension failed" >&2; exit 1; }
"$(cat "$repo/${CANOPY_AO_BUILD_DIR:-build}/python_executable")" - "$tmp/report.json" "$installed" <<'PY'
import json, os, sys
report = json.load(open(sys.argv[1]))
objects = report["objects"]
assert objects, "the report lists no baked object"
for name, e in objects.items():
    assert e["vertices"] > 0, (name, e)
    assert 0.0 < e["ao_mean"] < 1.0, (name, e["ao_mean"])  # baked: some shade, never black
assert min(e["ao_mean"] for e in objects.values()) < 0.9, "nothing was shaded"
print(f"extension bake OK: {len(objects)} object(s) baked by {os.path.dirname(sys.argv[2])}")
PY
