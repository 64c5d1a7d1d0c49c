#!/usr/bin/env bash
# The portable extension zip (docs/PORTABILITY.md): the native module built without
# OpenImageIO for one Python, with Debian 12's Embree and TBB carried beside it under names of
# their own (libembree3-canopyao.so.3, libtbb-canopyao.so.12: SONAME and DT_NEEDED patched, found
# through an $ORIGIN RUNPATH), so it loads where the system has neither and never takes the
# copies a Blender loaded; its Embree calls go through native/portable/embree_shim.cpp.
# Called by scripts/build_extension.sh --portable.
#   scripts/build_portable.sh OUT_DIR [PYTHON]
# PYTHON: a version 3.N or the path of an interpreter with its headers (e.g. a pyenv 3.13);
# default: this system's python3. For 3.N the module is built for /usr/bin/python3.N (headers
# from the distribution's python3.N-dev) or, where this system has no python3.N, for the headers
# of a build chroot that has them (scripts/chroot.sh: trixie has 3.13, sid 3.14), without
# running that Python. Prints the zip's path on its last line:
# OUT_DIR/canopy_ao-<version>-linux_x64-cp<XY>.zip.
set -euo pipefail
cd "$(dirname "$0")/.."
out=$1
python=${2:-/usr/bin/python3}
py_root=
if [[ $python != */* ]]; then
  [[ $python =~ ^3\.[0-9]+$ ]] || { echo "build_portable.sh: PYTHON is 3.N or an interpreter's path, got '$python'" >&2; exit 1; }
  if [[ ! -x /usr/bin/python$python ]]; then
    chroots=$(dirname "$(scripts/chroot.sh trixie path)")
    for dir in "$chroots"/*/; do
      [[ -e $dir/.ready && -f $dir/usr/include/python$python/Python.h ]] && { py_root=${dir%/}; break; }
    done
    [[ -n $py_root ]] || { echo "build_portable.sh: no Python $python here: neither /usr/bin/python$python nor a build chroot in $chroots with its headers (python$python-dev); give an interpreter's path" >&2; exit 1; }
  fi
  pyver=$python
  python=/usr/bin/python$python
fi
if [[ -z $py_root ]]; then
  [[ -x $python ]] || { echo "build_portable.sh: no Python interpreter '$python' (give 3.N for /usr/bin/python3.N, with its python3.N-dev, or an interpreter's path)" >&2; exit 1; }
  pyver=$("$python" -c 'import sys; print("%d.%d" % sys.version_info[:2])')
fi
command -v patchelf >/dev/null || { echo "build_portable.sh: patchelf is missing (apt-get install patchelf)" >&2; exit 1; }
tag=cp${pyver/./}
suffix_of_carried=-canopyao  # libX.so.N is carried as libX-canopyao.so.N
build=${CANOPY_AO_PORTABLE_BUILD_DIR:-build-portable-$tag}
# The zip's C++ runtime baseline (GCC 10's libstdc++): the module links its own, and what the
# carried libraries need beyond it comes from native/portable/cxx_compat.cpp.
cxx_baseline=(GLIBCXX_3.4.28 CXXABI_1.3.12)

# A chroot's Python: its headers, copied into the build folder (again only when they changed),
# with the architecture's own pyconfig.h in place of Debian's multiarch switch, and its module
# suffix read from its sysconfig data (no interpreter of another distribution is run).
python_args=()
if [[ -n $py_root ]]; then
  multiarch=$(gcc -print-multiarch)
  headers=$build/python$pyver-headers
  if ! diff -rq -x pyconfig.h "$py_root/usr/include/python$pyver" "$headers" >/dev/null 2>&1; then
    rm -rf "$headers"
    mkdir -p "$build"
    cp -r "$py_root/usr/include/python$pyver" "$headers"
  fi
  config=$py_root/usr/include/$multiarch/python$pyver/pyconfig.h
  [[ -f $config ]] || config=$py_root/usr/include/python$pyver/pyconfig.h
  cmp -s "$config" "$headers/pyconfig.h" || cp "$config" "$headers/pyconfig.h"
  sysconfigs=("$py_root/usr/lib/python$pyver"/_sysconfigdata_*"$multiarch".py)
  sysconfig=${sysconfigs[0]}
  [[ -f $sysconfig ]] || { echo "build_portable.sh: $py_root has no _sysconfigdata for python$pyver" >&2; exit 1; }
  ext_suffix=$(/usr/bin/python3 -c '
import ast, sys
tree = ast.parse(open(sys.argv[1]).read())
for node in tree.body:
    if isinstance(node, ast.Assign) and node.targets[0].id == "build_time_vars":
        print(ast.literal_eval(node.value)["EXT_SUFFIX"])' "$sysconfig")
  [[ $ext_suffix == .cpython-${tag#cp}-*.so ]] || { echo "build_portable.sh: $sysconfig gives the suffix '$ext_suffix'" >&2; exit 1; }
  python_args=(-DCANOPY_AO_PYTHON_HEADERS="$(cd "$headers" && pwd)"
               -DCANOPY_AO_PYTHON_EXT_SUFFIX="$ext_suffix")
  echo "Python $pyver: the headers of $py_root (python$pyver-dev), module suffix $ext_suffix" >&2
else
  ext_suffix=$("$python" -c 'import sysconfig; print(sysconfig.get_config_var("EXT_SUFFIX"))')
  python_args=(-DPython_EXECUTABLE="$python")
fi

# pybind11 2.12 or newer: older ones read NumPy 2's arrays wrongly (its dtype structure changed;
# Blender's newer series bundle NumPy 2) and predate Python 3.13. Debian 12 has 2.10: the headers
# (pybind11 is headers and CMake files only) of the trixie chroot's pybind11-dev are copied into
# the build folder, or those of CANOPY_AO_PYBIND11_ROOT/usr.
pybind11=()
have=$(dpkg-query -W -f='${Version}' pybind11-dev 2>/dev/null | cut -d- -f1 || true)
if [[ $(printf '%s\n' "${have:-0}" 2.12 | sort -V | head -n1) != 2.12 ]]; then
  root=${CANOPY_AO_PYBIND11_ROOT:-$(scripts/chroot.sh trixie path)}
  [[ -f $root/usr/lib/cmake/pybind11/pybind11Config.cmake && -d $root/usr/include/pybind11 ]] || {
    echo "build_portable.sh: this system's pybind11 (${have:-none}) is older than 2.12 and $root has" \
      "no pybind11-dev: run 'scripts/chroot.sh trixie setup' (as root) or set" \
      "CANOPY_AO_PYBIND11_ROOT to a root holding usr/include/pybind11" >&2
    exit 1
  }
  # Copied again only when they changed (a copy's new times would rebuild every binding).
  if ! diff -rq "$root/usr/include/pybind11" "$build/pybind11/include/pybind11" >/dev/null 2>&1 ||
     ! diff -rq "$root/usr/lib/cmake/pybind11" "$build/pybind11/lib/cmake/pybind11" >/dev/null 2>&1; then
    rm -rf "$build/pybind11"
    mkdir -p "$build/pybind11/lib/cmake" "$build/pybind11/include"
    cp -r "$root/usr/lib/cmake/pybind11" "$build/pybind11/lib/cmake/"
    cp -r "$root/usr/include/pybind11" "$build/pybind11/include/"
  fi
  pybind11=(-Dpybind11_DIR="$(cd "$build/pybind11/lib/cmake/pybind11" && pwd)")
fi

# The normal build's flags, but no OpenImageIO, no tests, and the module stays in the build
# folder (addon/canopy_ao/ keeps the system build's module).
cmake -S . -B "$build" -DCMAKE_BUILD_TYPE=Release -DCANOPY_AO_WITH_OIIO=OFF \
  -DCANOPY_AO_COPY_TO_ADDON=OFF -DCANOPY_AO_TESTS=OFF -DCANOPY_AO_BENCH=OFF \
  -DCANOPY_AO_PYTHON_VERSION="$pyver" "${python_args[@]}" "${pybind11[@]}" \
  -DCANOPY_AO_EMBREE_SHIM="libembree3$suffix_of_carried.so.3" >/dev/null
cmake --build "$build" -j"$(nproc)" --target _core >/dev/null
built=$build/_core$ext_suffix
[[ -f $built ]] || { echo "build_portable.sh: $built was not built" >&2; exit 1; }

stage=$(mktemp -d)
trap 'rm -rf "$stage"' EXIT
pkg=$stage/canopy_ao
mkdir "$pkg"
tar -C addon/canopy_ao --exclude=__pycache__ --exclude='_core*.so' --exclude='*.pyc' -cf - . |
  tar -C "$pkg" -xf -
cp "$built" "$pkg/"
module=$pkg/_core$ext_suffix

# Every shared library the module needs that is not the C/C++ runtime is carried, renamed
# (libX.so.N -> libX-canopyao.so.N); anything else it needs is an error.
runtime='^(libc|libm|libstdc\+\+|libgcc_s|libpthread|libdl|libmvec|ld-linux-x86-64)\.so'
declare -A renamed
carry() {  # carry SONAME: copy the system's library beside the module, renamed, with its own needs
  local lib=$1 path new
  [[ -z ${renamed[$lib]:-} ]] || return 0
  path=$(/sbin/ldconfig -p | awk -v l="$lib" '$1 == l && /x86-64/ && !found {print $NF; found = 1}')  # reads all: no SIGPIPE
  [[ -f $path ]] || { echo "build_portable.sh: $lib not found on this system" >&2; exit 1; }
  new=$(echo "$lib" | sed -E "s/^(lib[^.]+)\\.so/\\1$suffix_of_carried.so/")
  renamed[$lib]=$new
  cp -L "$path" "$pkg/$new"
  chmod 644 "$pkg/$new"
  patchelf --set-soname "$new" "$pkg/$new"
  bundle "$pkg/$new"
  # Its libstdc++ needs brought down to the baseline: the symbols let go bind by name, to the
  # system's libstdc++ or, where that is older, to the compat library it now needs too.
  local let_go
  let_go=$(/usr/bin/python3 scripts/portable_cxx.py "$pkg/$new" "$compat" "${cxx_baseline[@]}")
  if [[ -n $let_go ]]; then
    sed "s/^/$new: /" <<<"$let_go" >&2
    if [[ ! -f $pkg/$compat_name ]]; then
      cp "$compat" "$pkg/$compat_name"
      chmod 644 "$pkg/$compat_name"
      bundle "$pkg/$compat_name"
    fi
    patchelf --add-needed "$compat_name" "$pkg/$new"
  fi
}
bundle() {  # bundle FILE: FILE's non-runtime needs carried and renamed; RUNPATH $ORIGIN
  local f=$1 lib
  for lib in $(readelf -d "$f" | sed -n 's/.*(NEEDED).*\[\(.*\)\]/\1/p'); do
    [[ $lib =~ $runtime ]] && continue
    case $lib in libembree*|libtbb*) ;; *)
      echo "build_portable.sh: $(basename "$f") needs $lib, which the portable zip cannot carry" >&2
      exit 1 ;;
    esac
    carry "$lib"
    patchelf --replace-needed "$lib" "${renamed[$lib]}" "$f"
  done
  patchelf --set-rpath '$ORIGIN' "$f"
}
compat=$build/libcxxcompat$suffix_of_carried.so.1  # native/portable/cxx_compat.cpp
compat_name=$(basename "$compat")
[[ -f $compat ]] || { echo "build_portable.sh: $compat was not built" >&2; exit 1; }
bundle "$module"
# Embree is not a DT_NEEDED of the module: embree_shim.cpp loads it (dlopen, by the renamed
# name, found through the module's RUNPATH).
carry libembree3.so.3

version=$(sed -n 's/^version = "\(.*\)"/\1/p' addon/canopy_ao/blender_manifest.toml)
mkdir -p "$out"
dest=$(cd "$out" && pwd)/canopy_ao-$version-linux_x64-$tag.zip
# Where Blender has extensions, it checks the package (this Debian's Blender may be older).
bversion=$(scripts/blender_version.sh 2>/dev/null || echo 0)
if [[ $(printf '%s\n' "$bversion" 4.2 | sort -V | head -n1) == 4.2 ]]; then
  blender --factory-startup --command extension validate "$pkg" >"$stage/validate.log" 2>&1 ||
    { cat "$stage/validate.log" >&2; echo "build_portable.sh: Blender's validate failed" >&2; exit 1; }
fi
# The package's files at the zip's top level, as Blender's 'extension build' lays them out.
/usr/bin/python3 - "$pkg" "$dest" <<'PY'
import os, sys, zipfile
src, dest = sys.argv[1], sys.argv[2]
tmp = dest + ".tmp"
with zipfile.ZipFile(tmp, "w", zipfile.ZIP_DEFLATED) as z:
    for root, dirs, files in os.walk(src):
        dirs.sort()
        for name in sorted(files):
            path = os.path.join(root, name)
            z.write(path, os.path.relpath(path, src))
os.replace(tmp, dest)
PY
echo "$dest"
