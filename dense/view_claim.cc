#include "dense/view_claim.h"

#include <fcntl.h>
#include <sys/file.h>
#include <unistd.h>

#include <cerrno>
#include <cstring>
#include <string>
#include <system_error>

#include "colmap_io/error.h"

namespace dispmvs::dense {

namespace fs = std::filesystem;

fs::path ClaimPath(const colmap_io::Workspace& workspace, const std::string& name) {
  return workspace.StereoDir() / "dispmvs_claims" / (name + ".lock");
}

fs::path FusionClaimPath(const colmap_io::Workspace& workspace) {
  return workspace.StereoDir() / "dispmvs_fusion.lock";
}

namespace {

long ReadHolderPid(int fd) {
  char text[32] = {};
  const ssize_t n = ::pread(fd, text, sizeof text - 1, 0);
  if (n <= 0) return 0;
  return std::strtol(text, nullptr, 10);
}

// The pid is only a hint for the message of a process that finds the view
// claimed, so a failed write is not an error.
void WriteOwnPid(int fd) {
  const std::string pid = std::to_string(::getpid()) + "\n";
  if (::ftruncate(fd, 0) == 0) {
    [[maybe_unused]] const ssize_t written = ::pwrite(fd, pid.data(), pid.size(), 0);
  }
}

}  // namespace

std::optional<ViewClaim> ViewClaim::TryClaim(const fs::path& lock_path, long* holder_pid) {
  std::error_code error;
  fs::create_directories(lock_path.parent_path(), error);
  if (error) {
    throw colmap_io::IoError(lock_path.parent_path().string(),
                             "cannot create folder: " + error.message());
  }
  const int fd = ::open(lock_path.c_str(), O_RDWR | O_CREAT | O_CLOEXEC, 0644);
  if (fd < 0) {
    throw colmap_io::IoError(lock_path.string(),
                             std::string("cannot open lock file: ") + std::strerror(errno));
  }
  int status;
  do {
    status = ::flock(fd, LOCK_EX | LOCK_NB);
  } while (status != 0 && errno == EINTR);
  if (status != 0) {
    const int lock_error = errno;
    if (lock_error == EWOULDBLOCK) {
      if (holder_pid != nullptr) *holder_pid = ReadHolderPid(fd);
      ::close(fd);
      return std::nullopt;
    }
    ::close(fd);
    throw colmap_io::IoError(lock_path.string(),
                             std::string("cannot lock: ") + std::strerror(lock_error));
  }
  WriteOwnPid(fd);
  return ViewClaim(fd);
}

ViewClaim::ViewClaim(ViewClaim&& other) noexcept : fd_(other.fd_) { other.fd_ = -1; }

ViewClaim& ViewClaim::operator=(ViewClaim&& other) noexcept {
  if (this != &other) {
    if (fd_ >= 0) ::close(fd_);
    fd_ = other.fd_;
    other.fd_ = -1;
  }
  return *this;
}

// Closing the descriptor releases the flock.
ViewClaim::~ViewClaim() {
  if (fd_ >= 0) ::close(fd_);
}

}  // namespace dispmvs::dense
