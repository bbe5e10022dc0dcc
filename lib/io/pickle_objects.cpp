// What the pickle reader's opcodes build (METHOD 1.4): the whitelist of globals, REDUCE on the
// whitelisted callables, NEWOBJ and BUILD (numpy arrays and dtypes, class instances).
#include <algorithm>
#include <cctype>
#include <optional>
#include <unordered_map>

#include "core/error.hpp"
#include "io/bytes.hpp"
#include "io/dtype.hpp"
#include "io/unpickler.hpp"

namespace th::io::detail {

namespace {

constexpr int kMaxDims = 32;  // numpy's NPY_MAXDIMS

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

}  // namespace

Node* Unpickler::make_global(std::string_view module, std::string_view name) {
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

// Raw bytes of array data: bytes, or a str holding latin-1 code points (Python 2 data read
// as text); `storage` keeps a converted copy alive.
std::string_view Unpickler::raw_bytes(const Node* n, std::string& storage, const char* what) {
  if (n->t == Node::T::Bytes) return n->text;
  if (n->t == Node::T::Str) {
    auto latin1 = detail::utf8_to_latin1(n->text);
    if (!latin1) error(what, " is a str with characters beyond latin-1");
    storage = std::move(*latin1);
    return storage;
  }
  error(what, " is a ", describe(n), ", not bytes");
}

std::vector<int64_t> Unpickler::shape_of(const Node* n, const char* what) {
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

torch::Tensor Unpickler::array_from(std::string_view data, const detail::NpyDType& dtype,
                                    const std::vector<int64_t>& shape, bool fortran) {
  const int64_t count = *detail::element_count(shape);
  const uint64_t needed = static_cast<uint64_t>(count) * static_cast<uint64_t>(dtype.size);
  if (data.size() != needed) {
    error("array data has ", data.size(), " bytes, but shape ", detail::shape_repr(shape), " of ",
          dtype.name(), " needs ", needed);
  }
  return detail::decode_array(data, dtype, shape, fortran);
}

std::string Unpickler::encode_text(const Node* str, const Node* encoding) {
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
Node* Unpickler::call(Node* callable, Node* args) {
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

Node* Unpickler::call_extension(Node* callable, Node* args) {
  const auto& fn = ext_->globals.at(callable->name);
  if (!fn) error("cannot call ", callable->name);
  Node* n = make(Node::T::Opaque);
  n->value = std::make_shared<Value>(fn(to_value(args, name_, in_.size()).as_list()));
  return n;
}

Node* Unpickler::make_instance(const Node* cls) {
  Node* n = make(Node::T::Instance);
  n->i = cls->i;
  n->name = cls->name;
  return n;
}

// NEWOBJ: cls.__new__(cls, *args).
Node* Unpickler::new_object(Node* cls, Node* args) {
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
void Unpickler::build(Node* obj, Node* state) {
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
void Unpickler::build_array(Node* obj, Node* state) {
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
    if (raw->t != Node::T::List) error("object ndarray data is a ", describe(raw), ", not a list");
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
void Unpickler::build_dtype(Node* obj, Node* state) {
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

}  // namespace th::io::detail
