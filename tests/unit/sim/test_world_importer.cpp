// Map importer: value rasters, anti-aliased and noisy colour rasters, palettes and transparency,
// elevation and colour images (resampled), synthesised heights, clear errors for bad inputs, and the
// mission targets derived from the map's parked cars or taken from a user's file.
#include <gtest/gtest.h>

#include <gdal_priv.h>

#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include <cmath>
#include <filesystem>
#include <fstream>
#include <limits>
#include <set>
#include <string>
#include <vector>

#include <unistd.h>

#include "airground/sim/generator.hpp"
#include "airground/sim/importer.hpp"
#include "airground/messages/geometry.hpp"
#include "airground/platform/rng.hpp"

namespace ag::sim {
namespace {

namespace fs = std::filesystem;

// Test files go under one directory per process (concurrent runs do not meet), removed at the end.
fs::path scratch_root() { return fs::path(::testing::TempDir()) / ("ag_world_import_" + std::to_string(::getpid())); }
class ScratchCleanup : public ::testing::Environment {
 public:
  void TearDown() override { fs::remove_all(scratch_root()); }
};
[[maybe_unused]] const ::testing::Environment* const kScratchCleanup = ::testing::AddGlobalTestEnvironment(new ScratchCleanup);

fs::path dir_for(const std::string& name) {
  const fs::path p = scratch_root() / name;
  fs::remove_all(p);
  fs::create_directories(p);
  return p;
}

std::string write_text(const fs::path& p, const std::string& text) {
  std::ofstream(p, std::ios::binary | std::ios::trunc) << text;
  return p.string();
}

std::string write_rgb_png(const fs::path& p, const cv::Mat& rgb) {
  cv::Mat bgr;
  cv::cvtColor(rgb, bgr, rgb.channels() == 4 ? cv::COLOR_RGBA2BGRA : cv::COLOR_RGB2BGR);
  EXPECT_TRUE(cv::imwrite(p.string(), bgr));
  return p.string();
}

// A float or integer raster as GeoTIFF, optionally with a geotransform and nodata value.
std::string write_tif(const fs::path& p, const cv::Mat& m, GDALDataType type, double pixel_m = 0, std::optional<double> nodata = std::nullopt) {
  GDALAllRegister();
  GDALDataset* ds = GetGDALDriverManager()->GetDriverByName("GTiff")->Create(p.string().c_str(), m.cols, m.rows, 1, type, nullptr);
  EXPECT_NE(ds, nullptr);
  if (pixel_m > 0) {
    double gt[6] = {600000.0, pixel_m, 0, 5200000.0, 0, -pixel_m};
    ds->SetGeoTransform(gt);
  }
  if (nodata) ds->GetRasterBand(1)->SetNoDataValue(*nodata);
  cv::Mat f64;
  m.convertTo(f64, CV_64F);
  EXPECT_EQ(ds->GetRasterBand(1)->RasterIO(GF_Write, 0, 0, m.cols, m.rows, f64.data, m.cols, m.rows, GDT_Float64, 0, 0, nullptr), CE_None);
  GDALClose(GDALDataset::ToHandle(ds));
  return p.string();
}

constexpr const char* kValueLegend = R"(# test legend
classes:
  - {value: 1, class: road}
  - {value: 2, class: grass}
  - {value: 3, class: building}
  - {value: 5, class: vehicle}
)";

// The display colours of config/classes.yaml, as a user's hand-painted map would use them.
const cv::Vec3b kRoad(128, 64, 128), kDirt(150, 120, 80), kGrass(110, 190, 60), kBuilding(90, 90, 100), kWater(40, 110, 210);

constexpr const char* kColourLegend = R"(classes:
  - {color: [128, 64, 128], class: road}
  - {color: [150, 120, 80], class: dirt}
  - {color: [110, 190, 60], class: grass}
  - {color: [90, 90, 100], class: building}
  - {color: [40, 110, 210], class: water}
)";

ClassId class_of_colour(const cv::Vec3b& c) {
  if (c == kRoad) return ClassId::kRoad;
  if (c == kDirt) return ClassId::kDirt;
  if (c == kGrass) return ClassId::kGrass;
  if (c == kBuilding) return ClassId::kBuilding;
  return ClassId::kWater;
}

