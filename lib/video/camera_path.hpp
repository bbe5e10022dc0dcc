#pragma once
// Camera paths for free-viewpoint video (METHOD 7): the orbit around the person, a path file
// the user writes, or one dataset camera.
//
// Axis conventions. Cameras are OpenCV's (METHOD 2.2): x_cam = R x_world + T, x right, y down,
// z forward, so the rows of R are the camera's x, y and z axes in world coordinates and the
// centre is -R^T T. The reference implementation inverts [R|T] to camera-to-world and reorders
// its columns to LLFF's [down, right, backwards] = [y, x, -z] before building the orbit. So
// "the sum of the cameras' x axes in the reference code's axis order" (METHOD 7) is the sum of
// row 1 of each R: the OpenCV y axes, which point DOWN in the images. The orbit cameras it
// produces have the same rows as look_at(eye, target, -up) gives here (derivation in
// camera_path.cpp), so the person stands upright in the video.

#include <torch/types.h>

#include <filesystem>
#include <string>
#include <vector>

namespace th::video {

// One camera of a path, float64: K (3, 3) for the output image, R (3, 3) world -> camera,
// T (3, 1) metres. No lens distortion (the rendered image is a pinhole image).
struct PathCamera {
  torch::Tensor K;
  torch::Tensor R;
  torch::Tensor T;
};

// The ellipse the orbit camera moves on, derived from the dataset cameras (METHOD 7).
struct Orbit {
  torch::Tensor center;  // (3) mean of the camera centres
  torch::Tensor up;      // (3) unit, normalised sum of the cameras' y axes (points image-down)
  torch::Tensor axes;    // (3, 3) rows: up, a1 = unit(z0 x up), a2 = up x a1, with
                         // z0 = -(camera 0's z axis), the reference's c2w basis
  torch::Tensor radii;   // (3) 1.3 x 80th percentile (numpy's linear interpolation) of
                         // |axes (c_i - center)| over the cameras; radii[0] is unused
};

// R: (C, 3, 3) world -> camera rotations; T: (C, 3, 1) or (C, 3) translations in metres
// (C >= 1). Throws th::Error if the cameras' y axes cancel out (no up direction).
Orbit make_orbit(const torch::Tensor& R, const torch::Tensor& T);

// The camera at angle theta: eye = center + radii[1] sin(theta) a1 + radii[2] cos(theta) a2
// (the reference's [0, sin, cos] * rads), looking at `target` (3) world (the person: body
// centre) with -up pointing up in the image. K: (3, 3) intrinsics of the output image (METHOD 7:
// those of target view 3, scaled like the rendered images).
PathCamera orbit_camera(const Orbit& orbit, const torch::Tensor& K, const torch::Tensor& target,
                        double theta);

// n cameras at theta_k = 2 pi k / n, k = 0..n-1 (numpy's linspace(0, 2 pi, n + 1)[:-1]).
std::vector<PathCamera> orbit_path(const Orbit& orbit, const torch::Tensor& K,
                                   const torch::Tensor& target, int n);

// ---- path files ------------------------------------------------------------------------------
//
// A camera path file is YAML (JSON is valid YAML, so .json works too):
//
//   width: 512          # optional: output image size (0 or absent: the caller decides)
//   height: 512
//   cameras:            # one entry per video frame, in order
//     - K: [[fx, 0, cx], [0, fy, cy], [0, 0, 1]]   # or 9 numbers, row-major
//       R: [[...], [...], [...]]                   # world -> camera, or 9 numbers
//       T: [tx, ty, tz]                            # metres (x_cam = R x_world + T)
//
// R must be a rotation (orthonormal, det +1, within 1e-4).

struct CameraPath {
  std::vector<PathCamera> cameras;
  int width = 0;  // 0: not given
  int height = 0;
};

// Throws th::Error naming the file, the camera index and the key for anything malformed.
CameraPath read_camera_path(const std::filesystem::path& path);
// Writes the format above (so an orbit can be saved, edited and rendered again).
void write_camera_path(const std::filesystem::path& path, const CameraPath& cameras);

// A one-camera path from a list of (dataset) cameras by index. Throws th::Error naming the index
// and the valid range (`what` names the list in the message, e.g. "CoreView_387 cameras").
CameraPath single_camera(const std::vector<PathCamera>& cameras, int index,
                         const std::string& what = "cameras");

}  // namespace th::video
