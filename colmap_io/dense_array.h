#pragma once
// COLMAP's dense array files: the depth, normal and confidence maps under
// WORKSPACE/stereo/. The format (COLMAP's mvs::Mat<float>) is an ASCII header
// "WIDTH&HEIGHT&CHANNELS&" followed by WIDTH*HEIGHT*CHANNELS float32 values,
// little endian, channel-planar: value (row, col, c) sits at index
// c*WIDTH*HEIGHT + row*WIDTH + col. Depth maps have 1 channel (0 = no depth),
// normal maps 3.
//
// Note: COLMAP's consistency graphs share the header but not the payload
// (variable-length int32 lists), so they are not DenseArrays.

#include <cstddef>
#include <cstdint>
#include <filesystem>
#include <istream>
#include <optional>
#include <string>
#include <vector>

namespace dispmvs::colmap_io {

// Limits the reader enforces before trusting a header. They are far above any
// real map (a 65536 x 65536 depth map is 16 GiB) and only exist so that a
// corrupted header is reported as such.
constexpr uint64_t kMaxDenseArraySide = 65536;     // width and height
constexpr uint64_t kMaxDenseArrayChannels = 1024;

class DenseArray {
 public:
  DenseArray() = default;  // 0 x 0 x 0, holds nothing
  // Throws std::invalid_argument if a dimension is negative or above the
  // limits above.
  DenseArray(int width, int height, int channels, float fill_value = 0.0f);

  int width() const { return width_; }
  int height() const { return height_; }
  int channels() const { return channels_; }
  bool empty() const { return values_.empty(); }
  std::size_t size() const { return values_.size(); }

  // Bounds-checked access; throws std::out_of_range.
  float& at(int row, int col, int channel = 0);
  float at(int row, int col, int channel = 0) const;

  // Raw channel-planar storage (size() values), for loops that do their own
  // indexing and for handing maps to other libraries.
  float* data() { return values_.data(); }
  const float* data() const { return values_.data(); }
  const std::vector<float>& values() const { return values_; }

 private:
  std::size_t CheckedIndex(int row, int col, int channel) const;

  int width_ = 0;
  int height_ = 0;
  int channels_ = 0;
  std::vector<float> values_;
};

// Reads a dense array file. Throws IoError naming `path` when the file cannot
// be opened, the header is malformed, a dimension is zero or absurd, or the
// payload is not exactly WIDTH*HEIGHT*CHANNELS*4 bytes (truncated or trailing
// data). Nothing is allocated before the size has been checked against the
// bytes actually present.
DenseArray ReadDenseArray(const std::filesystem::path& path);

// nullopt when there is no regular file at `path` (a map that was not
// computed); otherwise ReadDenseArray(path), which throws for a file that
// cannot be read.
std::optional<DenseArray> ReadDenseArrayIfPresent(const std::filesystem::path& path);

// Same, from a seekable stream positioned at the header (the whole rest of the
// stream is the file). `source_name` is used in error messages.
DenseArray ReadDenseArray(std::istream& in, const std::string& source_name);

// Writes atomically (see atomic_file.h), creating parent directories. Throws
// IoError naming `path` on failure or if `array` is empty (COLMAP cannot read
// a zero-sized array back).
void WriteDenseArray(const DenseArray& array, const std::filesystem::path& path);

}  // namespace dispmvs::colmap_io
