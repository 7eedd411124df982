#pragma once
// What a run of dispmvs_colmap left in a folder, for tests that compare runs
// byte for byte or check that nothing was written.

#include <filesystem>
#include <map>
#include <string>

namespace dispmvs::testing {

// Every regular file under `root`, relative path -> bytes, except temporary
// files (NAME.tmp-*, which a killed run may leave), the claim locks (they
// hold pids: per view under dispmvs_claims/, and dispmvs_fusion.lock) and
// the per-view records under dispmvs_records/ (they hold times). Links are
// not followed.
std::map<std::string, std::string> FinalOutputs(const std::filesystem::path& root);

}  // namespace dispmvs::testing
