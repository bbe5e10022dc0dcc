#pragma once
// A safe reader and writer for the subset of Python pickles that numpy and SMPL files use
// (SPEC 1.4). Nothing read from a file is ever executed: globals outside a fixed whitelist are
// refused with an error naming them, and every malformed or truncated input gives a th::Error
// naming the file and the byte offset.

#include <torch/types.h>

#include <cstdint>
#include <filesystem>
#include <memory>
#include <string>
#include <string_view>
#include <utility>
#include <variant>
#include <vector>

namespace th::io {

// A Python value as a small tree. Numpy arrays (and numpy scalars, scipy sparse matrices,
// chumpy arrays) become tensors; sparse matrices are densified.
class Value {
 public:
  enum class Kind { None, Bool, Int, Float, Str, Bytes, List, Tuple, Dict, Set, Array, Object };
  using List = std::vector<Value>;
  using Dict = std::vector<std::pair<Value, Value>>;  // insertion order, like Python
  // An instance of a whitelisted class that has no dedicated kind (copy_reg._reconstructor of
  // object etc.): its qualified class name and its state (usually a Dict).
  struct Object {
    std::string cls;
    std::shared_ptr<Value> state;
  };

  Value() = default;  // None
  static Value none() { return {}; }
  static Value boolean(bool v);
  static Value integer(int64_t v);
  static Value floating(double v);
  static Value str(std::string v);
  static Value bytes(std::string v);
  static Value list(List v);
  static Value tuple(List v);
  static Value set(List v);
  static Value dict(Dict v);
  static Value array(torch::Tensor v);
  static Value object(std::string cls, Value state);

  Kind kind() const;
  bool is_none() const { return kind() == Kind::None; }
  // Python-ish type name for error messages ("dict", "ndarray float64 (6890, 3)", ...).
  std::string type_name() const;

  // Typed access; each throws th::Error naming the expected and the actual type.
  bool as_bool() const;
  int64_t as_int() const;          // Int, Bool
  double as_float() const;         // Float, Int, Bool
  const std::string& as_str() const;  // Str or Bytes (latin-1 bytes of Python 2 files)
  const List& as_list() const;     // List, Tuple or Set
  const Dict& as_dict() const;
  const Object& as_object() const;
  // Array as is; a Python int/float/bool as a 0-d tensor; a list of numbers as a 1-d tensor.
  torch::Tensor as_tensor() const;

  // Dict lookup by string key (also matches bytes keys from Python 2 files).
  const Value* find(std::string_view key) const;
  bool contains(std::string_view key) const { return find(key) != nullptr; }
  // Throws th::Error "missing key 'x'" when absent.
  const Value& operator[](std::string_view key) const;
  // List/tuple element; throws th::Error when out of range.
  const Value& at(size_t index) const;
  size_t size() const;  // elements of a list/tuple/set/dict

  bool operator==(const Value& other) const;  // deep; arrays compare dtype, shape and values

 private:
  std::variant<std::monostate, bool, int64_t, double, std::string /*str*/, List /*list*/,
               Dict, torch::Tensor, Object>
      v_;
  Kind kind_ = Kind::None;
};

// Reads a pickle file (protocols 2-5). Throws th::Error naming the file and byte offset.
Value read_pickle(const std::filesystem::path& path);
// Reads pickle bytes; `name` stands for the file in error messages.
Value parse_pickle(std::string_view bytes, const std::string& name);

// Writes the value as pickle.dumps(obj, protocol) would for the same Python objects (protocol
// 2-4; arrays as numpy pickles them). Byte-identical to CPython + numpy where Python would
// produce the same object graph (no memo sharing).
std::string pickle_bytes(const Value& value, int protocol = 3);

}  // namespace th::io
