// Checkpoints written by the installed Python torch's own torch.save (Debian 12's 1.13, Debian
// 13's 2.6 in scripts/check-libtorch2.sh's root): every storage dtype, views, a module's state
// dict, both archive namings, and a big-endian copy (tests/python/torch_save_formats.py).
#include <torch/torch.h>

#include <catch2/catch.hpp>
#include <fstream>
#include <iterator>
#include <string>

#include "core/error.hpp"
#include "io/files.hpp"
#include "pipeline/reference_import.hpp"
#include "support/test_env.hpp"

using namespace th;
using namespace th::model;
using namespace th::pipeline;

namespace {

const std::filesystem::path& fixtures() {
  static const auto dir = [] {
    auto d = test::scratch_dir("torch_save_formats");
    REQUIRE(test::run_python("tests/python/torch_save_formats.py", d.string()) == 0);
    return d;
  }();
  return dir;
}

// The formulas of torch_save_formats.py, computed here.
torch::Tensor dtype_values(const std::string& name) {
  const auto i = torch::arange(24, torch::kLong);
  torch::Tensor v;
  if (name == "float16" || name == "bfloat16" || name == "float32" || name == "float64") {
    const auto type = name == "float16"    ? torch::kHalf
                      : name == "bfloat16" ? torch::kBFloat16
                      : name == "float32"  ? torch::kFloat
                                           : torch::kDouble;
    v = (i.to(torch::kDouble) * 0.5 - 3).to(type);
  } else if (name == "int8") {
    v = (i * 7 - 80).to(torch::kChar);
  } else if (name == "uint8") {
    v = (i * 11).to(torch::kByte);
  } else if (name == "int16") {
    v = (i * 37 - 300).to(torch::kShort);
  } else if (name == "int32") {
    v = (i * 123457 - 1500000).to(torch::kInt);
  } else if (name == "int64") {
    v = i * (int64_t{1} << 40) - 3;
  } else {
    v = i.remainder(3).eq(0);
  }
  return v.reshape({2, 3, 4});
}

const std::vector<std::string> kDtypes = {"float16", "bfloat16", "float32", "float64", "int8",
                                          "uint8",   "int16",    "int32",   "int64",   "bool"};

void check_contents(const std::map<std::string, torch::Tensor>& sd) {
  for (const auto& name : kDtypes) {
    INFO("dtype." << name);
    REQUIRE(sd.count("dtype." + name));
    const auto& t = sd.at("dtype." + name);
    const auto expected = dtype_values(name);
    CHECK(t.scalar_type() == expected.scalar_type());
    CHECK(t.sizes() == expected.sizes());
    CHECK(torch::equal(t, expected));
  }
  CHECK(
      torch::equal(sd.at("view.transposed"), torch::arange(24, torch::kFloat).reshape({4, 6}).t()));
  const auto base = torch::arange(30, torch::kDouble) * 0.25;
  CHECK(torch::equal(sd.at("view.slice_a"), base.slice(0, 5, 17).reshape({3, 4})));
  CHECK(torch::equal(sd.at("view.slice_b"), base.slice(0, 20, 26, 2)));
  CHECK(sd.at("scalar").dim() == 0);
  CHECK(sd.at("scalar").item<float>() == 2.5f);
  CHECK(sd.at("empty").sizes() == torch::IntArrayRef({0, 3}));
  CHECK(
      torch::equal(sd.at("module.0.weight"), torch::arange(6, torch::kFloat).reshape({2, 3}) - 2));
  CHECK(torch::equal(sd.at("module.0.bias"), torch::tensor({0.5f, -0.5f})));
  CHECK(torch::equal(sd.at("module.1.running_var"), torch::ones({2})));
  CHECK(sd.at("module.1.num_batches_tracked").scalar_type() == torch::kLong);
  CHECK(sd.at("module.1.num_batches_tracked").item<int64_t>() == 0);
  CHECK(torch::equal(sd.at("param"), torch::tensor({1.0f, -2.0f, 4.0f})));
}

}  // namespace

TEST_CASE("torch.save checkpoints of the installed torch import with every dtype",
          "[pipeline][checkpoint][python]") {
  const auto& dir = fixtures();
  std::ifstream layout((dir / "layout.txt").string());
  std::string version;
  std::getline(layout, version);
  INFO("written by torch " << version);
  if (version.rfind("1.", 0) != 0) {
    // PyTorch 2.x's layout: the fixture has its new records (the reader passes over them).
    const std::string records((std::istreambuf_iterator<char>(layout)),
                              std::istreambuf_iterator<char>());
    CHECK(records.find("byteorder\n") != std::string::npos);
    CHECK(records.find(".data/serialization_id\n") != std::string::npos);
  }
  for (const char* file : {"every_dtype.pth", "every_dtype_buffer.pth"}) {
    INFO(file);
    check_contents(read_torch_state_dict(dir / file, "net"));
  }
  // The whole file: non-tensor entries become 0-d tensors, strings are skipped.
  const auto all = read_torch_state_dict(dir / "every_dtype.pth", "");
  CHECK(all.at("epoch").item<int64_t>() == 7);
  CHECK(all.at("meta.step").item<int64_t>() == 3);
  CHECK_FALSE(all.count("meta.torch"));
}

TEST_CASE("a big-endian torch.save checkpoint imports byte-swapped",
          "[pipeline][checkpoint][python]") {
  check_contents(read_torch_state_dict(fixtures() / "every_dtype_big.pth", "net"));
  CHECK_THROWS_WITH(read_torch_state_dict(fixtures() / "bad_byteorder.pth", "net"),
                    Catch::Contains("byteorder") && Catch::Contains("middle"));
}

TEST_CASE("a checkpoint with a corrupt storage record fails naming the file",
          "[pipeline][checkpoint][python]") {
  // LibTorch's zip reader threw c10::Error past read_torch_state_dict for a record whose local
  // header is damaged (it does not check CRCs, so a damaged header is what it notices).
  std::string bytes = io::read_file(fixtures() / "every_dtype.pth");
  const size_t name = bytes.find("/data/0");  // first in the local header of that record
  REQUIRE(name != std::string::npos);
  const size_t header = bytes.rfind("PK\x03\x04", name);
  REQUIRE(header != std::string::npos);
  bytes[header + 3] = '\x05';  // no longer a local header signature
  const auto file = test::scratch_dir("torch_save_formats_corrupt") / "bad_header.pth";
  std::ofstream(file, std::ios::binary) << bytes;
  CHECK_THROWS_AS(read_torch_state_dict(file, "net"), th::Error);
  CHECK_THROWS_WITH(read_torch_state_dict(file, "net"), Catch::Contains("bad_header.pth"));
}
