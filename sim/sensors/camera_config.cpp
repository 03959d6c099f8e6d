// The simulated camera's YAML sections (camera, camera_shading, camera_sensor): the schema with units and
// ranges, and loading them into CameraModel, CameraShading and CameraSensor.
#include <string>
#include <string_view>

#include "airground/platform/config.hpp"
#include "airground/platform/param_binding.hpp"
#include "airground/sim/camera.hpp"

namespace ag::sim {

namespace {

constexpr ParamField<CameraModel> kCameraFields[] = {
    field::integer("width", &CameraModel::width, 16, 16384, "px", "image width"),
    field::integer("height", &CameraModel::height, 16, 16384, "px", "image height"),
    field::real("fx", &CameraModel::fx, 1.0, 1.0e5, "px", "focal length along x"),
    field::real("fy", &CameraModel::fy, 1.0, 1.0e5, "px", "focal length along y"),
    field::real("cx", &CameraModel::cx, -0.5, 16383.5, "px", "principal point x (pixel centres are integers)"),
    field::real("cy", &CameraModel::cy, -0.5, 16383.5, "px", "principal point y"),
    field::real("k1", &CameraModel::k1, -5.0, 5.0, "", "radial distortion r^2"),
    field::real("k2", &CameraModel::k2, -5.0, 5.0, "", "radial distortion r^4"),
    field::real("p1", &CameraModel::p1, -1.0, 1.0, "", "tangential distortion"),
    field::real("p2", &CameraModel::p2, -1.0, 1.0, "", "tangential distortion"),
    field::real("k3", &CameraModel::k3, -5.0, 5.0, "", "radial distortion r^6"),
};
constexpr auto kCameraParams = param_specs(kCameraFields);
constexpr ParamField<CameraShading> kShadingFields[] = {
    field::real("sun_azimuth_deg", &CameraShading::sun_azimuth_deg, 0.0, 360.0, "deg",
                "compass azimuth of the sun, clockwise from north"),
    field::real("sun_elevation_deg", &CameraShading::sun_elevation_deg, 1.0, 90.0, "deg", "sun above the horizon"),
    field::real("ambient", &CameraShading::ambient, 0.0, 1.0, "", "light share reaching shadowed surfaces"),
    field::boolean("shadows", &CameraShading::shadows, "cast shadows (a second ray toward the sun)"),
    field::boolean("detail_texture", &CameraShading::detail_texture, "world-fixed fine texture for stereo"),
    field::real("max_range_m", &CameraShading::max_range_m, 1.0, 1.0e6, "m", "longest ray; beyond is sky"),
};
constexpr auto kShadingParams = param_specs(kShadingFields);
// The camera_sensor section's defaults are the real camera's, CameraSensor::field() (every effect on), not
// the ideal camera a default-constructed CameraSensor is: its rows bind the members of this struct.
struct FieldCameraSensor : CameraSensor {
  constexpr FieldCameraSensor() noexcept : CameraSensor(CameraSensor::field()) {}
};
// A CameraSensor member as a member of FieldCameraSensor, so that its row's default is field()'s.
template <class T>
constexpr auto sensor_member(T CameraSensor::*m) noexcept -> T FieldCameraSensor::* {
  return m;
}
constexpr ParamField<FieldCameraSensor> kSensorFields[] = {
    field::boolean("noise", sensor_member(&CameraSensor::noise), "photon shot and read noise, gain, 8-bit quantisation"),
    field::real("full_well_e", sensor_member(&CameraSensor::full_well_e), 100.0, 1.0e6, "e-", "full-well capacity per sensor pixel"),
    field::real("read_noise_e", sensor_member(&CameraSensor::read_noise_e), 0.0, 1000.0, "e-", "read (temporal dark) noise rms per sensor pixel"),
    field::integer("sensor_width_px", sensor_member(&CameraSensor::sensor_width_px), 16, 16384, "px",
                   "native sensor width; a rendered pixel averages (this / width)^2 sensor pixels"),
    field::real("full_scale_exposure_s", sensor_member(&CameraSensor::full_scale_exposure_s), 1.0e-6, 1.0, "s",
                "exposure at gain 1 that fills the well on a white sun-lit surface"),
    field::boolean("auto_exposure", sensor_member(&CameraSensor::auto_exposure), "exposure and gain follow the frame mean"),
    field::real("exposure_s", sensor_member(&CameraSensor::exposure_s), 1.0e-6, 1.0, "s", "fixed exposure; the auto-exposure's first"),
    field::real("gain", sensor_member(&CameraSensor::gain), 1.0, 256.0, "", "fixed gain; the auto-exposure's first"),
    field::real("exposure_min_s", sensor_member(&CameraSensor::exposure_min_s), 1.0e-6, 1.0, "s", "shortest exposure"),
    field::real("exposure_max_s", sensor_member(&CameraSensor::exposure_max_s), 1.0e-6, 1.0, "s", "longest exposure; then gain"),
    field::real("gain_max", sensor_member(&CameraSensor::gain_max), 1.0, 256.0, "", "highest gain"),
    field::real("ae_target", sensor_member(&CameraSensor::ae_target), 0.05, 0.95, "", "frame mean aimed at, share of full scale"),
    field::real("ae_speed", sensor_member(&CameraSensor::ae_speed), 0.05, 1.0, "", "share of the log error corrected per frame"),
    field::real("ae_tolerance", sensor_member(&CameraSensor::ae_tolerance), 0.0, 0.5, "", "relative error within which exposure is held"),
    field::boolean("motion_blur", sensor_member(&CameraSensor::motion_blur), "average sub-exposure samples along the motion"),
    field::integer("blur_max_samples", sensor_member(&CameraSensor::blur_max_samples), 1, 63, "", "most sub-exposure samples per pixel (odd)"),
    field::boolean("vignetting", sensor_member(&CameraSensor::vignetting), "cos^k illumination falloff toward the corners"),
    field::real("corner_illumination", sensor_member(&CameraSensor::corner_illumination), 0.05, 1.0, "",
                "illumination at the farthest image corner relative to the centre"),
};
constexpr auto kSensorParams = param_specs(kSensorFields);
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
  const CameraModel m = load_params(s, kCameraFields);
  if (auto st = m.check(); !st)
    return Error::make(ErrorCode::kConfig, "config error: " + std::string(origin) + ": " + st.error().message);
  return m;
}

Result<CameraShading> shading_from(const Result<Config>& cfg) {
  if (!cfg) return cfg.error();
  const SectionView s(cfg.value(), "camera_shading");
  return load_params(s, kShadingFields);
}

Result<CameraSensor> sensor_from(const Result<Config>& cfg, std::string_view origin) {
  if (!cfg) return cfg.error();
  const SectionView s(cfg.value(), "camera_sensor");
  const CameraSensor c = load_params(s, kSensorFields);  // FieldCameraSensor, as the CameraSensor it is
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
