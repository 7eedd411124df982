#pragma once
// Claims on a workspace's outputs: per view for the photometric pass, and
// one for the geometric pass and fusion together (FusionClaimPath).
// Per-view claims of the photometric pass, so that processes sharing a
// workspace never compute the same view at once: shards started together
// (--shard K/N), or the same shard started twice by mistake. A claim is an
// exclusive flock(2) on WS/stereo/dispmvs_claims/NAME.lock, taken before the
// view is computed and released when its maps are written. The kernel drops
// the lock when its process dies, however it dies, so a killed run never
// leaves a view claimed (the empty .lock files stay; deleting the folder is
// harmless).

#include <filesystem>
#include <optional>
#include <string>

#include "colmap_io/workspace.h"

namespace dispmvs::dense {

// WS/stereo/dispmvs_claims/NAME.lock (NAME may hold folders, as image names do).
std::filesystem::path ClaimPath(const colmap_io::Workspace& workspace, const std::string& name);

// WS/stereo/dispmvs_fusion.lock: the claim of the geometric pass and fusion,
// which write the workspace's shared outputs (every geometric map, one
// fused.ply), so that two such runs never interleave their writes and the
// run holding it knows that any temporaries beside those outputs are a
// killed run's. Outside dispmvs_claims/, so that no image name can collide
// with it.
std::filesystem::path FusionClaimPath(const colmap_io::Workspace& workspace);

class ViewClaim {
 public:
  // The claim on `lock_path` (its folders created as needed), or nullopt when
  // another process holds it; `holder_pid`, if given, then receives the pid
  // that process wrote into the file (0 if unknown). Throws IoError when the
  // lock file cannot be created or locked for another reason.
  static std::optional<ViewClaim> TryClaim(const std::filesystem::path& lock_path,
                                           long* holder_pid = nullptr);

  ViewClaim(ViewClaim&& other) noexcept;
  ViewClaim& operator=(ViewClaim&& other) noexcept;
  ViewClaim(const ViewClaim&) = delete;
  ViewClaim& operator=(const ViewClaim&) = delete;
  ~ViewClaim();  // releases the claim

 private:
  explicit ViewClaim(int fd) : fd_(fd) {}
  int fd_ = -1;
};

}  // namespace dispmvs::dense
