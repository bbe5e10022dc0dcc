#include "synth/motion.hpp"

#include <torch/torch.h>

#include <cmath>
#include <functional>

#include "geometry/camera.hpp"

namespace th::synth {
namespace {

constexpr double kPi = 3.14159265358979323846;
using Pose = std::array<double, 72>;
using Vec3 = std::array<double, 3>;

// SMPL joint indices.
enum Joint {
  kLHip = 1,
  kRHip = 2,
  kSpine1 = 3,
  kLKnee = 4,
  kRKnee = 5,
  kSpine2 = 6,
  kLAnkle = 7,
  kRAnkle = 8,
  kSpine3 = 9,
  kNeck = 12,
  kLCollar = 13,
  kRCollar = 14,
  kHead = 15,
  kLShoulder = 16,
  kRShoulder = 17,
  kLElbow = 18,
  kRElbow = 19,
  kLWrist = 20,
  kRWrist = 21
};

void set(Pose& p, int joint, const Vec3& r) {
  for (int c = 0; c < 3; ++c) p[3 * joint + c] = r[c];
}
void add(Pose& p, int joint, const Vec3& r) {
  for (int c = 0; c < 3; ++c) p[3 * joint + c] += r[c];
}

// Axis-angle of R_b * R_a (first a, then b), through the project's geometry helpers.
Vec3 compose(const Vec3& a, const Vec3& b) {
  auto ra = geometry::rodrigues(torch::tensor({a[0], a[1], a[2]}, torch::kFloat64));
  auto rb = geometry::rodrigues(torch::tensor({b[0], b[1], b[2]}, torch::kFloat64));
  auto r = geometry::axis_angle(torch::matmul(rb, ra));
  return {r[0].item<double>(), r[1].item<double>(), r[2].item<double>()};
}

// SMPL rest frame: x to the body's left, y up, z forward. Arms: `down` lowers the arm from
// the T-pose towards the body (about z), then `flex` swings it about x (negative: forward).
Vec3 arm(bool left, double down, double flex) {
  return compose({0, 0, left ? -down : down}, {flex, 0, 0});
}
// Elbow bend bringing the forearm forward (about the rest y axis; sign per side).
Vec3 elbow(bool left, double bend) { return {0, left ? -bend : bend, 0}; }

double smooth01(double x) {
  x = std::clamp(x, 0.0, 1.0);
  return x * x * (3.0 - 2.0 * x);
}
double bump(double u) { return std::pow(std::sin(kPi * std::clamp(u, 0.0, 1.0)), 2.0); }

// Per-person manner of moving.
struct Style {
  double arm_down, elbow_bend, stride, period, speed, turn, sway_phase;
};

enum class Activity { Walk, Raise, Squat, Twirl, Wave, Kick, Idle, Stretch };
const char* activity_name(Activity a) {
  static const char* names[] = {"walk", "raise", "squat", "twirl",
                                "wave", "kick",  "idle",  "stretch"};
  return names[int(a)];
}

struct Segment {
  Activity activity;
  int start = 0, end = 0;
  int variant = 0;         // side, raise direction, ...
  double amount = 1.0;     // depth / amplitude
  double direction = 1.0;  // twirl / turn direction
};

// Relaxed standing pose of the person.
Pose rest_pose(const Style& s, double t) {
  Pose p{};
  const double sway = 0.03 * std::sin(2 * kPi * t / 40.0 + s.sway_phase);
  set(p, kLShoulder, arm(true, s.arm_down, 0.05));
  set(p, kRShoulder, arm(false, s.arm_down, 0.05));
  set(p, kLElbow, elbow(true, s.elbow_bend));
  set(p, kRElbow, elbow(false, s.elbow_bend));
  set(p, kSpine1, {0.02, sway, 0});
  set(p, kHead, {0.05, -sway, 0});
  return p;
}

// Pose, heading rate (rad/frame) and forward speed (m/frame) of a segment at frame t.
struct Sample {
  Pose pose;
  double turn = 0.0, speed = 0.0;
};

Sample sample(const Segment& g, const Style& s, int t) {
  const double tau = t - g.start, len = std::max(1, g.end - g.start);
  const double u = tau / len;
  Sample out{rest_pose(s, t)};
  Pose& p = out.pose;
  const bool left = g.variant % 2 == 0;
  switch (g.activity) {
    case Activity::Walk: {
      const double ph = 2 * kPi * tau / s.period + g.variant;
      const double a = s.stride * g.amount, sn = std::sin(ph);
      set(p, kLHip, {-a * sn, 0, 0});
      set(p, kRHip, {a * sn, 0, 0});
      set(p, kLKnee, {0.1 + 1.1 * a * std::pow(std::max(0.0, std::cos(ph - 0.4)), 2.0), 0, 0});
      set(p, kRKnee, {0.1 + 1.1 * a * std::pow(std::max(0.0, -std::cos(ph - 0.4)), 2.0), 0, 0});
      set(p, kLAnkle, {0.15 * sn, 0, 0});
      set(p, kRAnkle, {-0.15 * sn, 0, 0});
      set(p, kLShoulder, arm(true, s.arm_down, 0.8 * a * sn));
      set(p, kRShoulder, arm(false, s.arm_down, -0.8 * a * sn));
      set(p, kLElbow, elbow(true, s.elbow_bend + 0.25 * a * (1 - sn)));
      set(p, kRElbow, elbow(false, s.elbow_bend + 0.25 * a * (1 + sn)));
      set(p, kSpine2, {0.04, -0.12 * a * sn, 0});
      out.turn = s.turn * g.direction;
      out.speed = s.speed * g.amount;
      break;
    }
    case Activity::Raise: {
      const double e = bump(u) * g.amount;
      if (g.variant % 3 == 0) {  // both arms sideways up
        set(p, kLShoulder, arm(true, s.arm_down - 2.5 * e, 0));
        set(p, kRShoulder, arm(false, s.arm_down - 2.5 * e, 0));
      } else if (g.variant % 3 == 1) {  // both arms forward up
        set(p, kLShoulder, arm(true, s.arm_down, -2.6 * e));
        set(p, kRShoulder, arm(false, s.arm_down, -2.6 * e));
      } else {  // one arm sideways, the other forward
        set(p, kLShoulder, arm(true, s.arm_down - 2.3 * e, 0));
        set(p, kRShoulder, arm(false, s.arm_down, -1.6 * e));
      }
      set(p, kLElbow, elbow(true, s.elbow_bend * (1 - e)));
      set(p, kRElbow, elbow(false, s.elbow_bend * (1 - e)));
      set(p, kSpine2, {-0.1 * e, 0, 0});
      set(p, kHead, {-0.25 * e, 0, 0});
      break;
    }
    case Activity::Squat: {
      const double e = bump(u) * g.amount;
      set(p, kLHip, {-1.55 * e, 0, -0.12 * e});
      set(p, kRHip, {-1.55 * e, 0, 0.12 * e});
      set(p, kLKnee, {2.0 * e, 0, 0});
      set(p, kRKnee, {2.0 * e, 0, 0});
      set(p, kLAnkle, {-0.45 * e, 0, 0});
      set(p, kRAnkle, {-0.45 * e, 0, 0});
      set(p, kSpine1, {0.35 * e, 0, 0});
      set(p, kLShoulder, arm(true, s.arm_down, -1.4 * e));
      set(p, kRShoulder, arm(false, s.arm_down, -1.4 * e));
      set(p, kHead, {-0.3 * e, 0, 0});
      break;
    }
    case Activity::Twirl: {
      const double e =
          bump(std::min(1.0, 2.5 * u)) * (u > 0.6 ? bump(1.0 - (u - 0.6) * 1.25) : 1.0);
      const double arms = std::max(e, smooth01(u * 4.0) * smooth01((1.0 - u) * 4.0));
      set(p, kLShoulder, arm(true, s.arm_down - 1.2 * arms, 0));
      set(p, kRShoulder, arm(false, s.arm_down - 1.2 * arms, 0));
      const double step = 0.25 * std::sin(2 * kPi * tau / 8.0);
      set(p, kLHip, {-step, 0, 0.1});
      set(p, kRHip, {step, 0, -0.1});
      set(p, kLKnee, {0.2 + std::max(0.0, step), 0, 0});
      set(p, kRKnee, {0.2 + std::max(0.0, -step), 0, 0});
      set(p, kHead, {0.0, -0.3 * g.direction, 0});
      out.turn = g.direction * 2 * kPi * 6.0 * u * (1.0 - u) / len;
      break;
    }
    case Activity::Wave: {
      const double e = smooth01(u * 4.0) * smooth01((1.0 - u) * 4.0);
      const double wave = 0.5 * std::sin(2 * kPi * tau / 6.0);
      set(p, left ? kLShoulder : kRShoulder, arm(left, s.arm_down - 2.0 * e, -0.3 * e));
      set(p, left ? kLElbow : kRElbow, {0, 0, (left ? 1 : -1) * e * (1.2 + wave)});
      set(p, kHead, {0.0, (left ? 0.3 : -0.3) * e, 0.0});
      break;
    }
    case Activity::Kick: {
      const double e = bump(u) * g.amount;
      set(p, left ? kLHip : kRHip, {-1.3 * e, 0, 0});
      set(p, left ? kLKnee : kRKnee, {0.5 * e * (1 - e), 0, 0});
      set(p, left ? kRKnee : kLKnee, {0.15 * e, 0, 0});
      set(p, kLShoulder, arm(true, s.arm_down - 1.0 * e, 0.3 * e));
      set(p, kRShoulder, arm(false, s.arm_down - 1.0 * e, 0.3 * e));
      set(p, kSpine1, {-0.15 * e, 0, 0});
      break;
    }
    case Activity::Stretch: {
      const double e = bump(u) * g.amount;
      const double side = left ? 1.0 : -1.0;
      set(p, kSpine1, {0, 0, -0.2 * side * e});
      set(p, kSpine2, {0, 0, -0.25 * side * e});
      set(p, left ? kLShoulder : kRShoulder, arm(left, s.arm_down - 2.8 * e, 0));
      set(p, left ? kLElbow : kRElbow, elbow(left, 0.4 * e));
      set(p, kHead, {0, 0, -0.2 * side * e});
      break;
    }
    case Activity::Idle: {
      const double look = 0.5 * std::sin(2 * kPi * tau / 24.0);
      set(p, kHead, {0.05, look, 0});
      set(p, kNeck, {0, 0.3 * look, 0});
      set(p, left ? kLKnee : kRKnee, {0.25, 0, 0});
      set(p, left ? kLHip : kRHip, {-0.1, 0, 0.05});
      set(p, kSpine1, {0, 0, left ? 0.05 : -0.05});
      add(p, kLWrist, {0, 0.2 * look, 0});
      break;
    }
  }
  return out;
}

}  // namespace

Motion make_motion(int frames, Rng& rng) {
  Style s;
  s.arm_down = rng.uniform(1.1, 1.35);
  s.elbow_bend = rng.uniform(0.1, 0.45);
  s.stride = rng.uniform(0.3, 0.5);
  s.period = rng.uniform(14.0, 22.0);
  s.speed = rng.uniform(0.025, 0.045);
  s.turn = rng.uniform(0.04, 0.09);
  s.sway_phase = rng.uniform(0.0, 2 * kPi);

  // The script: activities of 10-18 frames, overlapping by `fade` frames for cross-fades.
  const int fade = 5;
  const std::vector<Activity> kinds = {Activity::Walk,  Activity::Raise,  Activity::Squat,
                                       Activity::Twirl, Activity::Wave,   Activity::Kick,
                                       Activity::Idle,  Activity::Stretch};
  std::vector<Segment> script;
  int t = 0;
  Activity last = Activity::Idle;
  bool first = true;
  while (t < frames) {
    Activity a;
    do a = rng.pick(kinds);
    while (!first && a == last);
    first = false;
    last = a;
    Segment g;
    g.activity = a;
    g.start = script.empty() ? 0 : t - fade;
    g.end = g.start + int(rng.uniform(10.0, 19.0));
    if (a == Activity::Walk) g.end += 6;
    g.variant = int(rng.below(6));
    g.amount = rng.uniform(0.7, 1.0);
    g.direction = rng.chance(0.5) ? 1.0 : -1.0;
    script.push_back(g);
    t = g.end;
  }

  Motion m;
  for (const auto& g : script)
    m.script += (m.script.empty() ? "" : ", ") + std::string(activity_name(g.activity)) + " " +
                std::to_string(g.end - g.start);

  double heading = rng.uniform(0.0, 2 * kPi);
  double x = 0.0, y = 0.0;
  std::vector<std::array<double, 3>> path;
  for (int f = 0; f < frames; ++f) {
    Pose pose{};
    double turn = 0.0, speed = 0.0, total = 0.0;
    for (size_t k = 0; k < script.size(); ++k) {
      const Segment& g = script[k];
      if (f < g.start || f >= g.end) continue;
      double w = 1.0;
      if (k > 0) w *= smooth01((f - g.start + 0.5) / fade);
      if (k + 1 < script.size()) w *= smooth01((g.end - f - 0.5) / fade);
      const Sample smp = sample(g, s, f);
      for (int i = 0; i < 72; ++i) pose[i] += w * smp.pose[i];
      turn += w * smp.turn;
      speed += w * smp.speed;
      total += w;
    }
    for (double& v : pose) v /= total;
    turn /= total, speed /= total;

    FrameParams fp;
    fp.poses = pose;
    fp.poses[0] = fp.poses[1] = fp.poses[2] = 0.0;
    // Rh: the SMPL frame (y up, facing +z) stood up in the z-up world, then the heading.
    const Vec3 rh = compose({kPi / 2, 0, 0}, {0, 0, heading});
    fp.Rh = rh;
    path.push_back({x, y, heading});
    m.frames.push_back(fp);
    // Forward in the world for heading h: R_z(h) R_x(90 deg) (0, 0, 1) = (sin h, -cos h, 0).
    x += speed * std::sin(heading);
    y -= speed * std::cos(heading);
    heading += turn;
  }
  // Keep the person near the centre of the ring: centre the path, shrink it to 0.4 m.
  double mx = 0, my = 0, rmax = 0;
  for (const auto& p : path) mx += p[0] / frames, my += p[1] / frames;
  for (const auto& p : path) rmax = std::max(rmax, std::hypot(p[0] - mx, p[1] - my));
  const double shrink = rmax > 0.4 ? 0.4 / rmax : 1.0;
  const double ox = rng.uniform(-0.1, 0.1), oy = rng.uniform(-0.1, 0.1);
  for (int f = 0; f < frames; ++f) {
    m.frames[f].Th = {ox + (path[f][0] - mx) * shrink, oy + (path[f][1] - my) * shrink, 0.0};
  }
  return m;
}

}  // namespace th::synth
