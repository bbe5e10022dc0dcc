#!/usr/bin/env bash
# Installs everything TransHuman-C++ needs on Debian 12 (bookworm). Idempotent: packages
# already present are skipped, and apt-get update runs only when something is missing.
set -euo pipefail

packages=(
  build-essential cmake ninja-build pkg-config git
  libtorch-dev libopenblas0-pthread libopenblas-pthread-dev
  libopencv-dev libcli11-dev libspdlog-dev libfmt-dev catch2 libyaml-cpp-dev libgloo-dev
  libzstd-dev
  clang-format-14  # the formatting check (scripts/check-format.sh)
  chromium libjs-three  # the HTML report: three.js for its 3D viewer, Chromium for its test
  libcpp-httplib-dev  # transhuman-view serves its page over HTTP
  libdnnl-dev  # oneDNN's headers: the fp32 products call the library LibTorch links directly
  nlohmann-json3-dev  # every JSON file and answer is read and written with nlohmann::json
  python3 python3-numpy python3-scipy python3-torch python3-torchvision python3-skimage python3-opencv
)
# Optional extras (fuzzing): installed only with --with-fuzz.
if [[ "${1:-}" == "--with-fuzz" ]]; then
  packages+=(clang libclang-rt-14-dev)
fi

missing=()
for p in "${packages[@]}"; do
  if ! dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed"; then
    missing+=("$p")
  fi
done

if ((${#missing[@]} == 0)); then
  echo "install-deps: all ${#packages[@]} packages present"
  exit 0
fi

echo "install-deps: installing ${missing[*]}"
SUDO=""
if [[ $(id -u) -ne 0 ]]; then SUDO="sudo"; fi
export DEBIAN_FRONTEND=noninteractive
$SUDO apt-get update -qq
$SUDO apt-get install -y -qq --no-install-recommends "${missing[@]}"
