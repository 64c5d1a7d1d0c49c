#!/usr/bin/env bash
# Builds the Blender 4.2+ extension zip of Canopy AO, carrying the native module built for the
# Python and platform of the Blender installed here, and validates its manifest.
#   scripts/build_extension.sh [--out DIR]      (default DIR: out/)
#   scripts/build_extension.sh --portable [--python 3.N|INTERPRETER] [--out DIR]
#     the portable zip (docs/PORTABILITY.md, scripts/build_portable.sh) for Python 3.N or that
#     interpreter (default: this system's python3): out/canopy_ao-<version>-linux_x64-cp3N.zip,
#     needing no Embree, TBB or OpenImageIO on the system
# Prints the zip's path on its last line. Install it with
#   blender --command extension install-file -r user_default -e ZIP
# or in Blender: Edit > Preferences > Get Extensions > Install from Disk.
set -euo pipefail
cd "$(dirname "$0")/.."
out=out portable=0 pyver=
while (($#)); do
  case "$1" in
    --out) out=$2; shift 2 ;;
    --portable) portable=1; shift ;;
    --python) pyver=$2; shift 2 ;;
    *) echo "build_extension.sh: unknown argument '$1' (use --out DIR, --portable, --python 3.N|INTERPRETER)" >&2
       exit 2 ;;
  esac
done
[[ -z $pyver || $portable == 1 ]] || { echo "build_extension.sh: --python needs --portable" >&2; exit 2; }
mkdir -p "$out"
out=$(cd "$out" && pwd)

scripts/install_deps.sh
if ((portable)); then
  exec scripts/build_portable.sh "$out" $pyver
fi
version=$(scripts/blender_version.sh)
if [[ $(printf '%s\n' "$version" 4.2 | sort -V | head -n1) != 4.2 ]]; then
  echo "build_extension.sh: extensions need Blender 4.2 or later (this Blender: $version);" \
    "on older Blenders use scripts/install_addon.sh" >&2
  exit 1
fi
scripts/build.sh >/dev/null
build=${CANOPY_AO_BUILD_DIR:-build}
python=$(cat "$build/python_executable")
suffix=$("$python" -c 'import sysconfig; print(sysconfig.get_config_var("EXT_SUFFIX"))')
tag=$("$python" -c 'import sys; print("cp%d%d" % sys.version_info[:2])')
module=addon/canopy_ao/_core$suffix
[[ -f $module ]] || { echo "build_extension.sh: $module was not built" >&2; exit 1; }

# Stage the package with exactly one native module: the one for this Blender's Python.
stage=$(mktemp -d)
trap 'rm -rf "$stage"' EXIT
mkdir "$stage/canopy_ao"
tar -C addon/canopy_ao --exclude=__pycache__ --exclude='_core*.so' --exclude='*.pyc' -cf - . |
  tar -C "$stage/canopy_ao" -xf -
cp "$module" "$stage/canopy_ao/"

blender_cmd() {  # Blender's command-line tools, with the factory settings
  local log
  log=$(mktemp)
  if ! blender --factory-startup --command extension "$@" >"$log" 2>&1; then
    cat "$log" >&2
    rm -f "$log"
    echo "build_extension.sh: 'blender --command extension $1' failed" >&2
    exit 1
  fi
  grep -vE '^(Blender [0-9]|Read prefs|$)' "$log" >&2 || true
  rm -f "$log"
}
blender_cmd validate "$stage/canopy_ao"
rm -f "$stage"/*.zip
blender_cmd build --source-dir "$stage/canopy_ao" --output-dir "$stage"
zips=("$stage"/*.zip)
[[ -f ${zips[0]} ]] || { echo "build_extension.sh: Blender made no zip" >&2; exit 1; }
blender_cmd validate "${zips[0]}"
name=$(basename "${zips[0]}" .zip)
dest="$out/$name-$tag.zip"
mv "${zips[0]}" "$dest"
echo "$dest"
