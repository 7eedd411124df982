#pragma once
// A strict reader of 2-D floating-point NumPy .npy files (format versions 1.0
// and 2.0, as numpy.save writes them), for ground-truth disparity maps such
// as scikit-image's Middlebury Motorcycle pair.
//
// Accepted: magic "\x93NUMPY", version 1.0 (header length uint16 LE) or 2.0
// (uint32 LE); a header that is a Python dict literal with exactly the keys
// 'descr', 'fortran_order' and 'shape' (any order, either quote style,
// optional trailing comma), padded with spaces and ended by '\n'; descr
// '<f4' or '<f8' (little-endian float32 / float64); fortran_order False; a
// 2-D shape (rows, cols), each in [1, 65536]; then exactly rows * cols
// values, C order (row-major). Anything else (another version, big-endian
// or integer data, Fortran order, another number of dimensions, a truncated
// payload or trailing bytes) is refused with a message saying what was found.

#include <filesystem>
#include <string>
#include <vector>

namespace dispmvs::bench {

struct NpyMatrix {
  int rows = 0;
  int cols = 0;
  std::string descr;           // "<f4" or "<f8", as stored
  std::vector<double> values;  // rows * cols, row-major; float32 values converted exactly

  double at(int row, int col) const {
    return values[static_cast<std::size_t>(row) * static_cast<std::size_t>(cols) +
                  static_cast<std::size_t>(col)];
  }
};

// Parses the whole contents of a .npy file. Throws colmap_io::IoError naming
// `source_name` and what is wrong.
NpyMatrix ParseNpyMatrix(const std::string& bytes, const std::string& source_name);

// Reads and parses `path`; IoError naming it when it cannot be read.
NpyMatrix ReadNpyMatrix(const std::filesystem::path& path);

}  // namespace dispmvs::bench
