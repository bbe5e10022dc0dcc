#pragma once
// What the per-point stages read of the pixel feature p_v (METHOD 3.1, 3.4): FDI's appearance
// feature alpha_res_0(p_v) and the colour head's readout [view_fc_c . rgb_res_0 ; rgb_res_1](p_v)
// at the points' projections. p_v is never formed (METHOD 9): a linear layer that reads p_v
// commutes with bilinear upsampling and with sampling, so each layer is applied to every ResNet
// level (and, composed with the raw-RGB convolution, to the image) once per frame, and points
// sample those readouts (PixelReadouts).
//
// Readout windows (inference on CPU): progressive rendering evaluates only points within the
// culling distance of a body vertex, and those project into a rectangle of each view: the
// projection of the vertices' cubes of half-side `distance` (they contain the balls), plus a
// pixel. There the readouts are stored at full resolution (each window pixel read from the level
// table, which is then dropped), so a point reads 4 texels instead of 9 per level and 4 of the
// image: the same bilinear function, float rounding aside. Points elsewhere (full rendering, mesh
// grids) read p_v from the levels and apply the layer. A view whose cubes reach behind the camera
// gets the whole image.

#include <torch/torch.h>

#include "model/frame_cache.hpp"

namespace th::model {

class EncoderImpl;
class FDIImpl;

// The pixel stage of a frame, in the form that suits where and how it runs: none without the
// appearance branch ("w/o a"); readout windows where autograd does not record, the CPU kernels
// run (model/kernels/forms.hpp) and points are bounded to the body (`cull_distance` > 0); the
// level readouts otherwise. The window tables are stored in `window_type` (the readouts' own
// type, or bf16 from fp32 ones: Products::between); their gathers sum in fp32.
PixelStage prepare_pixels(const EncoderImpl& encoder, const EncodedViews& enc, const FDIImpl& fdi,
                          const HeadsFolded& heads, const FrameGeometry& geometry,
                          const torch::Tensor& vertices, double cull_distance,
                          c10::ScalarType window_type);

enum class PixelLayer { appearance, colour };
// The layer's readout at the projections uv (N, V, 2) -> (N, V, Cout), clamped at zero with
// `relu` and written in `dtype` (fp32 when unset); undefined w/o appearance.
torch::Tensor sample_pixels(const PixelStage& stage, const EncoderImpl& encoder,
                            const torch::Tensor& uv, PixelLayer layer, bool relu = false,
                            c10::optional<c10::ScalarType> dtype = c10::nullopt);

// The windows of a frame: per view, the rectangle that the points within `distance` of a vertex
// project into.
PixelWindows body_windows(const FrameGeometry& geometry, const torch::Tensor& vertices,
                          double distance, const PixelGeometry& pixels);

}  // namespace th::model
