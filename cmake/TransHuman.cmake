# Shared build settings for every target of the project.

# Warnings for our code only (LibTorch and OpenCV headers are SYSTEM includes).
set(TH_WARNINGS -Wall -Wextra -Wno-unused-parameter)

# One precompiled <torch/torch.h> for the whole project: th_pch owns it, every other target
# reuses it (the flags below are identical everywhere, which REUSE_FROM requires).
add_library(th_pch STATIC ${PROJECT_SOURCE_DIR}/lib/core/pch.cpp)
# LibTorch archives and PyTorch wheels ship fmt headers of their own in their include folder,
# which would shadow the fmt that the linked spdlog was built against. Then the system fmt goes
# first, through a folder of the build tree that holds only a link to its fmt/ (a compiler
# searches /usr/include last whatever the flags say, so that folder itself cannot be put first).
set(TH_TORCH_FMT OFF)
foreach(dir ${TORCH_INCLUDE_DIRS})
  if(EXISTS "${dir}/fmt/format.h")
    set(TH_TORCH_FMT ON)
  endif()
endforeach()
if(TH_TORCH_FMT AND TARGET fmt::fmt)
  get_target_property(fmt_dirs fmt::fmt INTERFACE_INCLUDE_DIRECTORIES)
  foreach(dir ${fmt_dirs})
    if(EXISTS "${dir}/fmt/format.h")
      set(shadow "${CMAKE_BINARY_DIR}/fmt_before_libtorch")
      file(MAKE_DIRECTORY "${shadow}")
      file(REMOVE "${shadow}/fmt")
      file(CREATE_LINK "${dir}/fmt" "${shadow}/fmt" SYMBOLIC)
      target_include_directories(th_pch SYSTEM BEFORE PUBLIC "${shadow}")
      message(STATUS "LibTorch ships fmt headers: the system fmt (${dir}/fmt) is searched first")
      break()
    endif()
  endforeach()
endif()
target_include_directories(th_pch SYSTEM PUBLIC ${TORCH_INCLUDE_DIRS} ${OpenCV_INCLUDE_DIRS})
target_link_libraries(th_pch PUBLIC ${TORCH_LIBRARIES})
# ATen's at::parallel_for is a header template: in our own kernels it runs threads only when our
# code is compiled with OpenMP (without it, it runs the whole range on the calling thread).
# LibTorch's CPU builds use OpenMP; the flag travels to every target through th_pch.
find_package(OpenMP)
if(OpenMP_CXX_FOUND)
  target_link_libraries(th_pch PUBLIC OpenMP::OpenMP_CXX)
else()
  message(WARNING "OpenMP not found: the project's own CPU kernels (at::parallel_for) will run on one thread")
endif()
target_compile_options(th_pch PRIVATE ${TH_WARNINGS})
target_precompile_headers(th_pch PRIVATE <torch/torch.h>)

function(th_use_pch target)
  target_compile_options(${target} PRIVATE ${TH_WARNINGS})
  target_precompile_headers(${target} REUSE_FROM th_pch)
endfunction()

# th_library(<name> DEPS <targets...>): a library made of every .cpp in the calling folder.
function(th_library name)
  cmake_parse_arguments(ARG "" "" "DEPS" ${ARGN})
  file(GLOB sources CONFIGURE_DEPENDS ${CMAKE_CURRENT_SOURCE_DIR}/*.cpp)
  if(NOT sources)
    message(STATUS "${name}: no sources yet, skipped")
    return()
  endif()
  add_library(${name} STATIC ${sources})
  target_include_directories(${name} PUBLIC ${PROJECT_SOURCE_DIR}/lib)
  target_link_libraries(${name} PUBLIC th_pch ${ARG_DEPS})
  th_use_pch(${name})
endfunction()

# th_test(<name> DEPS <targets...>): a Catch2 executable of every .cpp in the calling folder,
# registered with CTest test by test. Tests run with the repository as working directory and
# their scratch folders under the build tree's test_tmp (tests/support/test_env.hpp).
function(th_test name)
  cmake_parse_arguments(ARG "" "" "DEPS;PROPERTIES" ${ARGN})
  file(GLOB sources CONFIGURE_DEPENDS ${CMAKE_CURRENT_SOURCE_DIR}/*.cpp)
  if(NOT sources)
    message(STATUS "${name}: no tests yet, skipped")
    return()
  endif()
  if(Catch2_VERSION VERSION_GREATER_EQUAL 3)
    # Catch2 3 (Debian 13): its own main, and the Catch2 2 header the tests include as a shim.
    add_executable(${name} ${sources})
    target_include_directories(${name} BEFORE PRIVATE ${PROJECT_SOURCE_DIR}/tests/support/catch2_v3)
    target_link_libraries(${name} PRIVATE Catch2::Catch2WithMain ${ARG_DEPS})
  else()
    add_executable(${name} ${sources} ${PROJECT_SOURCE_DIR}/tests/support/catch_main.cpp)
    target_link_libraries(${name} PRIVATE Catch2::Catch2 ${ARG_DEPS})
  endif()
  target_include_directories(${name} PRIVATE ${PROJECT_SOURCE_DIR}/tests)
  # Compiled in, not passed as CTest ENVIRONMENT: Catch2 3's catch_discover_tests flattens a
  # list-valued property (only the first variable survived). See tests/support/test_env.hpp.
  target_compile_definitions(${name} PRIVATE TH_TEST_BUILD_DIR="${CMAKE_BINARY_DIR}"
                                             TH_TEST_PYTHON="${TH_PYTHON}")
  th_use_pch(${name})
  # A CTest entry whose filter matches no test case fails instead of passing empty (a ';' in a
  # test name once split one case into two entries that ran nothing). Catch2 2: NoTests;
  # Catch2 3 names it UnmatchedTestSpec (and knows no NoTests).
  if(Catch2_VERSION VERSION_GREATER_EQUAL 3)
    set(no_empty_runs --warn UnmatchedTestSpec)
  else()
    set(no_empty_runs --warn NoTests)
  endif()
  catch_discover_tests(${name}
    WORKING_DIRECTORY ${PROJECT_SOURCE_DIR}
    TEST_PREFIX "${name}:"
    EXTRA_ARGS ${no_empty_runs}
    PROPERTIES ${ARG_PROPERTIES})
endfunction()
