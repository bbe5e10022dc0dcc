#pragma once
// The little of the zip format that .npz needs (internal to lib/io): reading stored and
// deflated members (with zip64 records, as np.savez writes them) and writing stored members.

#include <string>
#include <string_view>
#include <utility>
#include <vector>

namespace th::io::detail {

struct ZipMember {
  std::string name;
  std::string data;  // uncompressed, CRC-checked
};

// All members in central-directory order. Throws th::Error naming `name`, the member and the
// byte offset for anything malformed, encrypted, or compressed other than stored/deflate.
std::vector<ZipMember> read_zip(std::string_view archive, const std::string& name);

// A zip of stored (uncompressed) members, dated 1980-01-01 so that the bytes are reproducible.
std::string write_zip(const std::vector<std::pair<std::string, std::string>>& members);

}  // namespace th::io::detail
