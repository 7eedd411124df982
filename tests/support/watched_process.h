#pragma once
// A program started in the background with its output in a file, watched
// for lines it prints (its progress) and killed or waited for: what the
// kill and concurrency tests of dispmvs_colmap need.

#include <sys/types.h>

#include <chrono>
#include <filesystem>
#include <string>
#include <vector>

namespace dispmvs::testing {

class WatchedProcess {
 public:
  using Clock = std::chrono::steady_clock;

  // Starts `program` with `args` (no shell); standard output and error both
  // go to `output`.
  WatchedProcess(const std::string& program, const std::vector<std::string>& args,
                 const std::filesystem::path& output);
  ~WatchedProcess();  // kills and reaps the process if still running
  WatchedProcess(const WatchedProcess&) = delete;
  WatchedProcess& operator=(const WatchedProcess&) = delete;

  // Polls the output (every millisecond) until it contains `text` (true) or
  // the process has exited (false).
  bool WaitForOutput(const std::string& text);
  // SIGKILL, unless the process has already exited. True when the signal
  // killed it, false when it had ended by itself first.
  bool Kill();
  // Waits for the exit; the exit status, or -1 for a death by signal.
  int Wait();

  std::string Output() const;
  Clock::time_point start_time() const { return start_; }

 private:
  // Reaps the process if it has ended (without blocking).
  bool Reap(bool block);

  pid_t pid_ = -1;
  bool reaped_ = false;
  int raw_status_ = 0;
  std::filesystem::path output_;
  Clock::time_point start_;
};

}  // namespace dispmvs::testing
