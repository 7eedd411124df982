#pragma once
// Reading and writing COLMAP sparse models (cameras, images, points3D) in
// COLMAP's binary (.bin) and text (.txt) forms. Readers validate everything
// they read and throw IoError naming the file on truncated, corrupted or
// inconsistent input; counts are checked against the bytes actually left in
// the file before anything is allocated. Writers are atomic (atomic_file.h).
// Extra files newer COLMAP releases put beside the trio (rigs, frames, ...)
// are ignored.

#include <filesystem>
#include <istream>

#include "colmap_io/sparse_model.h"

namespace dispmvs::colmap_io {

enum class SparseModelFormat { kBinary, kText };

// Which form `dir` holds: binary if cameras.bin, images.bin and points3D.bin
// all exist, else text if the .txt trio exists; IoError naming dir otherwise.
SparseModelFormat DetectSparseModelFormat(const std::filesystem::path& dir);

SparseModel ReadSparseModel(const std::filesystem::path& dir);  // auto-detects
SparseModel ReadSparseModelBinary(const std::filesystem::path& dir);
SparseModel ReadSparseModelText(const std::filesystem::path& dir);
void WriteSparseModelBinary(const SparseModel& model, const std::filesystem::path& dir);
void WriteSparseModelText(const SparseModel& model, const std::filesystem::path& dir);

// Single-file readers on streams (used by the directory readers and the
// fuzzers). `source_name` is used in error messages. They fill the part of
// `model` the file describes; consistency across files (an image's camera
// exists, tracks point at existing images) is checked by the directory readers.
void ReadCamerasBinary(std::istream& in, const std::string& source_name, SparseModel* model);
void ReadImagesBinary(std::istream& in, const std::string& source_name, SparseModel* model);
void ReadPoints3DBinary(std::istream& in, const std::string& source_name, SparseModel* model);
void ReadCamerasText(std::istream& in, const std::string& source_name, SparseModel* model);
void ReadImagesText(std::istream& in, const std::string& source_name, SparseModel* model);
void ReadPoints3DText(std::istream& in, const std::string& source_name, SparseModel* model);

// Cross-file consistency: images' cameras exist, track elements reference
// existing images and in-range points2D, points2D's point3D ids exist.
// Throws IoError naming `source_name`.
void ValidateSparseModel(const SparseModel& model, const std::string& source_name);

}  // namespace dispmvs::colmap_io
