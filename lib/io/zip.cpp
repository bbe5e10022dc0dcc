#include "io/zip.hpp"

#include <zlib.h>

#include <algorithm>
#include <cstdint>
#include <limits>

#include "core/error.hpp"
#include "core/files.hpp"
#include "io/bytes.hpp"

namespace th::io {
using namespace detail;
namespace {

constexpr uint32_t kLocalSig = 0x04034b50;
constexpr uint32_t kCentralSig = 0x02014b50;
constexpr uint32_t kEndSig = 0x06054b50;
constexpr uint32_t kEnd64Sig = 0x06064b50;
constexpr uint32_t kEnd64LocatorSig = 0x07064b50;
constexpr uint64_t kMaxDeflateRatio = 1032;  // deflate cannot expand data more than this

// Bounds-checked reads from an archive (memory or file), naming the archive in errors.
class Cursor {
 public:
  Cursor(const ZipSource& source, const std::string& name) : source_(source), name_(name) {}
  uint64_t size() const { return source_.size(); }
  void check(uint64_t offset, uint64_t n, const char* what) const {
    if (offset > size() || n > size() - offset) {
      th::fail(name_, ": truncated zip archive: ", what, " at byte ", offset, " (", n,
               " bytes) runs past the end (", size(), " bytes)");
    }
  }
  uint64_t at(uint64_t offset, int n, const char* what) const {
    check(offset, static_cast<uint64_t>(n), what);
    const std::string bytes = source_.read(offset, static_cast<uint64_t>(n));
    return load_le(bytes.data(), n);
  }
  std::string slice(uint64_t offset, uint64_t n, const char* what) const {
    check(offset, n, what);
    return source_.read(offset, n);
  }

