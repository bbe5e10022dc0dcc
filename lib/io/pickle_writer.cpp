// The pickle writer: CPython 3.11's C pickler (Modules/_pickle.c) replayed for the objects a
// Value holds, with numpy 1.24's ndarray/dtype __reduce__ (METHOD 1.4). Every save() of CPython
// is one call here that starts with boundary() (where protocol 4 may close a FRAME), then
// checks the memo, then writes the same opcodes and memo puts in the same order.
#include "io/pickle_writer.hpp"

#include <cstring>
#include <unordered_map>

#include "core/error.hpp"
#include "io/bytes.hpp"
#include "io/dtype.hpp"

namespace th::io {
namespace {

constexpr size_t kNoFrame = static_cast<size_t>(-1);
constexpr size_t kFrameTarget = 64 * 1024;  // FRAME_SIZE_TARGET
constexpr size_t kFrameHeader = 9;
constexpr size_t kFrameMin = 4;  // shorter frames are dropped
constexpr size_t kBatch = 1000;  // BATCHSIZE of APPENDS/SETITEMS/ADDITEMS

// Which CPython string object a str is, which decides what the memo shares:
//  Fresh     made at runtime (dtype codes, latin-1 text of array data): never shared;
//  Single    a one-character latin-1 string made at runtime (byte orders '<' '|', ...) or a
//            one-character non-identifier literal: CPython's per-character singletons;
//  Interned  identifier-like strings ([A-Za-z0-9_]*): interned, shared with 'latin1' and the
//            module name 'numpy' that numpy/pickle use;
//  Literal   any other string of the Value: one script's equal constants are one object.
enum class Space : char { Fresh = 'F', Single = '1', Interned = 'I', Literal = 'L' };

bool identifier_like(std::string_view s) {
  for (char c : s) {
    const bool ok =
        (c >= 'a' && c <= 'z') || (c >= 'A' && c <= 'Z') || (c >= '0' && c <= '9') || c == '_';
    if (!ok) return false;
  }
  return true;
}

Space space_of_value_str(std::string_view utf8) {
  if (identifier_like(utf8)) return Space::Interned;
  if (detail::utf8_length(utf8) == size_t{1} && detail::utf8_to_latin1(utf8)) return Space::Single;
  return Space::Literal;
}

class Pickler {
 public:
  explicit Pickler(int protocol) : proto_(protocol) {
    if (protocol < 2 || protocol > 4)
      th::fail("pickle protocol ", protocol, " is not supported for writing (2-4)");
  }

  // pickle.dumps(value): PROTO, the object, STOP.
  std::string dump(const Value& value) {
    start();
    save(value, 0);
    return finish();
  }

  // pickle.dumps(np.array(item, dtype=object) as a 0-d array), as np.save pickles a dict.
  std::string dump_object_array(const Value& item) {
    start();
    boundary();
    save_reconstruct_call();
    memo_put();
    boundary();  // state (1, (), dtype('O'), False, [item])
    write("(");
    save_int(1);
    boundary();
    write(")");
    save_dtype({'|', 'O', 8});
    save_bool(false);
    boundary();
    write("]");
    memo_put();
    save(item, 1);
    write("a");
    write("t");
    memo_put();
    write("b");
    return finish();
  }

 private:
  void start() {
    out_.push_back('\x80');
    out_.push_back(static_cast<char>(proto_));
    framing_ = proto_ >= 4;
  }
  std::string finish() {
    write(".");
    commit_frame();
    return std::move(out_);
  }

  // --- output and framing (_Pickler_Write, _Pickler_CommitFrame, _Pickler_OpcodeBoundary) ---
  void write(std::string_view data) {
    if (framing_ && frame_start_ == kNoFrame) {
      frame_start_ = out_.size();
      out_.append(kFrameHeader, '\xfe');
    }
    out_.append(data);
  }
  void write_byte(uint8_t b) { write(std::string_view(reinterpret_cast<const char*>(&b), 1)); }
  void commit_frame() {
    if (!framing_ || frame_start_ == kNoFrame) return;
    const size_t length = out_.size() - frame_start_ - kFrameHeader;
    if (length >= kFrameMin) {
      out_[frame_start_] = '\x95';
      for (size_t i = 0; i < 8; ++i)
        out_[frame_start_ + 1 + i] = static_cast<char>((length >> (8 * i)) & 0xff);
    } else {
      out_.erase(frame_start_, kFrameHeader);
    }
    frame_start_ = kNoFrame;
  }
  void boundary() {
    if (framing_ && frame_start_ != kNoFrame &&
        out_.size() - frame_start_ - kFrameHeader >= kFrameTarget) {
      commit_frame();
    }
  }
  // Large payloads go outside any frame (_Pickler_write_bytes).
  void write_payload(const std::string& header, std::string_view payload) {
    if (payload.size() >= kFrameTarget) {
      commit_frame();
      const bool framing = framing_;
      framing_ = false;
      write(header);
      write(payload);
      framing_ = framing;
    } else {
      write(header);
      write(payload);
    }
  }

