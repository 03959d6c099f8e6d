// The start-up check of where a role's classes come from (see sensor_labels_check.hpp).
#include "sensor_labels_check.hpp"

#include <string>

namespace ag {

namespace {
bool is(const Config& c, std::string_view key, std::string_view value) { return c.has(key) && c.get_text(key) == value; }
bool live_lidar(const Config& c) { return c.has("lidar.source") && c.get_text("lidar.source") != "none"; }

Status refuse(std::string_view origin, const std::string& why) {
  return Error::make(ErrorCode::kConfig, "config error: " + std::string(origin) + ": " + why);
}
}  // namespace

Status check_sensor_labels(const Config& c, std::string_view origin, bool labels_oracle) {
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
  if (is(c, "localization.labels", "gt") && is(c, "lidar.classes", "none") && live_lidar(c))
    return refuse(origin, "localization.labels: gt needs point classes, and lidar.classes: none gives every point unknown (an Ouster "
                          "measures range and reflectivity, not classes): the localizer would get no labelled points; use "
                          "localization.labels: geometric (docs/localization.md)");
  if (is(c, "lidar.classes", "reflectivity") && live_lidar(c) && !labels_oracle)
    return refuse(origin, "lidar.classes: reflectivity reads each point's class from the LiDAR's reflectivity byte, and a real Ouster "
                          "writes reflectivity there, not classes: the localizer would take reflectivity values for classes; use "
                          "lidar.classes: none with localization.labels: geometric (docs/localization.md), or name the ablation "
                          "with --oracle labels (only airground-sim hil's --oracle labels writes classes into that byte)");
  return ok_status();
}

std::vector<std::string> sensor_label_warnings(const Config& c, bool labels_oracle) {
  std::vector<std::string> w;
  if (labels_oracle && is(c, "lidar.classes", "reflectivity") && live_lidar(c))
    w.emplace_back("oracle labels: lidar.classes: reflectivity takes each point's class from the LiDAR's reflectivity byte (the "
                   "simulator's ground truth): a ground-truth ablation, not field mode");
  if (labels_oracle && is(c, "segmentation.labels", "gt"))
    w.emplace_back("oracle labels: segmentation.labels: gt relays the camera frames' classes (the simulator's ground truth): a "
                   "ground-truth ablation, not field mode");
  return w;
}

}  // namespace ag
