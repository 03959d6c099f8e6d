// The real base role (firmware_host/base/role.cpp: status, comms, web) built through RoleInstance with
// a temp config, comms over the inproc link "base", the web server on a free loopback port.
#pragma once

#include <chrono>
#include <memory>
#include <string>
#include <thread>
#include <vector>

#include "airground/base_station/web_stage.hpp"
#include "airground/platform/role_instance.hpp"
#include "mission_player.hpp"
#include "roles.hpp"

namespace ag::base_station::test {

struct BaseRig {
  SimClock clock{0};
  std::unique_ptr<RoleInstance> role;
  WebStage* web{nullptr};

  static std::unique_ptr<BaseRig> make(const TempDir& dir, std::vector<std::string> extra = {}) {
    auto rig = std::make_unique<BaseRig>();
    static const std::vector<ParamSection> schema = role_schema(base_role());
    Config cfg = Config::defaults(schema);
    std::vector<std::string> sets = {"robot.id=200", "comms.transport=inproc", "comms.key_file=" + write_key(dir.file("team.key")),
                                     "comms.epoch_from_clock=false", "comms.digest_period_s=0.2", "comms.deliver_map_tiles=true",
                                     "web.port=0", "web.bind=127.0.0.1", "web.log_path=" + dir.file("mission.jsonl")};
    sets.insert(sets.end(), extra.begin(), extra.end());
    for (const auto& s : sets) {
      auto st = cfg.set(s);
      EXPECT_TRUE(st.ok()) << s << ": " << st.error().message;
      if (!st) return nullptr;
    }
    auto r = RoleInstance::create(base_role(), cfg, rig->clock, "base");
    EXPECT_TRUE(r.ok()) << r.error().message;
    if (!r) return nullptr;
    rig->role = std::move(r).value();
    for (auto& s : rig->role->stages())
      if (auto* w = dynamic_cast<WebStage*>(s.stage.get())) rig->web = w;
    EXPECT_NE(rig->web, nullptr) << "the base role has a web stage";
    if (rig->web == nullptr) return nullptr;
    for (int i = 0; i < 200 && rig->web->port() == 0; ++i) std::this_thread::sleep_for(std::chrono::milliseconds(5));
    return rig;
  }
  void step(TimeNs now) {
    clock.set(now);
    for (auto& s : role->stages()) s.stage->step(now);
  }
  ~BaseRig() {
    if (role) role->stop_all();
  }
};

}  // namespace ag::base_station::test
