#include "synth/split.hpp"

#include <algorithm>
#include <sstream>

#include "synth/layout.hpp"
#include "synth/rig.hpp"

namespace th::synth {
namespace {

struct Range {
  int begin, ni, interval;
};

std::string view_list(const std::vector<int>& views) {
  std::string s = "[";
  for (size_t i = 0; i < views.size(); ++i) s += (i ? ", " : "") + std::to_string(views[i]);
  return s + "]";
}

}  // namespace

std::string split_yaml(const SynthConfig& c) {
  // Views that every human has (the 21-camera people lack two of the ring).
  int cameras = c.cameras.count;
  for (const auto& h : c.people.train)
    if (FolderLayout::style_for(h) == FolderStyle::Original21)
      cameras = std::min<int>(cameras, int(cameras_21(c.cameras.count).size()));
  auto available = [&](std::vector<int> v) {
    v.erase(std::remove_if(v.begin(), v.end(), [&](int i) { return i >= cameras; }), v.end());
    return v;
  };
  const std::vector<int> refs = available({0, 7, 15}), targets = available({3, 5, 10, 12, 18, 20});
  const int train = std::min(c.split.train_frames, c.frames);

  std::ostringstream o;
  o << "# Splits of the synthetic dataset: the protocols of METHOD 1.2 over the people and frames\n"
       "# that transhuman-synth generates. Written by it: this copy is the split of\n"
       "# configs/synth/default.yaml; every generated dataset also holds its own split.yaml.\n"
       "#\n"
       "# Schema (shared by every file in data_splits/, see zju_mocap.yaml):\n"
       "#   settings:\n"
       "#     <name>:                      training | pose | identity | one_shot | fitting\n"
       "#       reference_views: [i, ...]  fixed calibration indices, or `random`\n"
       "#       num_reference_views: N     with `random`: N cameras drawn per sample (may include\n"
       "#                                  the target)\n"
       "#       target_views: [i, ...]     or `all`: every camera of every frame is a sample\n"
       "#       humans:                    frames of a human are ims[begin : "
       "begin+ni][::interval]\n"
       "#         - {name: <folder>, begin: B, ni: N, interval: I}\n"
       "# Training people: frames [0, "
    << train
    << ") for training, the rest for pose\n"
       "# generalisation; the unseen people for identity generalisation and one-shot.\n"
       "settings:\n";
  auto setting = [&](const char* name, const std::vector<std::string>& humans, Range r,
                     const std::vector<int>& ref, const std::vector<int>& tgt) {
    o << "  " << name << ":\n";
    if (ref.empty())
      o << "    reference_views: random\n    num_reference_views: 3\n";
    else
      o << "    reference_views: " << view_list(ref) << "\n";
    o << "    target_views: " << (tgt.empty() ? std::string("all") : view_list(tgt)) << "\n";
    o << "    humans:\n";
    for (const auto& h : humans)
      o << "      - {name: " << h << ", begin: " << r.begin << ", ni: " << r.ni
        << ", interval: " << r.interval << "}\n";
  };
  setting("training", c.people.train, {0, train, 1}, {}, {});
  setting("pose", c.people.train, {train, c.frames - train, c.split.pose_interval}, refs, targets);
  setting("identity", c.people.unseen, {0, c.frames, c.split.test_interval}, refs, targets);
  setting("one_shot", c.people.unseen, {0, c.frames, c.split.test_interval}, {0}, targets);
  setting("fitting", c.people.train, {0, train, c.split.fitting_interval}, refs, targets);
  return o.str();
}

}  // namespace th::synth
