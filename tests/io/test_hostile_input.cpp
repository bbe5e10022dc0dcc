// Malicious, truncated and malformed input: always th::Error (naming the file and offset),
// never code execution, a crash, a huge allocation or a stack overflow.
#include <random>

#include "io_objects.hpp"

namespace th::test {
namespace {

using namespace std::string_literals;

std::string pickle_error(const std::string& bytes) {
  return error_of([&] { io::parse_pickle(bytes, "evil.pkl"); });
}

TEST_CASE(
    "a pickle calling os.system is refused with an error naming the global at every protocol") {
  fs::remove("PWNED");
  for (int proto = 2; proto <= 5; ++proto) {
    INFO("protocol " << proto);
    const std::string message = error_of(
        [&] { io::read_pickle(io_fixtures() / ("os_system_p" + std::to_string(proto) + ".pkl")); });
    CHECK_THAT(message, Catch::Contains("posix.system") || Catch::Contains("os.system"));
    CHECK_THAT(message, Catch::Contains("os_system_p" + std::to_string(proto) + ".pkl"));
  }
  CHECK_FALSE(fs::exists("PWNED"));
}

TEST_CASE("builtins.eval and other globals outside the whitelist are refused by name") {
  CHECK_THAT(error_of([] { io::read_pickle(io_fixtures() / "eval_p2.pkl"); }),
             Catch::Contains("__builtin__.eval"));
  CHECK_THAT(pickle_error("\x80\x04\x8c\x0asubprocess\x8c\x05Popen\x93."s),
             Catch::Contains("subprocess.Popen"));
  CHECK_THAT(pickle_error("\x80\x02"
                          "cbuiltins\ngetattr\n."s),
             Catch::Contains("builtins.getattr"));
  // Whitelisted names that are classes cannot be called with REDUCE either.
  CHECK_THAT(pickle_error("\x80\x02"
                          "cnumpy\nndarray\n)R."s),
             Catch::Contains("cannot call numpy.ndarray"));
}

TEST_CASE("protocol-5 out-of-band buffers are refused with a clear error") {
  CHECK_THAT(error_of([] { io::read_pickle(io_fixtures() / "oob_p5.pkl"); }),
             Catch::Contains("out-of-band"));
}

TEST_CASE(
    "every truncated prefix of real pickle and npy and npz files gives th::Error with an offset") {
  const fs::path dir = io_fixtures();
  const auto each_prefix = [](const std::string& bytes, const auto& parse) {
    for (size_t n = 0; n < bytes.size(); ++n) {
      const std::string prefix = bytes.substr(0, n);
      INFO("prefix of " << n << " bytes");
      const std::string message = error_of([&] { parse(prefix); });
      REQUIRE_THAT(message, Catch::Contains("byte") || Catch::Contains("not a zip"));
    }
  };
  for (const char* name : {"small_p3.pkl", "small_p4.pkl"}) {
    INFO(name);
    const std::string bytes = read_bytes(dir / name);
    REQUIRE_NOTHROW(io::parse_pickle(bytes, name));
    each_prefix(bytes, [&](const std::string& b) { io::parse_pickle(b, name); });
  }
  each_prefix(read_bytes(dir / "annots_small.npy"),
              [](const std::string& b) { io::parse_npy_value(b, "a.npy"); });
  each_prefix(read_bytes(dir / "dtype_f8_be_F.npy"),
              [](const std::string& b) { io::parse_npy(b, "f.npy"); });
  each_prefix(read_bytes(dir / "arrays.npz"),
              [](const std::string& b) { io::parse_npz(b, "a.npz"); });
  each_prefix(read_bytes(dir / "arrays_compressed.npz"),
              [](const std::string& b) { io::parse_npz(b, "c.npz"); });
}

TEST_CASE("wrong magic and unsupported versions and protocols are refused") {
  std::string npy = read_bytes(io_fixtures() / "dtype_f8_le_C.npy");
  CHECK_THAT(error_of([&] { io::parse_npy("\x93NUMPX" + npy.substr(6), "m.npy"); }),
             Catch::Contains("magic"));
  CHECK_THAT(error_of([&] { io::parse_npy("PK\x03\x04" + npy, "m.npy"); }),
             Catch::Contains("not a .npy"));
  npy[6] = 4;
  CHECK_THAT(error_of([&] { io::parse_npy(npy, "v.npy"); }), Catch::Contains("version 4.0"));
  CHECK_THAT(error_of([] { io::parse_npz("not a zip archive at all, just text.", "t.npz"); }),
             Catch::Contains("not a zip"));
  CHECK_THAT(pickle_error("\x80\x06N."s), Catch::Contains("protocol 6"));
  CHECK_THAT(pickle_error("\x80\x02\xff."s),
             Catch::Contains("unknown opcode") && Catch::Contains("byte 2"));
}

std::string npy_with_header(const std::string& dict) {
  std::string header = dict;
  header.append(64 - (10 + header.size() + 1) % 64, ' ');
  header.push_back('\n');
  std::string out = "\x93NUMPY\x01\x00"s;
  out.push_back(static_cast<char>(header.size() & 0xff));
  out.push_back(static_cast<char>(header.size() >> 8));
  return out + header + std::string(16, '\0');
}

TEST_CASE("absurd shapes are refused before allocating") {
  CHECK_THAT(error_of([] {
               io::parse_npy(
                   npy_with_header(
                       "{'descr': '<f8', 'fortran_order': False, 'shape': (1125899906842624,), }"),
                   "huge.npy");
             }),
             Catch::Contains("absurd"));
  CHECK_THAT(
      error_of([] {
        io::parse_npy(
            npy_with_header(
                "{'descr': '<f8', 'fortran_order': False, 'shape': (1073741824, 1073741824), }"),
            "huge2.npy");
      }),
      Catch::Contains("absurd"));
  CHECK_THAT(
      error_of([] {
        io::parse_npy(
            npy_with_header("{'descr': '<f8', 'fortran_order': False, 'shape': (1000, 1000), }"),
            "short.npy");
      }),
      Catch::Contains("truncated"));
  CHECK_THAT(error_of([] {
               io::parse_npy(
                   npy_with_header("{'descr': '<U8', 'fortran_order': False, 'shape': (2,), }"),
                   "u.npy");
             }),
             Catch::Contains("unsupported dtype '<U8'"));
  const fs::path dir = io_fixtures();
  CHECK_THAT(error_of([&] { io::read_pickle(dir / "absurd_shape.pkl"); }),
             Catch::Contains("absurd array shape"));
  CHECK_THAT(error_of([&] { io::read_pickle(dir / "shape_mismatch.pkl"); }),
             Catch::Contains("24 bytes") && Catch::Contains("(1000,)"));
  CHECK_THAT(error_of([&] { io::read_pickle(dir / "absurd_sparse.pkl"); }),
             Catch::Contains("too large to densify"));
  // A deflated .npz member claiming an impossible uncompressed size.
  std::string npz = read_bytes(dir / "arrays_compressed.npz");
  const size_t central = npz.find("PK\x01\x02");
  REQUIRE(central != std::string::npos);
  for (int k = 0; k < 4; ++k) npz[central + 24 + k] = k == 3 ? '\x7f' : '\xff';
  CHECK_THAT(error_of([&] { io::parse_npz(npz, "bomb.npz"); }), Catch::Contains("deflate cannot"));
}

TEST_CASE("recursion bombs give th::Error and not a stack overflow") {
  const int n = 100000;
  // 100000 nested lists through EMPTY_LIST + APPEND.
  CHECK_THAT(pickle_error("\x80\x02"s + std::string(n, ']') + std::string(n - 1, 'a') + "."),
             Catch::Contains("nesting deeper"));
  // ... through MARK + LIST and MARK + TUPLE.
  CHECK_THAT(pickle_error(std::string(n, '(') + std::string(n, 'l') + "."),
             Catch::Contains("nesting deeper"));
  CHECK_THAT(pickle_error(std::string(n, '(') + std::string(n, 't') + "."),
             Catch::Contains("nesting deeper"));
  // A list containing itself.
  CHECK_THAT(pickle_error("\x80\x02]q\x00h\x00"
                          "a."s),
             Catch::Contains("recursive"));
  // A chain built through the memo after the fact (each APPEND adds a shallow list).
  std::string chain = "\x80\x02"s;
  for (int i = 0; i < 1000; ++i)
    chain += "]r" + std::string(reinterpret_cast<const char*>(&i), 4) + "0";
  for (int i = 0; i + 1 < 1000; ++i) {
    const int next = i + 1;
    chain += "j" + std::string(reinterpret_cast<const char*>(&i), 4) + "j" +
             std::string(reinterpret_cast<const char*>(&next), 4) + "a0";
  }
  chain += "j\x00\x00\x00\x00."s;
  CHECK_THAT(pickle_error(chain), Catch::Contains("nesting deeper"));
  // Shared references doubling 64 times (a billion billion nodes if expanded).
  std::string dag = "\x80\x02]q\x00"s;
  for (int i = 0; i < 64; ++i)
    dag +=
        "](h\x00h\x00"
        "eq\x00"
        "0"s;
  dag += "h\x00."s;
  CHECK_THAT(pickle_error(dag), Catch::Contains("expands"));
}

TEST_CASE("malformed pickles give errors naming the file and the opcode's offset") {
  CHECK_THAT(pickle_error("\x80\x02"
                          "a."s),
             Catch::Contains("evil.pkl") && Catch::Contains("stack underflow") &&
                 Catch::Contains("byte 2"));
  CHECK_THAT(pickle_error("\x80\x02h\x05."s), Catch::Contains("memo entry 5"));
  CHECK_THAT(pickle_error("\x80\x02K\x01K\x02"
                          "b."s),
             Catch::Contains("BUILD"));
  CHECK_THAT(pickle_error("\x80\x02K\x01)R."s), Catch::Contains("not callable"));
  CHECK_THAT(pickle_error("\x80\x02}K\x01"
                          "a."s),
             Catch::Contains("APPEND to a dict"));
  CHECK_THAT(pickle_error("\x80\x02X\x02\x00\x00\x00\xff\xfe."s), Catch::Contains("UTF-8"));
  CHECK_THAT(pickle_error("\x80\x02"
                          "cnumpy.core.multiarray\n_reconstruct\nK\x01K\x02K\x03\x87R."s),
             Catch::Contains("not numpy.ndarray"));
  CHECK_THAT(pickle_error("\x80\x02}(]K\x01u."s), Catch::Contains("unhashable"));
  CHECK_THAT(pickle_error("\x80\x02\x8a\x0a\x00\x00\x00\x00\x00\x00\x00\x00\x00\x01."s),
             Catch::Contains("64 bits"));
  CHECK_THAT(pickle_error("\x80\x02N"s), Catch::Contains("truncated") && Catch::Contains("STOP"));
  CHECK_THAT(pickle_error("\x80\x02X\xff\xff\xff\x7f"
                          "abc."s),
             Catch::Contains("truncated"));
}

TEST_CASE(
    "randomly corrupted pickle and npy files give a value or th::Error and never anything else") {
  std::mt19937 rng(1234);
  const fs::path dir = io_fixtures();
  for (const char* name : {"small_p3.pkl", "small_p4.pkl", "annots_small.npy"}) {
    const std::string original = read_bytes(dir / name);
    for (int trial = 0; trial < 3000; ++trial) {
      std::string bytes = original;
      const int flips = 1 + static_cast<int>(rng() % 4);
      for (int f = 0; f < flips; ++f) bytes[rng() % bytes.size()] = static_cast<char>(rng() % 256);
      INFO(name << " trial " << trial);
      try {
        if (std::string(name).find(".npy") != std::string::npos) {
          io::parse_npy_value(bytes, name);
        } else {
          io::parse_pickle(bytes, name);
        }
      } catch (const th::Error&) {
      } catch (const std::exception& e) {
        FAIL("not a th::Error: " << e.what());
      }
    }
  }
}

}  // namespace
}  // namespace th::test
