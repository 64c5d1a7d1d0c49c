#!/usr/bin/env bash
# Installs the Debian packages Canopy AO needs, only those missing. Safe to re-run.
# Usage: scripts/install_deps.sh [--with-bench]
set -euo pipefail

pkgs=(
  build-essential cmake git pkg-config
  python3 python3-dev python3-numpy python3-pytest
  pybind11-dev libembree-dev libopenimageio-dev libtbb-dev
  libgtest-dev libbenchmark-dev
  blender xvfb xauth
  # Blender 5.x's own extensions add-on (bl_pkg: `blender --command extension ...`) imports
  # these, which Debian's blender package does not pull in.
  python3-cattr python3-requests
  # readelf, objdump, ldd: the module's load-time dependencies are checked in the tests.
  binutils libc-bin
  patchelf  # the portable zip carries Embree and TBB renamed (scripts/build_portable.sh)
  slurmctld slurmd slurm-client munge parallel nodejs  # batch back ends; Flamenco's JS
)
if [[ "${1:-}" == "--with-bench" ]]; then
  pkgs+=(python3-matplotlib)
fi

missing=()
for p in "${pkgs[@]}"; do
  dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || missing+=("$p")
done

SUDO=""
[[ $(id -u) -eq 0 ]] || SUDO="sudo"
if ((${#missing[@]})); then
  echo "canopy-ao: installing ${missing[*]}"
  export DEBIAN_FRONTEND=noninteractive
  # Wait for another apt (a chroot's set-up installing debootstrap: scripts/chroot.sh takes the
  # same lock) instead of failing on dpkg's.
  if exec 9>>/tmp/canopy-ao-apt.lock 2>/dev/null; then flock 9; fi  # no lock file: go on
  $SUDO apt-get -o DPkg::Lock::Timeout=600 update -qq
  $SUDO apt-get -o DPkg::Lock::Timeout=600 install -y -qq --no-install-recommends "${missing[@]}" >/dev/null
fi

# The Khronos glTF validator, run by node in tests/blender/test_gltf.py: npm (Debian's, where
# nodejs brought none) installs one pinned version into a project cache, once per version; the
# lock keeps concurrent runs (host and chroots, several worktrees) from installing over each
# other. Unreachable registry: a warning, and that test fails naming this script.
gltf_validator=2.0.0-dev.3.10
npm_dir=${CANOPY_AO_NPM:-/var/cache/canopy-ao/npm}
have_validator() {
  grep -qs "\"version\": \"$gltf_validator\"" "$npm_dir/node_modules/gltf-validator/package.json"
}
if ! have_validator; then
  if ! command -v npm >/dev/null; then
    echo "canopy-ao: installing npm"
    if exec 9>>/tmp/canopy-ao-apt.lock 2>/dev/null; then flock 9; fi  # as above
    $SUDO env DEBIAN_FRONTEND=noninteractive apt-get -o DPkg::Lock::Timeout=600 install -y -qq \
      --no-install-recommends npm >/dev/null
  fi
  $SUDO mkdir -p "$npm_dir"
  (
    flock 8
    if ! have_validator; then
      echo "canopy-ao: installing gltf-validator@$gltf_validator into $npm_dir"
      $SUDO npm install --prefix "$npm_dir" --no-audit --no-fund --loglevel=error \
        "gltf-validator@$gltf_validator" >/dev/null \
        || echo "canopy-ao: warning: npm could not install gltf-validator into $npm_dir" >&2
    fi
  ) 8>>/tmp/canopy-ao-npm.lock
fi
