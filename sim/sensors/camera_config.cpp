// The simulated camera's YAML sections (camera, camera_shading, camera_sensor): the schema with units and
// ranges, and loading them into CameraModel, CameraShading and CameraSensor.
#include <string>
#include <string_view>

#include "airground/platform/config.hpp"
#include "airground/sim/camera.hpp"

namespace ag::sim {

namespace {

constexpr CameraModel kDefaultModel{};
constexpr CameraShading kDefaultShading{};

constexpr ParamSpec kCameraParams[] = {
    ParamSpec::integer("width", kDefaultModel.width, 16, 16384, "px", "image width"),
    ParamSpec::integer("height", kDefaultModel.height, 16, 16384, "px", "image height"),
    ParamSpec::real("fx", kDefaultModel.fx, 1.0, 1.0e5, "px", "focal length along x"),
    ParamSpec::real("fy", kDefaultModel.fy, 1.0, 1.0e5, "px", "focal length along y"),
    ParamSpec::real("cx", kDefaultModel.cx, -0.5, 16383.5, "px", "principal point x (pixel centres are integers)"),
    ParamSpec::real("cy", kDefaultModel.cy, -0.5, 16383.5, "px", "principal point y"),
    ParamSpec::real("k1", kDefaultModel.k1, -5.0, 5.0, "", "radial distortion r^2"),
    ParamSpec::real("k2", kDefaultModel.k2, -5.0, 5.0, "", "radial distortion r^4"),
    ParamSpec::real("p1", kDefaultModel.p1, -1.0, 1.0, "", "tangential distortion"),
    ParamSpec::real("p2", kDefaultModel.p2, -1.0, 1.0, "", "tangential distortion"),
    ParamSpec::real("k3", kDefaultModel.k3, -5.0, 5.0, "", "radial distortion r^6"),
};
constexpr ParamSpec kShadingParams[] = {
    ParamSpec::real("sun_azimuth_deg", kDefaultShading.sun_azimuth_deg, 0.0, 360.0, "deg",
                    "compass azimuth of the sun, clockwise from north"),
    ParamSpec::real("sun_elevation_deg", kDefaultShading.sun_elevation_deg, 1.0, 90.0, "deg", "sun above the horizon"),
    ParamSpec::real("ambient", kDefaultShading.ambient, 0.0, 1.0, "", "light share reaching shadowed surfaces"),
    ParamSpec::boolean("shadows", kDefaultShading.shadows, "cast shadows (a second ray toward the sun)"),
    ParamSpec::boolean("detail_texture", kDefaultShading.detail_texture, "world-fixed fine texture for stereo"),
    ParamSpec::real("max_range_m", kDefaultShading.max_range_m, 1.0, 1.0e6, "m", "longest ray; beyond is sky"),
};
constexpr CameraSensor kDefaultSensor = CameraSensor::field();  // a section's defaults: the real camera
constexpr ParamSpec kSensorParams[] = {
    ParamSpec::boolean("noise", kDefaultSensor.noise, "photon shot and read noise, gain, 8-bit quantisation"),
    ParamSpec::real("full_well_e", kDefaultSensor.full_well_e, 100.0, 1.0e6, "e-", "full-well capacity per sensor pixel"),
    ParamSpec::real("read_noise_e", kDefaultSensor.read_noise_e, 0.0, 1000.0, "e-", "read (temporal dark) noise rms per sensor pixel"),
    ParamSpec::integer("sensor_width_px", kDefaultSensor.sensor_width_px, 16, 16384, "px",
                       "native sensor width; a rendered pixel averages (this / width)^2 sensor pixels"),
    ParamSpec::real("full_scale_exposure_s", kDefaultSensor.full_scale_exposure_s, 1.0e-6, 1.0, "s",
                    "exposure at gain 1 that fills the well on a white sun-lit surface"),
    ParamSpec::boolean("auto_exposure", kDefaultSensor.auto_exposure, "exposure and gain follow the frame mean"),
    ParamSpec::real("exposure_s", kDefaultSensor.exposure_s, 1.0e-6, 1.0, "s", "fixed exposure; the auto-exposure's first"),
    ParamSpec::real("gain", kDefaultSensor.gain, 1.0, 256.0, "", "fixed gain; the auto-exposure's first"),
    ParamSpec::real("exposure_min_s", kDefaultSensor.exposure_min_s, 1.0e-6, 1.0, "s", "shortest exposure"),
    ParamSpec::real("exposure_max_s", kDefaultSensor.exposure_max_s, 1.0e-6, 1.0, "s", "longest exposure; then gain"),
    ParamSpec::real("gain_max", kDefaultSensor.gain_max, 1.0, 256.0, "", "highest gain"),
    ParamSpec::real("ae_target", kDefaultSensor.ae_target, 0.05, 0.95, "", "frame mean aimed at, share of full scale"),
    ParamSpec::real("ae_speed", kDefaultSensor.ae_speed, 0.05, 1.0, "", "share of the log error corrected per frame"),
    ParamSpec::real("ae_tolerance", kDefaultSensor.ae_tolerance, 0.0, 0.5, "", "relative error within which exposure is held"),
    ParamSpec::boolean("motion_blur", kDefaultSensor.motion_blur, "average sub-exposure samples along the motion"),
    ParamSpec::integer("blur_max_samples", kDefaultSensor.blur_max_samples, 1, 63, "", "most sub-exposure samples per pixel (odd)"),
    ParamSpec::boolean("vignetting", kDefaultSensor.vignetting, "cos^k illumination falloff toward the corners"),
    ParamSpec::real("corner_illumination", kDefaultSensor.corner_illumination, 0.05, 1.0, "",
                    "illumination at the farthest image corner relative to the centre"),
};
constexpr ParamSection kCameraSchema[] = {
    {"camera", kCameraParams, "simulated nadir camera intrinsics (OpenCV model)"},
    {"camera_shading", kShadingParams, "lighting and texture of the simulated camera"},
    {"camera_sensor", kSensorParams, "noise, exposure, motion blur and vignetting of the simulated camera"},
};

Result<Config> load_camera_config(std::string_view yaml, std::string_view origin) {
  return Config::load_string(kCameraSchema, yaml, origin);
}
Result<Config> load_camera_config_file(const std::string& path) { return Config::load_file(kCameraSchema, path); }

Result<CameraModel> model_from(const Result<Config>& cfg, std::string_view origin) {
  if (!cfg) return cfg.error();
  const SectionView s(cfg.value(), "camera");
  CameraModel m;
  m.width = static_cast<int>(s.integer("width"));
  m.height = static_cast<int>(s.integer("height"));
  m.fx = s.real("fx");
  m.fy = s.real("fy");
  m.cx = s.real("cx");
  m.cy = s.real("cy");
  m.k1 = s.real("k1");
  m.k2 = s.real("k2");
  m.p1 = s.real("p1");
  m.p2 = s.real("p2");
  m.k3 = s.real("k3");
  if (auto st = m.check(); !st)
    return Error::make(ErrorCode::kConfig, "config error: " + std::string(origin) + ": " + st.error().message);
  return m;
}

Result<CameraShading> shading_from(const Result<Config>& cfg) {
  if (!cfg) return cfg.error();
  const SectionView s(cfg.value(), "camera_shading");
  CameraShading sh;
  sh.sun_azimuth_deg = s.real("sun_azimuth_deg");
  sh.sun_elevation_deg = s.real("sun_elevation_deg");
  sh.ambient = s.real("ambient");
  sh.shadows = s.boolean("shadows");
  sh.detail_texture = s.boolean("detail_texture");
  sh.max_range_m = s.real("max_range_m");
  return sh;
}

Result<CameraSensor> sensor_from(const Result<Config>& cfg, std::string_view origin) {
  if (!cfg) return cfg.error();
  const SectionView s(cfg.value(), "camera_sensor");
  CameraSensor c;
  c.noise = s.boolean("noise");
  c.full_well_e = s.real("full_well_e");
  c.read_noise_e = s.real("read_noise_e");
  c.sensor_width_px = static_cast<int>(s.integer("sensor_width_px"));
  c.full_scale_exposure_s = s.real("full_scale_exposure_s");
  c.auto_exposure = s.boolean("auto_exposure");
  c.exposure_s = s.real("exposure_s");
  c.gain = s.real("gain");
  c.exposure_min_s = s.real("exposure_min_s");
  c.exposure_max_s = s.real("exposure_max_s");
  c.gain_max = s.real("gain_max");
  c.ae_target = s.real("ae_target");
  c.ae_speed = s.real("ae_speed");
  c.ae_tolerance = s.real("ae_tolerance");
  c.motion_blur = s.boolean("motion_blur");
  c.blur_max_samples = static_cast<int>(s.integer("blur_max_samples"));
  c.vignetting = s.boolean("vignetting");
  c.corner_illumination = s.real("corner_illumination");
  if (auto st = c.check(); !st)
    return Error::make(ErrorCode::kConfig, "config error: " + std::string(origin) + ": " + st.error().message);
  return c;
}

}  // namespace

Result<CameraModel> CameraModel::load_string(std::string_view yaml, std::string_view origin) {
  return model_from(load_camera_config(yaml, origin), origin);
}
Result<CameraModel> CameraModel::load_file(const std::string& path) {
  return model_from(load_camera_config_file(path), path);
}
Result<CameraShading> CameraShading::load_string(std::string_view yaml, std::string_view origin) {
  return shading_from(load_camera_config(yaml, origin));
}
Result<CameraShading> CameraShading::load_file(const std::string& path) {
  return shading_from(load_camera_config_file(path));
}
Result<CameraSensor> CameraSensor::load_string(std::string_view yaml, std::string_view origin) {
  return sensor_from(load_camera_config(yaml, origin), origin);
}
Result<CameraSensor> CameraSensor::load_file(const std::string& path) {
  return sensor_from(load_camera_config_file(path), path);
}

}  // namespace ag::sim
