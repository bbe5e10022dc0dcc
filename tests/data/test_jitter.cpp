// Colour jitter (METHOD 2.1): one set of parameters per training sample, shared by the target and
// every reference view; none at test time.
#include <catch2/catch.hpp>

#include "body/smpl.hpp"
#include "data/dataset.hpp"
#include "support/test_env.hpp"

using namespace th::data;

namespace {

th::DataConfig brightness_only(bool enabled) {
  const auto root = th::test::tiny_dataset();
  th::DataConfig c;
  c.root = root.string();
  c.split_file = (root / "split.yaml").string();
  c.workers = 0;
  c.jitter.enabled = enabled;
  // A pure brightness change below 1 (no clamping): jittered = b * plain, pixel by pixel.
  c.jitter.brightness = {0.5, 0.9};
  c.jitter.contrast = {1.0, 1.0};
  c.jitter.saturation = {1.0, 1.0};
  c.jitter.hue = {0.0, 0.0};
  return c;
}

// The factor b with jittered = b * plain over the lit pixels, and the largest deviation from it.
std::pair<double, double> brightness_factor(const torch::Tensor& jittered,
                                            const torch::Tensor& plain) {
  const auto lit = plain > 0.05;
  const double b =
      (jittered.masked_select(lit).sum() / plain.masked_select(lit).sum()).item<double>();
  return {b, (jittered - b * plain).abs().max().item<double>()};
}

}  // namespace

TEST_CASE("colour jitter uses one set of parameters for the target and all references of a sample",
          "[dataset][jitter]") {
  const auto c_on = brightness_only(true), c_off = brightness_only(false);
  const auto smpl = load_body_model(c_on);
  const Dataset on(c_on, "training", Dataset::Mode::Train, smpl);
  const Dataset off(c_off, "training", Dataset::Mode::Train, smpl);
  std::vector<double> per_sample;
  for (size_t index : {size_t(0), on.size() / 2}) {
    const uint64_t seed = 1234 + index;
    const Sample j = on.load(index, seed), p = off.load(index, seed);
    REQUIRE(j.reference_views == p.reference_views);  // the same views, so pixels correspond
    REQUIRE(j.ref_images.sizes() == p.ref_images.sizes());
    const auto [b, dev] = brightness_factor(j.target_image, p.target_image);
    INFO("sample " << index << ": target brightness factor " << b);
    CHECK(b >= 0.5);
    CHECK(b <= 0.9);
    CHECK(dev < 1e-4);
    for (int64_t v = 0; v < j.ref_images.size(0); ++v) {
      const auto [bv, dv] = brightness_factor(j.ref_images[v], p.ref_images[v]);
      INFO("reference " << v << " factor " << bv);
      CHECK(bv == Approx(b).epsilon(1e-5));  // the target's parameters
      CHECK(dv < 1e-4);
    }
    per_sample.push_back(b);
  }
  CHECK(per_sample[0] != Approx(per_sample[1]).epsilon(1e-4));  // drawn per sample

  // Test-time samples are never jittered.
  const Dataset test_on(c_on, "identity", Dataset::Mode::Test, smpl);
  const Dataset test_off(c_off, "identity", Dataset::Mode::Test, smpl);
  const Sample tj = test_on.load(0, 7), tp = test_off.load(0, 7);
  CHECK(torch::equal(tj.target_image, tp.target_image));
  CHECK(torch::equal(tj.ref_images, tp.ref_images));
}
