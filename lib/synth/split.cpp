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
  o << "# Human splits of the synthetic dataset: the protocols of SPEC 1.2 over the people and\n"
       "# frames that transhuman-synth generates (written by it; this copy is for\n"
       "# configs/synth/default.yaml, each generated dataset also holds its own split.yaml).\n"
       "#\n"
       "# Schema:\n"
       "#   dataset: synthetic\n"
       "#   settings:\n"
       "#     <setting>:                  training | pose | identity | one_shot | fitting\n"
       "#       humans:                   list of {human, begin, ni, interval}; the frames of a\n"
       "#                                 human are ims[begin : begin + ni][::interval]\n"
       "#       reference_views: [...]    calibration indices of the input views; [] = random\n"
       "#       num_reference_views: n    how many random reference views when the list is []\n"
       "#                                 (drawn from all cameras, may include the target)\n"
       "#       target_views: [...]       calibration indices of the views to render;\n"
       "#                                 [] = every camera (training: one random per sample)\n"
       "dataset: synthetic\n"
       "settings:\n";
  auto setting = [&](const char* name, const std::vector<std::string>& humans, Range r,
                     const std::vector<int>& ref, int num_ref, const std::vector<int>& tgt) {
    o << "  " << name << ":\n    humans:\n";
    for (const auto& h : humans)
      o << "      - {human: " << h << ", begin: " << r.begin << ", ni: " << r.ni
        << ", interval: " << r.interval << "}\n";
    o << "    reference_views: " << view_list(ref) << "\n"
      << "    num_reference_views: " << num_ref << "\n"
      << "    target_views: " << view_list(tgt) << "\n";
  };
  setting("training", c.people.train, {0, train, 1}, {}, 3, {});
  setting("pose", c.people.train, {train, c.frames - train, c.split.pose_interval}, refs,
          int(refs.size()), targets);
  setting("identity", c.people.unseen, {0, c.frames, c.split.test_interval}, refs,
          int(refs.size()), targets);
  setting("one_shot", c.people.unseen, {0, c.frames, c.split.test_interval}, {0}, 1, targets);
  setting("fitting", c.people.train, {0, train, c.split.fitting_interval}, refs,
          int(refs.size()), targets);
  return o.str();
}

}  // namespace th::synth
