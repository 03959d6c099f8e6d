// Typed channels between stages: latest-value and ring channels, fanned out one buffer per reader so
// every buffer stays single-producer single-consumer. Wired in init(), sealed before the first step.
#pragma once

#include <algorithm>
#include <atomic>
#include <cstddef>
#include <cstdint>
#include <memory>
#include <string>
#include <string_view>
#include <vector>

#include "airground/platform/latest_value.hpp"
#include "airground/platform/result.hpp"
#include "airground/platform/spsc_ring.hpp"

namespace ag {

namespace detail {
template <typename T>
struct TypeTag {
  static constexpr char id = 0;
};
template <typename T>
constexpr const void* type_tag() noexcept {
  return &TypeTag<T>::id;
}

struct ChannelBase {
  virtual ~ChannelBase() = default;
  // Writer side, lockstep compute time only: what the writer publishes stays invisible until release().
  virtual void hold() noexcept = 0;
  virtual void release() noexcept = 0;
  std::string name;
  const void* tag{nullptr};
  bool has_writer{false};
  std::size_t writer_stage{kNoStage};  // index of the stage whose init() took the writer, if a stage did
  std::size_t subscribers{0};          // readers that wait on the writer (a tap does not)
  bool optional{false};                // read whether or not a role has a writer (allow_unwritten)
  static constexpr std::size_t kNoStage = static_cast<std::size_t>(-1);
};

template <typename T>
struct LatestChannel final : ChannelBase {
  void hold() noexcept override {
    for (auto& r : readers) r->hold();
  }
  void release() noexcept override {
    for (auto& r : readers) r->release();
  }
  std::vector<std::unique_ptr<LatestValue<T>>> readers;
};

template <typename T, std::size_t N>
struct RingChannel final : ChannelBase {
  void hold() noexcept override {
    for (auto& r : readers) r->hold();
  }
  void release() noexcept override {
    for (auto& r : readers) r->release();
  }
  std::vector<std::unique_ptr<SpscRing<T, N>>> readers;
  // Per reader: pushes refused because its ring was full (written by the producer only, read by anyone).
  std::vector<std::unique_ptr<std::atomic<std::uint64_t>>> drops;
  std::vector<char> tap;  // per reader: a tap (recorder) never holds the producer back, see free_slots()
};
}  // namespace detail

template <typename T>
class LatestWriter {
 public:
  LatestWriter() = default;
  explicit LatestWriter(detail::LatestChannel<T>* c) : ch_(c) {}
  void publish(const T& v) noexcept {
    for (auto& r : ch_->readers) r->write(v);
  }
  [[nodiscard]] bool connected() const noexcept { return ch_ != nullptr; }
  [[nodiscard]] std::size_t reader_count() const noexcept { return ch_ ? ch_->readers.size() : 0; }

 private:
  detail::LatestChannel<T>* ch_{nullptr};
};

template <typename T>
class LatestReader {
 public:
  LatestReader() = default;
  explicit LatestReader(LatestValue<T>* lv) : lv_(lv) {}
  [[nodiscard]] const T& read() noexcept { return lv_->read(); }
  [[nodiscard]] bool fresh() const noexcept { return lv_->fresh(); }
  [[nodiscard]] bool connected() const noexcept { return lv_ != nullptr; }

 private:
  LatestValue<T>* lv_{nullptr};
};

template <typename T, std::size_t N>
class RingWriter {
 public:
  RingWriter() = default;
  explicit RingWriter(detail::RingChannel<T, N>* c) : ch_(c) {}
  // Pushes to every reader; returns how many readers refused because they were full (counted).
  std::size_t push(const T& v) noexcept {
    std::size_t refused = 0;
    for (std::size_t i = 0; i < ch_->readers.size(); ++i) {
      if (!ch_->readers[i]->try_push(v)) {
        std::atomic<std::uint64_t>& d = *ch_->drops[i];
        d.store(d.load(std::memory_order_relaxed) + 1, std::memory_order_relaxed);  // one producer: no RMW needed
        ++refused;
      }
    }
    return refused;
  }
  // Slots every reader still has free (from the producer's side: a reader may free more meanwhile), so a
  // producer can hold back what some reader could not take instead of re-sending it to all. Taps do not
  // count: a slow recorder loses messages (counted) instead of holding the robot back.
  [[nodiscard]] std::size_t free_slots() const noexcept {
    std::size_t f = N;
    for (std::size_t i = 0; i < ch_->readers.size(); ++i)
      if (ch_->tap[i] == 0) f = std::min(f, N - std::min(N, ch_->readers[i]->unread_from_producer()));
    return f;
  }

