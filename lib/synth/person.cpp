#include "synth/person.hpp"

#include <torch/torch.h>

#include <cmath>
#include <functional>

#include "geometry/mesh.hpp"

namespace th::synth {
namespace {

constexpr double kPi = 3.14159265358979323846;

enum MaterialSlot : uint8_t { kSkin = 0, kUpper = 1, kLower = 2, kShoes = 3, kHairMat = 4 };

enum class Sleeve { Short, Elbow, Long };
enum class Lower { Trousers, Shorts, Skirt, WideTrousers };
enum class HairStyle { Short, Bob, Long, Buzz };

// The random choices that define an outfit (geometry only; colours are in the materials).
struct Outfit {
  Sleeve sleeve = Sleeve::Short;
  double shirt_loose = 0.02;  // extra stand-off at the hem (metres)
  double shirt_hem = 0.0;     // hem height relative to the hip joint
  Lower lower = Lower::Trousers;
  double leg_wide = 0.01;
  double skirt_drop = 0.4, skirt_flare = 1.5;
  HairStyle hair = HairStyle::Short;
  double hair_volume = 0.015;
  bool boots = false;
};

bool mirrored(Part p) { return p == Part::LegR || p == Part::FootR || p == Part::ArmR; }

// Builds the render mesh for one set of body positions (the template, for texture
// coordinates, or the shaped body, for geometry): same topology both times.
class MeshBuilder {
 public:
  MeshBuilder(const BodyTemplate& bt, const torch::Tensor& body_pos)
      : bt_(bt),
        pos_(body_pos.contiguous()),
        normals_(geometry::vertex_normals(body_pos, bt.model.faces).contiguous()),
        weights_(bt.model.weights.contiguous()) {}

  std::vector<double> positions;
  std::vector<double> weights;  // 24 per vertex
  std::vector<int64_t> faces;
  std::vector<uint8_t> material, label, cull;

  int64_t count() const { return int64_t(positions.size() / 3); }

  // The body's vertices; its faces are added by finish_body() once the clothes are known.
  void body() {
    const auto V = bt_.model.num_vertices();
    for (int64_t v = 0; v < V; ++v) add(point(v), body_weights(v));
    covered.assign(V, 0);
  }

  // The body's faces that are not hidden under clothes, skin everywhere (labels by part, as
  // a human parser would give). Culled when seen from behind: each part is closed.
  void finish_body() {
    auto f = bt_.model.faces.contiguous();
    auto part = bt_.vertex_part.contiguous();
    const int64_t* fp = f.data_ptr<int64_t>();
    const int64_t* pp = part.data_ptr<int64_t>();
    for (int64_t t = 0; t < f.size(0); ++t) {
      const int64_t a = fp[3 * t], b = fp[3 * t + 1], c = fp[3 * t + 2];
      if (covered[a] && covered[b] && covered[c]) continue;
      face(a, b, c, kSkin, skin_label(static_cast<Part>(pp[a])));
      cull.back() = 1;
    }
  }

  std::vector<uint8_t> covered;  // body vertices hidden under a garment

