#include "data/h36m.hpp"

#include "core/error.hpp"

namespace th::data {

namespace fs = std::filesystem;

fs::path human_folder(const fs::path& root, const std::string& name, DatasetKind dataset) {
  const fs::path posing = root / name / "Posing";
  if (dataset == DatasetKind::h36m) {
    if (!fs::is_regular_file(posing / "annots.npy") &&
        fs::is_regular_file(root / name / "annots.npy"))
      fail("'", (posing / "annots.npy").string(),
           "' is missing: data.dataset is h36m (Animatable NeRF's ", "<S>/Posing layout) but '",
           (root / name).string(), "' has the ZJU-MoCap layout; set data.dataset: zju_mocap");
    return posing;
  }
  if (!fs::is_regular_file(root / name / "annots.npy") &&
      fs::is_regular_file(posing / "annots.npy"))
    fail("'", (root / name / "annots.npy").string(), "' is missing: data.dataset is ",
         config::name_of(dataset), " but '", posing.string(),
         "' holds an H36M subject; set data.dataset: h36m");
  return root / name;
}

}  // namespace th::data
