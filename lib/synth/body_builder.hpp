#pragma once
// The synthetic body model in SMPL's form (METHOD 1.5): 24 joints with SMPL's kinematic tree and
// names, a T-pose template (y up, x to the body's left, z forward, metres, about 1.75 m tall,
// pelvis joint at the origin), smooth LBS weights, 10 shape directions with a meaning, zero
// pose blend shapes and a J_regressor whose rows average rings of vertices.
//
// Surface: a union of closed parts, each a swept tube (rings of a superellipse cross-section
// with a pole at each end, so every part is a closed genus-0 surface): torso, two legs, two
// feet, two arms (hands included), neck and head. Parts overlap where they meet (hips,
// shoulders, neck, ankles); they are not welded. Each ring is point-symmetric about its centre
// (segment counts are multiples of 4), so the mean of a ring's vertices is its centre: the
// J_regressor rows average the ring through each joint, and joints follow any shape exactly.
//
// Shape directions (unit coefficient ~ one standard deviation of adult variation):
//   0 stature (uniform scale)      1 weight/girth (torso and limbs)   2 shoulder width
//   3 hip width                    4 leg length                       5 arm length
//   6 torso length                 7 chest and belly depth            8 head size
//   9 limb muscularity

#include <torch/types.h>

#include <array>
#include <string>
#include <vector>

#include "body/smpl.hpp"

namespace th::synth {

constexpr int kNumBetas = 10;

enum class Part : int { Torso, LegL, LegR, FootL, FootR, ArmL, ArmR, Neck, Head };
constexpr int kNumParts = 9;
const char* part_name(Part p);

// Vertex layout of one part: pole 0, then rings x segments (ring-major), then pole 1.
struct PartLayout {
  Part part;
  int64_t first = 0;               // index of pole 0
  int rings = 0;                   // rings between the poles
  int segments = 0;                // vertices per ring
  std::vector<double> ring_coord;  // per ring, the template coordinate along the part's axis
                                   // (y for torso/neck/head, -y for legs, z for feet, |x| arms)
  int64_t pole0() const { return first; }
  int64_t pole1() const { return first + 1 + int64_t(rings) * segments; }
  int64_t vertex(int ring, int segment) const {
    return first + 1 + int64_t(ring) * segments + ((segment % segments) + segments) % segments;
  }
  int64_t num_vertices() const { return int64_t(rings) * segments + 2; }
  // Ring whose template coordinate is nearest to `coord`.
  int ring_at(double coord) const;
};

// Template landmarks that garments and textures are placed by (template coordinates).
struct Landmarks {
  double hip_y, knee_y, ankle_y, sole_y, spine1_y, spine2_y, neck_y, head_y, arm_y;
  double shoulder_x, elbow_x, wrist_x;
  std::array<double, 3> head_center, head_radii;
};

struct BodyTemplate {
  body::SmplModel model;          // what is written as smpl_model.npz / .pkl
  std::vector<PartLayout> parts;  // indexed by Part
  torch::Tensor vertex_part;      // (V) int64, Part of each vertex
  Landmarks landmarks;
  const PartLayout& layout(Part p) const { return parts[static_cast<int>(p)]; }
};

// Builds the model. Deterministic and independent of any seed: every synthetic dataset uses
// the same body model, as every ZJU-MoCap subject uses the same SMPL.
BodyTemplate build_body_template();

}  // namespace th::synth
