// Payload (version 1): u64 n_vertices, u64 n_faces, u8 has_normals, u8 has_uv, u8 has_colors,
// then vertices (3 f32 each), normals, uv (2 f32), colours (3 u8), faces (3 i32), and the
// texture image (i32 w, h, channels + pixels).
#include "artisan/core/io/mesh_format.hpp"

#include "artisan/core/error.hpp"
#include "artisan/core/io/blob_container.hpp"
#include "artisan/core/io/bytes.hpp"
#include "binary_fields.hpp"

namespace artisan::io {

namespace {
constexpr BlobMagic kMagic = {'A', 'R', 'T', 'I', 'S', 'M', 'S', '\x1a'};
}

std::vector<uint8_t> encode_mesh(const TriangleMesh& mesh, bool compress) {
  mesh.validate();
  ByteWriter w;
  w.put<uint64_t>(mesh.vertices.size());
  w.put<uint64_t>(mesh.faces.size());
  w.put<uint8_t>(!mesh.normals.empty());
  w.put<uint8_t>(!mesh.uv.empty());
  w.put<uint8_t>(!mesh.colors.empty());
  w.put_array(reinterpret_cast<const float*>(mesh.vertices.data()), mesh.vertices.size() * 3);
  if (!mesh.normals.empty()) w.put_array(reinterpret_cast<const float*>(mesh.normals.data()), mesh.normals.size() * 3);
  if (!mesh.uv.empty()) w.put_array(reinterpret_cast<const float*>(mesh.uv.data()), mesh.uv.size() * 2);
  if (!mesh.colors.empty()) w.put_array(reinterpret_cast<const uint8_t*>(mesh.colors.data()), mesh.colors.size() * 3);
  w.put_array(reinterpret_cast<const int*>(mesh.faces.data()), mesh.faces.size() * 3);
  detail::put_image(w, mesh.texture);
  return seal_blob(kMagic, kMeshFormatVersion, w.bytes(), compress);
}

TriangleMesh decode_mesh(std::span<const uint8_t> bytes, const std::string& source) {
  const auto raw = open_blob(bytes, kMagic, kMeshFormatVersion, "mesh", source);
  ByteReader r(raw, source);
  const auto nv = r.get<uint64_t>("vertex count");
  const auto nf = r.get<uint64_t>("face count");
  if (nv > r.remaining() / 12 || nf > r.remaining() / 12)
    r.fail("counts", std::to_string(nv) + " vertices and " + std::to_string(nf) + " faces do not fit the payload");
  const bool has_normals = r.get<uint8_t>("has_normals");
  const bool has_uv = r.get<uint8_t>("has_uv");
  const bool has_colors = r.get<uint8_t>("has_colors");
  TriangleMesh mesh;
  mesh.vertices.resize(nv);
  r.get_array(reinterpret_cast<float*>(mesh.vertices.data()), nv * 3, "vertices");
  if (has_normals) {
    mesh.normals.resize(nv);
    r.get_array(reinterpret_cast<float*>(mesh.normals.data()), nv * 3, "normals");
  }
  if (has_uv) {
    mesh.uv.resize(nv);
    r.get_array(reinterpret_cast<float*>(mesh.uv.data()), nv * 2, "uv");
  }
  if (has_colors) {
    mesh.colors.resize(nv);
    r.get_array(reinterpret_cast<uint8_t*>(mesh.colors.data()), nv * 3, "colours");
  }
  mesh.faces.resize(nf);
  r.get_array(reinterpret_cast<int*>(mesh.faces.data()), nf * 3, "faces");
  mesh.texture = detail::get_image(r);
  if (r.remaining() != 0) r.fail("payload", std::to_string(r.remaining()) + " unexpected bytes at the end");
  try {
    mesh.validate();
  } catch (const Error& e) {
    throw Error(source + ": " + e.what());
  }
  return mesh;
}

}  // namespace artisan::io
