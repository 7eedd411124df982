#include "colmap_io/image_header.h"

#include <algorithm>
#include <cctype>
#include <cstdarg>
#include <cstdio>
#include <cstring>
#include <limits>
#include <memory>

#include <tiffio.h>
#include <webp/decode.h>

#include "colmap_io/error.h"

namespace dispmvs::colmap_io {
namespace {

// Larger sides are refused: no camera is that large, and OpenCV refuses
// above 2^20 anyway. Keeps every product below of sides exact in 64 bits.
constexpr uint32_t kMaxSide = 1u << 24;

bool StartsWith(const std::string& bytes, const char* magic, std::size_t length) {
  return bytes.size() >= length && std::memcmp(bytes.data(), magic, length) == 0;
}

uint32_t BigEndian(const std::string& bytes, std::size_t at, int length) {
  uint32_t value = 0;
  for (int i = 0; i < length; ++i) value = (value << 8) | static_cast<uint8_t>(bytes[at + i]);
  return value;
}

uint32_t LittleEndian(const std::string& bytes, std::size_t at, int length) {
  uint32_t value = 0;
  for (int i = length - 1; i >= 0; --i) value = (value << 8) | static_cast<uint8_t>(bytes[at + i]);
  return value;
}

// Fills width and height, refusing 0 and sides above kMaxSide.
void SetSize(ImageHeader& header, uint64_t width, uint64_t height, const std::string& path) {
  if (width == 0 || height == 0 || width > kMaxSide || height > kMaxSide) {
    throw IoError(path, std::string(ImageFormatName(header.format)) + " header gives a size of " +
                            std::to_string(width) + "x" + std::to_string(height) +
                            " (each side must be 1 to " + std::to_string(kMaxSide) + ")");
  }
  header.width = static_cast<int>(width);
  header.height = static_cast<int>(height);
}

[[noreturn]] void Truncated(ImageFormat format, const std::string& path) {
  throw IoError(path, std::string(ImageFormatName(format)) + " header is truncated");
}

// PNG: the signature, then the IHDR chunk first (the PNG specification
// requires it there), width and height as big-endian 32-bit numbers. Then
// the chunks (length, type, data, CRC) are walked to IEND, so that a cut
// file is named as such instead of failing inside libpng.
void ReadPng(const std::string& bytes, ImageHeader& header, const std::string& path) {
  if (bytes.size() < 24) Truncated(header.format, path);
  if (bytes.compare(12, 4, "IHDR") != 0) {
    throw IoError(path, "PNG file does not start with its IHDR chunk (damaged file)");
  }
  SetSize(header, BigEndian(bytes, 16, 4), BigEndian(bytes, 20, 4), path);
  for (uint64_t at = 8; at + 8 <= bytes.size();) {
    const uint64_t end = at + 12 + BigEndian(bytes, at, 4);  // length, type, data, CRC
    const std::string type = bytes.substr(at + 4, 4);
    if (end > bytes.size()) {
      throw IoError(path, "PNG file is truncated: it ends inside its " + type + " chunk");
    }
    if (type == "IEND") return;
    at = end;
  }
  throw IoError(path, "PNG file is truncated: it ends before its IEND chunk");
}

// JPEG: walks the marker segments to the first frame header (SOFn), which
// gives the size, then to the first scan, and asks for an end-of-image marker
// after it. Entropy-coded data escapes every 0xFF byte (0xFF 0x00), so the
// only 0xFF 0xD9 after the first scan is a real marker.
void ReadJpeg(const std::string& bytes, ImageHeader& header, const std::string& path) {
  const auto damaged = [&](const std::string& why) {
    return IoError(path, "JPEG file is damaged: " + why);
  };
  bool have_frame = false;
  std::size_t at = 2;  // after SOI (0xFF 0xD8)
  while (true) {
    if (at >= bytes.size()) {
      throw damaged(have_frame ? "it ends before its first scan" : "no frame header");
    }
    if (static_cast<uint8_t>(bytes[at]) != 0xFF) {
      throw damaged("a marker was expected at byte " + std::to_string(at));
    }
    while (at < bytes.size() && static_cast<uint8_t>(bytes[at]) == 0xFF) ++at;  // fill bytes
    if (at >= bytes.size()) Truncated(header.format, path);
    const uint8_t marker = static_cast<uint8_t>(bytes[at++]);
    // Markers without a length: TEM, RSTn, SOI, EOI.
    if (marker == 0x01 || (marker >= 0xD0 && marker <= 0xD8)) continue;
    if (marker == 0xD9) throw damaged("end-of-image marker before any scan");
    if (at + 2 > bytes.size()) Truncated(header.format, path);
    const uint32_t length = BigEndian(bytes, at, 2);  // counts its own two bytes
    if (length < 2 || at + length > bytes.size()) {
      throw damaged("a marker segment runs past the end of the file (truncated?)");
    }
    // SOF0-SOF15 except DHT (C4), JPG (C8) and DAC (CC).
    const bool frame = marker >= 0xC0 && marker <= 0xCF && marker != 0xC4 && marker != 0xC8 &&
                       marker != 0xCC;
    if (frame && !have_frame) {
      if (length < 8) throw damaged("frame header too short");
      const uint32_t height = BigEndian(bytes, at + 3, 2);
      const uint32_t width = BigEndian(bytes, at + 5, 2);
      if (height == 0) {
        throw IoError(path, "JPEG gives its height in a DNL marker, which is not supported");
      }
      SetSize(header, width, height, path);
      have_frame = true;
    }
    if (marker == 0xDA) {  // start of scan: the entropy-coded data follows
      if (!have_frame) throw damaged("a scan before the frame header");
      if (bytes.find("\xFF\xD9", at + length) == std::string::npos) {
        throw IoError(path, "JPEG file is truncated: it ends before its end-of-image marker");
      }
      return;
    }
    at += length;
  }
}

// BMP: the file header (14 bytes), then the info header whose first field is
// its own size: 12 for OS/2's (16-bit sides), larger for Windows' (32-bit
// sides, a negative height for a top-down image).
void ReadBmp(const std::string& bytes, ImageHeader& header, const std::string& path) {
  if (bytes.size() < 26) Truncated(header.format, path);
  const uint32_t info_size = LittleEndian(bytes, 14, 4);
  if (info_size == 12) {
    SetSize(header, LittleEndian(bytes, 18, 2), LittleEndian(bytes, 20, 2), path);
    return;
  }
  if (info_size < 40) {
    throw IoError(path, "BMP info header of " + std::to_string(info_size) +
                            " bytes is not one of the known kinds (damaged file)");
  }
  const auto width = static_cast<int32_t>(LittleEndian(bytes, 18, 4));
  const auto height = static_cast<int32_t>(LittleEndian(bytes, 22, 4));
  const int64_t abs_height = height < 0 ? -static_cast<int64_t>(height) : height;
  SetSize(header, width < 0 ? 0 : static_cast<uint64_t>(width),
          static_cast<uint64_t>(abs_height), path);
}

// PNM: "P1" to "P6", then width and height as decimal numbers, read token
// by token exactly as OpenCV's PNM decoder (its own code, not a library's)
// reads them, since any difference lets a header say one size to this check
// and another to the decoder. Its rules: before a number, white space is
// skipped, and a '#' starts a comment that runs to a line break, after which
// one more byte is taken; any other byte is an error; the byte right after a
// number's digits is taken whatever it is (so "3#" is the number 3, and the
// '#' starts no comment). The fuzzer found a header read as 27222x4 here and
// as 27222x22220 by the decoder, which then allocated 605 MB, before these
// rules were followed to the letter.
void ReadPnm(const std::string& bytes, ImageHeader& header, const std::string& path) {
  std::size_t at = 2;  // after "P" and the digit
  const auto next = [&]() -> int {
    if (at >= bytes.size()) Truncated(header.format, path);
    return static_cast<unsigned char>(bytes[at++]);
  };
  const auto number = [&]() -> uint64_t {
    int code = next();
    while (!std::isdigit(code)) {
      if (code == '#') {
        do code = next(); while (code != '\n' && code != '\r');
        code = next();
      } else if (std::isspace(code)) {
        while (std::isspace(code)) code = next();
      } else {
        throw IoError(path, "PNM header: unexpected byte " + std::to_string(code) + " at byte " +
                                std::to_string(at - 1));
      }
    }
    uint64_t value = 0;
    do {
      value = std::min<uint64_t>(value * 10 + static_cast<uint64_t>(code - '0'), kMaxSide + 1);
      code = at < bytes.size() ? next() : ' ';  // the byte after the digits is taken
    } while (std::isdigit(code));
    return value;  // above kMaxSide: refused by SetSize, never overflows
  };
  const uint64_t width = number();
  const uint64_t height = number();
  SetSize(header, width, height, path);
}

// WebP: libwebp's own parse of the first 32 bytes, the call OpenCV's
// signature check makes, so that both agree on what is a WebP file.
void ReadWebp(const std::string& bytes, ImageHeader& header, const std::string& path) {
  WebPBitstreamFeatures features;
  if (WebPGetFeatures(reinterpret_cast<const uint8_t*>(bytes.data()), 32, &features) !=
      VP8_STATUS_OK) {
    throw IoError(path, "WebP header is damaged");
  }
  if (features.has_animation) throw IoError(path, "animated WebP is not supported");
  SetSize(header, static_cast<uint64_t>(std::max(features.width, 0)),
          static_cast<uint64_t>(std::max(features.height, 0)), path);
}

// libtiff reads TIFF's first directory from memory through these.
struct MemoryFile {
  const std::string* bytes;
  uint64_t position = 0;
  std::string first_error;
};

tmsize_t MemoryRead(thandle_t handle, void* buffer, tmsize_t size) {
  auto* file = static_cast<MemoryFile*>(handle);
  if (size <= 0 || file->position >= file->bytes->size()) return 0;
  const uint64_t count =
      std::min<uint64_t>(static_cast<uint64_t>(size), file->bytes->size() - file->position);
  std::memcpy(buffer, file->bytes->data() + file->position, count);
  file->position += count;
  return static_cast<tmsize_t>(count);
}

tmsize_t MemoryWrite(thandle_t, void*, tmsize_t) { return -1; }

toff_t MemorySeek(thandle_t handle, toff_t offset, int whence) {
  auto* file = static_cast<MemoryFile*>(handle);
  uint64_t base = 0;
  if (whence == SEEK_CUR) base = file->position;
  if (whence == SEEK_END) base = file->bytes->size();
  if (offset > std::numeric_limits<uint64_t>::max() - base) return static_cast<toff_t>(-1);
  file->position = base + offset;
  return file->position;
}

int MemoryClose(thandle_t) { return 0; }
toff_t MemorySize(thandle_t handle) { return static_cast<MemoryFile*>(handle)->bytes->size(); }
int MemoryMap(thandle_t, void**, toff_t*) { return 0; }
void MemoryUnmap(thandle_t, void*, toff_t) {}

// libtiff reports through handlers; the first error becomes the message and
// nothing goes to the terminal.
int KeepFirstError(TIFF*, void* user_data, const char*, const char* format, va_list arguments) {
  auto* file = static_cast<MemoryFile*>(user_data);
  if (file->first_error.empty()) {
    char text[256];
    std::vsnprintf(text, sizeof text, format, arguments);
    file->first_error = text;
  }
  return 1;
}
int IgnoreWarning(TIFF*, void*, const char*, const char*, va_list) { return 1; }

// TIFF: libtiff reads the first directory (the image OpenCV decodes), with
// its allocations capped. The strip or tile buffer is sized as OpenCV 4.6's
// TIFF decoder sizes it: one tile (or one strip of RowsPerStrip rows, the
// whole image when the tag is absent or 2^32-1) of 4 bytes per pixel for
// 8-bit output (it reads RGBA), of the samples' own bytes otherwise.
void ReadTiff(const std::string& bytes, ImageHeader& header, const std::string& path) {
  MemoryFile file{&bytes, 0, {}};
  std::unique_ptr<TIFFOpenOptions, void (*)(TIFFOpenOptions*)> options(TIFFOpenOptionsAlloc(),
                                                                      TIFFOpenOptionsFree);
  TIFFOpenOptionsSetMaxSingleMemAlloc(options.get(), 64 << 20);
  TIFFOpenOptionsSetErrorHandlerExtR(options.get(), KeepFirstError, &file);
  TIFFOpenOptionsSetWarningHandlerExtR(options.get(), IgnoreWarning, &file);
  std::unique_ptr<TIFF, void (*)(TIFF*)> tiff(
      TIFFClientOpenExt(path.c_str(), "rm", &file, MemoryRead, MemoryWrite, MemorySeek,
                        MemoryClose, MemorySize, MemoryMap, MemoryUnmap, options.get()),
      TIFFClose);
  if (!tiff) {
    // libtiff's messages start with the name it was given: said once already.
    std::string reason = file.first_error;
    if (reason.rfind(path + ": ", 0) == 0) reason.erase(0, path.size() + 2);
    throw IoError(path, "TIFF file is damaged or truncated" + (reason.empty() ? "" : ": " + reason));
  }
  uint32_t width = 0, height = 0;
  uint16_t bits = 1, samples = 1;
  if (!TIFFGetField(tiff.get(), TIFFTAG_IMAGEWIDTH, &width) ||
      !TIFFGetField(tiff.get(), TIFFTAG_IMAGELENGTH, &height)) {
    throw IoError(path, "TIFF header gives no image size");
  }
  SetSize(header, width, height, path);
  TIFFGetFieldDefaulted(tiff.get(), TIFFTAG_BITSPERSAMPLE, &bits);
  TIFFGetFieldDefaulted(tiff.get(), TIFFTAG_SAMPLESPERPIXEL, &samples);
  // 1, 8 and 16 bits only: 10, 12 and 14 bits go through OpenCV's own
  // unpacking, which no camera image of a workspace needs (the first TIFF
  // the fuzzer found decoding to other pixels on every read was a 10-bit
  // one), and 32 and 64 bits are floats, which the project does not read.
  if (bits != 1 && bits != 8 && bits != 16) {
    throw IoError(path, "TIFF with " + std::to_string(bits) +
                            " bits per sample is not supported (1, 8 or 16)");
  }
  uint32_t tile_width = width, tile_height = 0;
  const bool tiled = TIFFIsTiled(tiff.get());
  if (tiled) {
    TIFFGetField(tiff.get(), TIFFTAG_TILEWIDTH, &tile_width);
    TIFFGetField(tiff.get(), TIFFTAG_TILELENGTH, &tile_height);
  } else {
    TIFFGetField(tiff.get(), TIFFTAG_ROWSPERSTRIP, &tile_height);
  }
  if (tile_width == 0) tile_width = width;
  if (tile_height == 0 || (!tiled && tile_height == std::numeric_limits<uint32_t>::max())) {
    tile_height = height;
  }
  // The colour model must fit the samples: OpenCV sizes its output by the
  // one and reads the other, so an RGB image of 1 sample per pixel left two
  // thirds of the image unwritten (the fuzzer found a 246-byte 16-bit TIFF
  // that decoded to other pixels on every read).
  uint16_t photometric = 0;
  if (!TIFFGetField(tiff.get(), TIFFTAG_PHOTOMETRIC, &photometric)) {
    throw IoError(path, "TIFF header gives no photometric interpretation (damaged file)");
  }
  const bool grey = photometric == PHOTOMETRIC_MINISWHITE || photometric == PHOTOMETRIC_MINISBLACK;
  const bool colour = photometric == PHOTOMETRIC_RGB || photometric == PHOTOMETRIC_YCBCR;
  if (!((grey && samples >= 1 && samples <= 4) || (colour && samples >= 3 && samples <= 4) ||
        (photometric == PHOTOMETRIC_PALETTE && samples == 1))) {
    throw IoError(path, "TIFF header is inconsistent or unsupported: photometric interpretation " +
                            std::to_string(photometric) + " with " + std::to_string(samples) +
                            " sample(s) per pixel");
  }
  // Strips or tiles that reach past the end of the file (a cut file), and,
  // uncompressed, strips or tiles shorter than their pixels (libtiff makes
  // up a missing StripByteCounts from the file's size).
  uint16_t compression = COMPRESSION_NONE;
  TIFFGetFieldDefaulted(tiff.get(), TIFFTAG_COMPRESSION, &compression);
  const uint32_t striles = TIFFNumberOfStrips(tiff.get());
  const uint32_t rows_per_strip = std::min(tile_height, height);
  const uint32_t strips_per_plane = (height + rows_per_strip - 1) / rows_per_strip;
  for (uint32_t strile = 0; strile < striles; ++strile) {
    int error = 0;
    const uint64_t offset = TIFFGetStrileOffsetWithErr(tiff.get(), strile, &error);
    const uint64_t count = TIFFGetStrileByteCountWithErr(tiff.get(), strile, &error);
    const std::string what = std::string(tiled ? "tile " : "strip ") + std::to_string(strile);
    if (error || offset > bytes.size() || count > bytes.size() - offset) {
      throw IoError(path, "TIFF file is damaged or truncated: its " + what +
                              " lies beyond the end of the file");
    }
    if (compression != COMPRESSION_NONE) continue;
    const uint32_t first_row = (strile % strips_per_plane) * rows_per_strip;
    const uint64_t needed =
        tiled ? TIFFTileSize64(tiff.get())
              : TIFFVStripSize64(tiff.get(), std::min(rows_per_strip, height - first_row));
    if (count < needed) {
      throw IoError(path, "TIFF file is damaged or truncated: its uncompressed " + what +
                              " holds " + std::to_string(count) + " bytes of the " +
                              std::to_string(needed) + " its pixels need");
    }
  }
  const uint64_t bytes_per_pixel =
      std::max<uint64_t>(4, static_cast<uint64_t>((bits + 7) / 8) * samples);
  // Each factor < 2^32 and bytes_per_pixel < 2^17: compare before multiplying.
  const uint64_t tile_pixels = static_cast<uint64_t>(tile_width) * tile_height;
  header.decoder_buffer_bytes = tile_pixels > (uint64_t{1} << 46) / bytes_per_pixel
                                    ? (uint64_t{1} << 46)
                                    : tile_pixels * bytes_per_pixel;
}

}  // namespace

const char* ImageFormatName(ImageFormat format) {
  switch (format) {
    case ImageFormat::kPng: return "PNG";
    case ImageFormat::kJpeg: return "JPEG";
    case ImageFormat::kTiff: return "TIFF";
    case ImageFormat::kBmp: return "BMP";
    case ImageFormat::kPnm: return "PNM";
    case ImageFormat::kWebp: return "WebP";
  }
  return "?";
}

ImageHeader ReadImageHeader(const std::string& bytes, const std::string& path) {
  ImageHeader header;
  if (StartsWith(bytes, "\x89PNG\r\n\x1a\n", 8)) {
    header.format = ImageFormat::kPng;
    ReadPng(bytes, header, path);
  } else if (StartsWith(bytes, "\xFF\xD8\xFF", 3)) {
    header.format = ImageFormat::kJpeg;
    ReadJpeg(bytes, header, path);
  } else if (StartsWith(bytes, "II*\0", 4) || StartsWith(bytes, "MM\0*", 4)) {
    header.format = ImageFormat::kTiff;
    ReadTiff(bytes, header, path);
  } else if (StartsWith(bytes, "BM", 2)) {
    header.format = ImageFormat::kBmp;
    ReadBmp(bytes, header, path);
  } else if (bytes.size() >= 3 && bytes[0] == 'P' && bytes[1] >= '1' && bytes[1] <= '6' &&
             std::isspace(static_cast<unsigned char>(bytes[2]))) {
    header.format = ImageFormat::kPnm;
    ReadPnm(bytes, header, path);
  } else if (bytes.size() >= 32 && StartsWith(bytes, "RIFF", 4) &&
             bytes.compare(8, 4, "WEBP") == 0) {
    header.format = ImageFormat::kWebp;
    ReadWebp(bytes, header, path);
  } else if (bytes.empty()) {
    throw IoError(path, "image file is empty");
  } else {
    throw IoError(path,
                  "not an image in a supported format (PNG, JPEG, TIFF, BMP, PNM, WebP): "
                  "unknown or damaged file signature");
  }
  return header;
}

}  // namespace dispmvs::colmap_io
