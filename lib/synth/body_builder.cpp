#include "synth/body_builder.hpp"

#include <torch/torch.h>

#include <cmath>
#include <functional>

namespace th::synth {
namespace {

using Vec3 = std::array<double, 3>;
constexpr double kPi = 3.14159265358979323846;

// Body measurements of the template (metres, SMPL frame). Every vertex position is a linear
// function of these numbers, so a shape direction (a change of some of them) is exact.
struct Dims {
  // joints
  double hip_x = 0.088, hip_y = -0.075, knee_y = -0.49, ankle_y = -0.88, ankle_z = -0.005;
  double spine1_y = 0.11, spine2_y = 0.24, spine3_y = 0.30, neck_y = 0.50, head_y = 0.58;
  double collar_x = 0.075, shoulder_x = 0.175, elbow_x = 0.43, wrist_x = 0.68, hand_x = 0.765,
         tip_x = 0.875, arm_y = 0.445, arm_z = -0.015;
  // feet
  double sole_y = -0.975, heel_z = -0.075, foot_z = 0.10, toe_z = 0.18, foot_w = 0.046,
         foot_h = 0.05;
  // torso half widths (x) and half depths (z)
  double hip_w = 0.172, waist_w = 0.145, chest_w = 0.165, shoulder_w = 0.185;
  double hip_d = 0.108, waist_d = 0.092, chest_d = 0.108, belly = 0.0;
  // limb radii
  double thigh_r = 0.085, knee_r = 0.051, calf_r = 0.057, ankle_r = 0.034;
  double upper_arm_r = 0.05, elbow_r = 0.037, forearm_r = 0.041, wrist_r = 0.027;
  double neck_r = 0.052;
  // head ellipsoid
  double head_cy = 0.675, head_cz = 0.02, head_rx = 0.078, head_ry = 0.112, head_rz = 0.095;
};

// Shape directions 1..9 as changes of the measurements (direction 0, stature, is a uniform
// scale about the pelvis and handled separately).
void apply_direction(Dims& d, int k) {
  switch (k) {
    case 1:  // weight / girth
      d.hip_w += 0.018, d.waist_w += 0.025, d.chest_w += 0.015, d.shoulder_w += 0.008;
      d.hip_d += 0.015, d.waist_d += 0.02, d.chest_d += 0.012;
      d.thigh_r += 0.01, d.knee_r += 0.003, d.calf_r += 0.005, d.upper_arm_r += 0.007;
      d.forearm_r += 0.004, d.neck_r += 0.005;
      break;
    case 2:  // shoulder width
      d.shoulder_x += 0.02, d.collar_x += 0.012, d.elbow_x += 0.02, d.wrist_x += 0.02;
      d.hand_x += 0.02, d.tip_x += 0.02, d.shoulder_w += 0.02;
      break;
    case 3:  // hip width
      d.hip_x += 0.012, d.hip_w += 0.02, d.hip_d += 0.005;
      break;
    case 4:  // leg length
      d.knee_y -= 0.022, d.ankle_y -= 0.045, d.sole_y -= 0.045;
      break;
    case 5:  // arm length
      d.elbow_x += 0.018, d.wrist_x += 0.036, d.hand_x += 0.036, d.tip_x += 0.036;
      break;
    case 6:  // torso length
      d.spine1_y += 0.008, d.spine2_y += 0.016, d.spine3_y += 0.02, d.neck_y += 0.03;
      d.head_y += 0.03, d.arm_y += 0.027, d.head_cy += 0.03;
      break;
    case 7:  // chest and belly depth
      d.chest_d += 0.015, d.belly += 0.02;
      break;
    case 8:  // head size (chin kept in place)
      d.head_rx += 0.005, d.head_ry += 0.007, d.head_rz += 0.006, d.head_cy += 0.007;
      break;
    case 9:  // limb muscularity
      d.thigh_r += 0.008, d.knee_r += 0.003, d.calf_r += 0.007, d.upper_arm_r += 0.007;
      d.elbow_r += 0.002, d.forearm_r += 0.005;
      break;
    default:
      break;
  }
}
constexpr double kStatureScale = 0.035;  // direction 0: +3.5 % per unit

// One key cross-section of a sweep. Poles have ra = rb = 0. `joint` >= 0 marks the ring whose
// centre is that joint (left-side index for mirrored parts).
struct Station {
  Vec3 c;
  double ra, rb;
  int joint = -1;
};

// A swept closed tube along the axis d = e1 x e2 (e1, e2 span the cross-section): vertices at
// c + ra f(cos phi) e1 + rb f(sin phi) e2, with f a signed power giving a superellipse.
struct Sweep {
  Part part;
  Vec3 e1, e2;
  double exponent;
  int segments;
  std::vector<Station> keys;
};

Station st(double x, double y, double z, double ra, double rb, int joint = -1) {
  return Station{{x, y, z}, ra, rb, joint};
}

// The unmirrored parts (torso, left leg, left foot, left arm, neck, head) for some measurements.
std::vector<Sweep> sweeps(const Dims& d) {
  std::vector<Sweep> out;
  const Vec3 X{1, 0, 0}, Y{0, 1, 0}, Z{0, 0, 1};

  // Torso, bottom (crotch) to top (base of the neck); ra: half depth (z), rb: half width (x).
  {
    Sweep s{Part::Torso, Z, X, 2.4, 32, {}};
    const double hy = d.hip_y, ay = d.arm_y, ny = d.neck_y;
    const double wz = 0.5 * d.belly;  // the belly pushes the waist forward
    s.keys = std::vector<Station>{
        st(0, hy - 0.075, -0.005, 0, 0),
        st(0, hy - 0.07, -0.005, 0.4 * d.hip_d, 0.35 * d.hip_w),
        st(0, hy - 0.055, -0.008, 0.75 * d.hip_d, 0.68 * d.hip_w),
        st(0, hy - 0.03, -0.01, 0.93 * d.hip_d, 0.9 * d.hip_w),
        st(0, hy, -0.01, d.hip_d, d.hip_w),
        st(0, 0.0, 0.0, 0.97 * d.hip_d + 0.3 * d.belly, 0.97 * d.hip_w, 0),
        st(0, d.spine1_y, wz, d.waist_d + 0.5 * d.belly, d.waist_w, 3),
        st(0, 0.5 * (d.spine1_y + d.spine2_y), 0.5 * wz,
           0.5 * (d.waist_d + d.chest_d) + 0.3 * d.belly, 0.5 * (d.waist_w + d.chest_w)),
        st(0, d.spine2_y, 0.0, d.chest_d, 0.96 * d.chest_w, 6),
        st(0, d.spine3_y, 0.005, d.chest_d, d.chest_w, 9),
        st(0, 0.5 * (d.spine3_y + ay), 0.0, 0.96 * d.chest_d, 0.5 * (d.chest_w + d.shoulder_w)),
        st(0, ay - 0.03, -0.01, 0.88 * d.chest_d, d.shoulder_w),
        st(0, ay + 0.01, -0.012, 0.75 * d.chest_d, 0.97 * d.shoulder_w),
        st(0, ay + 0.03, -0.014, 0.62 * d.chest_d, 0.85 * d.shoulder_w),
        st(0, ny - 0.01, -0.015, 0.52 * d.chest_d, 0.45 * d.shoulder_w),
        st(0, ny + 0.005, -0.015, 0.42 * d.chest_d, 0.28 * d.shoulder_w),
        st(0, ny + 0.012, -0.015, 0, 0),
    };
    out.push_back(std::move(s));
  }
  // Left leg, top (inside the pelvis) to below the ankle; ra: x, rb: z.
  {
    Sweep s{Part::LegL, X, Z, 2.0, 16, {}};
    const double hx = d.hip_x, kx = d.hip_x - 0.006, ax = d.hip_x - 0.004;
    const double hy = d.hip_y, ky = d.knee_y, ay = d.ankle_y, t = d.thigh_r, k = d.knee_r,
                 c = d.calf_r, a = d.ankle_r;
    auto along = [&](double f, double y0, double y1) { return y0 + f * (y1 - y0); };
    s.keys = std::vector<Station>{
        st(hx, hy + 0.1, 0, 0, 0),
        st(hx, hy + 0.085, 0, 0.5 * t, 0.5 * t),
        st(hx, hy + 0.05, 0, 0.85 * t, 0.85 * t),
        st(hx, hy, 0, t, 1.03 * t, 1),
        st(0.7 * hx + 0.3 * kx, along(0.3, hy, ky), 0.003, 0.9 * t, 0.93 * t),
        st(0.3 * hx + 0.7 * kx, along(0.7, hy, ky), 0.005, 0.55 * t + 0.45 * k,
           0.58 * t + 0.45 * k),
        st(kx, ky, 0.0, k, 1.04 * k, 4),
        st(kx, along(0.2, ky, ay), -0.008, 0.5 * (k + c), 0.5 * (k + c) * 1.04),
        st(0.6 * kx + 0.4 * ax, along(0.35, ky, ay), -0.015, c, 1.08 * c),
        st(0.3 * kx + 0.7 * ax, along(0.65, ky, ay), -0.01, 0.6 * c + 0.4 * a, 0.62 * c + 0.4 * a),
        st(ax, ay, d.ankle_z, a, 1.05 * a, 7),
        st(ax, ay - 0.03, d.ankle_z, 0.85 * a, 0.9 * a),
        st(ax, ay - 0.05, d.ankle_z, 0, 0),
    };
    out.push_back(std::move(s));
  }
  // Left foot, heel to toe; ra: half width (x), rb: half height (y).
  {
    Sweep s{Part::FootL, X, Y, 3.0, 12, {}};
    const double fx = d.hip_x + 0.002, so = d.sole_y, w = d.foot_w, h = d.foot_h;
    s.keys = std::vector<Station>{
        st(fx, so + 0.035, d.heel_z, 0, 0),
        st(fx, so + 0.035, d.heel_z + 0.008, 0.45 * w, 0.5 * h),
        st(fx, so + 0.042, d.heel_z + 0.025, 0.8 * w, 0.85 * h),
        st(fx, so + 0.05, d.heel_z + 0.06, 0.9 * w, h),
        st(fx, so + 0.045, d.ankle_z + 0.04, 0.95 * w, 0.85 * h),
        st(fx + 0.004, so + 0.028, d.foot_z, w, 0.55 * h, 10),
        st(fx + 0.006, so + 0.022, d.foot_z + 0.04, 0.95 * w, 0.42 * h),
        st(fx + 0.006, so + 0.02, d.toe_z - 0.02, 0.75 * w, 0.35 * h),
        st(fx + 0.005, so + 0.018, d.toe_z - 0.005, 0.4 * w, 0.2 * h),
        st(fx + 0.005, so + 0.018, d.toe_z, 0, 0),
    };
    out.push_back(std::move(s));
  }
  // Left arm with the hand, from inside the chest to the finger tips; ra: y, rb: z. The palm
  // faces down, as in SMPL's T-pose.
  {
    Sweep s{Part::ArmL, Y, Z, 2.0, 16, {}};
    const double y = d.arm_y, z = d.arm_z, u = d.upper_arm_r, e = d.elbow_r, f = d.forearm_r,
                 w = d.wrist_r;
    const double cx = d.collar_x, sx = d.shoulder_x, ex = d.elbow_x, wx = d.wrist_x, hx = d.hand_x,
                 tx = d.tip_x;
    auto along = [](double f0, double a, double b) { return a + f0 * (b - a); };
    s.keys = std::vector<Station>{
        st(cx - 0.035, y - 0.005, z, 0, 0),
        st(cx - 0.02, y - 0.005, z, 0.6 * u, 0.6 * u),
        st(cx, y - 0.005, z, 0.85 * u, 0.85 * u, 13),
        st(0.5 * (cx + sx), y, z, u, u),
        st(sx, y, z, 1.04 * u, 1.06 * u, 16),
        st(along(0.35, sx, ex), y, z, 0.95 * u, 0.95 * u),
        st(along(0.75, sx, ex), y, z, 0.5 * (u + e), 0.5 * (u + e)),
        st(ex, y, z, e, 1.03 * e, 18),
        st(along(0.2, ex, wx), y, z, f, 1.03 * f),
        st(along(0.6, ex, wx), y, z, 0.5 * (f + w), 0.55 * (f + w)),
        st(wx, y, z, w, 1.25 * w, 20),
        st(along(0.3, wx, hx), y, z, 0.017, 0.04),
        st(hx, y, z, 0.015, 0.044, 22),
        st(along(0.4, hx, tx), y, z, 0.012, 0.04),
        st(along(0.8, hx, tx), y, z, 0.009, 0.03),
        st(tx, y, z, 0, 0),
    };
    out.push_back(std::move(s));
  }
  // Neck, from inside the chest to inside the head; ra: z, rb: x.
  {
    Sweep s{Part::Neck, Z, X, 2.0, 12, {}};
    const double ny = d.neck_y, hy = d.head_y, r = d.neck_r;
    s.keys = std::vector<Station>{
        st(0, ny - 0.11, -0.01, 0, 0),
        st(0, ny - 0.1, -0.01, 0.6 * r, 0.6 * r),
        st(0, ny - 0.07, -0.01, r, r),
        st(0, ny, -0.01, 0.98 * r, r, 12),
        st(0, 0.5 * (ny + hy), 0.0, 0.95 * r, 0.95 * r),
        st(0, hy, 0.005, 0.9 * r, 0.92 * r, 15),
        st(0, hy + 0.04, 0.005, 0.8 * r, 0.8 * r),
        st(0, hy + 0.07, 0.005, 0, 0),
    };
    out.push_back(std::move(s));
  }
  // Head: an ellipsoid, slightly narrower towards the chin.
  {
    Sweep s{Part::Head, Z, X, 2.0, 20, {}};
    const int n = 16;
    for (int i = 0; i <= n; ++i) {
      const double th = kPi * i / n, sn = std::sin(th);
      const double narrow = th < 0.5 * kPi ? 0.88 + 0.12 * sn : 1.0;
      const double chin = th < 0.5 * kPi ? 0.01 * (1.0 - sn) : 0.0;
      const bool pole = i == 0 || i == n;
      s.keys.push_back(st(0, d.head_cy - d.head_ry * std::cos(th), d.head_cz + chin,
                          pole ? 0 : d.head_rz * sn, pole ? 0 : d.head_rx * sn * narrow));
    }
    out.push_back(std::move(s));
  }
  return out;
}

// Rings per key interval, fixed from the base measurements so that every shape has the same
// topology: about one ring per 2.4 cm; intervals that end in a pole get none in between.
std::vector<std::vector<int>> subdivisions(const std::vector<Sweep>& base) {
  std::vector<std::vector<int>> out;
  for (const auto& s : base) {
    std::vector<int> n;
    for (size_t k = 0; k + 1 < s.keys.size(); ++k) {
      const auto& a = s.keys[k].c;
      const auto& b = s.keys[k + 1].c;
      const double len = std::sqrt((a[0] - b[0]) * (a[0] - b[0]) + (a[1] - b[1]) * (a[1] - b[1]) +
                                   (a[2] - b[2]) * (a[2] - b[2]));
      const bool pole = k == 0 || k + 2 == s.keys.size();
      n.push_back(pole || s.part == Part::Head ? 1 : std::max(1, int(std::lround(len / 0.024))));
    }
    out.push_back(n);
  }
  return out;
}

double signed_power(double v, double p) { return v < 0 ? -std::pow(-v, p) : std::pow(v, p); }

// Rings of a sweep after subdivision (poles excluded) and the ring index of each joint key.
struct Rings {
  std::vector<Station> rings;
  Vec3 pole0, pole1;
  std::vector<std::pair<int, int>> joint_ring;  // (joint, ring)
};
Rings expand(const Sweep& s, const std::vector<int>& n) {
  Rings r;
  r.pole0 = s.keys.front().c;
  r.pole1 = s.keys.back().c;
  for (size_t k = 1; k + 1 < s.keys.size(); ++k) {
    const Station& key = s.keys[k];
    if (key.joint >= 0) r.joint_ring.emplace_back(key.joint, int(r.rings.size()));
    r.rings.push_back(key);
    if (k + 2 == s.keys.size()) break;
    const Station& next = s.keys[k + 1];
    for (int i = 1; i < n[k]; ++i) {
      const double t = double(i) / n[k];
      Station m;
      for (int c = 0; c < 3; ++c) m.c[c] = key.c[c] + t * (next.c[c] - key.c[c]);
      m.ra = key.ra + t * (next.ra - key.ra);
      m.rb = key.rb + t * (next.rb - key.rb);
      r.rings.push_back(m);
    }
  }
  return r;
}

// Vertices of one sweep: pole 0, rings, pole 1 (x mirrored when `mirror`).
void emit_vertices(const Sweep& s, const Rings& r, bool mirror, std::vector<double>& out) {
  auto push = [&](const Vec3& p) {
    out.push_back(mirror ? -p[0] : p[0]);
    out.push_back(p[1]);
    out.push_back(p[2]);
  };
  push(r.pole0);
  const double p = 2.0 / s.exponent;
  for (const auto& ring : r.rings)
    for (int j = 0; j < s.segments; ++j) {
      const double phi = 2.0 * kPi * j / s.segments;
      const double a = ring.ra * signed_power(std::cos(phi), p);
      const double b = ring.rb * signed_power(std::sin(phi), p);
      Vec3 v;
      for (int c = 0; c < 3; ++c) v[c] = ring.c[c] + a * s.e1[c] + b * s.e2[c];
      push(v);
    }
  push(r.pole1);
}

// Faces of a part (outward for e1 x e2 = axis; reversed for mirrored parts).
void emit_faces(const PartLayout& l, bool mirror, std::vector<int64_t>& out) {
  auto tri = [&](int64_t a, int64_t b, int64_t c) {
    out.push_back(a);
    out.push_back(mirror ? c : b);
    out.push_back(mirror ? b : c);
  };
  const int S = l.segments;
  for (int j = 0; j < S; ++j) tri(l.pole0(), l.vertex(0, j + 1), l.vertex(0, j));
  for (int i = 0; i + 1 < l.rings; ++i)
    for (int j = 0; j < S; ++j) {
      const int64_t a = l.vertex(i, j), b = l.vertex(i, j + 1), c = l.vertex(i + 1, j + 1),
                    d = l.vertex(i + 1, j);
      tri(a, b, c);
      tri(a, c, d);
    }
  for (int j = 0; j < S; ++j)
    tri(l.pole1(), l.vertex(l.rings - 1, j), l.vertex(l.rings - 1, j + 1));
}

// The left joint's right-side counterpart (identity for joints on the midline).
int mirror_joint(int j) {
  switch (j) {
    case 1:
      return 2;
    case 4:
      return 5;
    case 7:
      return 8;
    case 10:
      return 11;
    case 13:
      return 14;
    case 16:
      return 17;
    case 18:
      return 19;
    case 20:
      return 21;
    case 22:
      return 23;
    default:
      return j;
  }
}

// Part order in the vertex array and whether it is a mirrored copy of a left part.
struct PartSource {
  Part part;
  int sweep;  // index into sweeps()
  bool mirror;
};
const std::array<PartSource, kNumParts> kPartSources = {{{Part::Torso, 0, false},
                                                         {Part::LegL, 1, false},
                                                         {Part::LegR, 1, true},
                                                         {Part::FootL, 2, false},
                                                         {Part::FootR, 2, true},
                                                         {Part::ArmL, 3, false},
                                                         {Part::ArmR, 3, true},
                                                         {Part::Neck, 4, false},
                                                         {Part::Head, 5, false}}};

std::vector<double> positions(const Dims& d, const std::vector<std::vector<int>>& subdiv) {
  const auto sw = sweeps(d);
  std::vector<double> out;
  for (const auto& src : kPartSources)
    emit_vertices(sw[src.sweep], expand(sw[src.sweep], subdiv[src.sweep]), src.mirror, out);
  return out;
}

double smooth01(double x) {
  x = std::clamp(x, 0.0, 1.0);
  return x * x * (3.0 - 2.0 * x);
}

// Weights along a chain of bones: bones[0] before the first transition, bones[k] after the
// k-th; transition k is centred at centres[k] with half width widths[k] (ascending, apart).
std::array<double, body::kNumJoints> chain(double s, const std::vector<int>& bones,
                                           const std::vector<double>& centres,
                                           const std::vector<double>& widths) {
  std::array<double, body::kNumJoints> w{};
  std::vector<double> past(bones.size(), 1.0);  // past[k]: fraction beyond transition k
  for (size_t k = 1; k < bones.size(); ++k)
    past[k] = smooth01((s - (centres[k - 1] - widths[k - 1])) / (2.0 * widths[k - 1]));
  for (size_t k = 0; k < bones.size(); ++k)
    w[bones[k]] += past[k] - (k + 1 < bones.size() ? past[k + 1] : 0.0);
  return w;
}

// Skinning weights of a template vertex at p (left-side coordinates for mirrored parts).
std::array<double, body::kNumJoints> vertex_weights(Part part, const Vec3& p, const Dims& d) {
  switch (part) {
    case Part::Torso: {
      auto w = chain(p[1], {0, 3, 6, 9, 12},
                     {d.spine1_y - 0.01, d.spine2_y - 0.015, d.spine3_y + 0.012, d.neck_y - 0.004},
                     {0.04, 0.04, 0.03, 0.012});
      // The shoulder corners follow the collar bones, the hip corners the thighs a little.
      const double ax = std::abs(p[0]);
      const double collar =
          0.7 * smooth01((ax - 0.09) / 0.07) * smooth01((p[1] - (d.arm_y - 0.09)) / 0.08);
      const double hip =
          0.5 * smooth01((ax - 0.05) / 0.07) * smooth01((d.hip_y + 0.01 - p[1]) / 0.06);
      for (double& v : w) v *= 1.0 - collar - hip;
      w[p[0] >= 0 ? 13 : 14] += collar;
      w[p[0] >= 0 ? 1 : 2] += hip;
      return w;
    }
    case Part::LegL:
      return chain(-p[1], {0, 1, 4, 7}, {-(d.hip_y + 0.035), -d.knee_y, -d.ankle_y},
                   {0.045, 0.04, 0.025});
    case Part::FootL:
      return chain(p[2], {7, 10}, {d.ankle_z + 0.07}, {0.03});
    case Part::ArmL:
      return chain(p[0], {13, 16, 18, 20, 22},
                   {d.shoulder_x - 0.01, d.elbow_x, d.wrist_x, d.hand_x - 0.015},
                   {0.04, 0.035, 0.02, 0.02});
    case Part::Neck:
      return chain(p[1], {9, 12, 15}, {d.neck_y - 0.04, d.head_y}, {0.03, 0.025});
    default: {
      std::array<double, body::kNumJoints> w{};
      w[15] = 1.0;
      return w;
    }
  }
}

}  // namespace

const char* part_name(Part p) {
  static const char* names[] = {"torso",    "left_leg",  "right_leg", "left_foot", "right_foot",
                                "left_arm", "right_arm", "neck",      "head"};
  return names[static_cast<int>(p)];
}

int PartLayout::ring_at(double coord) const {
  int best = 0;
  for (int i = 1; i < rings; ++i)
    if (std::abs(ring_coord[i] - coord) < std::abs(ring_coord[best] - coord)) best = i;
  return best;
}

BodyTemplate build_body_template() {
  const Dims base;
  const auto base_sweeps = sweeps(base);
  const auto subdiv = subdivisions(base_sweeps);

  BodyTemplate bt;
  std::vector<double> verts = positions(base, subdiv);
  const int64_t V = int64_t(verts.size() / 3);

  // Layouts, faces, weights, J_regressor.
  std::vector<int64_t> faces;
  std::vector<int64_t> vertex_part(V);
  auto weights = torch::zeros({V, body::kNumJoints}, torch::kFloat64);
  auto jreg = torch::zeros({body::kNumJoints, V}, torch::kFloat64);
  auto wa = weights.accessor<double, 2>();
  auto ja = jreg.accessor<double, 2>();
  int64_t first = 0;
  bt.parts.resize(kNumParts);
  for (const auto& src : kPartSources) {
    const Sweep& s = base_sweeps[src.sweep];
    const Rings rings = expand(s, subdiv[src.sweep]);
    PartLayout l;
    l.part = src.part;
    l.first = first;
    l.rings = int(rings.rings.size());
    l.segments = s.segments;
    const Vec3 axis{s.e1[1] * s.e2[2] - s.e1[2] * s.e2[1], s.e1[2] * s.e2[0] - s.e1[0] * s.e2[2],
                    s.e1[0] * s.e2[1] - s.e1[1] * s.e2[0]};
    for (const auto& ring : rings.rings)
      l.ring_coord.push_back(ring.c[0] * axis[0] + ring.c[1] * axis[1] + ring.c[2] * axis[2]);
    emit_faces(l, src.mirror, faces);
    for (int64_t v = l.first; v < l.first + l.num_vertices(); ++v) {
      vertex_part[v] = static_cast<int64_t>(src.part);
      const Vec3 p{src.mirror ? -verts[3 * v] : verts[3 * v], verts[3 * v + 1], verts[3 * v + 2]};
      const auto w = vertex_weights(s.part, p, base);
      for (int j = 0; j < body::kNumJoints; ++j) wa[v][src.mirror ? mirror_joint(j) : j] += w[j];
    }
    for (const auto& [joint, ring] : rings.joint_ring) {
      const int j = src.mirror ? mirror_joint(joint) : joint;
      for (int k = 0; k < l.segments; ++k) ja[j][l.vertex(ring, k)] = 1.0 / l.segments;
    }
    bt.parts[static_cast<int>(src.part)] = l;
    first += l.num_vertices();
  }

  auto v_template = torch::from_blob(verts.data(), {V, 3}, torch::kFloat64).clone();
  // Shape directions by finite differences of the (linear) measurements -> vertices map.
  auto shapedirs = torch::zeros({V, 3, kNumBetas}, torch::kFloat64);
  shapedirs.select(2, 0).copy_(kStatureScale * v_template);
  for (int k = 1; k < kNumBetas; ++k) {
    Dims d = base;
    apply_direction(d, k);
    auto moved = positions(d, subdiv);
    shapedirs.select(2, k).copy_(torch::from_blob(moved.data(), {V, 3}, torch::kFloat64) -
                                 v_template);
  }

  auto& m = bt.model;
  m.v_template = v_template;
  m.shapedirs = shapedirs;
  m.posedirs = torch::zeros({V, 3, body::kNumPoseBlend}, torch::kFloat64);
  m.J_regressor = jreg;
  m.weights = weights;
  m.kintree_table = torch::zeros({2, body::kNumJoints}, torch::kInt64);
  for (int j = 0; j < body::kNumJoints; ++j) {
    m.kintree_table[0][j] = body::kParents[j];
    m.kintree_table[1][j] = j;
  }
  m.faces = torch::from_blob(faces.data(), {int64_t(faces.size() / 3), 3}, torch::kInt64).clone();
  bt.vertex_part = torch::from_blob(vertex_part.data(), {V}, torch::kInt64).clone();
  m.validate("synthetic body template");

  Landmarks& lm = bt.landmarks;
  lm.hip_y = base.hip_y, lm.knee_y = base.knee_y, lm.ankle_y = base.ankle_y;
  lm.sole_y = base.sole_y, lm.spine1_y = base.spine1_y, lm.spine2_y = base.spine2_y;
  lm.neck_y = base.neck_y, lm.head_y = base.head_y, lm.arm_y = base.arm_y;
  lm.shoulder_x = base.shoulder_x, lm.elbow_x = base.elbow_x, lm.wrist_x = base.wrist_x;
  lm.head_center = {0.0, base.head_cy, base.head_cz};
  lm.head_radii = {base.head_rx, base.head_ry, base.head_rz};
  return bt;
}

}  // namespace th::synth
