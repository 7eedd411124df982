#include "train/checkpoint.h"

#include <algorithm>
#include <cstdio>
#include <fstream>
#include <memory>
#include <optional>
#include <sstream>
#include <stdexcept>
#include <type_traits>
#include <utility>
#include <vector>

#include "model/safetensors.h"

namespace dispmvs::train::internal {
namespace {

namespace fs = std::filesystem;
using model::DispMvsNet;
using model::ModelConfig;

// "<prefix>-<step in nine digits>": steps are capped at 999'999'999 by Check().
std::string StepName(const char* prefix, int64_t step) {
  char buffer[48];
  std::snprintf(buffer, sizeof buffer, "%s-%09lld", prefix, static_cast<long long>(step));
  return buffer;
}
fs::path WeightsPath(const fs::path& dir, int64_t step) {
  return dir / (StepName("checkpoint", step) + ".safetensors");
}
fs::path OptimPath(const fs::path& dir, int64_t step) {
  return dir / (StepName("checkpoint", step) + ".optim.safetensors");
}
fs::path KeptWeightsPath(const fs::path& dir, int64_t step) {
  return dir / (StepName("weights", step) + ".safetensors");
}

// Steps of the complete checkpoints in `dir` (both files present), ascending.
std::vector<int64_t> CompleteCheckpoints(const fs::path& dir) {
  std::vector<int64_t> steps;
  const std::string prefix = "checkpoint-", suffix = ".safetensors";
  for (const auto& entry : fs::directory_iterator(dir)) {
    const std::string name = entry.path().filename().string();
    if (name.size() != prefix.size() + 9 + suffix.size() || name.rfind(prefix, 0) != 0 ||
        name.compare(name.size() - suffix.size(), suffix.size(), suffix) != 0) {
      continue;
    }
    const std::string digits = name.substr(prefix.size(), 9);
    if (!std::all_of(digits.begin(), digits.end(), [](char c) { return c >= '0' && c <= '9'; })) continue;
    const int64_t step = std::stoll(digits);
    if (fs::exists(OptimPath(dir, step))) steps.push_back(step);
  }
  std::sort(steps.begin(), steps.end());
  return steps;
}

// A folder (data set, photos) as a setting: its absolute path, so that a
// resumed run may name it relative to another working directory.
std::string AbsolutePathSetting(const std::string& root) {
  if (root.empty()) return "";
  std::error_code error;
  const fs::path canonical = fs::weakly_canonical(fs::absolute(root), error);
  return (error ? fs::absolute(root).lexically_normal() : canonical).string();
}

// 64-bit FNV-1a: a stable fingerprint (not a security hash) of what a
// setting names.
struct Fnv1a64 {
  uint64_t value = 14695981039346656037ull;
  void Add(const char* data, size_t size) {
    for (size_t i = 0; i < size; ++i) value = (value ^ static_cast<unsigned char>(data[i])) * 1099511628211ull;
  }
  void Add(const std::string& text) { Add(text.data(), text.size()); }
};

// A weights file as a run setting: its size and a 64-bit FNV-1a hash of its
// bytes, so that the same weights under another path resume, and other
// weights under the same path do not.
std::string InitWeightsSetting(const std::string& path) {
  if (path.empty()) return "";
  std::ifstream file(path, std::ios::binary);
  if (!file) throw std::invalid_argument("init_weights: cannot read " + path);
  Fnv1a64 hash;
  uint64_t size = 0;
  char buffer[1 << 16];
  while (file.read(buffer, sizeof buffer) || file.gcount() > 0) {
    hash.Add(buffer, static_cast<size_t>(file.gcount()));
    size += static_cast<uint64_t>(file.gcount());
  }
  char text[64];
  std::snprintf(text, sizeof text, "%llu bytes, fnv1a64 %016llx",
                static_cast<unsigned long long>(size), static_cast<unsigned long long>(hash.value));
  return text;
}

// The photo folder as a run setting: its absolute path, and a hash of the
// names and sizes of its files (sorted), so that a changed folder is noticed.
// "1,2,5" (empty: every step used all sources).
std::string JoinCounts(const std::vector<int64_t>& counts) {
  std::string text;
  for (const int64_t count : counts) text += (text.empty() ? "" : ",") + std::to_string(count);
  return text;
}

std::string TextureDirSetting(const std::string& dir) {
  if (dir.empty()) return "";
  std::vector<std::pair<std::string, uintmax_t>> files;
  for (const fs::directory_entry& entry : fs::directory_iterator(dir)) {
    if (entry.is_regular_file()) files.emplace_back(entry.path().filename().string(), entry.file_size());
  }
  std::sort(files.begin(), files.end());
  Fnv1a64 hash;
  for (const auto& [name, size] : files) hash.Add(name + "\n" + std::to_string(size) + "\n");
  char text[40];
  std::snprintf(text, sizeof text, " (%zu files, fnv1a64 %016llx)", files.size(),
                static_cast<unsigned long long>(hash.value));
  return AbsolutePathSetting(dir) + text;
}

// Settings added after checkpoints were first written, with the value that a
// checkpoint without one was trained with, so that such checkpoints resume.
std::optional<std::string> SettingBeforeItExisted(const std::string& key) {
  if (key == "mvsnet_root") return "";
  if (key == "mvsnet_fraction") return "1";
  if (key == "train_widening_max") return "1";
  if (key == "init_weights") return "";
  if (key == "texture_dir" || key == "photo_probability") return "";
  // Model v2's settings: before them, runs trained the paper's design
  // (whose configs ignore the matching loss) on a new scene every step.
  if (key == "matching_loss_weight") return std::to_string(0.5);
  if (key == "matching_warmup_steps") return "0";
  if (key == "depth_loss") return "inverse";
  if (key == "flow_loss_weight") return std::to_string(0.0);
  if (key == "scene_reuse") return "1";
  if (key == "train_coarse_iterations") return "0";
  if (key == "difficulty_start") return std::to_string(1.0);
  if (key == "difficulty_ramp_steps") return "0";
  if (key == "lr_warmup_steps") return "0";
  if (key == "source_counts") return "";
  if (key == "photometry") return "default";
  if (key == "supersampling") return "1";
  if (key == "specular_probability") return std::to_string(0.0);
  if (key == "jpeg_quality") return "";
  if (key == "background_at_infinity") return "0";
  return std::nullopt;
}

// Adam keeps its per-parameter state under the parameter's TensorImpl: its
// address printed to a string in older LibTorch (Debian's 1.13; it used
// c10::guts::to_string, since removed), the address itself (void*) in newer
// ones (PyTorch PR #108480, 2023). The key type comes from the state map, so
// the trainer builds against both: a GPU machine's CUDA PyTorch is newer.
template <typename StateMap>
typename StateMap::key_type AdamStateKey(const StateMap& /*state*/, const torch::Tensor& parameter) {
  using Key = typename StateMap::key_type;
  if constexpr (std::is_same_v<Key, std::string>) {
    std::ostringstream key;  // c10::guts::to_string's format: operator<< of the pointer
    key << static_cast<const void*>(parameter.unsafeGetTensorImpl());
    return key.str();
  } else {
    return static_cast<Key>(parameter.unsafeGetTensorImpl());
  }
}

void LoadCheckpoint(const fs::path& dir, int64_t step, DispMvsNet& net, torch::optim::Adam& optimizer,
                    const Settings& settings, torch::Device device) {
  const std::string optim_path = OptimPath(dir, step).string();
  const auto file = model::LoadSafetensors(optim_path);
  for (const auto& [key, value] : settings) {
    const auto found = file.metadata.find(key);
    const std::optional<std::string> stored =
        found != file.metadata.end() ? std::optional<std::string>(found->second) : SettingBeforeItExisted(key);
    if (!stored || *stored != value) {
      throw std::runtime_error(optim_path + ": checkpoint of a different run (" + key + " is '" +
                               stored.value_or("<missing>") +
                               "', this run has '" + value + "'); use another checkpoint dir");
    }
  }
  const auto step_entry = file.metadata.find("adam_step");
  if (step_entry == file.metadata.end()) throw std::runtime_error(optim_path + ": no adam_step");
  const int64_t adam_step = std::stoll(step_entry->second);

  model::LoadModuleWeights(*net, WeightsPath(dir, step).string());

  std::map<std::string, torch::Tensor> stored(file.tensors.begin(), file.tensors.end());
  optimizer.state().clear();
  for (const auto& item : net->named_parameters()) {
    const auto avg = stored.find("exp_avg/" + item.key());
    const auto avg_sq = stored.find("exp_avg_sq/" + item.key());
    if (avg == stored.end() || avg_sq == stored.end()) continue;
    if (avg->second.sizes() != item.value().sizes() || avg_sq->second.sizes() != item.value().sizes()) {
      throw std::runtime_error(optim_path + ": Adam state of " + item.key() + " has the wrong shape");
    }
    auto state = std::make_unique<torch::optim::AdamParamState>();
    state->step(adam_step);
    state->exp_avg(avg->second.to(device, item.value().scalar_type()));
    state->exp_avg_sq(avg_sq->second.to(device, item.value().scalar_type()));
    optimizer.state()[AdamStateKey(optimizer.state(), item.value())] = std::move(state);
  }
}

}  // namespace

Settings RunSettings(const TrainOptions& o) {
  std::ostringstream lr, clip, widening;
  lr.precision(17);
  clip.precision(17);
  widening.precision(17);
  lr << o.lr;
  clip << o.grad_clip;
  widening << o.train_widening_max;
  std::ostringstream mvsnet_fraction;
  mvsnet_fraction.precision(17);
  mvsnet_fraction << o.mvsnet_fraction;
  return {{"config", o.config},
          {"height", std::to_string(o.height)},
          {"width", std::to_string(o.width)},
          {"num_sources", std::to_string(o.num_sources)},
          {"batch_size", std::to_string(o.batch_size)},
          {"seed", std::to_string(o.seed)},
          {"lr", lr.str()},
          {"lr_halve_every", std::to_string(o.lr_halve_every)},
          {"lr_warmup_steps", std::to_string(o.lr_warmup_steps)},
          {"grad_clip", clip.str()},
          {"train_widening_max", widening.str()},
          {"mvsnet_root", AbsolutePathSetting(o.mvsnet_root)},
          {"mvsnet_fraction", mvsnet_fraction.str()},
          {"init_weights", InitWeightsSetting(o.init_weights)},
          {"texture_dir", TextureDirSetting(o.texture_dir)},
          {"photo_probability", o.texture_dir.empty() ? "" : std::to_string(o.photo_probability)},
          {"matching_loss_weight", std::to_string(o.matching_loss_weight)},
          {"matching_warmup_steps", std::to_string(o.matching_warmup_steps)},
          {"depth_loss", o.depth_loss},
          {"flow_loss_weight", std::to_string(o.flow_loss_weight)},
          {"scene_reuse", std::to_string(o.scene_reuse)},
          {"train_coarse_iterations", std::to_string(o.train_coarse_iterations)},
          {"difficulty_start", std::to_string(o.difficulty_start)},
          {"difficulty_ramp_steps", std::to_string(o.difficulty_ramp_steps)},
          {"source_counts", JoinCounts(o.source_counts)},
          {"photometry", o.photometry},
          {"supersampling", std::to_string(o.supersampling)},
          {"specular_probability", std::to_string(o.specular_probability)},
          {"jpeg_quality", o.jpeg_quality_max == 0 ? "" : std::to_string(o.jpeg_quality_min) + "," +
                                                           std::to_string(o.jpeg_quality_max)},
          {"background_at_infinity", o.background_at_infinity ? "1" : "0"}};
}

void SaveCheckpoint(const fs::path& dir, int64_t step, DispMvsNet& net, const ModelConfig& config,
                    torch::optim::Adam& optimizer, const Settings& settings, int64_t keep_weights_every) {
  model::NamedTensors tensors;
  int64_t adam_step = -1;
  for (const auto& item : net->named_parameters()) {
    auto found = optimizer.state().find(AdamStateKey(optimizer.state(), item.value()));
    if (found == optimizer.state().end()) continue;  // never received a gradient
    auto& state = static_cast<torch::optim::AdamParamState&>(*found->second);
    if (adam_step >= 0 && state.step() != adam_step) {
      throw std::runtime_error("Adam state: parameters at different steps");
    }
    adam_step = state.step();
    tensors.emplace_back("exp_avg/" + item.key(), state.exp_avg());
    tensors.emplace_back("exp_avg_sq/" + item.key(), state.exp_avg_sq());
  }
  if (tensors.size() != 2 * optimizer.state().size()) {
    // Every state belongs to one of the parameters: else AdamStateKey does
    // not match the optimizer's keys, and resuming would silently restart Adam.
    throw std::logic_error("Adam state: " + std::to_string(optimizer.state().size()) + " states, " +
                           std::to_string(tensors.size() / 2) + " found under the parameters' keys");
  }
  Settings metadata = settings;
  metadata["step"] = std::to_string(step);
  metadata["adam_step"] = std::to_string(std::max<int64_t>(adam_step, 0));
  model::SaveSafetensors(OptimPath(dir, step).string(), tensors, metadata);
  model::SaveModuleWeights(*net, config, WeightsPath(dir, step).string());  // marks it complete

  for (int64_t older : CompleteCheckpoints(dir)) {
    if (older >= step) continue;
    if (keep_weights_every > 0 && older % keep_weights_every == 0) {
      fs::rename(WeightsPath(dir, older), KeptWeightsPath(dir, older));
    } else {
      fs::remove(WeightsPath(dir, older));
    }
    fs::remove(OptimPath(dir, older));
  }
}

int64_t RestoreRun(const TrainOptions& options, const fs::path& dir, const Settings& settings,
                   DispMvsNet& net, torch::optim::Adam& optimizer, torch::Device device, Logger& log) {
  const auto checkpoints = CompleteCheckpoints(dir);
  if (!checkpoints.empty()) {
    const int64_t start = checkpoints.back();
    LoadCheckpoint(dir, start, net, optimizer, settings, device);
    log.Line("resumed from " + WeightsPath(dir, start).string() + " at step " + std::to_string(start));
    return start;
  }
  if (!options.init_weights.empty()) {
    // Checked before anything is trained: a mismatch names the tensor.
    model::LoadModuleWeights(*net, options.init_weights);
    log.Line("initialised from " + options.init_weights + " (" + settings.at("init_weights") + ")");
  }
  return 0;
}

}  // namespace dispmvs::train::internal
