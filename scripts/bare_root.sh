#!/usr/bin/env bash
# Creates and caches a bare Debian root (debootstrap minbase + python3 + python3-numpy, nothing
# else: no Embree, TBB or OpenImageIO) and runs commands in it, to prove that a portable
# extension's module needs nothing from the system but glibc, the C++ runtime, Python and numpy
# (docs/PORTABILITY.md).
#
# Usage: scripts/bare_root.sh SUITE setup              create (once; cached)
#        scripts/bare_root.sh SUITE run DIR CMD [ARG..] run CMD inside, host folder DIR at /pkg
#        scripts/bare_root.sh SUITE path               print the root's directory
#
# The root lives in $CANOPY_AO_CHROOTS (default /var/cache/canopy-ao/chroots)/SUITE-bare, beside
# the build chroots (scripts/chroot.sh, whose archive look-up it shares), and is made once.
# Needs root.
set -euo pipefail

die() { echo "canopy-ao bare root: $*" >&2; exit 1; }
[[ $# -ge 2 ]] || die "usage: $0 SUITE setup|run DIR CMD...|path"
suite=$1 action=$2
shift 2
[[ $suite =~ ^[a-z]+$ ]] || die "suite must be a Debian codename, got '$suite'"
repo=$(cd "$(dirname "$0")/.." && pwd)
root_dir=${CANOPY_AO_CHROOTS:-/var/cache/canopy-ao/chroots}
dir=$root_dir/$suite-bare
packages=python3,python3-numpy

setup() {
  [[ $(id -u) -eq 0 ]] || die "must run as root (debootstrap, chroot)"
  command -v debootstrap >/dev/null || die "debootstrap is missing (apt-get install debootstrap)"
  mkdir -p "$root_dir"
  exec 9>"$root_dir/.$suite-bare.lock"
  flock 9
  if [[ -e $dir/.ready && $(cat "$dir/.ready") == "$packages" ]]; then
    echo "canopy-ao bare root: $suite ready (cached at $dir)"
    return 0
  fi
  local url
  url=$("$repo/scripts/chroot.sh" "$suite" archive-url)
  rm -rf "$dir" "$dir.tmp"
  echo "canopy-ao bare root: debootstrap $suite (minbase + $packages) into $dir"
  if ! debootstrap --variant=minbase --include="$packages" "$suite" "$dir.tmp" "$url" \
      >"$root_dir/$suite-bare.debootstrap.log" 2>&1; then
    tail -n 20 "$root_dir/$suite-bare.debootstrap.log" >&2
    rm -rf "$dir.tmp"
    die "debootstrap of $suite failed (log: $root_dir/$suite-bare.debootstrap.log)"
  fi
  rm -rf "$dir.tmp/var/cache/apt/archives/"*.deb
  echo "$packages" >"$dir.tmp/.ready"
  mv "$dir.tmp" "$dir"
  echo "canopy-ao bare root: $suite ready at $dir"
}

# CMD runs with an empty environment (no LD_LIBRARY_PATH), host folder at /pkg (read-only), in a
# private mount namespace: nothing stays mounted.
enter() {
  [[ -e $dir/.ready ]] || die "$dir is not ready: run '$0 $suite setup' first"
  local host=$1
  shift
  mkdir -p "$dir/pkg"
  unshare --mount --propagation private -- /bin/bash -euo pipefail -c '
    dir=$1 host=$2; shift 2
    mount -t proc proc "$dir/proc"
    mount -t tmpfs -o mode=1777 tmp "$dir/tmp"
    mount --bind -o ro "$host" "$dir/pkg"
    exec chroot "$dir" /usr/bin/env -i HOME=/root LANG=C.UTF-8 PATH=/usr/bin:/bin "$@"
  ' canopy-ao-bare "$dir" "$(cd "$host" && pwd)" "$@"
}

case $action in
  setup) setup ;;
  run) [[ $# -ge 2 ]] || die "run needs a folder and a command"; enter "$@" ;;
  path) echo "$dir" ;;
  *) die "unknown action '$action' (setup, run, path)" ;;
esac
