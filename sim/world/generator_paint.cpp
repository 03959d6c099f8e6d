// The generated world's aerial colour: the albedo of every class, then road paint (lanes, zebra crossings,
// parking bays, the staging pad), car glass and roof ridges.
#include <opencv2/imgproc.hpp>

#include <algorithm>
#include <cmath>
#include <vector>

#include "airground/sim/world_texture.hpp"
#include "generator_town.hpp"

namespace ag::sim::generator {

void ProceduralTown::paint() {
  w_.albedo = paint_albedo(w_.class_id, w_.height, g_.resolution, derive_seed(seed_, kPaint));
  Rng rng(derive_seed(seed_, kMarkings));
  cv::Mat lane_white(g_.height, g_.width, CV_8UC1, cv::Scalar(0));
  cv::Mat lane_yellow(g_.height, g_.width, CV_8UC1, cv::Scalar(0));
  cv::Mat paint_white(g_.height, g_.width, CV_8UC1, cv::Scalar(0));  // crossings and bays: also inside junctions
  cv::Mat paint_yellow(g_.height, g_.width, CV_8UC1, cv::Scalar(0));
  const double line_w = std::max(0.15, g_.resolution * 0.7);
  const auto dashed = [&](cv::Mat& m, const std::vector<P2>& line, double dash, double gap) {
    const double len = length_of(line);
    for (double s = rng.uniform(0, dash + gap); s + dash < len; s += dash + gap) {
      std::vector<P2> piece;
      for (double u = s; u <= s + dash + 1e-9; u += 0.5) piece.push_back(along(line, u).first);
      draw_polyline(m, piece, line_w, 255, cv::LINE_AA);
    }
  };
  for (const Road& road : roads_) {
    if (road.width >= 6.5) dashed(road.yellow_centre ? lane_yellow : lane_white, road.centre, 3.0, 5.0);
    if (road.width >= 7.5) {
      const double edge = road.width / 2 - kCurbWidth - 0.35;
      draw_polyline(lane_white, offset_polyline(road.centre, edge), line_w, 255, cv::LINE_AA);
      draw_polyline(lane_white, offset_polyline(road.centre, -edge), line_w, 255, cv::LINE_AA);
    }
  }
  // Zebra crossings on some arms of the grid junctions.
  for (std::size_t j = 0; j < ew_y_.size(); ++j) {
    for (std::size_t i = 0; i < ns_x_.size(); ++i) {
      const bool west = ew_segment_[j][i], east = ew_segment_[j][i + 1];
      if (!west && !east) continue;
      const auto zebra = [&](P2 centre, double yaw, double road_w) {  // stripes run along the road
        const double usable = road_w / 2 - kCurbWidth - 0.4;
        for (double v = -usable + 0.25; v <= usable - 0.25; v += 1.0) {
          const P2 off(-std::sin(yaw) * v, std::cos(yaw) * v);
          fill_box(paint_white, Box{centre + off, 1.5, 0.25, yaw}, 255, cv::LINE_AA);
        }
      };
      const P2 x(ns_x_[i], ew_y_[j]);
      for (const double dir : {-1.0, 1.0}) {  // arms of the north-south road
        if (rng.bernoulli(0.35)) zebra(x + P2(0, dir * (ew_w_[j] / 2 + 2.5)), kPi / 2, ns_w_[i]);
      }
      if (west && rng.bernoulli(0.35)) zebra(x - P2(ns_w_[i] / 2 + 2.5, 0), 0.0, ew_w_[j]);
      if (east && rng.bernoulli(0.35)) zebra(x + P2(ns_w_[i] / 2 + 2.5, 0), 0.0, ew_w_[j]);
    }
  }
  // Parking bays: the lines between them.
  for (const Box& bay : bays_) {
    const double cs = std::cos(bay.yaw), sn = std::sin(bay.yaw);
    for (const double side : {-1.0, 1.0}) {
      const P2 v(-sn * bay.half_wid * side, cs * bay.half_wid * side), u(cs * bay.half_len, sn * bay.half_len);
      draw_polyline(paint_white, {bay.c + v - u, bay.c + v + u}, line_w, 255, cv::LINE_AA);
    }
  }
  // The staging pad: a yellow border and cross, easy to find from the air.
  {
    const Box pad{staging_.c - P2(kCurbWidth / 2, 0), kStagingPad / 2 - 0.8, kStagingPad / 2 - 0.8, 0};
    const P2 a = pad.c + P2(-pad.half_len, -pad.half_wid), b = pad.c + P2(pad.half_len, -pad.half_wid);
    const P2 c = pad.c + P2(pad.half_len, pad.half_wid), d = pad.c + P2(-pad.half_len, pad.half_wid);
    draw_polyline(paint_yellow, {a, b, c, d, a}, 0.4, 255, cv::LINE_AA);
    draw_polyline(paint_yellow, {a + (c - a) * 0.3, a + (c - a) * 0.7}, 0.4, 255, cv::LINE_AA);
    draw_polyline(paint_yellow, {b + (d - b) * 0.3, b + (d - b) * 0.7}, 0.4, 255, cv::LINE_AA);
  }
  const cv::Mat wear = value_noise(cv::Size(g_.width, g_.height), std::max(0.7 / g_.resolution, 1.5), derive_seed(seed_, kMarkings));
  for (int r = 0; r < g_.height; ++r) {
    const auto* k = w_.class_id.ptr<std::uint8_t>(r);
    const auto* h = w_.height.ptr<float>(r);
    const auto* jd = junction_dist_.ptr<float>(r);
    const auto* lw = lane_white.ptr<std::uint8_t>(r);
    const auto* ly = lane_yellow.ptr<std::uint8_t>(r);
    const auto* pw = paint_white.ptr<std::uint8_t>(r);
    const auto* py = paint_yellow.ptr<std::uint8_t>(r);
    const auto* wr = wear.ptr<float>(r);
    auto* o = w_.albedo.ptr<cv::Vec3b>(r);
    for (int c = 0; c < g_.width; ++c) {
      if (k[c] != raw(ClassId::kRoad) || h[c] > 0.05F) continue;
      const bool lanes_here = jd[c] > 1.5F;
      const float white = std::max(lanes_here ? lw[c] / 255.0F : 0.0F, pw[c] / 255.0F);
      const float yellow = std::max(lanes_here ? ly[c] / 255.0F : 0.0F, py[c] / 255.0F);
      const float fade = 0.72F + 0.2F * wr[c];  // worn paint
      const auto blend = [&](float alpha, float R, float G, float B) {
        if (alpha <= 0.0F) return;
        const float a = alpha * fade;
        o[c] = cv::Vec3b(static_cast<std::uint8_t>(o[c][0] + (R - o[c][0]) * a), static_cast<std::uint8_t>(o[c][1] + (G - o[c][1]) * a),
                         static_cast<std::uint8_t>(o[c][2] + (B - o[c][2]) * a));
      };
      blend(white, 236.0F, 236.0F, 230.0F);
      blend(yellow, 232.0F, 190.0F, 40.0F);
    }
  }
  // Car glass: windscreen and rear window darker than the paint.
  for (const Pose2& p : cars_) {
    const Box car{{p.x, p.y}, kCarLength / 2, kCarWidth / 2, p.yaw};
    const double reach = car.reach(0);
    for_cells(p.x - reach, p.y - reach, p.x + reach, p.y + reach, [&](int c, int r, double x, double y) {
      if (!car.contains(x, y) || cls(c, r) != raw(ClassId::kVehicle)) return;
      const P2 l = car.to_local(x, y);
      const bool windscreen = l.x > 0.35 && l.x < 1.15 && std::fabs(l.y) < 0.72;
      const bool rear = l.x < -1.15 && l.x > -1.75 && std::fabs(l.y) < 0.7;
      if (windscreen || rear) w_.albedo.at<cv::Vec3b>(r, c) = cv::Vec3b(38, 44, 54);
    });
  }
  // Ridge lines on pitched roofs.
  for (const BuildingPart& p : gables_) {
    const double reach = p.box.reach(0);
    for_cells(p.box.c.x - reach, p.box.c.y - reach, p.box.c.x + reach, p.box.c.y + reach, [&](int c, int r, double x, double y) {
      if (!p.box.contains(x, y, -0.3) || cls(c, r) != raw(ClassId::kBuilding)) return;
      // Only where this part's roof is the top surface: a wing's ridge stops where it meets the main roof.
      const double ridge = p.eave + p.rise + static_cast<double>(p.base - w_.terrain.at<float>(r, c));
      if (static_cast<double>(w_.height.at<float>(r, c)) > ridge + 0.05) return;
      if (std::fabs(p.box.to_local(x, y).y) < std::max(0.15, g_.resolution * 0.6)) {
        cv::Vec3b& v = w_.albedo.at<cv::Vec3b>(r, c);
        for (int ch = 0; ch < 3; ++ch) v[ch] = static_cast<std::uint8_t>(std::min(255, v[ch] + 26));
      }
    });
  }
}

}  // namespace ag::sim::generator
