// bench_segmentation: our ErfNet engine (AVX2+FMA path) against OpenCV's cv::dnn running the same network
// from an ONNX export of the same weights (tools/erfnet_onnx.py), at 512x384 and 640x400 with 1 and 2
// threads: milliseconds per frame (median), GFLOP/s (2 x the reference network's MACs per frame) and the
// percentage of this machine's AVX2 FMA peak, measured first in this process with the same thread count.
// OpenCV is held to AVX2 (OPENCV_CPU_DISABLE=AVX512F,AVX512-SKX, set by re-executing itself) so that both
// use the same ISA. The logits of both are compared once (max |difference|) to show it is the same net.
//   bench_segmentation [--weights FILE.agw] [--onnx-dir DIR] [--runs N]
// AG_BENCH_OUT=<file> appends the figures as one JSON line.
#include <immintrin.h>
#include <unistd.h>

#include <opencv2/core.hpp>
#include <opencv2/dnn.hpp>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <ctime>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <string>
#include <thread>
#include <vector>

#include "airground/segmentation/erfnet.hpp"
#include "bench_common.hpp"

namespace {

using Clock = std::chrono::steady_clock;

double ms_since(Clock::time_point t0) { return std::chrono::duration<double, std::milli>(Clock::now() - t0).count(); }

double thread_cpu_ms() {
  timespec ts{};
  clock_gettime(CLOCK_THREAD_CPUTIME_ID, &ts);
  return 1e3 * static_cast<double>(ts.tv_sec) + 1e-6 * static_cast<double>(ts.tv_nsec);
}

// Milliseconds of one call: the calling thread's CPU time when it does all the work (1 thread: robust to
// other processes taking the core), wall time otherwise.
template <typename F>
double time_ms(int threads, F&& f) {
  if (threads == 1) {
    const double t0 = thread_cpu_ms();
    f();
    return thread_cpu_ms() - t0;
  }
  const auto t0 = Clock::now();
  f();
  return ms_since(t0);
}

double median(std::vector<double> v) {
  std::sort(v.begin(), v.end());
  return v[v.size() / 2];
}

// 12 independent 8-wide FMA chains (enough to hide the FMA latency on two ports): FLOPs per second of one
// thread spinning on nothing else.
__attribute__((target("avx2,fma"), noinline)) double fma_flops(std::int64_t iters, float seed, bool cpu_time) {
  __m256 a[12];
  for (int k = 0; k < 12; ++k) a[k] = _mm256_set1_ps(seed + static_cast<float>(k));
  const __m256 m = _mm256_set1_ps(0.999999F), c = _mm256_set1_ps(1e-7F);
  const auto t0 = Clock::now();
  const double c0 = thread_cpu_ms();
  for (std::int64_t i = 0; i < iters; ++i) {
#pragma GCC unroll 12
    for (int k = 0; k < 12; ++k) a[k] = _mm256_fmadd_ps(a[k], m, c);
  }
  const double s = (cpu_time ? thread_cpu_ms() - c0 : ms_since(t0)) / 1e3;
  __m256 sum = a[0];
  for (int k = 1; k < 12; ++k) sum = _mm256_add_ps(sum, a[k]);
  float out[8];
  _mm256_storeu_ps(out, sum);
  if (out[0] == 12345.0F) std::printf(" ");  // keep the chains alive
  return static_cast<double>(iters) * 12 * 8 * 2 / s;
}

// Peak GFLOP/s of `threads` threads spinning on FMAs at the same time (best of a few tries); one thread in
// its CPU time, several in wall time, as the rows they are compared with.
double fma_peak_gflops(int threads) {
  constexpr std::int64_t kIters = 40'000'000;
  double best = 0;
  for (int rep = 0; rep < 3; ++rep) {
    std::vector<double> per(static_cast<std::size_t>(threads));
    std::vector<std::thread> ts;
    for (int t = 0; t < threads; ++t) ts.emplace_back([&, t] { per[static_cast<std::size_t>(t)] = fma_flops(kIters, 1.0F + static_cast<float>(t), threads == 1); });
    for (auto& t : ts) t.join();
    double total = 0;
    for (double f : per) total += f;
    best = std::max(best, total / 1e9);
  }
  return best;
}

std::vector<std::uint8_t> test_image(int w, int h) {
  std::vector<std::uint8_t> img(static_cast<std::size_t>(w) * static_cast<std::size_t>(h) * 3);
  std::uint32_t s = 12345;
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x)
      for (int c = 0; c < 3; ++c) {
        s = s * 1664525U + 1013904223U;
        const double v = 128 + 80 * std::sin(0.05 * x + 0.9 * c) * std::cos(0.07 * y) + static_cast<double>(s >> 27);
        img[(static_cast<std::size_t>(y) * static_cast<std::size_t>(w) + static_cast<std::size_t>(x)) * 3 + static_cast<std::size_t>(c)] =
            static_cast<std::uint8_t>(std::clamp(v, 0.0, 255.0));
      }
  return img;
}

