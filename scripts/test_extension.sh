#!/usr/bin/env bash
# Extension test (Blender 4.2+): builds the extension zip and a repository of it
# (build_extension.sh --repo), installs the zip with Blender's own `extension install-file` into
# a throw-away user configuration, then, in another, adds the repository by its file:// URL,
# syncs, checks that `extension list` lists the add-on and installs it from there, and bakes an
# example scene through the package installed from the repository (bl_ext.canopy_ao_repo.canopy_ao)
# with the throw-away preferences that hold the repository.
# Skipped, saying so, where Blender has no extensions (before 4.2).
set -euo pipefail
cd "$(dirname "$0")/.."
repo=$PWD

version=$(scripts/blender_version.sh)
if [[ $(printf '%s\n' "$version" 4.2 | sort -V | head -n1) != 4.2 ]]; then
  echo "== Extension test skipped: Blender $version has no extensions (4.2+)"
  exit 0
fi

echo "== Extension test (Blender $version): build, install-file, repository, bake through bl_ext"
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT
zip=$(scripts/build_extension.sh --out "$tmp/dist" --repo "$tmp/repo" | tail -n1)
echo "built $(basename "$zip") and the repository $tmp/repo"
# Everything Blender writes (preferences, extensions) goes to the throw-away folder: the
# preferences the repository commands save go under HOME's .config, whatever
# BLENDER_USER_RESOURCES says, so HOME is throw-away too.
export BLENDER_USER_RESOURCES="$tmp/user" HOME="$tmp/home"
unset BLENDER_USER_SCRIPTS BLENDER_USER_CONFIG BLENDER_USER_EXTENSIONS XDG_CONFIG_HOME
blender --factory-startup --command extension install-file -r user_default -e "$zip" \
  >"$tmp/install.log" 2>&1 || { cat "$tmp/install.log" >&2; echo "install-file failed" >&2; exit 1; }
installed=$(find "$tmp/user" -path '*/extensions/user_default/canopy_ao/blender_manifest.toml' | head -n1)
[[ -n $installed ]] || { cat "$tmp/install.log" >&2; echo "the extension is not where Blender installs it" >&2; exit 1; }
ls "$(dirname "$installed")"/_core*.so >/dev/null

# The repository, as a studio would point Blender at it: its only repository (--clear-all: no
# blender.org, nothing fetched from the network), added by URL, synced, listed, installed from.
export BLENDER_USER_RESOURCES="$tmp/user-repo" HOME="$tmp/home-repo"
ext() {  # $1: a name for the log; then the sub-command and its arguments
  local name=$1
  shift
  blender --online-mode --command extension "$@" >"$tmp/$name.log" 2>&1 ||
    { cat "$tmp/$name.log" >&2; echo "'extension $1' with the repository failed" >&2; exit 1; }
}
ext repo-add repo-add --clear-all --name "Canopy AO" --url "file://$tmp/repo/index.json" canopy_ao_repo
ext sync sync
ext list list
grep -qE '^ +canopy_ao: "Canopy AO"' "$tmp/list.log" ||
  { cat "$tmp/list.log" >&2; echo "Blender does not list canopy_ao from the repository" >&2; exit 1; }
ext install install canopy_ao
installed=$tmp/user-repo/extensions/canopy_ao_repo/canopy_ao/blender_manifest.toml
[[ -f $installed ]] ||
  { cat "$tmp/install.log" >&2; echo "canopy_ao was not installed from the repository" >&2; exit 1; }
python=$(cat "$repo/${CANOPY_AO_BUILD_DIR:-build}/python_executable")
"$python" - "$zip" "$(dirname "$installed")" <<'PY'
import os, sys, zipfile
with zipfile.ZipFile(sys.argv[1]) as z:
    (name,) = [n for n in z.namelist() if n.startswith("_core")]
    packed = z.read(name)
with open(os.path.join(sys.argv[2], name), "rb") as f:
    assert f.read() == packed, "the module installed from the repository is not the zip's"
PY
echo "repository OK: listed and installed from file://$tmp/repo/index.json"

# The example scene, then a bake with the CLI of the package installed from the repository (not
# the source tree's), with the throw-away preferences, which hold that repository (the factory
# settings know only user_default).
blender -b --factory-startup --python examples/make_scene.py -- \
  --scene round_tree --quick --out "$tmp/scene.blend" >"$tmp/scene.log" 2>&1 ||
  { cat "$tmp/scene.log" >&2; exit 1; }
cd "$tmp"  # nothing of the repository on sys.path
blender -b "$tmp/scene.blend" --python-exit-code 1 --python-expr \
  "import bl_ext.canopy_ao_repo.canopy_ao.cli as cli; cli.main()" -- \
  --all --method sphere --report "$tmp/report.json" >"$tmp/bake.log" 2>&1 ||
  { cat "$tmp/bake.log" >&2; echo "bake through the extension failed" >&2; exit 1; }
"$python" - "$tmp/report.json" "$installed" <<'PY'
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