cv::Mat value_raster() {
  cv::Mat v(40, 60, CV_8UC1, cv::Scalar(2));
  v(cv::Rect(10, 5, 20, 10)).setTo(3);
  v(cv::Rect(0, 20, 60, 6)).setTo(1);
  v(cv::Rect(40, 30, 4, 4)).setTo(5);
  v(cv::Rect(0, 35, 5, 5)).setTo(9);  // not in the legend
  return v;
}

ImportOptions value_options(const fs::path& d) {
  ImportOptions o;
  o.classes_path = (d / "classes.png").string();
  EXPECT_TRUE(cv::imwrite(o.classes_path, value_raster()));
  o.legend_path = write_text(d / "legend.yaml", kValueLegend);
  o.resolution_m_per_px = 0.5;
  o.name = "values";
  o.datum = Datum{47.0, 8.0, 400.0};
  return o;
}

void expect_error(const ImportOptions& o, const std::string& detail, std::optional<ErrorCode> code = std::nullopt) {
  const auto r = import_world(o);
  ASSERT_FALSE(r.ok()) << "should fail with: " << detail;
  EXPECT_NE(r.error().message.find(detail), std::string::npos) << r.error().message;
  if (code) {
    EXPECT_EQ(r.error().code, *code) << r.error().message;
  }
}

TEST(WorldImporter, ValueRaster) {
  const fs::path d = dir_for("values");
  const ImportOptions o = value_options(d);
  ImportReport rep;
  const auto r = import_world(o, &rep);
  ASSERT_TRUE(r.ok()) << r.error().message;
  const World& w = r.value();
  EXPECT_EQ(w.header.name, "values");
  EXPECT_EQ(w.header.source, "import");
  EXPECT_EQ(w.grid().width, 60);
  EXPECT_EQ(w.grid().height, 40);
  EXPECT_DOUBLE_EQ(w.grid().resolution, 0.5);
  EXPECT_DOUBLE_EQ(w.grid().origin_x, -15.0);
  EXPECT_DOUBLE_EQ(w.grid().origin_y, 10.0);
  EXPECT_DOUBLE_EQ(w.header.datum.height_m, 400.0);
  const cv::Mat v = value_raster();
  for (int row = 0; row < 40; ++row) {
    for (int c = 0; c < 60; ++c) {
      const int in = v.at<std::uint8_t>(row, c);
      const ClassId want = in == 1 ? ClassId::kRoad : in == 2 ? ClassId::kGrass : in == 3 ? ClassId::kBuilding : in == 5 ? ClassId::kVehicle : ClassId::kUnknown;
      ASSERT_EQ(w.class_at(c, row), want) << c << "," << row;
      const float h = w.height.at<float>(row, c);
      if (want == ClassId::kVehicle) {
        EXPECT_EQ(h, 1.5F);
      }
      if (want == ClassId::kBuilding) {
        EXPECT_GE(h, 8.0F);
        EXPECT_LE(h, 15.0F);
        EXPECT_EQ(h, w.height.at<float>(5, 10)) << "one height per building";
      }
      if (want == ClassId::kGrass || want == ClassId::kUnknown) {
        EXPECT_EQ(h, 0.0F);
      }
    }
  }
  EXPECT_EQ(w.height.at<float>(20, 30), 0.15F) << "curb where the road meets grass";
  EXPECT_EQ(w.height.at<float>(22, 30), 0.0F);
  EXPECT_EQ(cv::countNonZero(w.terrain), 0);
  EXPECT_EQ(rep.unknown_value_cells, 25);
  ASSERT_EQ(rep.unknown_values, std::vector<std::int64_t>{9});
  EXPECT_EQ(rep.class_cells[raw(ClassId::kBuilding)], 200);
  EXPECT_EQ(rep.class_cells[raw(ClassId::kRoad)], 360);
  EXPECT_NE(rep.summary().find("not in the legend (9)"), std::string::npos) << rep.summary();
  EXPECT_TRUE(rep.heights_synthesised);
  EXPECT_TRUE(rep.albedo_synthesised);
  EXPECT_EQ(w.class_at_xy(w.header.staging.x, w.header.staging.y), ClassId::kRoad);
  EXPECT_LT(w.header.staging.x, -10.0) << "the south-westerly open road";
  // Synthesised colour is textured.
  cv::Scalar mean, sd;
  cv::meanStdDev(w.albedo, mean, sd, w.class_id == raw(ClassId::kGrass));
  EXPECT_GT(sd[1], 2.0);
  // The result is a valid world that saves and loads.
  ASSERT_TRUE(save_world(w, (d / "world").string()).ok());
  const auto back = load_world((d / "world").string());
  ASSERT_TRUE(back.ok()) << back.error().message;
  EXPECT_EQ(cv::countNonZero(back->class_id != w.class_id), 0);
}

