// GDAL raster reading and ENU GeoTIFF writing, with GDAL's errors turned into ag::Error messages.
#include "airground/sim/world_raster.hpp"

#include <cpl_conv.h>
#include <cpl_error.h>
#include <gdal_priv.h>
#include <ogr_spatialref.h>

#include <algorithm>
#include <charconv>
#include <filesystem>
#include <memory>
#include <mutex>
#include <vector>

namespace ag::sim {

namespace {

void register_gdal_drivers() {
  static std::once_flag once;
  std::call_once(once, [] { GDALAllRegister(); });
}

// Collects GDAL's messages for this thread instead of letting them go to stderr, so a corrupt file
// becomes one clear error and tests stay quiet.
class GdalMessages {
 public:
  GdalMessages() {
    CPLPushErrorHandlerEx(&GdalMessages::on_message, this);
    CPLErrorReset();
  }
  ~GdalMessages() { CPLPopErrorHandler(); }
  GdalMessages(const GdalMessages&) = delete;
  GdalMessages& operator=(const GdalMessages&) = delete;

  [[nodiscard]] std::string failure() const { return failure_.empty() ? std::string("GDAL reported no detail") : failure_; }
  // GDAL's message without the file name, which the caller's message already starts with.
  [[nodiscard]] std::string failure_about(const std::string& path) const {
    std::string m = failure();
    for (auto at = m.find(path); at != std::string::npos; at = m.find(path)) {
      std::size_t end = at + path.size();
      while (end < m.size() && (m[end] == ':' || m[end] == ' ')) ++end;
      m.erase(at, end - at);
    }
    return m;
  }

