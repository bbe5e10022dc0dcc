#pragma once
// Binary PLY files for the reconstructed meshes (METHOD 7): what MeshLab, Blender and Open3D read.
//
// Written layout (binary_little_endian 1.0):
//   element vertex V: property float x, y, z [, property uchar red, green, blue]
//   element face F:   property list uchar int vertex_indices   (always 3 per face)

#include <filesystem>
#include <string>

#include "mesh/tri_mesh.hpp"

namespace th::mesh {

// mesh: verts (V, 3) float32, faces (F, 3) int64 (< 2^31), colors (V, 3) uint8 or undefined.
// Written atomically (temporary file + rename). Throws th::Error naming the path if it cannot
// be written. `comment` goes into the header (one line).
void write_ply(const std::filesystem::path& path, const TriMesh& mesh,
               const std::string& comment = "TransHuman-C++ marching cubes (METHOD 7)");

// Reads binary little-endian PLYs: a vertex element with x, y, z (float or double) and
// optionally red, green, blue (uchar), other scalar properties skipped; a face element with a
// list property vertex_indices (or vertex_index) of any integer types; polygons are fanned
// into triangles; other elements are skipped. Throws th::Error naming the file and what is
// wrong for anything else (ASCII, truncated, missing x/y/z). Returns colors only if present.
TriMesh read_ply(const std::filesystem::path& path);

}  // namespace th::mesh
