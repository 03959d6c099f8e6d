// World format: validate(), save/load round trip, byte-reproducible saves, GeoTIFF georeferencing, and a
// clear error naming the file for every kind of broken world directory.
#include <gtest/gtest.h>

#include <cpl_conv.h>
#include <gdal_priv.h>

#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include <cmath>
#include <filesystem>
#include <fstream>
#include <limits>
#include <string>
#include <vector>

#include <unistd.h>

#include "airground/sim/world.hpp"
#include "airground/sim/world_raster.hpp"

namespace ag::sim {
namespace {

namespace fs = std::filesystem;

// Test files go under one directory per process (concurrent runs do not meet), removed at the end.
fs::path scratch_root() { return fs::path(::testing::TempDir()) / ("ag_world_format_" + std::to_string(::getpid())); }
class ScratchCleanup : public ::testing::Environment {
 public:
  void TearDown() override { fs::remove_all(scratch_root()); }
};
[[maybe_unused]] const ::testing::Environment* const kScratchCleanup = ::testing::AddGlobalTestEnvironment(new ScratchCleanup);

World small_world() {
  World w;
  w.header.name = "test \"small\" world";
  w.header.seed = 1234567890123ULL;
  w.header.source = "generator";
  w.header.grid = GridGeometry{0.5, 40, 30, -10.0, 7.5};
  w.header.datum = Datum{46.5, 7.25, 512.5};
  w.header.staging = Pose2{-8.25, -6.0, 0.5};
  w.class_id = cv::Mat(30, 40, CV_8UC1);
  w.height = cv::Mat(30, 40, CV_32FC1);
  w.terrain = cv::Mat(30, 40, CV_32FC1);
  w.albedo = cv::Mat(30, 40, CV_8UC3);
  for (int r = 0; r < 30; ++r) {
    for (int c = 0; c < 40; ++c) {
      w.class_id.at<std::uint8_t>(r, c) = static_cast<std::uint8_t>((r / 5 + c / 7) % 7);
      w.height.at<float>(r, c) = 0.1F * static_cast<float>((r * 7 + c) % 50);
      w.terrain.at<float>(r, c) = -2.0F + 0.013F * static_cast<float>(r * c);
      w.albedo.at<cv::Vec3b>(r, c) = cv::Vec3b(static_cast<std::uint8_t>(r * 8), static_cast<std::uint8_t>(c * 6), 77);
    }
  }
  w.class_id.at<std::uint8_t>(3, 4) = 255;  // unknown is a valid id
  return w;
}

std::string fresh_dir(const std::string& name) {
  const fs::path p = scratch_root() / name;
  fs::remove_all(p);
  return p.string();
}

std::string saved_world(const std::string& name) {
  const std::string dir = fresh_dir(name);
  const auto s = save_world(small_world(), dir);
  EXPECT_TRUE(s.ok()) << (s.ok() ? "" : s.error().message);
  return dir;
}

std::vector<char> file_bytes(const fs::path& p) {
  std::ifstream in(p, std::ios::binary);
  std::vector<char> bytes(fs::exists(p) ? fs::file_size(p) : 0);
  in.read(bytes.data(), static_cast<std::streamsize>(bytes.size()));
  return bytes;
}

void write_text(const fs::path& p, const std::string& text) {
  std::ofstream out(p, std::ios::binary | std::ios::trunc);
  out << text;
}

std::string read_text(const fs::path& p) {
  const auto b = file_bytes(p);
  return {b.begin(), b.end()};
}

// The load must fail with `code` and a message naming `file` and containing `detail`.
void expect_load_error(const std::string& dir, ErrorCode code, const std::string& file, const std::string& detail) {
  const auto r = load_world(dir);
  ASSERT_FALSE(r.ok()) << "loading " << dir << " should fail (" << file << ": " << detail << ")";
  EXPECT_EQ(r.error().code, code) << r.error().message;
  EXPECT_NE(r.error().message.find(file), std::string::npos) << r.error().message;
  EXPECT_NE(r.error().message.find(detail), std::string::npos) << r.error().message;
}

bool mats_equal(const cv::Mat& a, const cv::Mat& b) {
  return a.size() == b.size() && a.type() == b.type() && std::equal(a.datastart, a.dataend, b.datastart);
}

TEST(WorldValidate, AcceptsAConsistentWorld) {
  const auto s = small_world().validate();
  EXPECT_TRUE(s.ok()) << (s.ok() ? "" : s.error().message);
}

TEST(WorldValidate, RejectsWrongSizesTypesIdsAndHeights) {
  {
    World w = small_world();
    w.class_id = cv::Mat(29, 40, CV_8UC1, cv::Scalar(2));
    const auto s = w.validate();
    ASSERT_FALSE(s.ok());
    EXPECT_NE(s.error().message.find("class layer"), std::string::npos) << s.error().message;
    EXPECT_NE(s.error().message.find("40x29"), std::string::npos) << s.error().message;
  }
  {
    World w = small_world();
    w.height.convertTo(w.height, CV_64F);
    const auto s = w.validate();
    ASSERT_FALSE(s.ok());
    EXPECT_NE(s.error().message.find("height layer"), std::string::npos) << s.error().message;
  }
  {
    World w = small_world();
    w.class_id.at<std::uint8_t>(10, 11) = 77;
    const auto s = w.validate();
    ASSERT_FALSE(s.ok());
    EXPECT_NE(s.error().message.find("77"), std::string::npos) << s.error().message;
    EXPECT_NE(s.error().message.find("col 11, row 10"), std::string::npos) << s.error().message;
  }
  {
    World w = small_world();
    w.height.at<float>(5, 6) = std::numeric_limits<float>::quiet_NaN();
    const auto s = w.validate();
    ASSERT_FALSE(s.ok());
    EXPECT_NE(s.error().message.find("not finite"), std::string::npos) << s.error().message;
  }
  {
    World w = small_world();
    w.height.at<float>(5, 6) = -1.0F;
    EXPECT_FALSE(w.validate().ok());
  }
  {
    World w = small_world();
    w.terrain.at<float>(0, 0) = std::numeric_limits<float>::infinity();
    EXPECT_FALSE(w.validate().ok());
  }
  {
    World w = small_world();
    w.albedo = cv::Mat(30, 40, CV_8UC4, cv::Scalar::all(0));
    EXPECT_FALSE(w.validate().ok());
  }
  {
    World w = small_world();
    w.header.grid.resolution = 0;
    EXPECT_FALSE(w.validate().ok());
  }
  {
    World w = small_world();
    w.header.datum.lat_deg = 91;
    EXPECT_FALSE(w.validate().ok());
  }
}

TEST(WorldFormat, SaveRefusesAnInvalidWorld) {
  World w = small_world();
  w.class_id.at<std::uint8_t>(0, 0) = 77;
  const auto s = save_world(w, fresh_dir("refuse"));
  ASSERT_FALSE(s.ok());
  EXPECT_NE(s.error().message.find("77"), std::string::npos);
}

TEST(WorldFormat, RoundTripIsExact) {
  const World w = small_world();
  const std::string dir = saved_world("roundtrip");
  for (const char* f : {"world.yaml", "class.png", "albedo.png", "height.tif", "terrain.tif"}) {
    EXPECT_TRUE(fs::exists(fs::path(dir) / f)) << f;
  }
  const auto r = load_world(dir);
  ASSERT_TRUE(r.ok()) << r.error().message;
  const World& l = r.value();
  EXPECT_EQ(l.header.name, w.header.name);
  EXPECT_EQ(l.header.seed, w.header.seed);
  EXPECT_EQ(l.header.source, w.header.source);
  EXPECT_EQ(l.header.format_version, 1);
  EXPECT_EQ(l.header.grid.width, 40);
  EXPECT_EQ(l.header.grid.height, 30);
  EXPECT_DOUBLE_EQ(l.header.grid.resolution, 0.5);
  EXPECT_DOUBLE_EQ(l.header.grid.origin_x, -10.0);
  EXPECT_DOUBLE_EQ(l.header.grid.origin_y, 7.5);
  EXPECT_DOUBLE_EQ(l.header.datum.lat_deg, 46.5);
  EXPECT_DOUBLE_EQ(l.header.datum.lon_deg, 7.25);
  EXPECT_DOUBLE_EQ(l.header.datum.height_m, 512.5);
  EXPECT_DOUBLE_EQ(l.header.staging.x, -8.25);
  EXPECT_DOUBLE_EQ(l.header.staging.y, -6.0);
  EXPECT_DOUBLE_EQ(l.header.staging.yaw, 0.5);
  EXPECT_TRUE(mats_equal(l.class_id, w.class_id));
  EXPECT_TRUE(mats_equal(l.albedo, w.albedo)) << "albedo must come back in RGB order";
  EXPECT_TRUE(mats_equal(l.height, w.height));
  EXPECT_TRUE(mats_equal(l.terrain, w.terrain));
  // The PNG is BGR on disk, as every viewer expects: pixel (0, 0) has R = 0, G = 0, B = 77.
  const cv::Mat bgr = cv::imread((fs::path(dir) / "albedo.png").string(), cv::IMREAD_UNCHANGED);
  EXPECT_EQ(bgr.at<cv::Vec3b>(2, 1), cv::Vec3b(77, 6, 16));
}

TEST(WorldFormat, SavingTwiceGivesIdenticalBytes) {
  const std::string a = saved_world("bytes_a"), b = saved_world("bytes_b");
  for (const char* f : {"world.yaml", "class.png", "albedo.png", "height.tif", "terrain.tif"}) {
    EXPECT_EQ(file_bytes(fs::path(a) / f), file_bytes(fs::path(b) / f)) << f;
  }
  EXPECT_FALSE(fs::exists(fs::path(a) / "height.tif.aux.xml")) << "everything belongs inside the GeoTIFF";
}

TEST(WorldFormat, GeoTiffCarriesTheEnuGridAndDatum) {
  const std::string dir = saved_world("geotiff");
  GDALAllRegister();
  GDALDataset* ds = GDALDataset::FromHandle(GDALOpen((fs::path(dir) / "height.tif").string().c_str(), GA_ReadOnly));
  ASSERT_NE(ds, nullptr);
  double gt[6];
  ASSERT_EQ(ds->GetGeoTransform(gt), CE_None);
  EXPECT_DOUBLE_EQ(gt[0], -10.0);
  EXPECT_DOUBLE_EQ(gt[1], 0.5);
  EXPECT_DOUBLE_EQ(gt[3], 7.5);
  EXPECT_DOUBLE_EQ(gt[5], -0.5);
  EXPECT_EQ(ds->GetRasterBand(1)->GetRasterDataType(), GDT_Float32);
  const std::string wkt = ds->GetProjectionRef();
  EXPECT_NE(wkt.find("Orthographic"), std::string::npos) << wkt;
  EXPECT_NE(wkt.find("46.5"), std::string::npos) << wkt;
  EXPECT_STREQ(ds->GetMetadataItem("AG_DATUM_LAT_DEG"), "46.5");
  EXPECT_STREQ(ds->GetMetadataItem("AG_DATUM_LON_DEG"), "7.25");
  EXPECT_STREQ(ds->GetMetadataItem("AG_DATUM_HEIGHT_M"), "512.5");
  EXPECT_STREQ(ds->GetMetadataItem("AG_RESOLUTION_M"), "0.5");
  EXPECT_STREQ(ds->GetMetadataItem("AG_LAYER"), "height");
  GDALClose(GDALDataset::ToHandle(ds));
}

TEST(WorldFormat, MissingDirectoryAndFiles) {
  expect_load_error(fresh_dir("nowhere"), ErrorCode::kIo, "nowhere", "missing");
  for (const char* f : {"world.yaml", "class.png", "albedo.png", "height.tif", "terrain.tif"}) {
    const std::string dir = saved_world(std::string("missing_") + f);
    fs::remove(fs::path(dir) / f);
    expect_load_error(dir, ErrorCode::kIo, f, "missing");
  }
}

TEST(WorldFormat, TruncatedFiles) {
  for (const char* f : {"class.png", "albedo.png", "height.tif", "terrain.tif"}) {
    const std::string dir = saved_world(std::string("truncated_") + f);
    const fs::path p = fs::path(dir) / f;
    fs::resize_file(p, fs::file_size(p) * 2 / 3);
    expect_load_error(dir, ErrorCode::kMalformed, f, "");
  }
  const std::string dir = saved_world("empty_png");
  fs::resize_file(fs::path(dir) / "class.png", 0);
  expect_load_error(dir, ErrorCode::kMalformed, "class.png", "not a PNG");
}

TEST(WorldFormat, ClassIdNotInTheTable) {
  const std::string dir = saved_world("id77");
  cv::Mat ids = small_world().class_id.clone();
  ids.at<std::uint8_t>(7, 9) = 77;
  ASSERT_TRUE(cv::imwrite((fs::path(dir) / "class.png").string(), ids));
  expect_load_error(dir, ErrorCode::kMalformed, "class.png", "class id 77 at cell (col 9, row 7)");
}

TEST(WorldFormat, WrongLayerTypesAndSizes) {
  {
    const std::string dir = saved_world("class_rgb");
    cv::Mat rgb;
    cv::cvtColor(small_world().class_id, rgb, cv::COLOR_GRAY2BGR);
    ASSERT_TRUE(cv::imwrite((fs::path(dir) / "class.png").string(), rgb));
    expect_load_error(dir, ErrorCode::kMalformed, "class.png", "3-channel");
  }
  {
    const std::string dir = saved_world("class_small");
    ASSERT_TRUE(cv::imwrite((fs::path(dir) / "class.png").string(), cv::Mat(30, 39, CV_8UC1, cv::Scalar(2))));
    expect_load_error(dir, ErrorCode::kMalformed, "class.png", "39x30");
  }
  {
    const std::string dir = saved_world("albedo_grey");
    ASSERT_TRUE(cv::imwrite((fs::path(dir) / "albedo.png").string(), cv::Mat(30, 40, CV_8UC1, cv::Scalar(2))));
    expect_load_error(dir, ErrorCode::kMalformed, "albedo.png", "expected 8-bit RGB");
  }
  {
    const std::string dir = saved_world("height_size");
    const World w = small_world();
    GridGeometry g = w.header.grid;
    g.width = 20;
    ASSERT_TRUE(write_geotiff((fs::path(dir) / "height.tif").string(), cv::Mat(30, 20, CV_32FC1, cv::Scalar(1)), g, w.header.datum, "height", "").ok());
    expect_load_error(dir, ErrorCode::kMalformed, "height.tif", "is 20x30 cells, world.yaml says 40x30");
  }
  {
    const std::string dir = saved_world("height_shifted");
    const World w = small_world();
    GridGeometry g = w.header.grid;
    g.origin_x += 3.0;
    ASSERT_TRUE(write_geotiff((fs::path(dir) / "height.tif").string(), w.height, g, w.header.datum, "height", "").ok());
    expect_load_error(dir, ErrorCode::kMalformed, "height.tif", "geotransform");
  }
  {
    const std::string dir = saved_world("terrain_int16");
    GDALAllRegister();
    GDALDriver* drv = GetGDALDriverManager()->GetDriverByName("GTiff");
    GDALDataset* ds = drv->Create((fs::path(dir) / "terrain.tif").string().c_str(), 40, 30, 1, GDT_Int16, nullptr);
    ASSERT_NE(ds, nullptr);
    std::vector<std::int16_t> zeros(40 * 30, 0);
    ASSERT_EQ(ds->GetRasterBand(1)->RasterIO(GF_Write, 0, 0, 40, 30, zeros.data(), 40, 30, GDT_Int16, 0, 0, nullptr), CE_None);
    GDALClose(GDALDataset::ToHandle(ds));
    expect_load_error(dir, ErrorCode::kMalformed, "terrain.tif", "expected Float32");
  }
  {
    const std::string dir = saved_world("height_nan");
    World w = small_world();
    w.height.at<float>(12, 13) = std::numeric_limits<float>::quiet_NaN();
    ASSERT_TRUE(write_geotiff((fs::path(dir) / "height.tif").string(), w.height, w.header.grid, w.header.datum, "height", "").ok());
    expect_load_error(dir, ErrorCode::kMalformed, "height.tif", "not finite");
  }
  {
    const std::string dir = saved_world("height_is_png");
    fs::copy_file(fs::path(dir) / "class.png", fs::path(dir) / "height.tif", fs::copy_options::overwrite_existing);
    expect_load_error(dir, ErrorCode::kMalformed, "height.tif", "");
  }
  {
    const std::string dir = saved_world("garbage_tif");
    write_text(fs::path(dir) / "terrain.tif", "II*\0 this is not a tiff at all");
    expect_load_error(dir, ErrorCode::kMalformed, "terrain.tif", "");
  }
}

TEST(WorldFormat, BrokenHeaders) {
  const std::string good = read_text(fs::path(saved_world("header_probe")) / "world.yaml");
  struct Case {
    std::string name, text, detail;
  };
  const auto replace = [&](const std::string& from, const std::string& to) {
    std::string t = good;
    const auto at = t.find(from);
    EXPECT_NE(at, std::string::npos) << from;
    return at == std::string::npos ? t : t.replace(at, from.size(), to);
  };
  const std::vector<Case> cases{
      {"garbage", "name: [unclosed\n  : : :\n", "malformed YAML"},
      {"empty", "", "expected a map"},
      {"truncated", good.substr(0, good.size() / 3), "missing key"},
      {"no_resolution", replace("resolution: 0.5", "resolutio: 0.5"), "missing key 'resolution'"},
      {"text_resolution", replace("resolution: 0.5", "resolution: fine"), "'resolution'"},
      {"negative_resolution", replace("resolution: 0.5", "resolution: -0.5"), "resolution must be"},
      {"version", replace("format_version: 1", "format_version: 2"), "format_version 2"},
      {"width", replace("width: 40", "width: 0"), "width and height"},
      {"datum", replace("lat_deg: 46.5", "lat_deg: 123"), "lat_deg"},
      {"no_layers", good.substr(0, good.find("layers:")), "layers"},
      {"escape", replace("class: \"class.png\"", "class: \"../class.png\""), "must not leave"},
  };
  for (const Case& c : cases) {
    const std::string dir = saved_world("header_" + c.name);
    write_text(fs::path(dir) / "world.yaml", c.text);
    SCOPED_TRACE(c.name);
    expect_load_error(dir, ErrorCode::kMalformed, "world.yaml", c.detail);
  }
}

TEST(WorldFormat, WrongSizeInHeaderIsCaughtAtTheLayers) {
  const std::string dir = saved_world("header_size");
  std::string y = read_text(fs::path(dir) / "world.yaml");
  y.replace(y.find("height: 30"), 10, "height: 31");
  write_text(fs::path(dir) / "world.yaml", y);
  expect_load_error(dir, ErrorCode::kMalformed, "class.png", "world.yaml says 40x31");
}

}  // namespace
}  // namespace ag::sim
