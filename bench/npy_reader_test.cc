#include "bench/npy_reader.h"

#include <gtest/gtest.h>

#include <cmath>
#include <limits>
#include <string>
#include <vector>

#include "bench/npy_test_util.h"
#include "colmap_io/error.h"
#include "tests/support/temp_dir.h"

namespace dispmvs::bench {
namespace {

using testing::Float32Bytes;
using testing::Float64Bytes;
using testing::NpyFile;

constexpr double kInf = std::numeric_limits<double>::infinity();

// The message of the IoError parsing `bytes` throws ("" if none).
std::string ParseError(const std::string& bytes) {
  try {
    ParseNpyMatrix(bytes, "d.npy");
  } catch (const colmap_io::IoError& error) {
    return error.what();
  }
  return "";
}

TEST(StereoPairNpyTest, ReadsNumpysFloat32Layout) {
  // numpy.save of a 2x3 float32 array, including +inf and NaN.
  const std::vector<double> values = {1.5, -2.25, kInf, 7.1913557052612305, 0.0,
                                      std::nan("")};
  const std::string bytes = NpyFile(
      1, "{'descr': '<f4', 'fortran_order': False, 'shape': (2, 3), }", Float32Bytes(values));
  ASSERT_EQ((bytes.size() - 6 * 4) % 64, 0u);  // numpy's alignment, as the helper builds it
  const NpyMatrix m = ParseNpyMatrix(bytes, "d.npy");
  EXPECT_EQ(m.rows, 2);
  EXPECT_EQ(m.cols, 3);
  EXPECT_EQ(m.descr, "<f4");
  ASSERT_EQ(m.values.size(), 6u);
  EXPECT_EQ(m.at(0, 0), 1.5);
  EXPECT_EQ(m.at(0, 1), -2.25);
  EXPECT_EQ(m.at(0, 2), kInf);
  EXPECT_EQ(m.at(1, 0), static_cast<double>(7.1913557052612305f));  // exact float32 value
  EXPECT_EQ(m.at(1, 1), 0.0);
  EXPECT_TRUE(std::isnan(m.at(1, 2)));
}

TEST(StereoPairNpyTest, ReadsVersion2Float64AnyKeyOrder) {
  const std::vector<double> values = {0.1, 1e300, -3.0};
  const NpyMatrix m = ParseNpyMatrix(
      NpyFile(2, "{\"shape\": (3,1), \"fortran_order\": False, \"descr\": \"<f8\"}",
              Float64Bytes(values)),
      "d.npy");
  EXPECT_EQ(m.rows, 3);
  EXPECT_EQ(m.cols, 1);
  EXPECT_EQ(m.descr, "<f8");
  EXPECT_EQ(m.values, values);
}

TEST(StereoPairNpyTest, ReadsAFile) {
  dispmvs::testing::TempDir dir;
  const auto path = dir.path() / "d.npy";
  dispmvs::testing::WriteFileBytes(path, testing::Float32Npy(1, 2, {4, 5}));
  const NpyMatrix m = ReadNpyMatrix(path);
  EXPECT_EQ(m.values, (std::vector<double>{4, 5}));
  try {
    ReadNpyMatrix(dir.path() / "missing.npy");
    ADD_FAILURE() << "no error";
  } catch (const colmap_io::IoError& error) {
    EXPECT_NE(std::string(error.what()).find("missing.npy: no such file"), std::string::npos);
  }
}

TEST(StereoPairNpyTest, RefusesEverythingElse) {
  const std::string f4 = Float32Bytes({1, 2, 3, 4, 5, 6});
  const auto with_dict = [&](const std::string& dict) { return NpyFile(1, dict, f4); };
  const std::string good = "{'descr': '<f4', 'fortran_order': False, 'shape': (2, 3), }";
  ASSERT_EQ(ParseError(with_dict(good)), "");

  const auto expect = [](const std::string& bytes, const std::string& fragment) {
    const std::string message = ParseError(bytes);
    EXPECT_EQ(message.rfind("d.npy: ", 0), 0u) << message;
    EXPECT_NE(message.find(fragment), std::string::npos) << "\"" << message << "\" lacks \""
                                                         << fragment << "\"";
  };
  expect("PK\x03\x04 a zip", "not a NumPy .npy file");
  expect("", "not a NumPy .npy file");
  std::string v3 = with_dict(good);
  v3[6] = 3;
  expect(v3, "NPY format version 3.0 is not supported");
  std::string v11 = with_dict(good);
  v11[7] = 1;
  expect(v11, "version 1.1");
  expect(with_dict(good).substr(0, 9), "truncated NPY preamble");
  expect(with_dict(good).substr(0, 40), "truncated NPY header");
  expect(with_dict("{'descr': '>f4', 'fortran_order': False, 'shape': (2, 3), }"),
         "'>f4' is big-endian");
  expect(with_dict("{'descr': '<i4', 'fortran_order': False, 'shape': (2, 3), }"),
         "dtype '<i4' is not supported");
  expect(with_dict("{'descr': '<f4', 'fortran_order': True, 'shape': (2, 3), }"),
         "Fortran-order");
  expect(with_dict("{'descr': '<f4', 'fortran_order': False, 'shape': (6,), }"),
         "shape (6,) is not 2-D");
  expect(with_dict("{'descr': '<f4', 'fortran_order': False, 'shape': (1, 2, 3), }"),
         "shape (1, 2, 3) is not 2-D");
  expect(with_dict("{'descr': '<f4', 'fortran_order': False, 'shape': (0, 3), }"),
         "each side must be in [1, 65536]");
  expect(with_dict("{'descr': '<f4', 'fortran_order': False, 'shape': (2, 3), 'x': 1}"),
         "unknown key 'x'");
  expect(with_dict("{'descr': '<f4', 'shape': (2, 3), }"), "key 'fortran_order' is missing");
  expect(with_dict("{'descr': '<f4', 'descr': '<f4', 'fortran_order': False, 'shape': (2, 3)}"),
         "key 'descr' appears twice");
  expect(with_dict("{'descr': '<f4', 'fortran_order': false, 'shape': (2, 3)}"),
         "expected True or False");
  expect(with_dict("{'descr': '<f4', 'fortran_order': False, 'shape': (2, -3)}"),
         "expected a non-negative integer");
  expect(with_dict("{'descr': '<f4' 'fortran_order': False, 'shape': (2, 3)}"),
         "expected ',' or '}'");
  expect(with_dict(good + " x"), "must end with spaces and a newline");
  // A header without its final newline: the data's first byte takes its place.
  std::string no_newline = with_dict(good);
  no_newline[no_newline.find('\n')] = ' ';
  expect(no_newline, "must end with spaces and a newline");
  expect(NpyFile(1, good, f4.substr(0, 23)), "truncated: shape (2, 3) of '<f4' needs 24 bytes");
  expect(NpyFile(1, good, f4 + "x"), "trailing data: shape (2, 3) of '<f4' needs 24 bytes of "
                                     "data, the file has 25");
}

}  // namespace
}  // namespace dispmvs::bench
