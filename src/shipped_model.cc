#include "src/shipped_model.h"

#include <stdexcept>
#include <system_error>

namespace dispmvs::cli {

namespace fs = std::filesystem;

#ifndef DISPMVS_SOURCE_MODELS_DIR
#define DISPMVS_SOURCE_MODELS_DIR "models"
#endif

std::vector<fs::path> ShippedModelCandidates(const std::string& file) {
  std::vector<fs::path> candidates;
  std::error_code error;
  const fs::path program = fs::read_symlink("/proc/self/exe", error);
  if (!error) {
    candidates.push_back(
        (program.parent_path().parent_path() / "share" / "dispmvs" / "models" / file)
            .lexically_normal());
  }
  candidates.push_back(fs::path(DISPMVS_SOURCE_MODELS_DIR) / file);
  return candidates;
}

fs::path FindShippedModel(const std::string& file) {
  const std::vector<fs::path> candidates = ShippedModelCandidates(file);
  std::string looked;
  for (const fs::path& candidate : candidates) {
    if (fs::is_regular_file(candidate)) return candidate;
    looked += (looked.empty() ? "" : ", ") + candidate.string();
  }
  throw std::runtime_error("the shipped weights " + file + " are in none of " + looked +
                           " (install with `cmake --install`, or pass --model_path)");
}

}  // namespace dispmvs::cli