// The staging pad keeps 40 m inside the edges when the map has room there: the quadrotor's survey leaves a
// 20 m border out and the robots' guesses are up to 16 m off, so a pad nearer the edge has guesses off the map.
TEST(WorldImporter, StagingPadKeepsClearOfTheBorderTheSurveyLeavesOut) {
  const fs::path d = dir_for("staging");
  cv::Mat v(200, 200, CV_8UC1, cv::Scalar(2));  // 100 m x 100 m of grass at 0.5 m
  v(cv::Rect(0, 0, 8, 200)).setTo(1);           // a road along the west edge (0-4 m)
  v(cv::Rect(0, 116, 200, 16)).setTo(1);        // an 8 m road across, 34-42 m from the south edge
  v(cv::Rect(0, 84, 200, 16)).setTo(1);         // another, 50-58 m from the south edge
  ImportOptions o;
  o.classes_path = (d / "classes.png").string();
  ASSERT_TRUE(cv::imwrite(o.classes_path, v));
  o.legend_path = write_text(d / "legend.yaml", kValueLegend);
  o.resolution_m_per_px = 0.5;
  o.datum = Datum{47.0, 8.0, 400.0};
  const auto r = import_world(o);
  ASSERT_TRUE(r.ok()) << r.error().message;
  const World& w = r.value();
  const GridGeometry& g = w.grid();
  const double from_west = w.header.staging.x - g.origin_x, from_south = w.header.staging.y - (g.origin_y - g.size_y());
  EXPECT_EQ(w.class_at_xy(w.header.staging.x, w.header.staging.y), ClassId::kRoad);
  EXPECT_GE(from_west, 40.0) << "not on the west edge's road, inside the border";
  EXPECT_LE(from_west, 42.0) << "the most south-westerly cell that is clear of it";
  EXPECT_NEAR(from_south, 54.0, 2.5) << "on the second cross road: the first is within 40 m of the south edge";
}

TEST(WorldImporter, SixteenBitGeoTiffTakesItsResolutionFromTheGeotransform) {
  const fs::path d = dir_for("geotiff16");
  cv::Mat v(30, 50, CV_16UC1, cv::Scalar(200));
  v(cv::Rect(0, 0, 20, 30)).setTo(100);
  cv::circle(v, cv::Point(35, 15), 6, cv::Scalar(300), cv::FILLED);
  ImportOptions o;
  o.classes_path = write_tif(d / "classes.tif", v, GDT_UInt16, 2.0);
  o.legend_path = write_text(d / "legend.yaml", "classes:\n  - {value: 100, class: water}\n  - {value: 200, class: dirt}\n  - {value: 300, class: tree}\n");
  const auto r = import_world(o);
  ASSERT_TRUE(r.ok()) << r.error().message;
  EXPECT_DOUBLE_EQ(r->grid().resolution, 2.0);
  EXPECT_EQ(r->class_at(5, 5), ClassId::kWater);
  EXPECT_EQ(r->class_at(25, 5), ClassId::kDirt);
  EXPECT_EQ(r->class_at(35, 15), ClassId::kTree);
  const float crown_top = r->height.at<float>(15, 35);
  EXPECT_GT(crown_top, 4.0F);
  EXPECT_LE(crown_top, 13.0F);
  EXPECT_LT(r->height.at<float>(15, 29), crown_top) << "crowns are domed";
}

