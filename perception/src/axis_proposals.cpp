#include "axis_proposals.hpp"
#include "slippage.hpp"

#include <algorithm>
#include <cmath>
#include <limits>
#include <numbers>

#include <Eigen/Eigenvalues>
#include <Eigen/Geometry>

namespace artisan::detail {

std::optional<ModelCylinder> model_cylinder(const PointCloud& model, const Eigen::Vector3d& axis_point, const Eigen::Vector3d& axis_direction,
                                            double res, double min_share) {
  if (model.points.empty() || model.normals.size() != model.points.size()) return std::nullopt;
  ModelCylinder c;
  c.point = axis_point;
  c.direction = axis_direction.normalized();
  c.start = std::numeric_limits<double>::max();
  c.end = std::numeric_limits<double>::lowest();
  size_t on = 0;
  std::vector<double> outer;
  for (size_t i = 0; i < model.points.size(); ++i) {
    const Eigen::Vector3d p = model.points[i].cast<double>() - c.point;
    const double along = p.dot(c.direction);
    c.start = std::min(c.start, along);
    c.end = std::max(c.end, along);
    const Eigen::Vector3d radial = p - along * c.direction;
    const double r = radial.norm();
    const Eigen::Vector3d n = model.normals[i].cast<double>();
    if (r < res || std::abs(n.dot(c.direction)) > 0.2) continue;
    const double facing = n.dot(radial / r);  // +1: outward, -1: inward (a bore)
    if (std::abs(facing) < 0.95) continue;
    ++on;
    if (facing > 0) outer.push_back(r);
  }
  c.share = static_cast<double>(on) / static_cast<double>(model.points.size());
  if (c.share < min_share || outer.empty()) return std::nullopt;
  // The outer radius: the median of the outward-facing points', at least half of which must lie
  // within a spacing of it (one outer cylinder, not several of different radii).
  std::sort(outer.begin(), outer.end());
  c.radius = outer[outer.size() / 2];
  const auto near_radius = std::count_if(outer.begin(), outer.end(), [&](double r) { return std::abs(r - c.radius) <= res; });
  if (2 * static_cast<size_t>(near_radius) < outer.size()) return std::nullopt;
  c.round = round_about(model, c.point, c.direction, res);
  return c;
}

std::vector<ModelCylinder> model_round_parts(const PointCloud& model, const Eigen::Vector3d& axis_point, const Eigen::Vector3d& axis_direction,
                                             double res, double min_share) {
  std::vector<ModelCylinder> parts;
  if (model.points.empty() || model.normals.size() != model.points.size()) return parts;
  const Eigen::Vector3d a = axis_direction.normalized();
  // The outward-facing points on cylinders about the axis: (radius, position along it).
  std::vector<std::pair<double, double>> outer;
  for (size_t i = 0; i < model.points.size(); ++i) {
    const Eigen::Vector3d p = model.points[i].cast<double>() - axis_point;
    const double along = p.dot(a);
    const Eigen::Vector3d radial = p - along * a;
    const double r = radial.norm();
    if (r < 3 * res || std::abs(model.normals[i].cast<double>().dot(a)) > 0.2 || model.normals[i].cast<double>().dot(radial / r) < 0.95) continue;
    outer.emplace_back(r, along);
  }
  std::sort(outer.begin(), outer.end());
  bool round = false, round_known = false;
  for (size_t first = 0; first < outer.size();) {
    size_t last = first;
    while (last < outer.size() && outer[last].first - outer[first].first <= res) ++last;
    const double share = static_cast<double>(last - first) / static_cast<double>(model.points.size());
    ModelCylinder c;
    c.point = axis_point;
    c.direction = a;
    c.radius = outer[first + (last - first) / 2].first;
    c.start = std::numeric_limits<double>::max();
    c.end = std::numeric_limits<double>::lowest();
    for (size_t k = first; k < last; ++k) c.start = std::min(c.start, outer[k].second), c.end = std::max(c.end, outer[k].second);
    c.share = share;
    first = last;
    if (share < min_share || c.end - c.start < c.radius) continue;
    if (!round_known) round = round_about(model, axis_point, a, res), round_known = true;
    if (!round) return {};
    c.round = true;
    parts.push_back(c);
  }
  std::sort(parts.begin(), parts.end(), [](const ModelCylinder& x, const ModelCylinder& y) { return x.share > y.share; });
  return parts;
}

bool round_about(const PointCloud& model, const Eigen::Vector3d& axis_point, const Eigen::Vector3d& axis_direction, double res) {
  // A turn that is no symmetry of the facets (2 pi / 7) keeps every point on the surface.
  const KdTree3 tree(model.points);
  const Eigen::AngleAxisd seventh(2 * std::numbers::pi / 7, axis_direction.normalized());
  const Eigen::Isometry3f turn = (Eigen::Translation3d(axis_point) * seventh * Eigen::Translation3d(-axis_point)).cast<float>();
  return share_moved_off(model, tree, turn, 1.5 * res, std::max<size_t>(1, model.points.size() / 64)) == 0;
}

namespace {

// The circle across `direction` that the points lie on (their distance from the axis through
// `centre` along it is `radius`): Gauss-Newton on the geometric distances from the given start,
// twice, the second time without the points more than `outlier` [m] off the first circle. The
// algebraic fit (Kasa) is biased small on a short arc with noise: a scanned pipe of 30 mm read
// as 24; so is a radius read off the normals, which meshing smooths and noise scatters.
bool fit_circle(const std::vector<Eigen::Vector3d>& points, const Eigen::Vector3d& direction, Eigen::Vector3d& centre, double& radius, double outlier) {
  const Eigen::Vector3d e1 = direction.unitOrthogonal(), e2 = direction.cross(e1);
  std::vector<Eigen::Vector2d> q;
  for (const auto& p : points) q.emplace_back((p - centre).dot(e1), (p - centre).dot(e2));
  Eigen::Vector3d x(0, 0, radius);  // centre offset (e1, e2), radius
  std::vector<char> use(q.size(), 1);
  for (int round = 0; round < 2; ++round) {
    for (int iteration = 0; iteration < 15; ++iteration) {
      Eigen::Matrix3d JtJ = Eigen::Matrix3d::Zero();
      Eigen::Vector3d Jtf = Eigen::Vector3d::Zero();
      for (size_t k = 0; k < q.size(); ++k) {
        if (!use[k]) continue;
        const Eigen::Vector2d off = q[k] - x.head<2>();
        const double rho = off.norm();
        if (!(rho > 0)) continue;
        const Eigen::Vector3d J(-off.x() / rho, -off.y() / rho, -1);
        JtJ += J * J.transpose();
        Jtf += J * (rho - x[2]);
      }
      const Eigen::Vector3d step = JtJ.ldlt().solve(-Jtf);
      if (!step.allFinite()) return false;
      x += step;
      if (step.norm() < 1e-7) break;
    }
    for (size_t k = 0; k < q.size(); ++k) use[k] = std::abs((q[k] - x.head<2>()).norm() - x[2]) <= outlier;
  }
  centre += x[0] * e1 + x[1] * e2;
  radius = x[2];
  return std::isfinite(radius) && radius > 0;
}

}  // namespace

std::vector<SceneAxis> scene_axes(const PointCloud& scene, const KdTree3& scene_tree, double radius, double res, const std::vector<char>& ignore,
                                  size_t min_points) {
  std::vector<SceneAxis> axes;
  const size_t n = scene.points.size();
  if (n == 0 || scene.normals.size() != n || !(radius > 0)) return axes;
  // Each point's neighbourhood (half a radius, at least three spacings): a cylinder's normals
  // all lie across its axis, which is the least direction of their scatter; and the points one
  // radius behind their surface along the normal lie on that axis. (Over so short an arc the
  // radius itself is not told apart from a somewhat larger or smaller one: the groups' fit does that.)
  const auto reach = static_cast<float>(std::max(0.5 * radius, 3 * res));
  const double tolerance = std::max(0.2 * radius, 2 * res);
  struct Local {
    Eigen::Vector3d point, direction;
    bool ok = false;
  };
  std::vector<Local> local(n);
  const auto skipped = [&](size_t i) { return !ignore.empty() && ignore[i]; };
  std::vector<size_t> near;
#pragma omp parallel for schedule(dynamic, 256) private(near)
  for (size_t i = 0; i < n; ++i) {
    if (skipped(i)) continue;
    scene_tree.within(scene.points[i], reach, near);
    std::erase_if(near, skipped);
    if (near.size() < 10) continue;
    Eigen::Matrix3d scatter = Eigen::Matrix3d::Zero();
    Eigen::Vector3d centre = Eigen::Vector3d::Zero();
    for (const size_t j : near) {
      const Eigen::Vector3d nj = scene.normals[j].cast<double>();
      scatter += nj * nj.transpose();
      centre += scene.points[j].cast<double>() - radius * nj;
    }
    scatter /= static_cast<double>(near.size());
    centre /= static_cast<double>(near.size());
    const Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> eig(scatter);  // ascending
    const Eigen::Vector3d values = eig.eigenvalues();
    // Normals that turn (not a plane: the middle value) about one direction (not a sphere: the least).
    if (values[1] < 0.005 || values[0] > 0.25 * values[1]) continue;
    const Eigen::Vector3d d = eig.eigenvectors().col(0);
    const Eigen::Matrix3d across = Eigen::Matrix3d::Identity() - d * d.transpose();
    size_t inliers = 0;
    for (const size_t j : near) inliers += (across * (scene.points[j].cast<double>() - radius * scene.normals[j].cast<double>() - centre)).norm() <= tolerance;
    if (5 * inliers < 4 * near.size()) continue;
    local[i] = {centre, d, true};
  }
  // Greedy grouping: the points whose axis lies on one line (within the tolerance, directions
  // within 15 degrees), the line refitted to them once; then the circle their points make
  // across it, which must have the radius (within 15%).
  std::vector<size_t> open;
  for (size_t i = 0; i < n; ++i)
    if (local[i].ok) open.push_back(i);
  std::vector<char> taken(n, 0);
  const double parallel = std::cos(15.0 * std::numbers::pi / 180);
  const auto gather = [&](const Eigen::Vector3d& point, const Eigen::Vector3d& direction) {
    std::vector<size_t> members;
    const Eigen::Matrix3d across = Eigen::Matrix3d::Identity() - direction * direction.transpose();
    for (const size_t j : open)
      if (!taken[j] && std::abs(local[j].direction.dot(direction)) >= parallel && (across * (local[j].point - point)).norm() <= tolerance)
        members.push_back(j);
    return members;
  };
  for (const size_t seed : open) {
    if (taken[seed]) continue;
    taken[seed] = 1;
    auto members = gather(local[seed].point, local[seed].direction);
    if (members.size() + 1 < min_points) continue;
    // Refit: the mean of the members' axis points, the mean of their directions (one sense).
    Eigen::Vector3d point = local[seed].point, direction = local[seed].direction;
    for (const size_t j : members) {
      point += local[j].point;
      direction += local[j].direction.dot(local[seed].direction) >= 0 ? local[j].direction : Eigen::Vector3d(-local[j].direction);
    }
    point /= static_cast<double>(members.size() + 1);
    direction.normalize();
    members = gather(point, direction);
    members.push_back(seed);
    if (members.size() < min_points) continue;
    for (const size_t j : members) taken[j] = 1;
    std::vector<Eigen::Vector3d> surface;
    for (const size_t j : members) surface.push_back(scene.points[j].cast<double>());
    double fitted = radius;
    if (!fit_circle(surface, direction, point, fitted, 2 * res) || std::abs(fitted - radius) > 0.15 * radius) continue;
    SceneAxis a;
    a.direction = direction;
    std::vector<double> along;
    for (const auto& p : surface) along.push_back((p - point).dot(direction));
    std::sort(along.begin(), along.end());
    // The extent without its outermost 1% (stray points at the ends).
    const double lo = along[along.size() / 100], hi = along[along.size() - 1 - along.size() / 100];
    a.point = point + 0.5 * (lo + hi) * direction;
    a.start = lo - 0.5 * (lo + hi);
    a.end = hi - 0.5 * (lo + hi);
    a.points = members.size();
    axes.push_back(a);
  }
  std::stable_sort(axes.begin(), axes.end(), [](const SceneAxis& a, const SceneAxis& b) { return a.points > b.points; });
  return axes;
}

std::vector<Transform> poses_on_axis(const ModelCylinder& cylinder, const SceneAxis& axis, double step, int turns) {
  std::vector<Transform> poses;
  if (!(step > 0)) return poses;
  const int turn_count = cylinder.round ? 1 : std::max(turns, 1);
  for (const double sense : {1.0, -1.0}) {
    const Eigen::Vector3d to = sense * axis.direction;
    const Eigen::Quaterniond align = Eigen::Quaterniond::FromTwoVectors(cylinder.direction, to);
    // The model's extent along the scene axis, from where its axis point goes.
    const double lo = std::min(sense * cylinder.start, sense * cylinder.end), hi = std::max(sense * cylinder.start, sense * cylinder.end);
    for (int k = 0; k < turn_count; ++k) {
      const Eigen::Matrix3d R = Eigen::AngleAxisd(2 * std::numbers::pi * k / turn_count, axis.direction).toRotationMatrix() * align.toRotationMatrix();
      // Every shift s (the model's axis point at axis.point + s direction) at which the model's
      // extent [s + lo, s + hi] overlaps the seen one [start, end].
      for (double s = axis.start - hi; s <= axis.end - lo + 1e-9; s += step) {
        Transform T = Transform::Identity();
        T.linear() = R;
        T.translation() = axis.point + s * axis.direction - R * cylinder.point;
        poses.push_back(T);
      }
    }
  }
  return poses;
}

}  // namespace artisan::detail
