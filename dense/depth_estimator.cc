#include "dense/depth_estimator.h"

#include <algorithm>
#include <cmath>
#include <stdexcept>
#include <thread>

#include <ATen/CPUGeneratorImpl.h>
#include <torch/torch.h>

#include "dense/feature_cache.h"
#include "model/confidence_model.h"
#include "model/confident_plane_fill.h"
#include "model/device.h"
#include "model/dispmvs_net.h"
#include "model/host_allocator.h"
#include "model/photometric_refinement.h"
#include "model/safetensors.h"

namespace dispmvs::dense {

namespace {

// Copies an RGB CV_32FC3 image into `out` [3,H,W] (channels first).
void CopyImage(const cv::Mat& image, torch::Tensor out) {
  if (image.type() != CV_32FC3 || !image.isContinuous()) {
    throw std::invalid_argument("DepthEstimator: images must be continuous CV_32FC3");
  }
  out.copy_(torch::from_blob(const_cast<float*>(image.ptr<float>()), {image.rows, image.cols, 3},
                             torch::kFloat32)
                .permute({2, 0, 1}));
}

torch::Tensor MatrixTensor(const Eigen::Matrix3d& K) {
  torch::Tensor t = torch::zeros({3, 3}, torch::kFloat64);
  auto a = t.accessor<double, 2>();
  for (int r = 0; r < 3; ++r) {
    for (int c = 0; c < 3; ++c) a[r][c] = K(r, c);
  }
  return t;
}

torch::Tensor PoseTensor(const Eigen::Matrix3d& R, const Eigen::Vector3d& t) {
  torch::Tensor m = torch::eye(4, torch::kFloat64);
  auto a = m.accessor<double, 2>();
  for (int r = 0; r < 3; ++r) {
    for (int c = 0; c < 3; ++c) a[r][c] = R(r, c);
    a[r][3] = t(r);
  }
  return m;
}

// [H,W] CPU float tensor -> dense array, non-finite or negative -> 0.
colmap_io::DenseArray ToDenseArray(const torch::Tensor& map) {
  const torch::Tensor cpu = map.to(torch::kCPU, torch::kFloat32).contiguous();
  const int height = static_cast<int>(cpu.size(0));
  const int width = static_cast<int>(cpu.size(1));
  colmap_io::DenseArray array(width, height, 1);
  const float* src = cpu.data_ptr<float>();
  float* dst = array.data();
  for (std::size_t i = 0; i < array.size(); ++i) {
    dst[i] = std::isfinite(src[i]) && src[i] > 0.0f ? src[i] : 0.0f;
  }
  return array;
}

}  // namespace

void EstimatorOptions::Check() const {
  if (model_path.empty()) throw std::invalid_argument("--model_path must not be empty");
  model::ResolvePrecision(precision, model::ParseUsableDevice(device, "--device"), "--precision");
  if (threads < 0) throw std::invalid_argument("--threads must be >= 0 (0 = one per core)");
  if (coarse_iterations < 0 || fine_iterations < 0) {
    throw std::invalid_argument("--coarse_iterations and --fine_iterations must be >= 0");
  }
  if (feature_cache_mb < 0) throw std::invalid_argument("--feature_cache_mb must be >= 0");
  if (tensor_cache_mb < 0) throw std::invalid_argument("--tensor_cache_mb must be >= 0");
  if (!(band_megapixels >= 0) || !std::isfinite(band_megapixels)) {
    throw std::invalid_argument("--band_megapixels must be a number >= 0 (0 = never in bands)");
  }
  model::ParseRefinementMode(refinement, "--refinement");
  if (confidence != "model" && confidence != "network") {
    throw std::invalid_argument("--confidence must be model or network, got '" + confidence + "'");
  }
  try {
    refinement_options.Check();
  } catch (const std::invalid_argument& error) {
    throw std::invalid_argument(std::string("--refine_* options: ") + error.what());
  }
  try {
    fill_options.Check();
  } catch (const std::invalid_argument& error) {
    throw std::invalid_argument(std::string("--fill_* options: ") + error.what());
  }
}

struct DepthEstimator::Impl {
  torch::Device device{torch::kCPU};
  model::Precision precision = model::Precision::kFloat32;
  model::ModelConfig config;
  model::DispMvsNet net{nullptr};
  std::unique_ptr<FeatureCache> features;
  bool refine = false;
  model::PhotometricRefinementOptions refinement;
  model::ConfidenceModel confidence_model;  // empty: the network's confidence
  model::ConfidentPlaneFillOptions fill;
};

DepthEstimator::DepthEstimator(const EstimatorOptions& options) : impl_(std::make_unique<Impl>()) {
  options.Check();
  impl_->device = model::ParseUsableDevice(options.device, "--device");
  impl_->precision = model::ResolvePrecision(options.precision, impl_->device, "--precision");
  if (impl_->device.is_cpu()) {
    model::KeepFreedTensorMemory();
    // Maps of 32 MiB and more (from about 2 megapixels) reused instead of
    // mapped afresh by glibc on every use (model/large_block_cache.h).
    if (options.tensor_cache_mb > 0) {
      model::LargeBlockCacheOptions cache;
      cache.max_cached_bytes = static_cast<std::size_t>(options.tensor_cache_mb) << 20;
      model::InstallLargeBlockCache(cache);
    }
  }
  impl_->features =
      std::make_unique<FeatureCache>(static_cast<std::size_t>(options.feature_cache_mb) << 20);
  const int threads = options.threads > 0
                          ? options.threads
                          : static_cast<int>(std::max(1u, std::thread::hardware_concurrency()));
  torch::set_num_threads(threads);
  try {
    impl_->config = model::ReadModelConfig(options.model_path);
    // Iteration counts are not part of the weights' shapes: the same weights
    // run with more or fewer updates.
    if (options.coarse_iterations > 0) impl_->config.coarse_iterations = options.coarse_iterations;
    if (options.fine_iterations > 0) impl_->config.fine_iterations = options.fine_iterations;
    impl_->net = model::DispMvsNet(impl_->config);
    model::LoadModuleWeights(*impl_->net, options.model_path);
    // The model reads the refinement's correlation and texture.
    if (options.confidence == "model" && model::ParseRefinementMode(options.refinement, "--refinement")) {
      impl_->confidence_model = model::ReadConfidenceModel(options.model_path);
    }
  } catch (const std::exception& error) {
    throw std::runtime_error("cannot use the weights " + options.model_path + ": " + error.what());
  }
  impl_->net->to(impl_->device);
  impl_->net->eval();
  impl_->net->set_precision(impl_->precision);
  impl_->net->set_fine_band_pixels(static_cast<int64_t>(options.band_megapixels * 1e6));
  impl_->refine = model::ParseRefinementMode(options.refinement, "--refinement");
  impl_->refinement = options.refinement_options;
  impl_->fill = options.fill_options;
}

DepthEstimator::~DepthEstimator() = default;

bool DepthEstimator::UsesConfidenceModel() const { return !impl_->confidence_model.empty(); }

DepthEstimator::WeightsInfo DepthEstimator::CheckWeightsFile(const std::string& model_path) {
  try {
    const model::ModelConfig config = model::ReadModelConfig(model_path);
    WeightsInfo info;
    info.name = config.name;
    info.needs_depth_range = config.NeedsDepthRange();
    return info;
  } catch (const std::exception& error) {
    throw std::runtime_error("cannot use the weights " + model_path + ": " + error.what());
  }
}

bool DepthEstimator::NeedsDepthRange() const { return impl_->config.NeedsDepthRange(); }

std::string DepthEstimator::Describe() const {
  int64_t parameters = 0;
  for (const auto& p : impl_->net->parameters()) parameters += p.numel();
  return impl_->config.name + ", " + std::to_string(parameters) + " parameters, " +
         std::to_string(impl_->config.coarse_iterations) + "+" +
         std::to_string(impl_->config.fine_iterations) + " iterations, " + impl_->device.str() +
         ", " + model::PrecisionName(impl_->precision);
}

DepthEstimator::EncoderUse DepthEstimator::encoder_use() const {
  const FeatureCache::Stats& stats = impl_->features->stats();
  EncoderUse use;
  use.encoded = stats.misses;
  use.reused = stats.hits;
  use.peak_cache_mb = static_cast<double>(stats.peak_bytes) / (1 << 20);
  return use;
}

DepthEstimate DepthEstimator::Estimate(std::vector<ProblemView> views,
                                       const std::optional<colmap_io::DepthRange>& hint,
                                       uint64_t seed, const StepCallback& step) {
  const auto begin = [&](const char* name) {
    if (step) step(name);
  };
  if (views.size() < 2) throw std::invalid_argument("DepthEstimator: need a reference and a source");
  if (hint && (!hint->valid || !(hint->d_min > 0) || !(hint->d_min < hint->d_max) ||
               !std::isfinite(hint->d_max))) {
    throw std::invalid_argument("DepthEstimator: invalid depth-range hint");
  }
  if (!hint && NeedsDepthRange()) {
    throw std::invalid_argument(
        "no depth-range hint, and the weights (" + impl_->config.name +
        ", init = random) need one: pass --depth_min and --depth_max, or use model v2 weights "
        "(init = match)");
  }
  const cv::Size size = views[0].image.size();
  // The views' images written straight into the network's input: one copy
  // of them, not one per image and one stacked (at 24 megapixels and five
  // views each copy is 1.4 GB).
  torch::Tensor images = torch::empty(
      {1, static_cast<int64_t>(views.size()), 3, size.height, size.width}, torch::kFloat32);
  std::vector<torch::Tensor> intrinsics, extrinsics;
  for (const ProblemView& view : views) {
    if (view.image.size() != size) {
      throw std::invalid_argument("DepthEstimator: all views must have the reference's size");
    }
  }
  for (std::size_t v = 0; v < views.size(); ++v) {
    ProblemView& view = views[v];
    CopyImage(view.image, images[0][static_cast<int64_t>(v)]);
    view.image.release();  // the pixels go now unless the caller kept them
    intrinsics.push_back(MatrixTensor(view.K));
    extrinsics.push_back(PoseTensor(view.R, view.t));
  }
  const auto float_on_device = torch::TensorOptions().dtype(torch::kFloat32).device(impl_->device);
  model::DispMvsInput input;
  input.images = images.to(float_on_device);
  images = torch::Tensor();  // on a GPU, the host copy goes now
  input.intrinsics = torch::stack(intrinsics).unsqueeze(0).to(float_on_device);
  input.extrinsics = torch::stack(extrinsics).unsqueeze(0).to(float_on_device);
  // Without a hint the range tensors stay undefined: the network's "no depth
  // range" (model v2). With one, it is passed even to weights that do not
  // need it: harmless, and the loss and diagnostics may use it.
  if (hint) {
    input.depth_min = torch::tensor({hint->d_min}, torch::kFloat64).to(float_on_device);
    input.depth_max = torch::tensor({hint->d_max}, torch::kFloat64).to(float_on_device);
  }

  torch::NoGradGuard no_grad;
  begin("encoders");
  // Each view's matching features, encoded alone (as forward() would), so a
  // reused one gives the same bits as a fresh one, and written straight into
  // the network's [V,C,h,w] input: a view's own tensor goes as soon as it is
  // copied (unless the feature cache keeps it).
  for (std::size_t v = 0; v < views.size(); ++v) {
    const auto encode = [&] { return impl_->net->EncodeMatching(input.images[0][v].unsqueeze(0)); };
    const model::FeaturePyramid features =
        views[v].image_id >= 0
            ? impl_->features->Get({views[v].image_id, size.width, size.height}, encode)
            : encode();
    if (v == 0) {
      const auto all_views = [&](const torch::Tensor& one) {
        std::vector<int64_t> shape = one.sizes().vec();
        shape[0] = static_cast<int64_t>(views.size());
        return torch::empty(shape, one.options());
      };
      input.matching_features = {all_views(features.coarse), all_views(features.fine)};
    }
    input.matching_features.coarse.narrow(0, static_cast<int64_t>(v), 1).copy_(features.coarse);
    input.matching_features.fine.narrow(0, static_cast<int64_t>(v), 1).copy_(features.fine);
  }
  // The initialisation is drawn on the CPU and moved, so CPU and CUDA runs
  // start from the same random depths.
  begin("network");
  const model::DispMvsOutput output =
      impl_->net->forward(input, at::make_generator<at::CPUGeneratorImpl>(seed));
  // The refinement reads the images and the network's maps, not the
  // features: they go before its own maps are allocated.
  input.matching_features = {};
  torch::Tensor depth = output.depth;
  torch::Tensor confidence = output.confidence;
  if (impl_->refine) {
    begin("refinement");
    const model::PhotometricRefinement refined = model::RefineDepthPhotometrically(input, output, impl_->refinement);
    depth = refined.depth;
    if (UsesConfidenceModel()) {
      confidence = model::ConfidenceMap(impl_->confidence_model, output.confidence, refined);
      if (impl_->fill.below > 0) depth = model::FillFromConfidentPlanes(depth, confidence, impl_->fill).depth;
    }
  }
  DepthEstimate estimate;
  estimate.depth = ToDenseArray(depth[0][0]);
  estimate.confidence = ToDenseArray(confidence[0][0] * output.valid[0][0]);
  return estimate;
}

}  // namespace dispmvs::dense
