#pragma once
// A synthetic person: body shape, clothes, hair and textures, and the render mesh that is
// skinned with the body model each frame. The clothes stand off the body (loose shirts, a
// skirt, hair volume), so the fitted body published in new_vertices is not the rendered
// surface, as with real captures.

#include <torch/types.h>

#include <cstdint>
#include <string>
#include <vector>

#include "synth/body_builder.hpp"
#include "synth/random.hpp"
#include "synth/texture.hpp"

namespace th::synth {

// Render mesh in the rest pose of one person (SMPL frame); posed with body::skin_points. The
// body's vertices come first; body faces hidden under clothes are left out.
struct RenderMesh {
  torch::Tensor rest;     // (P, 3) float64 rest positions with the person's shape
  torch::Tensor weights;  // (P, 24) float64 skinning weights
  torch::Tensor tex;      // (P, 3) float32 canonical (template-space) texture coordinates
  torch::Tensor faces;    // (Q, 3) int64
  std::vector<uint8_t> face_material;  // (Q) index into Person::materials
  std::vector<uint8_t> face_label;     // (Q) CIHP part label written to mask_cihp
  torch::Tensor cull;                  // (Q) bool: faces of closed surfaces (back faces hidden)
  int64_t num_body_vertices = 0;       // the first vertices are the body model's own
};

// How the person's folder is laid out (METHOD 1.1).
enum class FolderStyle {
  Standard,    // Camera_B{n}/{frame:06d}.jpg, new_params/, new_vertices/, 23 cameras
  Original21,  // CoreView_313/315: "Camera (k)" folders, long original names, 21 cameras
  Params396,   // CoreView_396: params/ and vertices/ instead of new_params/, new_vertices/
};
// Which masks exist: mask/ only, mask_cihp/ only, or both with different coverage.
enum class MaskStyle { Mask, Cihp, Both };

struct Person {
  std::string name;
  int index = 0;
  bool unseen = false;
  FolderStyle folders = FolderStyle::Standard;
  MaskStyle masks = MaskStyle::Mask;
  torch::Tensor shapes;     // (10) float64, the true shape coefficients
  std::string description;  // one line: outfit and hair, for the summary
  std::vector<Material> materials;
  RenderMesh mesh;
};

// CIHP labels used in mask_cihp (the LIP/CIHP 20-class convention).
namespace cihp {
constexpr uint8_t kHair = 2, kUpper = 5, kPants = 9, kTorsoSkin = 10, kSkirt = 12, kFace = 13,
                  kLeftArm = 14, kRightArm = 15, kLeftLeg = 16, kRightLeg = 17, kLeftShoe = 18,
                  kRightShoe = 19;
}

// Draws shape, outfit and colours for person `index` from `rng` and builds the render mesh.
// Categorical choices (pattern, sleeves, lower garment, hair) cycle with style_offset + index,
// so that consecutive people differ. The template's landmarks must outlive the person
// (materials point to them).
Person make_person(const BodyTemplate& body, const std::string& name, int index, bool unseen,
                   double shape_std, uint64_t style_offset, Rng& rng);

}  // namespace th::synth
