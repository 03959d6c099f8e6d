// The HIL run's wire bridges: Ouster packets over UDP and the ODrives on the cannelloni CAN bridge per
// ground robot; for the quadrotor UBX and MAVLink on two pseudo-terminals and the camera's frame stream on a FIFO.
#include <arpa/inet.h>
#include <fcntl.h>
#include <sys/socket.h>
#include <sys/stat.h>
#include <termios.h>
#include <unistd.h>

#include <array>
#include <cerrno>
#include <cmath>
#include <cstring>
#include <fstream>
#include <opencv2/core.hpp>

#include "airground/drivers/gps/ublox/ubx.hpp"
#include "gnss_device.hpp"
#include "hil_run.hpp"

namespace ag::sim::hil {
Status open_ugv_devices(Ugv& u, const json& meta, const fs::path& meta_path, std::uint16_t lidar_port, std::uint16_t imu_port,
                        std::uint16_t can_robot, std::uint16_t can_sim) {
  json m = meta;
  m["udp_port_lidar"] = lidar_port;
  m["udp_port_imu"] = imu_port;
  std::ofstream(meta_path) << m.dump(2) << "\n";
  auto info = ouster::read_metadata_file(meta_path.string());
  if (!info) return info.error();
  u.ouster = std::make_unique<OusterPackets>(info.value());
  u.udp = ::socket(AF_INET, SOCK_DGRAM | SOCK_CLOEXEC | SOCK_NONBLOCK, 0);
  int sndbuf = 4 << 20;
  ::setsockopt(u.udp, SOL_SOCKET, SO_SNDBUF, &sndbuf, sizeof sndbuf);
  u.lidar_to.sin_family = AF_INET;
  u.lidar_to.sin_port = htons(lidar_port);
  u.lidar_to.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
  can::CannelloniConfig cc;
  cc.bind_address = "127.0.0.1";
  cc.local_port = can_sim;
  cc.remote_port = can_robot;
  auto bus = can::CannelloniBus::open(cc);
  if (!bus) return bus.error();
  u.bus = std::move(bus).value();
  u.bp = base::BaseParams{};
  u.odrive = std::make_unique<base::OdriveSimulator>(*u.bus, std::array<std::uint8_t, 2>{u.bp.left_node, u.bp.right_node});
  u.last_pose = u.vehicle.pose();
  return ok_status();
}

// A pseudo-terminal in raw mode (no echo, no line discipline).
Status open_pty(Run& run, const char* name, Pty& p) {
  const int pty = ::posix_openpt(O_RDWR | O_NOCTTY | O_NONBLOCK | O_CLOEXEC);
  if (pty < 0 || ::grantpt(pty) != 0 || ::unlockpt(pty) != 0)
    return Error::make(ErrorCode::kIo, std::string("pseudo-terminal for ") + name + ": " + std::strerror(errno));
  p.fd = pty;
  p.path = ::ptsname(pty);
  p.slave = ::open(p.path.c_str(), O_RDWR | O_NOCTTY | O_CLOEXEC);  // held open: no hang-up while the robot reopens
  if (p.slave >= 0) {
    termios tio{};
    ::tcgetattr(p.slave, &tio);
    ::cfmakeraw(&tio);
    ::tcsetattr(p.slave, TCSANOW, &tio);
  }
  const fs::path link = run.out / (std::string(name) + ".pty");
  std::error_code ec;
  fs::remove(link, ec);
  fs::create_symlink(p.path, link, ec);
  return ok_status();
}

void pump_autopilot(Run& run) {
  std::array<std::uint8_t, 4096> buf{};
  // What does not fit in the pty's buffer is lost, as bytes are on a UART nobody reads.
  for (std::size_t n; (n = run.px4_link.to_robot.read(buf)) > 0;) (void)!::write(run.autopilot_pty.fd, buf.data(), n);
  for (ssize_t n; (n = ::read(run.autopilot_pty.fd, buf.data(), buf.size())) > 0;)
    (void)run.px4_link.from_robot.write(std::span<const std::uint8_t>(buf.data(), static_cast<std::size_t>(n)));
}

// The frame stream the uav's camera stage reads.
Status make_camera_fifo(Run& run) {
  run.fifo = run.out / "camera.agfs";
  std::error_code ec;
  fs::remove(run.fifo, ec);
  if (::mkfifo(run.fifo.c_str(), 0600) != 0) return Error::make(ErrorCode::kIo, "mkfifo " + run.fifo.string() + ": " + std::strerror(errno));
  return ok_status();
}

void step_base(Ugv& u, TimeNs now, double dt, const World& w) {
  u.odrive->step(now);
  u.vehicle.command_wheels(base::wheel_rad_s(u.bp, 0, u.odrive->vel_turns_s(0)), base::wheel_rad_s(u.bp, 1, u.odrive->vel_turns_s(1)));
  if (u.vehicle.step(dt, w)) ++u.collisions;
  const Pose2 p = u.vehicle.pose();
  u.distance_m += std::hypot(p.x - u.last_pose.x, p.y - u.last_pose.y);
  u.last_pose = p;
}

bool send_nav_pvt(int pty, TimeNs now, const GpsFix& fix) {
  NavPvtBytes msg;
  const std::size_t len = encode_nav_pvt_message(now, fix, msg);
  return ::write(pty, msg.data(), len) == static_cast<ssize_t>(len);
}

std::uint64_t send_revolution(Ugv& u, const Pose3& sp, TimeNs now, TimeNs lidar_period, bool labels_oracle, const World& w) {
  return u.ouster->send_revolution(std::span<const std::vector<LidarPoint>>(&u.scan, 1), sp, now, lidar_period, labels_oracle, w,
                                   [&u](std::span<const std::uint8_t> p) {
                                     return ::sendto(u.udp, p.data(), p.size(), 0, reinterpret_cast<const sockaddr*>(&u.lidar_to),
                                                     sizeof u.lidar_to) == static_cast<ssize_t>(p.size());
                                   });
}

std::optional<camera::FrameStreamWriter> open_frame_stream(const fs::path& fifo) {
  const int fd = ::open(fifo.c_str(), O_WRONLY | O_NONBLOCK | O_CLOEXEC);
  if (fd < 0) return std::nullopt;
  (void)::fcntl(fd, F_SETPIPE_SZ, 4 << 20);  // a whole frame fits: the reader drains it in one step
  auto wr = camera::FrameStreamWriter::from_fd(fd, fifo.string());
  if (!wr) return std::nullopt;
  return std::move(wr).value();
}

void fill_image(CameraImageMsg& m, const CameraFrame& cf, TimeNs now, std::uint32_t seq, bool labels_oracle) {
  m.stamp = now;
  m.published = now;
  m.seq = seq;
  m.labels = labels_oracle ? LabelSource::kGroundTruth : LabelSource::kNone;  // a camera gives no classes
  if (!labels_oracle) m.cls.fill(255);
  for (int r = 0; r < kImageHeight; ++r) {
    std::memcpy(m.rgb.data() + static_cast<std::size_t>(r) * kImageWidth * 3, cf.rgb.ptr<std::uint8_t>(r), kImageWidth * 3);
    if (labels_oracle) std::memcpy(m.cls.data() + static_cast<std::size_t>(r) * kImageWidth, cf.cls.ptr<std::uint8_t>(r), kImageWidth);
  }
}

void close_devices(Run& run) {
  for (Pty* p : {&run.gps_pty, &run.autopilot_pty}) {
    if (p->fd >= 0) ::close(p->fd);
    if (p->slave >= 0) ::close(p->slave);
  }
  for (auto& u : run.ugvs) {
    ::close(u->udp);
    run.res.can_frames_in += u->odrive->commands_received();
  }
}

}  // namespace ag::sim::hil
