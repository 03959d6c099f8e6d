// Role main: parse arguments, load and validate the config, build the stages, run them real-time
// under the service loop (signals, sd_notify, watchdog), stop cleanly and print the counters.
#include "role_main.hpp"

#include <algorithm>
#include <unistd.h>

#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <string>
#include <vector>

#include "airground/platform/executor.hpp"
#include "airground/platform/log.hpp"
#include "airground/platform/role_instance.hpp"
#include "airground/platform/service.hpp"
#include "airground_version.hpp"
#include "sensor_labels_check.hpp"
#include "stage_agreement_check.hpp"

namespace ag {

namespace {

void print_help(const RoleDescription& role, const char* argv0) {
  std::printf(
      "airground-%.*s %s — %.*s\n\n"
      "Usage: %s [options]\n\n"
      "Options:\n"
      "  -c, --config FILE     parameters (YAML); default /etc/airground/%.*s.yaml if it exists,\n"
      "                        otherwise the built-in defaults\n"
      "  -s, --set KEY=VALUE   override one parameter, e.g. --set log.level=debug (repeatable)\n"
      "      --print-config    print the effective parameters with units and ranges, then exit\n"
      "      --check-config    validate the configuration and exit (0 = valid)\n"
      "      --run-for SECONDS stop by itself after this long (default: run until SIGTERM/SIGINT)\n"
      "      --oracle labels   allow the simulator's ground truth as an ablation: point classes from the\n"
      "                        Ouster reflectivity byte (lidar.classes: reflectivity), which airground-sim\n"
      "                        hil --oracle labels writes; refused without it (a real Ouster gives no class)\n"
      "  -h, --help            this help\n"
      "  -V, --version         version and build\n\n"
      "Stages (rate, budget, priority, cpu):\n",
      static_cast<int>(role.name.size()), role.name.data(), kAirgroundVersion, static_cast<int>(role.summary.size()),
      role.summary.data(), argv0, static_cast<int>(role.name.size()), role.name.data());
  for (const auto& s : role.stages)
    std::printf("  %-22.*s %6.1f Hz %7u us  prio %2d  cpu %2d\n", static_cast<int>(s.name.size()), s.name.data(),
                s.rate_hz, s.budget_us, s.priority, s.cpu);
  std::printf(
      "\nExit status: 0 stopped cleanly, 1 runtime failure, 2 usage or configuration error.\n"
      "Under systemd (Type=notify) it reports READY=1 once running and feeds the watchdog while every\n"
      "stage thread is alive.\n");
}

bool file_exists(const std::string& p) { return access(p.c_str(), R_OK) == 0; }

}  // namespace

int run_role(const RoleDescription& role, int argc, char** argv) {
  std::string config_path;
  bool config_given = false;
  bool print_config = false;
  bool check_config = false;
  bool labels_oracle = false;  // --oracle labels: the user named the ground-truth ablation
  double run_for_s = 0.0;
  std::vector<std::string> sets;
  const std::string rname(role.name);

  for (int i = 1; i < argc; ++i) {
    const std::string a = argv[i];
    auto need_value = [&](const char* opt) -> const char* {
      if (i + 1 >= argc) {
        std::fprintf(stderr, "airground-%s: option %s needs a value (see --help)\n", rname.c_str(), opt);
        std::exit(2);
      }
      return argv[++i];
    };
    if (a == "-h" || a == "--help") {
      print_help(role, argv[0]);
      return 0;
    } else if (a == "-V" || a == "--version") {
      std::printf("airground-%s %s (%s, %s)\n", rname.c_str(), kAirgroundVersion, kAirgroundGitRevision, kAirgroundTarget);
      return 0;
    } else if (a == "-c" || a == "--config") {
      config_path = need_value("--config");
      config_given = true;
    } else if (a.rfind("--config=", 0) == 0) {
      config_path = a.substr(9);
      config_given = true;
    } else if (a == "-s" || a == "--set") {
      sets.emplace_back(need_value("--set"));
    } else if (a == "--print-config") {
      print_config = true;
    } else if (a == "--check-config") {
      check_config = true;
    } else if (a == "--oracle" || a.rfind("--oracle=", 0) == 0) {
      const std::string v = a == "--oracle" ? std::string(need_value("--oracle")) : a.substr(9);
      for (std::size_t b = 0; b <= v.size();) {
        const std::size_t e = std::min(v.find(',', b), v.size());
        const std::string name = v.substr(b, e - b);
        if (name != "labels") {
          std::fprintf(stderr, "airground-%s: --oracle: unknown oracle '%s' (a role binary knows only 'labels')\n", rname.c_str(),
                       name.c_str());
          return 2;
        }
        labels_oracle = true;
        b = e + 1;
      }
    } else if (a == "--run-for") {
      const char* v = need_value("--run-for");
      char* end = nullptr;
      run_for_s = std::strtod(v, &end);
      if (end == v || *end != '\0' || run_for_s <= 0) {
        std::fprintf(stderr, "airground-%s: --run-for needs a positive number of seconds, got '%s'\n", rname.c_str(), v);
        return 2;
      }
    } else {
      std::fprintf(stderr, "airground-%s: unknown option '%s' (see --help)\n", rname.c_str(), a.c_str());
      return 2;
    }
  }

  const std::vector<ParamSection> schema = role_schema(role);
  if (!config_given) {
    const std::string def = "/etc/airground/" + rname + ".yaml";
    if (file_exists(def)) config_path = def;
  }
  Result<Config> loaded = config_path.empty() ? Result<Config>(Config::defaults(schema)) : Config::load_file(schema, config_path);
  if (!loaded) {
    std::fprintf(stderr, "airground-%s: %s\n", rname.c_str(), loaded.error().message.c_str());
    return 2;
  }
  Config cfg = std::move(loaded).value();
  for (const auto& s : sets) {
    if (Status st = cfg.set(s); !st) {
      std::fprintf(stderr, "airground-%s: %s\n", rname.c_str(), st.error().message.c_str());
      return 2;
    }
  }
  if (print_config) {
    std::printf("# airground-%s %s effective configuration%s%s\n", rname.c_str(), kAirgroundVersion,
                config_path.empty() ? " (built-in defaults)" : " from ", config_path.c_str());
    std::fputs(cfg.to_yaml().c_str(), stdout);
    return 0;
  }
  // Classes the robot's sensors cannot give (a V4L2 camera's, an Ouster's) stop it here, with the keys.
  if (Status st = check_sensor_labels(cfg, config_path.empty() ? "built-in defaults" : config_path, labels_oracle); !st) {
    std::fprintf(stderr, "airground-%s: %s\n", rname.c_str(), st.error().message.c_str());
    return 2;
  }
  for (const std::string& w : sensor_label_warnings(cfg, labels_oracle))  // before the logger starts: straight to stderr
    std::fprintf(stderr, "airground-%s: warning: %s\n", rname.c_str(), w.c_str());
  for (const std::string& w : stage_agreement_warnings(cfg))
    std::fprintf(stderr, "airground-%s: warning: %s\n", rname.c_str(), w.c_str());
  if (check_config) {
    std::printf("%s: valid\n", config_path.empty() ? "built-in defaults" : config_path.c_str());
    return 0;
  }

  log::Level lvl{};
  log::parse_level(cfg.get_text("log.level"), lvl);
  log::set_level(lvl);

  // Signals are blocked before any thread exists so only the service loop below takes them.
  block_shutdown_signals();
  log::start_writer();
  const ServiceNotifier systemd = ServiceNotifier::from_environment();

  std::string instance = cfg.get_text("robot.name");
  if (instance.empty()) instance = rname + std::to_string(cfg.get_int("robot.id"));
  AG_LOG_INFO("main", "starting airground-%s %s robot=%s config=%s", rname.c_str(), kAirgroundVersion, instance.c_str(),
              config_path.empty() ? "(defaults)" : config_path.c_str());

  MonotonicClock clock;
  auto robot = RoleInstance::create(role, cfg, clock, instance, StageThreads::kRealtime);
  if (!robot) {
    AG_LOG_ERROR("main", "%s", robot.error().message.c_str());
    log::stop_writer();
    return 1;
  }
  for (const std::string& ch : robot.value()->channels().read_but_unwritten())
    AG_LOG_WARN("main", "channel '%s' is read but no stage of the %s role writes it (a misspelled channel name, or a stage "
                "missing from the role table): its readers will wait forever", ch.c_str(), rname.c_str());
  RealtimeOptions opts;
  opts.realtime_priority = cfg.get_bool("scheduler.realtime");
  opts.lock_memory = cfg.get_bool("scheduler.lock_memory");
  opts.pin_cpus = cfg.get_bool("scheduler.pin_cpus");
  RealtimeExecutor exec(opts);
  exec.add(*robot.value());
  auto rep = exec.start();
  if (!rep) {
    AG_LOG_ERROR("main", "scheduler did not start: %s", rep.error().message.c_str());
    log::stop_writer();
    return 1;
  }
  AG_LOG_INFO("main", "running stages=%zu threads=%zu fifo_threads=%zu pinned=%zu memory_locked=%s",
              robot.value()->stages().size(), rep->threads, rep->fifo_threads, rep->pinned_threads,
              rep->memory_locked ? "yes" : "no");
  systemd.ready("running " + std::to_string(robot.value()->stages().size()) + " stages");

  // Service loop: wait for a signal, feed the watchdog only while every stage thread is alive.
  const TimeNs silence = from_seconds(cfg.get_real("scheduler.watchdog_silence_s"));
  const TimeNs tick = systemd.watchdog_interval() > 0 ? std::min(systemd.watchdog_interval() / 2, 100 * kNsPerMs) : 100 * kNsPerMs;
  const TimeNs deadline = run_for_s > 0 ? monotonic_now() + from_seconds(run_for_s) : 0;
  int sig = 0;
  bool starved = false;
  while (sig == 0) {
    sig = wait_for_shutdown_signal(tick);
    const TimeNs now = monotonic_now();
    if (exec.threads_alive(now, silence)) {
      starved = false;
      if (systemd.watchdog_interval() > 0) systemd.watchdog();
    } else if (!starved) {
      starved = true;
      AG_LOG_ERROR("main", "a stage thread has not run for %.1f s: no longer feeding the watchdog", to_seconds(silence));
    }
    if (deadline != 0 && now >= deadline) break;
  }
  if (sig != 0) AG_LOG_INFO("main", "%s received: stopping", strsignal(sig));
  systemd.stopping();
  exec.request_stop();
  exec.join();
  robot.value()->stop_all();

  for (std::size_t i = 0; i < robot.value()->perf().size(); ++i) {
    const StagePerf& p = robot.value()->perf().at(i);
    const StagePerfSnapshot s = snapshot(p);
    AG_LOG_INFO("main", "final stage=%s runs=%llu exec_p50_us=%.1f exec_p99_us=%.1f exec_max_us=%.1f late_p99_us=%.1f overruns=%llu slips=%llu",
                p.name.c_str(), static_cast<unsigned long long>(s.runs), to_us(s.exec_p50), to_us(s.exec_p99),
                to_us(s.exec_max), to_us(s.late_p99), static_cast<unsigned long long>(s.overruns),
                static_cast<unsigned long long>(s.slips));
  }
  AG_LOG_INFO("main", "stopped cleanly");
  log::stop_writer();
  return 0;
}

}  // namespace ag
