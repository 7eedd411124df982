#include "colmap_io/dense_array.h"

#include <algorithm>
#include <cstring>
#include <fstream>
#include <stdexcept>
#include <system_error>

#include "colmap_io/atomic_file.h"
#include "colmap_io/error.h"

namespace dispmvs::colmap_io {
namespace {

// Digits per header field: 20 hold any uint64. Bounding the field keeps a file
// of garbage digits (e.g. endless leading zeros) from being scanned whole.
constexpr int kMaxHeaderDigits = 20;

// Reads one "DIGITS&" field of the header. Only plain decimal digits are
// accepted (no sign, no spaces): that is exactly what COLMAP writes, and it
// makes "-1&..." a clear error instead of a wrapped-around size_t.
uint64_t ReadHeaderField(std::istream& in, const char* field_name,
                         const std::string& source_name) {
  uint64_t value = 0;
  int num_digits = 0;
  while (true) {
    const int ch = in.get();
    if (ch == std::char_traits<char>::eof()) {
      throw IoError(source_name, std::string("malformed header: file ends inside the ") +
                                     field_name + " field (expected \"WIDTH&HEIGHT&CHANNELS&\")");
    }
    if (ch == '&') break;
    if (ch < '0' || ch > '9') {
      throw IoError(source_name, std::string("malformed header: unexpected character in the ") +
                                     field_name +
                                     " field (expected decimal digits followed by '&')");
    }
    if (++num_digits > kMaxHeaderDigits) {
      throw IoError(source_name,
                    std::string("malformed header: the ") + field_name + " field is too long");
    }
    const uint64_t digit = static_cast<uint64_t>(ch - '0');
    if (value > (UINT64_MAX - digit) / 10) {
      throw IoError(source_name, std::string("malformed header: the ") + field_name +
                                     " does not fit in 64 bits");
    }
    value = value * 10 + digit;
  }
  if (num_digits == 0) {
    throw IoError(source_name, std::string("malformed header: empty ") + field_name + " field");
  }
  return value;
}

void CheckDimension(uint64_t value, uint64_t limit, const char* field_name,
                    const std::string& source_name) {
  if (value == 0) {
    throw IoError(source_name, std::string("invalid header: ") + field_name + " is 0");
  }
  if (value > limit) {
    throw IoError(source_name, std::string("invalid header: ") + field_name + " " +
                                   std::to_string(value) + " exceeds the limit of " +
                                   std::to_string(limit));
  }
}

// a * b, or throws if that overflows. With the dimension limits above this
// cannot trigger; it stays so that raising a limit can never reintroduce an
// overflow.
uint64_t CheckedMultiply(uint64_t a, uint64_t b, const std::string& source_name) {
  if (a != 0 && b > UINT64_MAX / a) {
    throw IoError(source_name, "invalid header: WIDTH*HEIGHT*CHANNELS overflows");
  }
  return a * b;
}

uint32_t LoadLittleEndian32(const unsigned char* bytes) {
  return static_cast<uint32_t>(bytes[0]) | (static_cast<uint32_t>(bytes[1]) << 8) |
         (static_cast<uint32_t>(bytes[2]) << 16) | (static_cast<uint32_t>(bytes[3]) << 24);
}

void StoreLittleEndian32(uint32_t value, char* bytes) {
  bytes[0] = static_cast<char>(value & 0xff);
  bytes[1] = static_cast<char>((value >> 8) & 0xff);
  bytes[2] = static_cast<char>((value >> 16) & 0xff);
  bytes[3] = static_cast<char>((value >> 24) & 0xff);
}

// Number of bytes between the current read position and the end of `in`,
// leaving the position unchanged.
uint64_t RemainingBytes(std::istream& in, const std::string& source_name) {
  const std::istream::pos_type here = in.tellg();
  in.seekg(0, std::ios::end);
  const std::istream::pos_type end = in.tellg();
  in.seekg(here);
  if (here == std::istream::pos_type(-1) || end == std::istream::pos_type(-1) || !in) {
    throw IoError(source_name, "cannot determine the file size");
  }
  return static_cast<uint64_t>(end - here);
}

}  // namespace

DenseArray::DenseArray(int width, int height, int channels, float fill_value) {
  if (width < 0 || height < 0 || channels < 0 ||
      static_cast<uint64_t>(width) > kMaxDenseArraySide ||
      static_cast<uint64_t>(height) > kMaxDenseArraySide ||
      static_cast<uint64_t>(channels) > kMaxDenseArrayChannels) {
    throw std::invalid_argument("DenseArray: invalid size " + std::to_string(width) + " x " +
                                std::to_string(height) + " x " + std::to_string(channels));
  }
  width_ = width;
  height_ = height;
  channels_ = channels;
  values_.assign(static_cast<std::size_t>(width) * static_cast<std::size_t>(height) *
                     static_cast<std::size_t>(channels),
                 fill_value);
}

std::size_t DenseArray::CheckedIndex(int row, int col, int channel) const {
  if (row < 0 || row >= height_ || col < 0 || col >= width_ || channel < 0 ||
      channel >= channels_) {
    throw std::out_of_range("DenseArray::at(" + std::to_string(row) + ", " +
                            std::to_string(col) + ", " + std::to_string(channel) +
                            ") outside " + std::to_string(width_) + " x " +
                            std::to_string(height_) + " x " + std::to_string(channels_));
  }
  const std::size_t plane = static_cast<std::size_t>(width_) * static_cast<std::size_t>(height_);
  return static_cast<std::size_t>(channel) * plane +
         static_cast<std::size_t>(row) * static_cast<std::size_t>(width_) +
         static_cast<std::size_t>(col);
}

float& DenseArray::at(int row, int col, int channel) {
  return values_[CheckedIndex(row, col, channel)];
}

float DenseArray::at(int row, int col, int channel) const {
  return values_[CheckedIndex(row, col, channel)];
}

DenseArray ReadDenseArray(std::istream& in, const std::string& source_name) {
  const uint64_t width = ReadHeaderField(in, "width", source_name);
  const uint64_t height = ReadHeaderField(in, "height", source_name);
  const uint64_t channels = ReadHeaderField(in, "channels", source_name);
  CheckDimension(width, kMaxDenseArraySide, "width", source_name);
  CheckDimension(height, kMaxDenseArraySide, "height", source_name);
  CheckDimension(channels, kMaxDenseArrayChannels, "channels", source_name);

  const uint64_t num_values =
      CheckedMultiply(CheckedMultiply(width, height, source_name), channels, source_name);
  const uint64_t expected_bytes = CheckedMultiply(num_values, sizeof(float), source_name);
  const uint64_t actual_bytes = RemainingBytes(in, source_name);
  if (actual_bytes != expected_bytes) {
    throw IoError(source_name,
                  std::string(actual_bytes < expected_bytes ? "truncated" : "trailing data") +
                      ": header says " + std::to_string(width) + "x" + std::to_string(height) +
                      "x" + std::to_string(channels) + " (" + std::to_string(expected_bytes) +
                      " bytes of float32) but " + std::to_string(actual_bytes) +
                      " bytes follow the header");
  }

  // Only now, with the payload known to be present, is memory committed.
  DenseArray array(static_cast<int>(width), static_cast<int>(height), static_cast<int>(channels));
  float* out = array.data();
  // Read in blocks so the temporary byte buffer stays small.
  constexpr std::size_t kBlockValues = 1 << 16;
  std::vector<unsigned char> block(kBlockValues * sizeof(float));
  for (uint64_t done = 0; done < num_values;) {
    const std::size_t count =
        static_cast<std::size_t>(std::min<uint64_t>(kBlockValues, num_values - done));
    in.read(reinterpret_cast<char*>(block.data()),
            static_cast<std::streamsize>(count * sizeof(float)));
    if (in.gcount() != static_cast<std::streamsize>(count * sizeof(float))) {
      throw IoError(source_name, "read error in the float32 payload");
    }
    for (std::size_t i = 0; i < count; ++i) {
      const uint32_t bits = LoadLittleEndian32(block.data() + i * sizeof(float));
      std::memcpy(out + done + i, &bits, sizeof(float));
    }
    done += count;
  }
  return array;
}

DenseArray ReadDenseArray(const std::filesystem::path& path) {
  // A directory opens fine as an ifstream on Linux and then fails to read,
  // which would be reported as a malformed header.
  std::error_code ec;
  if (std::filesystem::is_directory(path, ec)) {
    throw IoError(path.string(), "is a directory, not a dense array file");
  }
  std::ifstream in(path, std::ios::binary);
  if (!in) throw IoError(path.string(), "cannot open dense array file");
  return ReadDenseArray(in, path.string());
}

std::optional<DenseArray> ReadDenseArrayIfPresent(const std::filesystem::path& path) {
  std::error_code ec;
  if (!std::filesystem::is_regular_file(path, ec)) return std::nullopt;
  return ReadDenseArray(path);
}

void WriteDenseArray(const DenseArray& array, const std::filesystem::path& path) {
  if (array.empty()) {
    throw IoError(path.string(), "refusing to write an empty dense array (" +
                                     std::to_string(array.width()) + "x" +
                                     std::to_string(array.height()) + "x" +
                                     std::to_string(array.channels()) + ")");
  }
  WriteFileAtomically(path, [&](std::ostream& out) {
    // std::to_string, not operator<<: a stream imbued with a grouping locale
    // would write "1,024".
    const std::string header = std::to_string(array.width()) + '&' +
                               std::to_string(array.height()) + '&' +
                               std::to_string(array.channels()) + '&';
    out.write(header.data(), static_cast<std::streamsize>(header.size()));
    constexpr std::size_t kBlockValues = 1 << 16;
    std::vector<char> block(kBlockValues * sizeof(float));
    const float* values = array.data();
    for (std::size_t done = 0; done < array.size();) {
      const std::size_t count = std::min(kBlockValues, array.size() - done);
      for (std::size_t i = 0; i < count; ++i) {
        uint32_t bits;
        std::memcpy(&bits, values + done + i, sizeof(float));
        StoreLittleEndian32(bits, block.data() + i * sizeof(float));
      }
      out.write(block.data(), static_cast<std::streamsize>(count * sizeof(float)));
      done += count;
    }
  });
}

}  // namespace dispmvs::colmap_io
