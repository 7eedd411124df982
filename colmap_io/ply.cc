#include "colmap_io/ply.h"

#include <cstring>
#include <fstream>
#include <limits>
#include <sstream>

#include "colmap_io/atomic_file.h"
#include "colmap_io/error.h"

namespace dispmvs::colmap_io {
namespace {

// The property lines of the vertex element, in file order.
constexpr const char* kPropertyLines[] = {
    "property float x",  "property float y",     "property float z",
    "property float nx", "property float ny",    "property float nz",
    "property uchar red", "property uchar green", "property uchar blue",
};

// The longest header line we accept; a real one is < 40 characters, this only
// stops a binary file from being read as one huge line.
constexpr std::size_t kMaxHeaderLineLength = 1024;

// Floats are encoded byte by byte so that the file is little endian whatever
// the host's byte order.
void AppendFloat(float value, std::string* out) {
  uint32_t bits = 0;
  std::memcpy(&bits, &value, sizeof(bits));
  for (int shift = 0; shift < 32; shift += 8) out->push_back(static_cast<char>((bits >> shift) & 0xFFu));
}

float DecodeFloat(const unsigned char* bytes) {
  uint32_t bits = 0;
  for (int i = 3; i >= 0; --i) bits = (bits << 8) | bytes[i];
  float value = 0;
  std::memcpy(&value, &bits, sizeof(value));
  return value;
}

std::string ReadHeaderLine(std::istream& in, const std::string& source_name) {
  std::string line;
  char c = 0;
  while (in.get(c)) {
    if (c == '\n') {
      if (!line.empty() && line.back() == '\r') line.pop_back();
      return line;
    }
    line.push_back(c);
    if (line.size() > kMaxHeaderLineLength) throw IoError(source_name, "PLY header line too long");
  }
  throw IoError(source_name, "PLY header ends before end_header");
}

// Header lines other than comments.
std::string NextHeaderLine(std::istream& in, const std::string& source_name) {
  while (true) {
    std::string line = ReadHeaderLine(in, source_name);
    if (line.rfind("comment", 0) == 0 || line.rfind("obj_info", 0) == 0) continue;
    return line;
  }
}

uint64_t ParseVertexCount(const std::string& line, const std::string& source_name) {
  std::istringstream fields(line);
  std::string keyword, element, count_text, extra;
  fields >> keyword >> element >> count_text;
  if (keyword != "element" || element != "vertex" || (fields >> extra)) {
    throw IoError(source_name, "expected 'element vertex N', got '" + line + "'");
  }
  if (count_text.empty() || count_text.size() > 19 ||
      count_text.find_first_not_of("0123456789") != std::string::npos) {
    throw IoError(source_name, "bad vertex count in '" + line + "'");
  }
  return std::stoull(count_text);
}

}  // namespace

void WritePlyHeader(uint64_t count, std::ostream& out) {
  out << "ply\nformat binary_little_endian 1.0\nelement vertex " << count << "\n";
  for (const char* property : kPropertyLines) out << property << "\n";
  out << "end_header\n";
}

void AppendPlyRecord(const PlyPoint& point, std::string* record) {
  for (float v : point.xyz) AppendFloat(v, record);
  for (float v : point.normal) AppendFloat(v, record);
  for (uint8_t v : point.rgb) record->push_back(static_cast<char>(v));
}

void WritePlyPoints(const std::vector<PlyPoint>& points, const std::filesystem::path& path) {
  WriteFileAtomically(path, [&](std::ostream& out) {
    WritePlyHeader(points.size(), out);
    std::string record;
    record.reserve(kPlyPointRecordBytes);
    for (const PlyPoint& point : points) {
      record.clear();
      AppendPlyRecord(point, &record);
      out.write(record.data(), static_cast<std::streamsize>(record.size()));
    }
  });
}

std::vector<PlyPoint> ReadPlyPoints(std::istream& in, const std::string& source_name) {
  if (NextHeaderLine(in, source_name) != "ply") throw IoError(source_name, "not a PLY file");
  const std::string format = NextHeaderLine(in, source_name);
  if (format != "format binary_little_endian 1.0") {
    throw IoError(source_name, "unsupported PLY format '" + format + "' (need binary_little_endian 1.0)");
  }
  const uint64_t count = ParseVertexCount(NextHeaderLine(in, source_name), source_name);
  for (const char* expected : kPropertyLines) {
    const std::string line = NextHeaderLine(in, source_name);
    if (line != expected) {
      throw IoError(source_name, "expected '" + std::string(expected) + "', got '" + line + "'");
    }
  }
  const std::string end = NextHeaderLine(in, source_name);
  if (end != "end_header") {
    throw IoError(source_name, "expected 'end_header' (only x y z nx ny nz red green blue "
                               "vertices are supported), got '" + end + "'");
  }

  // Size check before allocating: the body must be exactly count records.
  const std::streampos body_start = in.tellg();
  in.seekg(0, std::ios::end);
  const std::streampos file_end = in.tellg();
  if (body_start < 0 || file_end < body_start) throw IoError(source_name, "cannot determine the PLY body size");
  in.seekg(body_start);
  const uint64_t body_bytes = static_cast<uint64_t>(file_end - body_start);
  if (count > body_bytes / kPlyPointRecordBytes || count * kPlyPointRecordBytes != body_bytes) {
    throw IoError(source_name, "PLY body has " + std::to_string(body_bytes) + " bytes, " +
                                   std::to_string(count) + " vertices need " +
                                   (count > body_bytes / kPlyPointRecordBytes
                                        ? std::string("more")
                                        : std::to_string(count * kPlyPointRecordBytes)));
  }

  std::vector<PlyPoint> points(static_cast<std::size_t>(count));
  unsigned char record[kPlyPointRecordBytes];
  for (PlyPoint& point : points) {
    if (!in.read(reinterpret_cast<char*>(record), sizeof(record))) {
      throw IoError(source_name, "PLY body truncated");
    }
    for (int i = 0; i < 3; ++i) point.xyz[i] = DecodeFloat(record + 4 * i);
    for (int i = 0; i < 3; ++i) point.normal[i] = DecodeFloat(record + 12 + 4 * i);
    for (int i = 0; i < 3; ++i) point.rgb[i] = record[24 + i];
  }
  return points;
}

std::vector<PlyPoint> ReadPlyPoints(const std::filesystem::path& path) {
  std::ifstream in(path, std::ios::binary);
  if (!in) throw IoError(path.string(), "cannot open for reading");
  return ReadPlyPoints(in, path.string());
}

}  // namespace dispmvs::colmap_io
