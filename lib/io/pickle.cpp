// The pickle reader (a stack machine over a whitelist; SPEC 1.4) and Value.
#include "io/pickle.hpp"

#include <algorithm>
#include <charconv>
#include <cmath>
#include <cstring>
#include <deque>
#include <optional>
#include <unordered_map>

#include "core/error.hpp"
#include "io/bytes.hpp"
#include "io/dtype.hpp"

namespace th::io {

// ---------------------------------------------------------------------------------------------
// Value

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

// ---------------------------------------------------------------------------------------------
// Reader

namespace {

// Classes and functions a pickle may name. Anything else is refused.
enum class Global {
  Reconstruct,   // numpy.core.multiarray._reconstruct(ndarray, shape, typecode) + BUILD
  Scalar,        // numpy.core.multiarray.scalar(dtype, bytes)
  FromBuffer,    // numpy.core.numeric._frombuffer(buffer, dtype, shape, order) (protocol 5)
  NdArray,       // numpy.ndarray (argument of _reconstruct)
  DTypeClass,    // numpy.dtype(code, align, copy) + BUILD(state)
  CodecsEncode,  // _codecs.encode(str, 'latin1'): bytes at protocol 2
  Set,
  FrozenSet,
  Bytes,
  Bytearray,
  Object,         // builtins.object (argument of copyreg._reconstructor)
  Reconstructor,  // copyreg._reconstructor(cls, object, None)
  OrderedDict,
  Csc,     // scipy.sparse csc_matrix / csc_array
  Csr,     // scipy.sparse csr_matrix / csr_array
  Chumpy,  // chumpy.ch.Ch
  Extension,  // a global of PickleExtensions::globals
  PlainClass,  // a class under PickleExtensions::class_prefixes: NEWOBJ + BUILD(dict)
};

std::optional<Global> lookup_global(std::string_view module_in, std::string_view name) {
  std::string module(module_in);
  if (module == "__builtin__") module = "builtins";  // Python 2 names
  if (module == "copy_reg") module = "copyreg";
  if (module.rfind("numpy._core", 0) == 0) module = "numpy.core" + module.substr(11);  // numpy 2
  static const std::unordered_map<std::string, Global> table = {
      {"numpy.core.multiarray._reconstruct", Global::Reconstruct},
      {"numpy.core._multiarray_umath._reconstruct", Global::Reconstruct},
      {"numpy.core.multiarray.scalar", Global::Scalar},
      {"numpy.core._multiarray_umath.scalar", Global::Scalar},
      {"numpy.core.numeric._frombuffer", Global::FromBuffer},
      {"numpy.ndarray", Global::NdArray},
      {"numpy.dtype", Global::DTypeClass},
      {"_codecs.encode", Global::CodecsEncode},
      {"builtins.set", Global::Set},
      {"builtins.frozenset", Global::FrozenSet},
      {"builtins.bytes", Global::Bytes},
      {"builtins.bytearray", Global::Bytearray},
      {"builtins.object", Global::Object},
      {"copyreg._reconstructor", Global::Reconstructor},
      {"collections.OrderedDict", Global::OrderedDict},
      {"scipy.sparse.csc.csc_matrix", Global::Csc},
      {"scipy.sparse._csc.csc_matrix", Global::Csc},
      {"scipy.sparse._csc.csc_array", Global::Csc},
      {"scipy.sparse._arrays.csc_array", Global::Csc},
      {"scipy.sparse.csr.csr_matrix", Global::Csr},
      {"scipy.sparse._csr.csr_matrix", Global::Csr},
      {"scipy.sparse._csr.csr_array", Global::Csr},
      {"scipy.sparse._arrays.csr_array", Global::Csr},
      {"chumpy.ch.Ch", Global::Chumpy},
  };
  const auto it = table.find(module + "." + std::string(name));
  if (it == table.end()) return std::nullopt;
  return it->second;
}

bool is_instance_class(Global g) {
  return g == Global::Csc || g == Global::Csr || g == Global::Chumpy || g == Global::PlainClass;
}

// One Python object while unpickling. Objects reference each other by pointer (the memo shares
// them, BUILD and APPEND mutate them, as in Python); all live in the Unpickler's arena, so
// cycles and deep chains cost nothing to free.
struct Node {
  enum class T : uint8_t {
    None,
    Bool,
    Int,
    Float,
    Str,
    Bytes,
    List,
    Tuple,
    Dict,
    Set,
    FrozenSet,
    Global,        // i: Global, name: dotted name
    DType,         // dtype
    Array,         // tensor
    ObjArray,      // object-dtype array: items (flat), shape, i: Fortran order
    PendingArray,  // _reconstruct result waiting for BUILD
    Instance,      // name: class, i: Global, state: merged __dict__ (a Dict node) or null
    Opaque,        // value: made by a PickleExtensions callback
  };
  T t = T::None;
  size_t pos = 0;  // offset of the opcode that made it
  int64_t i = 0;
  double f = 0;
  std::string_view text;  // Str (UTF-8) / Bytes: into the input or into `owned`
  std::string owned;
  std::vector<Node*> items;  // List/Tuple/Set/FrozenSet/ObjArray; Dict: k0, v0, k1, v1, ...
  std::string name;
  detail::NpyDType dtype;
  std::vector<int64_t> shape;
  torch::Tensor tensor;
  Node* state = nullptr;
  std::shared_ptr<Value> value;
};

// Array::name of a numpy scalar (numpy.core.multiarray.scalar), which Python hashes like the
// equal int, float or bool: such keys become plain keys.
constexpr const char* kNumpyScalar = "numpy scalar";

bool is_numpy_scalar(const Node* n) {
  return n->t == Node::T::Array && n->name == kNumpyScalar && n->tensor.dim() == 0 &&
         !n->tensor.is_complex();
}

const char* node_type_name(const Node* n) {
  switch (n->t) {
    case Node::T::None:
      return "None";
    case Node::T::Bool:
      return "bool";
    case Node::T::Int:
      return "int";
    case Node::T::Float:
      return "float";
    case Node::T::Str:
      return "str";
    case Node::T::Bytes:
      return "bytes";
    case Node::T::List:
      return "list";
    case Node::T::Tuple:
      return "tuple";
    case Node::T::Dict:
      return "dict";
    case Node::T::Set:
      return "set";
    case Node::T::FrozenSet:
      return "frozenset";
    case Node::T::Global:
      return "global";
    case Node::T::DType:
      return "numpy.dtype";
    case Node::T::Array:
      return "ndarray";
    case Node::T::ObjArray:
      return "object ndarray";
    case Node::T::PendingArray:
      return "ndarray without data";
    case Node::T::Instance:
    case Node::T::Opaque:
      return "object";
  }
  return "?";
}

std::string describe(const Node* n) {
  if (n->t == Node::T::Global || n->t == Node::T::Instance)
    return std::string(node_type_name(n)) + " " + n->name;
  return node_type_name(n);
}

// Dense matrices from scipy.sparse may not exceed this many elements.
constexpr int64_t kMaxDenseElements = int64_t{1} << 26;
constexpr int kMaxDims = 32;  // numpy's NPY_MAXDIMS

// Node -> Value, checking depth (recursive structures end here too) and the total work, so
// that memo sharing cannot blow a small file up into an exponentially large tree.
class Converter {
 public:
  Converter(const std::string& name, size_t input_size)
      : name_(name),
        node_budget_(std::max<size_t>(size_t{1} << 20, 16 * input_size)),
        byte_budget_(std::max<size_t>(size_t{64} << 20, 8 * input_size)) {}

