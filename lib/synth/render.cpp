#include "synth/render.hpp"

#include <torch/torch.h>

#include <cmath>
#include <limits>
#include <opencv2/imgproc.hpp>

#include "geometry/camera.hpp"
#include "render/raster.hpp"

namespace th::synth {
namespace {

constexpr double kPi = 3.14159265358979323846;
constexpr double kWallRadius = 6.0;  // the studio is a cylinder of this radius (metres)

struct Light {
  double dir[3];  // towards the light, unit
  double power;
};
const Light kLights[2] = {{{0.3455, -0.4442, 0.8265}, 0.72}, {{-0.7276, 0.6063, 0.3203}, 0.25}};
constexpr double kAmbient = 0.3;

Rgb studio_colour(const double* c, const double* d, float* floor_xy) {
  floor_xy[0] = floor_xy[1] = std::numeric_limits<float>::quiet_NaN();
  // Floor (z = 0) if the ray goes down and meets it inside the walls.
  if (d[2] < -1e-9) {
    const double t = -c[2] / d[2];
    const double x = c[0] + t * d[0], y = c[1] + t * d[1];
    if (std::hypot(x, y) < kWallRadius) {
      floor_xy[0] = float(x), floor_xy[1] = float(y);
      // A plain floor with a painted circle: texture here would cost JPEG bytes in every
      // image and teach the networks nothing about people.
      float g = 0.43f;
      if (std::abs(std::hypot(x, y) - 1.6) < 0.025) g = 0.75f;
      return {g * 0.98f, g, g * 1.03f};
    }
  }
  // Wall: first hit of the cylinder x^2 + y^2 = R^2 from inside.
  const double a = d[0] * d[0] + d[1] * d[1], b = 2 * (c[0] * d[0] + c[1] * d[1]),
               cc = c[0] * c[0] + c[1] * c[1] - kWallRadius * kWallRadius;
  const double t = (-b + std::sqrt(std::max(0.0, b * b - 4 * a * cc))) / (2 * std::max(a, 1e-12));
  const double x = c[0] + t * d[0], y = c[1] + t * d[1], z = c[2] + t * d[2];
  if (z > 4.0) return {0.16f, 0.16f, 0.18f};  // ceiling
  // Flat panels: gradients and fine texture would cost JPEG bytes in every image.
  const double az = std::atan2(y, x);
  const double seam = std::abs(std::remainder(az, kPi / 4.0)) * kWallRadius;  // 8 panels
  Rgb col{0.3f, 0.315f, 0.35f};
  if (seam < 0.03) col = {0.22f, 0.22f, 0.25f};
  if (z > 0.95 && z < 1.05) col = {0.5f, 0.48f, 0.42f};  // a rail around the room
  if (z < 0.12) col = {0.2f, 0.2f, 0.22f};               // skirting board
  return col;
}

// Rounds to nearest (v is clamped to [0, 1] first, so adding 0.5 and truncating is exact).
uint8_t to_byte(float v) { return uint8_t(std::clamp(v, 0.0f, 1.0f) * 255.0f + 0.5f); }

}  // namespace

StudioView make_studio_view(const CameraCalib& cam, const std::pair<cv::Mat, cv::Mat>& maps,
                            int width, int height) {
  StudioView view;
  view.cam = cam;
  view.maps = maps;
  view.background.create(height, width, CV_8UC3);
  view.floor_xy.create(height, width, CV_32FC2);
  auto centre = geometry::camera_center(cam.R, cam.T).contiguous();
  // Ray direction through pinhole pixel (x, y): R^T K^-1 (x, y, 1) (METHOD 2.2).
  auto M = torch::matmul(cam.R.transpose(0, 1), torch::inverse(cam.K)).contiguous();
  const double* m = M.data_ptr<double>();
  const double* c = centre.data_ptr<double>();
  for (int v = 0; v < height; ++v)
    for (int u = 0; u < width; ++u) {
      const double x = view.maps.first.at<float>(v, u), y = view.maps.second.at<float>(v, u);
      const double d[3] = {m[0] * x + m[1] * y + m[2], m[3] * x + m[4] * y + m[5],
                           m[6] * x + m[7] * y + m[8]};
      float* fxy = view.floor_xy.ptr<float>(v) + 2 * u;
      const Rgb col = studio_colour(c, d, fxy);
      uint8_t* bg = view.background.ptr<uint8_t>(v) + 3 * u;
      for (int k = 0; k < 3; ++k) bg[2 - k] = to_byte(col[k]);
    }
  // The studio is out of focus (the camera focuses on the person): a slight blur, which also
  // keeps the JPEG files small.
  cv::GaussianBlur(view.background, view.background, cv::Size(0, 0), 1.5);
  return view;
}

RenderedView render_view(const PosedMesh& posed, const StudioView& view, int width, int height,
                         int supersample, double ground_x, double ground_y) {
  const int s = supersample;
  const RenderMesh& mesh = *posed.mesh;
  const auto& materials = *posed.materials;
  RenderedView r;
  r.bgr = view.background.clone();
  r.alpha = cv::Mat::zeros(height, width, CV_32F);
  r.labels = cv::Mat::zeros(height, width, CV_8U);

  // Contact shadow on the floor within 0.8 m of the person's ground point: only the image box
  // of that disc (its outline projected and distorted) is visited.
  cv::Rect shadow_box(0, 0, width, height);
  {
    std::vector<double> rim;
    for (int i = 0; i < 16; ++i) {
      const double a = 2 * kPi * i / 16;
      rim.insert(rim.end(), {ground_x + 0.8 * std::cos(a), ground_y + 0.8 * std::sin(a), 0.0});
    }
    auto cam = geometry::world_to_camera(torch::tensor(rim, torch::kFloat64).reshape({16, 3}),
                                         view.cam.R, view.cam.T);
    if (cam.select(1, 2).min().item<double>() > 0.1) {
      auto px =
          geometry::distort_pixels(geometry::project(cam, view.cam.K), view.cam.K, view.cam.D);
      const int bx0 = std::max(0, int(std::floor(px.select(1, 0).min().item<double>())));
      const int by0 = std::max(0, int(std::floor(px.select(1, 1).min().item<double>())));
      const int bx1 = std::min(width, int(std::ceil(px.select(1, 0).max().item<double>())) + 1);
      const int by1 = std::min(height, int(std::ceil(px.select(1, 1).max().item<double>())) + 1);
      shadow_box = bx0 < bx1 && by0 < by1 ? cv::Rect(bx0, by0, bx1 - bx0, by1 - by0) : cv::Rect();
    }
  }
  for (int y = shadow_box.y; y < shadow_box.y + shadow_box.height; ++y) {
    const float* fxy = view.floor_xy.ptr<float>(y);
    uint8_t* out = r.bgr.ptr<uint8_t>(y);
    for (int x = shadow_box.x; x < shadow_box.x + shadow_box.width; ++x) {
      if (std::isnan(fxy[2 * x])) continue;
      const double dx = fxy[2 * x] - ground_x, dy = fxy[2 * x + 1] - ground_y;
      const double d2 = dx * dx + dy * dy;
      if (d2 > 0.64) continue;
      const float shade = float(1.0 - 0.5 * std::exp(-d2 / (2 * 0.2 * 0.2)));
      for (int c = 0; c < 3; ++c) out[3 * x + c] = uint8_t(out[3 * x + c] * shade + 0.5f);
    }
  }

  // Only the pinhole box around the person is rasterised (1 px margin).
  auto verts_cam = geometry::world_to_camera(posed.verts, view.cam.R, view.cam.T);
  auto uv = geometry::project(verts_cam, view.cam.K);
  const int x0 = std::max(0, int(std::floor(uv.select(1, 0).min().item<double>())) - 1);
  const int y0 = std::max(0, int(std::floor(uv.select(1, 1).min().item<double>())) - 1);
  const int x1 = std::min(width - 1, int(std::ceil(uv.select(1, 0).max().item<double>())) + 1);
  const int y1 = std::min(height - 1, int(std::ceil(uv.select(1, 1).max().item<double>())) + 1);
  if (x0 > x1 || y0 > y1) return r;
  const int cw = x1 - x0 + 1, ch = y1 - y0 + 1;

  // Subpixel i of pixel u sits at u + (i + 0.5) / s - 0.5: scale K, shift to the crop.
  auto K = view.cam.K.clone();
  K.slice(0, 0, 2).mul_(s);
  K[0][2] += (s - 1) / 2.0 - s * x0;
  K[1][2] += (s - 1) / 2.0 - s * y0;
  render::RasterOptions options;
  options.cull = mesh.cull;
  const render::Raster raster =
      render::rasterize(verts_cam, mesh.faces, K, cw * s, ch * s, options);

  auto verts = posed.verts.to(torch::kFloat32).contiguous();
  auto normals = posed.normals.to(torch::kFloat32).contiguous();
  auto tex = mesh.tex.contiguous();
  auto faces = mesh.faces.contiguous();
  auto centre = geometry::camera_center(view.cam.R, view.cam.T).to(torch::kFloat32).contiguous();
  const float* vp = verts.data_ptr<float>();
  const float* np = normals.data_ptr<float>();
  const float* tp = tex.data_ptr<float>();
  const int64_t* fp = faces.data_ptr<int64_t>();
  const float* cp = centre.data_ptr<float>();
  const int32_t* ids = raster.face_id.data_ptr<int32_t>();
  const float* bary = raster.bary.data_ptr<float>();
  const float inv = 1.0f / float(s * s);

  // Shade and box-filter into premultiplied colour + coverage. As in multisample
  // anti-aliasing, the samples of one pixel that see the same surface (same material, depths
  // within 2 cm) are shaded once, at the mean of their surface attributes; the samples only
  // decide coverage. Silhouettes and garment borders stay anti-aliased at a fraction of the cost.
  cv::Mat fg(ch, cw, CV_32FC4, cv::Scalar::all(0));
  cv::Mat labels(ch, cw, CV_8U, cv::Scalar::all(0));
  const float* depth = raster.depth.data_ptr<float>();
  const int W = cw * s;
  struct Group {
    int material, count;
    uint8_t label;
    float depth;
    float t[3], n[3], p[3];
  };
  std::vector<Group> groups;
  for (int py = 0; py < ch; ++py)
    for (int px = 0; px < cw; ++px) {
      groups.clear();
      for (int sy = 0; sy < s; ++sy)
        for (int sx = 0; sx < s; ++sx) {
          const int64_t pix = int64_t(py * s + sy) * W + (px * s + sx);
          const int32_t f = ids[pix];
          if (f < 0) continue;
          const int material = mesh.face_material[f];
          Group* g = nullptr;
          for (auto& cand : groups)
            if (cand.material == material && std::abs(cand.depth - depth[pix]) < 0.02f) g = &cand;
          if (!g) {
            groups.push_back(Group{
                material, 0, mesh.face_label[f], depth[pix], {0, 0, 0}, {0, 0, 0}, {0, 0, 0}});
            g = &groups.back();
          }
          const float* b = bary + 3 * pix;
          const int64_t* tri = fp + 3 * int64_t(f);
          for (int k = 0; k < 3; ++k)
            for (int c = 0; c < 3; ++c) {
              g->t[c] += b[k] * tp[3 * tri[k] + c];
              g->n[c] += b[k] * np[3 * tri[k] + c];
              g->p[c] += b[k] * vp[3 * tri[k] + c];
            }
          ++g->count;
        }
      if (groups.empty()) continue;
      float* out = fg.ptr<float>(py) + 4 * px;
      int best = 0;
      for (size_t gi = 0; gi < groups.size(); ++gi) {
        Group& g = groups[gi];
        if (g.count > groups[best].count) best = int(gi);
        for (int c = 0; c < 3; ++c) g.t[c] /= float(g.count), g.p[c] /= float(g.count);
        const float len = std::sqrt(g.n[0] * g.n[0] + g.n[1] * g.n[1] + g.n[2] * g.n[2]) + 1e-12f;
        float facing = 0.0f;
        for (int c = 0; c < 3; ++c) {
          g.n[c] /= len;
          facing += g.n[c] * (cp[c] - g.p[c]);
        }
        // Two-sided: the inside of a sleeve or skirt is seen from behind its normal, and is
        // darker (it gets little light).
        float inside = 1.0f;
        if (facing < 0) {
          for (float& v : g.n) v = -v;
          inside = 0.55f;
        }
        double light = kAmbient;
        for (const Light& l : kLights)
          light +=
              l.power * std::max(0.0, g.n[0] * l.dir[0] + g.n[1] * l.dir[1] + g.n[2] * l.dir[2]);
        const Rgb a = albedo(materials[g.material], g.t);
        const float k = float(light) * inside * float(g.count) * inv;
        out[0] += a[0] * k, out[1] += a[1] * k, out[2] += a[2] * k;
        out[3] += float(g.count) * inv;
      }
      labels.at<uint8_t>(py, px) = groups[best].label;
    }

  // The distorted pixels that can see the box: distort its outline (2 px margin).
  std::vector<double> outline;
  for (int i = 0; i <= 16; ++i) {
    const double fx = x0 - 2 + (cw + 3) * i / 16.0, fy = y0 - 2 + (ch + 3) * i / 16.0;
    for (double v :
         {fx, double(y0 - 2), fx, double(y1 + 2), double(x0 - 2), fy, double(x1 + 2), fy})
      outline.push_back(v);
  }
  auto d = geometry::distort_pixels(torch::tensor(outline, torch::kFloat64).reshape({-1, 2}),
                                    view.cam.K, view.cam.D);
  const int dx0 = std::max(0, int(std::floor(d.select(1, 0).min().item<double>())) - 1);
  const int dy0 = std::max(0, int(std::floor(d.select(1, 1).min().item<double>())) - 1);
  const int dx1 = std::min(width - 1, int(std::ceil(d.select(1, 0).max().item<double>())) + 1);
  const int dy1 = std::min(height - 1, int(std::ceil(d.select(1, 1).max().item<double>())) + 1);
  if (dx0 > dx1 || dy0 > dy1) return r;
  const cv::Rect roi(dx0, dy0, dx1 - dx0 + 1, dy1 - dy0 + 1);
  std::pair<cv::Mat, cv::Mat> maps{view.maps.first(roi) - float(x0),
                                   view.maps.second(roi) - float(y0)};
  const cv::Mat fg_d = geometry::distort_image(fg, maps, cv::INTER_LINEAR);
  geometry::distort_image(labels, maps, cv::INTER_NEAREST).copyTo(r.labels(roi));

  for (int y = 0; y < roi.height; ++y) {
    const float* f = fg_d.ptr<float>(y);
    float* alpha = r.alpha.ptr<float>(y + roi.y) + roi.x;
    uint8_t* out = r.bgr.ptr<uint8_t>(y + roi.y) + 3 * roi.x;
    for (int x = 0; x < roi.width; ++x) {
      const float a = std::clamp(f[4 * x + 3], 0.0f, 1.0f);
      if (a <= 0.0f) continue;
      alpha[x] = a;
      for (int c = 0; c < 3; ++c) {
        const float bg = out[3 * x + 2 - c] * (1.0f / 255.0f);
        out[3 * x + 2 - c] = to_byte(f[4 * x + c] + (1.0f - a) * bg);
      }
    }
  }
  return r;
}

}  // namespace th::synth
