#pragma once
// Sizes and iteration counts of the DispMVS network. Check() validates a
// configuration; Paper() matches the authors' release, Small() is a reduced
// network for CPU work and tests. The configuration travels with the weights
// as safetensors metadata (ToMetadata / FromMetadata).

#include <cstdint>
#include <map>
#include <string>

namespace dispmvs::model {

struct ModelConfig {
  std::string name = "paper";

  // Matching-feature encoder (all views): channels at 1/16 and 1/4.
  int64_t match_coarse_channels = 128;
  int64_t match_fine_channels = 96;
  // Width of the first encoder layer; deeper layers scale from it.
  int64_t encoder_base_channels = 32;

  // Context encoder (reference only): per stage, GRU hidden state (tanh) and
  // context input (relu); the encoder outputs hidden + input channels.
  int64_t hidden_coarse = 128;
  int64_t context_input_coarse = 128;
  int64_t hidden_fine = 96;
  int64_t context_input_fine = 96;
  bool deformable_context_decoder = true;

  // Epipolar correlation: pooled levels x samples per level.
  int64_t coarse_levels = 4;
  int64_t coarse_samples = 9;
  int64_t fine_levels = 2;
  int64_t fine_samples = 5;

  // GRU iterations per stage.
  int64_t coarse_iterations = 8;
  int64_t fine_iterations = 2;

  // How the coarse stage starts (metadata key "init"):
  //  * kRandom, the paper's: a random inverse depth drawn inside the
  //    depth-range hint; every coarse iteration samples 2-D source features
  //    around the current match. Needs a hint.
  //  * kMatch (model v2): a 1-D correlation volume along each source's whole
  //    epipolar segment is computed once per stage; the start is the best
  //    match of each source along it, triangulated and fused; the GRU reads
  //    the volume. Needs no depth range at all.
  // Weights written before this field existed were trained with kRandom, so
  // a file without the key reads as kRandom.
  enum class Init { kRandom, kMatch };
  Init init = Init::kRandom;

  // Whether forward() needs DispMvsInput::depth_min/depth_max.
  bool NeedsDepthRange() const { return init == Init::kRandom; }

  // Throws std::invalid_argument naming the first bad field.
  void Check() const;

  static ModelConfig Paper();
  static ModelConfig Small();
  // Small() with init = kMatch and 4 coarse iterations: the CPU
  // configuration of model v2. Its coarse stage starts from the best match,
  // not from a random depth, and 4 iterations measured better than the
  // paper's 8 (models/README.md, "GRU iterations").
  static ModelConfig SmallV2();
  // Paper() with init = kMatch: model v2 at the paper's widths.
  static ModelConfig PaperV2();
  // The configuration named "paper", "small", "paper_v2" or "small_v2" (the
  // names dispmvs_train --config and dispmvs_bench --config take); throws
  // std::invalid_argument for any other.
  static ModelConfig ByName(const std::string& name);

  std::map<std::string, std::string> ToMetadata() const;
  // Throws std::invalid_argument on a missing or malformed key.
  static ModelConfig FromMetadata(const std::map<std::string, std::string>& metadata);
};

}  // namespace dispmvs::model

namespace dispmvs::model {
// "random" / "match", and back (std::invalid_argument on other text).
const char* InitName(ModelConfig::Init init);
ModelConfig::Init ParseInit(const std::string& text);
}  // namespace dispmvs::model
