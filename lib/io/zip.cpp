#include "io/zip.hpp"

#include <zlib.h>

#include <algorithm>
#include <limits>

#include "core/error.hpp"
#include "io/bytes.hpp"

namespace th::io::detail {
namespace {

constexpr uint32_t kLocalSig = 0x04034b50;
constexpr uint32_t kCentralSig = 0x02014b50;
constexpr uint32_t kEndSig = 0x06054b50;
constexpr uint32_t kEnd64Sig = 0x06064b50;
constexpr uint32_t kEnd64LocatorSig = 0x07064b50;
constexpr uint64_t kMaxDeflateRatio = 1032;  // deflate cannot expand data more than this

class Cursor {
 public:
  Cursor(std::string_view data, const std::string& name) : data_(data), name_(name) {}
  uint64_t at(size_t offset, int n, const char* what) const {
    if (offset > data_.size() || static_cast<size_t>(n) > data_.size() - offset) {
      th::fail(name_, ": truncated zip archive: ", what, " at byte ", offset,
               " runs past the end (", data_.size(), " bytes)");
    }
    return load_le(data_.data() + offset, n);
  }
  std::string_view slice(uint64_t offset, uint64_t n, const char* what) const {
    if (offset > data_.size() || n > data_.size() - offset) {
      th::fail(name_, ": truncated zip archive: ", what, " at byte ", offset, " (", n,
               " bytes) runs past the end (", data_.size(), " bytes)");
    }
    return data_.substr(static_cast<size_t>(offset), static_cast<size_t>(n));
  }

