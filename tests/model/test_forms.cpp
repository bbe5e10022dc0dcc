// Where each operation picks its form (model/kernels/forms.hpp): the pixel stage by grad mode and
// device when a frame is prepared, the kernels by device; the stages' timing hook.
#include <torch/torch.h>

#include <catch2/catch.hpp>
#include <string>

#include "model/frame_fixture.hpp"
#include "model/kernels/forms.hpp"
#include "model/precision.hpp"
#include "model/transhuman.hpp"
#include "render/volume.hpp"

using namespace th;
using namespace th::model;

using test::max_abs;

TEST_CASE("the pixel stage takes its form when the frame is prepared, and the frame keeps it",
          "[model][forms]") {
  const auto frame = test::synthetic_frame();
  torch::manual_seed(5);
  TransHuman model(test::tiny_model_config());
  test::center_density(*model, frame);
  // Inference on CPU reads readout windows; under autograd (training) the full readouts.
  FrameCache inference;
  {
    torch::NoGradGuard no_grad;
    inference = model->prepare(frame.inputs, 0.1);
  }
  const auto training = model->prepare(frame.inputs, 0.1);
  CHECK(std::holds_alternative<WindowReadouts>(inference.pixels));
  CHECK(std::holds_alternative<PixelReadouts>(training.pixels));

  // A frame keeps its form whatever the mode of the call that evaluates it: the inference frame
  // evaluated while autograd records reads its windows, and equals the training frame.
  torch::manual_seed(6);
  const auto pts = frame.inputs.vertices.narrow(0, 0, 48) + 0.03 * torch::randn({48, 3});
  const auto dirs = torch::randn({48, 3});
  const auto a = model->forward(inference, pts, dirs);
  torch::Tensor b;
  {
    torch::NoGradGuard no_grad;
    b = model->forward(training, pts, dirs);
  }
  CHECK(max_abs(a, b) < 1e-5 * (1 + b.abs().max().item<double>()));
}

TEST_CASE("profiling: each stage's time, the method's results unchanged", "[model][forms]") {
  const auto frame = test::synthetic_frame();
  torch::manual_seed(7);
  TransHuman model(test::tiny_model_config());
  torch::NoGradGuard no_grad;
  const auto pts = frame.inputs.vertices.narrow(0, 0, 32) + 0.03 * torch::randn({32, 3});
  const auto dirs = torch::randn({32, 3});
  const auto plain = model->forward(model->prepare(frame.inputs, 0.1), pts, dirs);

  render::Profile profile;
  model->set_profile(&profile);
  const auto cache = model->prepare(frame.inputs, 0.1);
  const auto timed = model->forward(cache, pts, dirs);
  model->set_profile(nullptr);
  CHECK(torch::equal(plain, timed));
  for (const char* stage :
       {"encoder", "painting", "transhe", "readouts", "dparf", "sampling", "fdi", "heads"}) {
    INFO(stage);
    CHECK(profile.seconds.count(stage) == 1);
    CHECK(profile.seconds[stage] >= 0);
  }
  CHECK(profile.open.empty());  // every timer closed
  CHECK(profile.stages.empty());
  // Each per-point stage counts the work of its operations, in itself or in its parts.
  for (const std::string stage : {"dparf", "sampling", "fdi", "heads"}) {
    INFO(stage);
    render::Work w;
    for (const auto& [name, work] : profile.work)
      if (name == stage || name.rfind(stage + ".", 0) == 0) {
        w.flops += work.flops;
        w.bytes += work.bytes;
      }
    CHECK(w.flops > 0);
    CHECK(w.bytes > 0);
  }
  // The parts of DPaRF and of the pixel sampling, timed inside them.
  for (const char* part :
       {"dparf.fields", "dparf.codes", "dparf.gather", "sampling.taps", "sampling.gather"}) {
    INFO(part);
    CHECK(profile.seconds.count(part) == 1);
    CHECK(profile.work[part].bytes > 0);
  }

  // Without a profile, nothing more is recorded.
  const auto before = profile.seconds;
  model->forward(cache, pts, dirs);
  CHECK(profile.seconds == before);
}

TEST_CASE("work is counted in the innermost stage open on the thread, products at their shapes",
          "[model][forms]") {
  torch::NoGradGuard no_grad;
  const auto x = torch::randn({300, 64}), w = torch::randn({96, 64}), b = torch::randn({96});
  render::Profile profile;
  for (const bool onednn : {false, true}) {
    Products p;
    p.onednn = onednn;
    {
      render::ScopedTimer outer(&profile, "outer");
      render::ScopedTimer inner(&profile, "inner");
      p.linear(x, w, b);
    }
    {
      render::ScopedTimer outer(&profile, "outer");
      p.linear(x, w, b);
    }
  }
  const double flops = 2.0 * 300 * 64 * 96 + 300 * 96;
  const double bytes = 4.0 * (300 * 64 + 96 * 64 + 96 + 300 * 96);
  CHECK(profile.work["inner"].flops == 2 * flops);
  CHECK(profile.work["inner"].bytes == 2 * bytes);
  CHECK(profile.work["outer"].flops == 2 * flops);
  // bf16: the conversions of x and w count their traffic, the product its bf16 operands.
  Products bf;  // LibTorch's bf16 product: the bias converted too
  bf.precision = Precision::bf16;
  render::Profile p16;
  {
    render::ScopedTimer t(&p16, "bf16");
    bf.linear(x, w, b);
  }
  CHECK(p16.work["bf16"].flops == flops);
  CHECK(p16.work["bf16"].bytes ==
        6.0 * (300 * 64 + 96 * 64 + 96) + 2.0 * (300 * 64 + 96 * 64 + 96 + 300 * 96));
  // No timer open on the thread: nothing is counted anywhere.
  Products{}.linear(x, w, b);
  CHECK(profile.work.size() == 2);
  CHECK(p16.work.size() == 1);
}

TEST_CASE("LibTorch forms: the CPU kernels step aside while the guard lives", "[model][forms]") {
  const auto frame = test::synthetic_frame();
  torch::manual_seed(5);
  TransHuman model(test::tiny_model_config());
  torch::NoGradGuard no_grad;
  auto pixels = [&] { return model->prepare(frame.inputs, 0.1).pixels; };
  CHECK(kernels::cpu_kernels(torch::kCPU));
  CHECK(std::holds_alternative<WindowReadouts>(pixels()));
  {
    kernels::LibTorchForms outer;
    CHECK_FALSE(kernels::cpu_kernels(torch::kCPU));
    {
      kernels::LibTorchForms inner;
      CHECK_FALSE(kernels::cpu_kernels(torch::kCPU));
    }
    CHECK_FALSE(kernels::cpu_kernels(torch::kCPU));  // the inner guard restores the outer's
    // Readout windows are a CPU kernel's form: the LibTorch forms read the level readouts.
    CHECK(std::holds_alternative<PixelReadouts>(pixels()));
  }
  CHECK(kernels::cpu_kernels(torch::kCPU));
  CHECK(std::holds_alternative<WindowReadouts>(pixels()));
  CHECK_FALSE(kernels::cpu_kernels(torch::Device(torch::kCUDA, 0)));  // no kernel of ours there
}
