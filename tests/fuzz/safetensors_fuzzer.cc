// libFuzzer target for the safetensors loader (model weights): the input is
// the whole file, loaded with LoadSafetensors and ReadModelConfig.
//
// Only the project's sources (safetensors, its JSON parser, the model config)
// are instrumented; LibTorch is linked as Debian ships it (see
// tests/fuzz/CMakeLists.txt). AddressSanitizer's allocator still serves
// LibTorch's allocations, so a tensor the loader sizes wrongly is caught.
//
// Properties checked, besides "no crash, no sanitizer report, no huge
// allocation" (run with -rss_limit_mb):
//  * both functions throw nothing but std::runtime_error (the loader's
//    documented error; anything else, c10::Error included, is a crash);
//  * what LoadSafetensors accepts, SaveSafetensors writes (or refuses with
//    std::invalid_argument for an empty tensor name, as documented); loading
//    that file gives the same metadata and tensors (names, dtypes, shapes,
//    bytes), and saving them again gives the same bytes;
//  * a ModelConfig that ReadModelConfig accepts passes Check() and survives
//    ToMetadata/FromMetadata unchanged.

#include <torch/torch.h>

#include <cstddef>
#include <cstdint>
#include <cstdlib>
#include <cstring>
#include <stdexcept>
#include <string>

#include "model/config.h"
#include "model/safetensors.h"
#include "tests/fuzz/fuzz_support.h"

namespace {

using dispmvs::model::ModelConfig;
using dispmvs::model::SafetensorsFile;

bool SameTensors(const SafetensorsFile& a, const SafetensorsFile& b) {
  if (a.metadata != b.metadata || a.tensors.size() != b.tensors.size()) return false;
  for (std::size_t i = 0; i < a.tensors.size(); ++i) {
    const torch::Tensor& x = a.tensors[i].second;
    const torch::Tensor& y = b.tensors[i].second;
    if (a.tensors[i].first != b.tensors[i].first || x.scalar_type() != y.scalar_type() ||
        x.sizes() != y.sizes() || !x.is_contiguous() || !y.is_contiguous()) {
      return false;
    }
    const std::size_t bytes = static_cast<std::size_t>(x.numel()) * x.element_size();
    if (bytes > 0 && std::memcmp(x.data_ptr(), y.data_ptr(), bytes) != 0) return false;
  }
  return true;
}

bool HasEmptyName(const SafetensorsFile& file) {
  for (const auto& [name, tensor] : file.tensors) {
    if (name.empty()) return true;
  }
  return false;
}

// The loaded file, or false when the loader rejected it.
bool Load(const std::string& path, SafetensorsFile* file) {
  try {
    *file = dispmvs::model::LoadSafetensors(path);
    return true;
  } catch (const std::runtime_error&) {
    return false;
  }
}

void CheckTensorRoundTrip(const std::string& input_path) {
  SafetensorsFile file;
  if (!Load(input_path, &file)) return;
  const std::string output = dispmvs::fuzz::ScratchPath("output.safetensors").string();
  try {
    dispmvs::model::SaveSafetensors(output, file.tensors, file.metadata);
  } catch (const std::invalid_argument&) {
    if (HasEmptyName(file)) return;
    std::abort();
  }
  const std::string first = dispmvs::fuzz::ReadBytes(output);
  SafetensorsFile again;
  if (!Load(output, &again) || !SameTensors(file, again)) std::abort();
  dispmvs::model::SaveSafetensors(output, again.tensors, again.metadata);
  if (dispmvs::fuzz::ReadBytes(output) != first) std::abort();
}

void CheckModelConfig(const std::string& input_path) {
  ModelConfig config;
  try {
    config = dispmvs::model::ReadModelConfig(input_path);
  } catch (const std::runtime_error&) {
    return;
  }
  try {
    config.Check();
    const auto metadata = config.ToMetadata();
    if (ModelConfig::FromMetadata(metadata).ToMetadata() != metadata) std::abort();
  } catch (const std::invalid_argument&) {
    std::abort();  // an accepted configuration must be valid
  }
}

}  // namespace

extern "C" int LLVMFuzzerInitialize(int*, char***) {
  // One thread: the fuzzer measures one input at a time, and LibTorch's pools
  // would only add noise.
  torch::set_num_threads(1);
  return 0;
}

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  const auto input_path = dispmvs::fuzz::ScratchPath("input.safetensors");
  dispmvs::fuzz::WriteBytes(input_path, data, size);
  CheckTensorRoundTrip(input_path.string());
  CheckModelConfig(input_path.string());
  return 0;
}
