#include "dense/colmap_export.h"

#include <fstream>
#include <stdexcept>
#include <string>
#include <system_error>
#include <utility>
#include <vector>

#include "colmap_io/atomic_file.h"
#include "colmap_io/error.h"
#include "colmap_io/stereo_config.h"
#include "dense/workspace_maps.h"

namespace dispmvs::dense {

namespace fs = std::filesystem;
using namespace colmap_io;

namespace {

// Copies `from` to `to` through a temporary name.
void CopyAtomically(const fs::path& from, const fs::path& to) {
  std::ifstream in(from, std::ios::binary);
  if (!in) throw IoError(from.string(), "cannot open for reading");
  WriteFileAtomically(to, [&](std::ostream& out) {
    out << in.rdbuf();
    if (in.bad()) throw IoError(from.string(), "read failed");
  });
}

// A symbolic link at `link` to `target`, unless `link` already is one to it.
void EnsureSymlink(const fs::path& target, const fs::path& link) {
  std::error_code error;
  if (fs::is_symlink(link)) {
    if (fs::equivalent(link, target, error)) return;
    throw IoError(link.string(), "exists and links elsewhere");
  }
  if (fs::exists(link)) throw IoError(link.string(), "exists and is not a link to the workspace");
  fs::create_directory_symlink(target, link, error);
  if (error) throw IoError(link.string(), "cannot create link: " + error.message());
}

}  // namespace

int ExportForColmap(const Workspace& workspace, const DensePlan& plan, const fs::path& export_root,
                    std::ostream& log) {
  const fs::path root = fs::absolute(export_root);
  if (fs::equivalent(root, workspace.root()) ||
      (fs::exists(root) && fs::equivalent(root, fs::absolute(workspace.root())))) {
    throw std::invalid_argument("--export_path must differ from the workspace");
  }
  std::error_code error;
  fs::create_directories(root, error);
  if (error) throw IoError(root.string(), "cannot create folder: " + error.message());
  EnsureSymlink(fs::canonical(workspace.ImagesDir()), root / "images");
  EnsureSymlink(fs::canonical(workspace.SparseDir()), root / "sparse");
  const Workspace exported(root);
  exported.CreateStereoFolders();
  log << "export: copying the maps of " << plan.problems.size() << " reference image(s) to "
      << root.string() << '\n'
      << std::flush;

  std::vector<PatchMatchEntry> entries;
  std::vector<std::string> fusion_list;
  int exported_images = 0;
  for (const StereoProblem& problem : plan.problems) {
    const std::string& name = plan.ImageOf(problem.reference_image_id).name;
    bool any = false;
    for (const auto& [ours, theirs] : {std::pair<const char*, const char*>{kPhotometricType, "photometric"},
                                       {kGeometricType, "geometric"}}) {
      const MapPaths from = PathsOf(workspace, name, ours);
      if (!fs::is_regular_file(from.depth) || !fs::is_regular_file(from.normal)) continue;
      CopyAtomically(from.normal, exported.NormalMapPath(name, theirs));
      CopyAtomically(from.depth, exported.DepthMapPath(name, theirs));
      any = true;
    }
    if (!any) continue;
    ++exported_images;
    fusion_list.push_back(name);
    std::vector<std::string> sources;
    for (image_t source : problem.source_image_ids) sources.push_back(plan.ImageOf(source).name);
    if (sources.empty()) continue;
    PatchMatchEntry entry;
    entry.reference = name;
    entry.sources = SourceSpec::Explicit(std::move(sources));
    entries.push_back(std::move(entry));
  }
  WritePatchMatchConfig(entries, exported.PatchMatchConfigPath());
  WriteFusionConfig(fusion_list, exported.FusionConfigPath());
  log << "export: " << exported_images << " image(s) under COLMAP's names in " << root.string()
      << "\n  fuse with: colmap stereo_fusion --workspace_path " << root.string()
      << " --input_type geometric --output_path " << (root / "fused.ply").string() << '\n';
  return exported_images;
}

}  // namespace dispmvs::dense
