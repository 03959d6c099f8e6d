// bench_ring: ag::SpscRing against moodycamel::ReaderWriterQueue, producer -> consumer throughput and
// two-thread ping-pong round trip, each over several repetitions; the medians are compared at the end.
#include <benchmark/benchmark.h>
#include <readerwriterqueue/readerwriterqueue.h>

#include <algorithm>
#include <atomic>
#include <cstdint>
#include <cstdio>
#include <cstring>
#include <map>
#include <memory>
#include <string>
#include <thread>
#include <vector>

#include "airground/platform/spsc_ring.hpp"
#include "bench_common.hpp"

namespace {

constexpr std::size_t kCapacity = 4096;
constexpr std::uint64_t kItems = std::uint64_t{1} << 22;  // moved per throughput iteration
constexpr std::uint64_t kTrips = std::uint64_t{1} << 14;  // round trips per latency iteration
constexpr std::uint64_t kStop = ~std::uint64_t{0};        // ping-pong sentinel (never a payload)

// Where the two threads run; decided once in main().
struct Placement {
  int producer_cpu{-1};
  int consumer_cpu{-1};
  bool pinned{false};
  bool yield{false};  // fewer than 2 CPUs: spinning threads must yield or they starve each other
};
Placement g_place;

// One failed poll: the CPU's spin-wait hint, or a yield when both threads share one CPU.
inline void relax() noexcept {
  if (g_place.yield) {
    std::this_thread::yield();
  } else {
#if defined(__x86_64__) || defined(__i386__)
    __builtin_ia32_pause();
#elif defined(__aarch64__)
    asm volatile("yield" ::: "memory");
#endif
  }
}

void place_producer() {
  if (g_place.pinned) ag::bench::pin_this_thread(g_place.producer_cpu);
}
void place_consumer() {
  if (g_place.pinned) ag::bench::pin_this_thread(g_place.consumer_cpu);
}

// The two queues behind one interface: push never blocks, pop copies the front out and frees it.
struct AgQueue {
  ag::SpscRing<std::uint64_t, kCapacity> q;
  bool push(std::uint64_t v) noexcept { return q.try_push(v); }
  bool pop(std::uint64_t& v) noexcept {
    const std::uint64_t* p = q.front();
    if (p == nullptr) return false;
    v = *p;
    q.pop();
    return true;
  }
};

struct MoodyQueue {
  moodycamel::ReaderWriterQueue<std::uint64_t> q{kCapacity};
  bool push(std::uint64_t v) noexcept { return q.try_enqueue(v); }
  bool pop(std::uint64_t& v) noexcept { return q.try_dequeue(v); }
};

// Payload i: distinct, order-sensitive, cheap to recompute on the consumer side.
constexpr std::uint64_t value_of(std::uint64_t i) noexcept { return i * 0x9E3779B97F4A7C15ull + 1; }

std::uint64_t expected_sum() noexcept {
  std::uint64_t s = 0;
  for (std::uint64_t i = 0; i < kItems; ++i) s += value_of(i);
  return s;
}

template <typename Q>
void bm_throughput(benchmark::State& state) {
  auto q = std::make_unique<Q>();
  std::atomic<std::uint64_t> round{0};
  std::atomic<std::uint64_t> done{0};
  std::atomic<bool> stop{false};
  std::atomic<std::uint64_t> sum{0};
  std::atomic<std::uint64_t> mismatch{0};
  std::atomic<std::uint64_t> empty_polls{0};  // consumer found the queue empty (diagnostic: which end waits)
  const std::uint64_t want = expected_sum();
  std::uint64_t full_polls = 0;                 // producer found the queue full

  ag::bench::AffinityGuard restore;
  place_producer();
  std::thread consumer([&] {
    place_consumer();
    for (std::uint64_t r = 1;; ++r) {
      while (round.load(std::memory_order_acquire) < r) {
        if (stop.load(std::memory_order_acquire)) return;
        relax();
      }
      std::uint64_t s = 0;
      std::uint64_t bad = 0;
      std::uint64_t empty = 0;
      for (std::uint64_t i = 0; i < kItems; ++i) {
        std::uint64_t v = 0;
        while (!q->pop(v)) {
          ++empty;
          relax();
        }
        bad |= v ^ value_of(i);  // order and content
        s += v;
      }
      sum.store(s, std::memory_order_relaxed);
      mismatch.store(bad, std::memory_order_relaxed);
      empty_polls.store(empty_polls.load(std::memory_order_relaxed) + empty, std::memory_order_relaxed);
      done.store(r, std::memory_order_release);
    }
  });

  std::uint64_t r = 0;
  for (auto _ : state) {
    ++r;
    round.store(r, std::memory_order_release);
    for (std::uint64_t i = 0; i < kItems; ++i) {
      while (!q->push(value_of(i))) {
        ++full_polls;
        relax();
      }
    }
    while (done.load(std::memory_order_acquire) < r) relax();
    if (sum.load(std::memory_order_relaxed) != want || mismatch.load(std::memory_order_relaxed) != 0) {
      state.SkipWithError("checksum mismatch: items lost, duplicated or reordered");
      break;
    }
  }
  stop.store(true, std::memory_order_release);
  consumer.join();
  const auto items = state.iterations() * static_cast<std::int64_t>(kItems);
  state.SetItemsProcessed(items);
  // Failed polls per item: shows whether the run was producer-bound (queue empty) or consumer-bound (full).
  const auto per_item = static_cast<double>(std::max<std::int64_t>(items, 1));
  state.counters["full_polls/item"] = static_cast<double>(full_polls) / per_item;
  state.counters["empty_polls/item"] = static_cast<double>(empty_polls.load()) / per_item;
}

template <typename Q>
void bm_round_trip(benchmark::State& state) {
  auto ping = std::make_unique<Q>();
  auto pong = std::make_unique<Q>();

  ag::bench::AffinityGuard restore;
  place_producer();
  std::thread echo([&] {
    place_consumer();
    for (;;) {
      std::uint64_t v = 0;
      while (!ping->pop(v)) relax();
      if (v == kStop) return;
      while (!pong->push(v)) relax();
    }
  });
  auto trip = [&](std::uint64_t v) noexcept {
    while (!ping->push(v)) relax();
    std::uint64_t back = 0;
    while (!pong->pop(back)) relax();
    return back;
  };

  for (std::uint64_t i = 0; i < 1024; ++i) (void)trip(i);  // both threads running, lines warm
  std::uint64_t bad = 0;
  for (auto _ : state) {
    for (std::uint64_t i = 0; i < kTrips; ++i) bad |= trip(i) ^ i;
  }
  while (!ping->push(kStop)) relax();
  echo.join();
  if (bad != 0) state.SkipWithError("round trip returned a different value");
  const auto trips = state.iterations() * static_cast<std::int64_t>(kTrips);
  state.SetItemsProcessed(trips);
  state.counters["round_trips"] = benchmark::Counter(static_cast<double>(trips));
}

// Console output as usual, and every non-failed repetition kept for the summary.
class KeepingReporter : public benchmark::ConsoleReporter {
 public:
  void ReportRuns(const std::vector<Run>& runs) override {
    for (const auto& r : runs)
      if (r.run_type == Run::RT_Iteration && !r.error_occurred) kept_[r.run_name.function_name].push_back(r);
    ConsoleReporter::ReportRuns(runs);
  }
  [[nodiscard]] const std::vector<Run>* find(const std::string& name) const {
    auto it = kept_.find(name);
    return it == kept_.end() ? nullptr : &it->second;
  }

