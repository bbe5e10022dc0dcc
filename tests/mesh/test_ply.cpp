// Binary PLY writer and reader (METHOD 7 meshes).

#include <torch/torch.h>

#include <catch2/catch.hpp>
#include <fstream>
#include <iterator>

#include "core/error.hpp"
#include "mesh/ply.hpp"
#include "support/test_env.hpp"

namespace {

th::mesh::TriMesh tetrahedron(bool colored) {
  th::mesh::TriMesh m;
  m.verts = torch::tensor({0.f, 0.f, 0.f, 1.5f, 0.f, 0.f, 0.f, -2.25f, 0.f, 0.f, 0.f, 1e-7f})
                .reshape({4, 3});
  m.faces = torch::tensor({0, 2, 1, 0, 1, 3, 1, 2, 3, 0, 3, 2}, torch::kInt64).reshape({4, 3});
  if (colored)
    m.colors =
        torch::tensor({255, 0, 0, 0, 255, 0, 0, 0, 255, 7, 8, 9}, torch::kUInt8).reshape({4, 3});
  return m;
}

std::string slurp(const std::filesystem::path& p) {
  std::ifstream in(p, std::ios::binary);
  return {std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>()};
}

}  // namespace

TEST_CASE("PLY round trip with and without vertex colours", "[mesh][ply]") {
  const auto dir = th::test::scratch_dir("mesh_ply");
  for (bool colored : {false, true}) {
    const auto m = tetrahedron(colored);
    const auto path = dir / (colored ? "color.ply" : "plain.ply");
    th::mesh::write_ply(path, m);
    const auto back = th::mesh::read_ply(path);
    CHECK(torch::equal(back.verts, m.verts));
    CHECK(torch::equal(back.faces, m.faces));
    CHECK(back.colors.defined() == colored);
    if (colored) CHECK(torch::equal(back.colors, m.colors));

    // The layout, computed by hand: header text, then 12 (+3) bytes per vertex and
    // 1 + 3 * 4 bytes per face.
    const std::string bytes = slurp(path);
    const std::string header =
        std::string(
            "ply\nformat binary_little_endian 1.0\n"
            "comment TransHuman-C++ marching cubes (METHOD 7)\n"
            "element vertex 4\nproperty float x\nproperty float y\nproperty float z\n") +
        (colored ? "property uchar red\nproperty uchar green\nproperty uchar blue\n" : "") +
        "element face 4\nproperty list uchar int vertex_indices\nend_header\n";
    CHECK(bytes.substr(0, header.size()) == header);
    CHECK(bytes.size() == header.size() + 4 * (colored ? 15 : 12) + 4 * 13);
    // Face 1 = (0, 1, 3): count byte 3 then little-endian int32s.
    const size_t face1 = header.size() + 4 * (colored ? 15 : 12) + 13;
    CHECK(bytes.substr(face1, 13) == std::string("\x03\0\0\0\0\x01\0\0\0\x03\0\0\0", 13));
  }
}

TEST_CASE("PLY reader: clear errors for ASCII, truncated and foreign files", "[mesh][ply]") {
  const auto dir = th::test::scratch_dir("mesh_ply_errors");
  const auto good = dir / "good.ply";
  th::mesh::write_ply(good, tetrahedron(true));
  const std::string bytes = slurp(good);

  const auto truncated = dir / "truncated.ply";
  std::ofstream(truncated, std::ios::binary) << bytes.substr(0, bytes.size() - 5);
  CHECK_THROWS_WITH(th::mesh::read_ply(truncated),
                    Catch::Contains("truncated.ply") && Catch::Contains("truncated"));

  const auto ascii = dir / "ascii.ply";
  std::ofstream(ascii) << "ply\nformat ascii 1.0\nelement vertex 0\nend_header\n";
  CHECK_THROWS_WITH(th::mesh::read_ply(ascii), Catch::Contains("ascii"));

  const auto other = dir / "other.ply";
  std::ofstream(other) << "solid cube\n";
  CHECK_THROWS_AS(th::mesh::read_ply(other), th::Error);
  CHECK_THROWS_AS(th::mesh::read_ply(dir / "missing.ply"), th::Error);
}

TEST_CASE("PLY writer: empty meshes and unwritable paths", "[mesh][ply]") {
  const auto dir = th::test::scratch_dir("mesh_ply_empty");
  th::mesh::TriMesh empty{torch::zeros({0, 3}), torch::zeros({0, 3}, torch::kInt64), {}};
  th::mesh::write_ply(dir / "empty.ply", empty);
  const auto back = th::mesh::read_ply(dir / "empty.ply");
  CHECK(back.num_verts() == 0);
  CHECK(back.num_faces() == 0);
  CHECK_THROWS_WITH(th::mesh::write_ply(dir / "no" / "such" / "dir.ply", empty),
                    Catch::Contains("dir.ply"));
}