  Value convert(Node* n, int depth) {
    if (depth > kMaxDepth) {
      th::fail(name_, ": nesting deeper than ", kMaxDepth,
               " levels (or a recursive structure) at the ", describe(n), " made at byte ", n->pos);
    }
    if (++nodes_ > node_budget_) {
      th::fail(name_, ": the pickle expands to more than ", node_budget_,
               " objects through shared references (made at byte ", n->pos, ")");
    }
    switch (n->t) {
      case Node::T::None:
        return Value();
      case Node::T::Bool:
        return Value::boolean(n->i != 0);
      case Node::T::Int:
        return Value::integer(n->i);
      case Node::T::Float:
        return Value::floating(n->f);
      case Node::T::Str:
        return Value::str(take_text(n));
      case Node::T::Bytes:
        return Value::bytes(take_text(n));
      case Node::T::List:
      case Node::T::Tuple: {
        Value::List items;
        items.reserve(n->items.size());
        for (Node* item : n->items) items.push_back(convert(item, depth + 1));
        return n->t == Node::T::List ? Value::list(std::move(items))
                                     : Value::tuple(std::move(items));
      }
      case Node::T::Set:
      case Node::T::FrozenSet: {
        Value::List items;
        std::unordered_map<std::string, size_t> seen;
        for (Node* item : n->items) {
          if (seen.emplace(key_of(item, depth + 1), items.size()).second)
            items.push_back(key_value(item, depth + 1));
        }
        return Value::set(std::move(items));
      }
      case Node::T::Dict: {
        Value::Dict entries;
        std::unordered_map<std::string, size_t> seen;
        for (size_t k = 0; k + 1 < n->items.size(); k += 2) {
          const auto [it, fresh] = seen.emplace(key_of(n->items[k], depth + 1), entries.size());
          Value value = convert(n->items[k + 1], depth + 1);
          if (fresh) {
            entries.emplace_back(key_value(n->items[k], depth + 1), std::move(value));
          } else {
            entries[it->second].second = std::move(value);  // Python keeps the first key
          }
        }
        return Value::dict(std::move(entries));
      }
      case Node::T::Array:
        return Value::array(n->tensor);
      case Node::T::ObjArray:
        return object_array(n, depth);
      case Node::T::PendingArray:
        th::fail(name_, ": the ndarray made at byte ", n->pos,
                 " never received its data (no BUILD)");
      case Node::T::DType:
        return Value::object("numpy.dtype", Value::str(n->dtype.descr()));
      case Node::T::Global:
        return Value::object(n->name, Value());
      case Node::T::Instance:
        return instance(n, depth);
      case Node::T::Opaque:
        return *n->value;
    }
    th::fail(name_, ": internal error converting the object made at byte ", n->pos);
  }

 private:
  std::string take_text(const Node* n) {
    bytes_ += n->text.size();
    if (bytes_ > byte_budget_) {
      th::fail(name_, ": the pickle expands to more than ", byte_budget_,
               " bytes of strings through shared references (made at byte ", n->pos, ")");
    }
    return std::string(n->text);
  }

  // A numpy scalar as the plain Python value it equals: bool, int or float.
  static Value plain_value(const Node* n) {
    const auto& t = n->tensor;
    if (t.scalar_type() == torch::kBool) return Value::boolean(t.item<bool>());
    if (t.is_floating_point()) return Value::floating(t.item<double>());
    return Value::integer(t.item<int64_t>());
  }
  static std::string plain_key(const Node* n) {
    const auto& t = n->tensor;
    if (!t.is_floating_point()) return "i" + std::to_string(t.item<int64_t>()) + ";";
    return float_key(t.item<double>(), n);
  }
  // NaN equals only itself (the same object), so its key is the node's identity.
  static std::string float_key(double f, const Node* identity) {
    if (std::isfinite(f) && f == std::floor(f) && std::fabs(f) < 9.2e18) {
      return "i" + std::to_string(static_cast<int64_t>(f)) + ";";
    }
    if (std::isnan(f)) return "nan@" + std::to_string(reinterpret_cast<uintptr_t>(identity)) + ";";
    uint64_t bits = 0;
    std::memcpy(&bits, &f, sizeof bits);
    return "f" + std::to_string(bits) + ";";
  }
  // Dict keys and set elements: numpy scalars become the equal plain value.
  Value key_value(Node* n, int depth) { return is_numpy_scalar(n) ? plain_value(n) : convert(n, depth); }

