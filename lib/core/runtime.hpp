#pragma once
// Process-wide runtime facts: which BLAS LibTorch is using, the compute device, threads.

#include <torch/types.h>

#include <string>

namespace th::runtime {

struct BlasInfo {
  std::string name;       // "OpenBLAS", "BLIS", "MKL", "reference BLAS" or "unknown"
  std::string library;    // resolved path of the loaded libblas
  std::string details;    // e.g. OpenBLAS's config string and threading model
  bool slow = false;      // true for the reference (netlib) BLAS
};

// Inspects the libraries loaded into this process (/proc/self/maps + dlsym).
BlasInfo detect_blas();
// Logs the BLAS at info level, or a loud warning for the slow reference BLAS.
void log_blas();

// "auto" -> CUDA when the linked LibTorch has it and a GPU is present, else CPU.
// "cuda" without CUDA is a th::Error.
torch::Device select_device(const std::string& requested);
// threads <= 0: one per core. Returns the number in effect.
int set_threads(int threads);

// OpenBLAS keeps a thread pool of its own beside LibTorch's (found at run time with dlsym, as
// detect_blas does): its size, 0 when the loaded BLAS is not OpenBLAS.
int blas_threads();
// Sets OpenBLAS's thread count; nothing when the loaded BLAS is not OpenBLAS.
void set_blas_threads(int threads);

// LibTorch's and OpenBLAS's thread counts set to `threads` for the lifetime of the object and
// restored after (code that brings its own parallelism, e.g. the synthetic generator's workers).
class ScopedThreads {
 public:
  explicit ScopedThreads(int threads);
  ~ScopedThreads();
  ScopedThreads(const ScopedThreads&) = delete;
  ScopedThreads& operator=(const ScopedThreads&) = delete;

 private:
  int torch_, blas_;
};

}  // namespace th::runtime
