// Localization channels: which scan labels and which aerial classes are compared with each other.
#include <stdexcept>
#include <utility>

#include "airground/localization/scan.hpp"

namespace ag::loc {

LocalizationChannels::LocalizationChannels() noexcept {
  scan_.fill(-1);
  fine_.fill(-1);
}

int LocalizationChannels::add_channel(std::string name, double weight) {
  if (count_ >= kMaxChannels) throw std::invalid_argument("LocalizationChannels: more than kMaxChannels channels");
  const auto k = static_cast<std::size_t>(count_);
  name_[k] = std::move(name);
  weight_[k] = static_cast<float>(weight);
  return count_++;
}

LocalizationChannels LocalizationChannels::per_class(const ClassTable& table) {
  LocalizationChannels c;
  for (const ClassInfo& info : table.all()) {
    if (info.id == ClassId::kUnknown || info.localization_weight <= 0.0) continue;
    const int k = c.add_channel(info.name, info.localization_weight);
    c.count_scan_label(raw(info.id), k);
    c.add_map_source(raw(info.id), k);
    if (info.traversability == Traversability::kBlocked) c.set_obstacle_space(k);
  }
  return c;
}

LocalizationChannels LocalizationChannels::two_class(double ground_weight, double obstacle_weight, bool obstacle_faces) {
  LocalizationChannels c;
  const int ground = c.add_channel("ground", ground_weight);
  const int obstacle = c.add_channel("obstacle", obstacle_weight);
  c.set_obstacle_space(obstacle);
  for (const ClassId id : {ClassId::kRoad, ClassId::kDirt, ClassId::kGrass, ClassId::kWater}) {
    c.count_scan_label(raw(id), ground);
    c.add_map_source(raw(id), ground);
  }
  for (const ClassId id : {ClassId::kTree, ClassId::kBuilding, ClassId::kVehicle}) {
    c.count_scan_label(raw(id), obstacle);
    c.add_map_source(raw(id), obstacle);
  }
  if (!obstacle_faces) return c;
  const int faces = c.add_channel("obstacle faces", obstacle_weight);
  c.set_surface(faces, true);
  for (const ClassId id : {ClassId::kTree, ClassId::kBuilding, ClassId::kVehicle}) {
    c.count_scan_label_fine(raw(id), faces, kFacesMaxBinM);
    c.add_map_source(raw(id), faces);
  }
  return c;
}

int LocalizationChannels::add_off_route(Traversability level, const ClassTable& table) {
  const int k = add_channel("off route", 0.0);
  for (const ClassInfo& info : table.all())
    if (info.id != ClassId::kUnknown && static_cast<int>(info.traversability) > static_cast<int>(level)) add_map_source(raw(info.id), k);
  obstacle_ = static_cast<std::uint8_t>(1U << static_cast<unsigned>(k));
  return k;
}

}  // namespace ag::loc
