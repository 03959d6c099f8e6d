// airground-sim segment: one image through the C++ ErfNet engine (pipeline/segmentation), the logits
// saved as logits.npy (float32, classes x height x width) and the argmax as classes.png.
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <string>
#include <thread>
#include <vector>

#include "airground/messages/classes.hpp"
#include "airground/segmentation/erfnet.hpp"
#include "airground/sim/world_png.hpp"

namespace fs = std::filesystem;

namespace {

constexpr const char* kSegmentHelp =
    "airground-sim segment --weights FILE --image IMAGE.png --out DIR [--threads N] [--path auto|avx2|neon|portable]\n\n"
    "Runs ErfNet (our weights format, see docs/segmentation.md; tools/erfnet_export.py makes one from a PyTorch\n"
    "state_dict) on one RGB image, normalised by 1/255 (and the weights' mean/std) as the reference evaluation\n"
    "does. An image whose sides are not multiples of 8 is padded (edge pixels repeated) and the outputs cropped.\n"
    "Writes into DIR:\n"
    "  logits.npy          float32, classes x height x width\n"
    "  classes.png         8-bit argmax (index in logit order)\n"
    "  classes_colour.png  the argmax in config/classes.yaml's colours (logit i is the class the weights name\n"
    "                      i-th, or class id i when they name none)\n"
    "  --threads N   threads for the frame (default: all cores)\n"
    "  --path P      kernel path (default auto: the fastest this CPU has)\n";

[[noreturn]] void usage(const std::string& msg) {
  std::fprintf(stderr, "airground-sim segment: %s (see airground-sim segment --help)\n", msg.c_str());
  std::exit(2);
}

bool write_npy(const std::string& path, const float* data, int c, int h, int w) {
  std::string header = "{'descr': '<f4', 'fortran_order': False, 'shape': (" + std::to_string(c) + ", " + std::to_string(h) + ", " +
                       std::to_string(w) + "), }";
  const std::size_t total = 10 + header.size() + 1;
  header.append((64 - total % 64) % 64, ' ');
  header.push_back('\n');
  std::ofstream f(path, std::ios::binary);
  if (!f) return false;
  const auto len = static_cast<std::uint16_t>(header.size());
  f.write("\x93NUMPY\x01\x00", 8);
  f.write(reinterpret_cast<const char*>(&len), 2);
  f.write(header.data(), static_cast<std::streamsize>(header.size()));
  f.write(reinterpret_cast<const char*>(data), static_cast<std::streamsize>(sizeof(float) * static_cast<std::size_t>(c) * static_cast<std::size_t>(h) *
                                                                           static_cast<std::size_t>(w)));
  return static_cast<bool>(f);
}

}  // namespace

