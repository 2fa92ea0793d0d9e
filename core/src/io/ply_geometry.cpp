// Meshes, point clouds and Cyberware range grids on top of the generic PLY layer.
#include <algorithm>
#include <cmath>
#include <string>

#include "artisan/core/error.hpp"
#include "artisan/core/io/ply.hpp"

namespace artisan::io {

namespace {

[[noreturn]] void fail(const std::filesystem::path& source, const std::string& what) { throw FileError(source, what); }

const PlyElement& require_element(const PlyFile& ply, const std::string& name, const std::filesystem::path& source) {
  const auto* e = ply.find(name);
  if (!e) fail(source, "has no element \"" + name + "\"");
  return *e;
}

const PlyProperty& require_scalar(const PlyElement& e, const std::string& name, const std::filesystem::path& source) {
  const auto* p = e.find(name);
  if (!p) fail(source, "element " + e.name + " has no property \"" + name + "\"");
  if (p->is_list()) fail(source, "element " + e.name + " property \"" + name + "\" is a list, expected a scalar");
  return *p;
}

const PlyProperty* optional_scalar(const PlyElement& e, const std::string& name) {
  const auto* p = e.find(name);
  return p && !p->is_list() ? p : nullptr;
}

std::vector<Eigen::Vector3f> read_xyz(const PlyElement& vertex, const std::string& x, const std::string& y,
                                      const std::string& z, const std::filesystem::path& source, bool require_finite) {
  const auto& px = require_scalar(vertex, x, source);
  const auto& py = require_scalar(vertex, y, source);
  const auto& pz = require_scalar(vertex, z, source);
  std::vector<Eigen::Vector3f> out(vertex.count);
  for (size_t i = 0; i < vertex.count; ++i) {
    out[i] = Eigen::Vector3f(static_cast<float>(px.values[i]), static_cast<float>(py.values[i]), static_cast<float>(pz.values[i]));
    if (require_finite && !out[i].allFinite()) {
      fail(source, "vertex " + std::to_string(i) + " (" + x + " " + y + " " + z + ") = (" + std::to_string(px.values[i]) +
                       ", " + std::to_string(py.values[i]) + ", " + std::to_string(pz.values[i]) + ") is not finite");
    }
  }
  return out;
}

std::vector<Eigen::Vector3f> read_optional_normals(const PlyElement& vertex, const std::filesystem::path& source) {
  if (!optional_scalar(vertex, "nx") || !optional_scalar(vertex, "ny") || !optional_scalar(vertex, "nz")) return {};
  return read_xyz(vertex, "nx", "ny", "nz", source, true);
}

std::vector<Color3> read_optional_colors(const PlyElement& vertex) {
  const auto* r = optional_scalar(vertex, "red");
  const auto* g = optional_scalar(vertex, "green");
  const auto* b = optional_scalar(vertex, "blue");
  if (!r || !g || !b) return {};
  const bool unit = r->type == PlyType::kFloat32 || r->type == PlyType::kFloat64;
  auto to8 = [unit](double v) {
    const double x = unit ? v * 255.0 : v;
    return static_cast<uint8_t>(std::isfinite(x) ? std::clamp(std::lround(x), 0L, 255L) : 0);
  };
  std::vector<Color3> out(vertex.count);
  for (size_t i = 0; i < vertex.count; ++i) out[i] = Color3(to8(r->values[i]), to8(g->values[i]), to8(b->values[i]));
  return out;
}

PlyProperty scalar(const std::string& name, PlyType type, size_t reserve) {
  PlyProperty p;
  p.name = name;
  p.type = type;
  p.values.reserve(reserve);
  return p;
}

void add_xyz(PlyElement& e, const std::vector<Eigen::Vector3f>& v, const char* x, const char* y, const char* z) {
  auto px = scalar(x, PlyType::kFloat32, v.size()), py = scalar(y, PlyType::kFloat32, v.size()),
       pz = scalar(z, PlyType::kFloat32, v.size());
  for (const auto& p : v) {
    px.values.push_back(p.x());
    py.values.push_back(p.y());
    pz.values.push_back(p.z());
  }
  e.properties.push_back(std::move(px));
  e.properties.push_back(std::move(py));
  e.properties.push_back(std::move(pz));
}

void add_colors(PlyElement& e, const std::vector<Color3>& colors) {
  const char* names[] = {"red", "green", "blue"};
  for (int k = 0; k < 3; ++k) {
    auto p = scalar(names[k], PlyType::kUint8, colors.size());
    for (const auto& c : colors) p.values.push_back(c[k]);
    e.properties.push_back(std::move(p));
  }
}

int obj_info_int(const PlyFile& ply, const std::string& key, const std::filesystem::path& source) {
  for (const auto& [k, v] : ply.obj_info) {
    if (k != key) continue;
    try {
      size_t used = 0;
      const int n = std::stoi(v, &used);
      if (used == v.size() && n > 0) return n;
    } catch (const std::exception&) {
    }
    fail(source, "obj_info " + key + " \"" + v + "\" is not a positive integer");
  }
  fail(source, "has a range_grid but no obj_info " + key);
}

}  // namespace

bool ply_has_range_grid(const PlyFile& ply) { return ply.find("range_grid") != nullptr; }

RangeImage ply_to_range_image(const PlyFile& ply, const std::filesystem::path& source) {
  const int cols = obj_info_int(ply, "num_cols", source);
  const int rows = obj_info_int(ply, "num_rows", source);
  const auto& vertex = require_element(ply, "vertex", source);
  const auto& grid = require_element(ply, "range_grid", source);
  if (grid.count != static_cast<size_t>(cols) * rows) {
    fail(source, "range_grid has " + std::to_string(grid.count) + " cells, but num_cols x num_rows = " +
                     std::to_string(cols) + " x " + std::to_string(rows));
  }
  const PlyProperty* indices = grid.find("vertex_indices");
  if (!indices || !indices->is_list()) fail(source, "range_grid has no list property vertex_indices");
  const auto points = read_xyz(vertex, "x", "y", "z", source, true);

  RangeImage image = RangeImage::empty_of_size(cols, rows);
  std::vector<uint8_t> used(vertex.count, 0);
  size_t used_count = 0;
  for (size_t cell = 0; cell < grid.count; ++cell) {
    const uint32_t begin = indices->list_offsets[cell], end = indices->list_offsets[cell + 1];
    if (end == begin) continue;
    if (end - begin > 1) fail(source, "range_grid cell " + std::to_string(cell) + " lists " + std::to_string(end - begin) + " vertices; expected 0 or 1");
    const double vi = indices->values[begin];
    if (vi < 0 || vi >= static_cast<double>(vertex.count)) {
      fail(source, "range_grid cell " + std::to_string(cell) + " refers to vertex " + std::to_string(vi) + " of " + std::to_string(vertex.count));
    }
    const auto v = static_cast<size_t>(vi);
    if (used[v]) fail(source, "vertex " + std::to_string(v) + " appears in more than one range_grid cell");
    used[v] = 1;
    ++used_count;
    // Grid row 0 is the bottom scanline; image row 0 is the top.
    const int x = static_cast<int>(cell % cols);
    const int y = rows - 1 - static_cast<int>(cell / cols);
    image.points_sensor[image.index(x, y)] = points[v];
    image.valid[image.index(x, y)] = 1;
  }
  if (used_count != vertex.count) {
    fail(source, std::to_string(vertex.count - used_count) + " of " + std::to_string(vertex.count) + " vertices are not on the range grid");
  }
  bool cyberware = false;
  for (const auto& [k, v] : ply.obj_info) {
    image.sensor.attributes[k] = v;
    if (k == "is_cyberware_data" && v == "1") cyberware = true;
  }
  image.sensor.kind = cyberware ? "cyberware" : "ply-range-grid";
  return image;
}

TriangleMesh ply_to_mesh(const PlyFile& ply, const std::filesystem::path& source) {
  const auto& vertex = require_element(ply, "vertex", source);
  TriangleMesh mesh;
  mesh.vertices = read_xyz(vertex, "x", "y", "z", source, true);
  mesh.normals = read_optional_normals(vertex, source);
  mesh.colors = read_optional_colors(vertex);
  for (const auto& [u, v] : {std::pair{"u", "v"}, {"s", "t"}, {"texture_u", "texture_v"}}) {
    const auto* pu = optional_scalar(vertex, u);
    const auto* pv = optional_scalar(vertex, v);
    if (!pu || !pv) continue;
    mesh.uv.resize(vertex.count);
    for (size_t i = 0; i < vertex.count; ++i) mesh.uv[i] = Eigen::Vector2f(pu->values[i], pv->values[i]);
    break;
  }
  if (const auto* face = ply.find("face")) {
    const PlyProperty* idx = face->find("vertex_indices");
    if (!idx) idx = face->find("vertex_index");
    if (!idx || !idx->is_list()) fail(source, "element face has no list property vertex_indices");
    mesh.faces.reserve(face->count);
    for (size_t f = 0; f < face->count; ++f) {
      const uint32_t begin = idx->list_offsets[f], end = idx->list_offsets[f + 1];
      if (end - begin < 3) fail(source, "face " + std::to_string(f) + " has " + std::to_string(end - begin) + " vertices; at least 3 needed");
      for (uint32_t k = begin; k < end; ++k) {
        const double vi = idx->values[k];
        if (vi < 0 || vi >= static_cast<double>(vertex.count))
          fail(source, "face " + std::to_string(f) + " refers to vertex " + std::to_string(static_cast<long long>(vi)) + " of " + std::to_string(vertex.count));
      }
      for (uint32_t k = begin + 1; k + 1 < end; ++k)  // fan triangulation of polygons
        mesh.faces.emplace_back(static_cast<int>(idx->values[begin]), static_cast<int>(idx->values[k]), static_cast<int>(idx->values[k + 1]));
    }
  }
  return mesh;
}

PointCloud ply_to_point_cloud(const PlyFile& ply, const std::filesystem::path& source) {
  const auto& vertex = require_element(ply, "vertex", source);
  PointCloud cloud;
  cloud.points = read_xyz(vertex, "x", "y", "z", source, true);
  cloud.normals = read_optional_normals(vertex, source);
  cloud.colors = read_optional_colors(vertex);
  return cloud;
}

PlyFile range_image_to_ply(const RangeImage& image, PlyFormat format) {
  image.validate();
  PlyFile ply;
  ply.format = format;
  for (const auto& [k, v] : image.sensor.attributes) {
    if (k == "num_cols" || k == "num_rows" || k.empty() || k.find_first_of(" \t\r\n") != std::string::npos ||
        v.find_first_of("\r\n") != std::string::npos)
      continue;
    ply.obj_info.emplace_back(k, v);
  }
  ply.obj_info.emplace_back("num_cols", std::to_string(image.width));
  ply.obj_info.emplace_back("num_rows", std::to_string(image.height));
  // Vertices in grid order: bottom row first (see ply_to_range_image).
  std::vector<Eigen::Vector3f> points;
  points.reserve(image.valid_count());
  PlyElement grid{"range_grid", image.pixel_count(), {}};
  PlyProperty indices;
  indices.name = "vertex_indices";
  indices.type = PlyType::kInt32;
  indices.list_count_type = PlyType::kUint8;
  indices.list_offsets.reserve(image.pixel_count() + 1);
  indices.list_offsets.push_back(0);
  for (int y = image.height - 1; y >= 0; --y) {
    for (int x = 0; x < image.width; ++x) {
      const size_t i = image.index(x, y);
      if (image.valid[i]) {
        indices.values.push_back(static_cast<double>(points.size()));
        points.push_back(image.points_sensor[i]);
      }
      indices.list_offsets.push_back(static_cast<uint32_t>(indices.values.size()));
    }
  }
  PlyElement vertex{"vertex", points.size(), {}};
  add_xyz(vertex, points, "x", "y", "z");
  grid.properties.push_back(std::move(indices));
  ply.elements.push_back(std::move(vertex));
  ply.elements.push_back(std::move(grid));
  return ply;
}

PlyFile mesh_to_ply(const TriangleMesh& mesh, PlyFormat format) {
  mesh.validate();
  PlyFile ply;
  ply.format = format;
  PlyElement vertex{"vertex", mesh.vertices.size(), {}};
  add_xyz(vertex, mesh.vertices, "x", "y", "z");
  if (!mesh.normals.empty()) add_xyz(vertex, mesh.normals, "nx", "ny", "nz");
  if (!mesh.uv.empty()) {
    auto pu = scalar("u", PlyType::kFloat32, mesh.uv.size()), pv = scalar("v", PlyType::kFloat32, mesh.uv.size());
    for (const auto& t : mesh.uv) {
      pu.values.push_back(t.x());
      pv.values.push_back(t.y());
    }
    vertex.properties.push_back(std::move(pu));
    vertex.properties.push_back(std::move(pv));
  }
  if (!mesh.colors.empty()) add_colors(vertex, mesh.colors);
  ply.elements.push_back(std::move(vertex));
  PlyElement face{"face", mesh.faces.size(), {}};
  PlyProperty idx;
  idx.name = "vertex_indices";
  idx.type = PlyType::kInt32;
  idx.list_count_type = PlyType::kUint8;
  idx.values.reserve(mesh.faces.size() * 3);
  idx.list_offsets.reserve(mesh.faces.size() + 1);
  idx.list_offsets.push_back(0);
  for (const auto& f : mesh.faces) {
    for (int k = 0; k < 3; ++k) idx.values.push_back(f[k]);
    idx.list_offsets.push_back(static_cast<uint32_t>(idx.values.size()));
  }
  face.properties.push_back(std::move(idx));
  ply.elements.push_back(std::move(face));
  return ply;
}

PlyFile point_cloud_to_ply(const PointCloud& cloud, PlyFormat format) {
  cloud.validate();
  PlyFile ply;
  ply.format = format;
  PlyElement vertex{"vertex", cloud.points.size(), {}};
  add_xyz(vertex, cloud.points, "x", "y", "z");
  if (!cloud.normals.empty()) add_xyz(vertex, cloud.normals, "nx", "ny", "nz");
  if (!cloud.colors.empty()) add_colors(vertex, cloud.colors);
  ply.elements.push_back(std::move(vertex));
  return ply;
}

}  // namespace artisan::io
