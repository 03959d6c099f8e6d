// Real UDP between network namespaces made by the test (ip netns + veth + a bridge): three robots, 20 %
// loss injected in user space, convergence; then one robot's link cut (link down) and restored.
// Skipped, saying why, where namespaces cannot be made (not root, no ip tool, a sandbox without them).
#include <fcntl.h>
#include <sched.h>
#include <unistd.h>

#include <gtest/gtest.h>

#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <random>
#include <string>
#include <thread>

#include "airground/comms/link_hub.hpp"
#include "airground/drivers/net/udp/udp_link.hpp"
#include "team_rig.hpp"

namespace ag::comms {
namespace {

int sh(const std::string& cmd) {
  const int rc = std::system((cmd + " >/dev/null 2>&1").c_str());
  return rc;
}

// Namespaces ag<pid><x> for robots a, b, c and a switch namespace holding the bridge.
class Netns {
 public:
  Netns() : tag_("ag" + std::to_string(::getpid())) {}
  ~Netns() {
    for (const char* x : {"a", "b", "c", "sw"}) sh("ip netns del " + tag_ + x);
  }
  std::string name(const std::string& x) const { return tag_ + x; }
  // Returns "" on success, else why it could not.
  std::string make() {
    if (::geteuid() != 0) return "not root: network namespaces need CAP_SYS_ADMIN";
    if (sh("ip -V") != 0) return "no 'ip' tool (iproute2)";
    if (sh("ip netns add " + name("sw")) != 0) return "'ip netns add' is not allowed here";
    made_ = true;
    const std::string sw = name("sw");
    if (sh("ip -n " + sw + " link add br0 type bridge") != 0 || sh("ip -n " + sw + " link set br0 up") != 0)
      return "cannot make a bridge in a namespace";
    int k = 1;
    for (const char* x : {"a", "b", "c"}) {
      const std::string ns = name(x);
      const std::string port = std::string("p") + x;
      if (sh("ip netns add " + ns) != 0 ||
          sh("ip link add name eth0 netns " + ns + " type veth peer name " + port + " netns " + sw) != 0 ||
          sh("ip -n " + sw + " link set " + port + " master br0") != 0 || sh("ip -n " + sw + " link set " + port + " up") != 0 ||
          sh("ip -n " + ns + " addr add 10.77.0." + std::to_string(k) + "/24 broadcast 10.77.0.255 dev eth0") != 0 ||
          sh("ip -n " + ns + " link set eth0 up") != 0 || sh("ip -n " + ns + " link set lo up") != 0)
        return std::string("cannot wire namespace ") + x;
      ++k;
    }
    return "";
  }
  // Opens a UDP link inside namespace x (the socket stays in it after this thread goes back).
  Result<std::unique_ptr<net::UdpLink>> open_in(const std::string& x, const net::UdpLinkConfig& cfg) {
    const int self = ::open("/proc/self/ns/net", O_RDONLY | O_CLOEXEC);
    const int target = ::open(("/var/run/netns/" + name(x)).c_str(), O_RDONLY | O_CLOEXEC);
    if (self < 0 || target < 0 || ::setns(target, CLONE_NEWNET) != 0) {
      if (self >= 0) ::close(self);
      if (target >= 0) ::close(target);
      return Error::make(ErrorCode::kIo, "setns into " + name(x) + " failed");
    }
    auto link = net::UdpLink::open(cfg);
    ::setns(self, CLONE_NEWNET);
    ::close(self);
    ::close(target);
    return link;
  }