 private:
  std::map<std::string, std::vector<Run>> kept_;
};

double median(std::vector<double> v) {
  if (v.empty()) return 0.0;
  std::sort(v.begin(), v.end());
  const std::size_t n = v.size();
  return n % 2 == 1 ? v[n / 2] : 0.5 * (v[n / 2 - 1] + v[n / 2]);
}

// Median items/s over the repetitions, 0 when the benchmark did not run.
double median_items_per_s(const KeepingReporter& rep, const std::string& name) {
  const auto* runs = rep.find(name);
  if (runs == nullptr) return 0.0;
  std::vector<double> v;
  for (const auto& r : *runs) {
    auto it = r.counters.find("items_per_second");
    if (it != r.counters.end()) v.push_back(it->second.value);
  }
  return median(v);
}

// Median ns per round trip over the repetitions, 0 when the benchmark did not run.
double median_ns_per_trip(const KeepingReporter& rep, const std::string& name) {
  const auto* runs = rep.find(name);
  if (runs == nullptr) return 0.0;
  std::vector<double> v;
  for (const auto& r : *runs) {
    auto it = r.counters.find("round_trips");
    if (it == r.counters.end() || it->second.value <= 0.0) continue;
    v.push_back(r.real_accumulated_time * 1e9 / it->second.value);
  }
  return median(v);
}

double safe_ratio(double a, double b) { return b > 0.0 ? a / b : 0.0; }

void print_help(const char* argv0) {
  std::printf(
      "usage: %s [google-benchmark flags]\n"
      "  Moves %llu uint64 items producer -> consumer through ag::SpscRing<uint64_t, %zu> and\n"
      "  moodycamel::ReaderWriterQueue<uint64_t>(%zu) (checksummed), then ping-pongs one value over two\n"
      "  queues of each kind. Each is repeated 7 times by default, repetitions randomly interleaved\n"
      "  (--benchmark_repetitions=N, --benchmark_enable_random_interleaving=false to change), and the\n"
      "  medians are compared. full_polls/item and empty_polls/item count failed try_push / pop polls:\n"
      "  which side waited. AG_BENCH_OUT=<file> appends the summary as one JSON line.\n\n",
      argv0, static_cast<unsigned long long>(kItems), kCapacity, kCapacity);
}

}  // namespace

