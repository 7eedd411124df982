#include "model/config.h"

#include <cerrno>
#include <cstdlib>
#include <stdexcept>
#include <string>

namespace dispmvs::model {
namespace {

void RequirePositive(const char* field, int64_t value) {
  if (value < 1) {
    throw std::invalid_argument("ModelConfig." + std::string(field) + " must be >= 1, got " +
                                std::to_string(value));
  }
}

// Correlation samples sit symmetrically around the current match, so their
// count must be odd.
void RequireOddPositive(const char* field, int64_t value) {
  if (value < 1 || value % 2 == 0) {
    throw std::invalid_argument("ModelConfig." + std::string(field) +
                                " must be odd and >= 1, got " + std::to_string(value));
  }
}

// Upper bound on any channel count: far above any sensible network, low
// enough that a corrupted weights file cannot make us build a huge module.
constexpr int64_t kMaxChannels = 4096;
constexpr int64_t kMaxLevels = 16;
constexpr int64_t kMaxSamples = 257;
constexpr int64_t kMaxIterations = 1000;

void RequireAtMost(const char* field, int64_t value, int64_t limit) {
  if (value > limit) {
    throw std::invalid_argument("ModelConfig." + std::string(field) + " must be <= " +
                                std::to_string(limit) + ", got " + std::to_string(value));
  }
}

// Keys of the metadata map: the field names, so a weights file is readable
// with any safetensors tool.
const char* const kName = "name";
const char* const kDeformable = "deformable_context_decoder";
const char* const kInit = "init";

// Calls visit(key, field) for every integer field; Config is ModelConfig or
// const ModelConfig, so one list serves reading and writing.
template <class Config, class Visit>
void ForEachIntField(Config& c, Visit visit) {
  visit("match_coarse_channels", c.match_coarse_channels);
  visit("match_fine_channels", c.match_fine_channels);
  visit("encoder_base_channels", c.encoder_base_channels);
  visit("hidden_coarse", c.hidden_coarse);
  visit("context_input_coarse", c.context_input_coarse);
  visit("hidden_fine", c.hidden_fine);
  visit("context_input_fine", c.context_input_fine);
  visit("coarse_levels", c.coarse_levels);
  visit("coarse_samples", c.coarse_samples);
  visit("fine_levels", c.fine_levels);
  visit("fine_samples", c.fine_samples);
  visit("coarse_iterations", c.coarse_iterations);
  visit("fine_iterations", c.fine_iterations);
}

const std::string& Lookup(const std::map<std::string, std::string>& metadata,
                          const std::string& key) {
  auto it = metadata.find(key);
  if (it == metadata.end()) {
    throw std::invalid_argument("ModelConfig metadata: missing key '" + key + "'");
  }
  return it->second;
}

// Strict decimal integer: optional '-', digits only, no spaces, in range.
int64_t ParseInt(const std::string& key, const std::string& text) {
  const auto bad = [&] {
    return std::invalid_argument("ModelConfig metadata: key '" + key + "' is not an integer: '" +
                                 text + "'");
  };
  const size_t first_digit = (!text.empty() && text[0] == '-') ? 1 : 0;
  if (text.size() == first_digit || text.size() > 20) throw bad();
  for (size_t i = first_digit; i < text.size(); ++i) {
    if (text[i] < '0' || text[i] > '9') throw bad();
  }
  errno = 0;
  char* end = nullptr;
  const long long value = std::strtoll(text.c_str(), &end, 10);
  if (errno == ERANGE || end != text.c_str() + text.size()) throw bad();
  return static_cast<int64_t>(value);
}

}  // namespace

void ModelConfig::Check() const {
  if (name.empty()) throw std::invalid_argument("ModelConfig.name must not be empty");
  RequirePositive("match_coarse_channels", match_coarse_channels);
  RequirePositive("match_fine_channels", match_fine_channels);
  RequirePositive("encoder_base_channels", encoder_base_channels);
  RequirePositive("hidden_coarse", hidden_coarse);
  RequirePositive("context_input_coarse", context_input_coarse);
  RequirePositive("hidden_fine", hidden_fine);
  RequirePositive("context_input_fine", context_input_fine);
  RequirePositive("coarse_levels", coarse_levels);
  RequireOddPositive("coarse_samples", coarse_samples);
  RequirePositive("fine_levels", fine_levels);
  RequireOddPositive("fine_samples", fine_samples);
  RequirePositive("coarse_iterations", coarse_iterations);
  RequirePositive("fine_iterations", fine_iterations);

  RequireAtMost("match_coarse_channels", match_coarse_channels, kMaxChannels);
  RequireAtMost("match_fine_channels", match_fine_channels, kMaxChannels);
  // The encoder's deepest layer has 4x the base width.
  RequireAtMost("encoder_base_channels", encoder_base_channels, kMaxChannels / 4);
  RequireAtMost("hidden_coarse", hidden_coarse, kMaxChannels);
  RequireAtMost("context_input_coarse", context_input_coarse, kMaxChannels);
  RequireAtMost("hidden_fine", hidden_fine, kMaxChannels);
  RequireAtMost("context_input_fine", context_input_fine, kMaxChannels);
  RequireAtMost("coarse_levels", coarse_levels, kMaxLevels);
  RequireAtMost("coarse_samples", coarse_samples, kMaxSamples);
  RequireAtMost("fine_levels", fine_levels, kMaxLevels);
  RequireAtMost("fine_samples", fine_samples, kMaxSamples);
  RequireAtMost("coarse_iterations", coarse_iterations, kMaxIterations);
  RequireAtMost("fine_iterations", fine_iterations, kMaxIterations);
}

ModelConfig ModelConfig::Paper() { return ModelConfig{}; }

ModelConfig ModelConfig::Small() {
  ModelConfig c;
  c.name = "small";
  c.match_coarse_channels = 64;
  c.match_fine_channels = 48;
  c.encoder_base_channels = 16;
  c.hidden_coarse = 64;
  c.context_input_coarse = 64;
  c.hidden_fine = 48;
  c.context_input_fine = 48;
  // Levels, samples and iterations as in the paper: they set the search
  // range and convergence, not the cost.
  return c;
}

ModelConfig ModelConfig::SmallV2() {
  ModelConfig c = Small();
  c.name = "small_v2";
  c.init = Init::kMatch;
  // Starting from the best match, the coarse stage needs fewer iterations
  // than the paper's 8 from a random start: with the stage-6 weights, 4 gave
  // more pixels within 2 % on the 20 validation scenes and on Motorcycle, a
  // lower AbsRel, and 10 % less time per view (models/README.md).
  c.coarse_iterations = 4;
  return c;
}

ModelConfig ModelConfig::PaperV2() {
  ModelConfig c = Paper();
  c.name = "paper_v2";
  c.init = Init::kMatch;
  return c;
}

ModelConfig ModelConfig::ByName(const std::string& name) {
  if (name == "paper") return Paper();
  if (name == "small") return Small();
  if (name == "paper_v2") return PaperV2();
  if (name == "small_v2") return SmallV2();
  throw std::invalid_argument("config must be 'paper', 'small', 'paper_v2' or 'small_v2', got '" +
                              name + "'");
}

const char* InitName(ModelConfig::Init init) {
  return init == ModelConfig::Init::kMatch ? "match" : "random";
}

ModelConfig::Init ParseInit(const std::string& text) {
  if (text == "random") return ModelConfig::Init::kRandom;
  if (text == "match") return ModelConfig::Init::kMatch;
  throw std::invalid_argument("ModelConfig: init must be 'random' or 'match', got '" + text + "'");
}

std::map<std::string, std::string> ModelConfig::ToMetadata() const {
  std::map<std::string, std::string> out;
  out[kName] = name;
  ForEachIntField(*this, [&](const char* key, int64_t value) { out[key] = std::to_string(value); });
  out[kDeformable] = deformable_context_decoder ? "true" : "false";
  out[kInit] = InitName(init);
  return out;
}

ModelConfig ModelConfig::FromMetadata(const std::map<std::string, std::string>& metadata) {
  ModelConfig c;
  c.name = Lookup(metadata, kName);
  ForEachIntField(
      c, [&](const char* key, int64_t& value) { value = ParseInt(key, Lookup(metadata, key)); });
  const std::string& deformable = Lookup(metadata, kDeformable);
  if (deformable == "true") {
    c.deformable_context_decoder = true;
  } else if (deformable == "false") {
    c.deformable_context_decoder = false;
  } else {
    throw std::invalid_argument("ModelConfig metadata: key '" + std::string(kDeformable) +
                                "' must be 'true' or 'false', got '" + deformable + "'");
  }
  // Optional: weights from before model v2 have no "init" and used kRandom.
  const auto init = metadata.find(kInit);
  c.init = init == metadata.end() ? Init::kRandom : ParseInit(init->second);
  c.Check();
  return c;
}

}  // namespace dispmvs::model
