#pragma once
// The viewer's requests and answers: errors as HTTP statuses, parameters read and checked (a bad
// one is a 400 naming it), the camera a view asks for, and images and JSON as answer bodies.
// Private to lib/viewer (it needs <httplib.h>).

#include <httplib.h>
#include <torch/types.h>

#include <nlohmann/json.hpp>
#include <string>

#include "video/camera_path.hpp"

namespace th::viewer {

// A request answered with an error: its status, a message naming the cause, and Retry-After
// seconds when trying again later may succeed.
struct HttpError {
  int status = 500;
  std::string message;
  int retry_after_s = 0;
};

// A request parameter that is not what it must be: answered with 400 and this message.
struct BadRequest : HttpError {
  explicit BadRequest(std::string text) : HttpError{400, std::move(text)} {}
};

// Parameter `name` as given; BadRequest when it is missing.
std::string param(const httplib::Request& req, const std::string& name);
// Parameter `name` as an integer in [lo, hi].
int int_param(const httplib::Request& req, const std::string& name, int lo, int hi);
// `text` (parameter `name`) as a finite number.
double number(const std::string& name, const std::string& text);
// Parameter `name` as x,y,z, each at most `max_abs` from 0: (3,) float64.
torch::Tensor vec3(const httplib::Request& req, const std::string& name, double max_abs);

// The pinhole camera at `eye` looking along `forward` with `up` roughly up, vertical field of
// view `fovy` degrees, for a width x height image: OpenCV axes (x right, y down, z forward).
video::PathCamera look_camera(const torch::Tensor& eye, const torch::Tensor& forward,
                              const torch::Tensor& up, double fovy, int width, int height);

using Json = nlohmann::ordered_json;

// An answer's body: bytes of a name that are not UTF-8 become U+FFFD, and a NaN or infinite
// score is written as null (JSON has neither).
std::string body(const Json& answer);
// A 3-vector: [x, y, z].
Json vec3_json(const torch::Tensor& v);

// (H, W, 3) float RGB in [0, 1], or (H, W) values in [0, 1] shown as grey, as PNG bytes (or
// JPEG at quality 90 with `jpeg`: a few times faster to make, for views shown while moving).
// Each value becomes the nearest of 256 levels as transhuman-render's images do (x 255, rounded
// half to even, clamped; NaN black).
std::string png(const torch::Tensor& image, bool jpeg = false);

// What a view shows: its colours rgb (H, W, 3), or depth (H, W) (near light, far dark, black
// where nothing is) or accumulated opacity acc (H, W) as grey; mode rgb | depth | acc.
torch::Tensor display(const torch::Tensor& rgb, const torch::Tensor& depth,
                      const torch::Tensor& acc, const std::string& mode);

}  // namespace th::viewer
