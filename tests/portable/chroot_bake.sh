# Run by tests/portable/test_portable.sh inside a build chroot (scripts/chroot.sh), @ZIP@ replaced
# by the portable zip's path there: where that chroot's Blender has extensions (4.2+) and runs
# the zip's Python, the zip is installed with Blender's own command and bakes the example tree
# (ray-traced) through the installed package; else it says why nothing was installed.
set -euo pipefail
zip=@ZIP@
ask() { blender -b --factory-startup --python-expr "$1" 2>/dev/null | sed -n 's/^CANOPY_AO=//p'; }
tag=$(ask 'import sys; print("CANOPY_AO=cp%d%d" % sys.version_info[:2])')
v=$(ask 'import bpy; print("CANOPY_AO=%d.%d" % bpy.app.version[:2])')
if [[ $zip != *-$tag.zip || $(printf '%s\n' "$v" 4.2 | sort -V | head -n1) != 4.2 ]]; then
  echo "not installed: this chroot's Blender $v runs $tag"
  exit 0
fi
export BLENDER_USER_RESOURCES=/tmp/user
cd /tmp
blender --factory-startup --command extension install-file -r user_default -e "$zip" \
  >/tmp/install.log 2>&1 || { cat /tmp/install.log; exit 1; }
blender -b --factory-startup --python /canopy-ao/examples/make_scene.py -- \
  --scene round_tree --quick --out /tmp/scene.blend >/tmp/scene.log 2>&1 || { cat /tmp/scene.log; exit 1; }
blender -b --factory-startup /tmp/scene.blend --python-exit-code 1 --python-expr \
  "import bl_ext.user_default.canopy_ao.core.native as n
assert n._core is not None and not hasattr(n._core, 'write_image'), n.core_status()
import bl_ext.user_default.canopy_ao.cli as c; c.main()" -- \
  --all --method raytrace --samples 16 --report /tmp/report.json >/tmp/bake.log 2>&1 ||
  { cat /tmp/bake.log; exit 1; }
python3 - "$v" <<'PY'
import json, sys
o = json.load(open("/tmp/report.json"))["objects"]
assert o and all(0 < e["ao_mean"] < 1 for e in o.values()), o
print(f"Blender {sys.argv[1]} installed the zip and baked {len(o)} objects through it")
PY
