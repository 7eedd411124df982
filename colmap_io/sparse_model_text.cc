// COLMAP's text sparse model: cameras.txt, images.txt, points3D.txt, with the
// header comments COLMAP 3.8 writes (Reconstruction::Write*Text) and doubles
// printed with 17 significant digits (max_digits10), so text round trips are
// exact. Readers report the file and the 1-based line number of any problem.

#include <charconv>
#include <fstream>
#include <limits>
#include <locale>
#include <string>
#include <string_view>
#include <system_error>
#include <vector>

#include "colmap_io/atomic_file.h"
#include "colmap_io/camera_models.h"
#include "colmap_io/error.h"
#include "colmap_io/sparse_model_checks.h"
#include "colmap_io/sparse_model_io.h"

namespace dispmvs::colmap_io {
namespace {

bool IsSpace(char c) {
  return c == ' ' || c == '\t' || c == '\r' || c == '\n' || c == '\v' || c == '\f';
}

std::vector<std::string_view> SplitFields(std::string_view line) {
  std::vector<std::string_view> fields;
  size_t i = 0;
  while (i < line.size()) {
    while (i < line.size() && IsSpace(line[i])) ++i;
    const size_t start = i;
    while (i < line.size() && !IsSpace(line[i])) ++i;
    if (i > start) fields.push_back(line.substr(start, i - start));
  }
  return fields;
}

// Reads a file line by line and numbers the lines for error messages.
class LineReader {
 public:
  LineReader(std::istream& in, std::string source_name)
      : in_(in), source_name_(std::move(source_name)) {}

  // Next line, comments and blank lines included; false at the end.
  bool NextRaw(std::string* line) {
    if (!std::getline(in_, *line)) return false;
    ++line_number_;
    return true;
  }

  // Next line that is neither blank nor a '#' comment.
  bool NextData(std::string* line) {
    while (NextRaw(line)) {
      const size_t first = line->find_first_not_of(" \t\r\v\f");
      if (first == std::string::npos || (*line)[first] == '#') continue;
      return true;
    }
    return false;
  }

  [[noreturn]] void Fail(const std::string& what) const {
    throw IoError(source_name_, "line " + std::to_string(line_number_) + ": " + what);
  }

  template <typename T>
  T ParseInt(std::string_view field, const char* what) const {
    T value{};
    const auto [end, ec] = std::from_chars(field.data(), field.data() + field.size(), value);
    if (ec != std::errc() || end != field.data() + field.size()) {
      Fail(std::string(what) + ": '" + std::string(field) + "' is not a valid " +
           (std::numeric_limits<T>::is_signed ? "integer" : "non-negative integer") + " in range");
    }
    return value;
  }

  double ParseDouble(std::string_view field, const char* what) const {
    double value = 0;
    const auto [end, ec] = std::from_chars(field.data(), field.data() + field.size(), value);
    if (ec != std::errc() || end != field.data() + field.size()) {
      Fail(std::string(what) + ": '" + std::string(field) + "' is not a number");
    }
    return value;
  }