int segment_cmd(int argc, char** argv) {
  std::string weights, image, out, path_name = "auto";
  int threads = static_cast<int>(std::max(1U, std::thread::hardware_concurrency()));
  for (int i = 2; i < argc; ++i) {
    const std::string a = argv[i];
    if (a == "--help" || a == "-h") {
      std::fputs(kSegmentHelp, stdout);
      return 0;
    }
    if (i + 1 >= argc) usage(a + " needs a value");
    const std::string v = argv[++i];
    if (a == "--weights") weights = v;
    else if (a == "--image") image = v;
    else if (a == "--out") out = v;
    else if (a == "--path") path_name = v;
    else if (a == "--threads") {
      char* end = nullptr;
      const long t = std::strtol(v.c_str(), &end, 10);
      if (*end != '\0' || t < 1 || t > 64) usage("--threads must be 1..64, got '" + v + "'");
      threads = static_cast<int>(t);
    } else {
      usage("unknown option '" + a + "'");
    }
  }
  if (weights.empty() || image.empty() || out.empty()) usage("--weights, --image and --out are required");
  ag::seg::KernelPath path = ag::seg::KernelPath::kAuto;
  if (path_name == "avx2") path = ag::seg::KernelPath::kAvx2;
  else if (path_name == "neon") path = ag::seg::KernelPath::kNeon;
  else if (path_name == "portable") path = ag::seg::KernelPath::kPortable;
  else if (path_name != "auto") usage("--path must be auto, avx2, neon or portable");

  auto w = ag::seg::load_weights(weights);
  if (!w.ok()) {
    std::fprintf(stderr, "airground-sim segment: %s\n", w.error().message.c_str());
    return 1;
  }
  const cv::Mat bgr = cv::imread(image, cv::IMREAD_COLOR);
  if (bgr.empty()) {
    std::fprintf(stderr, "airground-sim segment: %s: cannot read the image (missing, or not an image format OpenCV knows)\n", image.c_str());
    return 1;
  }
  cv::Mat rgb;
  cv::cvtColor(bgr, rgb, cv::COLOR_BGR2RGB);
  const int W = rgb.cols, H = rgb.rows;
  const int PW = (W + 7) / 8 * 8, PH = (H + 7) / 8 * 8;
  if (PW != W || PH != H) cv::copyMakeBorder(rgb, rgb, 0, PH - H, 0, PW - W, cv::BORDER_REPLICATE);
  auto net = ag::seg::ErfNet::create(w.value(), ag::seg::ErfNetOptions{PW, PH, threads, path});
  if (!net.ok()) {
    std::fprintf(stderr, "airground-sim segment: %s\n", net.error().message.c_str());
    return 1;
  }
  ag::seg::ErfNet& e = *net.value();
  const std::string& h = w.value().header.class_names.empty() ? std::string() : w.value().header.class_names.front();
  std::printf("segment: %s (%d classes%s%s), image %dx%d%s, %s path, %d thread(s)\n", weights.c_str(), e.num_classes(), h.empty() ? "" : ", first ",
              h.c_str(), W, H, (PW != W || PH != H) ? (" padded to " + std::to_string(PW) + "x" + std::to_string(PH)).c_str() : "",
              std::string(ag::seg::kernel_path_name(e.path())).c_str(), e.threads());
  const auto t0 = std::chrono::steady_clock::now();
  e.run_rgb8(rgb.ptr<std::uint8_t>(), rgb.step[0]);
  const double ms = std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();

  fs::create_directories(out);
  // Crop the planes and the class map back to the image.
  std::vector<float> logits(static_cast<std::size_t>(e.num_classes()) * static_cast<std::size_t>(W) * static_cast<std::size_t>(H));
  cv::Mat cls(H, W, CV_8U);
  for (int c = 0; c < e.num_classes(); ++c)
    for (int y = 0; y < H; ++y)
      std::memcpy(&logits[(static_cast<std::size_t>(c) * static_cast<std::size_t>(H) + static_cast<std::size_t>(y)) * static_cast<std::size_t>(W)],
                  e.logits() + (static_cast<std::size_t>(c) * static_cast<std::size_t>(PH) + static_cast<std::size_t>(y)) * static_cast<std::size_t>(PW),
                  sizeof(float) * static_cast<std::size_t>(W));
  for (int y = 0; y < H; ++y) std::memcpy(cls.ptr<std::uint8_t>(y), e.classes() + static_cast<std::size_t>(y) * static_cast<std::size_t>(PW), static_cast<std::size_t>(W));
  const std::string npy = (fs::path(out) / "logits.npy").string(), png = (fs::path(out) / "classes.png").string();
  if (!write_npy(npy, logits.data(), e.num_classes(), H, W) || !cv::imwrite(png, cls)) {
    std::fprintf(stderr, "airground-sim segment: cannot write into %s\n", out.c_str());
    return 1;
  }
  std::string colour;
  // Logit index -> class id: by the weights' names, else the table's ids in order.
  const auto& names = w.value().header.class_names;
  const ag::ClassTable& table = ag::ClassTable::builtin();
  std::vector<std::uint8_t> id_of(256, 255);
  bool mappable = true;
  for (int i = 0; i < e.num_classes(); ++i) {
    if (!names.empty()) {
      const auto id = table.by_name(names[static_cast<std::size_t>(i)]);
      if (id) id_of[static_cast<std::size_t>(i)] = ag::raw(*id);
      else mappable = false;
    } else if (table.valid_id(static_cast<std::uint8_t>(i)) && i != 255) {
      id_of[static_cast<std::size_t>(i)] = static_cast<std::uint8_t>(i);
    } else {
      mappable = false;
    }
  }
  if (mappable) {
    cv::Mat ids(H, W, CV_8U), c;
    for (int y = 0; y < H; ++y)
      for (int x = 0; x < W; ++x) ids.at<std::uint8_t>(y, x) = id_of[cls.at<std::uint8_t>(y, x)];
    cv::cvtColor(ag::sim::class_display_image(ids), c, cv::COLOR_RGB2BGR);
    colour = (fs::path(out) / "classes_colour.png").string();
    if (!cv::imwrite(colour, c)) colour.clear();
  }
  std::printf("segmented in %.1f ms (%.1f GFLOP/s): %s (%dx%dx%d float32), %s%s%s\n", ms, 2.0 * e.reference_macs() / (ms * 1e6), npy.c_str(),
              e.num_classes(), H, W, png.c_str(), colour.empty() ? "" : ", ", colour.c_str());
  return 0;
}