 private:
  static void CPL_STDCALL on_message(CPLErr level, CPLErrorNum /*num*/, const char* msg) {
    auto* self = static_cast<GdalMessages*>(CPLGetErrorHandlerUserData());
    if (self != nullptr && level >= CE_Failure && self->failure_.empty() && msg != nullptr) self->failure_ = msg;
  }
  std::string failure_;
};

struct DatasetCloser {
  void operator()(GDALDataset* d) const noexcept { GDALClose(GDALDataset::ToHandle(d)); }
};
using DatasetPtr = std::unique_ptr<GDALDataset, DatasetCloser>;

std::string number(double v) {
  char buf[64];
  const auto res = std::to_chars(buf, buf + sizeof buf, v);
  return std::string(buf, res.ptr);
}

int cv_depth_of(GDALDataType t) {
  switch (t) {
    case GDT_Byte: return CV_8U;
    case GDT_UInt16: return CV_16U;
    case GDT_Int16: return CV_16S;
    case GDT_Int32: return CV_32S;
    case GDT_Float32: return CV_32F;
    case GDT_UInt32:  // does not fit int32: read as double
    case GDT_Float64: return CV_64F;
    default: return -1;
  }
}

GDALDataType gdal_type_of(int cv_depth) {
  switch (cv_depth) {
    case CV_8U: return GDT_Byte;
    case CV_16U: return GDT_UInt16;
    case CV_16S: return GDT_Int16;
    case CV_32S: return GDT_Int32;
    case CV_32F: return GDT_Float32;
    default: return GDT_Float64;
  }
}

// Opens a raster read-only; a missing file, a directory or an unreadable file is an error naming it.
Result<DatasetPtr> open_raster(const std::string& path) {
  register_gdal_drivers();
  std::error_code ec;
  if (!std::filesystem::exists(path, ec)) return Error::make(ErrorCode::kIo, path + ": missing (no such file)");
  if (std::filesystem::is_directory(path, ec)) return Error::make(ErrorCode::kIo, path + ": is a directory, not a raster");
  GdalMessages messages;
  DatasetPtr ds(GDALDataset::FromHandle(GDALOpen(path.c_str(), GA_ReadOnly)));
  if (!ds) return Error::make(ErrorCode::kMalformed, path + ": not a readable raster (" + messages.failure_about(path) + ")");
  return ds;
}

}  // namespace

Result<RasterShape> probe_raster(const std::string& path) {
  auto opened = open_raster(path);
  if (!opened) return opened.error();
  DatasetPtr ds = std::move(opened).value();
  RasterShape shape{ds->GetRasterXSize(), ds->GetRasterYSize(), ds->GetRasterCount(), ""};
  if (shape.bands > 0) shape.data_type = GDALGetDataTypeName(ds->GetRasterBand(1)->GetRasterDataType());
  return shape;
}

Result<Raster> read_raster(const std::string& path) {
  auto opened = open_raster(path);
  if (!opened) return opened.error();
  DatasetPtr ds = std::move(opened).value();
  GdalMessages messages;  // what GDAL says while the bands are read
  const int w = ds->GetRasterXSize(), h = ds->GetRasterYSize(), bands = ds->GetRasterCount();
  if (bands < 1 || bands > 4) {
    return Error::make(ErrorCode::kMalformed, path + ": has " + std::to_string(bands) + " bands, expected 1 to 4");
  }
  if (w <= 0 || h <= 0 || static_cast<double>(w) * h > 4.0e8) {
    return Error::make(ErrorCode::kMalformed, path + ": unsupported size " + std::to_string(w) + "x" + std::to_string(h));
  }
  GDALRasterBand* first = ds->GetRasterBand(1);
  const GDALDataType type = first->GetRasterDataType();
  const int depth = cv_depth_of(type);
  if (depth < 0) {
    return Error::make(ErrorCode::kMalformed, path + ": unsupported pixel type " + std::string(GDALGetDataTypeName(type)));
  }
  Raster out;
  out.data_type = GDALGetDataTypeName(type);
  std::vector<cv::Mat> planes;
  for (int b = 1; b <= bands; ++b) {
    GDALRasterBand* band = ds->GetRasterBand(b);
    if (band->GetRasterDataType() != type) return Error::make(ErrorCode::kMalformed, path + ": bands have different pixel types");
    cv::Mat plane(h, w, CV_MAKETYPE(depth, 1));
    const CPLErr err = band->RasterIO(GF_Read, 0, 0, w, h, plane.data, w, h, gdal_type_of(depth), 0, 0, nullptr);
    if (err != CE_None) {
      return Error::make(ErrorCode::kMalformed,
                         path + ": band " + std::to_string(b) + " cannot be read, truncated or corrupt? (" + messages.failure_about(path) + ")");
    }
    planes.push_back(std::move(plane));
  }
  if (planes.size() == 1) {
    out.pixels = std::move(planes.front());
  } else {
    cv::merge(planes, out.pixels);
  }
  std::array<double, 6> gt{};
  if (ds->GetGeoTransform(gt.data()) == CE_None) out.geotransform = gt;
  int has_nodata = 0;
  const double nodata = first->GetNoDataValue(&has_nodata);
  if (has_nodata != 0) out.nodata = nodata;
  if (const GDALColorTable* table = first->GetColorTable(); table != nullptr && bands == 1) {
    const int n = table->GetColorEntryCount();
    out.palette = cv::Mat(std::max(n, 1), 1, CV_8UC3, cv::Scalar::all(0));
    for (int i = 0; i < n; ++i) {
      const GDALColorEntry* e = table->GetColorEntry(i);
      out.palette.at<cv::Vec3b>(i) = cv::Vec3b(static_cast<std::uint8_t>(std::clamp<short>(e->c1, 0, 255)),
                                               static_cast<std::uint8_t>(std::clamp<short>(e->c2, 0, 255)),
                                               static_cast<std::uint8_t>(std::clamp<short>(e->c3, 0, 255)));
    }
  }
  if (const char* wkt = ds->GetProjectionRef(); wkt != nullptr) out.projection_wkt = wkt;
  return out;
}

std::string enu_proj_string(const Datum& datum) {
  return "+proj=ortho +lat_0=" + number(datum.lat_deg) + " +lon_0=" + number(datum.lon_deg) +
         " +x_0=0 +y_0=0 +datum=WGS84 +units=m +no_defs";
}

Status write_geotiff(const std::string& path, const cv::Mat& layer, const GridGeometry& grid, const Datum& datum,
                     std::string_view layer_name, std::string_view meaning) {
  register_gdal_drivers();
  if (layer.type() != CV_32FC1 || layer.cols != grid.width || layer.rows != grid.height) {
    return Error::make(ErrorCode::kInvalidArgument, path + ": layer must be CV_32FC1 of the grid size");
  }
  GdalMessages messages;
  // Without PAM, GDAL keeps everything in the .tif (no .aux.xml sidecar) and the bytes stay reproducible.
  CPLSetThreadLocalConfigOption("GDAL_PAM_ENABLED", "NO");
  GDALDriver* driver = GetGDALDriverManager()->GetDriverByName("GTiff");
  if (driver == nullptr) return Error::make(ErrorCode::kInternal, "GDAL has no GTiff driver");
  const char* options[] = {"TILED=YES", "COMPRESS=DEFLATE", "PREDICTOR=3", "ZLEVEL=3", nullptr};
  Status result = ok_status();
  {
    DatasetPtr ds(driver->Create(path.c_str(), grid.width, grid.height, 1, GDT_Float32, const_cast<char**>(options)));
    if (!ds) {
      result = Error::make(ErrorCode::kIo, path + ": cannot create (" + messages.failure() + ")");
    } else {
      double gt[6] = {grid.origin_x, grid.resolution, 0.0, grid.origin_y, 0.0, -grid.resolution};
      ds->SetGeoTransform(gt);
      OGRSpatialReference srs;
      if (srs.importFromProj4(enu_proj_string(datum).c_str()) == OGRERR_NONE) {
        char* wkt = nullptr;
        srs.exportToWkt(&wkt);
        ds->SetProjection(wkt);
        CPLFree(wkt);
      }
      ds->SetMetadataItem("AG_LAYER", std::string(layer_name).c_str());
      ds->SetMetadataItem("AG_MEANING", std::string(meaning).c_str());
      ds->SetMetadataItem("AG_UNIT", "m");
      ds->SetMetadataItem("AG_RESOLUTION_M", number(grid.resolution).c_str());
      ds->SetMetadataItem("AG_DATUM_LAT_DEG", number(datum.lat_deg).c_str());
      ds->SetMetadataItem("AG_DATUM_LON_DEG", number(datum.lon_deg).c_str());
      ds->SetMetadataItem("AG_DATUM_HEIGHT_M", number(datum.height_m).c_str());
      ds->SetMetadataItem("AG_FRAME", "local ENU map frame: x east, y north [m], origin at the datum");
      GDALRasterBand* band = ds->GetRasterBand(1);
      band->SetDescription(std::string(layer_name).c_str());
      band->SetUnitType("m");
      cv::Mat contiguous = layer.isContinuous() ? layer : layer.clone();
      if (band->RasterIO(GF_Write, 0, 0, grid.width, grid.height, contiguous.data, grid.width, grid.height, GDT_Float32, 0, 0,
                         nullptr) != CE_None) {
        result = Error::make(ErrorCode::kIo, path + ": cannot write (" + messages.failure() + ")");
      }
      ds->FlushCache();
      if (CPLGetLastErrorType() >= CE_Failure && result.ok()) {
        result = Error::make(ErrorCode::kIo, path + ": cannot flush (" + messages.failure() + ")");
      }
    }
  }
  CPLSetThreadLocalConfigOption("GDAL_PAM_ENABLED", nullptr);
  return result;
}

}  // namespace ag::sim