 private:
  const ZipSource& source_;
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

std::string MemorySource::read(uint64_t offset, uint64_t n) const {
  return std::string(bytes_.substr(static_cast<size_t>(offset), static_cast<size_t>(n)));
}

// path_ is initialised first: a FIFO or a device is refused before the stream opens it (which
// would block on a FIFO).
FileSource::FileSource(const std::filesystem::path& path)
    : path_((refuse_special_file(path, "input"), path)), in_(path, std::ios::binary) {
  std::error_code ec;
  size_ = std::filesystem::file_size(path, ec);
  if (!in_ || ec)
    th::fail("cannot open '", path.string(), "'", ec ? ": " + ec.message() : std::string());
}

std::string FileSource::read(uint64_t offset, uint64_t n) const {
  std::string out(static_cast<size_t>(n), '\0');
  in_.clear();
  in_.seekg(static_cast<std::streamoff>(offset));
  in_.read(out.data(), static_cast<std::streamsize>(n));
  if (static_cast<uint64_t>(in_.gcount()) != n)
    th::fail("cannot read ", n, " bytes at byte ", offset, " of '", path_.string(), "'");
  return out;
}

std::vector<ZipEntry> list_zip(const ZipSource& source, const std::string& name) {
  const Cursor c(source, name);
  const uint64_t total = source.size();
  if (total < 22) th::fail(name, ": not a zip archive (", total, " bytes)");
  // End of central directory: the last signature within the comment's reach.
  const uint64_t lowest = total > 22 + 65535 ? total - 22 - 65535 : 0;
  const std::string tail = c.slice(lowest, total - lowest, "end of archive");
  uint64_t end = UINT64_MAX;
  for (size_t p = tail.size() - 22 + 1; p-- > 0;) {
    if (load_le(tail.data() + p, 4) == kEndSig) {
      end = lowest + p;
      break;
    }
  }
  if (end == UINT64_MAX) th::fail(name, ": not a zip archive (no end of central directory)");
  uint64_t entries = c.at(end + 10, 2, "end record");
  uint64_t cd_size = c.at(end + 12, 4, "end record");
  uint64_t cd_offset = c.at(end + 16, 4, "end record");
  if (entries == 0xffff || cd_size == 0xffffffff || cd_offset == 0xffffffff) {
    if (end < 20 || c.at(end - 20, 4, "zip64 locator") != kEnd64LocatorSig) {
      th::fail(name, ": zip64 archive without a zip64 locator at byte ",
               end - std::min<uint64_t>(end, 20));
    }
    const uint64_t rec = c.at(end - 20 + 8, 8, "zip64 locator");
    if (c.at(rec, 4, "zip64 end record") != kEnd64Sig)
      th::fail(name, ": bad zip64 end record at byte ", rec);
    entries = c.at(rec + 32, 8, "zip64 end record");
    cd_size = c.at(rec + 40, 8, "zip64 end record");
    cd_offset = c.at(rec + 48, 8, "zip64 end record");
  }
  if (entries > cd_size / 46)
    th::fail(name, ": central directory at byte ", cd_offset, " cannot hold ", entries, " entries");
  // The central directory in memory (it lies inside the archive, so no larger than it).
  const std::string cd_bytes = c.slice(cd_offset, cd_size, "central directory");
  const MemorySource cd_source(cd_bytes);
  const std::string cd_name =
      name + " (central directory at byte " + std::to_string(cd_offset) + ")";
  const Cursor cd(cd_source, cd_name);

  std::vector<ZipEntry> out;
  uint64_t p = 0;
  for (uint64_t e = 0; e < entries; ++e) {
    if (cd.at(p, 4, "central directory entry") != kCentralSig) {
      th::fail(name, ": bad central directory entry at byte ", cd_offset + p);
    }
    const uint64_t flags = cd.at(p + 8, 2, "central directory entry");
    ZipEntry m;
    m.method = cd.at(p + 10, 2, "central directory entry");
    m.crc = cd.at(p + 16, 4, "central directory entry");
    m.compressed_size = cd.at(p + 20, 4, "central directory entry");
    m.size = cd.at(p + 24, 4, "central directory entry");
    const uint64_t name_len = cd.at(p + 28, 2, "central directory entry");
    const uint64_t extra_len = cd.at(p + 30, 2, "central directory entry");
    const uint64_t comment_len = cd.at(p + 32, 2, "central directory entry");
    uint64_t local = cd.at(p + 42, 4, "central directory entry");
    m.name = cd.slice(p + 46, name_len, "member name");
    const std::string where = name + "/" + m.name;
    const std::string extra = cd.slice(p + 46 + name_len, extra_len, "extra field");
    // zip64 extra field: the 64-bit values of the fields that are 0xffffffff, in order.
    for (size_t x = 0; x + 4 <= extra.size();) {
      const uint64_t id = load_le(extra.data() + x, 2), len = load_le(extra.data() + x + 2, 2);
      if (x + 4 + len > extra.size()) break;
      if (id == 1) {
        size_t f = x + 4;
        for (uint64_t* field : {&m.size, &m.compressed_size, &local}) {
          if (*field != 0xffffffff) continue;
          if (f + 8 > x + 4 + len)
            th::fail(where, ": short zip64 extra field at byte ", cd_offset + p);
          *field = load_le(extra.data() + f, 8);
          f += 8;
        }
      }
      x += 4 + len;
    }
    if (flags & 1) th::fail(where, ": encrypted zip members are not supported");
    if (m.method != 0 && m.method != 8)
      th::fail(where, ": unsupported zip compression method ", m.method,
               " (only stored and deflate)");
    if (m.method == 0 && m.compressed_size != m.size)
      th::fail(where, ": stored member with different sizes (", m.compressed_size, " vs ", m.size,
               ")");
    if (c.at(local, 4, "local header") != kLocalSig)
      th::fail(where, ": bad local header at byte ", local);
    const uint64_t local_name = c.at(local + 26, 2, "local header");
    const uint64_t local_extra = c.at(local + 28, 2, "local header");
    m.data_offset = local + 30 + local_name + local_extra;
    c.check(m.data_offset, m.compressed_size, "member data");
    out.push_back(std::move(m));
    p += 46 + name_len + extra_len + comment_len;
  }
  return out;
}

std::string read_member(const ZipSource& source, const ZipEntry& entry, const std::string& name) {
  const std::string where = name + "/" + entry.name;
  const Cursor c(source, name);
  std::string raw = c.slice(entry.data_offset, entry.compressed_size, "member data");
  std::string data = entry.method == 0 ? std::move(raw) : inflate_raw(raw, entry.size, where);
  const uLong actual =
      crc32_z(crc32(0L, Z_NULL, 0), reinterpret_cast<const Bytef*>(data.data()), data.size());
  if (actual != entry.crc) th::fail(where, ": CRC mismatch (corrupt archive)");
  return data;
}

std::vector<ZipMember> read_zip(std::string_view archive, const std::string& name) {
  const MemorySource source(archive);
  std::vector<ZipMember> members;
  for (const auto& e : list_zip(source, name))
    members.push_back({e.name, read_member(source, e, name)});
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

}  // namespace th::io
