// .npy / .npz reading and writing against files numpy itself wrote and reads.
#include "io_objects.hpp"

namespace th::test {
namespace {

const std::vector<std::string> kCodes = {"f2", "f4", "f8", "i1", "i2", "i4",
                                         "i8", "u1", "u2", "u4", "b1"};
const std::vector<std::string> kWritable = {"f2", "f4", "f8", "i1", "i2", "i4", "i8", "u1", "b1"};

TEST_CASE(
    "read_npy returns every dtype in both byte orders and both memory orders as C-contiguous "
    "tensors") {
  const fs::path dir = io_fixtures();
  for (const auto& code : kCodes) {
    const torch::Tensor expected = dtype_values(code);
    const bool one_byte = code == "i1" || code == "u1" || code == "b1";
    for (const std::string endian : {"le", "be"}) {
      if (one_byte && endian == "be") continue;
      for (const std::string order : {"C", "F"}) {
        const std::string name = "dtype_" + code + "_" + endian + "_" + order + ".npy";
        INFO(name);
        const torch::Tensor t = io::read_npy(dir / name);
        CHECK(t.scalar_type() == expected.scalar_type());
        CHECK(t.sizes() == expected.sizes());
        CHECK(t.is_contiguous());
        CHECK(torch::equal(t, expected));
      }
    }
  }
}

TEST_CASE("read_npy reads format versions 1 2 and 3 and Python 2 headers with long ints") {
  const fs::path dir = io_fixtures();
  for (const char* name : {"version_1.npy", "version_2.npy", "version_3.npy"}) {
    INFO(name);
    CHECK(torch::equal(io::read_npy(dir / name), dtype_values("f8")));
  }
  CHECK(torch::equal(io::read_npy(dir / "py2_header.npy"),
                     torch::arange(6, torch::kDouble).reshape({2, 3})));
}

TEST_CASE("read_npy reads 0-d and empty arrays") {
  const fs::path dir = io_fixtures();
  const torch::Tensor scalar = io::read_npy(dir / "scalar.npy");
  CHECK(scalar.dim() == 0);
  CHECK(scalar.item<double>() == 2.5);
  const torch::Tensor empty = io::read_npy(dir / "empty.npy");
  CHECK(empty.sizes() == torch::IntArrayRef({0, 3}));
  CHECK(empty.scalar_type() == torch::kFloat);
}

TEST_CASE("read_npy refuses object arrays and names read_npy_value") {
  const std::string message = error_of([&] { io::read_npy(io_fixtures() / "params.npy"); });
  CHECK_THAT(message, Catch::Contains("params.npy") && Catch::Contains("read_npy_value"));
}

TEST_CASE("read_npy_value returns ZJU-MoCap's annots.npy and params.npy as the dicts numpy saved") {
  const fs::path dir = io_fixtures();
  const Value annots = io::read_npy_value(dir / "annots.npy");
  CHECK(annots == annots_value());
  CHECK(annots["cams"]["K"].size() == 23);
  CHECK(annots["ims"].at(3)["ims"].at(22).as_str() == "Camera_B23/000003.jpg");
  CHECK(io::read_npy_value(dir / "params.npy") == params_value());
  // A numeric file comes back as an array.
  CHECK(io::read_npy_value(dir / "dtype_f8_le_C.npy") == Value::array(dtype_values("f8")));
}

TEST_CASE("read_npy_value returns a 1-d object array as a list") {
  const Value v = io::read_npy_value(io_fixtures() / "object_1d.npy");
  CHECK(v == Value::list({Value::integer(1), Value::str("a"), Value()}));
}

TEST_CASE("npy_bytes is byte-identical to np.save for every writable dtype") {
  const fs::path dir = io_fixtures();
  for (const auto& code : kWritable) {
    INFO(code);
    CHECK(byte_difference(io::npy_bytes(dtype_values(code)),
                          read_bytes(dir / ("dtype_" + code + "_le_C.npy"))) == "");
  }
  CHECK(byte_difference(io::npy_bytes(torch::scalar_tensor(2.5, torch::kDouble)),
                        read_bytes(dir / "scalar.npy")) == "");
  CHECK(byte_difference(io::npy_bytes(torch::zeros({0, 3}, torch::kFloat)),
                        read_bytes(dir / "empty.npy")) == "");
}

TEST_CASE("write_npy files are byte-identical to np.save and numpy's copies read back equal") {
  const fs::path dir = scratch_dir("io_write_npy");
  std::map<std::string, torch::Tensor> written;
  for (const auto& code : kWritable) written["npy_" + code] = dtype_values(code);
  written["scalar"] = torch::scalar_tensor(2.5, torch::kDouble);
  written["empty"] = torch::zeros({0, 3}, torch::kFloat);
  written["vector"] = torch::arange(5, torch::kLong);
  written["transposed"] = torch::arange(12, torch::kDouble).reshape({3, 4}).t();  // not contiguous
  for (const auto& [name, t] : written) io::write_npy(dir / (name + ".npy"), t);
  REQUIRE(check_written("npy", dir) == 0);
  for (const auto& [name, t] : written) {
    INFO(name);
    CHECK(io::read_npy(dir / ("py_" + name + ".npy")).equal(t));
  }
}

TEST_CASE("write_npy_value writes annots and params byte-identical to np.save of the same dicts") {
  const fs::path fixtures = io_fixtures();
  // numpy -> C++ -> bytes: re-writing what was read gives numpy's file back.
  for (const char* name : {"annots.npy", "params.npy"}) {
    INFO(name);
    CHECK(byte_difference(io::npy_value_bytes(io::read_npy_value(fixtures / name)),
                          read_bytes(fixtures / name)) == "");
  }
  // C++ -> numpy -> C++.
  const fs::path dir = scratch_dir("io_write_npy_value");
  io::write_npy_value(dir / "annots.npy", annots_value());
  io::write_npy_value(dir / "params.npy", params_value());
  REQUIRE(check_written("objects", dir) == 0);
  CHECK(io::read_npy_value(dir / "py_annots.npy") == annots_value());
  CHECK(io::read_npy_value(dir / "py_params.npy") == params_value());
}

TEST_CASE("write_npy_value of an array writes a numeric .npy") {
  CHECK(byte_difference(io::npy_value_bytes(Value::array(dtype_values("f4"))),
                        io::npy_bytes(dtype_values("f4"))) == "");
}

TEST_CASE("read_npz reads np.savez (stored) and np.savez_compressed (deflate) archives") {
  const fs::path dir = io_fixtures();
  const auto stored = io::read_npz(dir / "arrays.npz");
  REQUIRE(stored.size() == 3);
  CHECK(torch::equal(stored.at("a"), dtype_values("f8")));
  CHECK(torch::equal(stored.at("b"), dtype_values("i4")));
  CHECK(torch::equal(stored.at("c"), dtype_values("b1")));
  const auto compressed = io::read_npz(dir / "arrays_compressed.npz");
  REQUIRE(compressed.size() == 2);
  CHECK(torch::equal(compressed.at("a"), dtype_values("f8")));
  CHECK(torch::equal(compressed.at("big"), torch::arange(100000, torch::kLong).remainder(7)));
}

TEST_CASE("write_npz archives are read by numpy and numpy's compressed copy reads back") {
  const fs::path dir = scratch_dir("io_write_npz");
  const std::map<std::string, torch::Tensor> arrays = {
      {"a", dtype_values("f8")}, {"b", dtype_values("i4")}, {"c", dtype_values("b1")}};
  io::write_npz(dir / "arrays.npz", arrays);
  REQUIRE(check_written("npz", dir) == 0);
  const auto back = io::read_npz(dir / "py_arrays.npz");
  REQUIRE(back.size() == 3);
  for (const auto& [key, t] : arrays) CHECK(torch::equal(back.at(key), t));
}

TEST_CASE("writes are atomic: no temporary file is left next to the result") {
  const fs::path dir = scratch_dir("io_atomic");
  io::write_npy(dir / "a.npy", torch::ones({3}));
  io::write_npy(dir / "a.npy", torch::zeros({4}));  // replaces
  io::write_npz(dir / "b.npz", {{"x", torch::ones({2})}});
  io::write_npy_value(dir / "c.npy", params_value());
  size_t files = 0;
  for (const auto& entry : fs::directory_iterator(dir)) {
    INFO(entry.path().string());
    CHECK(entry.path().filename().string().find(".tmp") == std::string::npos);
    ++files;
  }
  CHECK(files == 3);
  CHECK(torch::equal(io::read_npy(dir / "a.npy"), torch::zeros({4})));
}

TEST_CASE("read_npy on a missing file names the path") {
  CHECK_THAT(error_of([] { io::read_npy("/nonexistent/x.npy"); }),
             Catch::Contains("/nonexistent/x.npy"));
}

}  // namespace
}  // namespace th::test
