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
#include <ostream>
#include <string>

#include "colmap_io/sparse_model.h"

namespace dispmvs::colmap_io {

enum class SparseModelFormat { kBinary, kText };

// Which form `dir` holds: binary if cameras.bin, images.bin and points3D.bin
// all exist, else text if the .txt trio exists; IoError naming dir otherwise.
SparseModelFormat DetectSparseModelFormat(const std::filesystem::path& dir);

SparseModel ReadSparseModel(const std::filesystem::path& dir);  // auto-detects
SparseModel ReadSparseModelBinary(const std::filesystem::path& dir);
SparseModel ReadSparseModelText(const std::filesystem::path& dir);
// Writers validate the model first (ValidateSparseModel) so that they never
// produce files the readers would reject; IoError naming dir otherwise.
void WriteSparseModelBinary(const SparseModel& model, const std::filesystem::path& dir);
void WriteSparseModelText(const SparseModel& model, const std::filesystem::path& dir);

// Single-file readers on streams (used by the directory readers and the
// fuzzers). `source_name` is used in error messages. Each replaces the part
// of `model` its file describes; consistency across files (an image's camera
// exists, tracks point at existing images) is checked by the directory readers.
// Values are stored as read: quaternions are checked to be normalisable but
// not normalised (Image::RotationMatrix normalises), so round trips are exact.
void ReadCamerasBinary(std::istream& in, const std::string& source_name, SparseModel* model);
void ReadImagesBinary(std::istream& in, const std::string& source_name, SparseModel* model);
void ReadPoints3DBinary(std::istream& in, const std::string& source_name, SparseModel* model);
void ReadCamerasText(std::istream& in, const std::string& source_name, SparseModel* model);
void ReadImagesText(std::istream& in, const std::string& source_name, SparseModel* model);
void ReadPoints3DText(std::istream& in, const std::string& source_name, SparseModel* model);

// Single-file writers on streams. They write what they are given (the
// directory writers above validate the whole model first); records are
// written in id order. They throw IoError naming `target_name` for records
// the format cannot hold (unknown model, parameter count mismatch, a NUL in
// a binary image name, and for text an image name that is empty or contains
// whitespace).
void WriteCamerasBinary(const SparseModel& model, std::ostream& out, const std::string& target_name);
void WriteImagesBinary(const SparseModel& model, std::ostream& out, const std::string& target_name);
void WritePoints3DBinary(const SparseModel& model, std::ostream& out, const std::string& target_name);
void WriteCamerasText(const SparseModel& model, std::ostream& out, const std::string& target_name);
void WriteImagesText(const SparseModel& model, std::ostream& out, const std::string& target_name);
void WritePoints3DText(const SparseModel& model, std::ostream& out, const std::string& target_name);

// Consistency of a whole model: every record passes the checks the readers
// apply (known model and matching parameter count, finite values,
// normalisable quaternions), map keys equal the records' ids, images' cameras
// exist, image names are unique, track elements reference existing images
// and in-range points2D that refer back to the point (each at most once), and
// every point2D's point3D id exists and lists that observation in its track.
// The directory readers and writers call it.
// Throws IoError naming `source_name`.
void ValidateSparseModel(const SparseModel& model, const std::string& source_name);

}  // namespace dispmvs::colmap_io
