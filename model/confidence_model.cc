#include "model/confidence_model.h"

#include <cmath>
#include <cstdio>
#include <map>
#include <sstream>
#include <stdexcept>

#include "model/safetensors.h"

namespace dispmvs::model {

torch::Tensor ConfidenceFeatures(const torch::Tensor& network_confidence, const PhotometricRefinement& refinement) {
  const auto opts = refinement.output_score.options().dtype(torch::kFloat32);
  const torch::Tensor score = refinement.output_score.to(opts);
  const torch::Tensor computed = (score > -1).to(opts);
  const torch::Tensor output_ncc = score * computed;
  const torch::Tensor gap = torch::clamp_min(refinement.score.to(opts) - score, 0) * computed;
  return torch::cat({torch::ones_like(score), network_confidence.to(opts), output_ncc, computed, gap,
                     refinement.refined.to(opts), torch::log(torch::clamp_min(refinement.texture.to(opts), 1e-3)),
                     output_ncc * output_ncc},
                    1);
}

torch::Tensor ConfidenceFromFeatures(const ConfidenceModel& model, const torch::Tensor& features,
                                     const torch::Tensor& signal_support) {
  const torch::Tensor predicted = PredictConfidence(model, features);
  return torch::where(signal_support.to(predicted.device()) > 0, predicted, torch::zeros_like(predicted));
}

torch::Tensor ConfidenceMap(const ConfidenceModel& model, const torch::Tensor& network_confidence,
                            const PhotometricRefinement& refinement) {
  return ConfidenceFromFeatures(model, ConfidenceFeatures(network_confidence, refinement),
                                refinement.signal_support);
}

std::string ConfidenceModel::ToText() const {
  std::string text;
  char number[40];
  for (const double c : coefficients) {
    std::snprintf(number, sizeof number, "%.17g", c);
    text += (text.empty() ? "" : " ") + std::string(number);
  }
  return text;
}

ConfidenceModel ConfidenceModel::FromText(const std::string& text) {
  std::istringstream in(text);
  ConfidenceModel model;
  std::string word;
  while (in >> word) {
    size_t used = 0;
    double value = 0;
    try {
      value = std::stod(word, &used);
    } catch (const std::exception&) {
      used = 0;
    }
    if (used != word.size() || !std::isfinite(value)) {
      throw std::invalid_argument("confidence model: '" + word + "' is not a finite number");
    }
    model.coefficients.push_back(value);
  }
  if (static_cast<int64_t>(model.coefficients.size()) != kConfidenceFeatures) {
    throw std::invalid_argument("confidence model: expected " + std::to_string(kConfidenceFeatures) +
                                " coefficients, got " + std::to_string(model.coefficients.size()));
  }
  return model;
}

torch::Tensor PredictConfidence(const ConfidenceModel& model, const torch::Tensor& features) {
  if (model.empty()) throw std::invalid_argument("PredictConfidence: no confidence model");
  if (features.dim() != 4 || features.size(1) != kConfidenceFeatures ||
      static_cast<int64_t>(model.coefficients.size()) != kConfidenceFeatures) {
    throw std::invalid_argument("PredictConfidence: expected features [B," + std::to_string(kConfidenceFeatures) +
                                ",H,W] and as many coefficients");
  }
  const torch::Tensor c =
      torch::tensor(model.coefficients, torch::kFloat64).to(features.options()).view({1, kConfidenceFeatures, 1, 1});
  return torch::sigmoid((features * c).sum(1, /*keepdim=*/true));
}

ConfidenceModel FitConfidenceModel(const torch::Tensor& features, const torch::Tensor& labels, double ridge,
                                   int max_iterations) {
  if (features.dim() != 2 || features.size(1) != kConfidenceFeatures || labels.dim() != 1 ||
      labels.size(0) != features.size(0)) {
    throw std::invalid_argument("FitConfidenceModel: expected features [M," + std::to_string(kConfidenceFeatures) +
                                "] and labels [M]");
  }
  const torch::Tensor x = features.to(torch::kFloat64).cpu();
  const torch::Tensor y = labels.to(torch::kFloat64).cpu();
  const double positives = y.sum().item<double>();
  if (positives <= 0 || positives >= static_cast<double>(y.size(0))) {
    throw std::invalid_argument("FitConfidenceModel: the labels must hold both classes");
  }
  const double m = static_cast<double>(x.size(0));
  // Mean log-likelihood terms, so the ridge means the same for any M.
  torch::Tensor penalty = torch::full({kConfidenceFeatures}, ridge, torch::kFloat64);
  penalty[0] = 0;
  torch::Tensor w = torch::zeros({kConfidenceFeatures}, torch::kFloat64);
  for (int it = 0; it < max_iterations; ++it) {
    const torch::Tensor p = torch::sigmoid(x.matmul(w));
    const torch::Tensor gradient = x.t().matmul(p - y) / m + penalty * w;
    const torch::Tensor hessian =
        (x.t() * (p * (1 - p))).matmul(x) / m + torch::diag(penalty) +
        1e-12 * torch::eye(kConfidenceFeatures, torch::kFloat64);
    const torch::Tensor step = torch::linalg::solve(hessian, gradient.unsqueeze(1), /*left=*/true).squeeze(1);
    w = w - step;
    if (step.abs().max().item<double>() < 1e-10) break;
  }
  ConfidenceModel model;
  auto a = w.accessor<double, 1>();
  for (int64_t i = 0; i < kConfidenceFeatures; ++i) {
    if (!std::isfinite(a[i])) throw std::runtime_error("FitConfidenceModel: the fit diverged");
    model.coefficients.push_back(a[i]);
  }
  return model;
}

ConfidenceModel ReadConfidenceModel(const std::string& weights_path) {
  const std::map<std::string, std::string> metadata = ReadSafetensorsMetadata(weights_path);
  const auto found = metadata.find(kConfidenceModelKey);
  if (found == metadata.end()) return {};
  try {
    return ConfidenceModel::FromText(found->second);
  } catch (const std::invalid_argument& e) {
    throw std::runtime_error(weights_path + ": " + e.what());
  }
}

void WriteConfidenceModel(const std::string& input, const std::string& output, const ConfidenceModel& model) {
  SafetensorsFile file = LoadSafetensors(input);
  file.metadata[kConfidenceModelKey] = model.ToText();
  ConfidenceModel::FromText(file.metadata[kConfidenceModelKey]);  // a model that reads back
  SaveSafetensors(output, file.tensors, file.metadata);
}

}  // namespace dispmvs::model