  // Python's hash equality for the key types pickles use (1 == 1.0 == True).
  std::string key_of(const Node* n, int depth) {
    if (depth > kMaxDepth)
      th::fail(name_, ": dict key nested deeper than ", kMaxDepth, " levels at byte ", n->pos);
    if (++nodes_ > node_budget_) {
      th::fail(name_, ": the pickle expands to more than ", node_budget_,
               " objects through shared references (made at byte ", n->pos, ")");
    }
    switch (n->t) {
      case Node::T::None:
        return "N";
      case Node::T::Bool:
      case Node::T::Int:
        return "i" + std::to_string(n->i) + ";";
      case Node::T::Float:
        return float_key(n->f, n);
      case Node::T::Str:
        return "s" + std::to_string(n->text.size()) + ":" + std::string(n->text);
      case Node::T::Bytes:
        return "b" + std::to_string(n->text.size()) + ":" + std::string(n->text);
      case Node::T::Tuple: {
        std::string key = "t" + std::to_string(n->items.size()) + "(";
        for (const Node* item : n->items) key += key_of(item, depth + 1);
        return key + ")";
      }
      case Node::T::FrozenSet: {
        std::vector<std::string> keys;
        for (const Node* item : n->items) keys.push_back(key_of(item, depth + 1));
        std::sort(keys.begin(), keys.end());
        keys.erase(std::unique(keys.begin(), keys.end()), keys.end());
        std::string key = "F" + std::to_string(keys.size()) + "(";
        for (const auto& k : keys) key += k;
        return key + ")";
      }
      case Node::T::Global:
        return "g" + n->name + ";";
      case Node::T::DType:
        return "d" + n->dtype.descr() + ";";
      case Node::T::Array:
        if (is_numpy_scalar(n)) return plain_key(n);
        [[fallthrough]];
      default:
        th::fail(name_, ": unhashable ", describe(n), " (made at byte ", n->pos,
                 ") used as a dict key or set element");
    }
  }

  // ndarray.tolist() of an object array; a 0-d one is the object itself.
  Value object_array(Node* n, int depth) {
    if (n->shape.empty()) return convert(n->items.at(0), depth + 1);
    const size_t ndim = n->shape.size();
    std::vector<Node*> flat = n->items;
    if (n->i != 0 && ndim > 1) {  // Fortran order: reorder into C order
      std::vector<int64_t> index(ndim, 0);
      for (size_t c = 0; c < flat.size(); ++c) {
        int64_t f = 0, stride = 1;
        for (size_t d = 0; d < ndim; ++d) {
          f += index[d] * stride;
          stride *= n->shape[d];
        }
        flat[c] = n->items[static_cast<size_t>(f)];
        for (size_t d = ndim; d-- > 0;) {
          if (++index[d] < n->shape[d]) break;
          index[d] = 0;
        }
      }
    }
    size_t next = 0;
    return nest(n, flat, 0, next, depth);
  }

  Value nest(Node* n, const std::vector<Node*>& flat, size_t dim, size_t& next, int depth) {
    if (depth > kMaxDepth) th::fail(name_, ": object array at byte ", n->pos, " nested too deeply");
    Value::List items;
    for (int64_t k = 0; k < n->shape[dim]; ++k) {
      if (dim + 1 == n->shape.size()) {
        items.push_back(convert(flat[next++], depth + 1));
      } else {
        items.push_back(nest(n, flat, dim + 1, next, depth + 1));
      }
    }
    return Value::list(std::move(items));
  }

  // The last value of a str/bytes key in a Dict node (Python keeps the last assignment).
  static Node* field(const Node* dict, std::string_view key) {
    Node* found = nullptr;
    if (dict == nullptr || dict->t != Node::T::Dict) return nullptr;
    for (size_t k = 0; k + 1 < dict->items.size(); k += 2) {
      const Node* key_node = dict->items[k];
      if ((key_node->t == Node::T::Str || key_node->t == Node::T::Bytes) && key_node->text == key) {
        found = dict->items[k + 1];
      }
    }
    return found;
  }

  Node* required_field(Node* inst, std::string_view key) {
    Node* v = field(inst->state, key);
    if (v == nullptr)
      th::fail(name_, ": ", inst->name, " made at byte ", inst->pos, " has no '", key,
               "' in its state");
    return v;
  }

  torch::Tensor field_tensor(Node* inst, std::string_view key, int depth) {
    Value v = convert(required_field(inst, key), depth + 1);
    if (v.kind() != Value::Kind::Array && v.kind() != Value::Kind::List &&
        v.kind() != Value::Kind::Tuple) {
      th::fail(name_, ": '", key, "' of the ", inst->name, " made at byte ", inst->pos, " is a ",
               v.type_name(), ", not an array");
    }
    return v.as_tensor();
  }

  Value instance(Node* n, int depth) {
    if (static_cast<Global>(n->i) == Global::PlainClass)
      return Value::object(n->name, n->state ? convert(n->state, depth + 1) : Value());
    if (n->tensor.defined()) return Value::array(n->tensor);  // shared: densified once
    if (static_cast<Global>(n->i) == Global::Chumpy) {
      n->tensor = field_tensor(n, "x", depth);
    } else {
      n->tensor = densify(n, depth);
    }
    return Value::array(n->tensor);
  }

