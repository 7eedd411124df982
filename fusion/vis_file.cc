#include "fusion/vis_file.h"

#include <fstream>
#include <limits>

#include "colmap_io/atomic_file.h"
#include "colmap_io/error.h"
#include "colmap_io/ply.h"
#include "fusion/fused_cloud_writer.h"

namespace dispmvs::fusion {
namespace {

// Integers are encoded byte by byte so that the file is little endian whatever
// the host's byte order.
void AppendLittleEndian(uint64_t value, int num_bytes, std::string* out) {
  for (int i = 0; i < num_bytes; ++i) out->push_back(static_cast<char>((value >> (8 * i)) & 0xFFu));
}

uint64_t DecodeLittleEndian(const unsigned char* bytes, int num_bytes) {
  uint64_t value = 0;
  for (int i = num_bytes - 1; i >= 0; --i) value = (value << 8) | bytes[i];
  return value;
}

// Bounded reads: every read and count is checked against the bytes left in
// the stream, measured once up front.
class VisReader {
 public:
  VisReader(std::istream& in, const std::string& source_name)
      : in_(in), source_name_(source_name) {
    const std::streampos start = in_.tellg();
    in_.seekg(0, std::ios::end);
    const std::streampos end = in_.tellg();
    in_.seekg(start);
    if (start < 0 || end < start || !in_) {
      throw colmap_io::IoError(source_name_, "cannot determine the size of the .vis data");
    }
    remaining_ = static_cast<uint64_t>(end - start);
  }

  uint64_t remaining() const { return remaining_; }

  uint64_t ReadUint(int num_bytes, const std::string& field) {
    unsigned char bytes[8];
    ReadBytes(bytes, static_cast<uint64_t>(num_bytes), field);
    return DecodeLittleEndian(bytes, num_bytes);
  }

  void ReadBytes(unsigned char* out, uint64_t size, const std::string& field) {
    if (size > remaining_) {
      throw colmap_io::IoError(source_name_, "truncated .vis file: " + field + " needs " +
                                                 std::to_string(size) + " bytes, only " +
                                                 std::to_string(remaining_) + " left");
    }
    in_.read(reinterpret_cast<char*>(out), static_cast<std::streamsize>(size));
    if (!in_) throw colmap_io::IoError(source_name_, "read error in " + field);
    remaining_ -= size;
  }

 private:
  std::istream& in_;
  const std::string& source_name_;
  uint64_t remaining_ = 0;
};

}  // namespace

void AppendVisibilityHeader(uint64_t num_points, std::string* out) {
  AppendLittleEndian(num_points, 8, out);
}

void AppendVisibilityRecord(const std::vector<uint32_t>& images, std::string* out) {
  AppendLittleEndian(images.size(), 4, out);
  for (uint32_t image : images) AppendLittleEndian(image, 4, out);
}

void WriteVisibilityFile(const std::vector<FusedPoint>& points,
                         const std::filesystem::path& path) {
  colmap_io::WriteFileAtomically(path, [&](std::ostream& out) {
    std::string buffer;
    AppendVisibilityHeader(points.size(), &buffer);
    // Written in chunks to keep memory flat on large clouds.
    constexpr std::size_t kFlushBytes = 1 << 20;
    for (const FusedPoint& point : points) {
      if (point.visibility.size() > std::numeric_limits<uint32_t>::max()) {
        throw colmap_io::IoError(path.string(), "a point has too many visible images");
      }
      AppendVisibilityRecord(point.visibility, &buffer);
      if (buffer.size() >= kFlushBytes) {
        out.write(buffer.data(), static_cast<std::streamsize>(buffer.size()));
        buffer.clear();
      }
    }
    out.write(buffer.data(), static_cast<std::streamsize>(buffer.size()));
  });
}

std::vector<std::vector<uint32_t>> ReadVisibilityFile(std::istream& in,
                                                      const std::string& source_name) {
  VisReader reader(in, source_name);
  const uint64_t num_points = reader.ReadUint(8, "the number of points");
  // Each point takes at least its 4-byte count.
  if (num_points > reader.remaining() / 4) {
    throw colmap_io::IoError(source_name, "the header declares " + std::to_string(num_points) +
                                              " points but only " +
                                              std::to_string(reader.remaining()) +
                                              " bytes follow (4 or more per point): "
                                              "wrong count or truncated file");
  }
  std::vector<std::vector<uint32_t>> visibility(static_cast<std::size_t>(num_points));
  std::vector<unsigned char> bytes;
  for (uint64_t p = 0; p < num_points; ++p) {
    const std::string field = "point " + std::to_string(p);
    const uint64_t count = reader.ReadUint(4, field + " count");
    if (count > reader.remaining() / 4) {
      throw colmap_io::IoError(source_name, "truncated .vis file: " + field + " lists " +
                                                std::to_string(count) + " images, only " +
                                                std::to_string(reader.remaining()) +
                                                " bytes left");
    }
    bytes.resize(static_cast<std::size_t>(count) * 4);
    reader.ReadBytes(bytes.data(), bytes.size(), field + " image indices");
    std::vector<uint32_t>& images = visibility[static_cast<std::size_t>(p)];
    images.resize(static_cast<std::size_t>(count));
    for (std::size_t i = 0; i < images.size(); ++i) {
      images[i] = static_cast<uint32_t>(DecodeLittleEndian(bytes.data() + 4 * i, 4));
    }
  }
  if (reader.remaining() != 0) {
    throw colmap_io::IoError(source_name, std::to_string(reader.remaining()) +
                                              " unexpected bytes after the " +
                                              std::to_string(num_points) +
                                              " points the header declares (wrong count?)");
  }
  return visibility;
}

std::vector<std::vector<uint32_t>> ReadVisibilityFile(const std::filesystem::path& path) {
  std::ifstream in(path, std::ios::binary);
  if (!in) throw colmap_io::IoError(path.string(), "cannot open for reading");
  return ReadVisibilityFile(in, path.string());
}

void WriteFusedPointCloud(const std::vector<FusedPoint>& points,
                          const std::filesystem::path& ply_path) {
  FusedCloudWriter writer(ply_path);
  for (const FusedPoint& point : points) writer.Add(point);
  writer.Finish();
}

}  // namespace dispmvs::fusion
