// The pose graph's solves: the factors as Ceres cost functors, the window problem and its solution.
#include <ceres/ceres.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <ctime>
#include <vector>

#include "pose_graph_internal.hpp"

namespace ag::mapping {
namespace {

// [-] weak prior on an aligned segment's log-scale, centred on its current value: only keeps the solve
// well posed when the window holds no GPS; the GPS factors outweigh it by orders of magnitude.
constexpr double kScaleMemorySigma = 0.5;

double thread_cpu_ms() {
  timespec ts{};
  clock_gettime(CLOCK_THREAD_CPUTIME_ID, &ts);
  return static_cast<double>(ts.tv_sec) * 1e3 + static_cast<double>(ts.tv_nsec) * 1e-6;
}

// Relative odometry between consecutive frames i -> j: translation in i's body frame (odometry units)
// times the segment scale, and rotation; whitened by the between sigmas.
struct BetweenCost {
  Eigen::Vector3d t_ij;
  Eigen::Quaterniond q_ij;
  double inv_sigma_t;
  double inv_sigma_r;

  template <typename T>
  bool operator()(const T* pi, const T* qi, const T* pj, const T* qj, const T* log_scale, T* res) const {
    const Eigen::Map<const Eigen::Matrix<T, 3, 1>> p_i(pi), p_j(pj);
    const Eigen::Map<const Eigen::Quaternion<T>> q_i(qi), q_j(qj);
    const Eigen::Quaternion<T> qi_inv = q_i.conjugate();
    const Eigen::Matrix<T, 3, 1> dp = qi_inv * (p_j - p_i);
    const T s = ceres::exp(log_scale[0]);
    Eigen::Map<Eigen::Matrix<T, 3, 1>> rt(res);
    rt = (dp - s * t_ij.cast<T>()) * T(inv_sigma_t);
    Eigen::Quaternion<T> dq = q_ij.conjugate().cast<T>() * (qi_inv * q_j);
    const T sign = dq.w() < T(0) ? T(-1) : T(1);
    Eigen::Map<Eigen::Matrix<T, 3, 1>> rr(res + 3);
    rr = dq.vec() * (T(2) * sign * T(inv_sigma_r));
    return true;
  }
};

// Roll and pitch from the gravity-aligned odometry: the map's up axis seen from the body.
struct GravityCost {
  Eigen::Vector3d up_in_body;
  double inv_sigma;

  template <typename T>
  bool operator()(const T* q, T* res) const {
    const Eigen::Map<const Eigen::Quaternion<T>> q_i(q);
    const Eigen::Matrix<T, 3, 1> up = q_i.conjugate() * Eigen::Matrix<T, 3, 1>(T(0), T(0), T(1));
    Eigen::Map<Eigen::Matrix<T, 3, 1>> r(res);
    r = (up - up_in_body.cast<T>()) * T(inv_sigma);
    return true;
  }
};

// Position-only GPS factor (the fix interpolated to the frame time), per-axis whitening.
struct GpsCost {
  Eigen::Vector3d pos;
  Eigen::Vector3d inv_sigma;

