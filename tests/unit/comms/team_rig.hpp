// A team of gossip nodes on one in-process hub, stepped in lockstep: what the protocol tests drive.
#pragma once

#include <unistd.h>

#include <cstdint>
#include <cstdio>
#include <filesystem>
#include <memory>
#include <string>
#include <vector>

#include "airground/comms/gossip_node.hpp"
#include "airground/comms/journal.hpp"
#include "airground/comms/link_hub.hpp"
#include "airground/comms/record_store.hpp"

namespace ag::comms::test {

inline TeamKey test_key(std::uint8_t salt = 0) {
  TeamKey k;
  for (std::size_t i = 0; i < k.bytes.size(); ++i) k.bytes[i] = static_cast<std::uint8_t>(i * 7 + 3 + salt);
  return k;
}

// A fresh folder under /tmp, removed with the object.
struct TempDir {
  std::filesystem::path path;
  TempDir() {
    char tmpl[] = "/tmp/ag_comms_XXXXXX";
    path = ::mkdtemp(tmpl);
  }
  ~TempDir() {
    std::error_code ec;
    std::filesystem::remove_all(path, ec);
  }
  [[nodiscard]] std::string file(const std::string& name) const { return (path / name).string(); }
};

struct Member {
  std::unique_ptr<RecordStore> store;
  std::unique_ptr<Journal> journal;
  std::unique_ptr<GossipNode> node;
  JournalReport report;
};

class Team {
 public:
  // Small stores (test teams run 11 robots in one process).
  static constexpr StoreLimits kTestLimits{2048, 4u << 20, 65536};
  Team(int n, double loss, std::uint64_t seed, GossipParams base = {}, StoreLimits limits = kTestLimits,
       std::string journal_dir = {})
      : hub_(n, loss, seed, base.mtu_bytes, 1024), base_(base), limits_(limits), dir_(std::move(journal_dir)) {
    for (int i = 0; i < n; ++i) {
      members_.emplace_back();
      start(i);
    }
  }

  // (Re)starts member i: its store from its journal when the team has a journal folder.
  void start(int i) {
    Member& m = members_[static_cast<std::size_t>(i)];
    m.store = std::make_unique<RecordStore>(limits_);
    std::uint32_t epoch = 1;
    if (!dir_.empty()) {
      auto j = Journal::open(dir_ + "/robot" + std::to_string(i) + ".agj", *m.store, 1, m.report);
      if (!j) {
        std::fprintf(stderr, "%s\n", j.error().message.c_str());
        std::abort();
      }
      m.journal = std::move(j.value());
      epoch = m.journal->epoch();
    }
    GossipParams p = base_;
    p.self = static_cast<RobotId>(i);
    p.seed = base_.seed + static_cast<std::uint64_t>(i);
    m.node = std::make_unique<GossipNode>(p, test_key(), *m.store, epoch, m.journal.get());
  }
  // As a kill -9: no flush, no goodbye; whatever its socket held is gone.
  void kill(int i) {
    Member& m = members_[static_cast<std::size_t>(i)];
    m.node.reset();
    m.journal.reset();
    m.store.reset();
    hub_.clear_inbox(i);
  }
  [[nodiscard]] bool alive(int i) const { return members_[static_cast<std::size_t>(i)].node != nullptr; }

  void step(TimeNs dt) {
    now_ += dt;
    for (std::size_t i = 0; i < members_.size(); ++i)
      if (members_[i].node) members_[i].node->tick(now_, hub_.endpoint(static_cast<int>(i)));
  }
  // Steps until every live store is identical or `limit` passes; returns the time taken [ns] or -1.
  TimeNs run_until_converged(TimeNs limit, TimeNs dt = 100 * kNsPerMs) {
    const TimeNs t0 = now_;
    while (now_ - t0 <= limit) {
      if (converged()) return now_ - t0;
      step(dt);
    }
    return converged() ? now_ - t0 : -1;
  }
  [[nodiscard]] bool converged() const {
    const RecordStore* first = nullptr;
    for (const Member& m : members_) {
      if (!m.store) continue;
      if (first == nullptr) first = m.store.get();
      else if (m.store->size() != first->size() || m.store->content_hash() != first->content_hash()) return false;
    }
    return true;
  }
  [[nodiscard]] std::uint64_t bytes_out() const {
    std::uint64_t b = 0;
    for (const Member& m : members_)
      if (m.node) b += m.node->stats().bytes_out;
    return b;
  }

  GossipNode& node(int i) { return *members_[static_cast<std::size_t>(i)].node; }
  RecordStore& store(int i) { return *members_[static_cast<std::size_t>(i)].store; }
  Member& member(int i) { return members_[static_cast<std::size_t>(i)]; }
  LinkHub& hub() { return hub_; }
  [[nodiscard]] TimeNs now() const { return now_; }
  [[nodiscard]] int size() const { return static_cast<int>(members_.size()); }

 private:
  LinkHub hub_;
  GossipParams base_;
  StoreLimits limits_;
  std::string dir_;
  std::vector<Member> members_;
  TimeNs now_{kNsPerS};
};

inline std::vector<std::uint8_t> bytes_of(const std::string& s) { return {s.begin(), s.end()}; }

}  // namespace ag::comms::test
