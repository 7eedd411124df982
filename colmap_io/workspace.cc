#include "colmap_io/workspace.h"

#include <system_error>

#include "colmap_io/error.h"
#include "colmap_io/sparse_model_io.h"

namespace dispmvs::colmap_io {
namespace {

void RequireDirectory(const std::filesystem::path& dir, const std::string& what) {
  std::error_code ec;
  const std::filesystem::file_status status = std::filesystem::status(dir, ec);
  if (!std::filesystem::exists(status)) {
    throw IoError(dir.string(), what + " does not exist");
  }
  if (!std::filesystem::is_directory(status)) {
    throw IoError(dir.string(), what + " is not a directory");
  }
}

// Why `name` cannot be used as a path relative to a workspace folder, or "".
std::string UnsafeImageNameReason(const std::string& name) {
  if (name.empty()) return "empty image name";
  if (name.find('\0') != std::string::npos) return "image name contains a NUL character";
  if (name.find('\\') != std::string::npos) return "image name contains a backslash";
  const std::filesystem::path path(name);
  if (path.is_absolute() || path.has_root_path()) return "image name is an absolute path";
  for (const auto& component : path) {
    if (component == "." || component == "..") {
      return "image name has a \".\" or \"..\" component";
    }
  }
  if (name.back() == '/') return "image name ends with '/'";
  return "";
}

}  // namespace

Workspace::Workspace(const std::filesystem::path& root) : root_(root) {
  RequireDirectory(root_, "workspace folder");
  RequireDirectory(ImagesDir(), "images folder of the workspace");
  RequireDirectory(SparseDir(), "sparse folder of the workspace");
}

SparseModel Workspace::ReadModel() const { return ReadSparseModel(SparseDir()); }

std::filesystem::path Workspace::ImagePath(const std::string& image_name) const {
  const std::string reason = UnsafeImageNameReason(image_name);
  if (!reason.empty()) throw IoError(root_.string(), reason + ": \"" + image_name + "\"");
  return ImagesDir() / image_name;
}

std::filesystem::path Workspace::MapPath(const std::filesystem::path& folder,
                                         const std::string& image_name,
                                         const std::string& type) const {
  const std::string reason = UnsafeImageNameReason(image_name);
  if (!reason.empty()) throw IoError(root_.string(), reason + ": \"" + image_name + "\"");
  if (type.empty() || type.find_first_of("/\\") != std::string::npos ||
      type.find('\0') != std::string::npos) {
    throw IoError(root_.string(), "invalid map type \"" + type + "\"");
  }
  // Appended as a string: COLMAP's naming is NAME + "." + TYPE + ".bin", the
  // image's own extension included (image1.jpg.geometric.bin).
  return folder / (image_name + "." + type + ".bin");
}

std::filesystem::path Workspace::DepthMapPath(const std::string& image_name,
                                              const std::string& type) const {
  return MapPath(DepthMapsDir(), image_name, type);
}

std::filesystem::path Workspace::NormalMapPath(const std::string& image_name,
                                               const std::string& type) const {
  return MapPath(NormalMapsDir(), image_name, type);
}

std::filesystem::path Workspace::ConfidenceMapPath(const std::string& image_name,
                                                   const std::string& type) const {
  return MapPath(ConfidenceMapsDir(), image_name, type);
}

std::filesystem::path Workspace::ConsistencyGraphPath(const std::string& image_name,
                                                      const std::string& type) const {
  return MapPath(ConsistencyGraphsDir(), image_name, type);
}

void Workspace::CreateStereoFolders() const {
  for (const std::filesystem::path& dir :
       {DepthMapsDir(), NormalMapsDir(), ConfidenceMapsDir(), ConsistencyGraphsDir()}) {
    std::error_code ec;
    std::filesystem::create_directories(dir, ec);
    if (ec) throw IoError(dir.string(), "cannot create directory: " + ec.message());
    // create_directories reports no error when `dir` exists as a file.
    RequireDirectory(dir, "stereo folder");
  }
}

}  // namespace dispmvs::colmap_io
