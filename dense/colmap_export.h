#pragma once
// The export step of dispmvs_colmap: our maps under COLMAP's PatchMatch names
// in a sibling workspace, for Debian's `colmap stereo_fusion`, which only
// accepts --input_type photometric|geometric.

#include <filesystem>
#include <ostream>

#include "colmap_io/workspace.h"
#include "dense/plan.h"

namespace dispmvs::dense {

// Writes a workspace at `export_root` whose images/ and sparse/ are symbolic
// links to ours and whose stereo/ holds our photometric and geometric maps
// under COLMAP's names (NAME.photometric.bin, NAME.geometric.bin; depth and
// normal, as PatchMatch writes) plus a patch-match.cfg with each reference's
// sources and a fusion.cfg of the exported images. Safe to repeat: links
// already in place are kept, files are replaced through temporary names.
// Throws std::invalid_argument when `export_root` is the workspace, IoError
// when a link exists and points elsewhere or a file cannot be written.
// Returns the number of images exported.
int ExportForColmap(const colmap_io::Workspace& workspace, const DensePlan& plan,
                    const std::filesystem::path& export_root, std::ostream& log);

}  // namespace dispmvs::dense
