#include "mesh/ply.hpp"

#include <torch/torch.h>

#include <cstring>
#include <sstream>
#include <vector>

#include "core/error.hpp"
#include "io/files.hpp"

namespace th::mesh {
namespace {

template <class T>
void append(std::string& out, T value) {
  char bytes[sizeof(T)];
  std::memcpy(bytes, &value, sizeof(T));  // little-endian host (io/bytes.hpp asserts it)
  out.append(bytes, sizeof(T));
}

// PLY scalar types: size in bytes and reading as double (enough for indices < 2^53).
int type_size(const std::string& type) {
  if (type == "char" || type == "uchar" || type == "int8" || type == "uint8") return 1;
  if (type == "short" || type == "ushort" || type == "int16" || type == "uint16") return 2;
  if (type == "int" || type == "uint" || type == "float" || type == "int32" || type == "uint32" ||
      type == "float32")
    return 4;
  if (type == "double" || type == "float64") return 8;
  return 0;
}

double load(const char* p, const std::string& type) {
  auto get = [p](auto v) {
    std::memcpy(&v, p, sizeof(v));
    return static_cast<double>(v);
  };
  if (type == "char" || type == "int8") return get(int8_t{});
  if (type == "uchar" || type == "uint8") return get(uint8_t{});
  if (type == "short" || type == "int16") return get(int16_t{});
  if (type == "ushort" || type == "uint16") return get(uint16_t{});
  if (type == "int" || type == "int32") return get(int32_t{});
  if (type == "uint" || type == "uint32") return get(uint32_t{});
  if (type == "float" || type == "float32") return get(float{});
  return get(double{});
}

struct Property {
  std::string name, type;  // scalar type, or item type of a list
  std::string count_type;  // non-empty for lists
};
struct Element {
  std::string name;
  int64_t count = 0;
  std::vector<Property> properties;
};

}  // namespace

void write_ply(const std::filesystem::path& path, const TriMesh& mesh, const std::string& comment) {
  check_mesh(mesh, "write_ply");
  const int64_t nv = mesh.num_verts(), nf = mesh.num_faces();
  TORCH_CHECK(nv < (int64_t(1) << 31), "write_ply: too many vertices for int32 indices: ", nv);
  const bool colored = mesh.colors.defined();

  std::ostringstream header;
  header << "ply\nformat binary_little_endian 1.0\n";
  if (!comment.empty()) header << "comment " << comment << "\n";
  header << "element vertex " << nv << "\nproperty float x\nproperty float y\nproperty float z\n";
  if (colored) header << "property uchar red\nproperty uchar green\nproperty uchar blue\n";
  header << "element face " << nf << "\nproperty list uchar int vertex_indices\nend_header\n";

  std::string out = header.str();
  out.reserve(out.size() + nv * (12 + (colored ? 3 : 0)) + nf * 13);
  auto v = mesh.verts.contiguous();
  const float* vp = v.data_ptr<float>();
  torch::Tensor c = colored ? mesh.colors.contiguous() : torch::Tensor();
  const uint8_t* cp = colored ? c.data_ptr<uint8_t>() : nullptr;
  for (int64_t i = 0; i < nv; ++i) {
    out.append(reinterpret_cast<const char*>(vp + 3 * i), 12);
    if (colored) out.append(reinterpret_cast<const char*>(cp + 3 * i), 3);
  }
  auto f = mesh.faces.contiguous();
  const int64_t* fp = f.data_ptr<int64_t>();
  for (int64_t i = 0; i < nf; ++i) {
    append<uint8_t>(out, 3);
    for (int k = 0; k < 3; ++k) append<int32_t>(out, static_cast<int32_t>(fp[3 * i + k]));
  }
  io::write_file_atomic(path, out);
}

TriMesh read_ply(const std::filesystem::path& path) {
  const std::string bytes = io::read_file(path);
  const std::string name = path.string();
  const size_t end = bytes.find("end_header\n");
  if (bytes.rfind("ply\n", 0) != 0 || end == std::string::npos)
    fail("'", name, "' is not a PLY file (no 'ply' ... 'end_header' header)");

  std::vector<Element> elements;
  std::istringstream header(bytes.substr(0, end));
  std::string line;
  while (std::getline(header, line)) {
    std::istringstream words(line);
    std::string key;
    words >> key;
    if (key == "format") {
      std::string format;
      words >> format;
      if (format != "binary_little_endian")
        fail("'", name, "': PLY format '", format, "' not supported (binary_little_endian only)");
    } else if (key == "element") {
      Element e;
      words >> e.name >> e.count;
      if (!words || e.count < 0) fail("'", name, "': bad PLY element line '", line, "'");
      elements.push_back(e);
    } else if (key == "property") {
      if (elements.empty()) fail("'", name, "': PLY property before any element");
      Property p;
      std::string type;
      words >> type;
      if (type == "list")
        words >> p.count_type >> p.type >> p.name;
      else
        p.type = type, words >> p.name;
      if (!words || type_size(p.type) == 0 ||
          (!p.count_type.empty() && type_size(p.count_type) == 0))
        fail("'", name, "': bad PLY property line '", line, "'");
      elements.back().properties.push_back(p);
    }
  }

  TriMesh mesh;
  std::vector<float> verts;
  std::vector<uint8_t> colors;
  std::vector<int64_t> faces;
  bool have_colors = false, have_verts = false;
  size_t pos = end + std::string("end_header\n").size();
  auto need = [&](size_t n, const Element& e, int64_t row) {
    if (pos + n > bytes.size())
      fail("'", name, "' is truncated in element '", e.name, "' row ", row, " (offset ", pos, ")");
  };
  for (const Element& e : elements) {
    const bool is_vertex = e.name == "vertex", is_face = e.name == "face";
    int xyz[3] = {-1, -1, -1}, rgb[3] = {-1, -1, -1}, index_list = -1;
    static const char* const xyz_names[3] = {"x", "y", "z"};
    static const char* const rgb_names[3] = {"red", "green", "blue"};
    for (size_t k = 0; k < e.properties.size(); ++k) {
      const std::string& n = e.properties[k].name;
      const bool scalar = e.properties[k].count_type.empty();
      for (int a = 0; a < 3; ++a) {
        if (scalar && n == xyz_names[a]) xyz[a] = int(k);
        if (scalar && n == rgb_names[a]) rgb[a] = int(k);
      }
      if ((n == "vertex_indices" || n == "vertex_index") && !e.properties[k].count_type.empty())
        index_list = int(k);
    }
    if (is_vertex) {
      if (xyz[0] < 0 || xyz[1] < 0 || xyz[2] < 0)
        fail("'", name, "': PLY vertex element without x, y, z");
      have_verts = true;
      have_colors = rgb[0] >= 0 && rgb[1] >= 0 && rgb[2] >= 0;
    }
    if (is_face && index_list < 0) fail("'", name, "': PLY face element without vertex_indices");
    std::vector<double> row_values(e.properties.size());
    std::vector<int64_t> polygon;
    for (int64_t row = 0; row < e.count; ++row) {
      for (size_t k = 0; k < e.properties.size(); ++k) {
        const Property& p = e.properties[k];
        if (p.count_type.empty()) {
          need(type_size(p.type), e, row);
          row_values[k] = load(&bytes[pos], p.type);
          pos += type_size(p.type);
          continue;
        }
        need(type_size(p.count_type), e, row);
        const auto n = static_cast<int64_t>(load(&bytes[pos], p.count_type));
        pos += type_size(p.count_type);
        need(size_t(n) * type_size(p.type), e, row);
        polygon.clear();
        for (int64_t q = 0; q < n; ++q, pos += type_size(p.type))
          polygon.push_back(static_cast<int64_t>(load(&bytes[pos], p.type)));
        if (is_face && int(k) == index_list) {
          if (n < 3) fail("'", name, "': PLY face ", row, " has ", n, " vertices");
          for (int64_t q = 1; q + 1 < n; ++q)
            faces.insert(faces.end(), {polygon[0], polygon[q], polygon[q + 1]});
        }
      }
      if (is_vertex) {
        for (int a = 0; a < 3; ++a) verts.push_back(static_cast<float>(row_values[xyz[a]]));
        if (have_colors)
          for (int a = 0; a < 3; ++a) colors.push_back(static_cast<uint8_t>(row_values[rgb[a]]));
      }
    }
  }
  if (!have_verts) fail("'", name, "': PLY file without a vertex element");

  const auto nv = static_cast<int64_t>(verts.size() / 3);
  mesh.verts = torch::from_blob(verts.data(), {nv, 3}, torch::kFloat32).clone();
  mesh.faces =
      torch::from_blob(faces.data(), {int64_t(faces.size() / 3), 3}, torch::kInt64).clone();
  if (have_colors) mesh.colors = torch::from_blob(colors.data(), {nv, 3}, torch::kUInt8).clone();
  for (int64_t idx : faces)
    if (idx < 0 || idx >= nv) fail("'", name, "': PLY face index ", idx, " out of range");
  return mesh;
}

}  // namespace th::mesh
