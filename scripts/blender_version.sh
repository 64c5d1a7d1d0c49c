#!/usr/bin/env bash
# Prints the installed Blender's version as MAJOR.MINOR (e.g. 4.3); fails if Blender cannot say.
set -euo pipefail
v=$(blender -b --factory-startup --python-expr \
  'import bpy; print("CANOPY_AO_BV=%d.%d" % bpy.app.version[:2])' 2>/dev/null |
  sed -n 's/^CANOPY_AO_BV=//p')
[[ -n $v ]] || { echo "blender_version.sh: could not ask Blender for its version" >&2; exit 1; }
echo "$v"
