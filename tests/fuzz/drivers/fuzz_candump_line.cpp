// libFuzzer target: candump log text, line by line (parse_candump_text) and as one line; every record
// parsed is formatted again and must parse back to the same frame.
#include <cstddef>
#include <cstdint>
#include <cstdlib>
#include <string_view>

#include "airground/drivers/can/candump_log.hpp"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  using namespace ag::can;
  const std::string_view text(reinterpret_cast<const char*>(data), size);
  const CandumpLog log = parse_candump_text(text, "fuzz");
  for (const CandumpRecord& r : log.records) {
    if (r.error) continue;
    char buf[128];
    const std::size_t n = format_candump_line(r.frame, r.iface.size() < 32 ? r.iface : "can0", buf, sizeof buf);
    if (n == 0) continue;
    auto back = parse_candump_line(std::string_view(buf, n));
    if (!back.ok() || back.value().frame.id != r.frame.id || back.value().frame.dlc != r.frame.dlc ||
        back.value().frame.extended != r.frame.extended || back.value().frame.rtr != r.frame.rtr ||
        (!r.frame.rtr && back.value().frame.data != r.frame.data))
      std::abort();  // a frame that does not survive its own format
  }
  (void)parse_candump_line(text);
  return 0;
}
