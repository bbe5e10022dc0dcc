// The pickle reader (METHOD 1.4): a stack machine over the opcodes, with its stack, marks and
// memo. What the opcodes build from globals (the whitelist, REDUCE, NEWOBJ, BUILD) is in
// pickle_objects.cpp, the conversion of the result into a Value in pickle_convert.cpp.
#include "io/pickle.hpp"

#include <charconv>
#include <cstring>

#include "core/error.hpp"
#include "io/bytes.hpp"
#include "io/unpickler.hpp"

namespace th::io {

namespace detail {

Unpickler::Unpickler(std::string_view input, const std::string& name, const PickleExtensions* ext)
    : in_(input), name_(name), ext_(ext) {
  none_ = make(Node::T::None);
  true_ = make(Node::T::Bool);
  true_->i = 1;
  false_ = make(Node::T::Bool);
}

Value Unpickler::load() {
  for (;;) {
    op_pos_ = pos_;
    if (pos_ >= in_.size())
      th::fail(name_, ": truncated: the data ends at byte ", in_.size(), " before STOP");
    op_ = static_cast<uint8_t>(in_[pos_++]);
    if (op_ == '.') break;
    step();
  }
  Node* result = pop();
  return to_value(result, name_, in_.size());
}

std::string_view Unpickler::take(uint64_t n) {
  if (n > in_.size() - pos_) {
    th::fail(name_, ": truncated: opcode 0x", hex(op_), " at byte ", op_pos_, " needs ", n,
             " more bytes, but the data ends at byte ", in_.size());
  }
  std::string_view out = in_.substr(pos_, static_cast<size_t>(n));
  pos_ += static_cast<size_t>(n);
  return out;
}

uint64_t Unpickler::le(int n) { return detail::load_le(take(n).data(), n); }

std::string_view Unpickler::line() {
  const size_t end = in_.find('\n', pos_);
  if (end == std::string_view::npos) {
    th::fail(name_, ": truncated: opcode 0x", hex(op_), " at byte ", op_pos_,
             " needs a newline-terminated argument, but the data ends at byte ", in_.size());
  }
  std::string_view out = in_.substr(pos_, end - pos_);
  pos_ = end + 1;
  return out;
}

int64_t Unpickler::line_int() {
  std::string_view text = line();
  if (!text.empty() && text.back() == 'L') text.remove_suffix(1);  // Python 2 longs
  if (!text.empty() && text.front() == '+') text.remove_prefix(1);
  int64_t v = 0;
  const auto [end, ec] = std::from_chars(text.data(), text.data() + text.size(), v);
  if (ec != std::errc() || end != text.data() + text.size()) error("bad integer '", text, "'");
  return v;
}

Node* Unpickler::make(Node::T t) {
  Node& n = arena_.emplace_back();
  n.t = t;
  n.pos = op_pos_;
  return &n;
}

Node* Unpickler::make_int(int64_t v) {
  Node* n = make(Node::T::Int);
  n->i = v;
  return n;
}

Node* Unpickler::make_text(Node::T t, std::string_view view) {
  Node* n = make(t);
  n->text = view;
  return n;
}

Node* Unpickler::make_owned(Node::T t, std::string text) {
  Node* n = make(t);
  n->owned = std::move(text);
  n->text = n->owned;
  return n;
}

Node* Unpickler::make_str(std::string_view utf8) {
  if (!detail::utf8_length(utf8)) error("invalid UTF-8 in a str");
  return make_text(Node::T::Str, utf8);
}

Node* Unpickler::pop() {
  if (stack_.size() <= floor()) error("stack underflow");
  Node* n = stack_.back();
  stack_.pop_back();
  return n;
}

Node* Unpickler::top() {
  if (stack_.size() <= floor()) error("stack underflow");
  return stack_.back();
}

std::vector<Node*> Unpickler::pop_mark() {
  if (marks_.empty()) error("no MARK to pop back to");
  const size_t mark = marks_.back();
  marks_.pop_back();
  std::vector<Node*> items(stack_.begin() + static_cast<std::ptrdiff_t>(mark), stack_.end());
  stack_.resize(mark);
  return items;
}

void Unpickler::memo_put(uint64_t index) { memo_[index] = top(); }

void Unpickler::memo_get(uint64_t index) {
  const auto it = memo_.find(index);
  if (it == memo_.end()) error("memo entry ", index, " was never stored");
  push(it->second);
}

int64_t Unpickler::decode_long(std::string_view bytes) {
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

void Unpickler::step() {
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
      Node* n = make(op_ == 'l' ? Node::T::List : op_ == 't' ? Node::T::Tuple : Node::T::FrozenSet);
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
      if (module->t != Node::T::Str || name->t != Node::T::Str) error("STACK_GLOBAL needs two str");
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
      n->value = std::make_shared<Value>(ext_->persistent_load(to_value(pid, name_, in_.size())));
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

}  // namespace detail

Value parse_pickle(std::string_view bytes, const std::string& name) {
  return detail::Unpickler(bytes, name).load();
}

Value parse_pickle(std::string_view bytes, const std::string& name,
                   const PickleExtensions& extensions) {
  return detail::Unpickler(bytes, name, &extensions).load();
}

Value read_pickle(const std::filesystem::path& path) {
  const std::string bytes = detail::read_file(path);
  return parse_pickle(bytes, path.string());
}

}  // namespace th::io
