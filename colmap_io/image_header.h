#pragma once
// What an image file is, read from its bytes before any decoder sees them.
//
// Why. OpenCV's cv::imread / cv::imdecode hand a file to the first of all its
// decoders whose signature check accepts it: besides PNG and JPEG, Debian's
// OpenCV carries DICOM (GDCM), JPEG 2000, OpenEXR, GDAL and others. A damaged
// file that looks to one of those like its own (GDCM only asks for "DICM" at
// byte 128) reaches code that can abort the whole process (a failed assert in
// GDCM), and a header can claim sizes that make a decoder allocate a
// gigabyte before anything checks them. So the project decides the format
// itself and reads the size from the header:
//
//  * Only the formats COLMAP workspaces hold in practice are accepted: PNG,
//    JPEG, TIFF, BMP, PNM (PBM/PGM/PPM) and WebP. Each is recognised with a
//    check at least as strict as the one OpenCV's own decoder for that format
//    makes (PNM: 'P', '1'-'6', white space; WebP: libwebp's WebPGetFeatures on
//    the first 32 bytes, exactly OpenCV's check), and those decoders come
//    before every other in OpenCV's list, so a file accepted here always goes
//    to its own format's decoder and never reaches the others.
//  * The width and height come from the header (PNG's IHDR, JPEG's frame
//    header, BMP's info header, the PNM header, libwebp, libtiff), so that a
//    caller can refuse an image of the wrong size before its pixels are
//    allocated. For TIFF the strip or tile buffer OpenCV's decoder allocates
//    is computed too (a header can make it a gigabyte for a tiny image).
//  * A JPEG must reach its end-of-image marker: libjpeg fills a truncated
//    JPEG with grey and reports success, which would put a grey band into a
//    depth map without a word.

#include <cstdint>
#include <string>

namespace dispmvs::colmap_io {

enum class ImageFormat { kPng, kJpeg, kTiff, kBmp, kPnm, kWebp };

// "PNG", "JPEG", ... for messages.
const char* ImageFormatName(ImageFormat format);

struct ImageHeader {
  ImageFormat format = ImageFormat::kPng;
  int width = 0;
  int height = 0;
  // Bytes the decoder allocates for its own work beside the decoded image:
  // TIFF's strip or tile buffer, as OpenCV 4.6's TIFF decoder sizes it;
  // 0 for the other formats, whose decoders work row by row or within the
  // image's own size.
  uint64_t decoder_buffer_bytes = 0;
};

// Reads the format and the size of the image file whose bytes are `bytes`.
// Throws IoError naming `path` with the reason when the bytes are not one of
// the accepted formats, the header is malformed or truncated, a size is 0 or
// above 2^24 per side, or a JPEG ends before its end-of-image marker. Reads no
// pixel data and allocates nothing proportional to the sizes it reads.
ImageHeader ReadImageHeader(const std::string& bytes, const std::string& path);

}  // namespace dispmvs::colmap_io
