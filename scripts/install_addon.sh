#!/usr/bin/env bash
# Put the Canopy AO add-on (with its built native module) where Blender finds it.
#
#   scripts/install_addon.sh [--copy] [--enable] [--dir ADDONS_DIR] [--blender BLENDER]
#
#   --copy      copy addon/canopy_ao instead of symlinking it (symlink: rebuilds show up at once)
#   --enable    also enable it in Blender's user preferences (saved), so a plain `blender` has it
#   --dir       the add-on folder to install into (default: Blender's user scripts/addons)
#   --blender   the Blender executable (default: blender)
#
# Build the module first: cmake -S . -B build-addon && cmake --build build-addon -j2
# Never replaces a directory or file it did not make: an existing canopy_ao that is not our
# symlink, nor a copy marked by this script, is left alone and the script fails.
set -euo pipefail

here="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
src="$here/addon/canopy_ao"
copy=0 enable=0 dest="" blender="${BLENDER:-blender}"
while [ $# -gt 0 ]; do
  case "$1" in
    --copy) copy=1 ;;
    --enable) enable=1 ;;
    --dir) dest="$2"; shift ;;
    --blender) blender="$2"; shift ;;
    -h|--help) sed -n '2,14p' "$0"; exit 0 ;;
    *) echo "install_addon.sh: unknown option $1 (see --help)" >&2; exit 2 ;;
  esac
  shift
done

if ! ls "$src"/_core*.so >/dev/null 2>&1; then
  echo "install_addon.sh: warning: no _core*.so in $src; the add-on will enable but cannot" \
       "bake until you build it (cmake -S . -B build-addon && cmake --build build-addon -j2)" >&2
fi

if [ -z "$dest" ]; then
  dest="$("$blender" -b --factory-startup --python-expr \
    'import bpy; print("ADDONS_DIR=" + bpy.utils.user_resource("SCRIPTS", path="addons"))' \
    2>/dev/null | sed -n 's/^ADDONS_DIR=//p' | tail -n 1)" || true
  if [ -z "$dest" ]; then
    ver="$("$blender" --version 2>/dev/null | sed -n 's/^Blender \([0-9]*\.[0-9]*\).*/\1/p' | head -n 1)"
    dest="$HOME/.config/blender/${ver:-3.4}/scripts/addons"
  fi
fi
mkdir -p "$dest"
target="$dest/canopy_ao"
marker=".canopy_ao_installed_copy"

if [ -L "$target" ]; then
  if [ "$(readlink -f "$target")" = "$(readlink -f "$src")" ] || [ -e "$target/$marker" ]; then
    rm "$target"
  else
    echo "install_addon.sh: $target is a symlink to $(readlink "$target"), not this checkout;" \
         "remove it yourself if you mean to replace it" >&2
    exit 1
  fi
elif [ -e "$target" ]; then
  if [ -d "$target" ] && [ -e "$target/$marker" ]; then
    rm -rf "$target"
  else
    echo "install_addon.sh: $target exists and was not installed by this script; leaving it" \
         "alone (move it away, then run again)" >&2
    exit 1
  fi
fi

if [ "$copy" = 1 ]; then
  mkdir "$target"
  (cd "$src" && tar --exclude='__pycache__' -cf - .) | (cd "$target" && tar -xf -)
  echo "$src" > "$target/$marker"
  echo "copied $src -> $target"
else
  ln -s "$src" "$target"
  echo "linked $target -> $src"
fi

if [ "$enable" = 1 ]; then
  # Without --factory-startup: enable in (and save) the user's own preferences.
  BLENDER_USER_SCRIPTS="$(dirname "$dest")" "$blender" -b --python-exit-code 1 --python-expr \
    'import addon_utils, bpy, sys
mod = addon_utils.enable("canopy_ao", default_set=True, handle_error=None)
if mod is None:
    sys.exit("could not enable canopy_ao")
bpy.ops.wm.save_userpref()
print("enabled canopy_ao in the user preferences")' || { echo "install_addon.sh: enabling failed" >&2; exit 1; }
fi
echo "check: $blender -b --factory-startup --addons canopy_ao --python-expr \"import bpy; print(hasattr(bpy.types.Scene, 'canopy_ao'))\""