  // scipy's toarray(): duplicates are summed.
  torch::Tensor densify(Node* n, int depth) {
    const bool csc = static_cast<Global>(n->i) == Global::Csc;
    auto bad = [&](const auto&... what) {
      th::fail(name_, ": ", n->name, " made at byte ", n->pos, ": ", what...);
    };
    Node* shape_node = field(n->state, "_shape");
    if (shape_node == nullptr) shape_node = field(n->state, "shape");
    if (shape_node == nullptr) bad("no '_shape' in its state");
    if (shape_node->t != Node::T::Tuple || shape_node->items.size() != 2 ||
        shape_node->items[0]->t != Node::T::Int || shape_node->items[1]->t != Node::T::Int) {
      bad("'_shape' is not a tuple of two ints");
    }
    const int64_t rows = shape_node->items[0]->i, cols = shape_node->items[1]->i;
    if (rows < 0 || cols < 0 || (rows > 0 && cols > kMaxDenseElements / rows)) {
      bad("shape (", rows, ", ", cols, ") is too large to densify (limit ", kMaxDenseElements,
          " elements)");
    }
    const torch::Tensor data = field_tensor(n, "data", depth).reshape({-1});
    const torch::Tensor indices = field_tensor(n, "indices", depth).reshape({-1});
    const torch::Tensor indptr = field_tensor(n, "indptr", depth).reshape({-1});
    if (indices.is_floating_point() || indptr.is_floating_point() ||
        indices.scalar_type() == torch::kBool) {
      bad("indices/indptr are not integer arrays");
    }
    if (data.scalar_type() == torch::kBool || data.numel() != indices.numel()) {
      bad("'data' (", data.numel(), " values) and 'indices' (", indices.numel(), ") do not match");
    }
    const int64_t major = csc ? cols : rows, minor = csc ? rows : cols;
    if (indptr.numel() != major + 1)
      bad("'indptr' has ", indptr.numel(), " entries, expected ", major + 1);
    const torch::Tensor ptr = indptr.to(torch::kLong);
    const torch::Tensor idx = indices.to(torch::kLong);
    const int64_t first = ptr[0].item<int64_t>(), last = ptr[-1].item<int64_t>();
    if (first < 0 || last > data.numel() || (major > 0 && (ptr.diff() < 0).any().item<bool>())) {
      bad("'indptr' is not a non-decreasing range within the ", data.numel(), " stored values");
    }
    const torch::Tensor used_idx = idx.slice(0, first, last);
    if (used_idx.numel() > 0 &&
        (used_idx.min().item<int64_t>() < 0 || used_idx.max().item<int64_t>() >= minor)) {
      bad("an index is outside 0..", minor - 1);
    }
    const torch::Tensor major_idx =
        torch::repeat_interleave(torch::arange(major, torch::kLong), ptr.diff());
    const torch::Tensor linear = csc ? used_idx * cols + major_idx : major_idx * cols + used_idx;
    // Sum in 64 bits (index_add_ lacks some small types), then back to the stored dtype.
    const auto wide = data.is_floating_point() ? torch::kDouble : torch::kLong;
    torch::Tensor dense = torch::zeros({rows * cols}, torch::TensorOptions().dtype(wide));
    dense.index_add_(0, linear, data.slice(0, first, last).to(wide));
    return dense.view({rows, cols}).to(data.scalar_type());
  }

  const std::string& name_;
  size_t node_budget_;
  size_t byte_budget_;
  size_t nodes_ = 0;
  size_t bytes_ = 0;
};

class Unpickler {
 public:
  Unpickler(std::string_view input, const std::string& name, const PickleExtensions* ext = nullptr)
      : in_(input), name_(name), ext_(ext) {
    none_ = make(Node::T::None);
    true_ = make(Node::T::Bool);
    true_->i = 1;
    false_ = make(Node::T::Bool);
  }

  Value load() {
    for (;;) {
      op_pos_ = pos_;
      if (pos_ >= in_.size())
        th::fail(name_, ": truncated: the data ends at byte ", in_.size(), " before STOP");
      op_ = static_cast<uint8_t>(in_[pos_++]);
      if (op_ == '.') break;
      step();
    }
    Node* result = pop();
    return Converter(name_, in_.size()).convert(result, 0);
  }

 private:
  template <class... Parts>
  [[noreturn]] void error(const Parts&... parts) {
    th::fail(name_, ": ", parts..., " (opcode 0x", hex(op_), " at byte ", op_pos_, ")");
  }

  static std::string hex(uint8_t b) {
    const char* digits = "0123456789abcdef";
    return {digits[b >> 4], digits[b & 15]};
  }

  std::string_view take(uint64_t n) {
    if (n > in_.size() - pos_) {
      th::fail(name_, ": truncated: opcode 0x", hex(op_), " at byte ", op_pos_, " needs ", n,
               " more bytes, but the data ends at byte ", in_.size());
    }
    std::string_view out = in_.substr(pos_, static_cast<size_t>(n));
    pos_ += static_cast<size_t>(n);
    return out;
  }
  uint64_t le(int n) { return detail::load_le(take(n).data(), n); }
  std::string_view line() {
    const size_t end = in_.find('\n', pos_);
    if (end == std::string_view::npos) {
      th::fail(name_, ": truncated: opcode 0x", hex(op_), " at byte ", op_pos_,
               " needs a newline-terminated argument, but the data ends at byte ", in_.size());
    }
    std::string_view out = in_.substr(pos_, end - pos_);
    pos_ = end + 1;
    return out;
  }
  int64_t line_int() {
    std::string_view text = line();
    if (!text.empty() && text.back() == 'L') text.remove_suffix(1);  // Python 2 longs
    if (!text.empty() && text.front() == '+') text.remove_prefix(1);
    int64_t v = 0;
    const auto [end, ec] = std::from_chars(text.data(), text.data() + text.size(), v);
    if (ec != std::errc() || end != text.data() + text.size()) error("bad integer '", text, "'");
    return v;
  }

  Node* make(Node::T t) {
    Node& n = arena_.emplace_back();
    n.t = t;
    n.pos = op_pos_;
    return &n;
  }
  Node* make_int(int64_t v) {
    Node* n = make(Node::T::Int);
    n->i = v;
    return n;
  }
  Node* make_text(Node::T t, std::string_view view) {
    Node* n = make(t);
    n->text = view;
    return n;
  }
  Node* make_owned(Node::T t, std::string text) {
    Node* n = make(t);
    n->owned = std::move(text);
    n->text = n->owned;
    return n;
  }
  Node* make_str(std::string_view utf8) {
    if (!detail::utf8_length(utf8)) error("invalid UTF-8 in a str");
    return make_text(Node::T::Str, utf8);
  }

  size_t floor() const { return marks_.empty() ? 0 : marks_.back(); }
  void push(Node* n) { stack_.push_back(n); }
  Node* pop() {
    if (stack_.size() <= floor()) error("stack underflow");
    Node* n = stack_.back();
    stack_.pop_back();
    return n;
  }
  Node* top() {
    if (stack_.size() <= floor()) error("stack underflow");
    return stack_.back();
  }
  std::vector<Node*> pop_mark() {
    if (marks_.empty()) error("no MARK to pop back to");
    const size_t mark = marks_.back();
    marks_.pop_back();
    std::vector<Node*> items(stack_.begin() + static_cast<std::ptrdiff_t>(mark), stack_.end());
    stack_.resize(mark);
    return items;
  }

  void memo_put(uint64_t index) { memo_[index] = top(); }
  void memo_get(uint64_t index) {
    const auto it = memo_.find(index);
    if (it == memo_.end()) error("memo entry ", index, " was never stored");
    push(it->second);
  }

