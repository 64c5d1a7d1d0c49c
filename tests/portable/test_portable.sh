#!/usr/bin/env bash
# The portable extension zip proves itself (docs/PORTABILITY.md):
#  1. it is built (scripts/build_extension.sh --portable) for the bare root's Python or PYTHON;
#  2. readelf/objdump/nm: the module and the libraries it carries need nothing but the C/C++
#     runtime and each other, no glibc version newer than 2.34, no libstdc++ one newer than GCC
#     10's (GLIBCXX_3.4.28, CXXABI_1.3.12; the module links its own libstdc++ and exports
#     PyInit__core alone), the compat library standing in for the newer ones behaves as
#     libstdc++ (cxx_compat_check.cpp), portable_cxx.py refuses an import it lacks, and
#     exceptions thrown in TBB tasks reach the caller in the bare root (tbb_exceptions.cpp);
#  3. in a bare root of SUITE (debootstrap minbase + python3 + python3-numpy, cached by
#     scripts/bare_root.sh), with an empty environment, the zip's module imports and bakes
#     ray-traced, proxy and texel AO (tests/portable/bake_probe.py), bit-identical to what the
#     Debian build's module (addon/canopy_ao/) gives on this machine, whatever the Python; the
#     root has no Embree, TBB or OpenImageIO, and the Debian build's module for the root's
#     Python, where there is one, fails to load there;
#  4. the module calls no Embree function by name (embree_shim.cpp): none can bind to the Embree 4
#     a Blender has loaded; and where SUITE's build chroot (scripts/chroot.sh) is ready, its
#     Blender installs the zip and bakes with it if it has extensions and the zip's Python
#     (tests/portable/chroot_bake.sh);
#  5. where the zip's Python is this Debian's Blender's, in that Blender the zip's package
#     (module without OpenImageIO: images written by core/image_files.py) bakes texel images in
#     EXR, PNG and TGA holding the same pixels as the repository's add-on (OpenImageIO) writes,
#     and re-bakes over those files without Overwrite (it reads their ownership records).
# Run by scripts/test.sh on the host leg, for bookworm and trixie. Needs root for the bare root
# (sudo otherwise).
#   tests/portable/test_portable.sh [SUITE [PYTHON]]
# SUITE: the bare root's Debian (default: this machine's); PYTHON: 3.N or an interpreter's path,
# as build_extension.sh --python takes (default: the bare root's python3's version, bookworm
# 3.11, trixie 3.13, built from the trixie chroot's headers where this system has no 3.13), e.g.
#   tests/portable/test_portable.sh trixie
#   tests/portable/test_portable.sh trixie ~/.pyenv/versions/3.13.0/bin/python3.13
set -euo pipefail
cd "$(dirname "$0")/../.."
suite=${1:-$(. /etc/os-release && echo "$VERSION_CODENAME")}
python=${2:-}
as_root=()
[[ $(id -u) -eq 0 ]] || as_root=(sudo --preserve-env=CANOPY_AO_CHROOTS)
fail() { echo "test_portable.sh: FAILED: $*" >&2; exit 1; }

tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT
chmod 755 "$tmp"
"${as_root[@]}" scripts/bare_root.sh "$suite" setup
bare_py=$("${as_root[@]}" scripts/bare_root.sh "$suite" run "$tmp" python3 -c \
  'import sys; print("cp%d%d" % sys.version_info[:2])')
[[ -n $python ]] || python=${bare_py:2:1}.${bare_py:3}
echo "== portable zip: build"
zip=$(scripts/build_extension.sh --portable ${python:+--python "$python"} --out "$tmp/dist" | tail -n1)
echo "built $(basename "$zip")"
[[ $zip == *-$bare_py.zip ]] || fail "$(basename "$zip") is not for the bare $suite root's Python ($bare_py)"
/usr/bin/python3 -m zipfile -e "$zip" "$tmp/pkg"
ls "$tmp/pkg"/_core*.so >/dev/null || fail "the zip holds no _core*.so"

