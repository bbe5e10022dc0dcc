# -DTH_BUNDLE=<dir>: take OpenCV, yaml-cpp, spdlog/fmt, CLI11, nlohmann-json, zlib, Catch2,
# cpp-httplib and Gloo's headers from a carry bundle made by scripts/device-bundle.sh instead of
# the system's packages (docs/BUILDING.md, "Building for a CUDA machine with the carry bundle").
# Defines the targets and variables that Debian's packages give (opencv_* in OpenCV_LIBS,
# OpenCV_INCLUDE_DIRS, CLI11::CLI11, spdlog::spdlog, fmt::fmt, yaml-cpp,
# nlohmann_json::nlohmann_json, ZLIB::ZLIB, Catch2::Catch2 and its Catch.cmake), and points each
# package's find_package() at a small config file that only reports the bundle's version, so the
# rest of the build is the same with or without a bundle. Without TH_BUNDLE nothing changes.
set(TH_BUNDLE "" CACHE PATH "carry bundle made by scripts/device-bundle.sh (empty: system packages)")
if(NOT TH_BUNDLE)
  return()
endif()
get_filename_component(TH_BUNDLE "${TH_BUNDLE}" ABSOLUTE)
if(NOT EXISTS "${TH_BUNDLE}/versions.cmake")
  message(FATAL_ERROR "TH_BUNDLE=${TH_BUNDLE} is not a bundle (no versions.cmake): make one with "
                      "scripts/device-bundle.sh")
endif()
include("${TH_BUNDLE}/versions.cmake")
set(_th_inc "${TH_BUNDLE}/include")
set(_th_lib "${TH_BUNDLE}/lib")

find_package(Threads REQUIRED)
# zlib: CMake's FindZLIB, pointed at the bundle's static archive.
set(ZLIB_INCLUDE_DIR "${_th_inc}" CACHE PATH "zlib headers" FORCE)
set(ZLIB_LIBRARY "${_th_lib}/libz.a" CACHE FILEPATH "zlib" FORCE)
find_package(ZLIB REQUIRED)

function(_th_bundle_static target file)  # _th_bundle_static(<target> <archive> DEPS... INCLUDES...)
  cmake_parse_arguments(ARG "" "" "DEPS;INCLUDES" ${ARGN})
  if(NOT EXISTS "${_th_lib}/${file}")
    message(FATAL_ERROR "the bundle ${TH_BUNDLE} has no lib/${file}: make it again with scripts/device-bundle.sh")
  endif()
  add_library(${target} STATIC IMPORTED GLOBAL)
  set_target_properties(${target} PROPERTIES IMPORTED_LOCATION "${_th_lib}/${file}"
                                             INTERFACE_LINK_LIBRARIES "${ARG_DEPS}"
                                             INTERFACE_INCLUDE_DIRECTORIES "${ARG_INCLUDES}")
endfunction()

function(_th_bundle_headers target)  # _th_bundle_headers(<target> [DEFINITIONS...] [DEPS...])
  cmake_parse_arguments(ARG "" "" "DEFINITIONS;DEPS" ${ARGN})
  add_library(${target} INTERFACE IMPORTED GLOBAL)
  set_target_properties(${target} PROPERTIES INTERFACE_INCLUDE_DIRECTORIES "${_th_inc}"
                                             INTERFACE_COMPILE_DEFINITIONS "${ARG_DEFINITIONS}"
                                             INTERFACE_LINK_LIBRARIES "${ARG_DEPS}")
endfunction()

# find_package(<name> [version]) then finds <build>/th_bundle/<name>/, whose config file reports
# the bundle's version and runs <body>.
function(_th_bundle_package name version body)
  set(dir "${CMAKE_BINARY_DIR}/th_bundle/${name}")
  file(MAKE_DIRECTORY "${dir}")
  file(WRITE "${dir}/${name}Config.cmake" "# Written by cmake/Bundle.cmake.\n${body}\n")
  file(WRITE "${dir}/${name}ConfigVersion.cmake"
       "set(PACKAGE_VERSION \"${version}\")\n"
       "if(PACKAGE_FIND_VERSION AND PACKAGE_VERSION VERSION_LESS PACKAGE_FIND_VERSION)\n"
       "  set(PACKAGE_VERSION_COMPATIBLE FALSE)\n"
       "else()\n"
       "  set(PACKAGE_VERSION_COMPATIBLE TRUE)\n"
       "endif()\n")
  set(${name}_DIR "${dir}" CACHE PATH "${name} from the carry bundle" FORCE)
endfunction()

# OpenCV: static modules, listed users before what they use.
_th_bundle_static(opencv_core libopencv_core.a INCLUDES "${_th_inc}/opencv4"
                  DEPS ZLIB::ZLIB Threads::Threads ${CMAKE_DL_LIBS} m)