  // --- memo ---
  uint32_t memo_put() {
    const uint32_t index = memo_count_++;
    if (proto_ >= 4) {
      write("\x94");  // MEMOIZE
    } else if (index < 256) {
      write("q");
      write_byte(static_cast<uint8_t>(index));
    } else {
      std::string op = "r";
      detail::append_le(op, index, 4);
      write(op);
    }
    return index;
  }
  void memo_get(uint32_t index) {
    std::string op;
    if (index < 256) {
      op = "h";
      op.push_back(static_cast<char>(index));
    } else {
      op = "j";
      detail::append_le(op, index, 4);
    }
    write(op);
  }
  // True (and a GET written) when `key` is memoized in `memo`.
  bool memo_hit(const std::unordered_map<std::string, uint32_t>& memo, const std::string& key) {
    const auto it = memo.find(key);
    if (it == memo.end()) return false;
    memo_get(it->second);
    return true;
  }

  // --- atoms ---
  void save_none() {
    boundary();
    write("N");
  }
  void save_bool(bool v) {
    boundary();
    write(v ? "\x88" : "\x89");
  }
  void save_int(int64_t v) {
    boundary();
    std::string op;
    if (v >= 0 && v <= 0xff) {
      op = "K";
      detail::append_le(op, static_cast<uint64_t>(v), 1);
    } else if (v >= 0 && v <= 0xffff) {
      op = "M";
      detail::append_le(op, static_cast<uint64_t>(v), 2);
    } else if (v >= INT32_MIN && v <= INT32_MAX) {
      op = "J";
      detail::append_le(op, static_cast<uint64_t>(static_cast<uint32_t>(static_cast<int32_t>(v))),
                        4);
    } else {
      // LONG1 with pickle's encode_long: (bit_length >> 3) + 1 bytes of two's complement,
      // dropping a redundant 0xff sign byte of negative numbers.
      const uint64_t magnitude = v < 0 ? ~static_cast<uint64_t>(v) + 1 : static_cast<uint64_t>(v);
      int bits = 0;
      for (uint64_t m = magnitude; m != 0; m >>= 1) ++bits;
      size_t n = static_cast<size_t>(bits >> 3) + 1;
      std::string body;
      for (size_t i = 0; i < n; ++i) {
        body.push_back(i < 8 ? static_cast<char>((static_cast<uint64_t>(v) >> (8 * i)) & 0xff)
                             : static_cast<char>(v < 0 ? 0xff : 0x00));
      }
      if (v < 0 && n > 1 && static_cast<uint8_t>(body[n - 1]) == 0xff &&
          (static_cast<uint8_t>(body[n - 2]) & 0x80)) {
        body.pop_back();
      }
      op = "\x8a";
      op.push_back(static_cast<char>(body.size()));
      op += body;
    }
    write(op);
  }
  void save_float(double v) {
    boundary();
    uint64_t bits = 0;
    std::memcpy(&bits, &v, sizeof bits);
    std::string op = "G";
    for (int i = 7; i >= 0; --i) op.push_back(static_cast<char>((bits >> (8 * i)) & 0xff));
    write(op);
  }

  void save_str(std::string_view utf8, Space space) {
    boundary();
    const std::string key = std::string(1, static_cast<char>(space)) + std::string(utf8);
    if (space != Space::Fresh && memo_hit(strs_, key)) return;
    std::string header;
    if (proto_ >= 4 && utf8.size() < 256) {
      header = "\x8c";
      detail::append_le(header, utf8.size(), 1);
    } else if (utf8.size() <= 0xffffffffu) {
      header = "X";
      detail::append_le(header, utf8.size(), 4);
    } else if (proto_ >= 4) {
      header = "\x8d";
      detail::append_le(header, utf8.size(), 8);
    } else {
      th::fail("cannot pickle a str of ", utf8.size(), " bytes at protocol ", proto_);
    }
    write_payload(header, utf8);
    const uint32_t index = memo_put();
    if (space != Space::Fresh) strs_[key] = index;
  }

