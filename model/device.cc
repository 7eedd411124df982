#include "model/device.h"

#include <optional>
#include <stdexcept>

#include <torch/cuda.h>

namespace dispmvs::model {

torch::Device ParseDevice(const std::string& text, const std::string& what) {
  std::optional<torch::Device> device;
  try {
    device.emplace(text);
  } catch (const std::exception&) {
    // LibTorch's own message lists every device type it knows; ours names
    // the ones the programs support.
  }
  if (!device || (!device->is_cpu() && !device->is_cuda())) {
    throw std::invalid_argument(what + " must be cpu, cuda or cuda:<index>, got '" + text + "'");
  }
  return *device;
}

torch::Device ParseUsableDevice(const std::string& text, const std::string& what) {
  const torch::Device device = ParseDevice(text, what);
  if (!device.is_cuda()) return device;
  if (!torch::cuda::is_available()) {
    throw std::invalid_argument(what + " " + text +
                                ": CUDA is not available (this LibTorch has no CUDA, or no GPU is visible)");
  }
  const auto count = static_cast<int64_t>(torch::cuda::device_count());
  if (device.has_index() && device.index() >= count) {
    throw std::invalid_argument(what + " " + text + ": only " + std::to_string(count) + " GPU(s) visible");
  }
  return device;
}

}  // namespace dispmvs::model