TEST(WorldImporter, AntiAliasedColourRasterMapsToTheNearestNeighbouringClass) {
  const fs::path d = dir_for("antialiased");
  cv::Mat img(160, 200, CV_8UC3, cv::Scalar(kGrass));
  // The reference: each shape's own anti-aliased coverage, a cell belonging to it when at least half covered.
  cv::Mat ref(160, 200, CV_8UC1, cv::Scalar(raw(ClassId::kGrass)));
  const auto draw = [&](auto&& shape, const cv::Vec3b& colour, ClassId cls) {
    shape(img, cv::Scalar(colour), cv::LINE_AA);
    cv::Mat coverage(img.size(), CV_8UC1, cv::Scalar(0));
    shape(coverage, cv::Scalar(255), cv::LINE_AA);
    ref.setTo(cv::Scalar(raw(cls)), coverage >= 128);
  };
  draw([](cv::Mat& m, cv::Scalar s, int lt) { cv::circle(m, cv::Point(60, 60), 35, s, cv::FILLED, lt); }, kRoad, ClassId::kRoad);
  draw(
      [](cv::Mat& m, cv::Scalar s, int lt) {
        cv::Point2f corners[4];
        cv::RotatedRect(cv::Point2f(140, 95), cv::Size2f(50, 30), 25).points(corners);
        std::vector<cv::Point> poly;
        for (const auto& c : corners) poly.emplace_back(cv::Point(static_cast<int>(std::lround(c.x * 16)), static_cast<int>(std::lround(c.y * 16))));
        cv::fillConvexPoly(m, poly, s, lt, 4);
      },
      kBuilding, ClassId::kBuilding);
  draw([](cv::Mat& m, cv::Scalar s, int lt) { cv::line(m, cv::Point(5, 150), cv::Point(195, 128), s, 7, lt); }, kWater, ClassId::kWater);

  ImportOptions o;
  o.classes_path = write_rgb_png(d / "classes.png", img);
  o.legend_path = write_text(d / "legend.yaml", kColourLegend);
  o.resolution_m_per_px = 0.25;
  ImportReport rep;
  const auto r = import_world(o, &rep);
  ASSERT_TRUE(r.ok()) << r.error().message;
  const std::vector<cv::Vec3b> legend{kRoad, kDirt, kGrass, kBuilding, kWater};
  const auto is_legend = [&](const cv::Vec3b& c) { return std::find(legend.begin(), legend.end(), c) != legend.end(); };
  const auto dist2 = [](const cv::Vec3b& a, const cv::Vec3b& b) {
    const cv::Vec3i diff = cv::Vec3i(a) - cv::Vec3i(b);
    return diff.dot(diff);
  };
  int edges = 0, blends = 0, third_class_traps = 0;
  for (int y = 0; y < img.rows; ++y) {
    for (int x = 0; x < img.cols; ++x) {
      const cv::Vec3b p = img.at<cv::Vec3b>(y, x);
      const ClassId got = r->class_at(x, y);
      if (is_legend(p)) {
        ASSERT_EQ(got, class_of_colour(p)) << "pure pixel " << x << "," << y;
        continue;
      }
      ++edges;
      int nearest_d2 = std::numeric_limits<int>::max();
      for (const cv::Vec3b& l : legend) nearest_d2 = std::min(nearest_d2, dist2(p, l));
      blends += nearest_d2 > 24 * 24 ? 1 : 0;  // the importer's own idea of "not a legend colour"
      // The colours present around the edge pixel, and the nearest of them (ties: the earlier legend entry).
      std::set<int> around;
      for (int dy = -2; dy <= 2; ++dy) {
        for (int dx = -2; dx <= 2; ++dx) {
          const int yy = std::clamp(y + dy, 0, img.rows - 1), xx = std::clamp(x + dx, 0, img.cols - 1);
          const cv::Vec3b q = img.at<cv::Vec3b>(yy, xx);
          for (std::size_t k = 0; k < legend.size(); ++k) {
            if (q == legend[k]) around.insert(static_cast<int>(k));
          }
        }
      }
      ASSERT_FALSE(around.empty());
      int best = *around.begin();
      for (const int k : around) {
        if (dist2(p, legend[static_cast<std::size_t>(k)]) < dist2(p, legend[static_cast<std::size_t>(best)])) best = k;
      }
      ASSERT_EQ(got, class_of_colour(legend[static_cast<std::size_t>(best)])) << "edge pixel " << x << "," << y;
      int global = 0;
      for (std::size_t k = 1; k < legend.size(); ++k) {
        if (dist2(p, legend[k]) < dist2(p, legend[static_cast<std::size_t>(global)])) global = static_cast<int>(k);
      }
      if (around.count(global) == 0) ++third_class_traps;
    }
  }
  EXPECT_GT(edges, 300);
  EXPECT_GT(third_class_traps, 10) << "the drawing has blends whose globally nearest colour is a third class";
  EXPECT_EQ(cv::countNonZero(r->class_id == raw(ClassId::kDirt)), 0) << "no dirt was drawn, so none may appear";
  EXPECT_EQ(rep.blended_cells, blends);
  EXPECT_GT(blends, 200);
  for (const ClassId c : {ClassId::kRoad, ClassId::kGrass, ClassId::kBuilding, ClassId::kWater}) {
    const double want = cv::countNonZero(ref == raw(c)), got = cv::countNonZero(r->class_id == raw(c));
    EXPECT_NEAR(got, want, 0.02 * want) << ClassTable::builtin().info(c).name;
  }
}

