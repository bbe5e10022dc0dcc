// Unpickled nodes -> Value (METHOD 1.4): containers with Python's key equality, object arrays
// as nested lists, scipy.sparse matrices densified, chumpy arrays as their `x`.
#include <algorithm>
#include <cmath>
#include <cstring>
#include <unordered_map>

#include "core/error.hpp"
#include "io/pickle_graph.hpp"

namespace th::io::detail {

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

namespace {

// Dense matrices from scipy.sparse may not exceed this many elements.
constexpr int64_t kMaxDenseElements = int64_t{1} << 26;

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
  Value key_value(Node* n, int depth) {
    return is_numpy_scalar(n) ? plain_value(n) : convert(n, depth);
  }

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

}  // namespace

Value to_value(Node* root, const std::string& name, size_t input_size) {
  return Converter(name, input_size).convert(root, 0);
}

}  // namespace th::io::detail