 private:
  detail::RingChannel<T, N>* ch_{nullptr};
};

template <typename T, std::size_t N>
class RingReader {
 public:
  RingReader() = default;
  explicit RingReader(SpscRing<T, N>* r, const std::atomic<std::uint64_t>* drops = nullptr) : ring_(r), drops_(drops) {}
  [[nodiscard]] T* front() noexcept { return ring_->front(); }
  void pop() noexcept { ring_->pop(); }
  [[nodiscard]] std::size_t size() const noexcept { return ring_->size(); }
  // Messages the writer could not give this reader because its ring was full.
  [[nodiscard]] std::uint64_t drops() const noexcept { return drops_ ? drops_->load(std::memory_order_relaxed) : 0; }
  [[nodiscard]] bool connected() const noexcept { return ring_ != nullptr; }

 private:
  SpscRing<T, N>* ring_{nullptr};
  const std::atomic<std::uint64_t>* drops_{nullptr};
};

// A channel named once with its message type (and ring size): the typed way to reach it. Constants of
// these live beside the messages (airground/messages/channels.hpp); a name that comes from configuration
// keeps the constant's type through with_name() (a view: use it in the call, do not keep it).
template <typename T>
struct LatestTopic {
  using Message = T;
  std::string_view name;
  [[nodiscard]] constexpr LatestTopic with_name(std::string_view n) const noexcept { return LatestTopic{n}; }
};
template <typename T, std::size_t N>
struct RingTopic {
  using Message = T;
  static constexpr std::size_t kCapacity = N;
  std::string_view name;
  [[nodiscard]] constexpr RingTopic with_name(std::string_view n) const noexcept { return RingTopic{n}; }
};

// One per robot instance. Lookups happen in init() only; the handles are what step() uses.
// The topic overloads are the string ones with the type and ring size taken from the topic: same
// registration, same refusals (a name used with two types is refused whichever way each side named it).
class ChannelRegistry {
 public:
  template <typename T>
  Result<LatestWriter<T>> latest_writer(const LatestTopic<T>& t) { return latest_writer<T>(t.name); }
  template <typename T>
  Result<LatestReader<T>> latest_reader(const LatestTopic<T>& t) { return latest_reader<T>(t.name); }
  template <typename T, std::size_t N>
  Result<RingWriter<T, N>> ring_writer(const RingTopic<T, N>& t) { return ring_writer<T, N>(t.name); }
  template <typename T, std::size_t N>
  Result<RingReader<T, N>> ring_reader(const RingTopic<T, N>& t) { return ring_reader<T, N>(t.name); }
  template <typename T, std::size_t N>
  Result<RingReader<T, N>> ring_tap(const RingTopic<T, N>& t) { return ring_tap<T, N>(t.name); }
  template <typename T>
  void allow_unwritten(const LatestTopic<T>& t) noexcept { allow_unwritten(t.name); }
  template <typename T, std::size_t N>
  void allow_unwritten(const RingTopic<T, N>& t) noexcept { allow_unwritten(t.name); }

