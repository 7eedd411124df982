#include "tests/support/watched_process.h"

#include <fcntl.h>
#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>

#include <cerrno>
#include <stdexcept>
#include <thread>

#include "tests/support/temp_dir.h"

namespace dispmvs::testing {

WatchedProcess::WatchedProcess(const std::string& program, const std::vector<std::string>& args,
                               const std::filesystem::path& output)
    : output_(output) {
  // Everything the child needs is prepared before fork().
  std::vector<std::string> argv_strings = {program};
  argv_strings.insert(argv_strings.end(), args.begin(), args.end());
  std::vector<char*> argv;
  for (std::string& arg : argv_strings) argv.push_back(arg.data());
  argv.push_back(nullptr);
  const int fd = ::open(output.c_str(), O_WRONLY | O_CREAT | O_TRUNC | O_CLOEXEC, 0644);
  if (fd < 0) throw std::runtime_error("cannot create " + output.string());
  start_ = Clock::now();
  pid_ = ::fork();
  if (pid_ < 0) {
    ::close(fd);
    throw std::runtime_error("fork failed");
  }
  if (pid_ == 0) {
    ::dup2(fd, STDOUT_FILENO);
    ::dup2(fd, STDERR_FILENO);
    ::execv(program.c_str(), argv.data());
    ::_exit(127);
  }
  ::close(fd);
}

WatchedProcess::~WatchedProcess() {
  if (!reaped_) {
    ::kill(pid_, SIGKILL);
    Reap(true);
  }
}

bool WatchedProcess::Reap(bool block) {
  if (reaped_) return true;
  pid_t result;
  do {
    result = ::waitpid(pid_, &raw_status_, block ? 0 : WNOHANG);
  } while (result < 0 && errno == EINTR);
  if (result == pid_) reaped_ = true;
  return reaped_;
}

bool WatchedProcess::WaitForOutput(const std::string& text) {
  for (;;) {
    // Read the output before checking for the exit, so that text printed
    // just before exiting is still seen.
    const bool ended = Reap(false);
    if (Output().find(text) != std::string::npos) return true;
    if (ended) return false;
    std::this_thread::sleep_for(std::chrono::milliseconds(1));
  }
}

bool WatchedProcess::Kill() {
  if (Reap(false)) return false;
  ::kill(pid_, SIGKILL);
  Reap(true);
  return WIFSIGNALED(raw_status_) && WTERMSIG(raw_status_) == SIGKILL;
}

int WatchedProcess::Wait() {
  Reap(true);
  return WIFEXITED(raw_status_) ? WEXITSTATUS(raw_status_) : -1;
}

std::string WatchedProcess::Output() const { return ReadFileBytes(output_); }

}  // namespace dispmvs::testing
