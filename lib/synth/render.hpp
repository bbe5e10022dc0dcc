#pragma once
// Images of the synthetic studio: the clothed, textured person rasterised (lib/render) with
// Lambertian shading under a fixed key light, a fill light and ambient light, anti-aliased with
// supersample^2 coverage samples per pixel (shaded once per visible surface per pixel, as in
// multisample anti-aliasing), composited over a studio background (floor, walls, a contact
// shadow) and passed through the camera's lens distortion, so that cv::undistort(img, K, D)
// gives back the pinhole image (METHOD 2.1). Masks come from the coverage.

#include <torch/types.h>

#include <opencv2/core.hpp>
#include <utility>
#include <vector>

#include "synth/person.hpp"
#include "synth/rig.hpp"

namespace th::synth {

// Everything about one camera that does not change from frame to frame.
struct StudioView {
  CameraCalib cam;
  std::pair<cv::Mat, cv::Mat> maps;  // distorted pixel -> pinhole pixel (geometry::distortion_maps)
  cv::Mat background;                // CV_8UC3 BGR photograph of the empty studio
  cv::Mat floor_xy;                  // CV_32FC2 floor point (world x, y) per pixel; NaN: no floor
};
// maps: geometry::distortion_maps(cam.K, cam.D, width, height), shared by every recording of
// the same ring camera (a recalibration moves a camera, it does not change its lens).
StudioView make_studio_view(const CameraCalib& cam, const std::pair<cv::Mat, cv::Mat>& maps,
                            int width, int height);

// A person posed for one frame.
struct PosedMesh {
  torch::Tensor verts;    // (P, 3) float64 world
  torch::Tensor normals;  // (P, 3) float64 world, unit
  const RenderMesh* mesh = nullptr;
  const std::vector<Material>* materials = nullptr;
};

struct RenderedView {
  cv::Mat bgr;     // CV_8UC3, the photograph
  cv::Mat alpha;   // CV_32F person coverage in [0, 1] (distorted like the photograph)
  cv::Mat labels;  // CV_8U CIHP label of the surface seen (0: background)
};

// Renders the person at width x height with supersample^2 samples per pixel; the contact
// shadow is centred at the world floor point (ground_x, ground_y).
RenderedView render_view(const PosedMesh& posed, const StudioView& view, int width, int height,
                         int supersample, double ground_x, double ground_y);

}  // namespace th::synth
