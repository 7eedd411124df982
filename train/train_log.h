#pragma once
// The training log: every line to the console stream and to train.log in the
// checkpoint directory (trainer.h). A file of its own because the loop
// (trainer.cc), the restoring of a run (checkpoint.h) and the training
// samples (training_samples.h) all write to it.
//
// Internal to train/: the public interface is trainer.h.

#include <filesystem>
#include <fstream>
#include <ostream>
#include <stdexcept>
#include <string>

namespace dispmvs::train::internal {

// Writes every line to the console stream and the log file.
class Logger {
 public:
  Logger(std::ostream& console, const std::filesystem::path& file)
      : console_(console), file_(file, std::ios::app) {
    if (!file_) throw std::runtime_error("cannot open log file " + file.string());
  }
  void Line(const std::string& line) {
    console_ << line << std::endl;
    file_ << line << std::endl;
  }

 private:
  std::ostream& console_;
  std::ofstream file_;
};

}  // namespace dispmvs::train::internal
