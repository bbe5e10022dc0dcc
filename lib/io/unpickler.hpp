#pragma once
// Internal to lib/io: the pickle reader. Its member functions are split by concern: the opcode
// stack machine in pickle.cpp, what the opcodes build from globals (whitelist, REDUCE, NEWOBJ,
// BUILD) in pickle_objects.cpp.

#include <torch/types.h>

#include <cstddef>
#include <cstdint>
#include <deque>
#include <string>
#include <string_view>
#include <unordered_map>
#include <vector>

#include "core/error.hpp"
#include "io/dtype.hpp"
#include "io/pickle.hpp"
#include "io/pickle_graph.hpp"

namespace th::io::detail {

class Unpickler {
 public:
  Unpickler(std::string_view input, const std::string& name, const PickleExtensions* ext = nullptr);

  Value load();

 private:
  template <class... Parts>
  [[noreturn]] void error(const Parts&... parts) {
    th::fail(name_, ": ", parts..., " (opcode 0x", hex(op_), " at byte ", op_pos_, ")");
  }

  static std::string hex(uint8_t b) {
    const char* digits = "0123456789abcdef";
    return {digits[b >> 4], digits[b & 15]};
  }

  // Reading the input (pickle.cpp).
  std::string_view take(uint64_t n);
  uint64_t le(int n);
  std::string_view line();
  int64_t line_int();
  int64_t decode_long(std::string_view bytes);

  // Nodes, the stack, marks and the memo (pickle.cpp).
  Node* make(Node::T t);
  Node* make_int(int64_t v);
  Node* make_text(Node::T t, std::string_view view);
  Node* make_owned(Node::T t, std::string text);
  Node* make_str(std::string_view utf8);

  size_t floor() const { return marks_.empty() ? 0 : marks_.back(); }
  void push(Node* n) { stack_.push_back(n); }
  Node* pop();
  Node* top();
  std::vector<Node*> pop_mark();

  void memo_put(uint64_t index);
  void memo_get(uint64_t index);

  // One opcode (pickle.cpp).
  void step();

  // Globals and what they build (pickle_objects.cpp).
  Node* make_global(std::string_view module, std::string_view name);

  static bool is_global(const Node* n, Global g) {
    return n->t == Node::T::Global && static_cast<Global>(n->i) == g;
  }
  static bool is_text(const Node* n) { return n->t == Node::T::Str || n->t == Node::T::Bytes; }

  std::string_view raw_bytes(const Node* n, std::string& storage, const char* what);
  std::vector<int64_t> shape_of(const Node* n, const char* what);
  torch::Tensor array_from(std::string_view data, const detail::NpyDType& dtype,
                           const std::vector<int64_t>& shape, bool fortran);
  std::string encode_text(const Node* str, const Node* encoding);

  Node* call(Node* callable, Node* args);
  Node* call_extension(Node* callable, Node* args);
  Node* make_instance(const Node* cls);
  Node* new_object(Node* cls, Node* args);
  void build(Node* obj, Node* state);
  void build_array(Node* obj, Node* state);
  void build_dtype(Node* obj, Node* state);

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

}  // namespace th::io::detail