  // A garment band over rings [r0, r1] of a body part, pushed out along the body normals by
  // offset(t) (t = 0 at r0, 1 at r1) plus `sole` times the downward part of the normal. Ends
  // at a pole are closed when `close` is set.
  void band(Part part, int r0, int r1, const std::function<double(double)>& offset, bool close,
            uint8_t mat, uint8_t lab, double sole = 0.0) {
    const PartLayout& l = bt_.layout(part);
    const bool mirror = mirrored(part);
    std::vector<std::vector<int64_t>> rows;
    auto shifted = [&](int64_t v, double t) {
      const double* n = normals_.data_ptr<double>() + 3 * v;
      const double off = offset(t) + sole * std::max(0.0, -n[1]);
      std::array<double, 3> p = point(v);
      for (int c = 0; c < 3; ++c) p[c] += off * n[c];
      return add(p, body_weights(v));
    };
    const bool pole0 = close && r0 == 0, pole1 = close && r1 == l.rings - 1;
    // The body under the band is hidden, except near an open end, where one can look in.
    for (int r = pole0 ? 0 : r0 + 2; r <= (pole1 ? l.rings - 1 : r1 - 2); ++r)
      for (int j = 0; j < l.segments; ++j) covered[l.vertex(r, j)] = 1;
    if (pole0) covered[l.pole0()] = 1;
    if (pole1) covered[l.pole1()] = 1;
    int64_t p0 = -1, p1 = -1;
    if (pole0) p0 = shifted(l.pole0(), 0.0);
    for (int r = r0; r <= r1; ++r) {
      std::vector<int64_t> row;
      const double t = r1 > r0 ? double(r - r0) / (r1 - r0) : 0.0;
      for (int j = 0; j < l.segments; ++j) row.push_back(shifted(l.vertex(r, j), t));
      rows.push_back(row);
    }
    if (pole1) p1 = shifted(l.pole1(), 1.0);
    auto tri = [&](int64_t a, int64_t b, int64_t c) {
      if (mirror) std::swap(b, c);
      face(a, b, c, mat, lab);
    };
    const int S = l.segments;
    if (pole0)
      for (int j = 0; j < S; ++j) tri(p0, rows[0][(j + 1) % S], rows[0][j]);
    for (size_t i = 0; i + 1 < rows.size(); ++i)
      for (int j = 0; j < S; ++j) {
        const int64_t a = rows[i][j], b = rows[i][(j + 1) % S], c = rows[i + 1][(j + 1) % S],
                      d = rows[i + 1][j];
        tri(a, b, c);
        tri(a, c, d);
      }
    if (pole1)
      for (int j = 0; j < S; ++j) tri(p1, rows.back()[j], rows.back()[(j + 1) % S]);
  }

  // A skirt: from a torso ring at the waist down by `drop`, widening by `flare`; the hem
  // follows the pelvis and both thighs.
  void skirt(double waist_y, double drop, double flare, uint8_t mat) {
    const PartLayout& l = bt_.layout(Part::Torso);
    const int ring = l.ring_at(waist_y);
    const int S = l.segments, K = 14;
    std::array<double, 3> centre{0, 0, 0};
    std::vector<std::array<double, 3>> top(S);
    for (int j = 0; j < S; ++j) {
      const int64_t v = l.vertex(ring, j);
      top[j] = point(v);
      const double* n = normals_.data_ptr<double>() + 3 * v;
      for (int c = 0; c < 3; ++c) {
        top[j][c] += 0.014 * n[c];
        centre[c] += top[j][c] / S;
      }
    }
    std::array<double, body::kNumJoints> hem_w{};
    hem_w[0] = 0.5, hem_w[1] = 0.25, hem_w[2] = 0.25;
    const int64_t first = count();
    for (int k = 0; k <= K; ++k) {
      const double t = double(k) / K;
      const double grow = 1.0 + (flare - 1.0) * t + 0.08 * std::sin(kPi * t);
      for (int j = 0; j < S; ++j) {
        const int64_t v = l.vertex(ring, j);
        std::array<double, 3> p{centre[0] + (top[j][0] - centre[0]) * grow, top[j][1] - drop * t,
                                centre[2] + (top[j][2] - centre[2]) * grow};
        auto w = body_weights(v);
        for (int q = 0; q < body::kNumJoints; ++q) w[q] = (1 - t) * w[q] + t * hem_w[q];
        add(p, w);
      }
    }
    for (int k = 0; k < K; ++k)
      for (int j = 0; j < S; ++j) {
        const int64_t a = first + k * S + j, b = first + k * S + (j + 1) % S,
                      c = first + (k + 1) * S + (j + 1) % S, d = first + (k + 1) * S + j;
        // Rows run downwards (against the torso's ring order), hence this winding.
        face(a, c, b, mat, cihp::kSkirt);
        face(a, d, c, mat, cihp::kSkirt);
      }
  }