 private:
  std::istream& in_;
  std::string source_name_;
  int64_t line_number_ = 0;
};

// C locale, so integers never get digit grouping whatever the global locale.
void PrepareTextStream(std::ostream& out) { out.imbue(std::locale::classic()); }

// A double printed as COLMAP prints it (an ostream with precision 17, i.e.
// printf's %.17g: max_digits10 significant digits, enough to read every
// double back bit for bit), via std::to_chars, which gives the same text
// several times faster than the stream does.
struct Exact {
  double value;
};

std::ostream& operator<<(std::ostream& out, Exact exact) {
  char buffer[64];
  const auto result =
      std::to_chars(buffer, buffer + sizeof(buffer), exact.value, std::chars_format::general,
                    std::numeric_limits<double>::max_digits10);
  return out.write(buffer, result.ptr - buffer);
}

// COLMAP 3.8 splits image lines at spaces and reads the name as one field.
void CheckNameWritable(const Image& image, const std::string& target_name) {
  if (image.name.empty()) {
    throw IoError(target_name, "image " + std::to_string(image.image_id) + " has an empty name");
  }
  for (const char c : image.name) {
    if (IsSpace(c)) {
      throw IoError(target_name, "image " + std::to_string(image.image_id) + " name '" +
                                     image.name +
                                     "' contains whitespace, which COLMAP's text format cannot "
                                     "hold; write the binary format instead");
    }
  }
}

}  // namespace

// ---------------------------------------------------------------------------
// Readers

void ReadCamerasText(std::istream& in, const std::string& source_name, SparseModel* model) {
  LineReader reader(in, source_name);
  model->cameras.clear();
  std::string line;
  while (reader.NextData(&line)) {
    // CAMERA_ID MODEL WIDTH HEIGHT PARAMS[]
    const std::vector<std::string_view> fields = SplitFields(line);
    if (fields.size() < 4) {
      reader.Fail("expected CAMERA_ID MODEL WIDTH HEIGHT PARAMS[], found " +
                  std::to_string(fields.size()) + " fields");
    }
    Camera camera;
    camera.camera_id = reader.ParseInt<uint32_t>(fields[0], "CAMERA_ID");
    const CameraModelInfo* info = FindCameraModelByName(std::string(fields[1]));
    if (info == nullptr) reader.Fail("unknown camera model '" + std::string(fields[1]) + "'");
    camera.model_id = info->id;
    camera.width = reader.ParseInt<uint64_t>(fields[2], "WIDTH");
    camera.height = reader.ParseInt<uint64_t>(fields[3], "HEIGHT");
    for (size_t i = 4; i < fields.size(); ++i) {
      camera.params.push_back(reader.ParseDouble(fields[i], "camera parameter"));
    }
    if (const std::string problem = internal::CheckCamera(camera); !problem.empty()) {
      reader.Fail("camera " + std::to_string(camera.camera_id) + ": " + problem);
    }
    const camera_t id = camera.camera_id;
    if (!model->cameras.emplace(id, std::move(camera)).second) {
      reader.Fail("duplicate camera id " + std::to_string(id));
    }
  }
}

void ReadImagesText(std::istream& in, const std::string& source_name, SparseModel* model) {
  LineReader reader(in, source_name);
  model->images.clear();
  model->image_file_order.clear();
  std::string line;
  while (reader.NextData(&line)) {
    // Line 1: IMAGE_ID QW QX QY QZ TX TY TZ CAMERA_ID NAME
    const std::vector<std::string_view> fields = SplitFields(line);
    if (fields.size() != 10) {
      reader.Fail("expected IMAGE_ID QW QX QY QZ TX TY TZ CAMERA_ID NAME (10 fields), found " +
                  std::to_string(fields.size()) + " fields" +
                  (fields.size() > 10 ? " (image names cannot contain spaces)" : ""));
    }
    Image image;
    image.image_id = reader.ParseInt<uint32_t>(fields[0], "IMAGE_ID");
    for (int k = 0; k < 4; ++k) image.qvec(k) = reader.ParseDouble(fields[1 + k], "quaternion");
    for (int k = 0; k < 3; ++k) image.tvec(k) = reader.ParseDouble(fields[5 + k], "translation");
    image.camera_id = reader.ParseInt<uint32_t>(fields[8], "CAMERA_ID");
    image.name = std::string(fields[9]);
    // Pose problems and duplicates are reported against this line, before
    // the POINTS2D line is read.
    if (const std::string problem = internal::CheckImage(image); !problem.empty()) {
      reader.Fail("image " + std::to_string(image.image_id) + ": " + problem);
    }
    if (model->images.count(image.image_id) != 0) {
      reader.Fail("duplicate image id " + std::to_string(image.image_id));
    }

    // Line 2: POINTS2D[] as (X, Y, POINT3D_ID); always present, possibly
    // empty, and never a comment (COLMAP reads it unconditionally).
    if (!reader.NextRaw(&line)) {
      reader.Fail("image " + std::to_string(image.image_id) +
                  ": missing the POINTS2D line that follows every image line");
    }
    const std::vector<std::string_view> point_fields = SplitFields(line);
    if (point_fields.size() % 3 != 0) {
      reader.Fail("image " + std::to_string(image.image_id) +
                  ": POINTS2D line must hold X Y POINT3D_ID triples, found " +
                  std::to_string(point_fields.size()) + " fields");
    }
    image.points2D.resize(point_fields.size() / 3);
    for (size_t p = 0; p < image.points2D.size(); ++p) {
      Point2D& point = image.points2D[p];
      point.xy.x() = reader.ParseDouble(point_fields[3 * p], "point2D X");
      point.xy.y() = reader.ParseDouble(point_fields[3 * p + 1], "point2D Y");
      const std::string_view id_field = point_fields[3 * p + 2];
      point.point3D_id =
          id_field == "-1" ? kInvalidPoint3DId : reader.ParseInt<uint64_t>(id_field, "POINT3D_ID");
    }
    if (const std::string problem = internal::CheckImage(image); !problem.empty()) {
      reader.Fail("image " + std::to_string(image.image_id) + ": " + problem);
    }
    const image_t id = image.image_id;
    model->images.emplace(id, std::move(image));
    model->image_file_order.push_back(id);
  }
}

void ReadPoints3DText(std::istream& in, const std::string& source_name, SparseModel* model) {
  LineReader reader(in, source_name);
  model->points3D.clear();
  std::string line;
  while (reader.NextData(&line)) {
    // POINT3D_ID X Y Z R G B ERROR TRACK[] as (IMAGE_ID, POINT2D_IDX)
    const std::vector<std::string_view> fields = SplitFields(line);
    if (fields.size() < 8 || (fields.size() - 8) % 2 != 0) {
      reader.Fail(
          "expected POINT3D_ID X Y Z R G B ERROR followed by IMAGE_ID POINT2D_IDX "
          "pairs, found " +
          std::to_string(fields.size()) + " fields");
    }
    Point3D point;
    point.point3D_id = reader.ParseInt<uint64_t>(fields[0], "POINT3D_ID");
    for (int k = 0; k < 3; ++k) point.xyz(k) = reader.ParseDouble(fields[1 + k], "position");
    for (int k = 0; k < 3; ++k) point.rgb[k] = reader.ParseInt<uint8_t>(fields[4 + k], "colour");
    point.error = reader.ParseDouble(fields[7], "ERROR");
    point.track.resize((fields.size() - 8) / 2);
    for (size_t e = 0; e < point.track.size(); ++e) {
      point.track[e].image_id = reader.ParseInt<uint32_t>(fields[8 + 2 * e], "track IMAGE_ID");
      point.track[e].point2D_idx =
          reader.ParseInt<uint32_t>(fields[9 + 2 * e], "track POINT2D_IDX");
    }
    if (const std::string problem = internal::CheckPoint3D(point); !problem.empty()) {
      reader.Fail("point3D " + std::to_string(point.point3D_id) + ": " + problem);
    }
    const point3D_t id = point.point3D_id;
    if (!model->points3D.emplace(id, std::move(point)).second) {
      reader.Fail("duplicate point3D id " + std::to_string(id));
    }
  }
}

SparseModel ReadSparseModelText(const std::filesystem::path& dir) {
  SparseModel model;
  const auto read = [&](const char* file_name, auto read_file) {
    const auto path = dir / file_name;
    std::ifstream in(path);
    if (!in) throw IoError(path.string(), "cannot open for reading");
    read_file(in, path.string(), &model);
  };
  read("cameras.txt", ReadCamerasText);
  read("images.txt", ReadImagesText);
  read("points3D.txt", ReadPoints3DText);
  ValidateSparseModel(model, dir.string());
  return model;
}

// ---------------------------------------------------------------------------
// Writers

void WriteCamerasText(const SparseModel& model, std::ostream& out, const std::string& target_name) {
  PrepareTextStream(out);
  out << "# Camera list with one line of data per camera:\n"
         "#   CAMERA_ID, MODEL, WIDTH, HEIGHT, PARAMS[]\n"
         "# Number of cameras: "
      << model.cameras.size() << "\n";
  for (const auto& [id, camera] : model.cameras) {
    const CameraModelInfo* info = FindCameraModelById(camera.model_id);
    if (info == nullptr || camera.params.size() != info->num_params) {
      throw IoError(target_name,
                    "camera " + std::to_string(id) + ": " + internal::CheckCamera(camera));
    }
    out << id << ' ' << info->name << ' ' << camera.width << ' ' << camera.height;
    for (const double param : camera.params) out << ' ' << Exact{param};
    out << '\n';
  }
}

void WriteImagesText(const SparseModel& model, std::ostream& out, const std::string& target_name) {
  PrepareTextStream(out);
  // Same statistic as COLMAP's header: observations (points2D with a 3-D
  // point) per image.
  uint64_t num_observations = 0;
  for (const auto& [id, image] : model.images) {
    for (const Point2D& point : image.points2D) num_observations += point.HasPoint3D() ? 1 : 0;
  }
  const double mean_observations =
      model.images.empty()
          ? 0.0
          : static_cast<double>(num_observations) / static_cast<double>(model.images.size());
  out << "# Image list with two lines of data per image:\n"
         "#   IMAGE_ID, QW, QX, QY, QZ, TX, TY, TZ, CAMERA_ID, NAME\n"
         "#   POINTS2D[] as (X, Y, POINT3D_ID)\n"
         "# Number of images: "
      << model.images.size() << ", mean observations per image: " << Exact{mean_observations}
      << "\n";
  for (const auto& [id, image] : model.images) {
    CheckNameWritable(image, target_name);
    out << id;
    for (int k = 0; k < 4; ++k) out << ' ' << Exact{image.qvec(k)};
    for (int k = 0; k < 3; ++k) out << ' ' << Exact{image.tvec(k)};
    out << ' ' << image.camera_id << ' ' << image.name << '\n';
    bool first = true;
    for (const Point2D& point : image.points2D) {
      if (!first) out << ' ';
      first = false;
      out << Exact{point.xy.x()} << ' ' << Exact{point.xy.y()} << ' ';
      if (point.HasPoint3D()) {
        out << point.point3D_id;
      } else {
        out << "-1";
      }
    }
    out << '\n';
  }
}

void WritePoints3DText(const SparseModel& model, std::ostream& out,
                       const std::string& /*target_name*/) {
  PrepareTextStream(out);
  uint64_t total_track_length = 0;
  for (const auto& [id, point] : model.points3D) total_track_length += point.track.size();
  const double mean_track_length =
      model.points3D.empty()
          ? 0.0
          : static_cast<double>(total_track_length) / static_cast<double>(model.points3D.size());
  out << "# 3D point list with one line of data per point:\n"
         "#   POINT3D_ID, X, Y, Z, R, G, B, ERROR, TRACK[] as (IMAGE_ID, POINT2D_IDX)\n"
         "# Number of points: "
      << model.points3D.size() << ", mean track length: " << Exact{mean_track_length} << "\n";
  for (const auto& [id, point] : model.points3D) {
    out << id;
    for (int k = 0; k < 3; ++k) out << ' ' << Exact{point.xyz(k)};
    for (const uint8_t channel : point.rgb) out << ' ' << static_cast<int>(channel);
    out << ' ' << Exact{point.error};
    for (const TrackElement& element : point.track) {
      out << ' ' << element.image_id << ' ' << element.point2D_idx;
    }
    out << '\n';
  }
}

void WriteSparseModelText(const SparseModel& model, const std::filesystem::path& dir) {
  ValidateSparseModel(model, dir.string());
  const auto cameras = dir / "cameras.txt";
  const auto images = dir / "images.txt";
  const auto points = dir / "points3D.txt";
  // Checked before any file is written, so a refusal leaves no partial model.
  for (const auto& [id, image] : model.images) CheckNameWritable(image, images.string());
  WriteFileAtomically(cameras,
                      [&](std::ostream& out) { WriteCamerasText(model, out, cameras.string()); });
  WriteFileAtomically(images,
                      [&](std::ostream& out) { WriteImagesText(model, out, images.string()); });
  WriteFileAtomically(points,
                      [&](std::ostream& out) { WritePoints3DText(model, out, points.string()); });
}

}  // namespace dispmvs::colmap_io
