// The start-up check of where a role's classes come from (see sensor_labels_check.hpp).
#include "sensor_labels_check.hpp"

#include <string>

namespace ag {

namespace {
bool is(const Config& c, std::string_view key, std::string_view value) { return c.has(key) && c.get_text(key) == value; }

Status refuse(std::string_view origin, const std::string& why) {
  return Error::make(ErrorCode::kConfig, "config error: " + std::string(origin) + ": " + why);
}
}  // namespace

Status check_sensor_labels(const Config& c, std::string_view origin) {
  const bool v4l2 = is(c, "camera.source", "v4l2");
  if (is(c, "segmentation.labels", "gt") && v4l2)
    return refuse(origin, "segmentation.labels: gt relays the camera driver's classes, and camera.source: v4l2 delivers RGB only "
                          "(no classes): the map would have none; use segmentation.labels: erfnet with segmentation.weights "
                          "(docs/segmentation.md)");
  if (is(c, "segmentation.labels", "erfnet") && is(c, "ortho_map.keyframes_channel", "keyframes"))
    return refuse(origin, "segmentation.labels: erfnet with ortho_map.keyframes_channel: keyframes: the mapper would never see "
                          "ErfNet's classes; set ortho_map.keyframes_channel: keyframes_labelled");
  if (is(c, "ortho_map.keyframes_channel", "keyframes") && v4l2)
    return refuse(origin, "ortho_map.keyframes_channel: keyframes carries the camera driver's classes, and camera.source: v4l2 "
                          "delivers RGB only: the map would have no classes; set ortho_map.keyframes_channel: keyframes_labelled "
                          "with segmentation.labels: erfnet");
  if (is(c, "localization.labels", "gt") && is(c, "lidar.classes", "none") && c.has("lidar.source") && c.get_text("lidar.source") != "none")
    return refuse(origin, "localization.labels: gt needs point classes, and lidar.classes: none gives every point unknown (an Ouster "
                          "measures range and reflectivity, not classes): the localizer would get no labelled points; use "
                          "localization.labels: geometric (docs/localization.md)");
  return ok_status();
}

std::vector<std::string> sensor_label_warnings(const Config& c) {
  std::vector<std::string> w;
  if (is(c, "lidar.classes", "reflectivity") && c.has("lidar.source") && c.get_text("lidar.source") != "none")
    w.emplace_back("lidar.classes: reflectivity reads each point's class from the LiDAR's reflectivity byte, where only airground-sim "
                   "hil's --oracle labels ablation writes classes: on a real Ouster the localizer would take reflectivity values for "
                   "classes; use lidar.classes: none with localization.labels: geometric (docs/localization.md)");
  return w;
}

}  // namespace ag