  // Hair: a shell over the skull from the crown down to a hairline that depends on the style,
  // `volume` off the head; long hair adds a curtain down the back. Rigid with the head.
  void hair(HairStyle style, double volume) {
    const PartLayout& l = bt_.layout(Part::Head);
    const auto top = point(l.pole1()), bottom = point(l.pole0());
    const double ry = 0.5 * (top[1] - bottom[1]);
    const std::array<double, 3> c{0.0, top[1] - ry, top[2]};
    const int eq = l.rings / 2;  // the equator ring (theta = pi/2)
    const double rz = point(l.vertex(eq, 0))[2] - c[2];
    const double rx = point(l.vertex(eq, l.segments / 4))[0];
    double front = 0.3, side = 0.52, back = 0.68;  // hairline angles from the crown (x pi)
    if (style == HairStyle::Bob) front = 0.34, side = 0.62, back = 0.74;
    if (style == HairStyle::Long) front = 0.3, side = 0.6, back = 0.72;
    if (style == HairStyle::Buzz) front = 0.27, side = 0.45, back = 0.6;
    const int J = 32, K = 10, L = 9;
    std::array<double, body::kNumJoints> w{};
    w[15] = 1.0;
    auto at = [&](double alpha, double phi, double v) {
      const double dx = std::sin(alpha) * std::sin(phi), dy = std::cos(alpha),
                   dz = std::sin(alpha) * std::cos(phi);
      return std::array<double, 3>{c[0] + (rx + v) * dx, c[1] + (ry + v) * dy,
                                   c[2] + (rz + v) * dz};
    };
    auto limit = [&](double phi) {
      const double cb = 0.5 * (1.0 - std::cos(phi));   // 0 front, 1 back
      const double sd = std::pow(std::sin(phi), 2.0);  // 1 at the sides
      return kPi * (front + (back - front) * cb + (side - 0.5 * (front + back)) * sd);
    };
    const int64_t crown = add(at(0.0, 0.0, volume), w);
    std::vector<std::vector<int64_t>> grid(J);
    for (int j = 0; j < J; ++j) {
      const double phi = 2.0 * kPi * j / J;
      for (int k = 1; k <= K; ++k) {
        const double f = double(k) / K;
        grid[j].push_back(add(at(limit(phi) * f, phi, volume * (1.0 - 0.35 * f * f)), w));
      }
    }
    const int64_t first_face = int64_t(faces.size() / 3);
    for (int j = 0; j < J; ++j) {
      const int n = (j + 1) % J;
      face(crown, grid[j][0], grid[n][0], kHairMat, cihp::kHair);
      for (int k = 0; k + 1 < K; ++k) {
        face(grid[j][k], grid[j][k + 1], grid[n][k + 1], kHairMat, cihp::kHair);
        face(grid[j][k], grid[n][k + 1], grid[n][k], kHairMat, cihp::kHair);
      }
    }
    if (style == HairStyle::Long) {
      // The curtain hangs from the widest part of the head over the back columns.
      std::vector<std::vector<int64_t>> curtain(J);
      for (int j = 0; j < J; ++j) {
        const double phi = 2.0 * kPi * j / J;
        if (std::cos(phi) > -0.25) continue;
        const auto start = point_of(grid[j][K - 1]);
        const auto widest = at(0.5 * kPi, phi, volume);
        for (int k = 1; k <= L; ++k) {
          const double f = double(k) / L;
          const double drop = f * (ry + 0.15);
          std::array<double, 3> p{widest[0] * (1.0 + 0.1 * f), start[1] - drop,
                                  widest[2] - 0.035 * f};
          curtain[j].push_back(add(p, w));
        }
      }
      for (int j = 0; j < J; ++j) {
        const int n = (j + 1) % J;
        if (curtain[j].empty() || curtain[n].empty()) continue;
        face(grid[j][K - 1], curtain[j][0], curtain[n][0], kHairMat, cihp::kHair);
        face(grid[j][K - 1], curtain[n][0], grid[n][K - 1], kHairMat, cihp::kHair);
        for (int k = 0; k + 1 < L; ++k) {
          face(curtain[j][k], curtain[j][k + 1], curtain[n][k + 1], kHairMat, cihp::kHair);
          face(curtain[j][k], curtain[n][k + 1], curtain[n][k], kHairMat, cihp::kHair);
        }
      }
    }
    hair_faces = {first_face, int64_t(faces.size() / 3)};
  }

