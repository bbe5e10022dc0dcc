#!/usr/bin/env bash
# Makes the carry bundle: everything, besides LibTorch, that a machine with only a compiler, CMake,
# Ninja and a LibTorch (a PyTorch installation) lacks to build and run TransHuman-C++. Run on a
# Debian 12 machine with the project's packages installed (scripts/install-deps.sh):
#   bash scripts/device-bundle.sh [OUT_DIR]      default OUT_DIR: build-bundle/ in the repository
# then build anywhere with
#   cmake -S . -B build -G Ninja -DTH_BUNDLE=<OUT_DIR> -DCMAKE_PREFIX_PATH=<LibTorch's prefix>
# (cmake/Bundle.cmake turns the folder into the same targets as Debian's packages give).
#
# What the bundle holds, and how every program's link is closed with static archives only:
# - OpenCV 4.6 (Debian 12's source package, fetched with `apt-get source`) built here as static
#   libraries of just the modules the project uses: core, imgproc, imgcodecs, calib3d, videoio
#   and the two calib3d needs (features2d, flann). Debian's own static OpenCV archives cannot be
#   used: imgcodecs registers every codec it was built with (GDAL, GDCM, OpenEXR, OpenJPEG, TIFF,
#   WebP) and videoio every capture backend (FFmpeg, GStreamer, DC1394, gPhoto2), so linking
#   them needs those libraries and their hundreds of dependencies, far over the carry limit.
#   This build has PNG and JPEG codecs (plus OpenCV's built-in BMP, PxM, PFM and HDR), the
#   pthreads parallel backend, no OpenCL, IPP, TBB, LAPACK or Eigen, and videoio without any
#   encoder library: cv::VideoWriter then only writes MJPG AVI files, so the free-viewpoint video
#   falls back to its PNG frames with a message (lib/video/frame_writer.cpp), as on any OpenCV
#   without FFmpeg.
# - Debian's static archives of the libraries those codecs and the project link: libpng16.a,
#   libjpeg.a (libjpeg-turbo), libz.a, libyaml-cpp.a, with their headers.
# - Header-only libraries: spdlog and fmt (used header-only: FMT_HEADER_ONLY; Debian's spdlog
#   already takes the external fmt), CLI11, nlohmann-json, cpp-httplib (the single header of
#   Debian's source package, used without TLS or compression: the viewer serves plain HTTP),
#   Catch2 2 with its CTest discovery scripts, and Gloo's headers (a PyTorch installation's
#   LibTorch has Gloo inside libtorch_cpu but ships no Gloo headers, which c10d's headers need).
# Nothing in the bundle is a shared library: the executables need at run time only LibTorch's
# libraries, the C/C++ runtime and glibc, which every machine with PyTorch has.
#
# Environment:
#   TH_BUNDLE_WORK  where sources are fetched and OpenCV is built (default
#                   /var/cache/transhuman/device-bundle; reused by the next run)
#   TH_JOBS         parallel compile jobs (default: nproc)
#   TH_BUILD_LOCK   a file to `flock` around each compile step (for machines shared by builds)
# Needs: the packages of scripts/install-deps.sh, cmake, ninja, xz-utils, and apt access to
# Debian's source packages (the host's mirror; TH_DEBIAN_MIRROR overrides it).
set -euo pipefail

repo=$(cd "$(dirname "$0")/.." && pwd)
out=${1:-$repo/build-bundle}
work=${TH_BUNDLE_WORK:-/var/cache/transhuman/device-bundle}
jobs=${TH_JOBS:-$(nproc)}
lock=${TH_BUILD_LOCK:-}

log() { echo "device-bundle: $*" >&2; }
die() {
  echo "device-bundle: $*" >&2
  exit 1
}

