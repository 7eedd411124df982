#include "colmap_io/dense_array.h"

#include <gtest/gtest.h>

#include <cmath>
#include <cstdint>
#include <cstring>
#include <limits>
#include <sstream>
#include <stdexcept>
#include <string>

#include "colmap_io/error.h"
#include "tests/support/temp_dir.h"

namespace dispmvs::colmap_io {
namespace {

using dispmvs::testing::ReadFileBytes;
using dispmvs::testing::TempDir;
using dispmvs::testing::WriteFileBytes;

// The four little-endian bytes of a float32, built independently of the code
// under test (x86 and ARM are little endian, but do not rely on it).
std::string FloatBytes(float value) {
  uint32_t bits;
  std::memcpy(&bits, &value, sizeof(bits));
  std::string bytes(4, '\0');
  for (int i = 0; i < 4; ++i) bytes[i] = static_cast<char>((bits >> (8 * i)) & 0xff);
  return bytes;
}

// Expects ReadDenseArray(path) to throw IoError whose message names the file
// and contains `fragment`.
void ExpectReadError(const TempDir& dir, const std::string& bytes, const std::string& fragment) {
  const auto path = dir.Make("bad.bin");
  WriteFileBytes(path, bytes);
  try {
    ReadDenseArray(path);
    FAIL() << "no error for contents of " << bytes.size() << " bytes, expected: " << fragment;
  } catch (const IoError& error) {
    const std::string message = error.what();
    EXPECT_NE(message.find(path.string()), std::string::npos) << message;
    EXPECT_NE(message.find(fragment), std::string::npos) << message;
    EXPECT_EQ(error.path(), path.string());
  }
}

TEST(DenseArrayTest, ConstructorFillsAndIndexesChannelPlanar) {
  DenseArray array(3, 2, 2, 7.5f);
  EXPECT_EQ(array.width(), 3);
  EXPECT_EQ(array.height(), 2);
  EXPECT_EQ(array.channels(), 2);
  ASSERT_EQ(array.size(), 12u);
  for (float value : array.values()) EXPECT_EQ(value, 7.5f);
  array.at(1, 2, 1) = -1.0f;
  // c*W*H + row*W + col = 1*6 + 1*3 + 2 = 11.
  EXPECT_EQ(array.data()[11], -1.0f);
  array.at(0, 1, 0) = 4.0f;  // 0 + 0 + 1
  EXPECT_EQ(array.data()[1], 4.0f);
}

TEST(DenseArrayTest, AtIsBoundsChecked) {
  DenseArray array(3, 2, 1);
  EXPECT_THROW(array.at(2, 0), std::out_of_range);
  EXPECT_THROW(array.at(0, 3), std::out_of_range);
  EXPECT_THROW(array.at(0, 0, 1), std::out_of_range);
  EXPECT_THROW(array.at(-1, 0), std::out_of_range);
  const DenseArray& const_array = array;
  EXPECT_THROW(const_array.at(0, -1), std::out_of_range);
}

TEST(DenseArrayTest, ConstructorRejectsBadSizes) {
  EXPECT_THROW(DenseArray(-1, 2, 1), std::invalid_argument);
  EXPECT_THROW(DenseArray(2, 2, -3), std::invalid_argument);
  EXPECT_THROW(DenseArray(static_cast<int>(kMaxDenseArraySide) + 1, 1, 1),
               std::invalid_argument);
  EXPECT_THROW(DenseArray(1, 1, static_cast<int>(kMaxDenseArrayChannels) + 1),
               std::invalid_argument);
  EXPECT_TRUE(DenseArray().empty());
}

TEST(DenseArrayTest, ReadsHandWrittenFile) {
  // 2 wide, 2 high, 2 channels. Channel-planar: channel 0 is the first four
  // floats (row-major), channel 1 the next four.
  std::string bytes = "2&2&2&";
  const float values[8] = {1.0f, 2.0f, 3.0f, 4.0f, -0.5f, 100.25f, 1e-3f, 6.0f};
  for (float value : values) bytes += FloatBytes(value);
  TempDir dir;
  const auto path = dir.Make("hand.bin");
  WriteFileBytes(path, bytes);

  const DenseArray array = ReadDenseArray(path);
  ASSERT_EQ(array.width(), 2);
  ASSERT_EQ(array.height(), 2);
  ASSERT_EQ(array.channels(), 2);
  EXPECT_EQ(array.at(0, 0, 0), 1.0f);
  EXPECT_EQ(array.at(0, 1, 0), 2.0f);
  EXPECT_EQ(array.at(1, 0, 0), 3.0f);
  EXPECT_EQ(array.at(1, 1, 0), 4.0f);
  EXPECT_EQ(array.at(0, 0, 1), -0.5f);
  EXPECT_EQ(array.at(0, 1, 1), 100.25f);
  EXPECT_EQ(array.at(1, 0, 1), 1e-3f);
  EXPECT_EQ(array.at(1, 1, 1), 6.0f);
}

TEST(DenseArrayTest, NonSquareHandWrittenFileUsesWidthAsRowStride) {
  // 3 wide, 1 high: a transposed reader would fail on at(0, 2).
  std::string bytes = "3&1&1&" + FloatBytes(10.0f) + FloatBytes(20.0f) + FloatBytes(30.0f);
  TempDir dir;
  const auto path = dir.Make("row.bin");
  WriteFileBytes(path, bytes);
  const DenseArray array = ReadDenseArray(path);
  ASSERT_EQ(array.width(), 3);
  ASSERT_EQ(array.height(), 1);
  EXPECT_EQ(array.at(0, 2), 30.0f);
  EXPECT_EQ(array.at(0, 1), 20.0f);
}

TEST(DenseArrayTest, WritesColmapHeaderAndLittleEndianPayload) {
  DenseArray array(2, 1, 1);
  array.at(0, 0) = 1.5f;
  array.at(0, 1) = -2.0f;
  TempDir dir;
  const auto path = dir.path() / "out.bin";
  WriteDenseArray(array, path);
  EXPECT_EQ(ReadFileBytes(path), "2&1&1&" + FloatBytes(1.5f) + FloatBytes(-2.0f));
}

TEST(DenseArrayTest, RoundTripIsBitExact) {
  DenseArray array(5, 3, 3);
  // Special values must survive too: NaN payloads, infinities, signed zero,
  // denormals.
  float* values = array.data();
  for (std::size_t i = 0; i < array.size(); ++i) {
    values[i] = static_cast<float>(i) * 0.1f - 2.0f;
  }
  values[0] = std::numeric_limits<float>::quiet_NaN();
  values[1] = std::numeric_limits<float>::infinity();
  values[2] = -0.0f;
  values[3] = std::numeric_limits<float>::denorm_min();
  values[4] = std::numeric_limits<float>::max();

  TempDir dir;
  const auto path = dir.path() / "nested" / "folder" / "round.bin";
  WriteDenseArray(array, path);
  const DenseArray back = ReadDenseArray(path);
  ASSERT_EQ(back.width(), 5);
  ASSERT_EQ(back.height(), 3);
  ASSERT_EQ(back.channels(), 3);
  ASSERT_EQ(back.size(), array.size());
  EXPECT_EQ(std::memcmp(back.data(), array.data(), array.size() * sizeof(float)), 0);
  EXPECT_TRUE(std::isnan(back.at(0, 0)));
  EXPECT_TRUE(std::signbit(back.at(0, 2)));
}

TEST(DenseArrayTest, RoundTripLargerThanOneIoBlock) {
  // 300 x 250 x 1 = 75000 values: more than the 65536-value blocks the reader
  // and writer use, so block boundaries are exercised.
  DenseArray array(300, 250, 1);
  for (int row = 0; row < 250; ++row) {
    for (int col = 0; col < 300; ++col) array.at(row, col) = static_cast<float>(row * 1000 + col);
  }
  TempDir dir;
  const auto path = dir.path() / "big.bin";
  WriteDenseArray(array, path);
  const DenseArray back = ReadDenseArray(path);
  EXPECT_EQ(back.at(249, 299), 249299.0f);
  EXPECT_EQ(back.at(218, 136), 218136.0f);  // value index 65536
  EXPECT_EQ(std::memcmp(back.data(), array.data(), array.size() * sizeof(float)), 0);
}

TEST(DenseArrayTest, ReadsFromStream) {
  std::istringstream in("1&1&1&" + FloatBytes(3.25f));
  const DenseArray array = ReadDenseArray(in, "in-memory");
  EXPECT_EQ(array.at(0, 0), 3.25f);
}

TEST(DenseArrayTest, MissingFileOrDirectoryIsAnIoError) {
  TempDir dir;
  EXPECT_THROW(ReadDenseArray(dir.path() / "absent.bin"), IoError);
  try {
    ReadDenseArray(dir.path());
    FAIL();
  } catch (const IoError& error) {
    EXPECT_NE(std::string(error.what()).find("is a directory"), std::string::npos);
  }
}

TEST(DenseArrayTest, RejectsMalformedHeaders) {
  TempDir dir;
  const std::string one_float = FloatBytes(1.0f);
  ExpectReadError(dir, "", "malformed header");
  ExpectReadError(dir, "2&2", "malformed header");
  ExpectReadError(dir, "2&2&", "malformed header");
  ExpectReadError(dir, "x&1&1&" + one_float, "malformed header");
  ExpectReadError(dir, " 1&1&1&" + one_float, "malformed header");
  ExpectReadError(dir, "1,1,1," + one_float, "malformed header");
  ExpectReadError(dir, "&1&1&" + one_float, "empty width");
  ExpectReadError(dir, "1&1&1.0&" + one_float, "malformed header");
  ExpectReadError(dir, "-1&1&1&" + one_float, "malformed header");
  ExpectReadError(dir, "1&+1&1&" + one_float, "malformed header");
  ExpectReadError(dir, std::string(5000, '0'), "too long");
}

TEST(DenseArrayTest, RejectsZeroAndAbsurdDimensions) {
  TempDir dir;
  const std::string one_float = FloatBytes(1.0f);
  ExpectReadError(dir, "0&1&1&", "width is 0");
  ExpectReadError(dir, "1&0&1&", "height is 0");
  ExpectReadError(dir, "1&1&0&", "channels is 0");
  ExpectReadError(dir, "65537&1&1&" + one_float, "width 65537 exceeds");
  ExpectReadError(dir, "1&70000&1&" + one_float, "height 70000 exceeds");
  ExpectReadError(dir, "1&1&1025&" + one_float, "channels 1025 exceeds");
  // 2^32 on every side: W*H*C would overflow 64 bits. Must be rejected
  // without allocating anything.
  ExpectReadError(dir, "4294967296&4294967296&4294967296&" + one_float, "exceeds");
  // Does not even fit in 64 bits.
  ExpectReadError(dir, "99999999999999999999&1&1&" + one_float, "64 bits");
}

TEST(DenseArrayTest, RejectsPayloadSizeMismatch) {
  TempDir dir;
  const std::string f = FloatBytes(1.0f);
  // 2x2x1 needs 16 bytes.
  ExpectReadError(dir, "2&2&1&" + f + f + f, "truncated");
  ExpectReadError(dir, "2&2&1&" + f + f + f + "ab", "truncated");
  ExpectReadError(dir, "2&2&1&", "truncated");
  ExpectReadError(dir, "2&2&1&" + f + f + f + f + "\n", "trailing data");
  ExpectReadError(dir, "2&2&1&" + f + f + f + f + f, "trailing data");
  // A large header with a tiny file: reported as truncated, and must not try
  // to allocate the 16 GiB the header claims.
  ExpectReadError(dir, "65536&65536&1&" + f, "truncated");
}

TEST(DenseArrayTest, WritingAnEmptyArrayIsAnError) {
  TempDir dir;
  const auto path = dir.path() / "empty.bin";
  EXPECT_THROW(WriteDenseArray(DenseArray(), path), IoError);
  EXPECT_THROW(WriteDenseArray(DenseArray(0, 4, 1), path), IoError);
  EXPECT_FALSE(std::filesystem::exists(path));
}

TEST(DenseArrayTest, ReadIfPresentTellsAbsentFromBroken) {
  const TempDir dir;
  const std::filesystem::path path = dir.path() / "d.bin";
  EXPECT_FALSE(ReadDenseArrayIfPresent(path).has_value());  // absent
  std::filesystem::create_directory(dir.path() / "folder.bin");
  EXPECT_FALSE(ReadDenseArrayIfPresent(dir.path() / "folder.bin").has_value());  // not a file
  WriteDenseArray(DenseArray(3, 2, 1, 4.5f), path);
  const std::optional<DenseArray> read = ReadDenseArrayIfPresent(path);
  ASSERT_TRUE(read.has_value());
  EXPECT_EQ(read->width(), 3);
  EXPECT_EQ(read->at(1, 2), 4.5f);
  WriteFileBytes(path, "3&2&1&");  // present but truncated
  EXPECT_THROW(ReadDenseArrayIfPresent(path), IoError);
}

}  // namespace
}  // namespace dispmvs::colmap_io
