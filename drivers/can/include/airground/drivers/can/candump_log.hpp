// candump log files, the can-utils text format (`candump -l`, read by `canplayer`):
//   (1436509052.249713) can0 123#DEADBEEF        standard id, 3 hex digits
//   (1436509052.249800) can0 1F334455#1122       extended id, 8 hex digits
//   (1436509052.250000) can0 123#R               remote request (optionally #R<dlc>)
// A line is one frame; its stamp is seconds.microseconds. CAN FD lines (`##`) are refused (classic
// CAN only). Reading never stops at a bad line: it is counted and the first error names file and line.
#pragma once

#include <cstdio>
#include <memory>
#include <string>
#include <string_view>
#include <vector>

#include "airground/drivers/can/can_bus.hpp"
#include "airground/drivers/can/can_error.hpp"
#include "airground/platform/clock.hpp"
#include "airground/platform/result.hpp"

namespace ag::can {

struct CandumpRecord {
  CanFrame frame;       // frame.stamp: the line's stamp [ns]
  std::string iface;    // "can0"
  bool error{false};    // an error frame (id with CAN_ERR_FLAG): frame.id holds the error classes
};

// One line into a record; the error says what is wrong with it.
Result<CandumpRecord> parse_candump_line(std::string_view line);
// The line for a frame (no newline): "(sec.usec) iface id#data".
std::string format_candump_line(const CanFrame& f, std::string_view iface);
// Same into a caller's buffer (no allocation); returns the length written, 0 if it does not fit.
std::size_t format_candump_line(const CanFrame& f, std::string_view iface, char* buf, std::size_t cap) noexcept;

struct CandumpLog {
  std::vector<CandumpRecord> records;
  std::size_t bad_lines{0};
  std::string first_error;  // "file:line: what" of the first bad line, empty when none
};
Result<CandumpLog> read_candump_file(const std::string& path);
CandumpLog parse_candump_text(std::string_view text, std::string_view origin);

// Writes frames as candump lines to a file (buffered by stdio; for recording, not the real-time path).
class CandumpWriter {
 public:
  static Result<std::unique_ptr<CandumpWriter>> create(const std::string& path, std::string iface = "can0");
  ~CandumpWriter();
  CandumpWriter(const CandumpWriter&) = delete;
  CandumpWriter& operator=(const CandumpWriter&) = delete;
  void write(const CanFrame& f) noexcept;
  void flush() noexcept;
  [[nodiscard]] std::size_t lines() const noexcept { return lines_; }

 private:
  CandumpWriter(std::FILE* f, std::string iface) : f_(f), iface_(std::move(iface)) {}
  std::FILE* f_{nullptr};
  std::string iface_;
  std::size_t lines_{0};
};

// A bus that records every frame it sends and receives through another bus.
class RecordingCanBus final : public CanBus {
 public:
  RecordingCanBus(CanBus& inner, CandumpWriter& log, const Clock& clock) : inner_(inner), log_(log), clock_(clock) {}
  [[nodiscard]] CanResult send(const CanFrame& f) noexcept override;
  [[nodiscard]] CanResult receive(CanFrame& out) noexcept override;
  [[nodiscard]] const CanBusCounters& counters() const noexcept override { return inner_.counters(); }
  [[nodiscard]] bool set_filters(std::span<const CanFilter> filters) noexcept override { return inner_.set_filters(filters); }

 private:
  CanBus& inner_;
  CandumpWriter& log_;
  const Clock& clock_;
};

// Replays a log: receive() hands out, in order, the frames stamped at or before the clock's now whose
// identifier passes `accept` (by default every frame), shifted so the log's first frame is at
// `start`. send() is counted and kept for inspection.
class CandumpReplayBus final : public CanBus {
 public:
  using Filter = bool (*)(const CanFrame&);
  CandumpReplayBus(std::vector<CandumpRecord> records, const Clock& clock, TimeNs start, Filter accept = nullptr);
  [[nodiscard]] CanResult send(const CanFrame& f) noexcept override;
  [[nodiscard]] CanResult receive(CanFrame& out) noexcept override;
  [[nodiscard]] const CanBusCounters& counters() const noexcept override { return c_; }
  [[nodiscard]] bool finished() const noexcept { return next_ >= records_.size(); }
  [[nodiscard]] TimeNs log_start() const noexcept { return t0_; }
  [[nodiscard]] TimeNs log_end() const noexcept { return records_.empty() ? t0_ : records_.back().frame.stamp; }
  [[nodiscard]] CanBusState state() const noexcept { return errors_.state(); }

 private:
  std::vector<CandumpRecord> records_;
  const Clock& clock_;
  TimeNs start_{0}, t0_{0};
  Filter accept_{nullptr};
  std::size_t next_{0};
  CanBusCounters c_;
  CanErrorTracker errors_;
};

}  // namespace ag::can
