#!/usr/bin/env bash
# Builds the Blender 4.2+ extension zip of Canopy AO, carrying the native module built for the
# Python and platform of the Blender installed here, and validates its manifest.
#   scripts/build_extension.sh [--out DIR]      (default DIR: out/)
#   scripts/build_extension.sh --portable [--python 3.N|INTERPRETER] [--out DIR]
#     the portable zip (docs/PORTABILITY.md, scripts/build_portable.sh) for Python 3.N (where
#     this system has no python3.N: the headers of a build chroot, e.g. trixie's 3.13) or that
#     interpreter (default: this system's python3): out/canopy_ao-<version>-linux_x64-cp3N.zip,
#     needing no Embree, TBB or OpenImageIO on the system
#   ... --repo DIR   also copies the zip into DIR and makes DIR an extension repository
#     (Blender's 'extension server-generate' writes DIR/index.json over every zip there), which
#     Blender adds by URL (file:///abs/DIR/index.json, or DIR served over HTTP); needs Blender 4.2+
# Prints the zip's path on its last line. Install it with
#   blender --command extension install-file -r user_default -e ZIP
# or in Blender: Edit > Preferences > Get Extensions > Install from Disk.
set -euo pipefail
cd "$(dirname "$0")/.."
out=out portable=0 pyver= repo=
while (($#)); do
  case "$1" in
    --out) out=$2; shift 2 ;;
    --portable) portable=1; shift ;;
    --python) pyver=$2; shift 2 ;;
    --repo) repo=$2; shift 2 ;;
    *) echo "build_extension.sh: unknown argument '$1' (use --out DIR, --portable, --python 3.N|INTERPRETER, --repo DIR)" >&2
       exit 2 ;;
  esac
done
[[ -z $pyver || $portable == 1 ]] || { echo "build_extension.sh: --python needs --portable" >&2; exit 2; }
mkdir -p "$out"
out=$(cd "$out" && pwd)

has_extensions() {  # Blender 4.2 or later installed here
  version=$(scripts/blender_version.sh)
  [[ $(printf '%s\n' "$version" 4.2 | sort -V | head -n1) == 4.2 ]]
}
if [[ -n $repo ]]; then
  has_extensions || { echo "build_extension.sh: --repo needs Blender 4.2 or later for" \
    "'extension server-generate' (this Blender: $version); build the zip without it and run" \
    "'blender --command extension server-generate --repo-dir DIR' with a Blender 4.2+ over" \
    "the folder of zips" >&2; exit 2; }
  mkdir -p "$repo"
  repo=$(cd "$repo" && pwd)
fi

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

publish() {  # $1: the built zip; into the repository (with --repo), then its path printed last
  if [[ -n $repo ]]; then
    cp "$1" "$repo/"
    blender_cmd server-generate --repo-dir "$repo"
    [[ -s $repo/index.json ]] || { echo "build_extension.sh: Blender wrote no $repo/index.json" >&2; exit 1; }
    echo "repository: $repo (add it in Blender by URL file://$repo/index.json)" >&2
  fi
  echo "$1"
}

scripts/install_deps.sh
if ((portable)); then
  log=$(mktemp)
  scripts/build_portable.sh "$out" $pyver >"$log" || { cat "$log"; rm -f "$log"; exit 1; }
  sed '$d' "$log"
  dest=$(tail -n1 "$log")
  rm -f "$log"
  publish "$dest"
  exit 0
fi
if ! has_extensions; then
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

blender_cmd validate "$stage/canopy_ao"
rm -f "$stage"/*.zip
blender_cmd build --source-dir "$stage/canopy_ao" --output-dir "$stage"
zips=("$stage"/*.zip)
[[ -f ${zips[0]} ]] || { echo "build_extension.sh: Blender made no zip" >&2; exit 1; }
blender_cmd validate "${zips[0]}"
name=$(basename "${zips[0]}" .zip)
dest="$out/$name-$tag.zip"
mv "${zips[0]}" "$dest"
publish "$dest"