  std::pair<int64_t, int64_t> hair_faces{0, 0};

 private:
  std::array<double, 3> point(int64_t v) const {
    const double* p = pos_.data_ptr<double>() + 3 * v;
    return {p[0], p[1], p[2]};
  }
  std::array<double, 3> point_of(int64_t built) const {
    return {positions[3 * built], positions[3 * built + 1], positions[3 * built + 2]};
  }
  std::array<double, body::kNumJoints> body_weights(int64_t v) const {
    std::array<double, body::kNumJoints> w{};
    const double* p = weights_.data_ptr<double>() + body::kNumJoints * v;
    std::copy(p, p + body::kNumJoints, w.begin());
    return w;
  }
  int64_t add(const std::array<double, 3>& p, const std::array<double, body::kNumJoints>& w) {
    positions.insert(positions.end(), p.begin(), p.end());
    weights.insert(weights.end(), w.begin(), w.end());
    return count() - 1;
  }
  void face(int64_t a, int64_t b, int64_t c, uint8_t mat, uint8_t lab) {
    faces.insert(faces.end(), {a, b, c});
    material.push_back(mat);
    label.push_back(lab);
    cull.push_back(0);
  }
  static uint8_t skin_label(Part p) {
    switch (p) {
      case Part::Torso:
        return cihp::kTorsoSkin;
      case Part::LegL:
        return cihp::kLeftLeg;
      case Part::LegR:
        return cihp::kRightLeg;
      case Part::FootL:
        return cihp::kLeftShoe;
      case Part::FootR:
        return cihp::kRightShoe;
      case Part::ArmL:
        return cihp::kLeftArm;
      case Part::ArmR:
        return cihp::kRightArm;
      default:
        return cihp::kFace;
    }
  }

