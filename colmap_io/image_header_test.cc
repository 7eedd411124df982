// The image header checks (image_header.h) and what ReadImageRgb does with
// them: every accepted format gives the size its decoder then reads; damaged
// and foreign files are refused with a reason before any decoder runs,
// including the inputs the fuzzer found (tests/fuzz/regressions/image_fuzzer).

#include "colmap_io/image_header.h"

#include <filesystem>
#include <string>
#include <vector>

#include <gtest/gtest.h>
#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>

#include "colmap_io/error.h"
#include "colmap_io/image_io.h"
#include "tests/support/temp_dir.h"

namespace dispmvs::colmap_io {
namespace {

namespace fs = std::filesystem;
using testing::ReadFileBytes;
using testing::TempDir;
using testing::WriteFileBytes;

// A 37x23 test card (odd sides, so width and height cannot be swapped
// unnoticed), grey or colour, 8 or 16 bits.
cv::Mat Card(int type) {
  cv::Mat image(23, 37, type);
  cv::randu(image, 0, CV_MAT_DEPTH(type) == CV_16U ? 65535 : 255);
  return image;
}

std::string Encode(const std::string& extension, const cv::Mat& image) {
  std::vector<uchar> bytes;
  EXPECT_TRUE(cv::imencode(extension, image, bytes)) << extension;
  return std::string(bytes.begin(), bytes.end());
}

// The message of the IoError that reading `path` throws; "" if none.
std::string ReadError(const fs::path& path, const ImageLimits& limits = {}) {
  try {
    ReadImageRgb(path, limits);
  } catch (const IoError& error) {
    EXPECT_EQ(error.path(), path.string());
    return error.what();
  }
  return "";
}

::testing::AssertionResult Contains(const std::string& text, const std::string& part) {
  if (text.find(part) != std::string::npos) return ::testing::AssertionSuccess();
  return ::testing::AssertionFailure() << "'" << text << "' does not contain '" << part << "'";
}

struct Encoded {
  const char* extension;
  ImageFormat format;
  int type;
};

const Encoded kAccepted[] = {
    {".png", ImageFormat::kPng, CV_8UC3},  {".png", ImageFormat::kPng, CV_16UC1},
    {".jpg", ImageFormat::kJpeg, CV_8UC3}, {".jpg", ImageFormat::kJpeg, CV_8UC1},
    {".tif", ImageFormat::kTiff, CV_8UC3}, {".tif", ImageFormat::kTiff, CV_16UC1},
    {".bmp", ImageFormat::kBmp, CV_8UC3},  {".ppm", ImageFormat::kPnm, CV_8UC3},
    {".pgm", ImageFormat::kPnm, CV_16UC1}, {".webp", ImageFormat::kWebp, CV_8UC3},
};

TEST(ImageHeaderTest, EveryAcceptedFormatGivesTheSizeItsDecoderReads) {
  TempDir dir;
  for (const Encoded& encoded : kAccepted) {
    SCOPED_TRACE(std::string(encoded.extension) + " type " + std::to_string(encoded.type));
    const std::string bytes = Encode(encoded.extension, Card(encoded.type));
    const ImageHeader header = ReadImageHeader(bytes, "card");
    EXPECT_EQ(header.format, encoded.format);
    EXPECT_EQ(header.width, 37);
    EXPECT_EQ(header.height, 23);
    // Independently: OpenCV's own decoding of the same bytes.
    const cv::Mat decoded = cv::imdecode(std::vector<uchar>(bytes.begin(), bytes.end()),
                                         cv::IMREAD_UNCHANGED);
    EXPECT_EQ(decoded.size(), cv::Size(header.width, header.height));
    const fs::path path = dir.Make(std::string("card") + encoded.extension);
    WriteFileBytes(path, bytes);
    ImageLimits limits;
    limits.expected_size = cv::Size(37, 23);
    EXPECT_EQ(ReadImageRgb(path, limits).size(), cv::Size(37, 23));
  }
}

TEST(ImageHeaderTest, SizesComeFromTheHeaderFields) {
  // Hand-made headers with sides that differ in every byte, each read back
  // exactly (no pixel data follows: the header alone is what is read).
  // PNG: IHDR (13 bytes and a CRC, not checked), then IEND.
  std::string png("\x89PNG\r\n\x1a\n\0\0\0\x0dIHDR\0\x01\x02\x03\0\0\x05\x06"
                  "\x08\x02\0\0\0crc!\0\0\0\0IENDcrc!",
                  45);
  EXPECT_EQ(ReadImageHeader(png, "p").width, 0x010203);
  EXPECT_EQ(ReadImageHeader(png, "p").height, 0x0506);

  std::string bmp(54, '\0');
  bmp[0] = 'B', bmp[1] = 'M', bmp[14] = 40;
  bmp[18] = 0x34, bmp[19] = 0x12;                                 // width 0x1234
  bmp[22] = static_cast<char>(0xFE), bmp[23] = bmp[24] = bmp[25] = static_cast<char>(0xFF);
  const ImageHeader top_down = ReadImageHeader(bmp, "b");  // height -2: top-down rows
  EXPECT_EQ(top_down.width, 0x1234);
  EXPECT_EQ(top_down.height, 2);

  const ImageHeader pnm = ReadImageHeader("P6\n# a comment 99 99\n 640\t# another\n480 255\n", "n");
  EXPECT_EQ(pnm.format, ImageFormat::kPnm);
  EXPECT_EQ(pnm.width, 640);
  EXPECT_EQ(pnm.height, 480);
  // The byte after a number is taken whatever it is: "3#2" is 3, then 2 (no
  // comment). Checked against OpenCV's own decoding of the same bytes.
  for (const std::string& header : {std::string("P5 3#2 255 "), std::string("P5\n3\n#c\r2\n255\n"),
                                     std::string("P5 3 #c\n2#255 ")}) {
    SCOPED_TRACE(header);
    const std::string bytes = header + "abcdef";
    const ImageHeader read = ReadImageHeader(bytes, "n");
    const cv::Mat decoded = cv::imdecode(std::vector<uchar>(bytes.begin(), bytes.end()),
                                         cv::IMREAD_UNCHANGED);
    EXPECT_EQ(cv::Size(read.width, read.height), cv::Size(3, 2));
    EXPECT_EQ(decoded.size(), cv::Size(3, 2));
  }

  // SOI, an APP0 segment to skip, then a baseline frame header (precision 8,
  // height 0x0102, width 0x0304), then a scan and the end-of-image marker.
  const std::string jpeg(
      "\xFF\xD8"
      "\xFF\xE0\x00\x04xx"
      "\xFF\xC0\x00\x0B\x08\x01\x02\x03\x04\x01\x01\x11\x00"
      "\xFF\xDA\x00\x02"
      "\x12\x34\xFF\x00\x56"
      "\xFF\xD9",
      32);
  const ImageHeader frame = ReadImageHeader(jpeg, "j");
  EXPECT_EQ(frame.width, 0x0304);
  EXPECT_EQ(frame.height, 0x0102);
  // The same without its end-of-image marker: a truncated file.
  TempDir dir;
  const fs::path cut = dir.Make("cut.jpg");
  WriteFileBytes(cut, jpeg.substr(0, jpeg.size() - 2));
  EXPECT_TRUE(
      Contains(ReadError(cut), "JPEG file is truncated: it ends before its end-of-image marker"));
}

TEST(ImageHeaderTest, ForeignAndDamagedFilesAreRefusedWithAReason) {
  TempDir dir;
  const auto refused = [&](const std::string& name, const std::string& bytes) {
    const fs::path path = dir.Make(name);
    WriteFileBytes(path, bytes);
    return ReadError(path);
  };
  const std::string unknown = "not an image in a supported format (PNG, JPEG, TIFF, BMP, PNM, WebP)";
  EXPECT_TRUE(Contains(refused("empty.png", ""), "image file is empty"));
  EXPECT_TRUE(Contains(refused("text.png", "hello, world"), unknown));
  // Formats OpenCV decodes but a COLMAP workspace does not hold never reach
  // their decoders.
  for (const char* extension : {".pfm", ".hdr", ".sr", ".pam"}) {
    SCOPED_TRACE(extension);
    cv::Mat image = Card(CV_8UC3);
    if (std::string(extension) == ".pfm" || std::string(extension) == ".hdr") {
      image.convertTo(image, CV_32FC3, 1.0 / 255);
    }
    EXPECT_TRUE(Contains(refused(std::string("foreign") + extension, Encode(extension, image)),
                         unknown));
  }
  // A DICOM signature ("DICM" at byte 128) behind a near-PNG start: what made
  // GDCM abort the process.
  std::string dicom(200, '\0');
  dicom.replace(0, 8, "\x89PNG\r\n)\n", 8);
  dicom.replace(128, 4, "DICM");
  EXPECT_TRUE(Contains(refused("dicom.png", dicom), unknown));
  // Every accepted format, cut short, is refused (never a partly grey image).
  for (const Encoded& encoded : kAccepted) {
    SCOPED_TRACE(encoded.extension);
    const std::string bytes = Encode(encoded.extension, Card(encoded.type));
    EXPECT_NE(refused(std::string("cut") + encoded.extension, bytes.substr(0, bytes.size() * 3 / 5)),
              "");
    EXPECT_NE(refused(std::string("head") + encoded.extension, bytes.substr(0, 20)), "");
  }
}

// A little-endian, uncompressed 4x2 8-bit grey TIFF in two strips of one
// row (4 bytes each), the first saying it holds `first_strip_bytes`, of
// which the file has `present` of the 8 pixel bytes.
std::string GreyTiff(uint16_t first_strip_bytes, std::size_t present) {
  std::string tiff("II*\0", 4);
  const auto u16 = [&tiff](uint32_t v) {
    tiff += static_cast<char>(v & 0xFF);
    tiff += static_cast<char>((v >> 8) & 0xFF);
  };
  const uint32_t entries = 8, data = 8 + 2 + entries * 12 + 4;
  u16(8), u16(0);  // the directory right after the header
  u16(entries);
  // SHORT values, one or two of them, inline in the entry.
  const auto entry = [&](uint32_t tag, uint32_t count, uint32_t first, uint32_t second) {
    u16(tag), u16(3), u16(count), u16(0), u16(first), u16(second);
  };
  entry(256, 1, 4, 0);                         // ImageWidth
  entry(257, 1, 2, 0);                         // ImageLength
  entry(258, 1, 8, 0);                         // BitsPerSample
  entry(259, 1, 1, 0);                         // Compression: none
  entry(262, 1, 1, 0);                         // Photometric: min is black
  entry(273, 2, data, data + 4);               // StripOffsets
  entry(278, 1, 1, 0);                         // RowsPerStrip
  entry(279, 2, first_strip_bytes, 4);         // StripByteCounts
  u16(0), u16(0);                              // no next directory
  tiff += std::string("abcdefgh").substr(0, present);
  return tiff;
}

TEST(ImageHeaderTest, UncompressedTiffStripsMustHoldTheirPixels) {
  TempDir dir;
  const fs::path whole = dir.Make("whole.tif"), cut = dir.Make("cut.tif"),
                 short_strip = dir.Make("short.tif");
  WriteFileBytes(whole, GreyTiff(4, 8));
  WriteFileBytes(cut, GreyTiff(4, 6));
  WriteFileBytes(short_strip, GreyTiff(3, 8));
  EXPECT_EQ(ReadImageRgb(whole).size(), cv::Size(4, 2));  // the hand-made file is valid
  EXPECT_TRUE(Contains(ReadError(cut),
                       "TIFF file is damaged or truncated: its strip 1 lies beyond the end of the "
                       "file"));
  EXPECT_TRUE(Contains(ReadError(short_strip),
                       "TIFF file is damaged or truncated: its uncompressed strip 0 holds 3 bytes "
                       "of the 4 its pixels need"));
}

TEST(ImageHeaderTest, WrongSizeIsRefusedBeforeDecoding) {
  TempDir dir;
  // A 37x23 PNG whose compressed pixels are destroyed (its chunks intact):
  // the size check must answer first, so the message is about the size, not
  // the decoding.
  std::string bytes = Encode(".png", Card(CV_8UC3));
  const std::size_t data = bytes.find("IDAT") + 4;
  for (std::size_t i = data; i < data + 100; ++i) bytes[i] = 'x';
  const fs::path path = dir.Make("damaged.png");
  WriteFileBytes(path, bytes);
  ImageLimits limits;
  limits.expected_size = cv::Size(320, 240);
  limits.expected_size_of = "camera 7";
  limits.size_mismatch_hint = "a hint";
  EXPECT_EQ(ReadError(path, limits),
            path.string() + ": image is 37x23 but camera 7 is 320x240 (a hint)");
  limits.expected_size = cv::Size(37, 23);
  EXPECT_TRUE(Contains(ReadError(path, limits), "cannot decode PNG image"));
  // Without an expected size, the pixel limit.
  ImageLimits small;
  small.max_pixels = 36 * 23;
  EXPECT_TRUE(Contains(ReadError(path, small), "image of 37x23 is larger than 828 pixels"));
  // A file far larger than any image of the expected size is not even read
  // (a sparse file: no disk space used).
  const fs::path huge = dir.Make("huge.png");
  WriteFileBytes(huge, Encode(".png", Card(CV_8UC3)));
  fs::resize_file(huge, 200u << 20);
  limits.expected_size = cv::Size(37, 23);
  EXPECT_TRUE(Contains(ReadError(huge, limits), "bytes is larger than any image of its allowed size"));
}

TEST(ImageHeaderTest, FuzzerFindingsAreRefusedWithoutDecoding) {
  const fs::path findings = fs::path(DISPMVS_SOURCE_DIR) / "tests/fuzz/regressions/image_fuzzer";
  // Aborted the process inside GDCM before the format check.
  EXPECT_TRUE(Contains(ReadError(findings / "image-gdcm-abort.bin"),
                       "not an image in a supported format"));
  // A 16392x6 TIFF whose 16390 rows per strip made the decoder allocate a
  // 1 GiB strip buffer: refused on the header, before any decoder runs, with
  // or without an expected size.
  const std::string tiff = ReadFileBytes(findings / "image-tiff-1gb.bin");
  const ImageHeader header = ReadImageHeader(tiff, "t");
  EXPECT_EQ(header.width, 16392);
  EXPECT_EQ(header.height, 6);
  EXPECT_EQ(header.decoder_buffer_bytes, uint64_t{16392} * 16390 * 4);
  EXPECT_TRUE(Contains(ReadError(findings / "image-tiff-1gb.bin"),
                       "TIFF header asks the decoder for a 1024 MiB buffer for a 16392x6 image"));
  ImageLimits camera;
  camera.expected_size = cv::Size(320, 240);
  EXPECT_TRUE(Contains(ReadError(findings / "image-tiff-1gb.bin", camera),
                       "image is 16392x6 but the expected size is 320x240"));
  // A PNM header whose second number follows a '#' right after the first:
  // read here once as 27222x4 (a comment) while OpenCV's decoder read
  // 27222x22220 and allocated 605 MB. Now read as the decoder reads it, and
  // refused for its size.
  const ImageHeader pnm = ReadImageHeader(ReadFileBytes(findings / "image-pnm-comment-605mb.bin"), "p");
  EXPECT_EQ(pnm.width, 27222);
  EXPECT_EQ(pnm.height, 22220);
  // A 10-bit TIFF with a damaged strip, which OpenCV's own 10-bit unpacking
  // decoded to other pixels on every read (bytes it never wrote).
  EXPECT_TRUE(Contains(ReadError(findings / "image-tiff-10bit-uninitialised.bin"),
                       "TIFF with 10 bits per sample is not supported (1, 8 or 16)"));
  // A 16-bit TIFF that says RGB with one sample per pixel: OpenCV made a
  // 3-channel image and filled a third of it, so every read differed.
  EXPECT_TRUE(Contains(ReadError(findings / "image-tiff-rgb-one-sample-uninitialised.bin"),
                       "TIFF header is inconsistent or unsupported: photometric interpretation 2 "
                       "with 1 sample(s) per pixel"));
  ImageLimits fuzzer_limit;
  fuzzer_limit.max_pixels = 262144;
  EXPECT_TRUE(Contains(ReadError(findings / "image-pnm-comment-605mb.bin", fuzzer_limit),
                       "image of 27222x22220 is larger than 262144 pixels"));
}

}  // namespace
}  // namespace dispmvs::colmap_io
