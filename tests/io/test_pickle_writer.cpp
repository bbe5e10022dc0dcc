// The pickle writer: byte-identical to CPython 3.11 + numpy 1.24 (checked by Python itself).
#include "io_objects.hpp"

namespace th::test {
namespace {

TEST_CASE(
    "pickle_bytes is byte-identical to pickle.dumps at protocols 2 to 4 including frames and "
    "batches") {
  const fs::path dir = scratch_dir("io_pickle_writer");
  for (int proto = 2; proto <= 4; ++proto) {
    const std::string p = std::to_string(proto);
    io::write_pickle(dir / ("writer_p" + p + ".pkl"), writer_value(), proto);
    io::write_pickle(dir / ("big_p" + p + ".pkl"), writer_big_value(), proto);
    io::write_pickle(dir / ("batches_p" + p + ".pkl"), writer_batches_value(), proto);
  }
  CHECK(check_written("pickle", dir) == 0);
}

TEST_CASE("pickle_bytes output reads back as the same Value") {
  for (int proto = 2; proto <= 4; ++proto) {
    INFO("protocol " << proto);
    for (const Value& v :
         {writer_value(), writer_batches_value(), annots_value(2, 2), params_value()}) {
      CHECK(io::parse_pickle(io::pickle_bytes(v, proto), "roundtrip.pkl") == v);
    }
  }
}

TEST_CASE("sets are pickled so that Python reads the same set") {
  const fs::path dir = scratch_dir("io_pickle_sets");
  const Value v = Value::dict({
      {str("s"), Value::set({Value::integer(1), str("a"),
                             Value::tuple({Value::integer(2), Value::integer(3)})})},
      {str("e"), Value::set({})},
  });
  for (int proto = 2; proto <= 4; ++proto) {
    io::write_pickle(dir / ("set_p" + std::to_string(proto) + ".pkl"), v, proto);
    CHECK(io::read_pickle(dir / ("set_p" + std::to_string(proto) + ".pkl")) == v);
  }
  CHECK(check_written("sets", dir) == 0);
}

TEST_CASE("the same tensor twice is pickled once and referenced through the memo") {
  const torch::Tensor t = torch::arange(1000, torch::kDouble);
  const std::string once = io::pickle_bytes(Value::list({arr(t)}), 3);
  const std::string twice = io::pickle_bytes(Value::list({arr(t), arr(t)}), 3);
  CHECK(twice.size() < once.size() + 16);
  CHECK(io::parse_pickle(twice, "twice.pkl") == Value::list({arr(t), arr(t)}));
}

TEST_CASE("pickle_bytes refuses protocols outside 2-4 and Object values and types numpy lacks") {
  CHECK_THAT(error_of([] { io::pickle_bytes(Value(), 5); }), Catch::Contains("protocol 5"));
  CHECK_THAT(error_of([] { io::pickle_bytes(Value::object("numpy.dtype", str("<f8")), 3); }),
             Catch::Contains("cannot pickle"));
  CHECK_THAT(error_of([] { io::pickle_bytes(arr(torch::zeros({2}, torch::kComplexFloat)), 3); }),
             Catch::Contains("numpy has no dtype"));
}

}  // namespace
}  // namespace th::test