 private:
  std::string tag_;
  bool made_{false};
};

TimeNs mono_now() {
  return std::chrono::duration_cast<std::chrono::nanoseconds>(std::chrono::steady_clock::now().time_since_epoch()).count();
}

struct Robot {
  std::unique_ptr<net::UdpLink> udp;
  std::unique_ptr<LossyLink> lossy;
  std::unique_ptr<RecordStore> store;
  std::unique_ptr<GossipNode> node;
};

bool converged(const std::vector<Robot>& r, std::size_t a, std::size_t b) {
  return r[a].store->size() == r[b].store->size() && r[a].store->content_hash() == r[b].store->content_hash();
}

// Runs the robots in real time (5 ms ticks) until `done` or the timeout; returns the seconds taken or -1.
template <typename F>
double run(std::vector<Robot>& robots, double timeout_s, F done) {
  const TimeNs t0 = mono_now();
  while (to_seconds(mono_now() - t0) < timeout_s) {
    for (auto& r : robots) r.node->tick(mono_now(), *r.lossy);
    if (done()) return to_seconds(mono_now() - t0);
    std::this_thread::sleep_for(std::chrono::milliseconds(5));
  }
  return -1;
}

TEST(UdpNetns, ThreeRobotsOverRealUdpWithLossAndALinkCutConverge) {
  Netns ns;
  const std::string why = ns.make();
  if (!why.empty()) GTEST_SKIP() << "network namespaces unavailable: " << why;

  std::vector<Robot> robots(3);
  const char* names[] = {"a", "b", "c"};
  std::mt19937_64 rng(5);
  for (int i = 0; i < 3; ++i) {
    net::UdpLinkConfig cfg;
    cfg.bind_address = "0.0.0.0";
    cfg.port = 47100;
    cfg.broadcast_address = "10.77.0.255";
    auto link = ns.open_in(names[i], cfg);
    ASSERT_TRUE(link.ok()) << link.error().message;
    Robot& r = robots[static_cast<std::size_t>(i)];
    r.udp = std::move(link.value());
    r.lossy = std::make_unique<LossyLink>(*r.udp, 0.2, static_cast<std::uint64_t>(i + 1));
    r.store = std::make_unique<RecordStore>(test::Team::kTestLimits);
    GossipParams p;
    p.self = static_cast<RobotId>(10 + i);
    p.digest_period_s = 0.2;
    p.peer_timeout_s = 1.0;
    r.node = std::make_unique<GossipNode>(p, test::test_key(), *r.store, 1, nullptr);
    for (int k = 0; k < 5; ++k) {
      std::vector<std::uint8_t> b(k == 0 ? 7000 : 60);
      for (auto& x : b) x = static_cast<std::uint8_t>(rng());
      r.node->publish(k == 0 ? tile_topic(i, k) : make_topic(TopicKind::kApp, static_cast<std::uint32_t>(k)), 3, mono_now(), b);
    }
  }
  auto all = [&] { return converged(robots, 0, 1) && converged(robots, 1, 2); };
  const double t1 = run(robots, 10.0, all);
  ASSERT_GE(t1, 0) << "no convergence over real UDP with 20 % loss";
  EXPECT_EQ(robots[0].store->size(), 15U);
  std::uint64_t bytes = 0, lost = 0;
  for (auto& r : robots) {
    bytes += r.node->stats().bytes_out;
    lost += r.lossy->dropped();
    EXPECT_EQ(r.node->stats().drop(DropReason::kForged), 0U);
    EXPECT_GT(r.udp->stats().received, 0U);
  }
  std::printf("[udp netns] 3 robots on a bridge, 20%% loss in user space: converged in %.2f s, %llu B sent, %llu datagrams dropped\n",
              t1, static_cast<unsigned long long>(bytes), static_cast<unsigned long long>(lost));

  // Cut robot a's link (the interface goes down), write on both sides, then restore it.
  ASSERT_EQ(sh("ip -n " + ns.name("a") + " link set eth0 down"), 0);
  robots[0].node->publish(make_topic(TopicKind::kClaims, 0), 6, mono_now(), test::bytes_of("a claims goal 2 while cut off"));
  robots[2].node->publish(make_topic(TopicKind::kFailures, 1), 7, mono_now(), test::bytes_of("c failed goal 1"));
  const double t_bc = run(robots, 5.0, [&] { return converged(robots, 1, 2); });
  ASSERT_GE(t_bc, 0) << "b and c go on without a";
  run(robots, 1.2, [] { return false; });  // a stays cut for a while: peers time out on both sides
  EXPECT_FALSE(converged(robots, 0, 1)) << "nothing crossed a downed link";
  EXPECT_GT(robots[0].udp->stats().send_errors + robots[0].udp->stats().would_block + robots[0].node->stats().send_failures, 0U)
      << "the cut is visible to a as send errors";
  ASSERT_EQ(sh("ip -n " + ns.name("a") + " link set eth0 up"), 0);
  const double t2 = run(robots, 10.0, all);
  ASSERT_GE(t2, 0) << "no convergence after the link came back";
  EXPECT_EQ(robots[1].store->size(), 17U);
  EXPECT_NE(robots[1].store->find(RecordKey{10, make_topic(TopicKind::kClaims, 0)}), RecordStore::kNoSlot);
  EXPECT_NE(robots[0].store->find(RecordKey{12, make_topic(TopicKind::kFailures, 1)}), RecordStore::kNoSlot);
  std::printf("[udp netns] link of robot a cut for %.1f s then restored: converged %.2f s after restore (peers timed out: %llu)\n",
              t_bc + 1.2, t2, static_cast<unsigned long long>(robots[1].node->stats().peers_timed_out));
}

}  // namespace
}  // namespace ag::comms
