#pragma once
// Internal to lib/io: the object graph the pickle reader builds (pickle.cpp,
// pickle_objects.cpp) and its conversion into a Value (pickle_convert.cpp).

#include <torch/types.h>

#include <cstddef>
#include <cstdint>
#include <memory>
#include <string>
#include <string_view>
#include <vector>

#include "io/dtype.hpp"
#include "io/pickle.hpp"

namespace th::io::detail {

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
  Csc,         // scipy.sparse csc_matrix / csc_array
  Csr,         // scipy.sparse csr_matrix / csr_array
  Chumpy,      // chumpy.ch.Ch
  Extension,   // a global of PickleExtensions::globals
  PlainClass,  // a class under PickleExtensions::class_prefixes: NEWOBJ + BUILD(dict)
};

inline bool is_instance_class(Global g) {
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
inline constexpr const char* kNumpyScalar = "numpy scalar";

inline bool is_numpy_scalar(const Node* n) {
  return n->t == Node::T::Array && n->name == kNumpyScalar && n->tensor.dim() == 0 &&
         !n->tensor.is_complex();
}

// Python-ish type of a node for error messages ("dict", "ndarray", ...); describe() adds the
// name of a global or of an instance's class ("global numpy.ndarray").
const char* node_type_name(const Node* n);
std::string describe(const Node* n);

// The Value a node stands for; `name` stands for the file in error messages. Checks nesting
// depth and bounds the work by `input_size` (the pickle's length), so that memo sharing cannot
// blow a small file up into an exponentially large tree.
Value to_value(Node* root, const std::string& name, size_t input_size);

}  // namespace th::io::detail
