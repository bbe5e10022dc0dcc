#include "data/h36m.hpp"

namespace th::data {

std::filesystem::path human_folder(const std::filesystem::path& root, const std::string& name) {
  const std::filesystem::path posing = root / name / "Posing";
  if (std::filesystem::is_regular_file(posing / "annots.npy")) return posing;
  return root / name;
}

}  // namespace th::data