int main(int argc, char** argv) {
  for (int i = 1; i < argc; ++i)
    if (std::strcmp(argv[i], "--help") == 0 || std::strcmp(argv[i], "-h") == 0) print_help(argv[0]);

  // Defaults first, so the same flags given on the command line win.
  // Repetitions run in random interleaved order so a noisy spell on the machine hits both queues alike.
  std::vector<char*> args;
  std::string reps = "--benchmark_repetitions=7";
  std::string interleave = "--benchmark_enable_random_interleaving=true";
  args.push_back(argv[0]);
  args.push_back(reps.data());
  args.push_back(interleave.data());
  for (int i = 1; i < argc; ++i) args.push_back(argv[i]);
  int n = static_cast<int>(args.size());
  args.push_back(nullptr);
  benchmark::Initialize(&n, args.data());
  if (benchmark::ReportUnrecognizedArguments(n, args.data())) return 1;

  const std::vector<int> cpus = ag::bench::allowed_cpus();
  if (cpus.size() >= 2) {
    g_place.producer_cpu = cpus[0];
    g_place.consumer_cpu = cpus[1];
    g_place.pinned = true;
    std::printf("ring bench: producer pinned to CPU %d, consumer pinned to CPU %d (%zu CPUs available), busy spin with the CPU pause hint\n",
                g_place.producer_cpu, g_place.consumer_cpu, cpus.size());
  } else {
    g_place.yield = true;
    std::printf("ring bench: only %zu CPU available: threads not pinned, spinning with sched_yield "
                "(figures are scheduler-bound, not queue-bound)\n",
                cpus.size());
  }
  std::fflush(stdout);

  benchmark::RegisterBenchmark("ring_throughput/airground", bm_throughput<AgQueue>)
      ->UseRealTime()->Unit(benchmark::kMillisecond)->MinTime(0.2);
  benchmark::RegisterBenchmark("ring_throughput/moodycamel", bm_throughput<MoodyQueue>)
      ->UseRealTime()->Unit(benchmark::kMillisecond)->MinTime(0.2);
  benchmark::RegisterBenchmark("ring_round_trip/airground", bm_round_trip<AgQueue>)
      ->UseRealTime()->Unit(benchmark::kMicrosecond)->MinTime(0.2);
  benchmark::RegisterBenchmark("ring_round_trip/moodycamel", bm_round_trip<MoodyQueue>)
      ->UseRealTime()->Unit(benchmark::kMicrosecond)->MinTime(0.2);

  KeepingReporter reporter;
  benchmark::RunSpecifiedBenchmarks(&reporter);
  benchmark::Shutdown();

  const double ag_tp = median_items_per_s(reporter, "ring_throughput/airground") / 1e6;
  const double mc_tp = median_items_per_s(reporter, "ring_throughput/moodycamel") / 1e6;
  const double ag_rt = median_ns_per_trip(reporter, "ring_round_trip/airground");
  const double mc_rt = median_ns_per_trip(reporter, "ring_round_trip/moodycamel");
  const double tp_ratio = safe_ratio(ag_tp, mc_tp);
  const double rt_ratio = safe_ratio(mc_rt, ag_rt);

  std::printf("\n");
  if (g_place.pinned)
    std::printf("(medians of the repetitions; producer on CPU %d, consumer on CPU %d)\n", g_place.producer_cpu,
                g_place.consumer_cpu);
  else
    std::printf("(medians of the repetitions; threads NOT pinned: single CPU)\n");
  if (ag_tp > 0.0 && mc_tp > 0.0)
    std::printf("ring throughput: airground %.1f Mitems/s, moodycamel %.1f Mitems/s, ratio X/Y = %.2f (goal >= 1.0)\n",
                ag_tp, mc_tp, tp_ratio);
  else
    std::printf("ring throughput: not measured (filtered out or failed)\n");
  if (ag_rt > 0.0 && mc_rt > 0.0)
    std::printf("ring round-trip: airground %.0f ns, moodycamel %.0f ns, ratio B/A = %.2f (>1 means airground faster)\n",
                ag_rt, mc_rt, rt_ratio);
  else
    std::printf("ring round-trip: not measured (filtered out or failed)\n");

  char line[512];
  std::snprintf(line, sizeof line,
                "{\"bench\":\"ring\",\"airground_mitems_per_s\":%.3f,\"moodycamel_mitems_per_s\":%.3f,"
                "\"throughput_ratio\":%.4f,\"airground_round_trip_ns\":%.1f,\"moodycamel_round_trip_ns\":%.1f,"
                "\"round_trip_ratio\":%.4f,\"pinned\":%s,\"producer_cpu\":%d,\"consumer_cpu\":%d}",
                ag_tp, mc_tp, tp_ratio, ag_rt, mc_rt, rt_ratio, g_place.pinned ? "true" : "false",
                g_place.producer_cpu, g_place.consumer_cpu);
  const std::string out = ag::bench::append_result_line(line);
  if (!out.empty()) std::printf("summary appended to %s\n", out.c_str());
  return 0;
}
