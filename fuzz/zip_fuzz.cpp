// libFuzzer entry for zip archives (METHOD 1.4, METHOD 8): arbitrary bytes go to the project's zip
// reader (io/zip.hpp, used by .npz) and, written to a file, to the reader of the reference
// implementation's .pth checkpoints (LibTorch's PyTorchStreamReader + the project's unpickler).
// LibTorch checks each record's CRC, so a mutated archive rarely gets as far as the unpickler:
// an input that does not start with "PK" is therefore taken as a checkpoint's records instead,
// data.pkl then the storages data/0, data/1, ... separated by "@@@@", and zipped here with
// valid CRCs (fuzz/make_seeds.py writes seeds of both kinds). th::Error is the expected answer
// to bad input; a crash, a sanitizer report, a leak or any other exception (c10::Error
// included) is a bug.
#include <cstddef>
#include <cstdint>
#include <fstream>
#include <string>
#include <string_view>
#include <utility>
#include <vector>

#include "core/error.hpp"
#include "io/zip.hpp"
#include "pipeline/reference_import.hpp"
#include "scratch.hpp"

namespace {

// "data.pkl@@@@storage 0@@@@storage 1..." -> the zip torch.save writes (records under archive/).
std::string checkpoint_from_records(std::string_view bytes) {
  std::vector<std::pair<std::string, std::string>> members = {{"archive/version", "3\n"}};
  constexpr std::string_view kSeparator = "@@@@";
  for (int index = -1;; ++index) {
    const size_t end = bytes.find(kSeparator);
    const std::string name = index < 0 ? "archive/data.pkl" : "archive/data/" + std::to_string(index);
    members.emplace_back(name, std::string(bytes.substr(0, end)));
    if (end == std::string_view::npos) break;
    bytes.remove_prefix(end + kSeparator.size());
  }
  return th::io::write_zip(members);
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  const std::string bytes(reinterpret_cast<const char*>(data), size);
  const bool is_zip = bytes.rfind("PK", 0) == 0;
  try {
    th::io::read_zip(bytes, "fuzz.zip");
  } catch (const th::Error&) {
  }
  const std::string file = is_zip ? bytes : checkpoint_from_records(bytes);
  try {
    th::pipeline::read_torch_state_dict(
        th::fuzz::write_input(reinterpret_cast<const uint8_t*>(file.data()), file.size(), "in.pth"),
        "net");
  } catch (const th::Error&) {
  }
  return 0;
}