  int64_t decode_long(std::string_view bytes) {
    if (bytes.empty()) return 0;
    const bool negative = (static_cast<uint8_t>(bytes.back()) & 0x80) != 0;
    if (bytes.size() > 8) {
      for (size_t k = 8; k < bytes.size(); ++k) {
        if (static_cast<uint8_t>(bytes[k]) != (negative ? 0xff : 0x00))
          error("integer does not fit in 64 bits");
      }
      if (((static_cast<uint8_t>(bytes[7]) & 0x80) != 0) != negative)
        error("integer does not fit in 64 bits");
      bytes = bytes.substr(0, 8);
    }
    uint64_t v = detail::load_le(bytes.data(), static_cast<int>(bytes.size()));
    if (negative && bytes.size() < 8) v |= ~uint64_t{0} << (8 * bytes.size());
    return static_cast<int64_t>(v);
  }

  Node* make_global(std::string_view module, std::string_view name) {
    const std::string dotted = std::string(module) + "." + std::string(name);
    auto g = lookup_global(module, name);
    if (!g && ext_ && ext_->globals.count(dotted)) g = Global::Extension;
    if (!g && ext_) {
      for (const auto& prefix : ext_->class_prefixes)
        if (dotted.compare(0, prefix.size(), prefix) == 0) g = Global::PlainClass;
    }
    if (!g) {
      error("refused global '", dotted,
            "': only numpy arrays, numpy scalars, scipy.sparse matrices, ",
            "chumpy arrays and plain Python containers may be unpickled");
    }
    Node* n = make(Node::T::Global);
    n->i = static_cast<int64_t>(*g);
    n->name = dotted;
    return n;
  }

  static bool is_global(const Node* n, Global g) {
    return n->t == Node::T::Global && static_cast<Global>(n->i) == g;
  }
  static bool is_text(const Node* n) { return n->t == Node::T::Str || n->t == Node::T::Bytes; }

  // Raw bytes of array data: bytes, or a str holding latin-1 code points (Python 2 data read
  // as text); `storage` keeps a converted copy alive.
  std::string_view raw_bytes(const Node* n, std::string& storage, const char* what) {
    if (n->t == Node::T::Bytes) return n->text;
    if (n->t == Node::T::Str) {
      auto latin1 = detail::utf8_to_latin1(n->text);
      if (!latin1) error(what, " is a str with characters beyond latin-1");
      storage = std::move(*latin1);
      return storage;
    }
    error(what, " is a ", describe(n), ", not bytes");
  }

  std::vector<int64_t> shape_of(const Node* n, const char* what) {
    if (n->t != Node::T::Tuple && n->t != Node::T::List)
      error(what, " is a ", describe(n), ", not a tuple");
    if (n->items.size() > static_cast<size_t>(kMaxDims))
      error(what, " has more than ", kMaxDims, " dimensions");
    std::vector<int64_t> shape;
    for (const Node* d : n->items) {
      if (d->t != Node::T::Int) error(what, " holds a ", describe(d), ", not an int");
      shape.push_back(d->i);
    }
    if (!detail::element_count(shape)) {
      error("absurd array shape ", detail::shape_repr(shape),
            " (negative, or more than 2^40 elements)");
    }
    return shape;
  }

  torch::Tensor array_from(std::string_view data, const detail::NpyDType& dtype,
                           const std::vector<int64_t>& shape, bool fortran) {
    const int64_t count = *detail::element_count(shape);
    const uint64_t needed = static_cast<uint64_t>(count) * static_cast<uint64_t>(dtype.size);
    if (data.size() != needed) {
      error("array data has ", data.size(), " bytes, but shape ", detail::shape_repr(shape), " of ",
            dtype.name(), " needs ", needed);
    }
    return detail::decode_array(data, dtype, shape, fortran);
  }

  std::string encode_text(const Node* str, const Node* encoding) {
    std::string enc = "utf-8";
    if (encoding != nullptr) {
      if (!is_text(encoding)) error("encoding is a ", describe(encoding));
      enc = std::string(encoding->text);
      std::transform(enc.begin(), enc.end(), enc.begin(),
                     [](unsigned char c) { return std::tolower(c); });
    }
    if (enc == "latin1" || enc == "latin-1" || enc == "iso-8859-1" || enc == "l1") {
      auto bytes = detail::utf8_to_latin1(str->text);
      if (!bytes) error("str with characters beyond latin-1 encoded as latin-1");
      return std::move(*bytes);
    }
    if (enc == "utf-8" || enc == "utf8") return std::string(str->text);
    error("unsupported encoding '", enc, "'");
  }

