#pragma once
// Where dispmvs_colmap finds the shipped weights when --model_path is not
// given, so that an installed or moved program keeps its model:
//   1. beside the program as installed: BIN/../share/dispmvs/models/FILE
//      (`cmake --install build --prefix P` puts the program in P/bin and the
//      weights in P/share/dispmvs/models);
//   2. the source tree the program was built from: SOURCE/models/FILE
//      (running it from the build folder).

#include <filesystem>
#include <string>
#include <vector>

namespace dispmvs::cli {

inline constexpr const char* kShippedModelFile = "dispmvs_small.safetensors";

// The places above, in that order, for the running program (found through
// /proc/self/exe) and the source folder compiled in.
std::vector<std::filesystem::path> ShippedModelCandidates(const std::string& file = kShippedModelFile);

// The first candidate that exists; throws std::runtime_error naming all of
// them when none does.
std::filesystem::path FindShippedModel(const std::string& file = kShippedModelFile);

}  // namespace dispmvs::cli
