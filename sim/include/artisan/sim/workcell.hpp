#pragma once
// A simulated workcell: static structure, objects (placed or dropped), robots and fixtures from
// URDF, sensors with their mounts, lights and environmental sources. Loaded from a JSON file;
// the format is documented in sim/README.md.
#include <cstdint>
#include <filesystem>
#include <map>
#include <string>
#include <vector>

#include <Eigen/Core>

#include "artisan/core/image.hpp"
#include "artisan/core/pose.hpp"
#include "artisan/core/triangle_mesh.hpp"

namespace artisan::sim {

struct Material {
  Eigen::Vector3f color{0.7f, 0.7f, 0.7f};  ///< diffuse RGB, each in [0, 1]
  float specular = 0.1f;                    ///< specular reflectance [0, 1]
  bool noise_texture = false;               ///< modulate by a procedural grey-noise texture
  float texture_scale_m = 0.2f;             ///< size of one repeat of the procedural texture [m]
  bool use_vertex_colors = true;            ///< use the mesh's per-vertex colours when it has them
};

enum class BodyRole { structure, object, robot_link };
const char* to_string(BodyRole role);

/// Geometry the physics engine uses for a body.
struct CollisionShape {
  enum class Kind { box, sphere, cylinder, mesh };
  Kind kind = Kind::mesh;
  Eigen::Vector3d size = Eigen::Vector3d::Zero();  ///< box: full size [m]
  double radius_m = 0.0;                            ///< sphere, cylinder [m]
  double length_m = 0.0;                            ///< cylinder, along z [m]
};

/// One rigid thing that is rendered and (unless a robot link) simulated.
struct Body {
  std::string name;
  /// The known object (library model) it is an instance of: the workcell's "model", else the
  /// mesh file's stem ("tee" for models/tee.ply) unless scaled; "" for primitives and robot links.
  std::string model;
  int instance_id = 0;  ///< >= 1, unique; 0 means "nothing" in instance images
  BodyRole role = BodyRole::structure;
  TriangleMesh mesh;    ///< render mesh in the body frame [m] (scale applied), with normals
  CollisionShape shape; ///< kind mesh: the render mesh (a convex hull when dropped)
  Material material;
  Transform T_world_body = Transform::Identity();
  bool drop = false;     ///< settled by physics onto what is below
  double mass_kg = 1.0;  ///< dropped objects
  std::string robot;     ///< robot links: the robot's name
  std::string link;      ///< robot links: the link's name
  Transform T_link_body = Transform::Identity();  ///< robot links: the visual's origin
};

struct JointSpec {
  enum class Type { fixed, revolute, continuous, prismatic };
  std::string name;
  Type type = Type::fixed;
  std::string parent_link;
  std::string child_link;
  Transform T_parent_joint = Transform::Identity();  ///< the joint origin in the parent link
  Eigen::Vector3d axis = Eigen::Vector3d::UnitZ();   ///< in the joint frame
  double lower = 0.0;     ///< limit [rad] or [m]
  double upper = 0.0;     ///< limit [rad] or [m]
  double velocity = 0.0;  ///< speed limit [rad/s] or [m/s]
};

/// A robot or fixture from URDF, posed by its joint values.
struct Robot {
  std::string name;
  std::filesystem::path urdf;
  std::string root_link;
  Transform T_world_root = Transform::Identity();
  std::vector<JointSpec> joints;
  std::map<std::string, double> joint_values;  ///< [rad] or [m]; missing joints are 0

