#pragma once
// METHOD 9: the exact shortcuts, in one place. Each is a transformation of one stage of the
// per-frame state (model/frame_cache.hpp), made once per frame, that leaves the rendered
// function unchanged up to float rounding; the plain pass of the paper's formulas
// (model/network.hpp) is what tests/model/test_network.cpp compares them with.
// With each transformation, the per-point code that reads the transformed stage.
//
// Not a stage transformation, but exact as well and also part of METHOD 9, in transhuman.cpp:
// during checkpointed training colour is evaluated only where sigma_raw > 0 (the compositing
// weight is 0 elsewhere, so neither the image nor a gradient changes).

#include <torch/torch.h>

#include "model/frame_cache.hpp"

namespace th::model {

class EncoderImpl;
class FDIImpl;
class HeadsImpl;

// 1. Human stage. fc_0 is linear and DPaRF's Nk weights sum to 1, so fc_0's token part is
// applied to the Nt tokens once per frame instead of to Nk tokens at every point:
// table (Nt, V * 256) = fc_0_tokens(T_v(c)) + bias, view-major within a row. Read per point by
// TokenFieldsImpl::forward (model/human.hpp: a weighted gather of the Nk rows, plus fc_0's
// coordinate part).
// tokens: (V, Nt, C).
torch::Tensor token_table(const torch::Tensor& tokens, const torch::nn::Linear& fc_0);

// 2. Folded weights. FDI: fc_1 is folded into both value projections and each key projection
// shares one product with its value projection (FDIImpl::fold, for each fusion; read by
// Plan::fuse). Colour head: view_fc's feature part is composed with feature_fc, and with
// rgb_res_0 into one 256-channel readout [view_fc_c . rgb_res_0 ; rgb_res_1] of p_v
// (HeadsImpl::fold; read by Plan::colour).
FoldedWeights fold_weights(const FDIImpl& fdi, const HeadsImpl& heads);

// 3. Pixel stage. A linear layer that reads p_v commutes with bilinear upsampling and with
// sampling, so FDI's alpha_res_0 and the colour head's folded readout are applied to each
// ResNet level (and the raw-RGB channels to the image) once per frame: PixelReadouts::alpha and
// ::color, read per point by PixelReadout::sample. p_v is never formed at full resolution.
PixelReadouts make_pixel_readouts(const EncoderImpl& encoder, const EncodedViews& enc,
                                  const FDIImpl& fdi, const HeadsFolded& heads);
// The same in window form (4. below): each readout at every pixel of `windows`.
WindowReadouts make_window_readouts(const EncoderImpl& encoder, const EncodedViews& enc,
                                    const FDIImpl& fdi, const HeadsFolded& heads,
                                    const PixelWindows& windows);

// 4. Readout windows (inference on CPU). Progressive rendering evaluates only points within the
// culling distance of a body vertex, and those project into a rectangle of each view: the
// projection of the vertices' cubes of half-side `distance` (they contain the balls), plus a
// pixel. There the readouts are stored at full resolution (each window pixel read from the
// level table, which is then dropped), so a point reads 4 texels instead of 9 per level and 4
// of the image: the same bilinear function, float rounding aside. Points elsewhere (full
// rendering, mesh grids) read p_v from the levels and apply the layer (WindowReadout::weight).
// A view whose cubes reach behind the camera gets the whole image.
PixelWindows body_windows(const FrameGeometry& geometry, const torch::Tensor& vertices,
                          double distance, const PixelGeometry& pixels);

}  // namespace th::model
