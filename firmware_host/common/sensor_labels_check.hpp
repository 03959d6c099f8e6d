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
// - localization.labels gt needs point classes: refused when lidar.classes is none and lidar.source is not none;
// - lidar.classes reflectivity with a live LiDAR reads each point's class from the Ouster's reflectivity
//   byte, where only the simulator's labels oracle writes classes: refused unless `labels_oracle` (the
//   user named the ablation: `--oracle labels` on the role binary, as airground-sim hil passes it).
// `origin` names the configuration (a file) in the message.
[[nodiscard]] Status check_sensor_labels(const Config& c, std::string_view origin, bool labels_oracle = false);

// Said at start-up (and by --check-config) when the labels oracle is named and the configuration uses it:
// the run is a ground-truth ablation, not field mode.
[[nodiscard]] std::vector<std::string> sensor_label_warnings(const Config& c, bool labels_oracle);

}  // namespace ag