TEST(WorldImporter, NoisyColoursStillMatch) {
  const fs::path d = dir_for("noisy");
  cv::Mat img(60, 80, CV_8UC3, cv::Scalar(kGrass));
  img(cv::Rect(0, 0, 40, 30)).setTo(cv::Scalar(kRoad));
  img(cv::Rect(40, 30, 40, 30)).setTo(cv::Scalar(kWater));
  Rng rng(5);
  cv::Mat noisy = img.clone();
  for (int y = 0; y < img.rows; ++y) {
    for (int x = 0; x < img.cols; ++x) {
      for (int k = 0; k < 3; ++k) {
        noisy.at<cv::Vec3b>(y, x)[k] = cv::saturate_cast<std::uint8_t>(img.at<cv::Vec3b>(y, x)[k] + static_cast<int>(rng.below(17)) - 8);
      }
    }
  }
  ImportOptions o;
  o.classes_path = write_rgb_png(d / "classes.png", noisy);
  o.legend_path = write_text(d / "legend.yaml", kColourLegend);
  o.resolution_m_per_px = 1.0;
  const auto r = import_world(o);
  ASSERT_TRUE(r.ok()) << r.error().message;
  for (int y = 0; y < img.rows; ++y) {
    for (int x = 0; x < img.cols; ++x) ASSERT_EQ(r->class_at(x, y), class_of_colour(img.at<cv::Vec3b>(y, x))) << x << "," << y;
  }
}

TEST(WorldImporter, PaletteAndTransparency) {
  const fs::path d = dir_for("palette");
  GDALAllRegister();
  GDALDataset* mem = GetGDALDriverManager()->GetDriverByName("MEM")->Create("", 30, 20, 1, GDT_Byte, nullptr);
  ASSERT_NE(mem, nullptr);
  std::vector<std::uint8_t> idx(30 * 20, 1);
  for (int x = 0; x < 10; ++x) {
    for (int y = 0; y < 20; ++y) idx[static_cast<std::size_t>(y * 30 + x)] = 0;
  }
  for (int x = 25; x < 30; ++x) {
    for (int y = 0; y < 20; ++y) idx[static_cast<std::size_t>(y * 30 + x)] = 2;
  }
  ASSERT_EQ(mem->GetRasterBand(1)->RasterIO(GF_Write, 0, 0, 30, 20, idx.data(), 30, 20, GDT_Byte, 0, 0, nullptr), CE_None);
  GDALColorTable table;
  for (const auto& [i, c] : std::vector<std::pair<int, cv::Vec3b>>{{0, kRoad}, {1, kGrass}, {2, kWater}}) {
    const GDALColorEntry e{c[0], c[1], c[2], 255};
    table.SetColorEntry(i, &e);
  }
  mem->GetRasterBand(1)->SetColorTable(&table);
  const std::string path = (d / "palette.png").string();
  GDALDataset* png = GetGDALDriverManager()->GetDriverByName("PNG")->CreateCopy(path.c_str(), mem, FALSE, nullptr, nullptr, nullptr);
  ASSERT_NE(png, nullptr);
  GDALClose(GDALDataset::ToHandle(png));
  GDALClose(GDALDataset::ToHandle(mem));
  ImportOptions o;
  o.classes_path = path;
  o.legend_path = write_text(d / "legend.yaml", kColourLegend);
  o.resolution_m_per_px = 1.0;
  auto r = import_world(o);
  ASSERT_TRUE(r.ok()) << r.error().message;
  EXPECT_EQ(r->class_at(3, 3), ClassId::kRoad);
  EXPECT_EQ(r->class_at(15, 3), ClassId::kGrass);
  EXPECT_EQ(r->class_at(28, 3), ClassId::kWater);

  cv::Mat rgba(20, 30, CV_8UC4, cv::Scalar(kGrass[0], kGrass[1], kGrass[2], 255));
  rgba(cv::Rect(0, 0, 6, 20)).setTo(cv::Scalar(0, 0, 0, 0));
  o.classes_path = write_rgb_png(d / "rgba.png", rgba);
  ImportReport rep;
  r = import_world(o, &rep);
  ASSERT_TRUE(r.ok()) << r.error().message;
  EXPECT_EQ(r->class_at(2, 2), ClassId::kUnknown);
  EXPECT_EQ(r->class_at(20, 2), ClassId::kGrass);
  EXPECT_EQ(rep.transparent_cells, 120);
}