  const JointSpec& joint(const std::string& name) const;  ///< throws artisan::Error
  /// Pose of every link in the workcell frame for the current joint values.
  std::map<std::string, Transform> link_poses() const;
};

/// A sensor: its kind, where it is mounted, and model parameters overriding the defaults.
struct SensorSpec {
  std::string name;
  std::string kind;                    ///< "minolta-vivid-700", "pioneer-trinocular", "environment"
  std::string mount = "world";         ///< "world" or "ROBOT/LINK"
  Transform T_mount_sensor = Transform::Identity();
  std::string pan_tilt_robot;          ///< pioneer: the pan/tilt unit (a robot of the workcell)
  std::string pan_joint = "ptu_pan";   ///< pioneer: joint names in that robot
  std::string tilt_joint = "ptu_tilt";
  std::map<std::string, double> params;  ///< overrides of the model's parameter struct, by field name
};

struct Light {
  Eigen::Vector3d position_world = Eigen::Vector3d(0, 0, 3);  ///< [m]
  Eigen::Vector3f diffuse{0.8f, 0.8f, 0.8f};                  ///< RGB [0, 1]
  Eigen::Vector3f ambient{0.15f, 0.15f, 0.15f};               ///< RGB [0, 1]
};

struct GammaSource {
  std::string name;
  Eigen::Vector3d position_world = Eigen::Vector3d::Zero();  ///< [m]
  double dose_rate_at_1m_uSv_per_h = 0.0;  ///< unshielded dose rate at 1 m [µSv/h]
};

/// A scalar field: base + gradient · p + Σ Gaussian hot spots.
struct ScalarField {
  struct Spot {
    Eigen::Vector3d position_world = Eigen::Vector3d::Zero();  ///< [m]
    double amplitude = 0.0;                                     ///< field units
    double sigma_m = 1.0;                                       ///< [m]
  };
  double base = 0.0;                                    ///< value at the workcell origin
  Eigen::Vector3d gradient = Eigen::Vector3d::Zero();   ///< [field units / m]
  std::vector<Spot> spots;
  double value_at(const Eigen::Vector3d& p_world) const;
};

inline ScalarField uniform_field(double value) {
  ScalarField f;
  f.base = value;
  return f;
}

struct EnvironmentSpec {
  std::vector<GammaSource> gamma_sources;
  double solid_attenuation_per_m = 60.0;  ///< linear attenuation inside bodies [1/m] (steel, ~0.66 MeV: 0.57 cm⁻¹)
  double air_attenuation_per_m = 0.0093;  ///< air at ~0.66 MeV [1/m]
  ScalarField temperature_C = uniform_field(20.0);     ///< [°C]
  ScalarField humidity_percent = uniform_field(45.0);  ///< relative humidity [%]
};

struct Workcell {
  std::filesystem::path source;  ///< the file it was loaded from (for messages)
  std::string name;
  std::vector<Body> bodies;
  std::vector<Robot> robots;
  std::vector<SensorSpec> sensors;
  std::vector<Light> lights;
  EnvironmentSpec environment;
  uint64_t drop_seed = 1;    ///< seeds the initial poses of dropped objects
  double start_time_s = 0.0; ///< simulated clock at load [s since the epoch]

  /// Throws artisan::Error naming the file and the known sensors.
  const SensorSpec& sensor(const std::string& name) const;
  Robot& robot(const std::string& name);  ///< throws artisan::Error
  const Robot& robot(const std::string& name) const;
  /// Sets a joint value; throws artisan::Error naming the joint, value and limits when beyond them.
  void set_joint(const std::string& robot, const std::string& joint, double value);
  /// Re-poses the robot-link bodies from the robots' joint values.
  void update_robot_poses();
  /// The sensor's pose in the workcell frame (through its mount).
  Transform T_world_sensor(const SensorSpec& sensor) const;
  /// Index of the body with this instance id, or -1.
  int body_index(int instance_id) const;
};

struct LoadOptions {
  /// Directories searched for package://PACKAGE/... (each holds PACKAGE/). The workcell's own
  /// "package_paths" (relative to the file) come first.
  std::vector<std::filesystem::path> package_paths;
};

/// Loads a workcell file; meshes and URDFs are resolved relative to it. Throws artisan::Error
/// (or FileError) naming the file, the field and the value on any defect. Dropped objects get
/// their initial pose only; run settle() (physics.hpp) to let them come to rest.
Workcell load_workcell(const std::filesystem::path& path, const LoadOptions& options = {});

}  // namespace artisan::sim
