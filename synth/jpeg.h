#pragma once
// What saving an image as a JPEG file does to it: the lossy steps of baseline
// JPEG (ITU-T T.81, JFIF colour space, 4:2:0 chroma, as libjpeg writes by
// default), applied in floating point. Real photographs reach a user as
// JPEGs, each compressed on its own, so two views of one surface carry
// different 8 x 8 block artefacts and smeared colour edges; the generator's
// images are exact unless a view is given a quality (ViewPhotometry).
//
// Encoder, then decoder:
//  1. R, G, B rounded to 8 bits (a camera writes 8-bit samples).
//  2. JFIF RGB -> YCbCr (full range, chroma centred on 128), rounded.
//  3. Cb and Cr averaged over 2 x 2 pixels (4:2:0), rounded (ties down and
//     up in alternate columns, as libjpeg does, so they do not bias colour).
//  4. Each plane in 8 x 8 blocks, the image first padded to a multiple of 16
//     by repeating its last row and column: minus 128, the orthonormal 2-D
//     DCT-II (T.81 A.3.3), each coefficient divided by its entry of the
//     quantisation table and rounded (half away from zero), multiplied back,
//     inverse DCT, plus 128, rounded and clamped to [0, 255].
//  5. Cb and Cr back to full size by the triangle filter (each output pixel
//     9/16, 3/16, 3/16, 1/16 of its four nearest chroma samples, the edges
//     repeated; libjpeg's default "fancy" upsampling), rounded (ties up in
//     even columns, down in odd ones, as libjpeg).
//  6. YCbCr -> RGB, rounded and clamped to 8 bits.
// The entropy coding between 4 and the decoder is lossless and is skipped.
// Tables: T.81 Annex K.1's luminance and chrominance tables, scaled by the
// IJG quality formula (50 = the tables as printed, 100 = all ones).
// Integer DCTs and fixed-point colour conversion in real codecs differ from
// this by a fraction of a grey level on average (jpeg_test.cc compares with
// OpenCV's libjpeg: the same mean error within 3 %).

#include <torch/torch.h>

#include <array>
#include <string>
#include <utility>

namespace dispmvs::synth {

// The 8 x 8 quantisation table (row = vertical frequency) a JPEG encoder of
// the given quality (1-100) uses for luminance (chroma = false) or Cb / Cr.
std::array<int, 64> JpegQuantisationTable(int quality, bool chroma);

// image [3,H,W] (RGB in [0, 1], values outside are clamped) -> the decoded
// JPEG of the given quality (1-100), [3,H,W] of multiples of 1/255 in the
// image's dtype and device. Throws std::invalid_argument on another shape or
// quality.
torch::Tensor JpegRoundTrip(const torch::Tensor& image, int quality);

// A quality range as the programs take it: "MIN,MAX" or one quality "Q"
// (= "Q,Q"), each in [1, 100], MIN <= MAX; "" or "0" = no compression,
// {0, 0}. Throws std::invalid_argument with the reason otherwise.
std::pair<int, int> ParseJpegQualityRange(const std::string& text);

}  // namespace dispmvs::synth
