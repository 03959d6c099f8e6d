// An in-process team of mission managers: ideal robots that drive straight to their goals, exchange their
// records as encoded gossip payloads (every record to every other live robot, after all have ticked, so
// simultaneous choices clash as on the radio), hear each other's poses, and a quadrotor's region batches.
#pragma once

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <memory>
#include <vector>

#include "airground/mission/manager.hpp"

namespace ag::mission::test {

struct Bot {
  std::unique_ptr<MissionManager> m;
  double x{0}, y{0};
  double sigma{0.3};
  double speed{2.0};
  bool alive{true};
  bool no_route{false};
  LocalizationStatus status{LocalizationStatus::kTracking};
  std::uint32_t route_seq{0};
};

struct Team {
  std::vector<Bot> bots;
  TimeNs now{0};
  double dt{0.2};
  std::vector<RegionRecord> regions;
  std::uint32_t regions_version{0};
  std::uint64_t delivered{0};
  double wall_x{1e18};  // [m] no robot gets east of this (ground the map calls free and is not)

  Bot& add(comms::RobotId id, std::uint8_t priority, double x, double y, ManagerParams p = {}) {
    p.self = id;
    p.priority = priority;
    p.start_x = x;
    p.start_y = y;
    Bot b;
    b.m = std::make_unique<MissionManager>(p);
    b.x = x;
    b.y = y;
    bots.push_back(std::move(b));
    return bots.back();
  }
  void region(std::uint32_t id, double gx, double gy) { regions.push_back(RegionRecord{id, static_cast<float>(gx), static_cast<float>(gy), static_cast<float>(gx), static_cast<float>(gy), 36, true}); }
  void publish_regions() {
    ++regions_version;
    const std::size_t batches = std::max<std::size_t>(1, (regions.size() + kRegionsPerBatch - 1) / kRegionsPerBatch);
    for (std::size_t b = 0; b < batches; ++b) {
      RegionBatch rb;
      rb.batches = static_cast<std::uint16_t>(batches);
      rb.regions_version = regions_version;
      rb.count = static_cast<std::uint8_t>(std::min(kRegionsPerBatch, regions.size() - b * kRegionsPerBatch));
      for (std::size_t i = 0; i < rb.count; ++i) rb.regions[i] = regions[b * kRegionsPerBatch + i];
      std::array<std::uint8_t, comms::kGossipPayloadMax> buf{};
      const std::size_t n = encode(rb, buf);
      for (Bot& bot : bots) {
        if (!bot.alive) continue;
        EXPECT_EQ(bot.m->on_record(0, regions_topic(static_cast<std::uint32_t>(b)), std::span<const std::uint8_t>(buf.data(), n), now), DecodeError::kOk);
      }
    }
  }
  void step() {
    for (std::size_t i = 0; i < bots.size(); ++i) {
      Bot& b = bots[i];
      if (!b.alive) continue;
      LocalizationMsg l;
      l.stamp = now;
      l.status = b.status;
      l.pose = Pose2{b.x, b.y, 0};
      l.covariance = {b.sigma * b.sigma, 0, 0, 0, b.sigma * b.sigma, 0, 0, 0, 0.01};
      b.m->on_localization(l);
      b.m->on_route(b.m->goal().id, ++b.route_seq, b.no_route ? RouteStatus::kNoRoute : RouteStatus::kOk);
      b.m->tick(now);
    }
    for (std::size_t i = 0; i < bots.size(); ++i) {
      Bot& b = bots[i];
      if (!b.alive) continue;
      for (const OutRecord& o : b.m->outbox())
        for (std::size_t j = 0; j < bots.size(); ++j) {
          if (j == i || !bots[j].alive) continue;
          {
            EXPECT_EQ(bots[j].m->on_record(b.m->params().self, o.topic, std::span<const std::uint8_t>(o.payload.data(), o.size), now), DecodeError::kOk);
            ++delivered;
          }
        }
      b.m->clear_outbox();
      for (std::size_t j = 0; j < bots.size(); ++j)
        if (j != i && bots[j].alive) bots[j].m->on_peer_heard(b.m->params().self, now);
    }
    for (Bot& b : bots) {
      if (!b.alive || b.no_route) continue;
      const GoalCommand& g = b.m->goal();
      if (g.cancel || g.id == 0) continue;
      const double dx = g.x - b.x, dy = g.y - b.y, d = std::hypot(dx, dy);
      const double s = std::min(d, b.speed * dt);
      if (d > 1e-9) {
        b.x = std::min(b.x + dx / d * s, wall_x);
        b.y += dy / d * s;
      }
    }
    now += from_seconds(dt);
  }
  [[nodiscard]] bool all_done() const {
    for (const Bot& b : bots)
      if (b.alive && !b.m->status().done) return false;
    return true;
  }
  [[nodiscard]] double seconds() const { return to_seconds(now); }
};

}  // namespace ag::mission::test
