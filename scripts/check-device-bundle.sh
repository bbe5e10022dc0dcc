#!/usr/bin/env bash
# Proves a carry bundle (scripts/device-bundle.sh) complete: builds the project against the
# bundle alone and runs its tests on the CPU, in a Debian 12 root that has a compiler, CMake,
# Ninja, pkg-config, Debian's CPU LibTorch (libtorch-dev, standing in for a PyTorch
# installation's LibTorch) with what libtorch-dev itself pulls in, and the Python modules of the
# tests' reference scripts, but no -dev package of the
# bundle's libraries (the script stops when it finds one). The build and the tests are
# scripts/device-run.sh's, run with DEVICE=cpu (the same targets; the CUDA phases on the CPU with
# shortened workloads; the CPU tests). Run as root on a Debian 12 machine:
#   bash scripts/check-device-bundle.sh [BUNDLE_DIR]      default BUNDLE_DIR: build-bundle/
# Environment:
#   TH_BUNDLE_ROOT    where the root lives (default /var/cache/transhuman/bundle-root)
#   TH_DEBIAN_MIRROR  the Debian mirror (default: the host's apt sources' one for its release)
#   TH_JOBS           build and test jobs (default: nproc)
#   TH_BUILD_LOCK     a file to `flock` around the build (for machines shared by builds)
#   TH_BUDGET_S       device-run.sh's budget (default 3600: a CPU build takes long)
# The root is made once and reused; the repository and the bundle are bind-mounted into it, the
# build goes to build-bundle-check/ in the repository and device-run.sh's outputs to
# build-bundle-check/out/. Not part of .ci/run.
set -euo pipefail

repo=$(cd "$(dirname "$0")/.." && pwd)
bundle=${1:-$repo/build-bundle}
case "$bundle" in /*) ;; *) bundle=$PWD/$bundle ;; esac
root=${TH_BUNDLE_ROOT:-/var/cache/transhuman/bundle-root}
jobs=${TH_JOBS:-$(nproc)}
inside=/transhuman  # the repository inside the root
inside_bundle=/transhuman-bundle

log() { echo "check-device-bundle: $*"; }
die() {
  echo "check-device-bundle: $*" >&2
  exit 1
}
[[ $(id -u) -eq 0 ]] || die "run as root (debootstrap, chroot and mounts need it)"
[[ -f $bundle/versions.cmake ]] || die "$bundle is not a bundle: make it with scripts/device-bundle.sh"

host_mirror() {  # the host's apt sources' mirror for its own release (as check-libtorch2.sh)
  local codename f
  codename=$(. /etc/os-release && echo "${VERSION_CODENAME:-}")
  [[ -n $codename ]] || return 1
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
  command -v debootstrap >/dev/null 2>&1 || {
    apt-get update -qq
    DEBIAN_FRONTEND=noninteractive apt-get install -y -qq --no-install-recommends debootstrap
  }
  mirror=${TH_DEBIAN_MIRROR:-$(host_mirror | head -n 1)}
  [[ -n $mirror ]] || die "no Debian mirror found in the host's apt sources; set TH_DEBIAN_MIRROR"
  if [[ -e $root ]]; then  # a root left half-made is made again
    for m in $(awk -v r="$root" 'index($2, r) == 1 { print $2 }' /proc/mounts | sort -r); do
      umount -l "$m"
    done
    rm -rf --one-file-system "$root"
  fi
  suite=$(. /etc/os-release && echo "$VERSION_CODENAME")
  log "debootstrap $suite from $mirror into $root"
  mkdir -p "$(dirname "$root")"
  debootstrap --variant=minbase "$suite" "$root" "$mirror"
  touch "$root/.transhuman-root-done"
fi
cp /etc/resolv.conf "$root/etc/resolv.conf"
bind /proc /proc
bind /sys /sys
bind /dev /dev
bind /dev/pts /dev/pts
bind "$repo" "$inside"
bind "$bundle" "$inside_bundle"

packages=(build-essential cmake ninja-build pkg-config libtorch-dev
  # the tests' reference scripts (docs/TESTING.md): Python modules, no -dev package
  python3-numpy python3-scipy python3-torch python3-torchvision python3-skimage python3-opencv)
if ! in_root dpkg -s "${packages[@]}" >/dev/null 2>&1; then
  log "installing ${packages[*]} into the root"
  in_root apt-get update -qq
  in_root apt-get install -y -qq --no-install-recommends "${packages[@]}"
fi

# The proof's premise: none of the bundle's libraries as a Debian -dev package (their runtime
# libraries may be there: Debian's libtorch1.13 links OpenCV's; the executables built here link
# the bundle's static archives, which device-run.sh checks with ldd).
log "packages of the root that match opencv|yaml|spdlog|fmt|cli11|nlohmann|httplib|catch|gloo:"
in_root dpkg-query -W -f='${db:Status-Abbrev} ${Package} ${Version}\n' |
  grep -E '^ii .*(opencv|yaml|spdlog|fmt|cli11|nlohmann|httplib|catch|gloo)' | sed 's/^/  /' || true
dev=$(in_root dpkg-query -W -f='${db:Status-Abbrev} ${Package}\n' |
  awk '$1 == "ii" { print $2 }' |
  grep -E '(opencv|yaml-cpp|spdlog|fmt|cli11|nlohmann|httplib|catch2|gloo|libpng|libjpeg).*-dev|^catch2$' || true)
[[ -z $dev ]] || die "the root has -dev packages of the bundle's libraries: $dev"
[[ ! -e $root/usr/include/opencv4 && ! -e $root/usr/include/yaml-cpp && ! -e $root/usr/include/spdlog &&
  ! -e $root/usr/include/CLI && ! -e $root/usr/include/nlohmann && ! -e $root/usr/include/catch2 &&
  ! -e $root/usr/include/gloo ]] || die "the root has headers of the bundle's libraries in /usr/include"
log "none of them is a -dev package; zlib1g-dev $(in_root dpkg-query -W -f='${Version}' zlib1g-dev 2>/dev/null || echo absent) comes with libtorch-dev (the build takes the bundle's zlib)"

lock_env=()
if [[ -n ${TH_BUILD_LOCK:-} ]]; then  # the same lock file inside the root
  touch "$TH_BUILD_LOCK"
  mkdir -p "$root/run/transhuman"
  touch "$root/run/transhuman/build.lock"
  mountpoint -q "$root/run/transhuman/build.lock" || {
    mount --bind "$TH_BUILD_LOCK" "$root/run/transhuman/build.lock"
    mounted+=("$root/run/transhuman/build.lock")
  }
  lock_env=(TH_BUILD_LOCK=/run/transhuman/build.lock)
fi
status=0
chroot "$root" /usr/bin/env -i HOME=/root LANG=C.UTF-8 \
  PATH=/usr/local/sbin:/usr/local/bin:/usr/sbin:/usr/bin:/sbin:/bin \
  DEVICE=cpu TH_BUNDLE="$inside_bundle" TH_BUILD_DIR=build-bundle-check "${lock_env[@]}" \
  OUT=$inside/build-bundle-check/out TH_JOBS="$jobs" TH_BUDGET_S="${TH_BUDGET_S:-3600}" \
  bash -c "cd $inside && bash scripts/device-run.sh" || status=$?
log "device-run.sh (DEVICE=cpu) exit $status; its summary:"
cat "$repo/build-bundle-check/out/summary.md" || true
log "all in $(($(date +%s) - start)) s"
exit "$status"
