#include "free_space.hpp"

#include <algorithm>
#include <atomic>
#include <cmath>

#include <Eigen/Eigenvalues>
#include <Eigen/Geometry>

namespace artisan::detail {

Plane largest_plane(const PointCloud& cloud, const std::vector<char>& taken, double distance, uint64_t& state) {
  Plane best;
  const size_t n = cloud.points.size();
  if (n < 3 || cloud.normals.size() != n) return best;
  const auto next = [&] {
    state ^= state << 13, state ^= state >> 7, state ^= state << 17;
    return state;
  };
  // The tries drawn in order, counted in parallel, the first of the most held kept.
  std::vector<Plane> tries;
  for (int it = 0; it < 150; ++it) {
    const size_t s = next() % n;
    if (taken[s]) continue;
    tries.push_back({.normal = cloud.normals[s], .offset = cloud.normals[s].dot(cloud.points[s]), .distance = static_cast<float>(distance)});
  }
#pragma omp parallel for schedule(dynamic, 1)
  for (size_t k = 0; k < tries.size(); ++k)
    for (size_t i = 0; i < n; ++i) tries[k].count += !taken[i] && tries[k].holds(cloud.points[i], cloud.normals[i]);
  for (const Plane& candidate : tries)
    if (candidate.count > best.count) best = candidate;
  return best;
}

FreeSpace::FreeSpace(const PointCloud& scene, const KdTree3& scene_tree, const std::vector<SensorView>& views, double resolution_m,
                     double tolerance_m, double max_incidence_rad, size_t largest_model_points, size_t smallest_support, bool own_bin_only,
                     double own_bin_min_incidence_rad)
    : scene_(scene), tree_(scene_tree), resolution_(resolution_m), tolerance_(tolerance_m), min_incidence_cos_(std::cos(max_incidence_rad)),
      own_bin_only_(own_bin_only), grazing_cos_(std::cos(own_bin_min_incidence_rad)) {
  find_planes(largest_model_points, smallest_support);
  Eigen::Vector3d centroid = Eigen::Vector3d::Zero();
  for (const auto& p : scene.points) centroid += p.cast<double>();
  if (!scene.points.empty()) centroid /= static_cast<double>(scene.points.size());
  for (const auto& view : views) {
    Map m;
    m.view = view;
    const Eigen::Vector3d axis = view.rays == SensorView::Rays::kPerspective ? Eigen::Vector3d((centroid - view.origin_mesh).normalized())
                                                                           : Eigen::Vector3d(-view.toward_sensor_mesh.normalized());
    if (!axis.allFinite()) continue;
    const Eigen::Vector3d x = axis.unitOrthogonal();
    m.R.row(0) = x.transpose();
    m.R.row(1) = axis.cross(x).transpose();
    m.R.row(2) = axis.transpose();
    std::vector<double> depths;
    for (const auto& p : scene.points) depths.push_back(m.local(p.cast<double>()).z());
    double median = 1.0;
    if (!depths.empty()) {
      std::nth_element(depths.begin(), depths.begin() + static_cast<long>(depths.size() / 2), depths.end());
      median = std::max(depths[depths.size() / 2], 1e-3);
    }
    // Bins about 1.5 resolutions wide at the scene's median depth.
    m.bin = view.rays == SensorView::Rays::kPerspective ? 1.5 * resolution_m / median : 1.5 * resolution_m;
    std::vector<detail::BinDepths::Binned> binned;
    for (const auto& p : scene.points)
      if (const auto key = m.key(p.cast<double>())) binned.push_back({key->u, key->v, key->depth});
    m.nearest.assign(binned);
    m.around.assign(binned, 1);
    maps_.push_back(std::move(m));
  }
}

FreeSpace::Check FreeSpace::check(const LibraryModel& model, const Transform& T) const {
  return check(model, T, [](const Check&) { return true; });
}

FreeSpace::Check FreeSpace::check(const LibraryModel& model, const Transform& T, const std::function<bool(const Check&)>& worth_it,
                                  double most_through) const {
  Check c;
  std::vector<Eigen::Vector3d> p(model.points.points.size()), n(model.points.points.size());
#pragma omp parallel for schedule(static)
  for (size_t i = 0; i < p.size(); ++i) {
    p[i] = T * model.points.points[i].cast<double>();
    n[i] = T.linear() * model.points.normals[i].cast<double>();
  }
  // Through a solid's face: model points more than the tolerance in front of it and behind it,
  // both over its region. A part stands on a table; a pose whose tee branch or valve stem goes
  // down through the table top (the rest of it on a pipe lying there) cannot be, though the
  // table hides what lies under it.
  if (!solids_.empty() && !p.empty()) {
    Eigen::Vector3d low = p[0], high = p[0];
    for (const auto& q : p) low = low.cwiseMin(q), high = high.cwiseMax(q);
    const double reach = (high - low).norm();
    for (const auto& solid : solids_) {
      // Most poses lie wholly on one side: the region is looked at only for those that do not.
      double nearest = std::numeric_limits<double>::infinity(), farthest = -nearest;  // signed distances from the face
      for (const auto& q : p) {
        const double d = solid.normal.dot(q) - solid.offset;
        nearest = std::min(nearest, d), farthest = std::max(farthest, d);
      }
      if (nearest >= -tolerance_ || farthest <= tolerance_) continue;
      size_t front = 0, behind = 0;
#pragma omp parallel for schedule(static) reduction(+ : front, behind)
      for (size_t i = 0; i < p.size(); ++i) {
        const double d = solid.normal.dot(p[i]) - solid.offset;
        if (std::abs(d) > tolerance_ && under(solid, p[i], reach)) ++(d > 0 ? front : behind);
      }
      c.through = std::max(c.through, static_cast<double>(std::min(front, behind)) / static_cast<double>(p.size()));
    }
  }
  if (c.through > most_through) {
    c.free_space = c.explained = c.occluded = c.planarity = c.continued = std::numeric_limits<double>::quiet_NaN();
    return c;
  }
  if (maps_.empty()) return c;
  // 0: not known yet; 1: explained by the scene; 2: not (nothing near, or only a background plane).
  std::vector<char> near(p.size(), 0);
  const auto near_scene = [&](size_t i) {
    if (!near[i]) {
      const auto j = tree_.nearest_within(p[i].cast<float>(), static_cast<float>(std::min(tolerance_, 2 * resolution_)));
      near[i] = j && !background_[j->first] ? 1 : 2;
    }
    return near[i] == 1;
  };
  std::vector<char> counted(p.size(), 0), violates(p.size(), 0), expected(p.size(), 0), seen_there(p.size(), 0), hidden(p.size(), 0);
  detail::BinDepths self;  // the model's own nearest depth per bin
  std::vector<detail::BinDepths::Binned> faces_view;  // the model points facing the view, binned
  std::vector<std::optional<Key>> keys(p.size());
  for (const auto& m : maps_) {
#pragma omp parallel for schedule(static)
    for (size_t i = 0; i < p.size(); ++i) keys[i] = m.key(p[i]);
    faces_view.clear();
    for (size_t i = 0; i < p.size(); ++i)
      if (keys[i] && n[i].dot(m.toward(p[i])) > 0) faces_view.push_back({keys[i]->u, keys[i]->v, keys[i]->depth});
    self.assign(faces_view);
    // Each point's own entries only: the points are independent.
#pragma omp parallel for schedule(dynamic, 256)
    for (size_t i = 0; i < p.size(); ++i) {
      if (!keys[i]) continue;
      const double incidence_cos = n[i].dot(m.toward(p[i]).normalized());
      if (incidence_cos <= min_incidence_cos_) continue;
      const Key& k = *keys[i];
      const double seen = m.around.at(k.u, k.v);
      if (!std::isfinite(seen)) continue;  // the sensor saw nothing there: no evidence either way
      const bool returned = !own_bin_only_ || incidence_cos > grazing_cos_ || std::isfinite(m.nearest.at(k.u, k.v));
      if (returned) {
        counted[i] = 1;
        if (k.depth < seen - tolerance_) violates[i] = 1;
      }
      // Parallel rays are only an approximation of a linear scanner's (the Stanford Cyberware
      // scans' real ray directions are not recorded): what it should have seen is not predicted.
      // Where its ray returned nothing (own_bin_only) a point is expected only when the scene
      // hides it.
      if (m.view.rays == SensorView::Rays::kPerspective && k.depth <= self.at(k.u, k.v) + tolerance_) {
        const bool there = near_scene(i), behind = !there && m.seen_at(k) < k.depth - tolerance_;
        if (!returned && !behind) continue;
        expected[i] = 1;
        if (there) seen_there[i] = 1;
        else if (behind) hidden[i] = 1;
      }
    }
  }
  size_t facing = 0, in_front = 0, should = 0, did = 0, occluded = 0;
  for (size_t i = 0; i < p.size(); ++i) {
    facing += counted[i];
    in_front += violates[i];
    should += expected[i];
    did += expected[i] && seen_there[i];
    occluded += expected[i] && !seen_there[i] && hidden[i];
  }
  if (facing) c.free_space = static_cast<double>(in_front) / static_cast<double>(facing);
  if (should) c.occluded = static_cast<double>(occluded) / static_cast<double>(should);
  Eigen::Matrix3d normals = Eigen::Matrix3d::Zero();
  for (size_t i = 0; i < p.size(); ++i)
    if (expected[i] && seen_there[i]) normals += n[i] * n[i].transpose();
  if (did) c.planarity = Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d>(normals / static_cast<double>(did)).eigenvalues().maxCoeff();
  if (should > occluded) c.explained = static_cast<double>(did) / static_cast<double>(should - occluded);
  else if (should) c.explained = 0;  // everything it should show is hidden: nothing supports it
  // Silhouette: where an object's seen surface ends, the scene beyond it steps away or turns
  // (its own outline against what lies behind). A pose whose explained surface the scene
  // continues smoothly past the model's outline - a flange's face "found" flush on a box's
  // face - lies on a larger surface, not on an object of its own. An explained model point is
  // continued when a scene point within 3 resolutions, off the model (farther than 1.5
  // resolutions from all its points), lies on its tangent plane (within half a resolution)
  // with a normal within 25 degrees of its own.
  if (!worth_it(c)) c.continued = std::numeric_limits<double>::quiet_NaN();
  else if (did) {
    // Whether a scene point lies off the model (farther than 1.5 resolutions from all its
    // points), asked of the model's own tree in its frame, and only for the scene points the
    // tangent-plane test leaves: 0 not known yet, 1 on it, 2 off it. (Marking what lies on the
    // model from each of its points first, most of them hidden, cost more.)
    const auto on_model_radius = static_cast<float>(1.5 * resolution_);
    std::vector<char> on_model(scene_.points.size(), 0);
    const Eigen::Isometry3f to_model = T.inverse().cast<float>();
    const auto off_model = [&](size_t s) {
      std::atomic_ref<char> state(on_model[s]);
      char known = state.load(std::memory_order_relaxed);
      if (!known) {
        known = model.tree.nearest_within(to_model * scene_.points[s], on_model_radius) ? 1 : 2;
        state.store(known, std::memory_order_relaxed);
      }
      return known == 2;
    };
    std::vector<size_t> around;
    size_t continued = 0;
#pragma omp parallel for schedule(dynamic, 256) private(around) reduction(+ : continued)
    for (size_t i = 0; i < p.size(); ++i) {
      if (!expected[i] || !seen_there[i]) continue;
      const Eigen::Vector3f pi = p[i].cast<float>(), ni = n[i].cast<float>();
      tree_.within(pi, static_cast<float>(3.0 * resolution_), around);
      for (const size_t s : around)
        if (std::abs(ni.dot(scene_.points[s] - pi)) <= static_cast<float>(0.5 * resolution_) && ni.dot(scene_.normals[s]) >= 0.9f && off_model(s)) {
          ++continued;
          break;
        }
    }
    c.continued = static_cast<double>(continued) / static_cast<double>(did);
  }
  return c;
}

void FreeSpace::find_planes(size_t largest_model_points, size_t smallest_support) {
  const size_t n = scene_.points.size();
  background_.assign(n, 0);
  support_.assign(n, 0);
  if (n < 3 || scene_.normals.size() != n) return;
  std::vector<char> taken(n, 0), on(n, 0);
  std::vector<size_t> stack, component, around;
  uint64_t state = 0x9e3779b97f4a7c15ull;
  for (int plane = 0; plane < 3; ++plane) {
    const auto best = largest_plane(scene_, taken, resolution_, state);
    if (best.count <= (smallest_support ? smallest_support : largest_model_points)) break;
    const bool background = best.count > largest_model_points;
    for (size_t i = 0; i < n; ++i) {
      on[i] = best.holds(scene_.points[i], scene_.normals[i]);
      taken[i] |= on[i];
      background_[i] |= on[i] && background;
      support_[i] |= background_[i];
    }
    for (size_t seed = 0; smallest_support && seed < n; ++seed) {
      if (on[seed] != 1) continue;
      component.clear();
      stack.assign(1, seed);
      on[seed] = 2;
      while (!stack.empty()) {
        const size_t i = stack.back();
        stack.pop_back();
        component.push_back(i);
        tree_.within(scene_.points[i], static_cast<float>(2 * resolution_), around);
        for (const size_t j : around)
          if (on[j] == 1) on[j] = 2, stack.push_back(j);
      }
      if (component.size() > smallest_support)
        for (const size_t i : component) support_[i] = 1;
    }
    std::vector<size_t> face;
    for (size_t i = 0; i < n; ++i)
      if (on[i] && support_[i]) face.push_back(i);
    if (!face.empty()) solids_.push_back(Solid(scene_, face, best.normal, best.offset));
  }
}

FreeSpace::Solid::Solid(const PointCloud& scene, const std::vector<size_t>& face, const Eigen::Vector3f& plane_normal, float plane_offset)
    : normal(plane_normal.cast<double>()), offset(plane_offset) {
  double facing = 0;
  for (const size_t i : face) facing += scene.normals[i].cast<double>().dot(normal);
  if (facing < 0) normal = -normal, offset = -offset;
  u = normal.unitOrthogonal();
  v = normal.cross(u);
  std::vector<Eigen::Vector2d> q;
  for (const size_t i : face) q.push_back(in_plane(scene.points[i].cast<double>()));
  // Andrew's monotone chain.
  std::sort(q.begin(), q.end(),
            [](const Eigen::Vector2d& a, const Eigen::Vector2d& b) { return a.x() < b.x() || (a.x() == b.x() && a.y() < b.y()); });
  const auto turn = [](const Eigen::Vector2d& o, const Eigen::Vector2d& a, const Eigen::Vector2d& b) {
    return (a - o).x() * (b - o).y() - (a - o).y() * (b - o).x();
  };
  std::vector<Eigen::Vector2d> h(2 * q.size());
  size_t k = 0;
  for (size_t i = 0; i < q.size(); ++i) {
    while (k >= 2 && turn(h[k - 2], h[k - 1], q[i]) <= 0) --k;
    h[k++] = q[i];
  }
  for (size_t i = q.size() - 1, lower = k + 1; i-- > 0;) {
    while (k >= lower && turn(h[k - 2], h[k - 1], q[i]) <= 0) --k;
    h[k++] = q[i];
  }
  h.resize(k > 1 ? k - 1 : k);
  hull = std::move(h);
  for (size_t i = 0; i < hull.size(); ++i) edges.push_back((hull[(i + 1) % hull.size()] - hull[i]).normalized());
}

double FreeSpace::Solid::outside(const Eigen::Vector3d& p) const {
  if (hull.size() < 3) return std::numeric_limits<double>::infinity();
  const Eigen::Vector2d q = in_plane(p);
  double out = -std::numeric_limits<double>::infinity();
  for (size_t i = 0; i < hull.size(); ++i) {
    const Eigen::Vector2d r = q - hull[i];
    out = std::max(out, edges[i].y() * r.x() - edges[i].x() * r.y());  // right of the edge: outside
  }
  return out;
}

bool FreeSpace::under(const Solid& solid, const Eigen::Vector3d& q, double reach) const {
  const double outside = solid.outside(q);
  if (outside <= 0) return true;
  if (outside > reach) return false;
  const Eigen::Vector3d foot = q - (solid.normal.dot(q) - solid.offset) * solid.normal;
  bool hidden = false;
  for (const auto& m : maps_) {
    const auto k = m.key(foot);
    if (!k) continue;
    const double seen = m.seen_at(*k);
    if (!std::isfinite(seen)) continue;
    if (seen > k->depth + tolerance_) return false;
    hidden = true;
  }
  return hidden;
}

}  // namespace artisan::detail