TEST(WorldImporter, ElevationAndColourImagesAreResampled) {
  const fs::path d = dir_for("elevation");
  ImportOptions o = value_options(d);
  cv::Mat elev(20, 30, CV_32FC1);
  for (int y = 0; y < 20; ++y) {
    for (int x = 0; x < 30; ++x) elev.at<float>(y, x) = 500.0F + static_cast<float>(x);
  }
  elev.at<float>(3, 3) = -9999.0F;
  elev.at<float>(4, 4) = -9999.0F;
  o.elevation_path = write_tif(d / "dem.tif", elev, GDT_Float32, 0, -9999.0);
  cv::Mat colour(80, 120, CV_8UC3, cv::Scalar(200, 30, 20));
  colour(cv::Rect(60, 0, 60, 80)).setTo(cv::Scalar(20, 40, 220));
  o.color_path = write_rgb_png(d / "ortho.png", colour);
  ImportReport rep;
  auto r = import_world(o, &rep);
  ASSERT_TRUE(r.ok()) << r.error().message;
  EXPECT_TRUE(rep.elevation_resampled);
  EXPECT_TRUE(rep.color_resampled);
  EXPECT_EQ(rep.elevation_filled_cells, 2);
  EXPECT_FALSE(rep.albedo_synthesised);
  // Terrain is elevation minus the datum height (400 m), resampled from 30 to 60 columns.
  EXPECT_NEAR(r->terrain.at<float>(30, 0), 100.0F, 0.6F);
  EXPECT_NEAR(r->terrain.at<float>(30, 59), 129.0F, 0.6F);
  EXPECT_GT(r->terrain.at<float>(30, 40), r->terrain.at<float>(30, 20));
  EXPECT_EQ(r->albedo.at<cv::Vec3b>(10, 5), cv::Vec3b(200, 30, 20)) << "RGB order";
  EXPECT_EQ(r->albedo.at<cv::Vec3b>(10, 55), cv::Vec3b(20, 40, 220));
  o.elevation_is_absolute = false;
  r = import_world(o);
  ASSERT_TRUE(r.ok());
  EXPECT_NEAR(r->terrain.at<float>(30, 0), 500.0F, 0.6F);
}

