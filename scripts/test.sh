#!/usr/bin/env bash
# Runs every test on every supported Debian stack: the legs of the test matrix.
#   host    this machine (Debian 12: Blender 3.4, Embree 3, OIIO 2.4, Python 3.11), and the
#           portable zips, cp311 in a bare Debian 12 root and cp313 in a bare Debian 13 root and
#           the trixie chroot's Blender (tests/portable/test_portable.sh)
#   trixie  a cached Debian 13 chroot (Blender 4.3, Embree 4, OIIO 2.5, Python 3.13)
#   sid     a cached Debian unstable chroot (Blender 5.x, Embree 4, OIIO 3.1, Python 3.14)
# Each leg builds and runs the whole suite (scripts/test_suite.sh) in its own build folder.
# Chroots are made once by scripts/chroot.sh (needs root and the Debian archive this machine's
# apt uses) and reused; a leg that cannot be set up fails.
#   CANOPY_AO_LEGS="host trixie"   run only these legs (default: all of them)
#   CANOPY_AO_PORTABLE_SUITES="bookworm trixie sid"   the bare roots the host leg proves a
#       portable zip in, each for its own Python (default: this Debian's and trixie: cp311, cp313;
#       sid adds cp314, about five more minutes)
set -euo pipefail
cd "$(dirname "$0")/.."

all_legs=(host trixie sid)
read -r -a legs <<<"${CANOPY_AO_LEGS:-${all_legs[*]}}"
for leg in "${legs[@]}"; do
  [[ " ${all_legs[*]} " == *" $leg "* ]] || { echo "test.sh: unknown leg '$leg' (${all_legs[*]})" >&2; exit 2; }
done
as_root=()
[[ $(id -u) -eq 0 ]] || as_root=(sudo --preserve-env=CANOPY_AO_BUILD_DIR,CI)

# A chroot's set-up result, waited for once (the host leg's portable test may need trixie's).
declare -A setup_rc
setup_done() {
  local leg=$1
  if [[ -z ${setup_rc[$leg]:-} ]]; then
    local ok=0
    wait "${setup_pid[$leg]}" || ok=$?
    setup_rc[$leg]=$ok
    cat "$setup_logs/$leg"
  fi
  return "${setup_rc[$leg]}"
}

run_leg() {
  local leg=$1
  if [[ $leg == host ]]; then
    local ok=0
    CANOPY_AO_BUILD_DIR=build scripts/test_suite.sh || ok=$?
    # The portable zips, each in a bare root of its suite (cached beside the chroots) and that
    # suite's Blender: cp311 in this Debian's, cp313 in trixie's (built here with the trixie
    # chroot's pybind11 and Python 3.13 headers, scripts/build_portable.sh).
    [[ -z ${setup_pid[trixie]:-} ]] || setup_done trixie || true
    if [[ ! -e $(scripts/chroot.sh trixie path)/.ready ]]; then
      echo "== Portable zip test skipped: it builds with the trixie chroot's pybind11, which is" \
           "not set up (run the trixie leg, or scripts/chroot.sh trixie setup)"
      return "$ok"
    fi
    local suite here
    here=$(. /etc/os-release && echo "$VERSION_CODENAME")
    for suite in ${CANOPY_AO_PORTABLE_SUITES:-$here trixie}; do
      [[ $suite == "$here" ]] || [[ -z ${setup_pid[$suite]:-} ]] || setup_done "$suite" || true
      echo "== Portable zip test in $suite (tests/portable/test_portable.sh $suite)"
      tests/portable/test_portable.sh "$suite" || ok=1
    done
    return "$ok"
  else
    setup_done "$leg" || { echo "test.sh: the $leg chroot could not be set up" >&2; return 1; }
    CANOPY_AO_BUILD_DIR="build-$leg" "${as_root[@]}" \
        scripts/chroot.sh "$leg" run /canopy-ao/scripts/test_suite.sh
  fi
}

# Chroots that are not ready yet are made in the background while the earlier legs run
# (debootstrap and apt are mostly waiting on the archive); each leg then waits for its own.
declare -A setup_pid
setup_logs=$(mktemp -d)
trap 'rm -rf "$setup_logs"' EXIT
for leg in "${legs[@]}"; do
  [[ $leg == host ]] && continue
  "${as_root[@]}" scripts/chroot.sh "$leg" setup >"$setup_logs/$leg" 2>&1 &
  setup_pid[$leg]=$!
done

passed=0 failed=0 summary=()
for leg in "${legs[@]}"; do
  echo "=== leg $leg"
  start=$SECONDS
  if run_leg "$leg"; then
    result=passed
    passed=$((passed + 1))
  else
    result=FAILED
    failed=$((failed + 1))
  fi
  summary+=("$(printf '%-7s %-6s %4d s' "$leg" "$result" $((SECONDS - start)))")
  echo "=== leg $leg: $result in $((SECONDS - start)) s"
done
echo "=== test matrix"
printf '  %s\n' "${summary[@]}"
echo "legs: $passed passed, $failed failed"
((failed == 0))
