#pragma once
// Process-wide runtime facts: which BLAS LibTorch is using, the compute device, threads.

#include <torch/types.h>

#include <string>

namespace th::runtime {

struct BlasInfo {
  std::string name;     // "OpenBLAS", "BLIS", "MKL", "reference BLAS" or "unknown"
  std::string library;  // resolved path of the loaded libblas
  std::string details;  // e.g. OpenBLAS's config string and threading model
  bool slow = false;    // true for the reference (netlib) BLAS
};

// Inspects the libraries loaded into this process (/proc/self/maps + dlsym).
BlasInfo detect_blas();
// Logs the BLAS at info level, or a loud warning for the slow reference BLAS.
void log_blas();

// glibc malloc set to serve large blocks from the heap and keep freed memory: the per-chunk
// tensors of the per-point network are tens of MB, and by default glibc maps and unmaps each
// one (every page of it faulted in again, each chunk: the page faults then cost as much as the
// arithmetic; transhuman-bench-speed measures it). The arithmetic is unchanged. TH_MALLOC=system
// keeps glibc's defaults (TH_MALLOC=keep, or unset: this); another value is a th::Error.
// Returns whether it was applied.
bool keep_freed_memory();

// What the processor offers for bf16 matrix products, from CPUID: AVX512-BF16 (dot products of
// bf16 pairs into fp32) and AMX-BF16 (tile products) execute them natively; on a processor with
// AVX-512 but neither, oneDNN emulates them with fp32 instructions (slower than fp32 itself);
// without AVX-512 LibTorch's bf16 products fall back to its reference kernels (much slower).
struct CpuBf16 {
  bool avx512 = false;       // AVX512F + BW + VL (what oneDNN's bf16 paths need)
  bool avx512_bf16 = false;  // AVX512_BF16
  bool amx_bf16 = false;     // AMX-BF16
  bool native() const { return avx512_bf16 || amx_bf16; }
  // e.g. "AVX512-BF16 and AMX-BF16", "AVX-512 without BF16 instructions", "no AVX-512"
  std::string describe() const;
};
CpuBf16 detect_cpu_bf16();

// "auto" -> CUDA when the linked LibTorch has it and a GPU is present, else CPU.
// "cuda" without CUDA is a th::Error.
torch::Device select_device(const std::string& requested);
// threads <= 0: one per core. Returns the number in effect.
int set_threads(int threads);

// How many threads at::parallel_for gives a loop of n iterations in the project's own code (its
// kernels: sampling, attention, DPaRF, culling). ATen's parallel_for is a header template that
// runs threads only where the caller is compiled with OpenMP (cmake/TransHuman.cmake): 1 means
// it is not, and the kernels run on one core whatever the thread count.
int parallel_for_threads(int64_t n);

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