_th_bundle_static(opencv_imgproc libopencv_imgproc.a DEPS opencv_core)
_th_bundle_static(opencv_flann libopencv_flann.a DEPS opencv_core)
_th_bundle_static(opencv_features2d libopencv_features2d.a DEPS opencv_imgproc opencv_flann)
_th_bundle_static(opencv_calib3d libopencv_calib3d.a DEPS opencv_features2d opencv_flann opencv_imgproc)
_th_bundle_static(th_bundle_png libpng16.a DEPS ZLIB::ZLIB m)
_th_bundle_static(th_bundle_jpeg libjpeg.a)
_th_bundle_static(opencv_imgcodecs libopencv_imgcodecs.a DEPS opencv_imgproc th_bundle_png th_bundle_jpeg)
_th_bundle_static(opencv_videoio libopencv_videoio.a DEPS opencv_imgcodecs opencv_imgproc)
set(_th_cv_modules ${TH_BUNDLE_OPENCV_MODULES})
string(REPLACE ";" " " _th_cv_list "${_th_cv_modules}")
_th_bundle_package(OpenCV "${TH_BUNDLE_OPENCV_VERSION}" "
set(OpenCV_INCLUDE_DIRS \"${_th_inc}/opencv4\")
set(OpenCV_LIBS)
foreach(c \${OpenCV_FIND_COMPONENTS})
  if(NOT \" ${_th_cv_list} \" MATCHES \" \${c} \")
    set(OpenCV_FOUND FALSE)
    set(OpenCV_NOT_FOUND_MESSAGE \"the carry bundle's OpenCV has no module \${c} (only ${_th_cv_list})\")
    return()
  endif()
  list(APPEND OpenCV_LIBS opencv_\${c})
endforeach()
if(NOT OpenCV_LIBS)
  foreach(c ${_th_cv_list})
    list(APPEND OpenCV_LIBS opencv_\${c})
  endforeach()
endif()")

# yaml-cpp: Debian's static archive, under the target name its package uses.
_th_bundle_static(yaml-cpp libyaml-cpp.a INCLUDES "${_th_inc}")
_th_bundle_package(yaml-cpp "${TH_BUNDLE_YAML_CPP_VERSION}" "")

# spdlog and fmt, header-only (Debian's spdlog headers take the external fmt).
_th_bundle_headers(fmt::fmt DEFINITIONS FMT_HEADER_ONLY=1)
_th_bundle_headers(spdlog::spdlog DEFINITIONS SPDLOG_FMT_EXTERNAL DEPS fmt::fmt Threads::Threads)
_th_bundle_package(fmt "${TH_BUNDLE_FMT_VERSION}" "")
_th_bundle_package(spdlog "${TH_BUNDLE_SPDLOG_VERSION}" "")

_th_bundle_headers(CLI11::CLI11)
_th_bundle_package(CLI11 "${TH_BUNDLE_CLI11_VERSION}" "")
_th_bundle_headers(nlohmann_json::nlohmann_json)
_th_bundle_package(nlohmann_json "${TH_BUNDLE_NLOHMANN_JSON_VERSION}" "")

# Catch2 2: the single header, and Catch.cmake (catch_discover_tests) on the module path.
_th_bundle_headers(Catch2::Catch2)
_th_bundle_package(Catch2 "${TH_BUNDLE_CATCH2_VERSION}" "")
list(APPEND CMAKE_MODULE_PATH "${TH_BUNDLE}/cmake")

# cpp-httplib (lib/viewer asks pkg-config): the bundle's relocatable cpp-httplib.pc goes first.
set(ENV{PKG_CONFIG_PATH} "${_th_lib}/pkgconfig:$ENV{PKG_CONFIG_PATH}")

# Gloo's headers (c10d's headers include them) are in ${_th_inc}, which every target has through
# spdlog::spdlog.
message(STATUS "Carry bundle ${TH_BUNDLE}: OpenCV ${TH_BUNDLE_OPENCV_VERSION} (static: ${_th_cv_list}), "
               "yaml-cpp ${TH_BUNDLE_YAML_CPP_VERSION}, spdlog ${TH_BUNDLE_SPDLOG_VERSION} + fmt "
               "${TH_BUNDLE_FMT_VERSION} (header-only), CLI11 ${TH_BUNDLE_CLI11_VERSION}, "
               "nlohmann-json ${TH_BUNDLE_NLOHMANN_JSON_VERSION}, zlib ${TH_BUNDLE_ZLIB_VERSION}, "
               "Catch2 ${TH_BUNDLE_CATCH2_VERSION}, cpp-httplib ${TH_BUNDLE_HTTPLIB_VERSION}")