  // REDUCE: callable(*args) for the whitelisted callables.
  Node* call(Node* callable, Node* args) {
    if (callable->t != Node::T::Global)
      error("REDUCE calls a ", describe(callable), ", which is not callable");
    if (args->t != Node::T::Tuple)
      error("arguments of ", callable->name, " are a ", describe(args), ", not a tuple");
    const std::vector<Node*>& a = args->items;
    const auto arity = [&](size_t lo, size_t hi) {
      if (a.size() < lo || a.size() > hi)
        error(callable->name, " called with ", a.size(), " arguments");
    };
    switch (static_cast<Global>(callable->i)) {
      case Global::Reconstruct: {
        arity(3, 3);
        if (!is_global(a[0], Global::NdArray))
          error("_reconstruct of a ", describe(a[0]), ", not numpy.ndarray");
        return make(Node::T::PendingArray);
      }
      case Global::DTypeClass: {
        arity(1, 3);
        if (!is_text(a[0])) error("numpy.dtype of a ", describe(a[0]));
        const auto dtype = detail::parse_dtype(a[0]->text);
        if (!dtype) error("unsupported dtype '", a[0]->text, "'");
        Node* n = make(Node::T::DType);
        n->dtype = *dtype;
        return n;
      }
      case Global::Scalar: {
        arity(1, 2);
        if (a[0]->t != Node::T::DType) error("numpy scalar of a ", describe(a[0]), ", not a dtype");
        if (a[0]->dtype.is_object()) return a.size() == 2 ? a[1] : none_;
        if (a.size() != 2) error("numpy scalar without data");
        std::string storage;
        const std::string_view data = raw_bytes(a[1], storage, "numpy scalar data");
        Node* n = make(Node::T::Array);
        n->tensor = array_from(data, a[0]->dtype, {}, false);
        n->name = kNumpyScalar;  // hashable, unlike a 0-d ndarray
        return n;
      }
      case Global::FromBuffer: {
        arity(4, 4);
        if (a[1]->t != Node::T::DType || a[1]->dtype.is_object())
          error("_frombuffer with a ", describe(a[1]));
        if (!is_text(a[3]) ||
            (a[3]->text != "C" && a[3]->text != "F" && a[3]->text != "A" && a[3]->text != "K")) {
          error("_frombuffer with order ", describe(a[3]));
        }
        std::string storage;
        const std::string_view data = raw_bytes(a[0], storage, "_frombuffer's buffer");
        const auto shape = shape_of(a[2], "_frombuffer's shape");
        Node* n = make(Node::T::Array);
        n->tensor = array_from(data, a[1]->dtype, shape, a[3]->text == "F");
        return n;
      }
      case Global::CodecsEncode: {
        arity(1, 2);
        if (a[0]->t != Node::T::Str) error("_codecs.encode of a ", describe(a[0]));
        return make_owned(Node::T::Bytes, encode_text(a[0], a.size() == 2 ? a[1] : nullptr));
      }
      case Global::Bytes:
      case Global::Bytearray: {
        arity(0, 2);
        if (a.empty()) return make_text(Node::T::Bytes, {});
        if (a[0]->t == Node::T::Bytes && a.size() == 1) return a[0];
        if (a[0]->t == Node::T::Str) {
          return make_owned(Node::T::Bytes, encode_text(a[0], a.size() == 2 ? a[1] : nullptr));
        }
        error(callable->name, " of a ", describe(a[0]));
      }
      case Global::Set:
      case Global::FrozenSet: {
        arity(0, 1);
        Node* n = make(is_global(callable, Global::Set) ? Node::T::Set : Node::T::FrozenSet);
        if (a.size() == 1) {
          const Node* src = a[0];
          if (src->t != Node::T::List && src->t != Node::T::Tuple && src->t != Node::T::Set &&
              src->t != Node::T::FrozenSet) {
            error(callable->name, " of a ", describe(src));
          }
          n->items = src->items;
        }
        return n;
      }
      case Global::OrderedDict: {
        arity(0, 0);
        return make(Node::T::Dict);
      }
      case Global::Reconstructor: {
        arity(3, 3);
        if (a[0]->t != Node::T::Global || !is_instance_class(static_cast<Global>(a[0]->i))) {
          error("copyreg._reconstructor of a ", describe(a[0]));
        }
        if (!is_global(a[1], Global::Object))
          error("copyreg._reconstructor with base ", describe(a[1]));
        if (a[2]->t != Node::T::None) error("copyreg._reconstructor with a base state");
        return make_instance(a[0]);
      }
      case Global::Extension:
        return call_extension(callable, args);
      default:
        error("cannot call ", callable->name);
    }
  }

  Node* call_extension(Node* callable, Node* args) {
    const auto& fn = ext_->globals.at(callable->name);
    if (!fn) error("cannot call ", callable->name);
    Node* n = make(Node::T::Opaque);
    n->value = std::make_shared<Value>(fn(Converter(name_, in_.size()).convert(args, 0).as_list()));
    return n;
  }

  Node* make_instance(const Node* cls) {
    Node* n = make(Node::T::Instance);
    n->i = cls->i;
    n->name = cls->name;
    return n;
  }

  // NEWOBJ: cls.__new__(cls, *args).
  Node* new_object(Node* cls, Node* args) {
    if (args->t != Node::T::Tuple) error("NEWOBJ arguments are a ", describe(args));
    if (cls->t != Node::T::Global) error("NEWOBJ of a ", describe(cls));
    const auto g = static_cast<Global>(cls->i);
    if (g == Global::Extension) return call_extension(cls, args);
    if (is_instance_class(g)) return make_instance(cls);
    if (g == Global::OrderedDict && args->items.empty()) return make(Node::T::Dict);
    if ((g == Global::Set || g == Global::FrozenSet) && args->items.empty()) {
      return make(g == Global::Set ? Node::T::Set : Node::T::FrozenSet);
    }
    error("cannot create a ", cls->name, " with NEWOBJ");
  }

  // BUILD: obj.__setstate__(state).
  void build(Node* obj, Node* state) {
    switch (obj->t) {
      case Node::T::PendingArray:
        return build_array(obj, state);
      case Node::T::DType:
        return build_dtype(obj, state);
      case Node::T::Instance: {
        Node* dict = state;
        Node* slots = nullptr;
        if (state->t == Node::T::Tuple && state->items.size() == 2) {
          dict = state->items[0];
          slots = state->items[1];
        }
        for (Node* part : {dict, slots}) {
          if (part == nullptr || part->t == Node::T::None) continue;
          if (part->t != Node::T::Dict)
            error("state of ", obj->name, " is a ", describe(part), ", not a dict");
          if (obj->state == nullptr) obj->state = make(Node::T::Dict);
          obj->state->items.insert(obj->state->items.end(), part->items.begin(), part->items.end());
        }
        return;
      }
      case Node::T::Dict:
        if (ext_ && ext_->ignore_dict_state) return;
        error("BUILD (__setstate__) on a ", describe(obj), " is not supported");
      default:
        error("BUILD (__setstate__) on a ", describe(obj), " is not supported");
    }
  }

