// The HIL run's three threads: physics (200 Hz, never stalls), the camera (renders and writes frames)
// and the sensor loop (GNSS, attitude, LiDAR, the oracle VO, and the mission as the base station sees it).
#include <arpa/inet.h>
#include <sys/socket.h>
#include <time.h>
#include <unistd.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <string>

#include "hil_run.hpp"
#include "worker_pool.hpp"

namespace ag::sim::hil {
namespace {

constexpr TimeNs kLidarPeriod = kNsPerS / 10, kStatePeriod = kNsPerS;

void sleep_until(TimeNs t) {
  timespec ts{static_cast<time_t>(t / kNsPerS), static_cast<long>(t % kNsPerS)};
  ::clock_nanosleep(CLOCK_MONOTONIC, TIMER_ABSTIME, &ts, nullptr);
}

// METHOD http://127.0.0.1:port/path (no body) with a short timeout: the status (0 on any failure: the
// base may be starting) and the body.
int http_request(const char* method, std::uint16_t port, const std::string& path, std::string& body) {
  const int fd = ::socket(AF_INET, SOCK_STREAM | SOCK_CLOEXEC, 0);
  if (fd < 0) return {};
  timeval tv{1, 0};
  ::setsockopt(fd, SOL_SOCKET, SO_RCVTIMEO, &tv, sizeof tv);
  ::setsockopt(fd, SOL_SOCKET, SO_SNDTIMEO, &tv, sizeof tv);
  sockaddr_in a{};
  a.sin_family = AF_INET;
  a.sin_port = htons(port);
  a.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
  std::string out;
  if (::connect(fd, reinterpret_cast<sockaddr*>(&a), sizeof a) == 0) {
    const std::string req = std::string(method) + " " + path + " HTTP/1.1\r\nHost: 127.0.0.1\r\nContent-Length: 0\r\nConnection: close\r\n\r\n";
    if (::send(fd, req.data(), req.size(), MSG_NOSIGNAL) == static_cast<ssize_t>(req.size())) {
      char buf[65536];
      for (;;) {
        const ssize_t n = ::recv(fd, buf, sizeof buf, 0);
        if (n <= 0) break;
        out.append(buf, static_cast<std::size_t>(n));
      }
    }
  }
  ::close(fd);
  const auto head = out.find("\r\n\r\n");
  if (head == std::string::npos || out.rfind("HTTP/1.1 ", 0) != 0) return 0;
  body = out.substr(head + 4);
  return std::atoi(out.c_str() + 9);
}

std::string http_get(std::uint16_t port, const char* path) {
  std::string body;
  return http_request("GET", port, path, body) == 200 ? body : std::string();
}

// The operator arms each ground robot from the base station once its page answers, as a user clicks
// "arm" there (the shipped robots start with their wheels latched: base.start_armed false).
void arm_from_base_station(Run& run) {
  for (auto& up : run.ugvs) {
    Ugv& u = *up;
    if (u.armed_by_operator) continue;
    std::string body;
    if (http_request("POST", run.web_port, "/api/arm?robot=" + std::to_string(u.id), body) == 202) {
      u.armed_by_operator = true;
      ++run.res.arm_requests;
    }
  }
}

// When the sensor loop's periodic work is next due.
struct SensorClock {
  TimeNs next_lidar, next_state, next_progress, next_trail, next_rec;
  TimeNs done_seen{-1};  // when every ground robot was first seen done
};

// The quadrotor's pose and each ground robot's lidar pose, read under the physics lock; the truth
// trail (when due) and the last 30 s of history taken on the way.
std::vector<Pose3> truth_snapshot(Run& run, TimeNs now, TimeNs next_trail, Pose3& qp) {
  std::vector<Pose3> lidar_poses;
  std::lock_guard<std::mutex> lk(run.mu);
  qp = run.quad->pose();
  for (auto& u : run.ugvs) {
    Pose3 p = u->vehicle.pose3();
    p.z += run.lidar_mount_z_m;
    lidar_poses.push_back(p);
    if (now >= next_trail) u->truth_trail.emplace_back(u->vehicle.pose().x, u->vehicle.pose().y);
    u->history.emplace_back(now, u->vehicle.pose());
    while (!u->history.empty() && u->history.front().first < now - 30 * kNsPerS) u->history.pop_front();
  }
  return lidar_poses;
}

void record_truth(Run& run, const Pose3& qp, const std::vector<Pose3>& lidar_poses) {
  std::lock_guard<std::mutex> lk(run.rec_mu);
  const TimeNs t = monotonic_now() - run.rec0;
  run.rec->uav_pose(t, qp);
  for (std::size_t k = 0; k < run.ugvs.size(); ++k) {
    Pose3 p = lidar_poses[k];
    p.z -= run.lidar_mount_z_m;
    run.rec->ugv_pose(t, static_cast<int>(k), p, nullptr, run.ugvs[k]->has_est ? &run.ugvs[k]->est : nullptr);
  }
  run.rec->tick(t, nullptr);
}

// GNSS: UBX NAV-PVT on the receiver's serial line. Attitude: the simulated PX4's ATTITUDE (and its
// HEARTBEAT) on TELEM2. Visual odometry only with the vo oracle: queued for the camera thread, which
// writes it to the frame stream before each image.
void send_gnss_attitude_vo(Run& run, TimeNs now, const Pose3& qp) {
  GpsFix fix;
  if (run.gps->sample(now, qp, fix)) {
    if (run.rec) {
      std::lock_guard<std::mutex> lk(run.rec_mu);
      run.rec->uav_gps(monotonic_now() - run.rec0, fix.lat_deg, fix.lon_deg, fix.height_m, fix.h_accuracy_m);
    }
    if (send_nav_pvt(run.gps_pty.fd, now, fix)) ++run.res.ubx_messages;
  }
  run.px4.step(now);
  AttitudeSample as;
  if (run.attitude->sample(now, qp, as)) run.px4.send_attitude(as);
  pump_autopilot(run);
  VoSample vs;
  if (run.vo && run.vo->sample(now, qp, vs)) {
    VoMsg m;
    m.stamp = vs.stamp;
    m.published = now;
    m.segment = vs.segment;
    m.tracking = vs.tracking;
    m.pose = vs.pose;
    std::lock_guard<std::mutex> lk(run.vo_mu);
    if (run.vo_queue.size() < 256) run.vo_queue.push_back(m);
  }
}

// Casts every ground robot's scan and sends it as one revolution of Ouster packets.
void lidar_revolution(Run& run, TimeNs now, const std::vector<Pose3>& lidar_poses, TimeNs& next_lidar) {
  HilResult& res = run.res;
  auto& ugvs = run.ugvs;
  for (std::size_t k = 0; k < ugvs.size(); ++k) run.lidar->scan(lidar_poses[k], run.opt.seed ^ static_cast<std::uint64_t>(now) ^ k, ugvs[k]->scan);
  if (run.rec) {
    std::lock_guard<std::mutex> lk(run.rec_mu);
    for (std::size_t k = 0; k < ugvs.size(); ++k) run.rec->ugv_scan(monotonic_now() - run.rec0, static_cast<int>(k), res.lidar_revolutions + 1, &ugvs[k]->scan, 1);
  }
  // A revolution every 100 ms; one the simulator could not cast in time is skipped, not sent late.
  next_lidar += kLidarPeriod;
  if (next_lidar < now) {
    res.lidar_revolutions_skipped += static_cast<std::uint64_t>((now - next_lidar) / kLidarPeriod) + 1;
    next_lidar = now + kLidarPeriod;
  }
  ++res.lidar_revolutions;
  for (std::size_t k = 0; k < ugvs.size(); ++k)
    res.lidar_packets += send_revolution(*ugvs[k], lidar_poses[k], now, kLidarPeriod, run.labels_oracle, run.world);
}

// The mission as the base station sees it; true once every ground robot has been done for 3 s (a few
// more polls with the robots standing, so the final error is not the base's lag).
bool poll_base_state(Run& run, TimeNs now, TimeNs& done_seen) {
  const std::string body = http_get(run.web_port, "/api/state");
  if (body.empty()) return false;
  run.last_state = body;
  arm_from_base_station(run);
  try {
    const json s = json::parse(body);
    const int n = static_cast<int>(run.mf.team.size());
    int done = 0;
    for (auto& up : run.ugvs) {
      Ugv& u = *up;
      for (const json& r : s.value("robots", json::array())) {
        if (r.value("id", -1) != u.id) continue;
        if (r.value("has_pose", false)) {
          u.has_est = true;
          u.est = Pose2{r.value("x", 0.0), r.value("y", 0.0), r.value("yaw", 0.0)};
          u.est_trail.emplace_back(u.est.x, u.est.y);
          // The pose is as old as the base's copy of it: compare with the truth of that time.
          std::lock_guard<std::mutex> lk(run.mu);
          const Pose2 tr = u.truth_at(now - static_cast<TimeNs>(r.value("age_s", 0.0) * 1e9));
          u.est_error_m = std::hypot(u.est.x - tr.x, u.est.y - tr.y);
          if (r.value("status", std::string()) == "tracking") u.errors.push_back(u.est_error_m);
        }
        if (r.contains("claim") && r["claim"].is_object()) u.state = r["claim"].value("state", std::string("-"));
      }
      if (u.state == "done") ++done;
    }
    if (done == n && done_seen < 0) done_seen = now;
    if (done == n && now - done_seen >= 3 * kNsPerS) return true;
  } catch (const std::exception&) {
    // a half-written answer: the next poll reads it again
  }
  return false;
}

void print_progress(Run& run, TimeNs now, const Pose3& qp) {
  std::fprintf(stderr, "hil %5.0f s  uav (%.0f, %.0f, %.0f) wp %zu  frames %llu  lidar pkts %llu", to_seconds(now - run.t0), qp.x, qp.y, qp.z,
               run.quad->waypoints_reached(), static_cast<unsigned long long>(run.cam_written.load()),
               static_cast<unsigned long long>(run.res.lidar_packets));
  std::lock_guard<std::mutex> lk(run.mu);
  for (auto& u : run.ugvs)
    std::fprintf(stderr, " | %s %s %.1f m%s", u->name.c_str(), u->state.c_str(), u->distance_m,
                 u->est_error_m >= 0 ? (" err " + fixed(u->est_error_m, 2) + " m").c_str() : "");
  std::fprintf(stderr, "\n");
}

}  // namespace

void physics_thread(Run& run) {
  TimeNs last = monotonic_now();
  TimeNs next = last;
  while (!run.stop.load(std::memory_order_relaxed)) {
    next += 5 * kNsPerMs;
    sleep_until(next);
    const TimeNs now = monotonic_now();
    const double dt = to_seconds(now - last);
    last = now;
    std::lock_guard<std::mutex> lk(run.mu);
    for (auto& up : run.ugvs) step_base(*up, now, dt, run.world);
    run.quad->step(dt);
  }
}

// Renders a frame every 1/camera_hz (or as fast as it can) and writes it, after the VO queued since
// the last one, to the frame stream (opened once the uav reads the FIFO). On its own thread so a slow
// render never holds back the LiDAR or the GNSS.
void camera_thread(Run& run) {
  std::optional<camera::FrameStreamWriter> frames;
  auto image = std::make_unique<CameraImageMsg>();
  CameraFrame cf;
  std::uint32_t image_seq = 0;
  const TimeNs period = static_cast<TimeNs>(1e9 / run.opt.camera_hz);
  TimeNs next = monotonic_now() + kNsPerS;
  std::vector<VoMsg> vo_out;
  WorkerPool cam_pool(2);
  std::uint64_t rendered = 0;
  while (!run.stop_camera.load(std::memory_order_relaxed)) {
    sleep_until(next);
    if (run.stop_camera.load(std::memory_order_relaxed)) break;
    const TimeNs now = monotonic_now();
    next += period;
    if (next < now) {
      run.cam_skipped.fetch_add(static_cast<std::uint64_t>((now - next) / period) + 1, std::memory_order_relaxed);
      next = now + period;
    }
    if (!frames) frames = open_frame_stream(run.fifo);
    Pose3 qp;
    {
      std::lock_guard<std::mutex> lk(run.mu);
      qp = run.quad->pose();
    }
    run.camera->prepare(qp, cf, now);
    constexpr int kBands = 8;
    cam_pool.run(kBands, [&](std::size_t j) {
      const int h = cf.rgb.rows, b = static_cast<int>(j);
      run.camera->render_rows(qp, h * b / kBands, h * (b + 1) / kBands, cf);
    });
    if (run.rec) {
      std::lock_guard<std::mutex> lk(run.rec_mu);
      run.rec->camera_frame(monotonic_now() - run.rec0, ++rendered, cf.rgb);
    }
    vo_out.clear();
    {
      std::lock_guard<std::mutex> lk(run.vo_mu);
      vo_out.assign(run.vo_queue.begin(), run.vo_queue.end());
      run.vo_queue.clear();
    }
    if (!frames) {
      run.cam_dropped.fetch_add(1, std::memory_order_relaxed);
      continue;
    }
    // (A failed write is counted, the stream kept: the camera stage does not reopen a FIFO that ended.)
    for (const VoMsg& m : vo_out)
      if (frames->write_vo(m)) run.vo_written.fetch_add(1, std::memory_order_relaxed);
    fill_image(*image, cf, now, image_seq++, run.labels_oracle);
    if (frames->write_image(*image)) run.cam_written.fetch_add(1, std::memory_order_relaxed);
    else run.cam_dropped.fetch_add(1, std::memory_order_relaxed);
  }
}

void sensor_loop(Run& run) {
  run.t0 = monotonic_now();
  const TimeNs t0 = run.t0;
  SensorClock due{t0 + kNsPerS, t0 + 2 * kNsPerS, t0 + 5 * kNsPerS, t0, t0};
  const TimeNs deadline = t0 + static_cast<TimeNs>(run.opt.max_duration_s * 1e9);
  while (true) {
    const TimeNs now = monotonic_now();
    if (now >= deadline) break;
    // A robot process that died ends the run.
    run.failure = reap_exited(run.children);
    if (!run.failure.empty()) break;
    Pose3 qp;
    const std::vector<Pose3> lidar_poses = truth_snapshot(run, now, due.next_trail, qp);
    if (now >= due.next_trail) due.next_trail += kNsPerS / 2;
    if (run.rec && now >= due.next_rec) {
      due.next_rec += kNsPerS / 10;
      record_truth(run, qp, lidar_poses);
    }
    send_gnss_attitude_vo(run, now, qp);
    if (now >= due.next_lidar) lidar_revolution(run, now, lidar_poses, due.next_lidar);
    if (now >= due.next_state) {
      due.next_state += kStatePeriod;
      if (poll_base_state(run, now, due.done_seen)) {
        run.res.mission_done = true;
        break;
      }
    }
    if (run.opt.progress && now >= due.next_progress) {
      due.next_progress += 5 * kNsPerS;
      print_progress(run, now, qp);
    }
    // Every 10 ms at least: the autopilot's 50 Hz ATTITUDE comes out on its own grid.
    const TimeNs wake = std::min({due.next_lidar, due.next_state, now + 10 * kNsPerMs});
    if (wake > monotonic_now()) sleep_until(wake);
  }
}

}  // namespace ag::sim::hil
