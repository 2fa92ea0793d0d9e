#pragma once
// Tessellated primitives and the project's own pipework models (pipes, elbows, tees, flanges,
// valves). Every mesh has per-vertex normals, faces counter-clockwise seen from outside, and is
// built in its own frame: the axis of a primitive or of the main run of a fitting is z, centred
// on the origin unless stated.
#include "artisan/core/triangle_mesh.hpp"

namespace artisan::sim {

/// Axis-aligned box centred on the origin; size [m] along x, y, z.
TriangleMesh make_box(const Eigen::Vector3d& size);
/// Sphere centred on the origin [m].
TriangleMesh make_sphere(double radius, int segments = 32);
/// Closed cylinder along z, centred on the origin [m].
TriangleMesh make_cylinder(double radius, double length, int segments = 32);

/// Pipework dimensions shared by the fittings.
struct PipeSize {
  double outer_diameter_m = 0.0603;  ///< DN50 outer diameter [m] (60.3 mm, ISO/ASME)
  double wall_m = 0.0039;            ///< wall thickness [m] (schedule 40, 3.9 mm)
  int segments = 32;                 ///< facets around the circumference
};

/// Straight hollow pipe along z, centred [m].
TriangleMesh make_pipe(double length, const PipeSize& size = {});
/// 90-degree elbow: from the origin along +z, bending towards +x with the given bend radius
/// (to the pipe axis) [m].
TriangleMesh make_elbow(double bend_radius, const PipeSize& size = {});
/// Equal tee: run along z (centred, `run_length` long), branch along +x from the run axis,
/// `branch_length` long [m].
TriangleMesh make_tee(double run_length, double branch_length, const PipeSize& size = {});
/// Weld-neck flange: a disc (`flange_diameter`, `thickness`) at z in [0, thickness] with a
/// pipe stub of `neck_length` beyond it along +z [m].
TriangleMesh make_flange(double flange_diameter, double thickness, double neck_length, const PipeSize& size = {});
/// Gate valve: a spherical body, two pipe ends along z (total `length`), a stem along +x and a
/// hand wheel at its end [m].
TriangleMesh make_valve(double length, const PipeSize& size = {});

}  // namespace artisan::sim
