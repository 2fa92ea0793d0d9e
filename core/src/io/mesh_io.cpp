// Mesh files: PLY through the project's reader, everything else through assimp.
#include "artisan/core/io/mesh_io.hpp"

#include <assimp/Exporter.hpp>
#include <assimp/Importer.hpp>
#include <assimp/config.h>
#include <assimp/postprocess.h>
#include <assimp/scene.h>

#include <algorithm>
#include <charconv>
#include <cmath>

#include "artisan/core/error.hpp"
#include "artisan/core/io/atomic_file.hpp"
#include "artisan/core/io/bytes.hpp"
#include "artisan/core/io/ply.hpp"

namespace artisan::io {

namespace {

void collect(const aiScene& scene, const aiNode& node, const aiMatrix4x4& parent, TriangleMesh& out,
             const std::filesystem::path& path) {
  const aiMatrix4x4 T = parent * node.mTransformation;
  aiMatrix3x3 R(T);
  R.Inverse().Transpose();  // normals transform with the inverse transpose
  for (unsigned m = 0; m < node.mNumMeshes; ++m) {
    const aiMesh& mesh = *scene.mMeshes[node.mMeshes[m]];
    if (!(mesh.mPrimitiveTypes & aiPrimitiveType_TRIANGLE)) continue;
    TriangleMesh part;
    part.vertices.reserve(mesh.mNumVertices);
    for (unsigned i = 0; i < mesh.mNumVertices; ++i) {
      const aiVector3D v = T * mesh.mVertices[i];
      part.vertices.emplace_back(v.x, v.y, v.z);
    }
    if (mesh.HasNormals()) {
      for (unsigned i = 0; i < mesh.mNumVertices; ++i) {
        aiVector3D n = R * mesh.mNormals[i];
        const float len = n.Length();
        if (len > 0) n /= len;
        part.normals.emplace_back(n.x, n.y, n.z);
      }
    }
    if (mesh.HasTextureCoords(0)) {
      // assimp's v points up (OpenGL); ours has its origin at the top-left.
      for (unsigned i = 0; i < mesh.mNumVertices; ++i)
        part.uv.emplace_back(mesh.mTextureCoords[0][i].x, 1.0f - mesh.mTextureCoords[0][i].y);
    }
    auto to8 = [](float c) { return static_cast<uint8_t>(std::clamp(std::lround(c * 255.0f), 0L, 255L)); };
    if (mesh.HasVertexColors(0)) {
      for (unsigned i = 0; i < mesh.mNumVertices; ++i) {
        const aiColor4D& c = mesh.mColors[0][i];
        part.colors.emplace_back(to8(c.r), to8(c.g), to8(c.b));
      }
    } else if (mesh.mMaterialIndex < scene.mNumMaterials &&
               scene.mMaterials[mesh.mMaterialIndex]->GetName() != aiString(AI_DEFAULT_MATERIAL_NAME)) {
      aiColor4D diffuse;
      if (scene.mMaterials[mesh.mMaterialIndex]->Get(AI_MATKEY_COLOR_DIFFUSE, diffuse) == AI_SUCCESS)
        part.colors.assign(mesh.mNumVertices, Color3(to8(diffuse.r), to8(diffuse.g), to8(diffuse.b)));
    }
    for (unsigned f = 0; f < mesh.mNumFaces; ++f) {
      const aiFace& face = mesh.mFaces[f];
      if (face.mNumIndices != 3) continue;  // points and lines left by the triangulation
      for (unsigned k = 0; k < 3; ++k)
        if (face.mIndices[k] >= mesh.mNumVertices) throw FileError(path, "face refers to a vertex out of range");
      part.faces.emplace_back(face.mIndices[0], face.mIndices[1], face.mIndices[2]);
    }
    out.append(part);
  }
  for (unsigned c = 0; c < node.mNumChildren; ++c) collect(scene, *node.mChildren[c], T, out, path);
}

std::string obj_text(const TriangleMesh& mesh) {
  std::string s = "# written by Artisan\n";
  char buf[64];
  auto num = [&](float v) {
    s += ' ';
    s.append(buf, std::to_chars(buf, buf + sizeof buf, v).ptr);
  };
  for (size_t i = 0; i < mesh.vertices.size(); ++i) {
    s += 'v';
    for (int k = 0; k < 3; ++k) num(mesh.vertices[i][k]);
    if (!mesh.colors.empty())
      for (int k = 0; k < 3; ++k) num(mesh.colors[i][k] / 255.0f);
    s += '\n';
  }
  for (const auto& n : mesh.normals) {
    s += "vn";
    for (int k = 0; k < 3; ++k) num(n[k]);
    s += '\n';
  }
  for (const auto& t : mesh.uv) {
    s += "vt";
    num(t.x());
    num(1.0f - t.y());  // OBJ's v points up
    s += '\n';
  }
  const bool has_n = !mesh.normals.empty(), has_t = !mesh.uv.empty();
  for (const auto& f : mesh.faces) {
    s += 'f';
    for (int k = 0; k < 3; ++k) {
      const std::string i = std::to_string(f[k] + 1);
      s += ' ' + i;
      if (has_t || has_n) s += '/' + (has_t ? i : std::string());
      if (has_n) s += '/' + i;
    }
    s += '\n';
  }
  return s;
}

aiMesh* to_ai_mesh(const TriangleMesh& mesh, unsigned material) {
  auto* out = new aiMesh();
  aiMesh& m = *out;
  m.mPrimitiveTypes = aiPrimitiveType_TRIANGLE;
  m.mMaterialIndex = material;
  m.mNumVertices = static_cast<unsigned>(mesh.vertices.size());
  m.mVertices = new aiVector3D[m.mNumVertices];
  for (unsigned i = 0; i < m.mNumVertices; ++i) m.mVertices[i] = aiVector3D(mesh.vertices[i].x(), mesh.vertices[i].y(), mesh.vertices[i].z());
  if (!mesh.normals.empty()) {
    m.mNormals = new aiVector3D[m.mNumVertices];
    for (unsigned i = 0; i < m.mNumVertices; ++i) m.mNormals[i] = aiVector3D(mesh.normals[i].x(), mesh.normals[i].y(), mesh.normals[i].z());
  }
  if (!mesh.uv.empty()) {
    m.mTextureCoords[0] = new aiVector3D[m.mNumVertices];
    m.mNumUVComponents[0] = 2;
    for (unsigned i = 0; i < m.mNumVertices; ++i) m.mTextureCoords[0][i] = aiVector3D(mesh.uv[i].x(), 1.0f - mesh.uv[i].y(), 0);
  }
  if (!mesh.colors.empty()) {
    m.mColors[0] = new aiColor4D[m.mNumVertices];
    for (unsigned i = 0; i < m.mNumVertices; ++i)
      m.mColors[0][i] = aiColor4D(mesh.colors[i][0] / 255.0f, mesh.colors[i][1] / 255.0f, mesh.colors[i][2] / 255.0f, 1.0f);
  }
  m.mNumFaces = static_cast<unsigned>(mesh.faces.size());
  m.mFaces = new aiFace[m.mNumFaces];
  for (unsigned f = 0; f < m.mNumFaces; ++f) {
    m.mFaces[f].mNumIndices = 3;
    m.mFaces[f].mIndices = new unsigned[3]{static_cast<unsigned>(mesh.faces[f][0]), static_cast<unsigned>(mesh.faces[f][1]),
                                           static_cast<unsigned>(mesh.faces[f][2])};
  }
  return out;
}

void write_gltf(const std::vector<SceneNode>& nodes, const std::filesystem::path& path, bool binary) {
  // aiScene owns (and deletes) everything attached to it.
  aiScene scene;
  const auto n = static_cast<unsigned>(nodes.size());
  scene.mRootNode = new aiNode("root");
  scene.mNumMaterials = 1;
  scene.mMaterials = new aiMaterial*[1]{new aiMaterial()};
  scene.mNumMeshes = n;
  scene.mMeshes = new aiMesh*[n];
  scene.mRootNode->mNumChildren = n;
  scene.mRootNode->mChildren = new aiNode*[n];
  for (unsigned k = 0; k < n; ++k) {
    scene.mMeshes[k] = to_ai_mesh(*nodes[k].mesh, 0);
    scene.mMeshes[k]->mName = nodes[k].name;
    auto* node = new aiNode(nodes[k].name);
    node->mParent = scene.mRootNode;
    node->mNumMeshes = 1;
    node->mMeshes = new unsigned[1]{k};
    const Eigen::Matrix4d T = nodes[k].T_parent_node.matrix();
    node->mTransformation = aiMatrix4x4(float(T(0, 0)), float(T(0, 1)), float(T(0, 2)), float(T(0, 3)), float(T(1, 0)), float(T(1, 1)),
                                        float(T(1, 2)), float(T(1, 3)), float(T(2, 0)), float(T(2, 1)), float(T(2, 2)), float(T(2, 3)), 0.f,
                                        0.f, 0.f, 1.f);
    scene.mRootNode->mChildren[k] = node;
  }
  Assimp::Exporter exporter;
  if (binary) {
    const aiExportDataBlob* blob = exporter.ExportToBlob(&scene, "glb2");
    if (!blob) throw FileError(path, std::string("glTF export failed: ") + exporter.GetErrorString());
    write_file_atomically(path, std::span(static_cast<const uint8_t*>(blob->data), blob->size));
    return;
  }
  // .gltf is JSON plus a "<stem>.bin" buffer beside it: export both into a private folder
  // beside the destination, then move them into place.
  const auto dir = path.has_parent_path() ? path.parent_path() : std::filesystem::path(".");
  const auto tmp = dir / ("." + path.filename().string() + ".export");
  std::error_code ec;
  std::filesystem::remove_all(tmp, ec);
  if (!std::filesystem::create_directory(tmp, ec)) throw FileError(path, "cannot create a temporary folder beside it");
  const auto staged = tmp / path.filename();
  if (exporter.Export(&scene, "gltf2", staged.string()) != AI_SUCCESS) {
    std::filesystem::remove_all(tmp, ec);
    throw FileError(path, std::string("glTF export failed: ") + exporter.GetErrorString());
  }
  for (const auto& entry : std::filesystem::directory_iterator(tmp)) {
    std::filesystem::rename(entry.path(), dir / entry.path().filename(), ec);
    if (ec) {
      std::filesystem::remove_all(tmp, ec);
      throw FileError(path, "cannot move the exported files into place");
    }
  }
  std::filesystem::remove_all(tmp, ec);
}

}  // namespace

TriangleMesh read_mesh(const std::filesystem::path& path) {
  std::error_code ec;
  if (!std::filesystem::is_regular_file(path, ec)) throw FileError(path, "no such file");
  if (std::filesystem::file_size(path, ec) == 0) throw FileError(path, "empty file");
  TriangleMesh mesh;
  if (lower_extension(path) == ".ply") {
    mesh = ply_to_mesh(read_ply(path), path);
  } else {
    Assimp::Importer importer;
    importer.SetPropertyBool(AI_CONFIG_IMPORT_COLLADA_IGNORE_UP_DIRECTION, true);
    importer.SetPropertyInteger(AI_CONFIG_PP_SBP_REMOVE, aiPrimitiveType_POINT | aiPrimitiveType_LINE);
    const aiScene* scene = importer.ReadFile(path.string(), aiProcess_Triangulate | aiProcess_JoinIdenticalVertices |
                                                                aiProcess_SortByPType | aiProcess_ValidateDataStructure);
    if (!scene || !scene->mRootNode) throw FileError(path, std::string("cannot read mesh: ") + importer.GetErrorString());
    collect(*scene, *scene->mRootNode, aiMatrix4x4(), mesh, path);
  }
  if (mesh.faces.empty()) throw FileError(path, "holds no triangles");
  try {
    mesh.validate();
  } catch (const Error& e) {
    throw FileError(path, e.what());
  }
  return mesh;
}

void write_mesh(const TriangleMesh& mesh, const std::filesystem::path& path) {
  try {
    mesh.validate();
  } catch (const Error& e) {
    throw FileError(path, std::string("cannot write an invalid mesh: ") + e.what());
  }
  const auto ext = lower_extension(path);
  if (ext == ".ply") {
    write_ply(mesh_to_ply(mesh, PlyFormat::kBinaryLittleEndian), path);
  } else if (ext == ".obj") {
    const auto text = obj_text(mesh);
    write_file_atomically(path, std::span(reinterpret_cast<const uint8_t*>(text.data()), text.size()));
  } else if (ext == ".gltf" || ext == ".glb") {
    write_gltf({{"mesh", &mesh, Transform::Identity()}}, path, ext == ".glb");
  } else if (ext == ".stl") {
    // Binary STL: 80-byte header, triangle count, then normal, 3 vertices and 2 spare bytes each.
    ByteWriter w;
    std::string header = "artisan binary STL";
    header.resize(80, ' ');
    w.put_bytes(std::span(reinterpret_cast<const uint8_t*>(header.data()), header.size()));
    w.put<uint32_t>(static_cast<uint32_t>(mesh.faces.size()));
    for (const auto& f : mesh.faces) {
      const Eigen::Vector3f a = mesh.vertices[f[0]], b = mesh.vertices[f[1]], c = mesh.vertices[f[2]];
      const Eigen::Vector3f n = (b - a).cross(c - a).normalized();
      for (const Eigen::Vector3f& v : {n, a, b, c})
        for (int k = 0; k < 3; ++k) w.put<float>(std::isfinite(v[k]) ? v[k] : 0.0f);
      w.put<uint16_t>(0);
    }
    write_file_atomically(path, w.bytes());
  } else {
    throw FileError(path, "cannot write meshes as \"" + ext + "\" (use .ply, .obj, .stl, .gltf or .glb)");
  }
}

void write_gltf_scene(const std::vector<SceneNode>& nodes, const std::filesystem::path& path) {
  const auto ext = lower_extension(path);
  if (ext != ".gltf" && ext != ".glb") throw FileError(path, "a glTF scene is written as .gltf or .glb");
  if (nodes.empty()) throw FileError(path, "cannot write a scene without nodes");
  for (const auto& n : nodes) {
    if (!n.mesh) throw FileError(path, "node '" + n.name + "' has no mesh");
    try {
      n.mesh->validate();
    } catch (const Error& e) {
      throw FileError(path, "node '" + n.name + "': " + e.what());
    }
  }
  write_gltf(nodes, path, ext == ".glb");
}

}  // namespace artisan::io
