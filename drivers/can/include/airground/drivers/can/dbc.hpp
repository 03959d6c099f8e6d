// A reader of the DBC signal database format (Vector CANdb++ text): messages (BO_), their signals
// (SG_: start bit, length, byte order, sign, factor, offset) and IEEE float value types (SIG_VALTYPE_),
// with a signal decoder over frame bytes. Enough to check our CAN encoders against a vendor's DBC.
#pragma once

#include <cstdint>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

#include "airground/drivers/can/can_bus.hpp"
#include "airground/platform/result.hpp"

namespace ag::can {

struct DbcSignal {
  std::string name;
  int start_bit{0};
  int length{0};
  bool little_endian{true};  // @1 (Intel); @0 is Motorola
  bool is_signed{false};
  double factor{1}, offset{0};
  int float_type{0};         // SIG_VALTYPE_: 0 integer, 1 IEEE float32, 2 IEEE double
  std::string unit;

  // The raw bits of the signal in a frame (Intel byte order only: what our controllers use).
  [[nodiscard]] std::uint64_t raw(const CanFrame& f) const noexcept;
  // The physical value: float bits as float, else (signed) integer x factor + offset.
  [[nodiscard]] double decode(const CanFrame& f) const noexcept;
};

struct DbcMessage {
  std::uint32_t id{0};
  std::string name;
  int dlc{0};
  std::vector<DbcSignal> signals;
  [[nodiscard]] const DbcSignal* signal(std::string_view n) const noexcept;
};

struct Dbc {
  std::vector<DbcMessage> messages;
  [[nodiscard]] const DbcMessage* message(std::string_view name) const noexcept;
  [[nodiscard]] const DbcMessage* message(std::uint32_t id) const noexcept;
};

Result<Dbc> parse_dbc(std::string_view text, std::string_view origin);
Result<Dbc> read_dbc_file(const std::string& path);

}  // namespace ag::can
