#include "render/raster.hpp"

#include <torch/torch.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <vector>

namespace th::render {

Raster rasterize(const torch::Tensor& verts_cam, const torch::Tensor& faces, const torch::Tensor& K,
                 int width, int height, const RasterOptions& options) {
  TORCH_CHECK(verts_cam.dim() == 2 && verts_cam.size(1) == 3,
              "rasterize: verts_cam must be (N, 3), got ", verts_cam.sizes());
  TORCH_CHECK(faces.dim() == 2 && faces.size(1) == 3, "rasterize: faces must be (F, 3), got ",
              faces.sizes());
  TORCH_CHECK(K.dim() == 2 && K.size(0) == 3 && K.size(1) == 3, "rasterize: K must be (3, 3), got ",
              K.sizes());
  TORCH_CHECK(width > 0 && height > 0, "rasterize: empty image ", width, "x", height);

  auto v = verts_cam.to(torch::kFloat64).cpu().contiguous();
  auto f = faces.to(torch::kInt64).cpu().contiguous();
  auto k = K.to(torch::kFloat64).cpu().contiguous();
  const int64_t n = v.size(0), nf = f.size(0);
  const double* vp = v.data_ptr<double>();
  const int64_t* fp = f.data_ptr<int64_t>();
  const double* kp = k.data_ptr<double>();
  TORCH_CHECK(nf == 0 || (f.min().item<int64_t>() >= 0 && f.max().item<int64_t>() < n),
              "rasterize: face index out of range for ", n, " vertices");

  torch::Tensor cull;
  const bool* cp = nullptr;
  if (options.cull.defined()) {
    TORCH_CHECK(options.cull.dim() == 1 && options.cull.size(0) == nf,
                "rasterize: cull must be (F) = (", nf, "), got ", options.cull.sizes());
    cull = options.cull.to(torch::kBool).cpu().contiguous();
    cp = cull.data_ptr<bool>();
  }

  // The z-test runs on inverse depth (larger is nearer; 0 is empty) and the barycentrics are
  // kept unnormalised until the end, so that only the final pass divides.
  Raster out;
  out.depth = torch::zeros({height, width}, torch::kFloat32);
  out.face_id = torch::full({height, width}, -1, torch::kInt32);
  out.bary = torch::zeros({height, width, 3}, torch::kFloat32);
  float* depth = out.depth.data_ptr<float>();
  int32_t* ids = out.face_id.data_ptr<int32_t>();
  float* bary = out.bary.data_ptr<float>();

  // Screen position and inverse depth of every vertex, once (faces share vertices).
  std::vector<double> screen(3 * n);
  std::vector<uint8_t> in_front(n);
  for (int64_t i = 0; i < n; ++i) {
    const double* p = vp + 3 * i;
    in_front[i] = p[2] > options.near;
    const double iz = 1.0 / p[2];
    screen[3 * i] = (kp[0] * p[0] + kp[1] * p[1]) * iz + kp[2];
    screen[3 * i + 1] = kp[4] * p[1] * iz + kp[5];
    screen[3 * i + 2] = iz;
  }

  for (int64_t t = 0; t < nf; ++t) {
    double su[3], sv[3], iz[3];
    const int64_t* tri = fp + 3 * t;
    if (!in_front[tri[0]] || !in_front[tri[1]] || !in_front[tri[2]]) continue;
    for (int c = 0; c < 3; ++c) {
      const double* q = screen.data() + 3 * tri[c];
      su[c] = q[0], sv[c] = q[1], iz[c] = q[2];
    }
    const double area = (su[1] - su[0]) * (sv[2] - sv[0]) - (sv[1] - sv[0]) * (su[2] - su[0]);
    if (!(std::abs(area) > 1e-12)) continue;  // degenerate or NaN
    // With y pointing down in the image, a face whose outward side looks at the camera winds
    // clockwise on screen (negative area).
    if (cp && cp[t] && area > 0) continue;
    // Pixel box of the triangle, clamped in floating point (vertices near the camera plane
    // project far outside any int range).
    const double bx0 = std::max(0.0, std::ceil(std::min({su[0], su[1], su[2]})));
    const double bx1 = std::min(width - 1.0, std::floor(std::max({su[0], su[1], su[2]})));
    const double by0 = std::max(0.0, std::ceil(std::min({sv[0], sv[1], sv[2]})));
    const double by1 = std::min(height - 1.0, std::floor(std::max({sv[0], sv[1], sv[2]})));
    if (!(bx0 <= bx1 && by0 <= by1)) continue;
    const int x0 = int(bx0), x1 = int(bx1), y0 = int(by0), y1 = int(by1);
    const double inv_area = 1.0 / area;
    // Edge functions are affine in (x, y): l_c(x, y) = a_c x + b_c y + c_c, normalised by the
    // area so that l_0 + l_1 + l_2 = 1 (screen-space barycentrics).
    double ea[3], eb[3], ec[3], inv_ea[3];
    for (int c = 0; c < 3; ++c) {
      const int i = (c + 1) % 3, j = (c + 2) % 3;
      ea[c] = (sv[i] - sv[j]) * inv_area;
      eb[c] = (su[j] - su[i]) * inv_area;
      ec[c] = (su[i] * sv[j] - su[j] * sv[i]) * inv_area;
      inv_ea[c] = ea[c] != 0 ? 1.0 / ea[c] : 0.0;
    }
    for (int y = y0; y <= y1; ++y) {
      // The span of this row where all three edge functions are >= 0 (one pixel of slack on
      // each side; the exact test below decides).
      double lo = x0, hi = x1;
      bool empty = false;
      double row[3];
      for (int c = 0; c < 3; ++c) {
        row[c] = eb[c] * y + ec[c];
        if (ea[c] > 0) {
          lo = std::max(lo, std::floor(-row[c] * inv_ea[c]) - 1);
        } else if (ea[c] < 0) {
          hi = std::min(hi, std::ceil(-row[c] * inv_ea[c]) + 1);
        } else if (row[c] < 0) {
          empty = true;
        }
      }
      if (empty || lo > hi) continue;
      float* drow = depth + static_cast<int64_t>(y) * width;
      for (int x = int(lo); x <= int(hi); ++x) {
        const double l0 = ea[0] * x + row[0];
        const double l1 = ea[1] * x + row[1];
        const double l2 = ea[2] * x + row[2];
        if (l0 < 0 || l1 < 0 || l2 < 0) continue;
        // Perspective-correct interpolation: 1/z is affine in screen space.
        const double w0 = l0 * iz[0], w1 = l1 * iz[1], w2 = l2 * iz[2];
        const float inv_depth = static_cast<float>(w0 + w1 + w2);
        if (!(inv_depth > drow[x])) continue;
        drow[x] = inv_depth;
        const int64_t pix = static_cast<int64_t>(y) * width + x;
        ids[pix] = static_cast<int32_t>(t);
        bary[3 * pix + 0] = static_cast<float>(w0);
        bary[3 * pix + 1] = static_cast<float>(w1);
        bary[3 * pix + 2] = static_cast<float>(w2);
      }
    }
  }

  // Inverse depth -> depth, unnormalised -> normalised barycentrics.
  const int64_t pixels = int64_t(width) * height;
  for (int64_t pix = 0; pix < pixels; ++pix) {
    if (ids[pix] < 0) {
      depth[pix] = std::numeric_limits<float>::infinity();
      continue;
    }
    float* b = bary + 3 * pix;
    const float sum = b[0] + b[1] + b[2];
    depth[pix] = 1.0f / sum;
    b[0] /= sum, b[1] /= sum, b[2] /= sum;
  }
  return out;
}

torch::Tensor interpolate(const Raster& raster, const torch::Tensor& faces,
                          const torch::Tensor& attrs) {
  TORCH_CHECK(attrs.dim() == 2, "interpolate: attrs must be (N, C), got ", attrs.sizes());
  const int64_t h = raster.face_id.size(0), w = raster.face_id.size(1);
  auto ids = raster.face_id.reshape({-1}).to(torch::kInt64);
  auto covered = ids >= 0;
  auto safe = ids.clamp_min(0);
  auto tri = faces.to(torch::kInt64).index_select(0, safe);  // (HW, 3)
  auto a = attrs.to(torch::kFloat32);
  auto values = a.index_select(0, tri.reshape({-1})).reshape({h * w, 3, a.size(1)});
  auto b = raster.bary.reshape({h * w, 3, 1});
  auto out = (values * b).sum(1) * covered.unsqueeze(1).to(torch::kFloat32);
  return out.reshape({h, w, a.size(1)});
}

}  // namespace th::render
