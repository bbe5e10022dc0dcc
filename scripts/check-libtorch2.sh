#!/usr/bin/env bash
# Builds TransHuman-C++ against Debian 13's LibTorch (2.6) and runs the whole CTest suite, in a
# Debian 13 (trixie) root made with debootstrap on a Debian 12 host. Run as root:
#   bash scripts/check-libtorch2.sh            make or reuse the root, build, run CTest
#   bash scripts/check-libtorch2.sh --root-only  make or update the root only
#   bash scripts/check-libtorch2.sh TARGET...    build only these targets (a quicker partial
#                                                check; TH_CTEST_ARGS='-R test_model' then
#                                                picks the tests to run)
# Idempotent: the root is made once and reused (packages are only installed when missing), the
# build folder (build-libtorch2/ in the repository) is reused too. Not part of .ci/run (the
# first run downloads and installs Debian 13's packages; their size: docs/TESTING.md).
#   TH_TRIXIE_ROOT   where the root lives (default /var/cache/transhuman/trixie-root)
#   TH_DEBIAN_MIRROR the Debian mirror (default: the host's apt sources' one for its release)
#   TH_JOBS          parallel build and test jobs (default: nproc)
#   TH_CTEST_ARGS    more ctest arguments (e.g. -R test_model)
set -euo pipefail

repo=$(cd "$(dirname "$0")/.." && pwd)
root=${TH_TRIXIE_ROOT:-/var/cache/transhuman/trixie-root}
suite=trixie
jobs=${TH_JOBS:-$(nproc)}
build_dir=build-libtorch2
inside=/transhuman  # where the repository is bind-mounted in the root

log() { echo "check-libtorch2: $*"; }
die() {
  echo "check-libtorch2: $*" >&2
  exit 1
}

root_only=0
targets=()
for arg in "$@"; do
  case "$arg" in
    --root-only) root_only=1 ;;
    -*) die "unknown option '$arg' (only --root-only)" ;;
    *) targets+=(--target "$arg") ;;
  esac
done
[[ $(id -u) -eq 0 ]] || die "run as root (debootstrap, chroot and mounts need it)"

# The mirror that the host's apt sources use for the host's own release (deb822 .sources files
# and one-line .list files); nothing is hard-coded.
host_mirror() {
  local codename
  codename=$(. /etc/os-release && echo "${VERSION_CODENAME:-}")
  [[ -n $codename ]] || return 1
  local f
  for f in /etc/apt/sources.list.d/*.sources; do
    [[ -f $f ]] || continue
    awk -v want="$codename" '
      function flush() { if (uri != "" && ok) { print uri; found = 1; exit } uri = ""; ok = 0 }
      /^[[:space:]]*$/ { flush(); next }
      /^URIs:/ { uri = $2 }
      /^Suites:/ { for (i = 2; i <= NF; ++i) if ($i == want) ok = 1 }
      END { if (!found) flush() }' "$f"
  done
  for f in /etc/apt/sources.list /etc/apt/sources.list.d/*.list; do
    [[ -f $f ]] || continue
    awk -v want="$codename" '
      $1 == "deb" { i = 2; if ($2 ~ /^\[/) { while ($i !~ /\]$/) ++i; ++i }
                    if ($(i + 1) == want) print $i }' "$f"
  done
}

mirror=${TH_DEBIAN_MIRROR:-$(host_mirror | head -n 1)}
[[ -n $mirror ]] || die "no Debian mirror found in the host's apt sources; set TH_DEBIAN_MIRROR"

# The mounts live only as long as this script.
mounted=()
cleanup() {
  local i
  for ((i = ${#mounted[@]} - 1; i >= 0; --i)); do
    umount "${mounted[i]}" 2>/dev/null || umount -l "${mounted[i]}" || true
  done
}
trap cleanup EXIT

bind() {  # bind <host path> <path inside the root>
  mkdir -p "$root$2"
  mountpoint -q "$root$2" && return 0
  mount --bind "$1" "$root$2"
  mounted+=("$root$2")
}

in_root() {
  chroot "$root" /usr/bin/env -i HOME=/root LANG=C.UTF-8 TERM="${TERM:-dumb}" \
    PATH=/usr/local/sbin:/usr/local/bin:/usr/sbin:/usr/bin:/sbin:/bin \
    DEBIAN_FRONTEND=noninteractive "$@"
}

start=$(date +%s)
if [[ ! -f $root/.transhuman-root-done ]]; then
  if ! command -v debootstrap >/dev/null 2>&1; then
    log "installing debootstrap"
    apt-get update -qq
    DEBIAN_FRONTEND=noninteractive apt-get install -y -qq --no-install-recommends debootstrap
  fi
  # A root left half-made by an interrupted run is made again from scratch.
  if [[ -e $root ]]; then
    for m in $(awk -v r="$root" 'index($2, r) == 1 { print $2 }' /proc/mounts | sort -r); do
      umount -l "$m"
    done
    rm -rf --one-file-system "$root"
  fi
  mkdir -p "$(dirname "$root")"
  log "debootstrap $suite from $mirror into $root"
  debootstrap --variant=minbase "$suite" "$root" "$mirror"
  touch "$root/.transhuman-root-done"
  log "root made in $(($(date +%s) - start)) s"
fi

cp /etc/resolv.conf "$root/etc/resolv.conf"
bind /proc /proc
bind /sys /sys
bind /dev /dev
bind /dev/pts /dev/pts
bind /dev/shm /dev/shm
bind "$repo" "$inside"

# The project's own package list (install-deps.sh is idempotent: apt only for what is missing).
step=$(date +%s)
in_root bash "$inside/scripts/install-deps.sh"
log "packages ready in $(($(date +%s) - step)) s"

version=$(in_root dpkg-query -W -f='${Version}' libtorch-dev)
py_version=$(in_root python3 -c 'import torch; print(torch.__version__)')
log "Debian 13 libtorch-dev $version, python3-torch $py_version"
((root_only)) && exit 0

step=$(date +%s)
generator=() keep_going=()
if in_root sh -c 'command -v ninja' >/dev/null; then
  generator=(-G Ninja)
  keep_going=(-- -k 0)  # every compile error at once, not just the first
fi
configure_log=$root/tmp/transhuman-configure.log
if ! in_root cmake -S "$inside" -B "$inside/$build_dir" "${generator[@]}" \
  -DCMAKE_BUILD_TYPE=Release >"$configure_log" 2>&1; then
  cat "$configure_log"
  die "configuring failed"
fi
grep "LibTorch" "$configure_log" || true
in_root cmake --build "$inside/$build_dir" -j "$jobs" "${targets[@]}" "${keep_going[@]}"
log "built in $(($(date +%s) - step)) s"

step=$(date +%s)
status=0
in_root sh -c "cd '$inside/$build_dir' && OMP_NUM_THREADS=1 ctest -j '$jobs' --output-on-failure \
  --timeout 900 ${TH_CTEST_ARGS:-}" || status=$?
log "tests ran in $(($(date +%s) - step)) s (exit $status)"
log "tested LibTorch $version (Debian 13 libtorch-dev; Python torch $py_version)"
log "all in $(($(date +%s) - start)) s"
exit "$status"