  // Bytes of one byte or none are CPython singletons; other bytes of the Value are literals
  // (equal ones shared); array data is fresh.
  void save_bytes(std::string_view data, bool literal) {
    boundary();
    const bool shared = data.size() <= 1 || literal;
    const std::string key = std::string(data.size() <= 1 ? "s" : "l") + std::string(data);
    if (shared && memo_hit(bytes_, key)) return;
    uint32_t index = 0;
    if (proto_ >= 3) {
      std::string header;
      if (data.size() < 256) {
        header = "C";
        detail::append_le(header, data.size(), 1);
      } else if (data.size() <= 0xffffffffu) {
        header = "B";
        detail::append_le(header, data.size(), 4);
      } else if (proto_ >= 4) {
        header = "\x8e";
        detail::append_le(header, data.size(), 8);
      } else {
        th::fail("cannot pickle bytes of ", data.size(), " bytes at protocol ", proto_);
      }
      write_payload(header, data);
      index = memo_put();
    } else if (data.empty()) {
      // Protocol 2: bytes() ...
      save_global("builtins", "bytes");
      boundary();
      write(")");
      write("R");
      index = memo_put();
    } else {
      // ... or _codecs.encode(data.decode('latin1'), 'latin1').
      save_global("_codecs", "encode");
      boundary();
      save_str(detail::latin1_to_utf8(data), data.size() == 1 ? Space::Single : Space::Fresh);
      save_str("latin1", Space::Interned);
      write("\x86");  // TUPLE2
      memo_put();
      write("R");
      index = memo_put();
    }
    if (shared) bytes_[key] = index;
  }

  void save_global(const std::string& module, const std::string& name) {
    boundary();
    const std::string key = module + " " + name;
    if (memo_hit(globals_, key)) return;
    if (proto_ >= 4) {
      save_str(module, identifier_like(module) ? Space::Interned : Space::Fresh);
      save_str(name, Space::Fresh);
      write("\x93");  // STACK_GLOBAL
    } else {
      const std::string mod =
          (proto_ < 3 && module == "builtins") ? "__builtin__" : module;  // fix_imports
      write("c" + mod + "\n" + name + "\n");
    }
    globals_[key] = memo_put();
  }

  // --- containers ---
  void save(const Value& v, int depth) {
    if (depth > kMaxDepth)
      th::fail("cannot pickle a value nested deeper than ", kMaxDepth, " levels");
    switch (v.kind()) {
      case Value::Kind::None:
        return save_none();
      case Value::Kind::Bool:
        return save_bool(v.as_bool());
      case Value::Kind::Int:
        return save_int(v.as_int());
      case Value::Kind::Float:
        return save_float(v.as_float());
      case Value::Kind::Str:
        return save_str(v.as_str(), space_of_value_str(v.as_str()));
      case Value::Kind::Bytes:
        return save_bytes(v.as_str(), true);
      case Value::Kind::List:
        return save_list(v.as_list(), depth);
      case Value::Kind::Tuple:
        return save_tuple(v.as_list(), depth);
      case Value::Kind::Set:
        return save_set(v.as_list(), depth);
      case Value::Kind::Dict:
        return save_dict(v.as_dict(), depth);
      case Value::Kind::Array:
        return save_array(v.as_tensor());
      case Value::Kind::Object:
        th::fail("cannot pickle a ", v.type_name());
    }
  }

  void save_tuple(const Value::List& items, int depth) {
    boundary();
    if (items.empty()) {
      write(")");  // EMPTY_TUPLE, not memoized
      return;
    }
    if (items.size() <= 3) {
      for (const auto& item : items) save(item, depth + 1);
      write_byte(static_cast<uint8_t>(0x84 + items.size()));  // TUPLE1..3
    } else {
      write("(");
      for (const auto& item : items) save(item, depth + 1);
      write("t");
    }
    memo_put();
  }

  void save_list(const Value::List& items, int depth) {
    boundary();
    write("]");
    memo_put();
    if (items.empty()) return;
    if (items.size() == 1) {
      save(items[0], depth + 1);
      write("a");
      return;
    }
    size_t total = 0;
    do {
      write("(");
      size_t batch = 0;
      while (total < items.size()) {
        save(items[total++], depth + 1);
        if (++batch == kBatch) break;
      }
      write("e");
    } while (total < items.size());
  }

