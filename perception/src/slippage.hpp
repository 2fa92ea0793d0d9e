#pragma once
// Private: whether a model's surface can slide along itself (Gelfand et al., "Geometrically
// stable sampling for the ICP algorithm", 3DIM 2003): the rigid motions that move every point
// along its tangent plane, to first order, leave a point-to-plane fit no hold on the pose. A
// pipe slides along its axis, an elbow about its bend; a flange turns about its axis too, but
// that turn maps it onto itself (a symmetry, no other pose); a tee or a valve does not slide.
#include "artisan/core/triangle_mesh.hpp"

namespace artisan::detail {

/// Whether some motion moves the model's surface along itself without being a symmetry of it.
/// The motions: the eigenvectors of the point-to-plane normal equations' 6x6 matrix (rotations
/// about the centroid in units of the points' RMS distance from it) whose eigenvalue is at most
/// `max_ratio` of the largest. Each is applied until some point has moved 3 `res`; it is a
/// symmetry when then at most 1% of the points lie more than 1.5 `res` from the model's surface.
bool slides_along_itself(const PointCloud& model, double res, double max_ratio = 0.1);

}  // namespace artisan::detail
