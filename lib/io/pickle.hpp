#pragma once
// A safe reader and writer for the subset of Python pickles that numpy and SMPL files use
// (METHOD 1.4). Nothing read from a file is ever executed: globals outside a fixed whitelist are
// refused with an error naming them, and every malformed or truncated input gives a th::Error
// naming the file and the byte offset.
//
// Reader: protocols 2-5 (and the simple protocol-0/1 opcodes). Whitelisted globals, under their
// Python 2 and 3 and numpy 1 and 2 names: numpy arrays (_reconstruct + BUILD, protocol-5
// _frombuffer with in-band buffers), numpy.dtype, numpy scalars, _codecs.encode (array bytes
// at protocol 2), set/frozenset/bytes/bytearray, collections.OrderedDict, scipy.sparse
// csc/csr matrices (densified) and chumpy.ch.Ch (its array `x`), built through
// copyreg._reconstructor or NEWOBJ. Python 2 strings (BINSTRING, SHORT_BINSTRING) are read as
// bytes (latin-1); Value::as_str and Value::find accept them where a str is expected.
// Limits: nesting deeper than kMaxDepth levels, arrays of more than 2^40 elements or whose
// data does not match their shape, and dense matrices of more than 2^26 elements are refused.

#include <torch/types.h>

#include <cstdint>
#include <filesystem>
#include <functional>
#include <map>
#include <memory>
#include <string>
#include <string_view>
#include <utility>
#include <variant>
#include <vector>

namespace th::io {

// Deepest container nesting a pickle may have (recursive structures hit this too).
constexpr int kMaxDepth = 256;

// A Python value as a small tree. Numpy arrays (and numpy scalars, scipy sparse matrices,
// chumpy arrays) become tensors; sparse matrices are densified. Object-dtype arrays become
// nested lists (like ndarray.tolist()); a 0-d object array becomes the object it holds.
class Value {
 public:
  enum class Kind { None, Bool, Int, Float, Str, Bytes, List, Tuple, Dict, Set, Array, Object };
  using List = std::vector<Value>;
  using Dict = std::vector<std::pair<Value, Value>>;  // insertion order, like Python
  // An instance of a whitelisted class that has no dedicated kind: a bare global (its dotted
  // name, state None) or a numpy.dtype (state: its descr string, e.g. "<f8").
  struct Object {
    std::string cls;
    std::shared_ptr<Value> state;
  };

  Value() = default;  // None
  static Value none() { return {}; }
  static Value boolean(bool v);
  static Value integer(int64_t v);
  static Value floating(double v);
  static Value str(std::string v);  // UTF-8 text
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
  bool as_bool() const;               // Bool, or an Int/one-element array that is 0 or 1
  int64_t as_int() const;             // Int, Bool, or an integer one-element array
  double as_float() const;            // Float, Int, Bool, or a one-element array (numpy scalar)
  const std::string& as_str() const;  // Str or Bytes (latin-1 bytes of Python 2 files)
  const List& as_list() const;        // List, Tuple or Set
  const Dict& as_dict() const;
  const Object& as_object() const;
  // Array as is; a Python int/float/bool as a 0-d tensor (int64/float64/bool); a list or tuple
  // of numbers or of equally shaped arrays stacked like np.array (bool < int64 < float64).
  torch::Tensor as_tensor() const;

  // Dict lookup by string key (also matches bytes keys from Python 2 files).
  const Value* find(std::string_view key) const;
  bool contains(std::string_view key) const { return find(key) != nullptr; }
  // Throws th::Error "missing key 'x'" (listing the keys present) when absent.
  const Value& operator[](std::string_view key) const;
  // List/tuple/set element; throws th::Error when out of range.
  const Value& at(size_t index) const;
  size_t size() const;  // elements of a list/tuple/set/dict; throws for other kinds

  // Deep; kinds must match (1 != 1.0 here); arrays compare dtype, shape and values; NaN equals
  // NaN so that round trips compare equal.
  bool operator==(const Value& other) const;
  bool operator!=(const Value& other) const { return !(*this == other); }

 private:
  std::variant<std::monostate, bool, int64_t, double, std::string /*str, bytes*/,
               List /*list, tuple, set*/, Dict, torch::Tensor, Object>
      v_;
  Kind kind_ = Kind::None;
};

// Reads a pickle file (protocols 2-5). Throws th::Error naming the file and byte offset.
Value read_pickle(const std::filesystem::path& path);
// Reads pickle bytes; `name` stands for the file in error messages.
Value parse_pickle(std::string_view bytes, const std::string& name);

// Extension point for formats built on pickle (PyTorch checkpoints, see
// model/checkpoint_import.cpp). Still nothing is executed: the callbacks receive converted
// Values and return Values.
struct PickleExtensions {
  // Extra globals by dotted name. REDUCE or NEWOBJ on one calls its function with the converted
  // arguments; a name mapped to an empty function may only appear as a value (it converts to
  // Value::object(name, None), like whitelisted bare globals).
  std::map<std::string, std::function<Value(const Value::List& args)>> globals;
  // BINPERSID: the converted persistent id -> the object it stands for. Empty: refused.
  std::function<Value(const Value& pid)> persistent_load;
  // Globals whose dotted name starts with one of these are plain classes: NEWOBJ makes an
  // instance, BUILD gives it a dict of attributes, and it converts to Value::object(name,
  // attributes). For TorchScript archives ("__torch__."); nothing of the class is executed.
  std::vector<std::string> class_prefixes;
  // Accept BUILD on a dict (attributes of a dict subclass, such as a state dict's _metadata)
  // and drop that state.
  bool ignore_dict_state = false;
};
Value parse_pickle(std::string_view bytes, const std::string& name,
                   const PickleExtensions& extensions);

// Writes the value as pickle.dumps(obj, protocol) of CPython 3.11 + numpy 1.24 would (protocol
// 2-4, protocol 4 with FRAMEs; arrays as numpy pickles them, C order). Byte-identical for the
// object graph a Python script builds from literals: equal strings (and bytes) are written
// once and referenced through the memo afterwards, as one script's constants are one object;
// the same tensor twice is the same ndarray twice. Sets are written in the order given (Python
// uses hash order). Object values cannot be written (th::Error).
std::string pickle_bytes(const Value& value, int protocol = 3);
// pickle_bytes written atomically to a file.
void write_pickle(const std::filesystem::path& path, const Value& value, int protocol = 3);

}  // namespace th::io
