#!/usr/bin/env bash
# Creates, caches and enters a Debian chroot (trixie, sid, ...) holding Canopy AO's build and test
# dependencies, so the same source is built and tested against that suite's Blender, Embree,
# OpenImageIO, pybind11, Python and CMake.
#
# Usage: scripts/chroot.sh SUITE setup          create (once) and bring up to date
#        scripts/chroot.sh SUITE run CMD [ARG..] run CMD inside, the repository at /canopy-ao
#        scripts/chroot.sh SUITE path           print the chroot's directory
#        scripts/chroot.sh SUITE archive-url    print the Debian archive the host's apt uses
#
# The chroot lives in $CANOPY_AO_CHROOTS (default /var/cache/canopy-ao/chroots)/SUITE and is
# reused between runs; SUITE/.ready is touched once debootstrap and scripts/install_deps.sh have
# both finished inside it. The packages come from the Debian archive this machine's own apt
# sources name (read at run time, never written down here). Mounts (/proc, /sys, /dev, /dev/shm,
# /tmp, the repository) are made in a private mount namespace, so they vanish when the command
# ends, however it ends. Needs root. Fails loudly when the archive cannot be reached.
set -euo pipefail

die() { echo "canopy-ao chroot: $*" >&2; exit 1; }

[[ $# -ge 2 ]] || die "usage: $0 SUITE setup|run CMD...|path"
suite=$1 action=$2
shift 2
[[ $suite =~ ^[a-z]+$ ]] || die "suite must be a Debian codename, got '$suite'"
repo=$(cd "$(dirname "$0")/.." && pwd)
root_dir=${CANOPY_AO_CHROOTS:-/var/cache/canopy-ao/chroots}
dir=$root_dir/$suite

# The Debian archive the host's apt already uses: first from apt's own view of its sources, else
# from the source files themselves.
archive_url() {
  local url
  url=$(apt-get indextargets --format '$(REPO_URI)' 'Identifier: Packages' 'Label: Debian' \
          2>/dev/null | head -n1 || true)
  if [[ -z $url ]]; then
    url=$(cat /etc/apt/sources.list /etc/apt/sources.list.d/*.list 2>/dev/null \
            | awk '$1 == "deb" && $2 ~ /\/debian\/?$/ {print $2; exit}')
  fi
  if [[ -z $url ]]; then
    url=$(cat /etc/apt/sources.list.d/*.sources 2>/dev/null \
            | awk '$1 == "URIs:" && $2 ~ /\/debian\/?$/ {print $2; exit}')
  fi
  [[ -n $url ]] || die "no Debian archive found in this machine's apt sources"
  echo "${url%/}"
}

# Runs "$@" in the chroot with the kernel file systems and the repository mounted, inside a
# private mount namespace (nothing is left mounted afterwards).
enter() {
  [[ -x $dir/bin/sh ]] || die "$dir is not a chroot: run '$0 $suite setup' first"
  cp -L /etc/resolv.conf "$dir/etc/resolv.conf" 2>/dev/null || true
  # The chroot shares this machine's network and host name: it resolves names as the host does
  # (slurmd binds to the host name).
  cp -L /etc/hosts "$dir/etc/hosts" 2>/dev/null || true
  mkdir -p "$dir/canopy-ao"
  # What crosses into the chroot's clean environment: CI and this project's own settings.
  local pass=(CI="${CI:-}")
  # ... and the host's trusted certificates, for the clients that fetch over TLS (npm): a
  # network whose proxy the host trusts through its own CA bundle is the chroot's network too.
  if [[ -s /etc/ssl/certs/ca-certificates.crt ]]; then
    mkdir -p "$dir/etc/ssl/certs"
    cp -L /etc/ssl/certs/ca-certificates.crt "$dir/etc/ssl/certs/canopy-ao-host-ca.crt"
    pass+=(NODE_EXTRA_CA_CERTS=/etc/ssl/certs/canopy-ao-host-ca.crt)
  fi
  local v
  for v in $(compgen -e | grep '^CANOPY_AO_' || true); do pass+=("$v=${!v}"); done
  unshare --mount --propagation private -- /bin/bash -euo pipefail -c '
    dir=$1 repo=$2; shift 2
    mount -t proc proc "$dir/proc"
    mount --rbind /sys "$dir/sys"
    mount --rbind /dev "$dir/dev"
    mount -t tmpfs -o mode=1777,nosuid,nodev shm "$dir/dev/shm"
    mount -t tmpfs -o mode=1777 tmp "$dir/tmp"
    mount --bind "$repo" "$dir/canopy-ao"
    exec chroot "$dir" /usr/bin/env -i HOME=/root TERM="${TERM:-dumb}" LANG=C.UTF-8 \
      PATH=/usr/local/sbin:/usr/local/bin:/usr/sbin:/usr/bin:/sbin:/bin \
      "$@"
  ' canopy-ao-chroot "$dir" "$repo" "${pass[@]}" "$@"
}

setup() {
  [[ $(id -u) -eq 0 ]] || die "must run as root (debootstrap, mount, chroot)"
  # test.sh sets up every chroot at once, and on a fresh machine each would install debootstrap:
  # one apt at a time on the host (a second apt-get fails on dpkg's lock instead of waiting).
  command -v debootstrap >/dev/null || {
    if exec 9>>/tmp/canopy-ao-apt.lock 2>/dev/null; then flock 9; fi  # no lock file: go on
    if ! command -v debootstrap >/dev/null; then
      echo "canopy-ao chroot: installing debootstrap"
      DEBIAN_FRONTEND=noninteractive apt-get -o DPkg::Lock::Timeout=600 install -y -qq \
        debootstrap >/dev/null \
        || { apt-get -o DPkg::Lock::Timeout=600 update -qq \
             && DEBIAN_FRONTEND=noninteractive apt-get -o DPkg::Lock::Timeout=600 install -y \
               -qq debootstrap >/dev/null; } \
        || die "could not install debootstrap on the host"
    fi
    exec 9>&-
  }
  local url
  url=$(archive_url)
  mkdir -p "$root_dir"
  # One setup at a time per suite (another process may be waiting on .ready).
  exec 9>"$root_dir/.$suite.lock"
  flock 9

  # Ready and made from today's dependency list and by today's way of entering the chroot
  # (what it passes in, such as the host's certificates): nothing to do (no network needed).
  local want
  want=$(cat "$repo/scripts/install_deps.sh" "$repo/scripts/chroot.sh" | sha256sum | cut -d' ' -f1)
  if [[ -e $dir/.ready && $(cat "$dir/.ready") == "$want" ]]; then
    echo "canopy-ao chroot: $suite ready (cached at $dir)"
    return 0
  fi

  if [[ ! -e $dir/.debootstrapped ]]; then
    rm -rf "$dir"
    echo "canopy-ao chroot: debootstrap $suite (minbase) into $dir"
    # sid's index in the archive may be a snapshot whose Release file has expired.
    if ! debootstrap --variant=minbase "$suite" "$dir.tmp" "$url" >"$root_dir/$suite.debootstrap.log" 2>&1; then
      tail -n 20 "$root_dir/$suite.debootstrap.log" >&2
      rm -rf "$dir.tmp"
      die "debootstrap of $suite from the host's Debian archive failed (log: $root_dir/$suite.debootstrap.log)"
    fi
    mv "$dir.tmp" "$dir"
    touch "$dir/.debootstrapped"
  fi

  # apt inside: the archive's sid index may have expired; no service starts in a chroot; no
  # recommends (as scripts/install_deps.sh asks).
  cat >"$dir/etc/apt/apt.conf.d/99canopy-ao" <<'EOF'
Acquire::Check-Valid-Until "false";
APT::Install-Recommends "false";
EOF
  printf '#!/bin/sh\nexit 101\n' >"$dir/usr/sbin/policy-rc.d"
  # Blender lists the mounted file systems through /etc/mtab. (-L too: outside a run /proc is not
  # mounted, so the link made by an earlier set-up dangles, and a second ln failed on it.)
  [[ -e $dir/etc/mtab || -L $dir/etc/mtab ]] || ln -s /proc/self/mounts "$dir/etc/mtab"
  chmod +x "$dir/usr/sbin/policy-rc.d"

  if ! enter /bin/bash -c 'apt-get update -qq && /canopy-ao/scripts/install_deps.sh && apt-get clean'; then
    die "installing the dependencies inside the $suite chroot failed"
  fi
  echo "$want" >"$dir/.ready"
  echo "canopy-ao chroot: $suite ready at $dir"
}

case $action in
  setup) setup ;;
  run)
    [[ $# -ge 1 ]] || die "run needs a command"
    [[ -e $dir/.ready ]] || die "$dir is not ready: run '$0 $suite setup' first"
    enter "$@"
    ;;
  path) echo "$dir" ;;
  archive-url) archive_url ;;
  *) die "unknown action '$action' (setup, run, path, archive-url)" ;;
esac