struct Row {
  int w{0}, h{0}, threads{0};
  double ours_ms{0}, direct_ms{0}, cv_ms{0}, gflop{0}, peak{0}, max_diff{0};
};

}  // namespace

int main(int argc, char** argv) {
  if (std::getenv("OPENCV_CPU_DISABLE") == nullptr) {  // OpenCV reads it when it loads: re-execute with it set
    setenv("OPENCV_CPU_DISABLE", "AVX512F,AVX512-SKX", 1);
    execv("/proc/self/exe", argv);
    std::perror("re-exec with OPENCV_CPU_DISABLE");
  }
  std::string weights = AG_SEG_BENCH_WEIGHTS, onnx_dir = AG_SEG_BENCH_ONNX_DIR;
  int runs = 5;
  for (int i = 1; i < argc; ++i) {
    const std::string a = argv[i];
    if (a == "--help" || a == "-h") {
      std::printf("bench_segmentation [--weights FILE.agw] [--onnx-dir DIR] [--runs N]\n"
                  "ErfNet: our engine (AVX2) vs cv::dnn on the same weights at 512x384 and 640x400, 1 and 2 threads.\n");
      return 0;
    }
    if (i + 1 >= argc) {
      std::fprintf(stderr, "%s needs a value\n", a.c_str());
      return 2;
    }
    if (a == "--weights") weights = argv[++i];
    else if (a == "--onnx-dir") onnx_dir = argv[++i];
    else if (a == "--runs") runs = std::max(1, std::atoi(argv[++i]));
    else {
      std::fprintf(stderr, "unknown option %s\n", a.c_str());
      return 2;
    }
  }
  if (!ag::seg::kernel_path_available(ag::seg::KernelPath::kAvx2)) {
    std::printf("bench_segmentation: this CPU has no AVX2+FMA; nothing to compare\n");
    return 0;
  }
  auto w = ag::seg::load_weights(weights);
  if (!w.ok()) {
    std::fprintf(stderr, "bench_segmentation: %s\n", w.error().message.c_str());
    return 1;
  }
  std::printf("bench_segmentation: ErfNet %u classes (%s), OPENCV_CPU_DISABLE=%s, OpenCV %s, %d runs each (median)\n",
              w.value().header.num_classes, weights.c_str(), std::getenv("OPENCV_CPU_DISABLE"), CV_VERSION, runs);
  const double peak1 = fma_peak_gflops(1), peak2 = fma_peak_gflops(2);
  std::printf("measured AVX2 FMA peak: %.1f GFLOP/s on 1 thread, %.1f GFLOP/s on 2 threads\n", peak1, peak2);
  std::printf("1-thread rows: thread CPU time; 2-thread rows: wall time. GFLOP/s = 2 x the reference network's MACs / time\n"
              "(for Winograd, which multiplies less, an effective figure). 'direct' is our engine without Winograd.\n");
  std::printf("%-8s %3s | %9s %8s %7s | %9s %7s | %9s %8s %7s | %7s %s\n", "size", "thr", "ours ms", "GFLOP/s", "% peak", "direct ms",
              "% peak", "cv::dnn", "GFLOP/s", "% peak", "speedup", "max|diff|");
  std::vector<Row> rows;
  for (auto [W, H] : {std::pair{512, 384}, std::pair{640, 400}}) {
    const std::string onnx = onnx_dir + "/erfnet_" + std::to_string(W) + "x" + std::to_string(H) + ".onnx";
    cv::dnn::Net cvnet;
    try {
      cvnet = cv::dnn::readNetFromONNX(onnx);
    } catch (const cv::Exception& e) {
      std::fprintf(stderr, "bench_segmentation: cannot read %s (%s)\n", onnx.c_str(), e.what());
      return 1;
    }
    cvnet.setPreferableBackend(cv::dnn::DNN_BACKEND_OPENCV);
    cvnet.setPreferableTarget(cv::dnn::DNN_TARGET_CPU);
    const std::vector<std::uint8_t> img = test_image(W, H);
    const cv::Mat mat(H, W, CV_8UC3, const_cast<std::uint8_t*>(img.data()));
    for (int threads : {1, 2}) {
      auto net = ag::seg::ErfNet::create(w.value(), ag::seg::ErfNetOptions{W, H, threads, ag::seg::KernelPath::kAvx2, true});
      auto direct = ag::seg::ErfNet::create(w.value(), ag::seg::ErfNetOptions{W, H, threads, ag::seg::KernelPath::kAvx2, false});
      if (!direct.ok()) {
        std::fprintf(stderr, "bench_segmentation: %s\n", direct.error().message.c_str());
        return 1;
      }
      if (!net.ok()) {
        std::fprintf(stderr, "bench_segmentation: %s\n", net.error().message.c_str());
        return 1;
      }
      cv::setNumThreads(threads);
      Row r;
      r.w = W;
      r.h = H;
      r.threads = threads;
      r.gflop = 2.0 * net.value()->reference_macs() / 1e9;
      r.peak = threads == 1 ? peak1 : peak2;
      cv::Mat out;
      std::vector<double> ours, theirs, dir;
      for (int k = 0; k < runs + 1; ++k) {  // the first round warms all up and is not counted; they take turns
        const double a = time_ms(threads, [&] { net.value()->run_rgb8(img.data(), static_cast<std::size_t>(W) * 3); });
        const double b = time_ms(threads, [&] {
          cvnet.setInput(cv::dnn::blobFromImage(mat, 1.0 / 255.0));
          out = cvnet.forward();
        });
        const double c = time_ms(threads, [&] { direct.value()->run_rgb8(img.data(), static_cast<std::size_t>(W) * 3); });
        if (k == 0) continue;
        ours.push_back(a);
        theirs.push_back(b);
        dir.push_back(c);
      }
      r.direct_ms = median(dir);
      const float* cvl = out.ptr<float>();
      const std::size_t n = static_cast<std::size_t>(W) * static_cast<std::size_t>(H) * w.value().header.num_classes;
      for (std::size_t i = 0; i < n; ++i) r.max_diff = std::max(r.max_diff, static_cast<double>(std::fabs(cvl[i] - net.value()->logits()[i])));
      r.ours_ms = median(ours);
      r.cv_ms = median(theirs);
      const double go = r.gflop / (r.ours_ms / 1e3), gc = r.gflop / (r.cv_ms / 1e3);
      const double gd = r.gflop / (r.direct_ms / 1e3);
      std::printf("%4dx%-3d %3d | %9.1f %8.1f %6.1f%% | %9.1f %6.1f%% | %9.1f %8.1f %6.1f%% | %6.2fx %.1e\n", W, H, threads, r.ours_ms, go,
                  100 * go / r.peak, r.direct_ms, 100 * gd / r.peak, r.cv_ms, gc, 100 * gc / r.peak, r.cv_ms / r.ours_ms, r.max_diff);
      std::fflush(stdout);
      rows.push_back(r);
    }
  }
  std::string json = "{\"bench\":\"segmentation\",\"peak_gflops_1t\":" + std::to_string(peak1) + ",\"peak_gflops_2t\":" + std::to_string(peak2) +
                     ",\"rows\":[";
  for (std::size_t i = 0; i < rows.size(); ++i) {
    const Row& r = rows[i];
    char buf[256];
    std::snprintf(buf, sizeof buf, "%s{\"w\":%d,\"h\":%d,\"threads\":%d,\"ours_ms\":%.2f,\"direct_ms\":%.2f,\"cvdnn_ms\":%.2f,\"speedup\":%.3f,\"max_diff\":%.2e}",
                  i ? "," : "", r.w, r.h, r.threads, r.ours_ms, r.direct_ms, r.cv_ms, r.cv_ms / r.ours_ms, r.max_diff);
    json += buf;
  }
  json += "]}";
  ag::bench::append_result_line(json);
  return 0;
}
