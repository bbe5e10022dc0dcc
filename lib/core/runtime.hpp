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

}  // namespace th::runtime
