#pragma once
// The one place where the sources look at the LibTorch version: Debian 12's 1.13 and 2.x
// (Debian 13's 2.6, the official archives, the LibTorch inside a PyTorch installation) build
// from the same code through the names below. Nothing else tests TORCH_VERSION_*.

#include <ATen/autocast_mode.h>
#include <c10/core/Allocator.h>
#include <torch/version.h>

#if TORCH_VERSION_MAJOR >= 2
#include <torch/csrc/distributed/c10d/Backend.hpp>
#else
#include <torch/csrc/distributed/c10d/ProcessGroup.hpp>
#endif

namespace th::compat {

// What a c10d collective runs on. In 1.13 ProcessGroupGloo and ProcessGroupNCCL are
// c10d::ProcessGroups; from 2.0 on they are c10d::Backends (a ProcessGroup became a dispatcher
// over Backends), with the same broadcast/allreduce/barrier calls.
#if TORCH_VERSION_MAJOR >= 2
using CollectiveGroup = c10d::Backend;
#else
using CollectiveGroup = c10d::ProcessGroup;
#endif

// The type of the totals that c10's allocator reports to a MemoryReportingInfoBase (int64_t in
// 1.13, size_t in 2.x), read from the declaration itself rather than from a version number.
namespace detail {
template <class F>
struct third_argument;
template <class C, class R, class A1, class A2, class A3, class A4, class A5>
struct third_argument<R (C::*)(A1, A2, A3, A4, A5)> {
  using type = A3;
};
}  // namespace detail
using MemoryTotal =
    detail::third_argument<decltype(&c10::MemoryReportingInfoBase::reportMemoryUsage)>::type;

// c10d's TCPStore: from 2.x on its options ask for the libuv backend by default, which builds
// without libuv (Debian 13's 2.6) refuse at rendezvous; the classic backend works everywhere.
// Detected from the member itself (1.13 has none).
template <class Options>
auto use_classic_tcpstore(Options& options, int) -> decltype(options.useLibUV = false, void()) {
  options.useLibUV = false;
}
template <class Options>
void use_classic_tcpstore(Options&, long) {}

// Autocast state per device type. 2.4 moved it to functions taking the device type (the
// per-device names of 1.13 are deprecated there).
#if TORCH_VERSION_MAJOR > 2 || (TORCH_VERSION_MAJOR == 2 && TORCH_VERSION_MINOR >= 4)
inline bool autocast_enabled(bool cuda) {
  return at::autocast::is_autocast_enabled(cuda ? at::kCUDA : at::kCPU);
}
inline void set_autocast_enabled(bool cuda, bool on) {
  at::autocast::set_autocast_enabled(cuda ? at::kCUDA : at::kCPU, on);
}
inline at::ScalarType autocast_dtype(bool cuda) {
  return at::autocast::get_autocast_dtype(cuda ? at::kCUDA : at::kCPU);
}
inline void set_autocast_dtype(bool cuda, at::ScalarType t) {
  at::autocast::set_autocast_dtype(cuda ? at::kCUDA : at::kCPU, t);
}
#else
inline bool autocast_enabled(bool cuda) {
  return cuda ? at::autocast::is_enabled() : at::autocast::is_cpu_enabled();
}
inline void set_autocast_enabled(bool cuda, bool on) {
  if (cuda)
    at::autocast::set_enabled(on);
  else
    at::autocast::set_cpu_enabled(on);
}
inline at::ScalarType autocast_dtype(bool cuda) {
  return cuda ? at::autocast::get_autocast_gpu_dtype() : at::autocast::get_autocast_cpu_dtype();
}
inline void set_autocast_dtype(bool cuda, at::ScalarType t) {
  if (cuda)
    at::autocast::set_autocast_gpu_dtype(t);
  else
    at::autocast::set_autocast_cpu_dtype(t);
}
#endif

}  // namespace th::compat