  template <typename T>
  bool operator()(const T* p, T* res) const {
    for (int k = 0; k < 3; ++k) res[k] = (p[k] - T(pos[k])) * T(inv_sigma[k]);
    return true;
  }
};

// The scale information of the between-factors among constant nodes: sqrt(B) (exp(log_s) - A/B).
struct ScaleInfoCost {
  double mean;
  double sqrt_info;
  template <typename T>
  bool operator()(const T* log_scale, T* res) const {
    res[0] = (ceres::exp(log_scale[0]) - T(mean)) * T(sqrt_info);
    return true;
  }
};

// Random walk between consecutive log-scale knots.
struct RandomWalkCost {
  double inv_sigma;
  template <typename T>
  bool operator()(const T* a, const T* b, T* res) const {
    res[0] = (b[0] - a[0]) * T(inv_sigma);
    return true;
  }
};

struct ScalarPriorCost {
  double mean;
  double inv_sigma;
  template <typename T>
  bool operator()(const T* x, T* res) const {
    res[0] = (x[0] - T(mean)) * T(inv_sigma);
    return true;
  }
};

}  // namespace

bool PoseGraph::Impl::update(bool force) {
  bool pending = false;
  for (const Segment& s : segments) pending = pending || s.pending;
  // A young segment (its scale and yaw from a short baseline) is re-solved whenever it has grown by
  // a third, so that the predictions chained from it do not run away before the regular solve.
  int every = std::max(prm.solve_every_frames, 1);
  if (!segments.empty() && segments.back().aligned) {
    const auto age = static_cast<int>(std::min<std::size_t>(segments.back().last - segments.back().first + 1, 1U << 20));
    every = std::min(every, std::max(3, age / 4));
  }
  if (!force && !pending && frames_since_solve < every) return false;
  frames_since_solve = 0;
  if (nodes.empty()) return false;
  const double t0 = thread_cpu_ms();
  const bool ran = solve();
  if (!ran) return false;
  st.last_solve_ms = thread_cpu_ms() - t0;
  ++st.solves;
  return true;
}

// Folds the between-factors whose nodes are both older than w0 (held constant from now on) into their
// segment's scale information.
void PoseGraph::Impl::accumulate_scale_info(std::size_t w0) {
  const double inv_var = 1.0 / (std::max(prm.between_sigma_m, 1e-9) * std::max(prm.between_sigma_m, 1e-9));
  const double fade = std::exp(-1.0 / static_cast<double>(std::max(prm.window_frames, 1)));
  for (Segment& s : segments) {
    if (!s.aligned || s.pending) continue;
    std::size_t k = std::max(s.info_until, s.first + 1);
    const std::size_t end = std::min(w0, s.last + 1);  // pairs (k-1, k) with k < w0
    for (; k < end; ++k) {
      const Node& m = nodes[k - 1];
      const Node& n = nodes[k];
      const Eigen::Vector3d a = rot(m).conjugate() * (pos(n) - pos(m));
      const Eigen::Vector3d b = m.odo_q.conjugate() * (n.odo_p - m.odo_p);
      Knot& kn = s.knots[n.knot];
      kn.info_a = fade * kn.info_a + inv_var * a.dot(b);
      kn.info_b = fade * kn.info_b + inv_var * b.squaredNorm();
    }
    s.info_until = std::max(s.info_until, k);
  }
}

bool PoseGraph::Impl::solve() {
  const std::size_t n_nodes = nodes.size();
  std::size_t w0 = prm.window_frames > 0 && n_nodes > static_cast<std::size_t>(prm.window_frames)
                       ? n_nodes - static_cast<std::size_t>(prm.window_frames)
                       : 0;
  // A segment's first solve covers all of it (it was placed by the alignment only).
  for (const Segment& s : segments)
    if (s.pending && s.last >= w0) w0 = std::min(w0, s.first);
  accumulate_scale_info(w0);

  ceres::Problem::Options popts;
  popts.manifold_ownership = ceres::DO_NOT_TAKE_OWNERSHIP;
  popts.loss_function_ownership = ceres::DO_NOT_TAKE_OWNERSHIP;
  popts.enable_fast_removal = false;
  ceres::Problem problem(popts);

  const double inv_bt = 1.0 / std::max(prm.between_sigma_m, 1e-9);
  const double inv_br = 1.0 / std::max(prm.between_sigma_rad, 1e-9);
  const bool gravity = prm.gravity_sigma_rad > 0;
  const double inv_g = gravity ? 1.0 / prm.gravity_sigma_rad : 0.0;
  const double vf = prm.gps_vertical_factor > 0 ? prm.gps_vertical_factor : 1.0;

  std::vector<std::size_t> segs_in;
  std::size_t variable_nodes = 0;
  const auto add_node = [&](Node& n, bool constant) {
    problem.AddParameterBlock(n.p, 3);
    problem.AddParameterBlock(n.q, 4, &quat_manifold);
    if (constant) {
      problem.SetParameterBlockConstant(n.p);
      problem.SetParameterBlockConstant(n.q);
    }
  };
  for (std::size_t i = w0; i < n_nodes; ++i) {
    Node& n = nodes[i];
    Segment& s = segments[n.seg];
    if (!s.aligned) continue;
    add_node(n, false);
    ++variable_nodes;
    if (segs_in.empty() || segs_in.back() != n.seg) segs_in.push_back(n.seg);
    if (i > s.first) {
      Node& m = nodes[i - 1];
      if (i - 1 < w0) add_node(m, true);
      const Eigen::Quaterniond qinv = m.odo_q.conjugate();
      auto* c = new ceres::AutoDiffCostFunction<BetweenCost, 6, 3, 4, 3, 4, 1>(
          new BetweenCost{qinv * (n.odo_p - m.odo_p), (qinv * n.odo_q).normalized(), inv_bt, inv_br});
      problem.AddResidualBlock(c, nullptr, m.p, m.q, n.p, n.q, &s.knots[n.knot].log_scale);
    }
    if (gravity) {
      auto* c = new ceres::AutoDiffCostFunction<GravityCost, 3, 4>(
          new GravityCost{n.odo_q.conjugate() * Eigen::Vector3d::UnitZ(), inv_g});
      problem.AddResidualBlock(c, nullptr, n.q);
    }
    if (n.has_gps) {
      const double ih = 1.0 / n.gps_sigma_h;
      auto* c = new ceres::AutoDiffCostFunction<GpsCost, 3, 3>(new GpsCost{n.gps, Eigen::Vector3d(ih, ih, ih / vf)});
      problem.AddResidualBlock(c, gps_loss.get(), n.p);
    }
  }
  if (variable_nodes == 0) return false;
  // Free knots: from the knot of the segment's first step in the window to its newest; the knot before
  // them is held constant and pulls the first free one through the random-walk prior.
  std::vector<double*> free_knots;
  const double drift = std::max(prm.scale_drift_per_sqrt_s, 1e-9);
  for (const std::size_t si : segs_in) {
    Segment& s = segments[si];
    const std::size_t k0 = nodes[std::max(w0, s.first)].knot;
    for (std::size_t k = k0; k < s.knots.size(); ++k) {
      Knot& kn = s.knots[k];
      if (!problem.HasParameterBlock(&kn.log_scale)) problem.AddParameterBlock(&kn.log_scale, 1);
      free_knots.push_back(&kn.log_scale);
      if (kn.info_b > 1e-9) {
        auto* c = new ceres::AutoDiffCostFunction<ScaleInfoCost, 1, 1>(new ScaleInfoCost{kn.info_a / kn.info_b, std::sqrt(kn.info_b)});
        problem.AddResidualBlock(c, nullptr, &kn.log_scale);
      }
      auto* c = new ceres::AutoDiffCostFunction<ScalarPriorCost, 1, 1>(new ScalarPriorCost{kn.log_scale, 1.0 / kScaleMemorySigma});
      problem.AddResidualBlock(c, nullptr, &kn.log_scale);
      if (k == 0) continue;
      Knot& prev = s.knots[k - 1];
      if (k == k0) {
        problem.AddParameterBlock(&prev.log_scale, 1);
        problem.SetParameterBlockConstant(&prev.log_scale);
      }
      const double dt = std::max(to_seconds(kn.start - prev.start), 1e-3);
      auto* w = new ceres::AutoDiffCostFunction<RandomWalkCost, 1, 1, 1>(new RandomWalkCost{1.0 / (drift * std::sqrt(dt))});
      problem.AddResidualBlock(w, nullptr, &prev.log_scale, &kn.log_scale);
    }
  }

  // Backup, in case the solver fails.
  std::vector<std::array<double, 7>> backup;
  backup.reserve(n_nodes - w0);
  for (std::size_t i = w0; i < n_nodes; ++i) {
    const Node& n = nodes[i];
    backup.push_back({n.p[0], n.p[1], n.p[2], n.q[0], n.q[1], n.q[2], n.q[3]});
  }
  std::vector<double> scale_backup;
  scale_backup.reserve(free_knots.size());
  for (const double* k : free_knots) scale_backup.push_back(*k);

  ceres::Solver::Options o;
  o.minimizer_type = ceres::TRUST_REGION;
  o.trust_region_strategy_type = ceres::LEVENBERG_MARQUARDT;
  o.linear_solver_type = ceres::SPARSE_NORMAL_CHOLESKY;
  o.sparse_linear_algebra_library_type = ceres::EIGEN_SPARSE;
  o.num_threads = 1;
  o.max_num_iterations = std::max(prm.max_iterations, 1);
  o.logging_type = ceres::SILENT;
  o.minimizer_progress_to_stdout = false;
  ceres::Solver::Summary summary;
  ceres::Solve(o, &problem, &summary);

  bool ok = summary.termination_type != ceres::FAILURE && std::isfinite(summary.final_cost);
  for (const double* k : free_knots) ok = ok && std::isfinite(*k);
  if (!ok) {
    for (std::size_t i = w0; i < n_nodes; ++i) {
      Node& n = nodes[i];
      const auto& b = backup[i - w0];
      std::copy(b.begin(), b.begin() + 3, n.p);
      std::copy(b.begin() + 3, b.end(), n.q);
    }
    for (std::size_t k = 0; k < free_knots.size(); ++k) *free_knots[k] = scale_backup[k];
    return false;
  }
  for (std::size_t i = w0; i < n_nodes; ++i) {
    Node& n = nodes[i];
    if (segments[n.seg].aligned) set_state(n, pos(n), rot(n));
  }
  for (const std::size_t si : segs_in) {
    Segment& s = segments[si];
    s.pending = false;
    s.initialised = std::isfinite(s.knots.back().log_scale) && std::exp(s.knots.back().log_scale) > 0;
  }
  st.last_final_cost = summary.final_cost;
  st.last_free_nodes = variable_nodes;
  st.last_iterations = static_cast<std::uint64_t>(summary.iterations.size());
  st.last_free_knots = free_knots.size();
  return true;
}

}  // namespace ag::mapping
