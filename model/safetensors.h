#pragma once
// Reading and writing the safetensors format (https://huggingface.co/docs/safetensors):
//   8 bytes  little-endian u64 N = header length
//   N bytes  JSON header {"__metadata__": {str: str},
//                         name: {"dtype": "F32", "shape": [..], "data_offsets": [b, e]}, ...}
//            padded with spaces to a multiple of 8
//   rest     raw little-endian row-major tensor data; offsets are relative to it.
// The loader trusts nothing in the file: every size and offset is checked
// against the file size before anything is allocated, and every failure is a
// std::runtime_error naming the path.

#include <torch/torch.h>

#include <map>
#include <string>
#include <utility>
#include <vector>

#include "model/config.h"

namespace dispmvs::model {

using NamedTensors = std::vector<std::pair<std::string, torch::Tensor>>;

// Writes `tensors` (any device, any layout; copied to contiguous CPU) in the
// given order. Writes a temporary file beside `path` and renames it over
// `path`, so a reader never sees half-written weights.
// Throws std::invalid_argument on duplicate/empty names or unsupported dtypes,
// std::runtime_error on I/O failure.
void SaveSafetensors(const std::string& path, const NamedTensors& tensors,
                     const std::map<std::string, std::string>& metadata);

struct SafetensorsFile {
  std::map<std::string, std::string> metadata;
  NamedTensors tensors;  // CPU tensors, in data-offset order
};

SafetensorsFile LoadSafetensors(const std::string& path);

// All named_parameters() followed by all named_buffers() of `module`, sorted
// by name within each group (a stable order), with config.ToMetadata() as
// metadata.
void SaveModuleWeights(const torch::nn::Module& module, const ModelConfig& config,
                       const std::string& path);

// A file's metadata, from its header alone (no tensor data is read; the
// header is validated as LoadSafetensors validates it).
std::map<std::string, std::string> ReadSafetensorsMetadata(const std::string& path);

// The ModelConfig stored in a weights file's metadata (validated by Check()).
ModelConfig ReadModelConfig(const std::string& path);

// Copies the file's tensors into `module`'s parameters and buffers (on their
// current device). Fails, before changing anything, with a message naming the
// first mismatch in name order: a missing tensor, an unexpected tensor, a
// wrong shape or a wrong dtype.
void LoadModuleWeights(torch::nn::Module& module, const std::string& path);

}  // namespace dispmvs::model
