#pragma once
// METHOD 4 progressive rendering (inference; the paper's appendix): samples farther than the
// culling distance from every body vertex are skipped (raw = 0), rays without any kept sample
// output 0, and the colour branch runs only where sigma_raw > 0. The image equals full
// rendering of the same field wherever the field's density is not positive beyond the
// culling distance. Rays are processed in batches and the field in chunks of
// config.chunk_points points, so memory stays bounded for any image size.
//
// Early ray termination (render.termination_transmittance = tau > 0): each ray's kept samples
// are evaluated front to back, a few per ray per round, and a ray stops once the transmittance
// in front of its next sample is below tau. Its skipped samples keep raw = 0. Compositing is
// unchanged, so the weights of the evaluated samples are exactly those of the exact render,
// and the skipped samples' weights sum to at most T_stop < tau (times 1 + S e-10 for the
// 1e-10 term of the product): rgb (sigmoid <= 1 per channel) and acc move by less than tau,
// depth by less than tau * far. tau = 0 evaluates every kept sample (the exact render).

#include "render/body_distance.hpp"
#include "render/volume.hpp"

namespace th::render {

RenderResult render_progressive(RadianceField& field, const BodyDistance& body, const Rays& rays,
                                const RenderConfig& config, Profile* profile = nullptr);

}  // namespace th::render
