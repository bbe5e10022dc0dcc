#pragma once
// What makes two runs' outputs interchangeable, for the commands that continue in a folder of
// their own outputs (transhuman-render's frames, transhuman-eval's rows): a request.yaml names
// the checkpoint, what was asked, and every setting that changes a pixel; a folder is continued
// only under the same request, and another one is refused naming the keys that differ.

#include <torch/types.h>
#include <yaml-cpp/yaml.h>

#include <string>

#include "core/config.hpp"

namespace th::inference {

// Writes, as one YAML map value, the settings that change a rendered pixel: the precision the
// products resolve to on `device`, eval.setting (its reference views), and every data.*,
// model.* and render.* key but those that cannot (training only, caches, checks, the loader's
// threads), paths absolute.
void emit_pixel_settings(YAML::Emitter& y, const Config& config, const torch::Device& device);

// The keys whose values differ between the request that made a folder's outputs (`before`, the
// text of its request.yaml) and this one (`now`), as "key (<outputs>: A, now: B)", a change of
// renderer first, at most four then a count; empty when `before` cannot be read.
std::string request_differences(const std::string& before, const std::string& now,
                                const std::string& outputs);

}  // namespace th::inference
