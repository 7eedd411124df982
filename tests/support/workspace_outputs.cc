#include "tests/support/workspace_outputs.h"

#include "tests/support/temp_dir.h"

namespace dispmvs::testing {

namespace fs = std::filesystem;

std::map<std::string, std::string> FinalOutputs(const fs::path& root) {
  std::map<std::string, std::string> files;
  for (const auto& entry : fs::recursive_directory_iterator(root)) {
    if (entry.is_symlink() || !entry.is_regular_file()) continue;
    if (entry.path().filename().string().find(".tmp-") != std::string::npos) continue;
    const std::string relative = fs::relative(entry.path(), root).string();
    if (relative.find("dispmvs_claims") != std::string::npos ||
        relative.find("dispmvs_fusion.lock") != std::string::npos ||
        relative.find("dispmvs_records") != std::string::npos) {
      continue;
    }
    files[relative] = ReadFileBytes(entry.path());
  }
  return files;
}

}  // namespace dispmvs::testing