echo "== portable zip: load-time needs (readelf, objdump)"
runtime='^(libc|libm|libstdc\+\+|libgcc_s|libpthread|libdl|libmvec|ld-linux-x86-64)\.so'
carried=$(cd "$tmp/pkg" && ls lib*-canopyao.so.* 2>/dev/null || true)
[[ -n $carried ]] || fail "the zip carries no libraries (Embree, TBB)"
for f in "$tmp/pkg"/_core*.so "$tmp/pkg"/lib*-canopyao.so.*; do
  name=$(basename "$f")
  for lib in $(readelf -d "$f" | sed -n 's/.*(NEEDED).*\[\(.*\)\]/\1/p'); do
    [[ $lib =~ $runtime ]] && continue
    grep -qxF "$lib" <<<"$carried" || fail "$name needs $lib, which is neither the runtime nor carried"
  done
  readelf -d "$f" | grep -q 'RUNPATH.*\[\$ORIGIN\]' || fail "$name has no \$ORIGIN RUNPATH"
  # The newest version of each family its symbols name (objdump -T) and that it requires of a
  # library (objdump -p, 'Version References', weak ones aside: the loader does not insist).
  newest() {  # newest FAMILY: e.g. GLIBCXX -> 3.4.21, or nothing
    { objdump -T "$f"; objdump -p "$f" | sed -n '/Version References/,$p' | awk '$2 != "0x02"'; } |
      { grep -oE "\b$1_[0-9.]+" || true; } | sed "s/$1_//" | sort -uV | tail -n1
  }
  glibc=$(newest GLIBC) cxx=$(newest GLIBCXX) cxxabi=$(newest CXXABI)
  echo "$name: newest GLIBC_${glibc:-none} GLIBCXX_${cxx:-none} CXXABI_${cxxabi:-none}"
  at_most() { [[ -z $2 || $(printf '%s\n' "$2" "$3" | sort -V | tail -n1) == "$3" ]] ||
    fail "$name needs $1_$2, newer than the $1_$3 baseline"; }
  at_most GLIBC "$glibc" 2.34
  at_most GLIBCXX "$cxx" 3.4.28
  at_most CXXABI "$cxxabi" 1.3.12
done
# The module carries its own libstdc++ and exports nothing but its init function (none of its
# calls can land in a Blender's libstdc++).
if readelf -d "$tmp/pkg"/_core*.so | grep 'NEEDED.*libstdc++' >/dev/null; then
  fail "the module needs libstdc++.so: it should link it statically"
fi
exported=$(nm -D --defined-only "$tmp/pkg"/_core*.so | awk '$3 != "PyInit__core" {print $3}')
[[ -z $exported ]] || fail "the module exports $(wc -l <<<"$exported") symbols besides PyInit__core: $(head -n3 <<<"$exported" | tr '\n' ' ')"
# What the carried libraries need beyond that baseline is native/portable/cxx_compat.cpp's: its
# functions against libstdc++'s own (tests/portable/cxx_compat_check.cpp).
g++ -O1 -o "$tmp/cxx_compat_check" tests/portable/cxx_compat_check.cpp -ldl
"$tmp/cxx_compat_check" "$tmp/pkg"/libcxxcompat-canopyao.so.* || fail "libcxxcompat-canopyao does not do what libstdc++ does"
# ... and a newer import the compat library lacks stops the build: Debian's own TBB against a
# "compat library" defining nothing of libstdc++'s (the carried TBB itself).
cp -L "$(/sbin/ldconfig -p | awk '$1 == "libtbb.so.12" && /x86-64/ && !f {print $NF; f = 1}')" "$tmp/tbb-copy.so"
if /usr/bin/python3 scripts/portable_cxx.py "$tmp/tbb-copy.so" "$tmp/pkg/libtbb-canopyao.so.12" \
    GLIBCXX_3.4.28 CXXABI_1.3.12 >"$tmp/refused.log" 2>&1 ||
   ! grep -q '_M_addrefEv@CXXABI_1.3.13' "$tmp/refused.log"; then
  cat "$tmp/refused.log" >&2
  fail "portable_cxx.py let a newer libstdc++ import through without a definition"
fi
rm "$tmp/tbb-copy.so"

rtc=$(nm -D --undefined-only "$tmp/pkg"/_core*.so | awk '$2 ~ /^rtc/ && n++ < 3 {print $2}')
[[ -z $rtc ]] || fail "the module calls Embree by name ($rtc ...): a Blender's own Embree would take the call"

echo "== portable zip: bake in a bare $suite root (python3 + numpy only)"
cp tests/portable/bake_probe.py "$tmp/"
mkdir "$tmp/debian"
cp addon/canopy_ao/_core*.so "$tmp/debian/"
chmod -R a+rX "$tmp"
# Bare: none of the libraries the Debian builds link is there.
"${as_root[@]}" scripts/bare_root.sh "$suite" run "$tmp" python3 -c '
import ctypes, ctypes.util
def loads(soname):
    try:
        return bool(ctypes.CDLL(soname))
    except OSError:
        return False