  void save_dict(const Value::Dict& entries, int depth) {
    boundary();
    write("}");
    memo_put();
    if (entries.empty()) return;
    if (entries.size() == 1) {
      save(entries[0].first, depth + 1);
      save(entries[0].second, depth + 1);
      write("s");
      return;
    }
    // batch_dict_exact: a multiple of BATCHSIZE ends with an empty MARK ... SETITEMS.
    size_t next = 0, batch = 0;
    do {
      batch = 0;
      write("(");
      while (next < entries.size()) {
        save(entries[next].first, depth + 1);
        save(entries[next].second, depth + 1);
        ++next;
        if (++batch == kBatch) break;
      }
      write("u");
    } while (batch == kBatch);
  }

  void save_set(const Value::List& items, int depth) {
    boundary();
    if (proto_ < 4) {  // set(list): REDUCE
      save_global("builtins", "set");
      boundary();
      save_list(items, depth + 1);
      write("\x85");
      memo_put();
      write("R");
      memo_put();
      return;
    }
    write("\x8f");  // EMPTY_SET
    memo_put();
    if (items.empty()) return;
    size_t next = 0, batch = 0;
    do {
      batch = 0;
      write("(");
      while (next < items.size()) {
        save(items[next++], depth + 1);
        if (++batch == kBatch) break;
      }
      write("\x90");  // ADDITEMS
    } while (batch == kBatch);
  }

  // --- numpy ---
  // _reconstruct, (ndarray, (0,), b'b'), REDUCE (the caller memoizes the array).
  void save_reconstruct_call() {
    save_global("numpy.core.multiarray", "_reconstruct");
    boundary();
    save_global("numpy", "ndarray");
    boundary();
    save_int(0);
    write("\x85");
    memo_put();
    save_bytes("b", false);
    write("\x87");
    memo_put();
    write("R");
  }

  void save_array(const torch::Tensor& array) {
    boundary();
    const std::string key =
        std::to_string(reinterpret_cast<uintptr_t>(array.unsafeGetTensorImpl()));
    if (memo_hit(arrays_, key)) return;
    const detail::NpyDType dtype = detail::dtype_of(array.scalar_type());
    save_reconstruct_call();
    arrays_[key] = memo_put();
    kept_.push_back(array);  // keeps the TensorImpl (the memo key) alive
    boundary();              // state (1, shape, dtype, is_fortran, data)
    write("(");
    save_int(1);
    boundary();
    const auto shape = array.sizes();
    if (shape.empty()) {
      write(")");
    } else {
      if (shape.size() <= 3) {
        for (int64_t d : shape) save_int(d);
        write_byte(static_cast<uint8_t>(0x84 + shape.size()));
      } else {
        write("(");
        for (int64_t d : shape) save_int(d);
        write("t");
      }
      memo_put();
    }
    save_dtype(dtype);
    save_bool(false);
    save_bytes(detail::encode_array(array.cpu()), false);
    write("t");
    memo_put();
    write("b");
  }

  // numpy.dtype(code, False, True) + BUILD((3, byteorder, None, None, None, -1, -1, flags)).
  // Dtypes of native arrays are numpy singletons, so each is written once.
  void save_dtype(const detail::NpyDType& dtype) {
    boundary();
    if (memo_hit(dtypes_, dtype.descr())) return;
    save_global("numpy", "dtype");
    boundary();
    save_str(dtype.code(), Space::Fresh);
    save_bool(false);
    save_bool(true);
    write("\x87");
    memo_put();
    write("R");
    dtypes_[dtype.descr()] = memo_put();
    boundary();
    write("(");
    save_int(3);
    save_str(std::string(1, dtype.order), Space::Single);
    save_none();
    save_none();
    save_none();
    save_int(-1);
    save_int(-1);
    save_int(dtype.is_object() ? 63 : 0);  // NPY_OBJECT_DTYPE_FLAGS
    write("t");
    memo_put();
    write("b");
  }

  int proto_;
  std::string out_;
  bool framing_ = false;
  size_t frame_start_ = kNoFrame;
  uint32_t memo_count_ = 0;
  std::unordered_map<std::string, uint32_t> strs_, bytes_, globals_, dtypes_, arrays_;
  std::vector<torch::Tensor> kept_;
};

}  // namespace

std::string pickle_bytes(const Value& value, int protocol) { return Pickler(protocol).dump(value); }

void write_pickle(const std::filesystem::path& path, const Value& value, int protocol) {
  detail::write_file_atomic(path, pickle_bytes(value, protocol));
}

namespace detail {
std::string pickle_object_array(const Value& item, int protocol) {
  return Pickler(protocol).dump_object_array(item);
}
}  // namespace detail

}  // namespace th::io
