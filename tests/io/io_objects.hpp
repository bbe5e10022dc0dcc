#pragma once
// Shared by the tests/io tests: the numpy-made fixtures, and the objects of
// tests/python/npy_pickle_objects.py rebuilt here from the same formulas with torch.

#include <sys/file.h>
#include <unistd.h>

#include <catch2/catch.hpp>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <limits>
#include <sstream>
#include <string>
#include <vector>

#include "core/error.hpp"
#include "io/npy.hpp"
#include "io/pickle.hpp"
#include "support/bytes.hpp"
#include "support/test_env.hpp"

namespace th::test {

namespace fs = std::filesystem;
using io::Value;

inline std::string read_bytes(const fs::path& path) {
  std::ifstream in(path, std::ios::binary);
  REQUIRE(in.good());
  std::ostringstream s;
  s << in.rdbuf();
  return s.str();
}

// The fixtures of tests/python/make_io_fixtures.py. Made once per build tree (and again when
// the script changes); a lock keeps test processes that ctest runs in parallel from racing.
inline fs::path io_fixtures() {
  static const fs::path dir = [] {
    const fs::path root = th::test::test_tmp_root();
    fs::create_directories(root);
    const fs::path out = root / "io_fixtures";
    const fs::path script = "tests/python/make_io_fixtures.py";
    const fs::path objects = "tests/python/npy_pickle_objects.py";
    const fs::path format = "tests/python/numpy1_format.py";
    const int lock = ::open((root / "io_fixtures.lock").c_str(), O_CREAT | O_RDWR, 0644);
    REQUIRE(lock >= 0);
    ::flock(lock, LOCK_EX);
    const fs::path done = out / "DONE";
    const bool fresh = fs::exists(done) &&
                       fs::last_write_time(done) >= fs::last_write_time(script) &&
                       fs::last_write_time(done) >= fs::last_write_time(objects) &&
                       fs::last_write_time(done) >= fs::last_write_time(format);
    int rc = 0;
    if (!fresh) {
      fs::remove_all(out);
      rc = run_python(script.string(), out.string());
    }
    ::flock(lock, LOCK_UN);
    ::close(lock);
    REQUIRE(rc == 0);
    return out;
  }();
  return dir;
}

// Runs tests/python/check_io_written.py <mode> <dir>: numpy checks what C++ wrote.
inline int check_written(const std::string& mode, const fs::path& dir) {
  return run_python("tests/python/check_io_written.py", mode + " " + dir.string());
}

inline torch::Tensor arange(int64_t n, torch::ScalarType type) {
  return torch::arange(n, torch::kLong).to(type);
}

// dtype_values(code) of npy_pickle_objects.py, as the reader returns it (u2/u4 widened).
inline torch::Tensor dtype_values(const std::string& code) {
  const torch::Tensor i = torch::arange(24, torch::kLong);
  torch::Tensor v;
  if (code[0] == 'f') {
    const auto type = code == "f2" ? torch::kHalf : code == "f4" ? torch::kFloat : torch::kDouble;
    v = (i.to(torch::kDouble) * 0.5 - 3).to(type);
  } else if (code == "i1") {
    v = (i * 7 - 80).to(torch::kChar);
  } else if (code[0] == 'i') {
    v = (i * 37 - 300).to(code == "i2" ? torch::kShort : code == "i4" ? torch::kInt : torch::kLong);
  } else if (code == "u1") {
    v = (i * 11).to(torch::kByte);
  } else if (code == "u2") {
    v = (i * 2000 + 7).to(torch::kInt);
  } else if (code == "u4") {
    v = i * 100000000 + 5;
  } else {
    v = i.remainder(3).eq(0);
  }
  return v.reshape({2, 3, 4});
}

inline Value str(const std::string& s) { return Value::str(s); }
inline Value arr(const torch::Tensor& t) { return Value::array(t); }
inline Value tensor2d(std::initializer_list<std::initializer_list<double>> rows) {
  std::vector<double> flat;
  int64_t cols = 0;
  for (const auto& r : rows) {
    cols = static_cast<int64_t>(r.size());
    flat.insert(flat.end(), r.begin(), r.end());
  }
  return arr(
      torch::tensor(flat, torch::kDouble).reshape({static_cast<int64_t>(rows.size()), cols}));
}

inline Value annots_value(int ncams = 23, int nframes = 4) {
  Value::List K, R, T, D, ims;
  for (int c = 0; c < ncams; ++c) {
    K.push_back(tensor2d({{1000.0 + c, 0, 512}, {0, 1001.0 + c, 500}, {0, 0, 1}}));
    R.push_back(arr(torch::arange(9, torch::kDouble).reshape({3, 3}) * 0.125 + c));
    T.push_back(tensor2d({{c * 10.5}, {c * -2.25}, {1000.0 + c}}));
    std::vector<double> d;
    for (int k = 0; k < 5; ++k) d.push_back(std::pow(0.5, k + 1) * c);
    D.push_back(arr(torch::tensor(d, torch::kDouble).reshape({5, 1})));
  }
  for (int f = 0; f < nframes; ++f) {
    Value::List paths;
    for (int c = 0; c < ncams; ++c) {
      char buffer[64];
      std::snprintf(buffer, sizeof buffer, "Camera_B%d/%06d.jpg", c + 1, f);
      paths.push_back(str(buffer));
    }
    ims.push_back(Value::dict({{str("ims"), Value::list(paths)}}));
  }
  return Value::dict({{str("cams"), Value::dict({{str("K"), Value::list(K)},
                                                 {str("R"), Value::list(R)},
                                                 {str("T"), Value::list(T)},
                                                 {str("D"), Value::list(D)}})},
                      {str("ims"), Value::list(ims)}});
}

inline Value params_value() {
  return Value::dict({
      {str("poses"), arr((torch::arange(72, torch::kDouble) * 0.01).reshape({1, 72}))},
      {str("Rh"), tensor2d({{0.1, 0.2, 0.3}})},
      {str("Th"), tensor2d({{0.5, -0.25, 2.0}})},
      {str("shapes"), arr((torch::arange(10, torch::kDouble) * 0.1 - 0.5).reshape({1, 10}))},
  });
}

inline Value ints(std::initializer_list<int64_t> values) {
  Value::List out;
  for (int64_t v : values) out.push_back(Value::integer(v));
  return Value::list(out);
}

inline Value range_list(int64_t n) {
  Value::List out;
  for (int64_t i = 0; i < n; ++i) out.push_back(Value::integer(i));
  return Value::list(out);
}

inline Value writer_value() {
  const double inf = std::numeric_limits<double>::infinity();
  Value::List floats;
  for (double f : {0.0, -0.0, 1.5, 1e300, inf, -inf, std::numeric_limits<double>::quiet_NaN()}) {
    floats.push_back(Value::floating(f));
  }
  const Value::List arrays = {
      arr(torch::zeros({2, 3}, torch::kDouble)),
      arr(torch::arange(5, torch::kInt)),
      arr(torch::scalar_tensor(true, torch::kBool)),
      arr(torch::tensor({1, 2}, torch::kByte)),
      arr(torch::full({1, 1}, 1.5, torch::kFloat)),
      arr(torch::arange(24, torch::kLong).reshape({2, 3, 4})),
      arr(torch::zeros({0, 3}, torch::kDouble)),
      arr(torch::zeros({1, 1, 2, 1}, torch::kFloat)),
      arr(torch::tensor({1}, torch::kByte)),
      arr(arange(3, torch::kChar)),
      arr(arange(3, torch::kShort)),
      arr(arange(3, torch::kHalf)),
  };
  return Value::dict({
      {str("none"), Value()},
      {str("true"), Value::boolean(true)},
      {str("false"), Value::boolean(false)},
      {str("ints"),
       ints({0, 255, 256, 65535, 65536, -1, -(int64_t{1} << 31), (int64_t{1} << 31) - 1,
             int64_t{1} << 31, -(int64_t{1} << 31) - 1, int64_t{1} << 62,
             std::numeric_limits<int64_t>::min(), std::numeric_limits<int64_t>::max(),
             int64_t{1} << 40, -(int64_t{1} << 40)})},
      {str("floats"), Value::list(floats)},
      {str("str"), str("h\xc3\xa9llo")},
      {str("empty"), str("")},
      {str("chars"), Value::list({str("a"), str("<"), str("/"), str("Z")})},
      {str("repeat"),
       Value::list({str("same text"), str("same text"), str("Camera_B1/000000.jpg")})},
      {str("bytes"), Value::bytes(std::string("\x00\x01"
                                              "binary",
                                              8))},
      {str("b1"), Value::bytes("b")},
      {str("b0"), Value::bytes("")},
      {str("tuple0"), Value::tuple({})},
      {str("tuple2"), Value::tuple({Value::integer(1), str("x")})},
      {str("tuple5"), Value::tuple({Value::integer(1), Value::integer(2), Value::integer(3),
                                    Value::integer(4), Value::integer(5)})},
      {str("nested"),
       Value::dict({{str("inner"), Value::list({Value::list({}), Value::dict({}),
                                                Value::list({Value::integer(1)})})}})},
      {str("arrays"), Value::list(arrays)},
      {str("numpy"), Value::integer(1)},
      {str("latin1"), Value::integer(2)},
  });
}

inline Value writer_big_value() {
  Value::List many;
  for (int i = 0; i < 3000; ++i)
    many.push_back(arr(torch::full({3}, static_cast<double>(i), torch::kFloat)));
  return Value::dict({
      {str("big"), arr(torch::arange(20000, torch::kDouble) * 0.25)},
      {str("many"), Value::list(many)},
      {str("long"), str(std::string(70000, 'x'))},
      {str("mid"), str(std::string(65535, 'y'))},
      {str("ints"), range_list(3000)},
  });
}

inline Value key_dict(const std::string& prefix, int n) {
  Value::Dict d;
  for (int i = 0; i < n; ++i) d.emplace_back(str(prefix + std::to_string(i)), Value::integer(i));
  return Value::dict(d);
}

inline Value writer_batches_value() {
  return Value::dict({
      {str("l1000"), range_list(1000)},
      {str("l2000"), range_list(2000)},
      {str("l1001"), range_list(1001)},
      {str("d1000"), key_dict("k", 1000)},
      {str("d2001"), key_dict("j", 2001)},
  });
}

// The message of the th::Error `f` throws, or "<no th::Error>".
template <class F>
std::string error_of(F&& f) {
  try {
    f();
  } catch (const th::Error& e) {
    return e.what();
  }
  return "<no th::Error>";
}

}  // namespace th::test
