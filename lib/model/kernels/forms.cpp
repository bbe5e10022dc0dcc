#include "model/kernels/forms.hpp"

namespace th::model::kernels {

namespace {
thread_local bool libtorch_forms = false;
}  // namespace

bool cpu_kernels(const c10::Device& device) { return device.is_cpu() && !libtorch_forms; }

LibTorchForms::LibTorchForms() : previous_(libtorch_forms) { libtorch_forms = true; }

LibTorchForms::~LibTorchForms() { libtorch_forms = previous_; }

}  // namespace th::model::kernels
