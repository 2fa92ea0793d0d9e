// Isotropic remeshing to a target edge length (CGAL Polygon Mesh Processing, after Botsch &
// Kobbelt, "A remeshing approach to multiresolution modeling", SGP 2004). Kept in its own file so
// the heavy template code compiles once.
#include <cmath>
#include <sstream>
#include <string>
#include <vector>

#include <CGAL/Exact_predicates_inexact_constructions_kernel.h>
#include <CGAL/Polygon_mesh_processing/orient_polygon_soup.h>
#include <CGAL/Polygon_mesh_processing/polygon_soup_to_polygon_mesh.h>
#include <CGAL/Polygon_mesh_processing/remesh.h>
#include <CGAL/Polygon_mesh_processing/repair_polygon_soup.h>
#include <CGAL/Surface_mesh.h>

#include "artisan/core/error.hpp"
#include "artisan/perception/meshing.hpp"

namespace artisan {

namespace {
using K = CGAL::Exact_predicates_inexact_constructions_kernel;
using SurfaceMesh = CGAL::Surface_mesh<K::Point_3>;
namespace PMP = CGAL::Polygon_mesh_processing;

std::string num(double v) {
  std::ostringstream s;
  s << v;
  return s.str();
}
}  // namespace

TriangleMesh remesh_to_resolution(const TriangleMesh& mesh, double target_edge_m) {
  if (!(target_edge_m > 0) || !std::isfinite(target_edge_m))
    throw Error("remesh_to_resolution: target edge length " + num(target_edge_m) + " m is not positive and finite");
  mesh.validate();
  if (mesh.faces.empty()) throw Error("remesh_to_resolution: the mesh has no faces");

  // Through a polygon soup: repairing and orienting it splits non-manifold vertices (two sheets
  // of a range-image mesh touching at one pixel), which a Surface_mesh cannot hold.
  std::vector<K::Point_3> points;
  points.reserve(mesh.vertices.size());
  for (const auto& v : mesh.vertices) points.emplace_back(v.x(), v.y(), v.z());
  std::vector<std::vector<std::size_t>> polygons;
  polygons.reserve(mesh.faces.size());
  for (const auto& f : mesh.faces)
    polygons.push_back({static_cast<std::size_t>(f[0]), static_cast<std::size_t>(f[1]), static_cast<std::size_t>(f[2])});
  PMP::repair_polygon_soup(points, polygons);
  PMP::orient_polygon_soup(points, polygons);
  SurfaceMesh surface;
  PMP::polygon_soup_to_polygon_mesh(points, polygons, surface);

  // Borders are constrained: split and collapsed to the target, their vertices slide along them.
  PMP::isotropic_remeshing(faces(surface), target_edge_m, surface,
                           CGAL::parameters::number_of_iterations(3).relax_constraints(true));
  surface.collect_garbage();

  TriangleMesh out;
  out.vertices.reserve(surface.number_of_vertices());
  for (auto v : surface.vertices()) {
    const auto& p = surface.point(v);
    out.vertices.emplace_back(static_cast<float>(p.x()), static_cast<float>(p.y()), static_cast<float>(p.z()));
  }
  out.faces.reserve(surface.number_of_faces());
  for (auto f : surface.faces()) {
    Eigen::Vector3i face;
    int k = 0;
    for (auto v : CGAL::vertices_around_face(surface.halfedge(f), surface)) face[k++] = static_cast<int>(v.idx());
    out.faces.push_back(face);
  }
  out.compute_vertex_normals();
  return out;
}

}  // namespace artisan