  // ndarray.__setstate__((version,) shape, dtype, is_fortran, rawdata).
  void build_array(Node* obj, Node* state) {
    if (state->t != Node::T::Tuple) error("ndarray state is a ", describe(state), ", not a tuple");
    const auto& s = state->items;
    size_t k = 0;
    if (s.size() == 5) {
      if (s[0]->t != Node::T::Int) error("ndarray state version is a ", describe(s[0]));
      k = 1;
    } else if (s.size() != 4) {
      error("ndarray state has ", s.size(), " items, expected 4 or 5");
    }
    const auto shape = shape_of(s[k], "ndarray shape");
    if (s[k + 1]->t != Node::T::DType) error("ndarray dtype is a ", describe(s[k + 1]));
    const detail::NpyDType dtype = s[k + 1]->dtype;
    if (s[k + 2]->t != Node::T::Bool && s[k + 2]->t != Node::T::Int)
      error("ndarray is_fortran is a ", describe(s[k + 2]));
    const bool fortran = s[k + 2]->i != 0;
    Node* raw = s[k + 3];
    const int64_t count = *detail::element_count(shape);
    if (dtype.is_object()) {
      if (raw->t != Node::T::List)
        error("object ndarray data is a ", describe(raw), ", not a list");
      if (static_cast<int64_t>(raw->items.size()) != count) {
        error("object ndarray of shape ", detail::shape_repr(shape), " has ", raw->items.size(),
              " items");
      }
      obj->t = Node::T::ObjArray;
      obj->items = raw->items;
      obj->shape = shape;
      obj->i = fortran ? 1 : 0;
      return;
    }
    std::string storage;
    const std::string_view data = raw_bytes(raw, storage, "ndarray data");
    obj->tensor = array_from(data, dtype, shape, fortran);
    obj->t = Node::T::Array;
  }

  // dtype.__setstate__((version, byteorder, subarray, names, fields, elsize, alignment, flags...)).
  void build_dtype(Node* obj, Node* state) {
    if (state->t != Node::T::Tuple || state->items.size() < 2)
      error("numpy.dtype state is not a tuple");
    const auto& s = state->items;
    if (s[0]->t != Node::T::Int) error("numpy.dtype state version is a ", describe(s[0]));
    if (s.size() >= 4 && (s[2]->t != Node::T::None || s[3]->t != Node::T::None)) {
      error("structured and sub-array dtypes are not supported");
    }
    if (!is_text(s[1]) || s[1]->text.size() != 1)
      error("numpy.dtype byte order is not one character");
    const char order = s[1]->text[0];
    if (order != '<' && order != '>' && order != '|' && order != '=')
      error("numpy.dtype byte order '", order, "'");
    auto& dt = obj->dtype;
    if (dt.size == 1 || dt.is_object()) {
      dt.order = '|';
    } else {
      dt.order = order == '>' ? '>' : '<';
    }
  }

