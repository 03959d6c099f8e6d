// The segmentation stage on its own robot: a role of the stage plus a sink that stands in for the
// ortho-mapper (subscribed to "keyframes_labelled"), built through RoleInstance (real config, real
// channels), with the writer pose_graph would hold.
#pragma once

#include <gtest/gtest.h>

#include <memory>
#include <string>
#include <vector>

#include "airground/messages/channels.hpp"
#include "airground/platform/role_instance.hpp"
#include "airground/segmentation/stage.hpp"

namespace ag::seg::test {

// Keeps the last keyframe it received and counts them (what the mapper would see).
class KeyframeSink final : public Stage {
 public:
  static std::unique_ptr<Stage> make() { return std::make_unique<KeyframeSink>(); }
  Status init(StageContext& ctx) override {
    auto r = ctx.channels.ring_reader(chan::kKeyframesLabelled);
    if (!r) return r.error();
    in_ = r.value();
    last = std::make_unique<KeyframeMsg>();
    return ok_status();
  }
  void step(TimeNs) noexcept override {
    while (KeyframeMsg* m = in_.front()) {
      *last = *m;
      ++received;
      in_.pop();
    }
  }
  std::unique_ptr<KeyframeMsg> last;
  int received{0};

 private:
  RingReader<KeyframeMsg, kKeyframeRing> in_;
};

inline constexpr StageSpec kRigStages[] = {
    {"segmentation", &SegmentationStage::make, 2.5, 300'000, 25, -1, SegmentationStage::kParams, "the stage under test"},
    {"sink", &KeyframeSink::make, 2.5, 1'000, 20, -1, {}, "the mapper's place"},
};
inline constexpr RoleDescription kRigRole{"uav", "segmentation stage rig", kRigStages, {}};

struct StageRig {
  SimClock clock{0};
  std::unique_ptr<RoleInstance> role;
  SegmentationStage* stage{nullptr};
  KeyframeSink* sink{nullptr};
  RingWriter<KeyframeMsg, kKeyframeRing> kf_w;

  // `sets`: "segmentation.key=value" overrides. Null (and `error` set) when the role refuses to start.
  static std::unique_ptr<StageRig> make(const std::vector<std::string>& sets, std::string* error = nullptr) {
    auto rig = std::make_unique<StageRig>();
    static const std::vector<ParamSection> schema = role_schema(kRigRole);
    Config cfg = Config::defaults(schema);
    for (const std::string& s : sets) {
      const Status st = cfg.set(s);
      EXPECT_TRUE(st.ok()) << s;
    }
    auto r = RoleInstance::create(kRigRole, cfg, rig->clock, "uav");
    if (!r.ok()) {
      if (error) *error = r.error().message;
      return nullptr;
    }
    rig->role = std::move(r).value();
    rig->stage = dynamic_cast<SegmentationStage*>(rig->role->stages()[0].stage.get());
    rig->sink = dynamic_cast<KeyframeSink*>(rig->role->stages()[1].stage.get());
    rig->kf_w = rig->role->channels().ring_writer(chan::kKeyframes).value();
    return rig;
  }
  void step(TimeNs now) {
    for (auto& s : role->stages()) s.stage->step(now);
  }
};

}  // namespace ag::seg::test