 private:
  std::string_view data_;
  const std::string& name_;
};

std::string inflate_raw(std::string_view in, uint64_t size, const std::string& where) {
  if (size > in.size() * kMaxDeflateRatio + 1024) {
    th::fail(where, ": claims ", size, " bytes from ", in.size(),
             " compressed bytes, which deflate cannot do");
  }
  std::string out(static_cast<size_t>(size), '\0');
  z_stream z{};
  if (inflateInit2(&z, -MAX_WBITS) != Z_OK) th::fail(where, ": cannot initialise zlib");
  int status = Z_OK;
  size_t in_done = 0, out_done = 0;
  // zlib counts in uInt; feed at most 1 GiB at a time.
  constexpr size_t kChunk = size_t{1} << 30;
  while (status == Z_OK) {
    z.next_in = reinterpret_cast<Bytef*>(const_cast<char*>(in.data() + in_done));
    z.avail_in = static_cast<uInt>(std::min(kChunk, in.size() - in_done));
    z.next_out = reinterpret_cast<Bytef*>(out.data() + out_done);
    z.avail_out = static_cast<uInt>(std::min(kChunk, out.size() - out_done));
    const uInt in_before = z.avail_in, out_before = z.avail_out;
    status = inflate(&z, Z_NO_FLUSH);
    in_done += in_before - z.avail_in;
    out_done += out_before - z.avail_out;
    if (status == Z_BUF_ERROR && in_before == z.avail_in && out_before == z.avail_out) break;
    if (status == Z_BUF_ERROR) status = Z_OK;
  }
  inflateEnd(&z);
  if (status != Z_STREAM_END || out_done != out.size()) {
    th::fail(where, ": corrupt deflate data (",
             status == Z_STREAM_END ? "wrong size" : "inflate failed", ")");
  }
  return out;
}

}  // namespace

std::vector<ZipMember> read_zip(std::string_view archive, const std::string& name) {
  const Cursor c(archive, name);
  if (archive.size() < 22) th::fail(name, ": not a zip archive (", archive.size(), " bytes)");
  // End of central directory: the last signature within the comment's reach.
  size_t end = std::string_view::npos;
  const size_t lowest = archive.size() > 22 + 65535 ? archive.size() - 22 - 65535 : 0;
  for (size_t p = archive.size() - 22 + 1; p-- > lowest;) {
    if (load_le(archive.data() + p, 4) == kEndSig) {
      end = p;
      break;
    }
  }
  if (end == std::string_view::npos)
    th::fail(name, ": not a zip archive (no end of central directory)");
  uint64_t entries = c.at(end + 10, 2, "end record");
  uint64_t cd_size = c.at(end + 12, 4, "end record");
  uint64_t cd_offset = c.at(end + 16, 4, "end record");
  if (entries == 0xffff || cd_size == 0xffffffff || cd_offset == 0xffffffff) {
    if (end < 20 || c.at(end - 20, 4, "zip64 locator") != kEnd64LocatorSig) {
      th::fail(name, ": zip64 archive without a zip64 locator at byte ",
               end - std::min<size_t>(end, 20));
    }
    const uint64_t rec = c.at(end - 20 + 8, 8, "zip64 locator");
    if (c.at(rec, 4, "zip64 end record") != kEnd64Sig)
      th::fail(name, ": bad zip64 end record at byte ", rec);
    entries = c.at(rec + 32, 8, "zip64 end record");
    cd_size = c.at(rec + 40, 8, "zip64 end record");
    cd_offset = c.at(rec + 48, 8, "zip64 end record");
  }
  c.slice(cd_offset, cd_size, "central directory");
  if (entries > cd_size / 46)
    th::fail(name, ": central directory at byte ", cd_offset, " cannot hold ", entries, " entries");

  std::vector<ZipMember> members;
  uint64_t p = cd_offset;
  for (uint64_t e = 0; e < entries; ++e) {
    if (c.at(p, 4, "central directory entry") != kCentralSig) {
      th::fail(name, ": bad central directory entry at byte ", p);
    }
    const uint64_t flags = c.at(p + 8, 2, "central directory entry");
    const uint64_t method = c.at(p + 10, 2, "central directory entry");
    const uint64_t crc = c.at(p + 16, 4, "central directory entry");
    uint64_t csize = c.at(p + 20, 4, "central directory entry");
    uint64_t usize = c.at(p + 24, 4, "central directory entry");
    const uint64_t name_len = c.at(p + 28, 2, "central directory entry");
    const uint64_t extra_len = c.at(p + 30, 2, "central directory entry");
    const uint64_t comment_len = c.at(p + 32, 2, "central directory entry");
    uint64_t local = c.at(p + 42, 4, "central directory entry");
    const std::string member(c.slice(p + 46, name_len, "member name"));
    const std::string where = name + "/" + member;
    const std::string_view extra = c.slice(p + 46 + name_len, extra_len, "extra field");
    // zip64 extra field: the 64-bit values of the fields that are 0xffffffff, in order.
    for (size_t x = 0; x + 4 <= extra.size();) {
      const uint64_t id = load_le(extra.data() + x, 2), len = load_le(extra.data() + x + 2, 2);
      if (x + 4 + len > extra.size()) break;
      if (id == 1) {
        size_t f = x + 4;
        for (uint64_t* field : {&usize, &csize, &local}) {
          if (*field != 0xffffffff) continue;
          if (f + 8 > x + 4 + len) th::fail(where, ": short zip64 extra field at byte ", p);
          *field = load_le(extra.data() + f, 8);
          f += 8;
        }
      }
      x += 4 + len;
    }
    if (flags & 1) th::fail(where, ": encrypted zip members are not supported");
    if (c.at(local, 4, "local header") != kLocalSig)
      th::fail(where, ": bad local header at byte ", local);
    const uint64_t local_name = c.at(local + 26, 2, "local header");
    const uint64_t local_extra = c.at(local + 28, 2, "local header");
    const std::string_view raw =
        c.slice(local + 30 + local_name + local_extra, csize, "member data");
    ZipMember m;
    m.name = member;
    if (method == 0) {
      if (csize != usize)
        th::fail(where, ": stored member with different sizes (", csize, " vs ", usize, ")");
      m.data = std::string(raw);
    } else if (method == 8) {
      m.data = inflate_raw(raw, usize, where);
    } else {
      th::fail(where, ": unsupported zip compression method ", method,
               " (only stored and deflate)");
    }
    const uLong actual =
        crc32_z(crc32(0L, Z_NULL, 0), reinterpret_cast<const Bytef*>(m.data.data()), m.data.size());
    if (actual != crc) th::fail(where, ": CRC mismatch (corrupt archive)");
    members.push_back(std::move(m));
    p += 46 + name_len + extra_len + comment_len;
  }
  return members;
}

std::string write_zip(const std::vector<std::pair<std::string, std::string>>& members) {
  constexpr uint64_t kDate = (0 << 9) | (1 << 5) | 1;  // 1980-01-01
  std::string out, central;
  for (const auto& [name, data] : members) {
    if (data.size() >= 0xffffffffu || out.size() >= 0xffffffffu || name.size() > 0xffff) {
      th::fail("zip member '", name, "' is too large for a zip without zip64");
    }
    const uint64_t crc =
        crc32_z(crc32(0L, Z_NULL, 0), reinterpret_cast<const Bytef*>(data.data()), data.size());
    const uint64_t offset = out.size();
    append_le(out, kLocalSig, 4);
    append_le(out, 20, 2);  // version needed
    append_le(out, 0, 2);   // flags
    append_le(out, 0, 2);   // stored
    append_le(out, 0, 2);   // time
    append_le(out, kDate, 2);
    append_le(out, crc, 4);
    append_le(out, data.size(), 4);
    append_le(out, data.size(), 4);
    append_le(out, name.size(), 2);
    append_le(out, 0, 2);
    out += name;
    out += data;

    append_le(central, kCentralSig, 4);
    append_le(central, 0x0314, 2);  // made by: unix, 2.0
    append_le(central, 20, 2);
    append_le(central, 0, 2);
    append_le(central, 0, 2);
    append_le(central, 0, 2);
    append_le(central, kDate, 2);
    append_le(central, crc, 4);
    append_le(central, data.size(), 4);
    append_le(central, data.size(), 4);
    append_le(central, name.size(), 2);
    append_le(central, 0, 2);  // extra
    append_le(central, 0, 2);  // comment
    append_le(central, 0, 2);  // disk
    append_le(central, 0, 2);  // internal attributes
    append_le(central, uint64_t{0600} << 16, 4);
    append_le(central, offset, 4);
    central += name;
  }
  if (members.size() >= 0xffff || out.size() >= 0xffffffffu)
    th::fail("zip archive too large without zip64");
  const uint64_t cd_offset = out.size();
  out += central;
  append_le(out, kEndSig, 4);
  append_le(out, 0, 2);
  append_le(out, 0, 2);
  append_le(out, members.size(), 2);
  append_le(out, members.size(), 2);
  append_le(out, central.size(), 4);
  append_le(out, cd_offset, 4);
  append_le(out, 0, 2);
  return out;
}

}  // namespace th::io::detail