  template <typename T>
  Result<LatestWriter<T>> latest_writer(std::string_view name) {
    auto ch = find_or_add<detail::LatestChannel<T>>(name);
    if (!ch) return ch.error();
    if (ch.value()->has_writer) return dup_writer(name);
    ch.value()->has_writer = true;
    ch.value()->writer_stage = initialising_;
    return LatestWriter<T>(ch.value());
  }
  template <typename T>
  Result<LatestReader<T>> latest_reader(std::string_view name) {
    if (sealed_) return sealed_error(name);
    auto ch = find_or_add<detail::LatestChannel<T>>(name);
    if (!ch) return ch.error();
    ch.value()->readers.push_back(std::make_unique<LatestValue<T>>());
    ++ch.value()->subscribers;
    return LatestReader<T>(ch.value()->readers.back().get());
  }
  template <typename T, std::size_t N>
  Result<RingWriter<T, N>> ring_writer(std::string_view name) {
    auto ch = find_or_add<detail::RingChannel<T, N>>(name);
    if (!ch) return ch.error();
    if (ch.value()->has_writer) return dup_writer(name);
    ch.value()->has_writer = true;
    ch.value()->writer_stage = initialising_;
    return RingWriter<T, N>(ch.value());
  }
  template <typename T, std::size_t N>
  Result<RingReader<T, N>> ring_reader(std::string_view name) {
    return add_ring_reader<T, N>(name, false);
  }
  // A reader that never holds the producer back (free_slots() ignores it): when it falls behind, its
  // ring refuses messages and counts them (RingReader::drops()). For recorders and monitors.
  template <typename T, std::size_t N>
  Result<RingReader<T, N>> ring_tap(std::string_view name) {
    return add_ring_reader<T, N>(name, true);
  }
  // Start-up: writers taken from now on belong to stage `index` of the role table (kNoStage: to none).
  void set_initialising(std::size_t index) noexcept { initialising_ = index; }
  // After every stage's init(): no more readers may be added (the fan-out lists are final). Builds each
  // stage's list of output channels.
  void seal() {
    sealed_ = true;
    initialising_ = detail::ChannelBase::kNoStage;
    outputs_.clear();
    for (auto& c : channels_) {
      if (c->writer_stage == detail::ChannelBase::kNoStage) continue;
      if (outputs_.size() <= c->writer_stage) outputs_.resize(c->writer_stage + 1);
      outputs_[c->writer_stage].push_back(c.get());
    }
  }
  // Lockstep compute time (sealed registries only): everything stage `index` publishes from now on stays
  // invisible to its readers until release_outputs(index). Never used on a robot.
  void hold_outputs(std::size_t index) noexcept {
    if (index < outputs_.size())
      for (auto* c : outputs_[index]) c->hold();
  }
  void release_outputs(std::size_t index) noexcept {
    if (index < outputs_.size())
      for (auto* c : outputs_[index]) c->release();
  }
  [[nodiscard]] std::size_t size() const noexcept { return channels_.size(); }
  // Channels something reads (a tap aside) but nothing writes: a misspelled name, or a stage or device
  // missing from the role; its readers would wait forever. The binaries say so at start-up and the
  // simulator checks every robot once it has taken the devices' writers.
  [[nodiscard]] std::vector<std::string> read_but_unwritten() const {
    std::vector<std::string> out;
    for (const auto& c : channels_)
      if (c->subscribers > 0 && !c->has_writer && !c->optional) out.push_back(c->name);
    return out;
  }
  // A reader that polls an input some roles never write (the comms stage's "gossip_out" on the base
  // station, which publishes no records) says so once it has subscribed; read_but_unwritten skips it.
  void allow_unwritten(std::string_view name) noexcept {
    for (auto& c : channels_)
      if (c->name == name) c->optional = true;
  }

 private:
  template <typename T, std::size_t N>
  Result<RingReader<T, N>> add_ring_reader(std::string_view name, bool tap) {
    if (sealed_) return sealed_error(name);
    auto ch = find_or_add<detail::RingChannel<T, N>>(name);
    if (!ch) return ch.error();
    ch.value()->readers.push_back(std::make_unique<SpscRing<T, N>>());
    ch.value()->drops.push_back(std::make_unique<std::atomic<std::uint64_t>>(0));
    ch.value()->tap.push_back(tap ? 1 : 0);
    if (!tap) ++ch.value()->subscribers;
    return RingReader<T, N>(ch.value()->readers.back().get(), ch.value()->drops.back().get());
  }
  template <typename C>
  Result<C*> find_or_add(std::string_view name) {
    using Tag = C;
    for (auto& c : channels_) {
      if (c->name == name) {
        if (c->tag != detail::type_tag<Tag>())
          return Error::make(ErrorCode::kInvalidArgument, "channel '" + std::string(name) + "' is used with two different message types");
        return static_cast<C*>(c.get());
      }
    }
    auto c = std::make_unique<C>();
    c->name = std::string(name);
    c->tag = detail::type_tag<Tag>();
    C* raw = c.get();
    channels_.push_back(std::move(c));
    return raw;
  }
  static Error dup_writer(std::string_view name) {
    return Error::make(ErrorCode::kInvalidArgument, "channel '" + std::string(name) + "' already has a writer (channels are single-producer)");
  }
  static Error sealed_error(std::string_view name) {
    return Error::make(ErrorCode::kInvalidArgument, "channel '" + std::string(name) + "': readers must subscribe in init()");
  }

  std::vector<std::unique_ptr<detail::ChannelBase>> channels_;
  std::vector<std::vector<detail::ChannelBase*>> outputs_;  // per stage index, built by seal()
  std::size_t initialising_{detail::ChannelBase::kNoStage};
  bool sealed_{false};
};

}  // namespace ag
