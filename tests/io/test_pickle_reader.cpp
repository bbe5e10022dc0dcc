// The pickle reader against pickles CPython + numpy + scipy wrote, and hand-assembled ones.
#include <cstring>

#include "io_objects.hpp"

namespace th::test {
namespace {

Value I(int64_t v) { return Value::integer(v); }

// mixed_object() of npy_pickle_objects.py.
Value mixed_expected() {
  Value::List many;
  for (int i = 0; i < 2500; ++i) many.push_back(I(i));
  Value::Dict dtypes;
  for (const char* code : {"f2", "f4", "f8", "i1", "i2", "i4", "i8", "u1", "u2", "u4", "b1"}) {
    dtypes.emplace_back(str(code), arr(dtype_values(code)));
  }
  const Value shared = Value::list({I(1), I(2)});
  return Value::dict({
      {str("int_small"), I(7)},
      {str("int_neg"), I(-3)},
      {str("int_2b"), I(300)},
      {str("int_4b"), I(70000)},
      {str("int_big"), I(int64_t{1} << 40)},
      {str("int_neg_big"), I(-(int64_t{1} << 40))},
      {str("int_max"), I(std::numeric_limits<int64_t>::max())},
      {str("int_min"), I(std::numeric_limits<int64_t>::min())},
      {str("float"), Value::floating(2.5)},
      {str("inf"), Value::floating(std::numeric_limits<double>::infinity())},
      {str("str"), str("h\xc3\xa9llo w\xc3\xb6rld")},
      {str("bytes"), Value::bytes(std::string("\x00\xff"
                                              "abc",
                                              5))},
      {str("none"), Value()},
      {str("true"), Value::boolean(true)},
      {str("false"), Value::boolean(false)},
      {str("list"), Value::list({I(1), str("a"), Value::floating(2.0)})},
      {str("tuple"), Value::tuple({I(1), I(2), I(3), I(4)})},
      {str("tuple1"), Value::tuple({I(5)})},
      {str("empty_tuple"), Value::tuple({})},
      {str("nested"),
       Value::dict({{str("a"), Value::list({Value::dict({{str("b"), Value::tuple({I(1)})}})})}})},
      {str("set"), Value::set({I(1), I(2), I(3)})},
      {str("frozenset"), Value::set({I(4)})},
      {str("shared"), Value::list({shared, shared})},
      {str("f4"), arr(torch::arange(6, torch::kFloat).reshape({2, 3}))},
      {str("big_endian"), arr(torch::arange(6, torch::kInt))},
      {str("fortran"), arr(torch::arange(6, torch::kDouble).reshape({2, 3}))},
      {str("bools"), arr(torch::tensor({true, false, true}, torch::kBool))},
      {str("empty"), arr(torch::zeros({0, 3}, torch::kDouble))},
      {str("scalar_f8"), arr(torch::scalar_tensor(1.5, torch::kDouble))},
      {str("scalar_i8"), arr(torch::scalar_tensor(-5, torch::kLong))},
      {str("dtype"), Value::object("numpy.dtype", str(">f4"))},
      {str("objects"), Value::list({Value::dict({{str("a"), I(1)}}), str("x"), Value()})},
      {str("ordered"), Value::dict({{str("z"), I(1)}, {str("a"), I(2)}})},
      {str("dtypes"), Value::dict(dtypes)},
      {str("dtypes_be"), Value::dict(dtypes)},
      {str("dtypes_F"), Value::dict(dtypes)},
      {str("many"), Value::list(many)},
      {str("long_str"), str(std::string(70000, 'x'))},
      {str("big"), arr(torch::arange(20000, torch::kDouble) * 0.25)},
  });
}

TEST_CASE("parse_pickle reads the same mixed object written at protocols 2 to 5") {
  const Value expected = mixed_expected();
  for (int proto = 2; proto <= 5; ++proto) {
    const Value v = io::read_pickle(io_fixtures() / ("mixed_p" + std::to_string(proto) + ".pkl"));
    REQUIRE(v.size() == expected.size());
    for (const auto& [key, value] : expected.as_dict()) {
      INFO("protocol " << proto << ", key " << key.as_str() << ": got "
                       << v[key.as_str()].type_name());
      CHECK(v[key.as_str()] == value);
    }
    const torch::Tensor fortran = v["fortran"].as_tensor();
    CHECK(fortran.is_contiguous());
  }
}

// posedirs of make_io_fixtures.py's smpl_arrays.
torch::Tensor posedirs_formula(int64_t depth) {
  return (torch::arange(6890 * 3 * depth, torch::kLong).remainder(1000).to(torch::kDouble) * 0.001)
      .reshape({6890, 3, depth});
}

void check_smpl(const Value& model, std::map<std::string, torch::Tensor> expected,
                int64_t posedirs_depth) {
  expected["posedirs"] = posedirs_formula(posedirs_depth);
  for (const auto& [key, want] : expected) {
    INFO(key);
    const torch::Tensor got = model[key].as_tensor();
    CHECK(got.scalar_type() == want.scalar_type());
    CHECK(got.sizes() == want.sizes());
    CHECK(torch::equal(got, want));
  }
  CHECK(model["bs_style"].as_str() == "lbs");
  CHECK(model["bs_type"].as_str() == "lrotmin");
}

TEST_CASE(
    "parse_pickle reads a Python 3 SMPL model with densified scipy J_regressor and chumpy "
    "shapedirs") {
  const Value model = io::read_pickle(io_fixtures() / "smpl_py3_p2.pkl");
  const auto expected = io::read_npz(io_fixtures() / "smpl_py3_expected.npz");
  check_smpl(model, expected, 9);
  CHECK(torch::equal(model["J_regressor_csr"].as_tensor(), expected.at("J_regressor")));
  CHECK(model["bs_style"].kind() == Value::Kind::Str);
}

TEST_CASE(
    "parse_pickle reads a Python 2 protocol-2 SMPL pickle with BINSTRING data and copy_reg names") {
  const Value model = io::read_pickle(io_fixtures() / "smpl_py2.pkl");
  check_smpl(model, io::read_npz(io_fixtures() / "smpl_py2_expected.npz"), 207);
  CHECK(model["scale"] == arr(torch::tensor({1.5, 2.5}, torch::kDouble)));  // SHORT_BINSTRING data
  // Python 2 str arrives as (latin-1) bytes; lookups by name still work.
  CHECK(model["bs_style"].kind() == Value::Kind::Bytes);
  CHECK(model.as_dict().front().first.kind() == Value::Kind::Bytes);
}

// How fast this is (about one memcpy) is measured by transhuman-bench-io, not asserted here.
TEST_CASE("a 6890x3x207 float64 array from a pickle is read exactly, into storage of its own") {
  std::string bytes = read_bytes(io_fixtures() / "posedirs_p4.pkl");
  const Value v = io::parse_pickle(bytes, "posedirs_p4.pkl");
  const torch::Tensor posedirs = v["posedirs"].as_tensor();
  CHECK(posedirs.sizes() == torch::IntArrayRef({6890, 3, 207}));
  CHECK(posedirs.is_contiguous());
  CHECK(posedirs.storage().nbytes() == size_t(6890) * 3 * 207 * sizeof(double));
  CHECK(torch::equal(posedirs, posedirs_formula(207)));
  // The input buffer can go: the tensor does not point into it.
  std::fill(bytes.begin(), bytes.end(), '\0');
  bytes.clear();
  bytes.shrink_to_fit();
  CHECK(torch::equal(posedirs, posedirs_formula(207)));
}

TEST_CASE("parse_pickle follows the memo and the stack and frame and set and text opcodes") {
  using namespace std::string_literals;
  const auto p = [](const std::string& bytes) { return io::parse_pickle(bytes, "hand.pkl"); };
  const Value l12 = Value::list({I(1), I(2)});
  CHECK(p("\x80\x02]q\x00(K\x01K\x02"
          "eh\x00\x86."s) == Value::tuple({l12, l12}));
  CHECK(p("\x80\x02K\x05"
          "2\x86."s) == Value::tuple({I(5), I(5)}));  // DUP
  CHECK(p("\x80\x02K\x01K\x02"
          "0."s) == I(1));  // POP
  CHECK(p("\x80\x02K\x07(K\x01K\x02"
          "1."s) == I(7));  // POP_MARK
  CHECK(p("(I42\nI01\nF2.5\nL123L\nl."s) ==
        Value::list({I(42), Value::boolean(true), Value::floating(2.5), I(123)}));  // protocol 0
  CHECK(p("(I3\np0\ng0\nl."s) == Value::list({I(3), I(3)}));                        // PUT/GET
  CHECK(p("\x80\x04\x8c\x02hi\x94j\x00\x00\x00\x00\x86."s) ==
        Value::tuple({str("hi"), str("hi")}));                              // MEMOIZE
  CHECK(p("\x80\x04\x95\x03\x00\x00\x00\x00\x00\x00\x00K\x01."s) == I(1));  // FRAME
  CHECK(p("\x80\x02\x8a\x09\xff\xff\xff\xff\xff\xff\xff\x7f\x00."s) ==
        I(std::numeric_limits<int64_t>::max()));
  CHECK(p("\x80\x02\x8b\x02\x00\x00\x00\xff\x7f."s) == I(32767));  // LONG4
  CHECK(p("\x80\x02\x8a\x01\xff."s) == I(-1));
  CHECK(p("\x80\x02G?\xf8\x00\x00\x00\x00\x00\x00."s) == Value::floating(1.5));  // BINFLOAT
  CHECK(p("\x80\x04\x8f(K\x01K\x02K\x01\x90."s) ==
        Value::set({I(1), I(2)}));                         // ADDITEMS, deduplicated
  CHECK(p("\x80\x04(K\x04\x91."s) == Value::set({I(4)}));  // FROZENSET
  // A repeated dict key keeps its first position and its last value, as in Python.
  CHECK(p("\x80\x02}(K\x01K\x02K\x05K\x06K\x01K\x03u."s) ==
        Value::dict({{I(1), I(3)}, {I(5), I(6)}}));
  CHECK(p("\x80\x02U\x03"
          "abc."s) == Value::bytes("abc"));                         // SHORT_BINSTRING
  CHECK(p("\x80\x02T\x02\x00\x00\x00hi."s) == Value::bytes("hi"));  // BINSTRING
  CHECK(p("\x80\x05\x96\x02\x00\x00\x00\x00\x00\x00\x00hi\x98."s) ==
        Value::bytes("hi"));  // BYTEARRAY8
  // Python 2 set via REDUCE on a list, and bytes via _codecs.encode.
  CHECK(p("\x80\x02"
          "c__builtin__\nset\n]K\x01"
          "a\x85R."s) == Value::set({I(1)}));
  CHECK(p("\x80\x02"
          "c_codecs\nencode\nX\x02\x00\x00\x00\xc3\xa9X\x06\x00\x00\x00latin1\x86R."s) ==
        Value::bytes("\xe9"));
}

TEST_CASE("parse_pickle reads numpy 2 global names (numpy._core)") {
  // pickle.dumps(np.float64(1.5), 2) with numpy._core.multiarray instead of numpy.core.multiarray.
  using namespace std::string_literals;
  const std::string bytes =
      "\x80\x02"
      "cnumpy._core.multiarray\nscalar\n"
      "cnumpy\ndtype\nX\x02\x00\x00\x00"
      "f8\x89\x88\x87R"
      "(K\x03X\x01\x00\x00\x00<NNNJ\xff\xff\xff\xffJ\xff\xff\xff\xffK\x00tb"
      "C\x08\x00\x00\x00\x00\x00\x00\xf8?\x86R."s;
  CHECK(io::parse_pickle(bytes, "np2.pkl") == arr(torch::scalar_tensor(1.5, torch::kDouble)));
}

TEST_CASE("parse_pickle reads arrays pickled under numpy 2's numpy._core names") {
  const Value v = Value::list({arr(dtype_values("f8")), arr(dtype_values("i4"))});
  for (int proto = 2; proto <= 4; ++proto) {
    std::string bytes = io::pickle_bytes(v, proto);
    const std::string from = "numpy.core.multiarray", to = "numpy._core.multiarray";
    const size_t at = bytes.find(from);
    REQUIRE(at != std::string::npos);
    bytes.replace(at, from.size(), to);
    if (proto == 4) bytes[at - 1] = static_cast<char>(to.size());  // SHORT_BINUNICODE length
    if (proto == 4) bytes.replace(2, 9, "");                       // drop the (now wrong) FRAME
    INFO("protocol " << proto);
    CHECK(io::parse_pickle(bytes, "np2.pkl") == v);
  }
}

TEST_CASE("read_pickle names the file when it cannot be opened") {
  CHECK_THAT(error_of([] { io::read_pickle("/nonexistent/model.pkl"); }),
             Catch::Contains("/nonexistent/model.pkl"));
}

}  // namespace
}  // namespace th::test
