// Value, the tree pickles are read into.
#include "io_objects.hpp"

namespace th::test {
namespace {

TEST_CASE("Value typed access names the expected and the actual type on a mismatch") {
  CHECK_THAT(error_of([] { Value::str("x").as_int(); }),
             Catch::Contains("expected an int, got str"));
  CHECK_THAT(error_of([] { Value::integer(1).as_dict(); }),
             Catch::Contains("expected a dict, got int"));
  CHECK_THAT(error_of([] {
               arr(torch::zeros({6890, 3}, torch::kDouble)).as_list();
             }),
             Catch::Contains("got ndarray float64 (6890, 3)"));
  CHECK(Value::integer(3).as_float() == 3.0);
  CHECK(Value::boolean(true).as_int() == 1);
  CHECK(arr(torch::scalar_tensor(2.5, torch::kDouble)).as_float() == 2.5);  // numpy scalar
  CHECK(arr(torch::scalar_tensor(7, torch::kLong)).as_int() == 7);
  CHECK(Value::bytes("latin").as_str() == "latin");
}

TEST_CASE("Value::operator[] names the missing key and lists the keys present") {
  const Value d = params_value();
  CHECK_THAT(error_of([&] { d["betas"]; }),
             Catch::Contains("missing key 'betas'") && Catch::Contains("'poses'"));
  CHECK_THAT(error_of([&] { d.at(0); }), Catch::Contains("expected a list"));
  CHECK_THAT(error_of([] { Value::list({}).at(2); }), Catch::Contains("index 2 out of range"));
}

TEST_CASE("Value::find matches Python 2 bytes keys as well as str keys") {
  const Value d =
      Value::dict({{Value::bytes("f"), Value::integer(1)}, {Value::str("g"), Value::integer(2)}});
  CHECK(d["f"].as_int() == 1);
  CHECK(d["g"].as_int() == 2);
  CHECK(d.contains("g"));
  CHECK_FALSE(d.contains("h"));
  CHECK(Value::integer(1).find("x") == nullptr);
}

TEST_CASE("Value::as_tensor stacks lists of numbers and of equally shaped arrays like np.array") {
  CHECK(torch::equal(Value::list({Value::integer(1), Value::integer(2)}).as_tensor(),
                     torch::tensor({1, 2}, torch::kLong)));
  CHECK(torch::equal(Value::list({Value::integer(1), Value::floating(2.5)}).as_tensor(),
                     torch::tensor({1.0, 2.5}, torch::kDouble)));
  const Value K = annots_value(3, 1)["cams"]["K"];
  const torch::Tensor stacked = K.as_tensor();
  CHECK(stacked.sizes() == torch::IntArrayRef({3, 3, 3}));
  CHECK(stacked[2][0][0].item<double>() == 1002.0);
  CHECK_THAT(error_of([] {
               Value::list({arr(torch::zeros({2})), arr(torch::zeros({3}))}).as_tensor();
             }),
             Catch::Contains("different shapes"));
  CHECK_THAT(error_of([] { Value::str("x").as_tensor(); }), Catch::Contains("got str"));
}

TEST_CASE("Value equality is deep and compares arrays by dtype and shape and values") {
  CHECK(annots_value(2, 1) == annots_value(2, 1));
  CHECK(annots_value(2, 1) != annots_value(3, 1));
  CHECK(arr(torch::zeros({2}, torch::kDouble)) != arr(torch::zeros({2}, torch::kFloat)));
  CHECK(arr(torch::zeros({2})) != arr(torch::zeros({1, 2})));
  CHECK(Value::integer(1) != Value::floating(1.0));
  CHECK(Value::str("a") != Value::bytes("a"));
  CHECK(Value::list({}) != Value::tuple({}));
  CHECK(Value::floating(std::nan("")) == Value::floating(std::nan("")));
  CHECK(Value::object("numpy.dtype", Value::str("<f8")) ==
        Value::object("numpy.dtype", Value::str("<f8")));
}

TEST_CASE("Value::type_name describes every kind") {
  CHECK(Value().type_name() == "None");
  CHECK(Value::set({}).type_name() == "set");
  CHECK(arr(torch::zeros({0}, torch::kBool)).type_name() == "ndarray bool (0,)");
  CHECK(arr(torch::scalar_tensor(1, torch::kByte)).type_name() == "ndarray uint8 ()");
  CHECK(Value::object("numpy.dtype", Value()).type_name() == "object numpy.dtype");
}

}  // namespace
}  // namespace th::test