TEST(WorldImporter, Errors) {
  const fs::path d = dir_for("errors");
  const ImportOptions good = value_options(d);
  {
    ImportOptions o = good;
    o.classes_path = (d / "nope.png").string();
    expect_error(o, "nope.png: missing", ErrorCode::kIo);
  }
  {
    ImportOptions o = good;
    o.legend_path = (d / "nolegend.yaml").string();
    expect_error(o, "nolegend.yaml: missing", ErrorCode::kIo);
  }
  const auto with_legend = [&](const std::string& text) {
    ImportOptions o = good;
    o.legend_path = write_text(d / "bad_legend.yaml", text);
    return o;
  };
  expect_error(with_legend("classes: [ {value: 1, class: road\n"), "bad_legend.yaml", ErrorCode::kMalformed);
  expect_error(with_legend("classes:\n  - {value: 1, class: tarmac}\n"), "unknown class 'tarmac' (known: road, dirt, grass");
  expect_error(with_legend("classes:\n  - {value: 1, class: road}\n  - {color: [1, 2, 3], class: grass}\n"), "mixes value and color");
  expect_error(with_legend("classes:\n  - {class: road}\n"), "bad_legend.yaml:2: entry needs 'value: N'");
  expect_error(with_legend("classes:\n  - {value: 1, class: road}\n  - {value: 1, class: grass}\n"), "listed twice");
  expect_error(with_legend("classes: []\n"), "non-empty 'classes:' list");
  expect_error(with_legend("classes:\n  - {color: [1, 2, 300], class: road}\n"), "0..255");
  {
    ImportOptions o = good;  // value legend, colour raster
    o.classes_path = write_rgb_png(d / "rgb.png", cv::Mat(40, 60, CV_8UC3, cv::Scalar(kGrass)));
    expect_error(o, "3 bands but the legend lists values");
  }
  {
    ImportOptions o = good;
    o.elevation_path = write_tif(d / "thin_dem.tif", cv::Mat(10, 60, CV_32FC1, cv::Scalar(3)), GDT_Float32);
    expect_error(o, "mismatched sizes");
  }
  {
    ImportOptions o = good;
    o.elevation_path = write_tif(d / "void_dem.tif", cv::Mat(40, 60, CV_32FC1, cv::Scalar(-9999)), GDT_Float32, 0, -9999.0);
    expect_error(o, "no valid values");
  }
  {
    ImportOptions o = good;
    o.color_path = write_rgb_png(d / "square.png", cv::Mat(60, 60, CV_8UC3, cv::Scalar(1, 2, 3)));
    expect_error(o, "mismatched sizes");
  }
  {
    ImportOptions o = good;
    o.classes_path = write_tif(d / "fractional.tif", cv::Mat(40, 60, CV_32FC1, cv::Scalar(1.5)), GDT_Float32);
    expect_error(o, "not an integer");
  }
  {
    ImportOptions o = good;
    o.resolution_m_per_px = 0;
    expect_error(o, "no resolution given");
  }
  {
    ImportOptions o = good;
    const fs::path cut = d / "cut.png";
    fs::copy_file(good.classes_path, cut, fs::copy_options::overwrite_existing);
    fs::resize_file(cut, fs::file_size(cut) / 2);
    o.classes_path = cut.string();
    expect_error(o, "cut.png", ErrorCode::kMalformed);
  }
  {
    // A large colour area the legend does not list is a missing entry, not a blend.
    cv::Mat img(100, 100, CV_8UC3, cv::Scalar(kGrass));
    img(cv::Rect(10, 10, 40, 40)).setTo(cv::Scalar(255, 0, 255));
    ImportOptions o = good;
    o.classes_path = write_rgb_png(d / "magenta.png", img);
    o.legend_path = write_text(d / "colours.yaml", kColourLegend);
    expect_error(o, "colour [255, 0, 255] covers 1600 pixels and is not in the legend", ErrorCode::kInvalidArgument);
  }
}

