// Value, the tree a pickle is read into and written from (METHOD 1.4).
#include <cmath>

#include "core/error.hpp"
#include "io/bytes.hpp"
#include "io/pickle.hpp"

namespace th::io {

namespace {

std::string tensor_type_name(const torch::Tensor& t) {
  std::string dtype;
  switch (t.scalar_type()) {
    case torch::kFloat:
      dtype = "float32";
      break;
    case torch::kDouble:
      dtype = "float64";
      break;
    case torch::kHalf:
      dtype = "float16";
      break;
    case torch::kChar:
      dtype = "int8";
      break;
    case torch::kShort:
      dtype = "int16";
      break;
    case torch::kInt:
      dtype = "int32";
      break;
    case torch::kLong:
      dtype = "int64";
      break;
    case torch::kByte:
      dtype = "uint8";
      break;
    case torch::kBool:
      dtype = "bool";
      break;
    default:
      dtype = c10::toString(t.scalar_type());
      break;
  }
  return "ndarray " + dtype + " " + detail::shape_repr(t.sizes().vec());
}

}  // namespace

Value Value::boolean(bool v) {
  Value r;
  r.v_ = v;
  r.kind_ = Kind::Bool;
  return r;
}
Value Value::integer(int64_t v) {
  Value r;
  r.v_ = v;
  r.kind_ = Kind::Int;
  return r;
}
Value Value::floating(double v) {
  Value r;
  r.v_ = v;
  r.kind_ = Kind::Float;
  return r;
}
Value Value::str(std::string v) {
  Value r;
  r.v_ = std::move(v);
  r.kind_ = Kind::Str;
  return r;
}
Value Value::bytes(std::string v) {
  Value r;
  r.v_ = std::move(v);
  r.kind_ = Kind::Bytes;
  return r;
}
Value Value::list(List v) {
  Value r;
  r.v_ = std::move(v);
  r.kind_ = Kind::List;
  return r;
}
Value Value::tuple(List v) {
  Value r;
  r.v_ = std::move(v);
  r.kind_ = Kind::Tuple;
  return r;
}
Value Value::set(List v) {
  Value r;
  r.v_ = std::move(v);
  r.kind_ = Kind::Set;
  return r;
}
Value Value::dict(Dict v) {
  Value r;
  r.v_ = std::move(v);
  r.kind_ = Kind::Dict;
  return r;
}
Value Value::array(torch::Tensor v) {
  TORCH_CHECK(v.defined(), "Value::array: undefined tensor");
  Value r;
  r.v_ = std::move(v);
  r.kind_ = Kind::Array;
  return r;
}
Value Value::object(std::string cls, Value state) {
  Value r;
  r.v_ = Object{std::move(cls), std::make_shared<Value>(std::move(state))};
  r.kind_ = Kind::Object;
  return r;
}

Value::Kind Value::kind() const { return kind_; }

std::string Value::type_name() const {
  switch (kind_) {
    case Kind::None:
      return "None";
    case Kind::Bool:
      return "bool";
    case Kind::Int:
      return "int";
    case Kind::Float:
      return "float";
    case Kind::Str:
      return "str";
    case Kind::Bytes:
      return "bytes";
    case Kind::List:
      return "list";
    case Kind::Tuple:
      return "tuple";
    case Kind::Dict:
      return "dict";
    case Kind::Set:
      return "set";
    case Kind::Array:
      return tensor_type_name(std::get<torch::Tensor>(v_));
    case Kind::Object:
      return "object " + std::get<Object>(v_).cls;
  }
  return "?";
}

namespace {
[[noreturn]] void type_error(const char* expected, const Value& got) {
  th::fail("expected ", expected, ", got ", got.type_name());
}
}  // namespace

bool Value::as_bool() const {
  if (kind_ == Kind::Bool) return std::get<bool>(v_);
  if (kind_ == Kind::Int || kind_ == Kind::Array) {
    const int64_t v = as_int();
    if (v == 0 || v == 1) return v == 1;
  }
  type_error("a bool", *this);
}

int64_t Value::as_int() const {
  if (kind_ == Kind::Int) return std::get<int64_t>(v_);
  if (kind_ == Kind::Bool) return std::get<bool>(v_) ? 1 : 0;
  if (kind_ == Kind::Array) {
    const auto& t = std::get<torch::Tensor>(v_);
    if (t.numel() == 1 && !t.is_floating_point())
      return t.reshape({}).to(torch::kLong).item<int64_t>();
  }
  type_error("an int", *this);
}

double Value::as_float() const {
  if (kind_ == Kind::Float) return std::get<double>(v_);
  if (kind_ == Kind::Int) return static_cast<double>(std::get<int64_t>(v_));
  if (kind_ == Kind::Bool) return std::get<bool>(v_) ? 1.0 : 0.0;
  if (kind_ == Kind::Array) {
    const auto& t = std::get<torch::Tensor>(v_);
    if (t.numel() == 1) return t.reshape({}).to(torch::kDouble).item<double>();
  }
  type_error("a float", *this);
}

const std::string& Value::as_str() const {
  if (kind_ == Kind::Str || kind_ == Kind::Bytes) return std::get<std::string>(v_);
  type_error("a str", *this);
}

const Value::List& Value::as_list() const {
  if (kind_ == Kind::List || kind_ == Kind::Tuple || kind_ == Kind::Set) return std::get<List>(v_);
  type_error("a list", *this);
}

const Value::Dict& Value::as_dict() const {
  if (kind_ == Kind::Dict) return std::get<Dict>(v_);
  type_error("a dict", *this);
}

const Value::Object& Value::as_object() const {
  if (kind_ == Kind::Object) return std::get<Object>(v_);
  type_error("an object", *this);
}

torch::Tensor Value::as_tensor() const {
  switch (kind_) {
    case Kind::Array:
      return std::get<torch::Tensor>(v_);
    case Kind::Bool:
      return torch::scalar_tensor(std::get<bool>(v_), torch::kBool);
    case Kind::Int:
      return torch::scalar_tensor(std::get<int64_t>(v_), torch::kLong);
    case Kind::Float:
      return torch::scalar_tensor(std::get<double>(v_), torch::kDouble);
    case Kind::List:
    case Kind::Tuple: {
      const auto& items = std::get<List>(v_);
      if (items.empty()) return torch::empty({0}, torch::kDouble);
      std::vector<torch::Tensor> parts;
      parts.reserve(items.size());
      for (const auto& item : items) parts.push_back(item.as_tensor());
      torch::ScalarType type = parts[0].scalar_type();
      for (const auto& p : parts) {
        if (p.sizes() != parts[0].sizes()) {
          th::fail("cannot make an array of a ", type_name(), " whose items have different shapes ",
                   detail::shape_repr(parts[0].sizes().vec()), " and ",
                   detail::shape_repr(p.sizes().vec()));
        }
        type = torch::promote_types(type, p.scalar_type());
      }
      for (auto& p : parts) p = p.to(type);
      return torch::stack(parts);
    }
    default:
      type_error("an array or numbers", *this);
  }
}

const Value* Value::find(std::string_view key) const {
  if (kind_ != Kind::Dict) return nullptr;
  for (const auto& [k, v] : std::get<Dict>(v_)) {
    if ((k.kind_ == Kind::Str || k.kind_ == Kind::Bytes) && std::get<std::string>(k.v_) == key)
      return &v;
  }
  return nullptr;
}

const Value& Value::operator[](std::string_view key) const {
  const Dict& d = as_dict();
  if (const Value* v = find(key)) return *v;
  std::string present;
  size_t shown = 0;
  for (const auto& entry : d) {
    if (shown == 12) {
      present += ", ...";
      break;
    }
    if (shown++ > 0) present += ", ";
    const Value& k = entry.first;
    present +=
        (k.kind_ == Kind::Str || k.kind_ == Kind::Bytes) ? "'" + k.as_str() + "'" : k.type_name();
  }
  th::fail("missing key '", key, "' (keys: ", present.empty() ? "none" : present, ")");
}

const Value& Value::at(size_t index) const {
  const List& items = as_list();
  if (index >= items.size()) {
    th::fail("index ", index, " out of range for a ", type_name(), " of ", items.size(), " items");
  }
  return items[index];
}

size_t Value::size() const {
  if (kind_ == Kind::Dict) return std::get<Dict>(v_).size();
  return as_list().size();
}

bool Value::operator==(const Value& other) const {
  if (kind_ != other.kind_) return false;
  switch (kind_) {
    case Kind::None:
      return true;
    case Kind::Bool:
      return std::get<bool>(v_) == std::get<bool>(other.v_);
    case Kind::Int:
      return std::get<int64_t>(v_) == std::get<int64_t>(other.v_);
    case Kind::Float: {
      const double a = std::get<double>(v_), b = std::get<double>(other.v_);
      return a == b || (std::isnan(a) && std::isnan(b));
    }
    case Kind::Str:
    case Kind::Bytes:
      return std::get<std::string>(v_) == std::get<std::string>(other.v_);
    case Kind::List:
    case Kind::Tuple:
    case Kind::Set:
      return std::get<List>(v_) == std::get<List>(other.v_);
    case Kind::Dict:
      return std::get<Dict>(v_) == std::get<Dict>(other.v_);
    case Kind::Array: {
      const auto& a = std::get<torch::Tensor>(v_);
      const auto& b = std::get<torch::Tensor>(other.v_);
      if (a.scalar_type() != b.scalar_type() || a.sizes() != b.sizes()) return false;
      if (a.is_floating_point()) {
        // NaN == NaN, as in the scalar case.
        return torch::logical_or(a.eq(b), torch::logical_and(a.isnan(), b.isnan()))
            .all()
            .item<bool>();
      }
      return torch::equal(a, b);
    }
    case Kind::Object: {
      const auto& a = std::get<Object>(v_);
      const auto& b = std::get<Object>(other.v_);
      if (a.cls != b.cls) return false;
      if (!a.state || !b.state) return !a.state && !b.state;
      return *a.state == *b.state;
    }
  }
  return false;
}

}  // namespace th::io
