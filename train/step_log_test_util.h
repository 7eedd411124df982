#pragma once
// For the trainer's tests: the numbers of a step line of a training log
// ("step 1/4  loss 0.12345  depth 0.12345  match ...").

#include <cmath>
#include <regex>
#include <string>

#include <gtest/gtest.h>

namespace dispmvs::train {

struct StepLosses {
  double loss = 0;   // what was minimised
  double depth = 0;  // the sequence loss
};

// The losses of step `step` (1-based, as logged); a test failure and NaNs
// when the log has no such line.
inline StepLosses LoggedStepLosses(const std::string& log, int step = 1) {
  const std::string number = R"(([-+0-9.eE]+|nan|inf|-nan))";
  const std::regex pattern("step " + std::to_string(step) + R"(/\d+  loss )" + number + "  depth " + number);
  std::smatch match;
  if (!std::regex_search(log, match, pattern)) {
    ADD_FAILURE() << "no step " << step << " in the log:\n" << log;
    return {std::nan(""), std::nan("")};
  }
  return {std::stod(match[1].str()), std::stod(match[2].str())};
}

}  // namespace dispmvs::train
