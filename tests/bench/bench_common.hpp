// Helpers shared by the benchmarks: CPU selection and pinning, spinning, the optional results file.
#pragma once

#include <pthread.h>
#include <sched.h>

#include <cstdio>
#include <cstdlib>
#include <string>
#include <vector>

namespace ag::bench {

// The CPUs this process may run on, in order.
inline std::vector<int> allowed_cpus() {
  std::vector<int> cpus;
  cpu_set_t set;
  CPU_ZERO(&set);
  if (sched_getaffinity(0, sizeof set, &set) != 0) return cpus;
  for (int c = 0; c < CPU_SETSIZE; ++c)
    if (CPU_ISSET(static_cast<std::size_t>(c), &set)) cpus.push_back(c);
  return cpus;
}

// Pins the calling thread to one CPU; false if refused (the thread then runs where it was allowed).
inline bool pin_this_thread(int cpu) {
  if (cpu < 0) return false;
  cpu_set_t set;
  CPU_ZERO(&set);
  CPU_SET(static_cast<std::size_t>(cpu), &set);
  return pthread_setaffinity_np(pthread_self(), sizeof set, &set) == 0;
}

// Saves the calling thread's affinity and restores it on scope exit.
class AffinityGuard {
 public:
  AffinityGuard() { ok_ = pthread_getaffinity_np(pthread_self(), sizeof saved_, &saved_) == 0; }
  AffinityGuard(const AffinityGuard&) = delete;
  AffinityGuard& operator=(const AffinityGuard&) = delete;
  ~AffinityGuard() {
    if (ok_) pthread_setaffinity_np(pthread_self(), sizeof saved_, &saved_);
  }

 private:
  cpu_set_t saved_{};
  bool ok_{false};
};

// Appends one JSON line to $AG_BENCH_OUT when it is set; returns the path written (empty if none).
inline std::string append_result_line(const std::string& json) {
  const char* path = std::getenv("AG_BENCH_OUT");
  if (path == nullptr || *path == '\0') return {};
  std::FILE* f = std::fopen(path, "a");
  if (f == nullptr) {
    std::fprintf(stderr, "cannot open AG_BENCH_OUT=%s for appending\n", path);
    return {};
  }
  std::fprintf(f, "%s\n", json.c_str());
  std::fclose(f);
  return path;
}

}  // namespace ag::bench
