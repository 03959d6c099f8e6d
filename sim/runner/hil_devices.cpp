// The HIL run's wire bridges: Ouster packets over UDP and the ODrives on the cannelloni CAN bridge per
// ground robot, UBX on a pseudo-terminal and the camera's frame stream on a FIFO for the quadrotor.
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
#include "hil_run.hpp"

namespace ag::sim::hil {
namespace {

// The Ouster reflectivity byte of a surface (calibrated reflectivity, 0-100 for diffuse targets): the
// world's albedo under the point, grey, scaled to 0-100; 0 outside the world.
std::uint8_t albedo_reflectivity(const World& w, double x, double y) noexcept {
  const GridGeometry& g = w.header.grid;
  const auto c = g.col(x), r = g.row(y);
  if (!g.contains(c, r) || w.albedo.empty()) return 0;
  const cv::Vec3b a = w.albedo.at<cv::Vec3b>(r, c);
  return static_cast<std::uint8_t>((static_cast<int>(a[0]) + static_cast<int>(a[1]) + static_cast<int>(a[2])) * 100 / (3 * 255));
}

}  // namespace

// The Ouster metadata every ground robot's driver reads: the OS-1-64 of the fixture, in the chosen
// packet profile (every profile has at least 8-bit reflectivity: the class id) at the chosen lidar mode.
Result<json> ouster_metadata(const HilOptions& opt) {
  json meta;
  {
    std::ifstream mf_in(OusterBeamModel::default_metadata_path());
    if (!mf_in) return Error::make(ErrorCode::kIo, "cannot read " + OusterBeamModel::default_metadata_path());
    try {
      mf_in >> meta;
    } catch (const std::exception& e) {
      return Error::make(ErrorCode::kMalformed, OusterBeamModel::default_metadata_path() + ": " + e.what());
    }
  }
  if (opt.lidar_columns != 512 && opt.lidar_columns != 1024 && opt.lidar_columns != 2048)
    return Error::make(ErrorCode::kInvalidArgument, "--lidar-columns must be 512, 1024 or 2048");
  meta["lidar_mode"] = std::to_string(opt.lidar_columns) + "x10";
  if (auto p = ouster::parse_udp_profile(opt.lidar_profile); !p)
    return Error::make(ErrorCode::kInvalidArgument, "--lidar-profile: " + p.error().message);
  meta["udp_profile_lidar"] = opt.lidar_profile;
  if (meta.contains("data_format")) {
    meta["data_format"]["udp_profile_lidar"] = opt.lidar_profile;
    meta["data_format"]["columns_per_frame"] = opt.lidar_columns;
    meta["data_format"]["column_window"] = json::array({0, opt.lidar_columns - 1});
  }
  return meta;
}

Status open_ugv_devices(Ugv& u, const json& meta, const fs::path& meta_path, std::uint16_t lidar_port, std::uint16_t imu_port,
                        std::uint16_t can_robot, std::uint16_t can_sim) {
  json m = meta;
  m["udp_port_lidar"] = lidar_port;
  m["udp_port_imu"] = imu_port;
  std::ofstream(meta_path) << m.dump(2) << "\n";
  auto info = ouster::read_metadata_file(meta_path.string());
  if (!info) return info.error();
  u.info = info.value();
  u.fmt = std::make_unique<ouster::PacketFormat>(u.info);
  u.frame = ouster::LidarFrame(u.info.mode.columns, static_cast<int>(u.info.beam_altitude_deg.size()),
                               ouster::has_second_return(u.info.profile));
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
Status open_gps_pty(Run& run) {
  const int pty = ::posix_openpt(O_RDWR | O_NOCTTY | O_NONBLOCK | O_CLOEXEC);
  if (pty < 0 || ::grantpt(pty) != 0 || ::unlockpt(pty) != 0) return Error::make(ErrorCode::kIo, std::string("pseudo-terminal: ") + std::strerror(errno));
  run.pty = pty;
  run.pty_path = ::ptsname(pty);
  run.pty_slave = ::open(run.pty_path.c_str(), O_RDWR | O_NOCTTY | O_CLOEXEC);  // held open: no hang-up while the robot reopens
  if (run.pty_slave >= 0) {
    termios tio{};
    ::tcgetattr(run.pty_slave, &tio);
    ::cfmakeraw(&tio);
    ::tcsetattr(run.pty_slave, TCSANOW, &tio);
  }
  std::error_code ec;
  fs::remove(run.out / "gps.pty", ec);
  fs::create_symlink(run.pty_path, run.out / "gps.pty", ec);
  return ok_status();
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
  constexpr double kTwoPi = 2.0 * M_PI;
  const double l = u.bp.left_sign * u.odrive->vel_turns_s(0) * kTwoPi / u.bp.gear_ratio;
  const double r = u.bp.right_sign * u.odrive->vel_turns_s(1) * kTwoPi / u.bp.gear_ratio;
  u.vehicle.command_wheels(l, r);
  if (u.vehicle.step(dt, w)) ++u.collisions;
  const Pose2 p = u.vehicle.pose();
  u.distance_m += std::hypot(p.x - u.last_pose.x, p.y - u.last_pose.y);
  u.last_pose = p;
}

bool send_nav_pvt(int pty, TimeNs now, const GpsFix& fix) {
  ublox::NavPvt p;
  p.itow_ms = static_cast<std::uint32_t>((now / kNsPerMs) % (7 * 24 * 3600 * 1000LL));
  p.fix_type = fix.fix_type == GpsFixType::kNoFix ? ublox::FixType::kNone : ublox::FixType::k3D;
  p.flags_raw = fix.fix_type == GpsFixType::kNoFix ? 0 : 1;  // gnssFixOK
  p.valid_raw = 0x07;
  p.num_sv = 14;
  p.lat_e7 = static_cast<std::int32_t>(std::lround(fix.lat_deg * 1e7));
  p.lon_e7 = static_cast<std::int32_t>(std::lround(fix.lon_deg * 1e7));
  p.height_mm = static_cast<std::int32_t>(std::lround(fix.height_m * 1e3));
  p.hmsl_mm = p.height_mm;
  p.h_acc_mm = static_cast<std::uint32_t>(std::lround(fix.h_accuracy_m * 1e3));
  p.v_acc_mm = static_cast<std::uint32_t>(std::lround(fix.v_accuracy_m * 1e3));
  p.vel_ned_mm_s[0] = static_cast<std::int32_t>(std::lround(fix.vel_north_mps * 1e3));
  p.vel_ned_mm_s[1] = static_cast<std::int32_t>(std::lround(fix.vel_east_mps * 1e3));
  p.vel_ned_mm_s[2] = static_cast<std::int32_t>(std::lround(-fix.vel_up_mps * 1e3));
  p.pdop_e2 = 120;
  std::array<std::uint8_t, ublox::kNavPvtLength> payload{};
  ublox::encode_nav_pvt(p, payload);
  std::uint8_t msg[ublox::kNavPvtLength + 8];
  const std::size_t len = ublox::ubx_encode(ublox::kClassNav, ublox::kIdNavPvt, payload, msg);
  return ::write(pty, msg, len) == static_cast<ssize_t>(len);
}

std::uint64_t send_revolution(Ugv& u, const Pose3& sp, TimeNs now, TimeNs lidar_period, bool labels_oracle, const World& w,
                              std::vector<std::uint8_t>& pkt) {
  ouster::LidarFrame& f = u.frame;
  f.clear();
  f.frame_id = u.frame_id++;
  const TimeNs col_dt = lidar_period / f.width;
  for (int c = 0; c < f.width; ++c) {
    f.column_timestamp_ns[static_cast<std::size_t>(c)] = static_cast<std::uint64_t>(now + c * col_dt);
    f.column_valid[static_cast<std::size_t>(c)] = 1;
  }
  f.columns_received = f.width;
  const double cy = std::cos(sp.yaw), sy = std::sin(sp.yaw);
  for (const LidarPoint& q : u.scan) {
    if (q.ring >= f.height || q.col >= f.width) continue;
    const std::size_t k = f.index(q.ring, q.col);
    f.range_mm[k] = static_cast<std::uint32_t>(std::lround(q.range * 1000.0f));
    // An Ouster measures reflectivity, not class: the surface's albedo (the true class only with --oracle labels).
    f.reflectivity[k] = labels_oracle ? q.cls : albedo_reflectivity(w, sp.x + cy * static_cast<double>(q.x) - sy * static_cast<double>(q.y),
                                                                     sp.y + sy * static_cast<double>(q.x) + cy * static_cast<double>(q.y));
    f.signal[k] = 200;
  }
  std::uint64_t sent = 0;
  const int cpp = u.fmt->columns_per_packet();
  for (int c0 = 0; c0 < f.width; c0 += cpp) {
    const std::size_t len = ouster::encode_lidar_packet(*u.fmt, f, c0, pkt);
    if (len > 0 && ::sendto(u.udp, pkt.data(), len, 0, reinterpret_cast<const sockaddr*>(&u.lidar_to), sizeof u.lidar_to) == static_cast<ssize_t>(len))
      ++sent;
  }
  return sent;
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
  ::close(run.pty);
  if (run.pty_slave >= 0) ::close(run.pty_slave);
  for (auto& u : run.ugvs) {
    ::close(u->udp);
    run.res.can_frames_in += u->odrive->commands_received();
  }
}

}  // namespace ag::sim::hil
