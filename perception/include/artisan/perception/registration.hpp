#pragma once
// Registering two overlapping views with no prior pose: spin-image matching for a rough pose
// (Johnson & Hebert, PAMI 1999, sections 4-5: similarity, outlier-based selection, geometric
// consistency, grouping, transforms, verification), refined by point-to-plane ICP.
#include <string>

#include "artisan/core/pose.hpp"
#include "artisan/core/triangle_mesh.hpp"
#include "artisan/perception/icp.hpp"
#include "artisan/perception/spin_image.hpp"

namespace artisan {

struct SpinMatchParams {
  SpinImageParams spin;
  double resolution_m = 0.0;            ///< [m] both meshes are resampled to this; 0: 3x the larger mesh resolution
  double scene_point_fraction = 0.3;    ///< [1] share of the source's resampled points whose spin images are matched
  double lambda = 3.0;                  ///< [1] weight of the overlap term in the similarity measure (eq. 8)
  double outlier_spread = 3.0;          ///< [1] a match is an upper outlier above q3 + k (q3 - q1) (section 4.3)
  double similarity_ratio = 0.5;        ///< [1] matches below this share of the best similarity are dropped
  double geometric_consistency = 0.25;  ///< [1] T_gc, the largest relative spin-map disagreement (eq. 9)
  double gamma_factor = 4.0;            ///< [1] gamma of the grouping distance (eq. 10), in resolutions
  int max_groups = 40;                  ///< [1] groups (seeds) turned into transforms and verified
  int min_group_size = 3;               ///< [1] correspondences needed for a transform
};

struct RegistrationSettings {
  SpinMatchParams match;
  IcpSettings icp;                 ///< the final refinement (distances scaled by the resolution below)
  double icp_distance_factor = 2;  ///< [1] final ICP's max correspondence distance, in source mesh resolutions
  double min_overlap = 0.15;       ///< [1] a result with less overlap is "too weak to trust" ...
  /// [1] ... and so is one whose final residual exceeds this many mesh resolutions. A wrong
  /// alignment leaves residuals spread over the whole correspondence distance (RMS ~1 resolution
  /// on the bunny scans); a right one leaves sensor noise (RMS under 0.45 resolution).
  double max_rmse_factor = 0.65;
  /// Refuse alignments whose overlap leaves a degree of freedom free (see conditioning).
  double min_conditioning = 0.01;
  /// Refuse alignments whose overlap lies within this x the resolution of one plane (RMS).
  double min_flatness_factor = 1.5;
};

struct RegistrationResult {
  Transform T_target_source = Transform::Identity();
  bool success = false;
  std::string failure;                    ///< why not, when !success
  double overlap_fraction = 0.0;          ///< [1] of the source's samples that lie on the target after ICP
  double rmse_m = 0.0;                    ///< [m] point-to-plane RMS of those samples
  /// How well the overlap pins down all six degrees of freedom: smallest over largest eigenvalue
  /// of the point-to-plane information matrix of the inliers (translations scaled by their
  /// spread). Near 0 when the overlap is one plane (or a cylinder...) that could slide.
  double conditioning = 0.0;
  /// RMS distance of the overlap from its best-fit plane [m]: small when the views only share
  /// a plane (a floor), however noisy its normals.
  double flatness_m = 0.0;
  size_t consistent_correspondences = 0;  ///< in the winning group
  size_t candidate_correspondences = 0;   ///< after similarity and consistency filtering
  size_t groups_verified = 0;
  double resolution_m = 0.0;              ///< [m] of the resampled clouds
  double seconds_spin_images = 0.0;
  double seconds_matching = 0.0;
  double seconds_icp = 0.0;
};

/// T_target_source with no initial pose. Throws artisan::Error on empty meshes.
RegistrationResult register_meshes(const TriangleMesh& target, const TriangleMesh& source,
                                   const RegistrationSettings& settings = {});

/// ICP only, from a given T_target_source (for --method icp/manual), with the same figures.
RegistrationResult refine_registration(const TriangleMesh& target, const TriangleMesh& source,
                                       const Transform& T_target_source_init, const RegistrationSettings& settings = {});

}  // namespace artisan
