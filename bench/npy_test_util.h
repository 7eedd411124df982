#pragma once
// Test helper: .npy files built byte by byte, independently of the reader.

#include <cstdint>
#include <cstring>
#include <string>
#include <vector>

namespace dispmvs::bench::testing {

// Magic, version, little-endian header length, `dict` padded with spaces to
// a multiple of 64 bytes in all and ended by '\n' (as numpy.save does), then
// `payload` as is.
inline std::string NpyFile(int major, const std::string& dict, const std::string& payload) {
  const std::size_t length_size = major == 1 ? 2 : 4;
  const std::size_t preamble = 6 + 2 + length_size;
  std::string header = dict;
  while ((preamble + header.size() + 1) % 64 != 0) header += ' ';
  header += '\n';
  std::string out = "\x93NUMPY";
  out += static_cast<char>(major);
  out += '\0';
  for (std::size_t i = 0; i < length_size; ++i) {
    out += static_cast<char>((header.size() >> (8 * i)) & 0xff);
  }
  return out + header + payload;
}

// Little-endian float32 / float64 bytes of `values`.
inline std::string Float32Bytes(const std::vector<double>& values) {
  std::string out;
  for (const double value : values) {
    const float f = static_cast<float>(value);
    uint32_t bits;
    std::memcpy(&bits, &f, sizeof bits);
    for (int i = 0; i < 4; ++i) out += static_cast<char>((bits >> (8 * i)) & 0xff);
  }
  return out;
}

inline std::string Float64Bytes(const std::vector<double>& values) {
  std::string out;
  for (const double value : values) {
    uint64_t bits;
    std::memcpy(&bits, &value, sizeof bits);
    for (int i = 0; i < 8; ++i) out += static_cast<char>((bits >> (8 * i)) & 0xff);
  }
  return out;
}

// A version 1.0 '<f4' file of a rows x cols matrix (row-major values), with
// numpy's own header text.
inline std::string Float32Npy(int rows, int cols, const std::vector<double>& values) {
  return NpyFile(1,
                 "{'descr': '<f4', 'fortran_order': False, 'shape': (" + std::to_string(rows) +
                     ", " + std::to_string(cols) + "), }",
                 Float32Bytes(values));
}

}  // namespace dispmvs::bench::testing
