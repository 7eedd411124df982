#pragma once
// The --device values of the programs ("cpu", "cuda", "cuda:<index>"), parsed
// in one place so that every program accepts and rejects the same text.

#include <string>

#include <torch/torch.h>

namespace dispmvs::model {

// Parses "cpu", "cuda" or "cuda:<index>" (index >= 0). Anything else, other
// device types included, throws std::invalid_argument
// "<what> must be cpu, cuda or cuda:<index>, got '<text>'". Checks the text
// only: option checks use it on machines without the device.
torch::Device ParseDevice(const std::string& text, const std::string& what = "device");

// ParseDevice, and then, for a CUDA device, that this LibTorch has CUDA and
// the device is visible: throws std::invalid_argument naming `what` and
// `text` otherwise. For the place that is about to use the device.
torch::Device ParseUsableDevice(const std::string& text, const std::string& what = "device");

}  // namespace dispmvs::model
