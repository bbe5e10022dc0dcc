#include "mesh/preview.hpp"

#include <torch/torch.h>

#include <cmath>

#include "geometry/camera.hpp"
#include "geometry/mesh.hpp"
#include "render/raster.hpp"

namespace th::mesh {

PreviewCamera frame_mesh(const TriMesh& mesh, const torch::Tensor& view_dir,
                         const torch::Tensor& up, int width, int height) {
  check_mesh(mesh, "frame_mesh");
  TORCH_CHECK(mesh.num_verts() > 0, "frame_mesh: empty mesh");
  TORCH_CHECK(width > 0 && height > 0, "frame_mesh: empty image ", width, "x", height);
  auto v = mesh.verts.to(torch::kFloat64);
  auto center = 0.5 * (std::get<0>(v.min(0)) + std::get<0>(v.max(0)));
  const double radius = std::max((v - center).norm(2, 1).max().item<double>(), 1e-9);
  // Half the field of view across the smaller image side: 20 degrees; the bounding sphere then
  // spans 90% of it.
  const double half_fov = 20.0 * M_PI / 180.0;
  const double focal = 0.5 * std::min(width, height) / std::tan(half_fov);
  const double distance = radius / std::sin(0.9 * half_fov);
  auto dir = view_dir.to(torch::kFloat64).reshape({3});
  dir = dir / dir.norm();
  auto [R, T] = geometry::look_at(center - distance * dir, center, up);
  PreviewCamera camera;
  camera.K = torch::tensor(
      {{focal, 0.0, 0.5 * (width - 1)}, {0.0, focal, 0.5 * (height - 1)}, {0.0, 0.0, 1.0}},
      torch::kFloat64);
  camera.R = R;
  camera.T = T;
  camera.width = width;
  camera.height = height;
  return camera;
}

cv::Mat render_preview(const TriMesh& mesh, const PreviewCamera& camera,
                       const PreviewOptions& options) {
  check_mesh(mesh, "render_preview");
  const int w = camera.width, h = camera.height;
  auto rgb = torch::tensor({options.background[0], options.background[1], options.background[2]})
                 .expand({h, w, 3})
                 .clone();
  if (mesh.num_faces() > 0) {
    auto R = camera.R.to(torch::kFloat64);
    auto verts_cam = geometry::world_to_camera(mesh.verts, R, camera.T);
    auto raster = render::rasterize(verts_cam, mesh.faces, camera.K, w, h);
    auto covered = raster.face_id >= 0;  // (H, W)

    // Normals in camera coordinates, interpolated and renormalised per pixel.
    auto normals = geometry::vertex_normals(mesh.verts.to(torch::kFloat64), mesh.faces);
    auto n = render::interpolate(raster, mesh.faces, torch::matmul(normals, R.t()));
    n = n / n.norm(2, 2, true).clamp_min(1e-12);
    // Unit viewing ray per pixel, K^-1 [x, y, 1] (METHOD 2.2's ray direction, camera frame).
    auto ys = torch::arange(h, torch::kFloat64), xs = torch::arange(w, torch::kFloat64);
    auto grid = torch::meshgrid({ys, xs}, "ij");
    auto pix = torch::stack({grid[1], grid[0], torch::ones_like(grid[0])}, 2);  // (H, W, 3)
    auto d = torch::matmul(pix, torch::inverse(camera.K.to(torch::kFloat64)).t());
    d = (d / d.norm(2, 2, true)).to(torch::kFloat32);
    // Headlight (towards the camera) and a key light from the upper left, front.
    auto key = torch::tensor({-0.4f, -0.6f, -1.0f});
    key = key / key.norm();
    auto head_term = (-(n * d).sum(2)).clamp_min(0);
    auto key_term = (n * key).sum(2).clamp_min(0);
    auto shade = options.ambient + (1.f - options.ambient) * (0.6f * head_term + 0.4f * key_term);

    torch::Tensor albedo;
    if (mesh.colors.defined()) {
      albedo = render::interpolate(raster, mesh.faces, mesh.colors.to(torch::kFloat32) / 255.f);
    } else {
      albedo =
          torch::tensor({options.color[0], options.color[1], options.color[2]}).expand({h, w, 3});
    }
    rgb = torch::where(covered.unsqueeze(2), albedo * shade.clamp(0, 1).unsqueeze(2), rgb);
  }
  auto bgr = (rgb.flip({2}) * 255.f).round().clamp(0, 255).to(torch::kUInt8).contiguous();
  return cv::Mat(h, w, CV_8UC3, bgr.data_ptr<uint8_t>()).clone();
}

}  // namespace th::mesh
