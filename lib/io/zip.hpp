#pragma once
// The zip container of .npz files and torch.save archives: reading stored and deflated members
// (with zip64 records, as np.savez writes them), listing an archive without reading it whole,
// and writing stored members. Part of lib/io's public API (checkpoints are checked through it).

#include <cstdint>
#include <filesystem>
#include <fstream>
#include <string>
#include <string_view>
#include <utility>
#include <vector>

namespace th::io {

struct ZipMember {
  std::string name;
  std::string data;  // uncompressed, CRC-checked
};

// Random access to the bytes of an archive: in memory or in a file (a checkpoint is checked
// without reading it whole).
class ZipSource {
 public:
  virtual ~ZipSource() = default;
  virtual uint64_t size() const = 0;
  // `n` bytes at `offset`; the caller has checked that they lie inside.
  virtual std::string read(uint64_t offset, uint64_t n) const = 0;
};

class MemorySource : public ZipSource {
 public:
  explicit MemorySource(std::string_view bytes) : bytes_(bytes) {}
  uint64_t size() const override { return bytes_.size(); }
  std::string read(uint64_t offset, uint64_t n) const override;

 private:
  std::string_view bytes_;
};

class FileSource : public ZipSource {
 public:
  explicit FileSource(const std::filesystem::path& path);  // throws th::Error naming the path
  uint64_t size() const override { return size_; }
  std::string read(uint64_t offset, uint64_t n) const override;

 private:
  std::filesystem::path path_;
  mutable std::ifstream in_;
  uint64_t size_ = 0;
};

// One member as the central directory and its local header describe it; its data lies inside
// the archive (checked).
struct ZipEntry {
  std::string name;
  uint64_t method = 0;  // 0 stored, 8 deflate (others are refused)
  uint64_t crc = 0;
  uint64_t compressed_size = 0;
  uint64_t size = 0;  // uncompressed, as claimed
  uint64_t data_offset = 0;
};

// The members in central-directory order, without reading their data. Throws th::Error naming
// `name`, the member and the byte offset for anything malformed, encrypted, or compressed other
// than stored/deflate.
std::vector<ZipEntry> list_zip(const ZipSource& source, const std::string& name);

// The uncompressed, CRC-checked data of one member listed by list_zip.
std::string read_member(const ZipSource& source, const ZipEntry& entry, const std::string& name);

// All members in central-directory order. Throws th::Error naming `name`, the member and the
// byte offset for anything malformed, encrypted, or compressed other than stored/deflate.
std::vector<ZipMember> read_zip(std::string_view archive, const std::string& name);

// A zip of stored (uncompressed) members, dated 1980-01-01 so that the bytes are reproducible.
std::string write_zip(const std::vector<std::pair<std::string, std::string>>& members);

}  // namespace th::io