  void step() {
    switch (op_) {
      case '(':
        marks_.push_back(stack_.size());
        break;   // MARK
      case '0':  // POP
        if (stack_.size() > floor()) {
          stack_.pop_back();
        } else {
          pop_mark();
        }
        break;
      case '1':
        pop_mark();
        break;  // POP_MARK
      case '2':
        push(top());
        break;  // DUP
      case 'N':
        push(none_);
        break;
      case 0x88:
        push(true_);
        break;  // NEWTRUE
      case 0x89:
        push(false_);
        break;     // NEWFALSE
      case 'I': {  // INT (text; "01"/"00" are bools)
        const size_t start = pos_;
        const std::string_view text = line();
        if (text == "01" || text == "00") {
          push(text == "01" ? true_ : false_);
        } else {
          pos_ = start;
          push(make_int(line_int()));
        }
        break;
      }
      case 'L':
        push(make_int(line_int()));
        break;     // LONG (text)
      case 'F': {  // FLOAT (text)
        const std::string_view text = line();
        double v = 0;
        const auto [end, ec] = std::from_chars(text.data(), text.data() + text.size(), v);
        if (ec != std::errc() || end != text.data() + text.size()) error("bad float '", text, "'");
        Node* n = make(Node::T::Float);
        n->f = v;
        push(n);
        break;
      }
      case 'J':
        push(make_int(static_cast<int32_t>(le(4))));
        break;  // BININT
      case 'K':
        push(make_int(static_cast<int64_t>(le(1))));
        break;  // BININT1
      case 'M':
        push(make_int(static_cast<int64_t>(le(2))));
        break;  // BININT2
      case 0x8a:
        push(make_int(decode_long(take(le(1)))));
        break;      // LONG1
      case 0x8b: {  // LONG4
        const auto n = static_cast<int32_t>(le(4));
        if (n < 0) error("negative byte count");
        push(make_int(decode_long(take(static_cast<uint64_t>(n)))));
        break;
      }
      case 'G': {  // BINFLOAT, big endian
        const std::string_view b = take(8);
        uint64_t bits = 0;
        for (char c : b) bits = (bits << 8) | static_cast<uint8_t>(c);
        Node* n = make(Node::T::Float);
        std::memcpy(&n->f, &bits, sizeof bits);
        push(n);
        break;
      }
      case 'T': {  // BINSTRING (Python 2 str: bytes)
        const auto n = static_cast<int32_t>(le(4));
        if (n < 0) error("negative byte count");
        push(make_text(Node::T::Bytes, take(static_cast<uint64_t>(n))));
        break;
      }
      case 'U':
        push(make_text(Node::T::Bytes, take(le(1))));
        break;  // SHORT_BINSTRING
      case 'X':
        push(make_str(take(le(4))));
        break;  // BINUNICODE
      case 0x8c:
        push(make_str(take(le(1))));
        break;  // SHORT_BINUNICODE
      case 0x8d:
        push(make_str(take(le(8))));
        break;  // BINUNICODE8
      case 'B':
        push(make_text(Node::T::Bytes, take(le(4))));
        break;  // BINBYTES
      case 'C':
        push(make_text(Node::T::Bytes, take(le(1))));
        break;    // SHORT_BINBYTES
      case 0x8e:  // BINBYTES8
      case 0x96:
        push(make_text(Node::T::Bytes, take(le(8))));
        break;    // BYTEARRAY8
      case 0x97:  // NEXT_BUFFER
        error(
            "out-of-band buffers (pickle protocol 5 with buffer_callback) are not supported; "
            "pickle without buffer_callback");
      case 0x98:
        top();
        break;  // READONLY_BUFFER: the buffer is already read-only here
      case ']':
        push(make(Node::T::List));
        break;
      case '}':
        push(make(Node::T::Dict));
        break;
      case ')':
        push(make(Node::T::Tuple));
        break;
      case 0x8f:
        push(make(Node::T::Set));
        break;      // EMPTY_SET
      case 'l':     // LIST
      case 't':     // TUPLE
      case 0x91: {  // FROZENSET
        auto items = pop_mark();
        Node* n = make(op_ == 'l'   ? Node::T::List
                       : op_ == 't' ? Node::T::Tuple
                                    : Node::T::FrozenSet);
        n->items = std::move(items);
        push(n);
        break;
      }
      case 'd': {  // DICT
        auto items = pop_mark();
        if (items.size() % 2 != 0) error("odd number of items for a dict");
        Node* n = make(Node::T::Dict);
        n->items = std::move(items);
        push(n);
        break;
      }
      case 0x85:
      case 0x86:
      case 0x87: {  // TUPLE1..3
        const size_t count = op_ - 0x84;
        if (stack_.size() < floor() + count) error("stack underflow");
        Node* n = make(Node::T::Tuple);
        n->items.assign(stack_.end() - static_cast<std::ptrdiff_t>(count), stack_.end());
        stack_.resize(stack_.size() - count);
        push(n);
        break;
      }
      case 'a': {  // APPEND
        Node* v = pop();
        Node* list = top();
        if (list->t != Node::T::List) error("APPEND to a ", describe(list));
        list->items.push_back(v);
        break;
      }
      case 'e': {  // APPENDS
        auto items = pop_mark();
        Node* list = top();
        if (list->t != Node::T::List) error("APPENDS to a ", describe(list));
        list->items.insert(list->items.end(), items.begin(), items.end());
        break;
      }
      case 's': {  // SETITEM
        Node* v = pop();
        Node* k = pop();
        Node* dict = top();
        if (dict->t != Node::T::Dict) error("SETITEM on a ", describe(dict));
        dict->items.push_back(k);
        dict->items.push_back(v);
        break;
      }
      case 'u': {  // SETITEMS
        auto items = pop_mark();
        Node* dict = top();
        if (dict->t != Node::T::Dict) error("SETITEMS on a ", describe(dict));
        if (items.size() % 2 != 0) error("odd number of items for SETITEMS");
        dict->items.insert(dict->items.end(), items.begin(), items.end());
        break;
      }
      case 0x90: {  // ADDITEMS
        auto items = pop_mark();
        Node* set = top();
        if (set->t != Node::T::Set) error("ADDITEMS on a ", describe(set));
        set->items.insert(set->items.end(), items.begin(), items.end());
        break;
      }
      case 'c': {  // GLOBAL
        const std::string_view module = line();
        const std::string_view name = line();
        push(make_global(module, name));
        break;
      }
      case 0x93: {  // STACK_GLOBAL
        Node* name = pop();
        Node* module = pop();
        if (module->t != Node::T::Str || name->t != Node::T::Str)
          error("STACK_GLOBAL needs two str");
        push(make_global(module->text, name->text));
        break;
      }
      case 'R': {  // REDUCE
        Node* args = pop();
        Node* callable = pop();
        push(call(callable, args));
        break;
      }
      case 0x81: {  // NEWOBJ
        Node* args = pop();
        Node* cls = pop();
        push(new_object(cls, args));
        break;
      }
      case 0x92: {  // NEWOBJ_EX
        Node* kwargs = pop();
        Node* args = pop();
        Node* cls = pop();
        if (kwargs->t != Node::T::Dict || !kwargs->items.empty())
          error("NEWOBJ_EX with keyword arguments");
        push(new_object(cls, args));
        break;
      }
      case 'b': {  // BUILD
        Node* state = pop();
        build(top(), state);
        break;
      }
      case 'p': {  // PUT (text)
        const int64_t index = line_int();
        if (index < 0) error("negative memo index");
        memo_put(static_cast<uint64_t>(index));
        break;
      }
      case 'q':
        memo_put(le(1));
        break;  // BINPUT
      case 'r':
        memo_put(le(4));
        break;  // LONG_BINPUT
      case 0x94:
        memo_put(memo_.size());
        break;     // MEMOIZE
      case 'g': {  // GET (text)
        const int64_t index = line_int();
        if (index < 0) error("negative memo index");
        memo_get(static_cast<uint64_t>(index));
        break;
      }
      case 'h':
        memo_get(le(1));
        break;  // BINGET
      case 'j':
        memo_get(le(4));
        break;      // LONG_BINGET
      case 0x80: {  // PROTO
        const uint64_t proto = le(1);
        if (proto > 5) error("unsupported pickle protocol ", proto);
        break;
      }
      case 0x95: {  // FRAME: the frame's bytes follow in place
        const uint64_t length = le(8);
        if (length > in_.size() - pos_) {
          th::fail(name_, ": truncated: FRAME at byte ", op_pos_, " announces ", length,
                   " bytes, but the data ends at byte ", in_.size());
        }
        break;
      }
      case 'Q': {  // BINPERSID
        if (!ext_ || !ext_->persistent_load) error("persistent ids are not supported");
        Node* pid = pop();
        Node* n = make(Node::T::Opaque);
        n->value = std::make_shared<Value>(ext_->persistent_load(Converter(name_, in_.size()).convert(pid, 0)));
        push(n);
        break;
      }
      case 'P':
        error("persistent ids are not supported");
      case 0x82:
      case 0x83:
      case 0x84:
        error("extension registry codes are not supported");
      case 'S':
      case 'V':
      case 'i':
      case 'o':
        error("protocol-0 text strings and INST/OBJ are not supported (use protocol 2 or later)");
      default:
        error("unknown opcode");
    }
  }

  std::string_view in_;
  const std::string& name_;
  const PickleExtensions* ext_ = nullptr;
  size_t pos_ = 0;
  size_t op_pos_ = 0;
  uint8_t op_ = 0;
  std::deque<Node> arena_;
  std::vector<Node*> stack_;
  std::vector<size_t> marks_;
  std::unordered_map<uint64_t, Node*> memo_;
  Node* none_ = nullptr;
  Node* true_ = nullptr;
  Node* false_ = nullptr;
};

}  // namespace

Value parse_pickle(std::string_view bytes, const std::string& name) {
  return Unpickler(bytes, name).load();
}

Value parse_pickle(std::string_view bytes, const std::string& name, const PickleExtensions& extensions) {
  return Unpickler(bytes, name, &extensions).load();
}

Value read_pickle(const std::filesystem::path& path) {
  const std::string bytes = detail::read_file(path);
  return parse_pickle(bytes, path.string());
}

}  // namespace th::io
