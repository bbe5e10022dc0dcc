#pragma once
// SPEC 4 progressive rendering (inference; the paper's appendix): samples farther than the
// culling distance from every body vertex are skipped (raw = 0), rays without any kept sample
// output 0, and the colour branch runs only where sigma_raw > 0. The image equals full
// rendering of the same field wherever the field's density is not positive beyond the
// culling distance. Rays are processed in batches and the field in chunks of
// config.chunk_points points, so memory stays bounded for any image size.

#include "render/body_distance.hpp"
#include "render/volume.hpp"

namespace th::render {

RenderResult render_progressive(RadianceField& field, const BodyDistance& body, const Rays& rays,
                                const RenderConfig& config, Profile* profile = nullptr);

}  // namespace th::render