  const BodyTemplate& bt_;
  torch::Tensor pos_, normals_, weights_;
};

void dress(MeshBuilder& b, const BodyTemplate& bt, const Outfit& o) {
  const Landmarks& lm = bt.landmarks;
  const PartLayout& torso = bt.layout(Part::Torso);
  b.body();

  // Lower garment first; the shirt (larger stand-off) goes over its waist.
  const bool skirt = o.lower == Lower::Skirt;
  const double waist = lm.spine1_y - 0.015;
  const double tight = 0.009;
  b.band(
      Part::Torso, 0, torso.ring_at(waist), [&](double) { return tight; }, true, kLower,
      skirt ? cihp::kSkirt : cihp::kPants);
  double hem = -lm.ankle_y - 0.03;  // leg coordinate is -y
  if (o.lower == Lower::Shorts) hem = -lm.knee_y - 0.08;
  if (skirt) hem = -lm.hip_y + 0.1;
  for (Part leg : {Part::LegL, Part::LegR}) {
    const PartLayout& l = bt.layout(leg);
    const double wide = o.lower == Lower::WideTrousers ? o.leg_wide + 0.02 : o.leg_wide;
    b.band(
        leg, 0, l.ring_at(hem), [&](double t) { return tight + wide * t * t; }, true, kLower,
        skirt ? cihp::kSkirt : cihp::kPants);
  }
  if (skirt) b.skirt(waist - 0.01, o.skirt_drop, o.skirt_flare, kLower);

  // Shirt: torso band flaring towards the hem, and sleeves.
  const int hem_ring = torso.ring_at(lm.hip_y + o.shirt_hem);
  const int top_ring = torso.ring_at(lm.neck_y - 0.012);
  b.band(
      Part::Torso, hem_ring, top_ring,
      [&](double t) { return 0.016 + o.shirt_loose * std::pow(1.0 - t, 1.5); }, false, kUpper,
      cihp::kUpper);
  double sleeve_end = lm.shoulder_x + 0.11;
  if (o.sleeve == Sleeve::Elbow) sleeve_end = lm.elbow_x + 0.03;
  if (o.sleeve == Sleeve::Long) sleeve_end = lm.wrist_x - 0.015;
  for (Part arm : {Part::ArmL, Part::ArmR}) {
    const PartLayout& l = bt.layout(arm);
    b.band(
        arm, l.ring_at(lm.shoulder_x - 0.07), l.ring_at(sleeve_end),
        [&](double t) { return 0.012 + 0.5 * o.shirt_loose * t; }, false, kUpper, cihp::kUpper);
  }

  // Shoes (boots reach up the calf), hair.
  for (Part foot : {Part::FootL, Part::FootR}) {
    const PartLayout& l = bt.layout(foot);
    b.band(
        foot, 0, l.rings - 1, [](double) { return 0.006; }, true, kShoes,
        foot == Part::FootL ? cihp::kLeftShoe : cihp::kRightShoe, 0.008);
  }
  for (Part leg : {Part::LegL, Part::LegR}) {
    const PartLayout& l = bt.layout(leg);
    const double from = -lm.ankle_y - (o.boots ? 0.24 : 0.035);
    b.band(
        leg, l.ring_at(from), l.rings - 1, [&](double) { return o.boots ? 0.014 : 0.007; }, true,
        kShoes, leg == Part::LegL ? cihp::kLeftShoe : cihp::kRightShoe);
  }
  b.hair(o.hair, o.hair_volume);
  b.finish_body();
}

Material material(Pattern p, Rgb c1, Rgb c2, Rgb c3, float scale, uint32_t seed,
                  const Landmarks* lm, int variant = 0) {
  Material m;
  m.pattern = p;
  m.c1 = c1, m.c2 = c2, m.c3 = c3;
  m.scale = scale;
  m.seed = seed;
  m.landmarks = lm;
  m.variant = variant;
  return m;
}

const char* pattern_name(Pattern p) {
  switch (p) {
    case Pattern::Solid:
      return "plain";
    case Pattern::Stripes:
      return "striped";
    case Pattern::Checks:
      return "checked";
    case Pattern::Dots:
      return "dotted";
    case Pattern::Print:
      return "printed";
    case Pattern::Denim:
      return "denim";
    default:
      return "";
  }
}

}  // namespace

Person make_person(const BodyTemplate& bt, const std::string& name, int index, bool unseen,
                   double shape_std, uint64_t style_offset, Rng& rng) {
  Person person;
  person.name = name;
  person.index = index;
  person.unseen = unseen;

  // Shape: independent normals, clipped at 2.5 standard deviations.
  person.shapes = torch::zeros({kNumBetas}, torch::kFloat64);
  for (int k = 0; k < kNumBetas; ++k)
    person.shapes[k] = std::clamp(rng.normal(), -2.5, 2.5) * shape_std;

  // Outfit: categorical choices rotate with the person's index (from the dataset's offset),
  // so that a few people already cover every pattern, sleeve, lower garment and hair style.
  const uint64_t start = style_offset;
  const uint64_t slot = start + uint64_t(index);
  Outfit o;
  o.sleeve = static_cast<Sleeve>(slot % 3);
  o.lower = static_cast<Lower>(slot % 4);
  o.hair = static_cast<HairStyle>((3 * slot + slot / 4) % 4);
  o.shirt_loose = rng.uniform(0.005, 0.05);
  o.shirt_hem = rng.uniform(-0.02, 0.06);
  o.leg_wide = rng.uniform(0.0, 0.02);
  o.skirt_drop = rng.uniform(0.32, 0.46);
  o.skirt_flare = rng.uniform(1.3, 1.75);
  o.hair_volume = o.hair == HairStyle::Buzz ? 0.004 : rng.uniform(0.012, 0.035);
  o.boots = rng.chance(0.25);

  const Landmarks* lm = &bt.landmarks;
  const std::vector<Rgb> skins = {{0.96f, 0.80f, 0.69f}, {0.90f, 0.71f, 0.57f},
                                  {0.78f, 0.57f, 0.42f}, {0.62f, 0.43f, 0.30f},
                                  {0.45f, 0.30f, 0.20f}, {0.32f, 0.21f, 0.14f}};
  const std::vector<Rgb> hairs = {{0.05f, 0.04f, 0.04f}, {0.20f, 0.12f, 0.07f},
                                  {0.40f, 0.25f, 0.13f}, {0.80f, 0.65f, 0.40f},
                                  {0.55f, 0.22f, 0.10f}, {0.62f, 0.62f, 0.62f}};
  const Rgb skin = skins[(start + index * 7) % skins.size()];
  const Rgb hair = hairs[(start / 3 + index * 5) % hairs.size()];
  const Rgb lips{skin[0] * 0.85f + 0.1f, skin[1] * 0.55f, skin[2] * 0.55f};

  // Shirt hues spread around the colour wheel by the golden angle from person to person.
  const float hue =
      float(std::fmod(start / 60.0 + index * 0.618033988749895 + 0.05 * rng.uniform(), 1.0));
  const float saturation = float(rng.uniform(0.45, 0.85));
  const float value = float(rng.uniform(0.55, 0.92));
  const Rgb shirt1 = hsv(hue, saturation, value);
  const Rgb shirt2 = rng.chance(0.5)
                         ? hsv(hue + 0.5f, 0.6f, 0.9f)
                         : (rng.chance(0.5) ? Rgb{0.95f, 0.95f, 0.93f} : Rgb{0.08f, 0.08f, 0.1f});
  const Rgb shirt3 = hsv(hue + 0.25f, 0.7f, 0.95f);
  const Pattern shirt_pattern = static_cast<Pattern>(slot % 5);  // Solid .. Print
  const float shirt_scale = float(rng.uniform(0.03, 0.07));

  const std::vector<Rgb> lowers = {{0.15f, 0.22f, 0.42f}, {0.08f, 0.08f, 0.09f},
                                   {0.62f, 0.53f, 0.36f}, {0.35f, 0.36f, 0.38f},
                                   {0.28f, 0.33f, 0.18f}, {0.55f, 0.12f, 0.16f}};
  Rgb lower1 = lowers[(start + index * 3) % lowers.size()];
  if (o.lower == Lower::Skirt) lower1 = hsv(hue + 0.4f, 0.65f, 0.75f);
  const Rgb lower2 = hsv(hue + 0.15f, 0.3f, 0.95f);
  const Pattern lower_patterns[] = {Pattern::Denim, Pattern::Solid, Pattern::Checks,
                                    Pattern::Stripes};
  Pattern lower_pattern = lower_patterns[(slot / 4 + slot / 2) % 4];
  if (o.lower == Lower::Skirt) {
    const Pattern skirt_patterns[] = {Pattern::Solid, Pattern::Checks, Pattern::Stripes,
                                      Pattern::Dots};
    lower_pattern = skirt_patterns[(slot / 4) % 4];
  }

  const std::vector<Rgb> shoes = {
      {0.1f, 0.1f, 0.1f}, {0.9f, 0.9f, 0.88f}, {0.4f, 0.25f, 0.12f}, {0.7f, 0.15f, 0.15f}};
  const Rgb shoe = shoes[(start + index) % shoes.size()];
  const Rgb sole = shoe[0] > 0.5f ? Rgb{0.2f, 0.2f, 0.2f} : Rgb{0.92f, 0.92f, 0.9f};

  const uint32_t seed = static_cast<uint32_t>(rng.bits());
  person.materials = {
      material(Pattern::Skin, skin, hair, lips, 0.05f, seed, lm),
      material(shirt_pattern, shirt1, shirt2, shirt3, shirt_scale, seed + 1, lm, int(slot)),
      material(lower_pattern, lower1, lower2, Rgb{0.9f, 0.85f, 0.6f},
               float(rng.uniform(0.04, 0.08)), seed + 2, lm, int(slot / 5)),
      material(Pattern::Shoe, shoe, sole, Rgb{0.95f, 0.95f, 0.95f}, 0.05f, seed + 3, lm),
      material(Pattern::Hair, hair, hair, hair, 0.05f, seed + 4, lm),
  };
  person.materials[kSkin].detail = 0.05f;
  person.materials[kHairMat].detail = 0.1f;

  static const char* sleeves[] = {"short-sleeve", "elbow-sleeve", "long-sleeve"};
  static const char* lowers_txt[] = {"trousers", "shorts", "skirt", "wide trousers"};
  static const char* hair_txt[] = {"short hair", "bob", "long hair", "buzz cut"};
  person.description = std::string(sleeves[int(o.sleeve)]) + " " + pattern_name(shirt_pattern) +
                       " shirt, " + pattern_name(lower_pattern) + " " + lowers_txt[int(o.lower)] +
                       ", " + hair_txt[int(o.hair)] + (o.boots ? ", boots" : "");

  // Geometry twice with one topology: on the template (texture coordinates) and on the
  // shaped body (rest positions).
  MeshBuilder canonical(bt, bt.model.v_template);
  dress(canonical, bt, o);
  auto shaped_body = bt.model.v_template + torch::matmul(bt.model.shapedirs, person.shapes);
  MeshBuilder shaped(bt, shaped_body);
  dress(shaped, bt, o);

  const int64_t P = canonical.count(), Q = int64_t(canonical.faces.size() / 3);
  TORCH_CHECK(shaped.count() == P && int64_t(shaped.faces.size() / 3) == Q,
              "make_person: garment topology depends on the shape");
  RenderMesh& mesh = person.mesh;
  mesh.rest = torch::from_blob(shaped.positions.data(), {P, 3}, torch::kFloat64).clone();
  mesh.weights =
      torch::from_blob(shaped.weights.data(), {P, body::kNumJoints}, torch::kFloat64).clone();
  mesh.tex =
      torch::from_blob(canonical.positions.data(), {P, 3}, torch::kFloat64).to(torch::kFloat32);
  mesh.faces = torch::from_blob(canonical.faces.data(), {Q, 3}, torch::kInt64).clone();
  mesh.face_material = canonical.material;
  mesh.face_label = canonical.label;
  mesh.cull = torch::from_blob(canonical.cull.data(), {Q}, torch::kUInt8).to(torch::kBool);
  mesh.num_body_vertices = bt.model.num_vertices();

  // The hair shell is built crown-outwards; make its faces point away from the head centre
  // (decided on the template, applied to the shared topology).
  auto [h0, h1] = canonical.hair_faces;
  if (h1 > h0) {
    auto f = mesh.faces.slice(0, h0, h1);
    auto tex = mesh.tex.to(torch::kFloat64);
    auto a = tex.index_select(0, f.select(1, 0)), b = tex.index_select(0, f.select(1, 1)),
         c = tex.index_select(0, f.select(1, 2));
    auto n = torch::cross(b - a, c - a, 1);
    auto centre = torch::tensor(
        {bt.landmarks.head_center[0], bt.landmarks.head_center[1], bt.landmarks.head_center[2]},
        torch::kFloat64);
    auto inward = (n * ((a + b + c) / 3.0 - centre)).sum(1) < 0;
    auto swapped = f.index({torch::indexing::Slice(), torch::tensor({0, 2, 1})});
    f.copy_(torch::where(inward.unsqueeze(1), swapped, f));
  }
  return person;
}

}  // namespace th::synth