(($# <= 1)) || die "usage: scripts/device-bundle.sh [OUT_DIR]"
case "$out" in
  /*) ;;
  *) out=$PWD/$out ;;
esac

# A compile step, under the lock when one is named, at a lower priority.
build() {
  if [[ -n $lock ]]; then
    flock "$lock" nice -n 5 "$@"
  else
    nice -n 5 "$@"
  fi
}

arch=$(gcc -print-multiarch 2>/dev/null || echo x86_64-linux-gnu)
libdir=/usr/lib/$arch

# What the host must have, with the Debian package that brings it.
missing=()
need() {  # need <path> <package>
  [[ -e $1 ]] || missing+=("$2 ($1)")
}
need /usr/include/yaml-cpp/yaml.h libyaml-cpp-dev
need "$libdir/libyaml-cpp.a" libyaml-cpp-dev
need /usr/include/spdlog/spdlog.h libspdlog-dev
need /usr/include/fmt/format-inl.h libfmt-dev
need /usr/include/CLI/CLI.hpp libcli11-dev
need /usr/include/nlohmann/json.hpp nlohmann-json3-dev
need /usr/include/catch2/catch.hpp catch2
need /usr/lib/cmake/Catch2/Catch.cmake catch2
need /usr/include/gloo/context.h libgloo-dev
need /usr/include/zlib.h zlib1g-dev
need "$libdir/libz.a" zlib1g-dev
need /usr/include/png.h libpng-dev
need "$libdir/libpng16.a" libpng-dev
need /usr/include/jpeglib.h libjpeg62-turbo-dev
need "$libdir/libjpeg.a" libjpeg62-turbo-dev
for tool in cmake ninja g++ xz apt-get; do
  command -v "$tool" >/dev/null 2>&1 || missing+=("$tool")
done
((${#missing[@]} == 0)) || die "missing on this machine: ${missing[*]} (bash scripts/install-deps.sh installs the packages)"

# The mirror that the host's apt sources use for its own release (as scripts/check-libtorch2.sh).
host_mirror() {
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

# Debian source packages, fetched with apt-get through a private source list (the host's apt
# configuration is left alone).
mkdir -p "$work/src"
apt_src=()
source_package() {  # source_package <name>: its orig tarball, downloaded once
  local name=$1 tarball
  tarball=$(find "$work/src" -maxdepth 1 -name "${name}_*.orig.tar.*" | sort | tail -n 1)
  if [[ -z $tarball ]]; then
    if ((${#apt_src[@]} == 0)); then
      local mirror codename
      mirror=${TH_DEBIAN_MIRROR:-$(host_mirror | head -n 1)}
      [[ -n $mirror ]] || die "no Debian mirror found in the host's apt sources; set TH_DEBIAN_MIRROR"
      codename=$(. /etc/os-release && echo "$VERSION_CODENAME")
      mkdir -p "$work/apt/lists/partial"
      echo "deb-src $mirror $codename main" >"$work/apt/sources.list"
      apt_src=(-o "Dir::Etc::SourceList=$work/apt/sources.list" -o Dir::Etc::SourceParts=/dev/null
        -o "Dir::State::Lists=$work/apt/lists")
      log "apt-get update (deb-src $mirror $codename)"
      apt-get "${apt_src[@]}" update -qq >&2
    fi
    log "fetching the source package $name"
    (cd "$work/src" && apt-get "${apt_src[@]}" source --download-only -qq "$name" 2>&1 |
      grep -v "unsandboxed" >&2 || true)
    tarball=$(find "$work/src" -maxdepth 1 -name "${name}_*.orig.tar.*" ! -name "*-contrib*" |
      sort | tail -n 1)
    [[ -n $tarball ]] || die "apt-get source $name gave no orig tarball"
  fi
  echo "$tarball"
}

# --- OpenCV: the project's modules only, static ---------------------------------------------
opencv_tar=$(source_package opencv)
opencv_src=$work/opencv-src
opencv_build=$work/opencv-build
opencv_prefix=$work/opencv-install
if [[ ! -f $opencv_src/modules/core/CMakeLists.txt ]]; then
  log "unpacking $(basename "$opencv_tar")"
  rm -rf "$opencv_src" && mkdir -p "$opencv_src"
  tar -xf "$opencv_tar" -C "$opencv_src" --strip-components=1
fi
opencv_modules=(core imgproc imgcodecs calib3d videoio features2d flann)
if [[ ! -f $opencv_build/build.ninja ]]; then
  log "configuring OpenCV ($(
    IFS=,
    echo "${opencv_modules[*]}"
  ))"
  off=()
  for w in IPP ITT TBB OPENMP OPENCL VA VA_INTEL LAPACK EIGEN CUDA OPENVX PROTOBUF QUIRC ADE \
    FFMPEG GSTREAMER V4L 1394 GPHOTO2 AVFOUNDATION MSMF DSHOW XINE OPENNI OPENNI2 PVAPI ARAVIS \
    XIMEA UEYE LIBREALSENSE GTK QT VTK OPENGL WIN32UI TIFF WEBP OPENJPEG JASPER OPENEXR GDAL GDCM \
    SPNG CAROTENE HALIDE VULKAN ONNX TIMVX CLP IMGCODEC_SUNRASTER; do
    off+=("-DWITH_$w=OFF")
  done
  build cmake -S "$opencv_src" -B "$opencv_build" -G Ninja -Wno-dev \
    -DCMAKE_BUILD_TYPE=Release -DCMAKE_INSTALL_PREFIX="$opencv_prefix" \
    -DCMAKE_POSITION_INDEPENDENT_CODE=ON -DBUILD_SHARED_LIBS=OFF \
    -DBUILD_LIST="$(
      IFS=,
      echo "${opencv_modules[*]}"
    )" \
    -DCPU_BASELINE=SSE3 -DCPU_DISPATCH="SSE4_1;AVX;AVX2" \
    -DBUILD_TESTS=OFF -DBUILD_PERF_TESTS=OFF -DBUILD_EXAMPLES=OFF -DBUILD_opencv_apps=OFF \
    -DBUILD_DOCS=OFF -DBUILD_JAVA=OFF -DBUILD_opencv_python3=OFF -DBUILD_opencv_python2=OFF \
    -DBUILD_ZLIB=OFF -DBUILD_PNG=OFF -DBUILD_JPEG=OFF -DBUILD_ITT=OFF -DBUILD_IPP_IW=OFF \
    -DWITH_PNG=ON -DWITH_JPEG=ON -DWITH_PTHREADS_PF=ON -DVIDEOIO_ENABLE_PLUGINS=OFF \
    -DHIGHGUI_ENABLE_PLUGINS=OFF -DCV_TRACE=OFF -DOPENCV_GENERATE_PKGCONFIG=OFF \
    -DOPENCV_ENABLE_NONFREE=OFF -DENABLE_PRECOMPILED_HEADERS=OFF -DINSTALL_CREATE_DISTRIB=OFF \
    -DZLIB_LIBRARY="$libdir/libz.a" -DZLIB_INCLUDE_DIR=/usr/include \
    -DPNG_LIBRARY="$libdir/libpng16.a" -DPNG_PNG_INCLUDE_DIR=/usr/include \
    -DJPEG_LIBRARY="$libdir/libjpeg.a" -DJPEG_INCLUDE_DIR=/usr/include \
    "${off[@]}" >"$work/opencv-configure.log" 2>&1 ||
    {
      tail -n 40 "$work/opencv-configure.log"
      die "configuring OpenCV failed (whole log: $work/opencv-configure.log)"
    }
fi
# One module per step: a shared lock is held for minutes, not for the whole build.
for m in "${opencv_modules[@]}"; do
  log "building opencv_$m"
  build ninja -C "$opencv_build" -j "$jobs" "opencv_$m" >"$work/opencv-build-$m.log" 2>&1 ||
    {
      tail -n 40 "$work/opencv-build-$m.log"
      die "building opencv_$m failed (whole log: $work/opencv-build-$m.log)"
    }
done
build ninja -C "$opencv_build" install >"$work/opencv-install.log" 2>&1 ||
  die "installing OpenCV failed ($work/opencv-install.log)"
opencv_version=$(sed -n 's/^#define CV_VERSION_\(MAJOR\|MINOR\|REVISION\) *\([0-9]*\).*/\2/p' \
  "$opencv_prefix/include/opencv4/opencv2/core/version.hpp" | paste -sd.)

# --- cpp-httplib: the single header of the source package ---------------------------------
httplib_tar=$(source_package cpp-httplib)
httplib_src=$work/httplib-src
if [[ ! -f $httplib_src/httplib.h ]]; then
  rm -rf "$httplib_src" && mkdir -p "$httplib_src"
  tar -xf "$httplib_tar" -C "$httplib_src" --strip-components=1
fi
[[ -f $httplib_src/httplib.h ]] || die "no httplib.h in $(basename "$httplib_tar")"
grep -q "inline void Server::stop" "$httplib_src/httplib.h" ||
  die "$httplib_src/httplib.h is not the single-file (header-only) cpp-httplib"

# --- The bundle ------------------------------------------------------------------------------
log "assembling $out"
rm -rf "$out"
mkdir -p "$out/include/opencv4" "$out/lib/pkgconfig" "$out/cmake" "$out/licenses"
cp -r "$opencv_prefix/include/opencv4/opencv2" "$out/include/opencv4/"
for m in "${opencv_modules[@]}"; do
  cp "$opencv_prefix/lib/libopencv_$m.a" "$out/lib/"
done
cp "$libdir/libpng16.a" "$libdir/libjpeg.a" "$libdir/libz.a" "$libdir/libyaml-cpp.a" "$out/lib/"
strip --strip-unneeded "$out"/lib/*.a  # local symbols and debug information
cp /usr/include/zlib.h /usr/include/zconf.h "$out/include/"
cp -r /usr/include/yaml-cpp /usr/include/spdlog /usr/include/fmt /usr/include/CLI \
  /usr/include/nlohmann /usr/include/gloo "$out/include/"
mkdir -p "$out/include/catch2"
cp /usr/include/catch2/catch.hpp "$out/include/catch2/"
cp /usr/lib/cmake/Catch2/Catch.cmake /usr/lib/cmake/Catch2/CatchAddTests.cmake "$out/cmake/"
cp "$httplib_src/httplib.h" "$out/include/"
# Relocatable: pkg-config resolves ${pcfiledir} to this file's folder.
httplib_version=$(sed -n 's/^#define CPPHTTPLIB_VERSION "\(.*\)"/\1/p' "$httplib_src/httplib.h")
cat >"$out/lib/pkgconfig/cpp-httplib.pc" <<EOF
prefix=\${pcfiledir}/../..
includedir=\${prefix}/include

Name: cpp-httplib
Description: A C++ HTTP server and client library (header-only, plain HTTP)
Version: ${httplib_version:-0}
Libs: -pthread
Cflags: -I\${includedir}
EOF

# Versions (cmake/Bundle.cmake reports them as the packages' versions) and provenance.
pkg_version() { dpkg-query -W -f='${Version}' "$1" 2>/dev/null || echo unknown; }
upstream() { pkg_version "$1" | sed 's/^[0-9]*://; s/[+~-].*//'; }
cat >"$out/versions.cmake" <<EOF
# Written by scripts/device-bundle.sh; read by cmake/Bundle.cmake.
set(TH_BUNDLE_OPENCV_VERSION "$opencv_version")
set(TH_BUNDLE_OPENCV_MODULES "${opencv_modules[*]}")
set(TH_BUNDLE_YAML_CPP_VERSION "$(upstream libyaml-cpp-dev)")
set(TH_BUNDLE_SPDLOG_VERSION "$(upstream libspdlog-dev)")
set(TH_BUNDLE_FMT_VERSION "$(upstream libfmt-dev)")
set(TH_BUNDLE_CLI11_VERSION "$(upstream libcli11-dev)")
set(TH_BUNDLE_NLOHMANN_JSON_VERSION "$(upstream nlohmann-json3-dev)")
set(TH_BUNDLE_CATCH2_VERSION "$(upstream catch2)")
set(TH_BUNDLE_ZLIB_VERSION "$(sed -n 's/^#define ZLIB_VERSION "\(.*\)"/\1/p' /usr/include/zlib.h)")
set(TH_BUNDLE_HTTPLIB_VERSION "${httplib_version:-0}")
EOF
{
  echo "TransHuman-C++ carry bundle, made $(date -u +%Y-%m-%d) by scripts/device-bundle.sh on" \
    "$(. /etc/os-release && echo "$PRETTY_NAME") ($(uname -m))"
  echo
  echo "opencv (source $(basename "$opencv_tar")): static, modules ${opencv_modules[*]}"
  echo "cpp-httplib (source $(basename "$httplib_tar")): httplib.h"
  for p in libyaml-cpp-dev libspdlog-dev libfmt-dev libcli11-dev nlohmann-json3-dev catch2 \
    libgloo-dev zlib1g-dev libpng-dev libjpeg62-turbo-dev; do
    echo "$p $(pkg_version "$p")"
  done
  echo
  (cd "$out" && find . -type f ! -path "./include/*" ! -path "./licenses/*" | sort |
    xargs du -k | awk '{ printf "%8d KiB  %s\n", $1, $2 }')
} >"$out/MANIFEST.txt"
for p in libyaml-cpp-dev libspdlog-dev libfmt-dev libcli11-dev nlohmann-json3-dev catch2 \
  libgloo-dev zlib1g-dev libpng-dev libjpeg62-turbo-dev; do
  [[ -f /usr/share/doc/$p/copyright ]] && cp "/usr/share/doc/$p/copyright" "$out/licenses/$p"
done
cp "$opencv_src/LICENSE" "$out/licenses/opencv"
[[ -f $httplib_src/LICENSE ]] && cp "$httplib_src/LICENSE" "$out/licenses/cpp-httplib"

log "OpenCV $opencv_version (${opencv_modules[*]}), cpp-httplib ${httplib_version:-?}"
log "$(du -sh "$out" | cut -f1) in $out"
