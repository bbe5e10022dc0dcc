#include "synth/texture.hpp"

#include <algorithm>
#include <cmath>

namespace th::synth {
namespace {

uint32_t hash3(int32_t x, int32_t y, int32_t z, uint32_t seed) {
  uint32_t h = seed * 0x27d4eb2du;
  h ^= static_cast<uint32_t>(x) * 0x8da6b343u;
  h ^= static_cast<uint32_t>(y) * 0xd8163841u;
  h ^= static_cast<uint32_t>(z) * 0xcb1ab31fu;
  h ^= h >> 15;
  h *= 0x2c1b3c6du;
  h ^= h >> 12;
  h *= 0x297a2d39u;
  h ^= h >> 15;
  return h;
}
float unit(uint32_t h) { return static_cast<float>(h >> 8) * (1.0f / 16777216.0f); }

float fract(float v) { return v - std::floor(v); }

Rgb mix(const Rgb& a, const Rgb& b, float t) {
  return {a[0] + t * (b[0] - a[0]), a[1] + t * (b[1] - a[1]), a[2] + t * (b[2] - a[2])};
}
Rgb scale(const Rgb& a, float s) { return {a[0] * s, a[1] * s, a[2] * s}; }

// Fabric grain: a fine value noise (4 mm cells), centred on 0.
float grain(const float* p, uint32_t seed) {
  return value_noise(p[0] / 0.004f, p[1] / 0.004f, p[2] / 0.004f, seed) - 0.5f;
}

// Soft-edged ellipse test: 1 inside, 0 outside.
float ellipse(float x, float y, float cx, float cy, float rx, float ry) {
  const float d = ((x - cx) / rx) * ((x - cx) / rx) + ((y - cy) / ry) * ((y - cy) / ry);
  return std::clamp((1.0f - d) * 8.0f, 0.0f, 1.0f);
}

Rgb skin(const Material& m, const float* p) {
  Rgb c = scale(m.c1, 1.0f + 0.5f * m.detail * grain(p, m.seed));
  if (!m.landmarks) return c;
  const auto& hc = m.landmarks->head_center;
  const auto& hr = m.landmarks->head_radii;
  const float qx = (p[0] - float(hc[0])) / float(hr[0]);
  const float qy = (p[1] - float(hc[1])) / float(hr[1]);
  const float qz = (p[2] - float(hc[2])) / float(hr[2]);
  if (qz < 0.45f || qy < -1.1f || qy > 0.9f || p[1] < m.landmarks->head_y) return c;
  const float ax = std::abs(qx);
  // Eyes: white with a dark iris; brows in the hair colour; lips; a shadow under the nose.
  const float eye = ellipse(ax, qy, 0.36f, 0.08f, 0.16f, 0.075f);
  const float iris = ellipse(ax, qy, 0.36f, 0.08f, 0.065f, 0.065f);
  const float brow = ellipse(ax, qy, 0.37f, 0.25f, 0.2f, 0.035f);
  const float lips = ellipse(qx, qy, 0.0f, -0.45f, 0.25f, 0.055f);
  const float nose = ellipse(qx, qy, 0.0f, -0.2f, 0.07f, 0.05f);
  c = mix(c, scale(c, 0.8f), nose);
  c = mix(c, m.c3, 0.8f * lips);
  c = mix(c, m.c2, 0.9f * brow);
  c = mix(c, Rgb{0.93f, 0.93f, 0.9f}, eye);
  c = mix(c, Rgb{0.12f, 0.08f, 0.05f}, iris);
  return c;
}

}  // namespace

float value_noise(float x, float y, float z, uint32_t seed) {
  const float fx = std::floor(x), fy = std::floor(y), fz = std::floor(z);
  const int32_t ix = static_cast<int32_t>(fx), iy = static_cast<int32_t>(fy),
                iz = static_cast<int32_t>(fz);
  auto s = [](float t) { return t * t * (3.0f - 2.0f * t); };
  const float tx = s(x - fx), ty = s(y - fy), tz = s(z - fz);
  float v = 0.0f;
  for (int c = 0; c < 8; ++c) {
    const int dx = c & 1, dy = (c >> 1) & 1, dz = (c >> 2) & 1;
    const float w = (dx ? tx : 1 - tx) * (dy ? ty : 1 - ty) * (dz ? tz : 1 - tz);
    v += w * unit(hash3(ix + dx, iy + dy, iz + dz, seed));
  }
  return v;
}

Rgb hsv(float h, float s, float v) {
  h = fract(h) * 6.0f;
  const int i = static_cast<int>(h);
  const float f = h - i, p = v * (1 - s), q = v * (1 - s * f), t = v * (1 - s * (1 - f));
  switch (i) {
    case 0:
      return {v, t, p};
    case 1:
      return {q, v, p};
    case 2:
      return {p, v, t};
    case 3:
      return {p, q, v};
    case 4:
      return {t, p, v};
    default:
      return {v, p, q};
  }
}

Rgb albedo(const Material& m, const float* p) {
  Rgb c = m.c1;
  switch (m.pattern) {
    case Pattern::Solid:
      break;
    case Pattern::Stripes: {
      const float coord = m.variant % 2 ? p[1] + 0.6f * p[0] : p[1];
      c = fract(coord / m.scale) < 0.5f ? m.c1 : m.c2;
      break;
    }
    case Pattern::Checks: {
      const float u = p[0] / m.scale, v = p[1] / m.scale, w = p[2] / m.scale;
      const int parity = (static_cast<int>(std::floor(u)) + static_cast<int>(std::floor(v)) +
                          static_cast<int>(std::floor(w))) &
                         1;
      c = parity ? m.c2 : m.c1;
      const float line = std::min({std::abs(fract(u) - 0.5f), std::abs(fract(v) - 0.5f)});
      if (line < 0.06f) c = mix(c, m.c3, 0.7f);
      break;
    }
    case Pattern::Dots: {
      const float u = p[0] / m.scale, v = p[1] / m.scale, w = p[2] / m.scale;
      const int32_t iu = int32_t(std::floor(u)), iv = int32_t(std::floor(v)),
                    iw = int32_t(std::floor(w));
      for (int c3 = 0; c3 < 8 && c == m.c1; ++c3) {
        const int32_t cu = iu - (c3 & 1), cv = iv - ((c3 >> 1) & 1), cw = iw - ((c3 >> 2) & 1);
        const uint32_t h = hash3(cu, cv, cw, m.seed + 101);
        const float ox = cu + 0.5f + unit(h) * 0.5f, oy = cv + 0.5f + unit(h * 747796405u) * 0.5f,
                    oz = cw + 0.5f + unit(h * 2891336453u) * 0.5f;
        const float r = 0.18f + 0.2f * unit(h ^ 0x9e3779b9u);
        const float d2 = (u - ox) * (u - ox) + (v - oy) * (v - oy) + (w - oz) * (w - oz);
        if (d2 < r * r) c = (h & 3) == 0 ? m.c3 : m.c2;
      }
      break;
    }
    case Pattern::Print: {
      if (m.landmarks) {
        const float cy = float(m.landmarks->spine2_y) + 0.03f;
        const float r = std::hypot(p[0], p[1] - cy);
        if (p[2] > 0.04f) {
          // Emblem on the chest: a ring around a star.
          const float ang = std::atan2(p[1] - cy, p[0]);
          const float star = 0.035f * (0.6f + 0.4f * std::cos(5.0f * ang));
          if (r > 0.055f && r < 0.07f) c = m.c2;
          if (r < star) c = m.c3;
        } else if (p[2] < -0.04f && std::abs(p[1] - cy) < 0.05f && std::abs(p[0]) < 0.11f) {
          c = fract(p[0] / 0.04f) < 0.55f ? m.c2 : m.c1;  // a barcode-like band on the back
        }
      }
      break;
    }
    case Pattern::Denim: {
      const float twill = fract((p[0] + p[1] + p[2]) / 0.006f);
      c = scale(m.c1, 0.9f + 0.2f * twill);
      if (m.landmarks && std::abs(p[2]) < 0.006f && p[1] < float(m.landmarks->hip_y)) c = m.c2;
      break;
    }
    case Pattern::Skin:
      return skin(m, p);
    case Pattern::Hair: {
      const float strands = value_noise(p[0] / 0.004f, p[1] / 0.05f, p[2] / 0.004f, m.seed + 3);
      return scale(m.c1, 0.75f + 0.5f * strands);
    }
    case Pattern::Shoe: {
      if (m.landmarks && p[1] < float(m.landmarks->sole_y) + 0.014f) return m.c2;
      if (m.landmarks && p[2] > 0.03f && p[2] < 0.11f && std::abs(std::abs(p[0]) - 0.09f) < 0.02f &&
          fract(p[2] / 0.018f) < 0.35f && p[1] > float(m.landmarks->sole_y) + 0.04f)
        return m.c3;
      break;
    }
  }
  return scale(c, 1.0f + m.detail * grain(p, m.seed));
}

}  // namespace th::synth
