// Differential-drive robot: acceleration- and speed-limited wheels, exact arc integration, footprint collisions.
#include "airground/sim/diff_drive.hpp"

#include <algorithm>
#include <cmath>

#include "airground/platform/param_binding.hpp"
#include "airground/sim/model_params.hpp"

namespace ag::sim {

namespace {

constexpr ParamField<DiffDriveConfig> kDriveFields[] = {
    field::real("track_width_m", &DiffDriveConfig::track_width_m, 0.05, 5.0, "m", "distance between left and right wheels"),
    field::real("wheel_radius_m", &DiffDriveConfig::wheel_radius_m, 0.01, 2.0, "m", "wheel radius"),
    field::real("max_wheel_speed_rad_s", &DiffDriveConfig::max_wheel_speed_rad_s, 0.1, 1000.0, "rad/s", "wheel speed limit"),
    field::real("max_linear_accel_mps2", &DiffDriveConfig::max_linear_accel_mps2, 0.01, 100.0, "m/s^2", "linear acceleration limit"),
    field::real("max_angular_accel_radps2", &DiffDriveConfig::max_angular_accel_radps2, 0.01, 1000.0, "rad/s^2", "angular acceleration limit"),
    field::real("footprint_radius_m", &DiffDriveConfig::footprint_radius_m, 0.01, 10.0, "m", "radius of the collision disc"),
    field::real("max_step_height_m", &DiffDriveConfig::max_step_height_m, 0.0, 10.0, "m", "highest climbable rise of the surface"),
    field::real("command_timeout_s", &DiffDriveConfig::command_timeout_s, 0.0, 60.0, "s", "stop when no command came for this long, 0 = never"),
    field::boolean("block_building", &DiffDriveConfig::block_building, "buildings stop the robot"),
    field::boolean("block_tree", &DiffDriveConfig::block_tree, "trees stop the robot"),
    field::boolean("block_vehicle", &DiffDriveConfig::block_vehicle, "vehicles stop the robot"),
    field::boolean("block_water", &DiffDriveConfig::block_water, "water stops the robot"),
};
constexpr auto kDriveParams = param_specs(kDriveFields);
constexpr ParamSection kDriveSchema[] = {{"diff_drive", kDriveParams, "differential-drive ground robot"}};

Result<DiffDriveConfig> drive_from(const Result<Config>& c) {
  if (!c) return c.error();
  const SectionView v(c.value(), "diff_drive");
  return load_params(v, kDriveFields);
}

double clamp_abs(double v, double lim) noexcept { return std::clamp(v, -lim, lim); }

// Surface height of the cell under a map point, or `fallback` outside the world.
double cell_surface_or(const World& w, double x, double y, double fallback) noexcept {
  const auto c = w.grid().col(x), r = w.grid().row(y);
  return w.grid().contains(c, r) ? static_cast<double>(w.surface_at(c, r)) : fallback;
}

// Surface height interpolated bilinearly between cell centres (edge cells extend outward), for a smooth
// body attitude; `fallback` outside the world.
double smooth_surface_or(const World& w, double x, double y, double fallback) noexcept {
  const GridGeometry& g = w.grid();
  if (!g.contains(g.col(x), g.row(y))) return fallback;
  const double fx = g.col_f(x) - 0.5, fy = g.row_f(y) - 0.5;
  const double c0f = std::floor(fx), r0f = std::floor(fy);
  const double ax = fx - c0f, ay = fy - r0f;
  const auto c0 = static_cast<std::int32_t>(c0f), r0 = static_cast<std::int32_t>(r0f);
  const auto at = [&](std::int32_t c, std::int32_t r) {
    return static_cast<double>(w.surface_at(std::clamp(c, 0, g.width - 1), std::clamp(r, 0, g.height - 1)));
  };
  return (1 - ay) * ((1 - ax) * at(c0, r0) + ax * at(c0 + 1, r0)) + ay * ((1 - ax) * at(c0, r0 + 1) + ax * at(c0 + 1, r0 + 1));
}

constexpr double kCollisionEventGap_s = 1.0;  // colliding steps closer than this in time are one event

}  // namespace

std::span<const ParamSection> diff_drive_config_schema() noexcept { return kDriveSchema; }

Result<DiffDriveConfig> load_diff_drive_config(const YAML::Node& node, std::string_view origin) {
  return drive_from(load_model_params(kDriveSchema, node, origin));
}
Result<DiffDriveConfig> load_diff_drive_config(std::string_view yaml, std::string_view origin) {
  return drive_from(load_model_params(kDriveSchema, yaml, origin));
}

DiffDriveRobot::DiffDriveRobot(const DiffDriveConfig& cfg, const Pose2& start) : cfg_(cfg), pose_(start) {}

void DiffDriveRobot::command_wheels(double left_rad_s, double right_rad_s) noexcept {
  cmd_left_ = clamp_abs(left_rad_s, cfg_.max_wheel_speed_rad_s);
  cmd_right_ = clamp_abs(right_rad_s, cfg_.max_wheel_speed_rad_s);
  since_command_ = 0.0;
}

void DiffDriveRobot::command_twist(double v_mps, double omega_rad_s) noexcept {
  const double half = 0.5 * cfg_.track_width_m * omega_rad_s;
  command_wheels((v_mps - half) / cfg_.wheel_radius_m, (v_mps + half) / cfg_.wheel_radius_m);
}

void DiffDriveRobot::reset(const Pose2& pose) noexcept {
  pose_ = pose;
  v_ = omega_ = wheel_left_ = wheel_right_ = cmd_left_ = cmd_right_ = 0.0;
  since_command_ = 0.0;
  have_z_ = false;
  in_collision_ = false;
}

bool DiffDriveRobot::blocks(ClassId c) const noexcept {
  switch (c) {
    case ClassId::kBuilding: return cfg_.block_building;
    case ClassId::kTree: return cfg_.block_tree;
    case ClassId::kVehicle: return cfg_.block_vehicle;
    case ClassId::kWater: return cfg_.block_water;
    default: return false;
  }
}

namespace {
// The disc enters the cell when the cell's nearest point to the centre is inside the disc.
bool disc_enters(const GridGeometry& g, double x, double y, double rad, std::int32_t c, std::int32_t r) noexcept {
  const double cx0 = g.origin_x + c * g.resolution, cy1 = g.origin_y - r * g.resolution;
  const double nx = std::clamp(x, cx0, cx0 + g.resolution) - x;
  const double ny = std::clamp(y, cy1 - g.resolution, cy1) - y;
  return nx * nx + ny * ny < rad * rad;
}
}  // namespace

bool DiffDriveRobot::enters_obstacle(const World& world, double x, double y, double ground_z,
                                     const Pose2* from) const noexcept {
  const GridGeometry& g = world.grid();
  const double rad = cfg_.footprint_radius_m;
  const auto c0 = g.col(x - rad), c1 = g.col(x + rad);
  const auto r0 = g.row(y + rad), r1 = g.row(y - rad);  // rows grow southwards
  for (auto r = r0; r <= r1; ++r) {
    for (auto c = c0; c <= c1; ++c) {
      if (!disc_enters(g, x, y, rad, c, r)) continue;
      // Cells the robot already stands on are not obstacles: it can back off a step it just came down
      // and leave whatever it was placed on.
      if (from != nullptr && disc_enters(g, from->x, from->y, rad, c, r)) continue;
      if (!g.contains(c, r)) return true;  // the world's edge is a wall
      if (blocks(world.class_at(c, r))) return true;
      if (static_cast<double>(world.surface_at(c, r)) - ground_z > cfg_.max_step_height_m) return true;
    }
  }
  return false;
}

bool DiffDriveRobot::footprint_free(const World& world, double x, double y, double ground_z) const noexcept {
  return !enters_obstacle(world, x, y, ground_z, nullptr);
}

void DiffDriveRobot::update_attitude(const World& world) noexcept {
  ground_z_ = cell_surface_or(world, pose_.x, pose_.y, ground_z_);
  z_ = smooth_surface_or(world, pose_.x, pose_.y, ground_z_);
  const double rad = cfg_.footprint_radius_m, c = std::cos(pose_.yaw), s = std::sin(pose_.yaw);
  const double front = smooth_surface_or(world, pose_.x + rad * c, pose_.y + rad * s, z_);
  const double back = smooth_surface_or(world, pose_.x - rad * c, pose_.y - rad * s, z_);
  const double left = smooth_surface_or(world, pose_.x - rad * s, pose_.y + rad * c, z_);
  const double right = smooth_surface_or(world, pose_.x + rad * s, pose_.y - rad * c, z_);
  pitch_ = -std::atan2(front - back, 2.0 * rad);  // REP-103: nose up is negative pitch
  roll_ = std::atan2(left - right, 2.0 * rad);    // left side up is positive roll
  have_z_ = true;
}

bool DiffDriveRobot::step(double dt, const World& world) {
  if (!(dt > 0)) return false;
  if (!have_z_) update_attitude(world);
  sim_time_ += dt;

  since_command_ += dt;
  double cl = cmd_left_, cr = cmd_right_;
  if (cfg_.command_timeout_s > 0 && since_command_ > cfg_.command_timeout_s) cl = cr = 0.0;

  // Accelerate in (v, omega) toward the command, then keep both wheels within their speed limit.
  const double r = cfg_.wheel_radius_m, w = cfg_.track_width_m;
  const double v_cmd = 0.5 * r * (cl + cr), om_cmd = r * (cr - cl) / w;
  double v = v_ + clamp_abs(v_cmd - v_, cfg_.max_linear_accel_mps2 * dt);
  double om = omega_ + clamp_abs(om_cmd - omega_, cfg_.max_angular_accel_radps2 * dt);
  double wl = (v - 0.5 * w * om) / r, wr = (v + 0.5 * w * om) / r;
  const double peak = std::max(std::abs(wl), std::abs(wr));
  if (peak > cfg_.max_wheel_speed_rad_s) {
    const double k = cfg_.max_wheel_speed_rad_s / peak;
    wl *= k;
    wr *= k;
    v *= k;
    om *= k;
  }

  // Exact arc, checked at sub-steps of at most half a cell so that thin walls are not jumped.
  const double arc = std::abs(v) * dt;
  const int n = std::max(1, static_cast<int>(std::ceil(arc / (0.5 * world.grid().resolution))));
  const Pose2 start = pose_;
  bool hit = false;
  Pose2 p = start;
  for (int i = 1; i <= n && !hit; ++i) {
    const Pose2 before = p;
    const double t = dt * i / n;
    if (std::abs(om) < 1e-9) {
      p.x = start.x + v * t * std::cos(start.yaw);
      p.y = start.y + v * t * std::sin(start.yaw);
      p.yaw = start.yaw;
    } else {
      const double yaw1 = start.yaw + om * t;
      p.x = start.x + v / om * (std::sin(yaw1) - std::sin(start.yaw));
      p.y = start.y - v / om * (std::cos(yaw1) - std::cos(start.yaw));
      p.yaw = wrap_angle(yaw1);
    }
    hit = arc > 0 && enters_obstacle(world, p.x, p.y, ground_z_, &before);
  }

  if (hit) {
    pose_ = start;
    v_ = omega_ = wheel_left_ = wheel_right_ = 0.0;
    // Creeping into a wall alternates tiny free steps and colliding ones: that is still one collision.
    if (collision_steps_ == 0 || sim_time_ - last_collision_time_ > kCollisionEventGap_s) ++collisions_;
    last_collision_time_ = sim_time_;
    ++collision_steps_;
    in_collision_ = true;
    return true;
  }
  in_collision_ = false;
  pose_ = p;
  v_ = v;
  omega_ = om;
  wheel_left_ = wl;
  wheel_right_ = wr;
  distance_ += arc;
  update_attitude(world);
  return false;
}

DiffDriveConfig with_wheels(DiffDriveConfig c, double wheel_radius_m, double track_width_m) noexcept {
  c.max_wheel_speed_rad_s = c.max_wheel_speed_rad_s * c.wheel_radius_m / wheel_radius_m;
  c.wheel_radius_m = wheel_radius_m;
  c.track_width_m = track_width_m;
  return c;
}

}  // namespace ag::sim
