// The start-up check that a role's classes come from something its sensors can give: a configuration
// that cannot work on the robot (a V4L2 camera has no classes, an Ouster gives no point classes) is
// refused before any stage starts, naming the keys.
#pragma once

#include <string>
#include <string_view>
#include <vector>

#include "airground/platform/config.hpp"
#include "airground/platform/result.hpp"

namespace ag {

// Checks the keys a role has (a config without a section passes that rule):
// - segmentation.labels gt relays the camera driver's classes: refused when camera.source is v4l2;
// - segmentation.labels erfnet with ortho_map.keyframes_channel keyframes: the mapper would never see
//   ErfNet's classes;
// - ortho_map.keyframes_channel keyframes with a V4L2 camera: the mapper's keyframes carry no classes;
// - localization.labels gt needs point classes: refused when lidar.classes is none and lidar.source is not none.
// `origin` names the configuration (a file) in the message.
[[nodiscard]] Status check_sensor_labels(const Config& c, std::string_view origin);

// What may work but most likely does not on a real robot, said at start-up (and by --check-config):
// - lidar.classes reflectivity with a live LiDAR: the class of each point is read from the Ouster's
//   reflectivity byte, where only airground-sim hil's --oracle labels ablation writes classes.
[[nodiscard]] std::vector<std::string> sensor_label_warnings(const Config& c);

}  // namespace ag