found = [n for n in ("embree3", "embree4", "tbb", "OpenImageIO") if ctypes.util.find_library(n)]
found += [s for s in ("libembree3.so.3", "libembree4.so.4", "libtbb.so.12") if loads(s)]
assert not found, f"the root is not bare: {found}"' || fail "the bare $suite root has Embree, TBB or OpenImageIO"
# ... and the Debian build's module for the root's Python (where one was built here) does not load.
if [[ -n $(ls "$tmp/debian"/_core.cpython-${bare_py#cp}-*.so 2>/dev/null) ]]; then
  if "${as_root[@]}" scripts/bare_root.sh "$suite" run "$tmp" python3 -c \
      "import sys; sys.path.insert(0, '/pkg/debian'); import _core" >"$tmp/debian.log" 2>&1; then
    fail "the Debian build's module loaded in the bare root: the root is not bare"
  fi
  grep -q 'cannot open shared object file' "$tmp/debian.log" ||
    { cat "$tmp/debian.log" >&2; fail "the Debian build's module failed in the bare root for another reason"; }
  echo "the Debian build's module does not load there: $(grep -o -m1 'lib[^:]*: cannot open shared object file' "$tmp/debian.log")"
else
  echo "the root has no Embree, TBB or OpenImageIO (no Debian build for $bare_py here to try)"
fi
"${as_root[@]}" scripts/bare_root.sh "$suite" run "$tmp" python3 /pkg/bake_probe.py /pkg/pkg \
  >"$tmp/bare.log" 2>&1 || { cat "$tmp/bare.log" >&2; fail "the portable module does not bake in the bare root"; }
# Where the compat library's functions bind there (all bound at load: LD_BIND_NOW): the carried
# libraries' calls whose version build_portable.sh dropped go to it or to libstdc++, and none of
# libstdc++'s own calls goes to it (its versioned definitions keep them apart).
"${as_root[@]}" scripts/bare_root.sh "$suite" run "$tmp" /usr/bin/env LD_BIND_NOW=1 \
  LD_DEBUG=bindings python3 /pkg/bake_probe.py /pkg/pkg >"$tmp/bindings.log" 2>&1 ||
  { tail -n 20 "$tmp/bindings.log" >&2; fail "the bake with LD_BIND_NOW failed in the bare root"; }
compat_bound=$(grep -c 'to /pkg/pkg/libcxxcompat-canopyao' "$tmp/bindings.log" || true)
if grep 'binding file [^ ]*libstdc++[^ ]* .*to /pkg/pkg/libcxxcompat' "$tmp/bindings.log" >&2; then
  fail "libstdc++'s own calls bind to libcxxcompat-canopyao"
fi
echo "the carried libraries' calls bound to libcxxcompat-canopyao there: $compat_bound"
# Exceptions thrown in TBB tasks cross the carried TBB (the system's libstdc++, the compat
# library) into code with the module's own static libstdc++ (tests/portable/tbb_exceptions.cpp,
# linked with the module's flags, CMakeLists.txt).
echo '{ global: run; local: *; };' >"$tmp/tbb_exceptions.map"  # as native/portable/module.map
g++ -O2 -fPIC -shared -fvisibility=hidden -static-libstdc++ -Wl,--exclude-libs,ALL \
  -Wl,--gc-sections -Wl,--version-script="$tmp/tbb_exceptions.map" \
  -o "$tmp/pkg/libtbb_exceptions.so" tests/portable/tbb_exceptions.cpp \
  "$tmp/pkg/libtbb-canopyao.so.12" -Wl,-rpath,'$ORIGIN'
chmod a+r "$tmp/pkg/libtbb_exceptions.so"
"${as_root[@]}" scripts/bare_root.sh "$suite" run "$tmp" python3 -c '
import ctypes
n = ctypes.CDLL("/pkg/pkg/libtbb_exceptions.so").run()
assert n == 50, f"{n} of 50 exceptions thrown in TBB tasks reached the caller"
print("50 of 50 exceptions thrown in TBB tasks reached the caller")' ||
  fail "exceptions thrown in TBB tasks do not cross the carried TBB"
rm "$tmp/pkg/libtbb_exceptions.so"
/usr/bin/python3 tests/portable/bake_probe.py addon/canopy_ao >"$tmp/host.log" ||
  fail "the Debian build's module does not bake on this machine"
/usr/bin/python3 - "$tmp/bare.log" "$tmp/host.log" <<'PY'
import json, sys
bare, host = (json.loads(open(p).read().split("PROBE ", 1)[1]) for p in sys.argv[1:])
bare.pop("module"), host.pop("module")  # the Pythons may differ; the AO may not
diff = [k for k in host if bare.get(k) != host[k]]
assert not diff, f"the portable module's {', '.join(diff)} AO differs from the Debian build's"
print(f"bare root bake bit-identical to the Debian build's: {', '.join(sorted(host))}")
PY
chroot_dir=$(scripts/chroot.sh "$suite" path)
if [[ -e $chroot_dir/.ready ]]; then
  echo "== portable zip: installed into the $suite chroot's Blender"
  # The chroot sees the repository at /canopy-ao: the zip and the script go to a build folder.
  under=build-portable-test-$suite
  rm -rf "$under" && mkdir -p "$under"
  cp "$zip" "$under/"
  sed "s|@ZIP@|/canopy-ao/$under/$(basename "$zip")|" tests/portable/chroot_bake.sh >"$under/run.sh"
  "${as_root[@]}" scripts/chroot.sh "$suite" run bash "/canopy-ao/$under/run.sh" ||
    fail "the zip does not install and bake in the $suite chroot's Blender"
  rm -rf "$under"
fi

blender_py=$(blender -b --factory-startup --python-expr \
  'import sys; print("CANOPY_AO_PY=cp%d%d" % sys.version_info[:2])' 2>/dev/null | sed -n 's/^CANOPY_AO_PY=//p')
if [[ $zip != *-$blender_py.zip ]]; then
  echo "== portable zip: no Blender bake here (this Blender runs ${blender_py:-no Python})"
  echo "portable zip OK: $(basename "$zip")"
  exit 0
fi
echo "== portable zip: texel images in this Debian's Blender, without OpenImageIO"
blender -b --factory-startup --python examples/make_scene.py -- \
  --scene round_tree --quick --out "$tmp/scene.blend" >"$tmp/scene.log" 2>&1 ||
  { cat "$tmp/scene.log" >&2; fail "could not make the example scene"; }
mkdir -p "$tmp/us-repo/addons" "$tmp/us-zip/addons"
ln -s "$PWD/addon/canopy_ao" "$tmp/us-repo/addons/canopy_ao"
ln -s "$tmp/pkg" "$tmp/us-zip/addons/canopy_ao"
bake() {  # bake WHICH(repo|zip) FORMAT DIR: a texel bake with that package's CLI
  local check="assert hasattr(m, 'write_image') == ('$1' == 'repo'), m.__file__"
  BLENDER_USER_SCRIPTS="$tmp/us-$1" blender -b "$tmp/scene.blend" --factory-startup \
    --addons canopy_ao --python-exit-code 1 --python-expr \
    "import canopy_ao._core as m, canopy_ao.cli as c; $check; c.main()" -- \
    --all --method sphere --mode texel --resolution 48 --image-format "$2" --image-dir "$3" \
    >"$tmp/bake.log" 2>&1 || { cat "$tmp/bake.log" >&2; fail "the $1 package's $2 bake into $3 failed"; }
}
for fmt in exr png tga; do
  bake repo "$fmt" "$tmp/img-repo-$fmt"
  bake zip "$fmt" "$tmp/img-zip-$fmt"
  cp -r "$tmp/img-repo-$fmt" "$tmp/img-over-$fmt"
  bake zip "$fmt" "$tmp/img-over-$fmt"  # over OpenImageIO's files, no Overwrite: its own
  bake zip "$fmt" "$tmp/img-zip-$fmt"   # over its own files, no Overwrite
done
/usr/bin/python3 - "$tmp" <<'PY'
import glob, os, sys
import numpy as np
sys.path.insert(0, "addon")
from canopy_ao import _core  # the Debian build's: OpenImageIO reads every file
tmp, n = sys.argv[1], 0
for fmt in ("exr", "png", "tga"):
    ref = sorted(glob.glob(f"{tmp}/img-repo-{fmt}/*"))
    for got in (sorted(glob.glob(f"{tmp}/img-zip-{fmt}/*")), sorted(glob.glob(f"{tmp}/img-over-{fmt}/*"))):
      assert ref and [os.path.basename(p) for p in ref] == [os.path.basename(p) for p in got], (ref, got)
      for a, b in zip(ref, got):
        pa, pb = _core.read_image(a), _core.read_image(b)
        assert pa.shape == pb.shape and np.array_equal(pa, pb), f"{b} differs from {a}"
        assert pa.min() < pa.max(), f"{a} is flat"
        assert open(a, "rb").read() != open(b, "rb").read() or "over" in b, "same writer?"
        n += 1
print(f"{n} texel images written without OpenImageIO hold the same pixels")
PY
echo "portable zip OK: $(basename "$zip")"
