#pragma once
// Procedural surface textures of the synthetic people. A texture is a function of the
// canonical (template-space, zero shape) position of a surface point, so a pattern stays
// fixed to the body and to the clothes whatever the pose, shape or view.

#include <array>
#include <cstdint>

#include "synth/body_builder.hpp"

namespace th::synth {

using Rgb = std::array<float, 3>;  // linear-ish RGB in [0, 1]

enum class Pattern : uint8_t {
  Solid,    // c1 with fabric grain
  Stripes,  // c1/c2 bands of period `scale` (horizontal, or diagonal when `variant` is odd)
  Checks,   // 3D checker of c1/c2 with c3 plaid lines
  Dots,     // c2 dots of random size on c1 (a print)
  Print,    // c1 with a c2/c3 emblem on the chest front and a c2 number band on the back
  Denim,    // c1 twill with c2 seams along the outside of the legs
  Skin,     // c1 skin tone; the head gets eyes, brows (c2), lips (c3)
  Hair,     // c1 with strands
  Shoe,     // c1 upper, c2 sole, c3 laces
};

struct Material {
  Pattern pattern = Pattern::Solid;
  Rgb c1{0.5f, 0.5f, 0.5f}, c2{0.2f, 0.2f, 0.2f}, c3{0.8f, 0.8f, 0.8f};
  float scale = 0.05f;   // pattern period (metres, canonical space)
  float detail = 0.08f;  // amplitude of the fine grain
  int variant = 0;
  uint32_t seed = 0;
  const Landmarks* landmarks = nullptr;  // template landmarks (face, soles, chest)
};

// Albedo of the material at canonical point p (3 floats).
Rgb albedo(const Material& m, const float* p);

// Value noise in [0, 1) at (x, y, z) on a unit lattice (smooth trilinear interpolation of
// hashed lattice values), reproducible from the seed.
float value_noise(float x, float y, float z, uint32_t seed);

// HSV (h in [0, 1), s, v in [0, 1]) to RGB.
Rgb hsv(float h, float s, float v);

}  // namespace th::synth
