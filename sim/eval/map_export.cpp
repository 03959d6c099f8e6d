// Ortho-map export: GeoTIFF in UTM (GDAL) and PNGs.
#include "airground/sim/map_export.hpp"

#include <GeographicLib/LocalCartesian.hpp>
#include <GeographicLib/UTMUPS.hpp>
#include <cpl_conv.h>
#include <gdal_priv.h>
#include <ogr_spatialref.h>

#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include <cmath>
#include <filesystem>
#include <limits>

#include "airground/messages/classes.hpp"
#include "airground/sim/world_png.hpp"

namespace ag::sim {

UtmFrame utm_frame(const Datum& datum) {
  UtmFrame f;
  const GeographicLib::LocalCartesian lc(datum.lat_deg, datum.lon_deg, datum.height_m);
  int zone = 0;
  bool north = true;
  auto to_utm = [&](double x, double y, double& e, double& n) {
    double lat = 0, lon = 0, h = 0;
    lc.Reverse(x, y, 0.0, lat, lon, h);
    int z = 0;
    bool nn = true;
    GeographicLib::UTMUPS::Forward(lat, lon, z, nn, e, n, zone == 0 ? GeographicLib::UTMUPS::STANDARD : zone);
    zone = z;
    north = nn;
  };
  constexpr double kStep = 500.0;  // [m] fit the affine over +-500 m
  double e0 = 0, n0 = 0, ex = 0, nx = 0, ey = 0, ny = 0, exm = 0, nxm = 0, eym = 0, nym = 0;
  to_utm(0, 0, e0, n0);
  to_utm(kStep, 0, ex, nx);
  to_utm(-kStep, 0, exm, nxm);
  to_utm(0, kStep, ey, ny);
  to_utm(0, -kStep, eym, nym);
  f.zone = zone;
  f.north = north;
  f.epsg = (north ? 32600 : 32700) + zone;
  f.e0 = e0;
  f.n0 = n0;
  f.a = (ex - exm) / (2 * kStep);
  f.c = (nx - nxm) / (2 * kStep);
  f.b = (ey - eym) / (2 * kStep);
  f.d = (ny - nym) / (2 * kStep);
  return f;
}

namespace {

struct DatasetCloser {
  void operator()(GDALDataset* d) const { GDALClose(d); }
};
using DatasetPtr = std::unique_ptr<GDALDataset, DatasetCloser>;

Status write_tif(const std::string& path, const GridGeometry& g, const UtmFrame& utm, GDALDataType type, int bands,
                 const void* data, double nodata, bool class_palette) {
  GDALAllRegister();
  CPLSetThreadLocalConfigOption("GDAL_PAM_ENABLED", "NO");
  GDALDriver* driver = GetGDALDriverManager()->GetDriverByName("GTiff");
  if (driver == nullptr) return Error::make(ErrorCode::kInternal, "GDAL has no GTiff driver");
  const char* options[] = {"TILED=YES", "COMPRESS=DEFLATE", bands == 3 ? "INTERLEAVE=PIXEL" : nullptr, nullptr};
  DatasetPtr ds(driver->Create(path.c_str(), g.width, g.height, bands, type, const_cast<char**>(options)));
  if (!ds) return Error::make(ErrorCode::kIo, path + ": GDAL cannot create it");
  // Pixel (col, row) corner -> map (x, y) = (origin_x + col res, origin_y - row res) -> UTM (affine).
  const double gt[6] = {utm.e0 + utm.a * g.origin_x + utm.b * g.origin_y, utm.a * g.resolution, -utm.b * g.resolution,
                        utm.n0 + utm.c * g.origin_x + utm.d * g.origin_y, utm.c * g.resolution, -utm.d * g.resolution};
  ds->SetGeoTransform(const_cast<double*>(gt));
  OGRSpatialReference srs;
  if (srs.importFromEPSG(utm.epsg) != OGRERR_NONE) return Error::make(ErrorCode::kInternal, "GDAL/PROJ does not know EPSG:" + std::to_string(utm.epsg));
  char* wkt = nullptr;
  srs.exportToWkt(&wkt);
  ds->SetProjection(wkt);
  CPLFree(wkt);
  ds->SetMetadataItem("AG_SOURCE", "airground aerial ortho-map (ASOOM)");
  const int size = GDALGetDataTypeSizeBytes(type);
  for (int b = 1; b <= bands; ++b) {
    GDALRasterBand* band = ds->GetRasterBand(b);
    if (bands == 1) band->SetNoDataValue(nodata);
    if (class_palette) {
      GDALColorTable table;
      const ClassTable& ct = ClassTable::builtin();
      for (int i = 0; i < 256; ++i) {
        GDALColorEntry e{0, 0, 0, 255};
        if (ct.valid_id(static_cast<std::uint8_t>(i))) {
          const Rgb c = ct.info(static_cast<ClassId>(i)).color;
          e.c1 = c.r;
          e.c2 = c.g;
          e.c3 = c.b;
        }
        table.SetColorEntry(i, &e);
      }
      band->SetColorTable(&table);
    }
    // Interleaved buffer: pixel spacing = bands * size, line spacing = width * bands * size.
    const auto* base = static_cast<const std::uint8_t*>(data) + static_cast<std::size_t>(b - 1) * static_cast<std::size_t>(size);
    if (band->RasterIO(GF_Write, 0, 0, g.width, g.height, const_cast<std::uint8_t*>(base), g.width, g.height, type,
                       static_cast<GSpacing>(bands * size), static_cast<GSpacing>(g.width) * bands * size, nullptr) != CE_None)
      return Error::make(ErrorCode::kIo, path + ": cannot write band " + std::to_string(b));
  }
  ds->FlushCache();
  CPLSetThreadLocalConfigOption("GDAL_PAM_ENABLED", nullptr);
  return ok_status();
}

}  // namespace

Status write_map_exports(const std::string& dir, const mapping::MapRaster& r, const Datum& datum) {
  std::error_code ec;
  std::filesystem::create_directories(dir, ec);
  if (ec) return Error::make(ErrorCode::kIo, "cannot create " + dir + ": " + ec.message());
  const GridGeometry& g = r.grid;
  if (g.width <= 0 || g.height <= 0) return Error::make(ErrorCode::kInvalidArgument, "the map is empty: nothing to export");
  const UtmFrame utm = utm_frame(datum);
  const std::string d = dir + "/";
  if (auto st = write_tif(d + "map_class.tif", g, utm, GDT_Byte, 1, r.cls.data(), 255, true); !st) return st;
  if (auto st = write_tif(d + "map_elevation.tif", g, utm, GDT_Float32, 1, r.elevation.data(), std::numeric_limits<double>::quiet_NaN(), false); !st) return st;
  if (auto st = write_tif(d + "map_rgb.tif", g, utm, GDT_Byte, 3, r.rgb.data(), 0, false); !st) return st;

  cv::Mat cls(g.height, g.width, CV_8UC1, const_cast<std::uint8_t*>(r.cls.data()));
  cv::Mat bgr;
  cv::cvtColor(class_display_image(cls), bgr, cv::COLOR_RGB2BGR);
  bool ok = cv::imwrite(d + "map_class.png", bgr);
  cv::Mat rgb(g.height, g.width, CV_8UC3, const_cast<std::uint8_t*>(r.rgb.data()));
  cv::cvtColor(rgb, bgr, cv::COLOR_RGB2BGR);
  ok = ok && cv::imwrite(d + "map_rgb.png", bgr);
  cv::Mat elev(g.height, g.width, CV_32FC1, const_cast<float*>(r.elevation.data()));
  double lo = std::numeric_limits<double>::max(), hi = -lo;
  for (const float e : r.elevation)
    if (std::isfinite(e)) {
      lo = std::min(lo, static_cast<double>(e));
      hi = std::max(hi, static_cast<double>(e));
    }
  cv::Mat grey(g.height, g.width, CV_8UC1, cv::Scalar(0));
  if (hi > lo)
    for (int y = 0; y < g.height; ++y)
      for (int x = 0; x < g.width; ++x) {
        const float e = elev.at<float>(y, x);
        if (std::isfinite(e)) grey.at<std::uint8_t>(y, x) = static_cast<std::uint8_t>(1 + 254.0 * (static_cast<double>(e) - lo) / (hi - lo));
      }
  cv::Mat colour;
  cv::applyColorMap(grey, colour, cv::COLORMAP_VIRIDIS);
  colour.setTo(cv::Scalar(0, 0, 0), grey == 0);
  ok = ok && cv::imwrite(d + "map_elevation.png", colour);
  if (!ok) return Error::make(ErrorCode::kIo, "cannot write the map PNGs in " + dir);
  return ok_status();
}

}  // namespace ag::sim
