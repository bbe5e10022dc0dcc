#include "core/runtime.hpp"

#include <dlfcn.h>
#if defined(__x86_64__) || defined(__i386__)
#include <cpuid.h>
#endif
#include <ATen/Parallel.h>
#include <malloc.h>
#include <spdlog/spdlog.h>
#include <torch/cuda.h>
#include <torch/utils.h>

#include <algorithm>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <limits>
#include <mutex>
#include <set>
#include <thread>

#include "core/error.hpp"

namespace th::runtime {
namespace {

std::string loaded_library(const std::string& needle) {
  std::ifstream maps("/proc/self/maps");
  std::string line;
  while (std::getline(maps, line)) {
    const auto slash = line.find('/');
    if (slash == std::string::npos) continue;
    const std::string path = line.substr(slash);
    if (std::filesystem::path(path).filename().string().find(needle) != std::string::npos)
      return path;
  }
  return "";
}

template <class F>
F find_symbol(const char* name) {
  return reinterpret_cast<F>(dlsym(RTLD_DEFAULT, name));
}

}  // namespace

bool keep_freed_memory() {
  const char* mode = std::getenv("TH_MALLOC");
  if (mode && std::strcmp(mode, "system") == 0) return false;
  if (mode && *mode && std::strcmp(mode, "keep") != 0)
    fail("environment variable TH_MALLOC='", mode,
         "': expected 'system' (glibc defaults) or 'keep'");
#ifdef __GLIBC__
  return mallopt(M_MMAP_MAX, 0) == 1 &&
         mallopt(M_TRIM_THRESHOLD, std::numeric_limits<int>::max()) == 1;
#else
  return false;
#endif
}

BlasInfo detect_blas() {
  BlasInfo info;
  info.library = loaded_library("libblas.so");
  if (info.library.empty()) info.library = loaded_library("blas");
  std::error_code ec;
  const std::string real = std::filesystem::canonical(info.library, ec).string();
  if (!ec) info.library = real;

  if (auto get_config = find_symbol<char* (*)()>("openblas_get_config")) {
    info.name = "OpenBLAS";
    info.details = get_config();
    if (auto get_parallel = find_symbol<int (*)()>("openblas_get_parallel")) {
      static const char* models[] = {"sequential", "pthreads", "OpenMP"};
      const int p = get_parallel();
      info.details += std::string(", threading: ") + (p >= 0 && p <= 2 ? models[p] : "?");
    }
  } else if (find_symbol<void*>("bli_info_get_version_str")) {
    info.name = "BLIS";
  } else if (find_symbol<void*>("mkl_get_version")) {
    info.name = "MKL";
  } else if (info.library.find("/blas/libblas.so") != std::string::npos) {
    // Debian's netlib reference implementation, the fallback of the libblas.so.3 alternative.
    info.name = "reference BLAS";
    info.slow = true;
  } else {
    info.name = "unknown";
  }
  return info;
}

void log_blas() {
  const BlasInfo b = detect_blas();
  if (b.slow) {
    spdlog::warn(
        "!!! LibTorch is using the slow reference BLAS ({}): matrix products run 16-23x "
        "slower. Install OpenBLAS: apt-get install libopenblas0-pthread (or run "
        "scripts/install-deps.sh) !!!",
        b.library);
  } else {
    spdlog::info("BLAS: {} ({}){}", b.name, b.library.empty() ? "not loaded" : b.library,
                 b.details.empty() ? "" : " [" + b.details + "]");
  }
}

CpuBf16 detect_cpu_bf16() {
  CpuBf16 c;
#if defined(__x86_64__) || defined(__i386__)
  unsigned a = 0, b = 0, cx = 0, d = 0;
  if (__get_cpuid_count(7, 0, &a, &b, &cx, &d)) {
    const unsigned leaf1_max = a;                                // subleaves of leaf 7
    c.avx512 = (b >> 16 & 1) && (b >> 30 & 1) && (b >> 31 & 1);  // AVX512F, BW, VL
    c.amx_bf16 = d >> 22 & 1;
    if (leaf1_max >= 1 && __get_cpuid_count(7, 1, &a, &b, &cx, &d)) c.avx512_bf16 = a >> 5 & 1;
  }
#endif
  return c;
}

std::string CpuBf16::describe() const {
  if (avx512_bf16 && amx_bf16) return "AVX512-BF16 and AMX-BF16";
  if (avx512_bf16) return "AVX512-BF16";
  if (amx_bf16) return "AMX-BF16";
  return avx512 ? "AVX-512 without BF16 instructions" : "no AVX-512";
}

torch::Device select_device(const std::string& requested) {
  const bool has_cuda = torch::cuda::is_available();
  if (requested == "cpu") return torch::kCPU;
  if (requested == "cuda") {
    if (!has_cuda)
      fail(
          "device 'cuda' requested, but the linked LibTorch has no CUDA or no GPU is visible "
          "(use --device cpu or auto)");
    return torch::kCUDA;
  }
  if (requested == "auto")
    return has_cuda ? torch::Device(torch::kCUDA) : torch::Device(torch::kCPU);
  fail("unknown device '", requested, "' (expected auto, cpu or cuda)");
}

int set_threads(int threads) {
  // Debian's LibTorch starts with a single OpenMP thread when OMP_NUM_THREADS is unset, so
  // "default" means one thread per core here.
  const int cores = static_cast<int>(std::max(1u, std::thread::hardware_concurrency()));
  // More threads than this only adds scheduling overhead; 100000 would hang thread creation.
  if (threads > 8 * cores)
    fail("threads=", threads, " is more than 8 per core (this machine has ", cores, "); at most ",
         8 * cores);
  if (threads <= 0) threads = cores;
  torch::set_num_threads(threads);
  return torch::get_num_threads();
}

int blas_threads() {
  const auto get = find_symbol<int (*)()>("openblas_get_num_threads");
  return get ? get() : 0;
}

void set_blas_threads(int threads) {
  if (const auto set = find_symbol<void (*)(int)>("openblas_set_num_threads")) set(threads);
}

ScopedThreads::ScopedThreads(int threads)
    : torch_(torch::get_num_threads()), blas_(blas_threads()) {
  torch::set_num_threads(threads);
  set_blas_threads(threads);
}

ScopedThreads::~ScopedThreads() {
  torch::set_num_threads(torch_);
  if (blas_ > 0) set_blas_threads(blas_);
}

int parallel_for_threads(int64_t n) {
  std::mutex mutex;
  std::set<int> seen;
  at::parallel_for(0, n, 1, [&](int64_t, int64_t) {
    std::lock_guard<std::mutex> lock(mutex);
    seen.insert(at::get_thread_num());
  });
  return int(seen.size());
}

}  // namespace th::runtime
