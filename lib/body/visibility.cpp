#include "body/visibility.hpp"

#include "core/error.hpp"
#include "geometry/camera.hpp"
#include "io/npy.hpp"
#include "render/raster.hpp"

namespace th::body {

torch::Tensor vertex_visibility(const torch::Tensor& vertices, const torch::Tensor& faces,
                                const torch::Tensor& K, const torch::Tensor& R,
                                const torch::Tensor& T, int width, int height,
                                const VisibilityOptions& options) {
  TORCH_CHECK(vertices.dim() == 2 && vertices.size(1) == 3, "vertices must be (Nv, 3)");
  const auto cam = geometry::world_to_camera(vertices, R, T);
  const auto raster = render::rasterize(cam, faces, K, width, height);
  const auto uv = geometry::project(cam, K);
  // The pixel whose centre is nearest to the vertex's projection.
  const auto px = torch::round(uv).to(torch::kInt64);
  const auto x = px.select(1, 0), y = px.select(1, 1);
  const auto inside = (x >= 0) & (x < width) & (y >= 0) & (y < height) & (cam.select(1, 2) > 0);
  const auto xi = x.clamp(0, width - 1), yi = y.clamp(0, height - 1);
  const auto zbuf = raster.depth.to(torch::kFloat64).index({yi, xi});
  // An empty pixel (projection just off the silhouette by rounding) occludes nothing.
  return inside & (cam.select(1, 2) <= zbuf + options.depth_tolerance);
}

torch::Tensor load_visibility_file(const std::filesystem::path& file, int64_t num_vertices) {
  const auto v = io::read_npy(file);
  if (v.numel() != num_vertices)
    fail("visibility file '", file.string(), "' has ", v.numel(), " entries, the body has ",
         num_vertices, " vertices");
  return v.reshape({-1}).to(torch::kBool);
}

}  // namespace th::body