// A generated world's class raster, imported as a user's map with part of it unknown (value 255, in no
// legend), gives back the generator's own target clusters: the same number, each centre within 0.5 m and
// the same cars, except those whose cars fell into the unknown part.
TEST(WorldTargets, AnImportedMapGivesBackTheGeneratorsCarClusters) {
  GeneratorOptions g;
  g.seed = 7;
  g.size_m = 200;
  g.targets = 6;
  std::vector<TargetCluster> truth;
  auto gen = generate_world(g, &truth);
  ASSERT_TRUE(gen.ok()) << gen.error().message;
  ASSERT_EQ(truth.size(), 6U);
  const fs::path d = dir_for("targets");
  cv::Mat raster = gen.value().class_id.clone();
  // Unknown over the north-east quarter's corner: what the user could not label.
  const cv::Rect hole(raster.cols * 3 / 4, 0, raster.cols / 4, raster.rows / 4);
  raster(hole).setTo(255);
  ImportOptions o;
  o.classes_path = (d / "classes.png").string();
  ASSERT_TRUE(cv::imwrite(o.classes_path, raster));
  o.legend_path = write_text(d / "legend.yaml", R"(classes:
  - {value: 0, class: road}
  - {value: 1, class: dirt}
  - {value: 2, class: grass}
  - {value: 3, class: tree}
  - {value: 4, class: building}
  - {value: 5, class: vehicle}
  - {value: 6, class: water}
)");
  o.resolution_m_per_px = g.resolution;
  ImportReport rep;
  auto w = import_world(o, &rep);
  ASSERT_TRUE(w.ok()) << w.error().message;
  EXPECT_EQ(rep.unknown_value_cells, static_cast<std::int64_t>(hole.area()));
  const GridGeometry& grid = w.value().grid();
  auto in_hole = [&](const Pose2& p) { return hole.contains(cv::Point(grid.col(p.x), grid.row(p.y))); };

  const DerivedTargets got = derive_targets(w.value());
  EXPECT_EQ(got.small_blobs, 0);
  std::size_t expected = 0;
  for (const TargetCluster& t : truth) {
    bool hidden = false;
    for (const Pose2& p : t.car_poses) hidden = hidden || in_hole(p);
    if (hidden) continue;  // (a cluster partly in the hole would come back smaller; none of seed 7's is)
    ++expected;
    const TargetCluster* best = nullptr;
    for (const TargetCluster& c : got.targets)
      if (best == nullptr || std::hypot(c.x - t.x, c.y - t.y) < std::hypot(best->x - t.x, best->y - t.y)) best = &c;
    ASSERT_NE(best, nullptr);
    EXPECT_LT(std::hypot(best->x - t.x, best->y - t.y), 0.5) << "target " << t.id;
    EXPECT_EQ(best->cars, t.cars) << "target " << t.id;
    for (const Pose2& car : t.car_poses) {  // every car found, its long axis along the car's
      double nearest = 1e9, axis = 0;
      for (const Pose2& c : best->car_poses)
        if (std::hypot(c.x - car.x, c.y - car.y) < nearest) {
          nearest = std::hypot(c.x - car.x, c.y - car.y);
          axis = std::fabs(std::sin(c.yaw - car.yaw));
        }
      EXPECT_LT(nearest, 0.3);
      EXPECT_LT(axis, 0.1) << "yaw along the car (either way)";
    }
  }
  EXPECT_GE(expected, 4U);
  EXPECT_EQ(got.targets.size(), expected);
  for (std::size_t i = 0; i < got.targets.size(); ++i) EXPECT_EQ(got.targets[i].id, static_cast<int>(i) + 1);

  // Linking wider than the clusters are apart merges them; a car's length apart splits every cluster.
  DeriveTargetsOptions wide;
  wide.link_m = 150;
  EXPECT_LT(derive_targets(w.value(), wide).targets.size(), expected);
  DeriveTargetsOptions tight;
  tight.link_m = 1.0;
  EXPECT_EQ(derive_targets(w.value(), tight).targets.size(), static_cast<std::size_t>(got.cars));
}

TEST(WorldTargets, AUsersTargetsFileIsCheckedAgainstTheWorld) {
  const fs::path d = dir_for("user_targets");
  auto w = import_world(value_options(d));
  ASSERT_TRUE(w.ok()) << w.error().message;
  // value_raster(): 60 x 40 px at 0.5 m (x -15..15, y -10..10), the road across rows 20-25 (y -3..0).
  TargetsFile f;
  f.staging = Pose2{-10.0, -1.5, 0.0};
  TargetCluster t;
  t.id = 3;
  t.x = 6.0;
  t.y = -5.0;
  t.cars = 1;
  t.car_poses = {Pose2{6.0, -5.0, 0.0}};
  f.targets = {t};
  EXPECT_TRUE(check_targets_in_world(f, w.value(), "mine.yaml").ok());
  ASSERT_TRUE(save_targets(f.targets, f.staging, d.string()).ok());
  auto back = load_targets_file((d / "targets.yaml").string());
  ASSERT_TRUE(back.ok()) << back.error().message;
  EXPECT_EQ(back.value().targets.size(), 1U);
  EXPECT_EQ(back.value().targets[0].id, 3);

  TargetsFile off = f;
  off.targets[0].x = 40.0;
  auto e = check_targets_in_world(off, w.value(), "mine.yaml");
  ASSERT_FALSE(e.ok());
  EXPECT_NE(e.error().message.find("mine.yaml"), std::string::npos) << e.error().message;
  EXPECT_NE(e.error().message.find("target 3"), std::string::npos) << e.error().message;
  TargetsFile roof = f;
  roof.staging = Pose2{-5.0, 7.0, 0.0};  // the building: rows 5-14, cols 10-29
  e = check_targets_in_world(roof, w.value(), "mine.yaml");
  ASSERT_FALSE(e.ok());
  EXPECT_NE(e.error().message.find("building"), std::string::npos) << e.error().message;
  EXPECT_FALSE(load_targets_file((d / "none.yaml").string()).ok());
}

}  // namespace
}  // namespace ag::sim
