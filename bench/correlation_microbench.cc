// Microbenchmarks (Google Benchmark) of the epipolar correlation sampler
// (model/correlation.h), the part of the network that every GRU iteration
// runs: the per-stage source pyramid, a whole Lookup(), and Lookup()'s two
// halves (bilinear sampling of the source features along the lines, and the
// dot products with the reference features), so that it is clear which half
// to optimise.
//
//   correlation_microbench [--benchmark_filter=Lookup] [--benchmark_repetitions=3]
//
// Shapes are those of a forward pass with N = 5 sources (batch 5 = one
// reference x 5 sources) at 640x512 and 1600x1152, for the coarse (1/16) and
// fine (1/4) stages of the shipped (small) and the paper configuration.
// Arguments: image width, image height, stage (0 coarse, 1 fine), config
// (0 small, 1 paper), intra-op threads. Features are random: the cost does
// not depend on their values; the matches sit on random lines inside the map,
// as during a pass.
//
// The *Training benchmarks time a training step's correlations, forward and
// backward, with the ATen ops against the fused node of correlation_cpu.h
// (see their comment); run them on their own:
//
//   correlation_microbench --benchmark_filter=Training

#include <cstdint>
#include <string>
#include <vector>

#include <benchmark/benchmark.h>
#include <torch/torch.h>

#include "model/config.h"
#include "model/correlation.h"
#include "model/host_allocator.h"
#include "model/segment_correlation.h"

namespace {

namespace F = torch::nn::functional;
using dispmvs::model::EpipolarCorrelation;
using dispmvs::model::ModelConfig;

constexpr int64_t kSources = 5;

struct Problem {
  int64_t channels = 0, levels = 0, samples = 0, height = 0, width = 0;
  torch::Tensor source, reference, base_xy, dir, eflow;
};

Problem MakeProblem(const benchmark::State& state) {
  const int64_t image_width = state.range(0);
  const int64_t image_height = state.range(1);
  const bool fine = state.range(2) == 1;
  const ModelConfig config = state.range(3) == 1 ? ModelConfig::Paper() : ModelConfig::Small();
  torch::set_num_threads(static_cast<int>(state.range(4)));
  const int64_t stride = fine ? 4 : 16;
  Problem p;
  p.channels = fine ? config.match_fine_channels : config.match_coarse_channels;
  p.levels = fine ? config.fine_levels : config.coarse_levels;
  p.samples = fine ? config.fine_samples : config.coarse_samples;
  p.height = (image_height + 15) / 16 * 16 / stride;
  p.width = (image_width + 15) / 16 * 16 / stride;
  torch::manual_seed(0);
  p.source = torch::randn({kSources, p.channels, p.height, p.width});
  p.reference = torch::randn({kSources, p.channels, p.height, p.width});
  // Base points anywhere in the map, unit directions, E-flow of a few pixels.
  p.base_xy = torch::stack({torch::rand({kSources, p.height, p.width}) * (p.width - 1),
                            torch::rand({kSources, p.height, p.width}) * (p.height - 1)},
                           1);
  const torch::Tensor angle = torch::rand({kSources, 1, p.height, p.width}) * 6.2832;
  p.dir = torch::cat({torch::cos(angle), torch::sin(angle)}, 1);
  p.eflow = torch::randn({kSources, 1, p.height, p.width}) * 3.0;
  return p;
}

void SetCounters(benchmark::State& state, const Problem& p) {
  const double samples =
      static_cast<double>(kSources * p.height * p.width * p.levels * p.samples);
  state.counters["samples/s"] =
      benchmark::Counter(samples, benchmark::Counter::kIsIterationInvariantRate);
  state.SetLabel(std::to_string(p.width) + "x" + std::to_string(p.height) + " C" +
                 std::to_string(p.channels) + " L" + std::to_string(p.levels) + " S" +
                 std::to_string(p.samples));
}

void BM_Pyramid(benchmark::State& state) {
  torch::NoGradGuard no_grad;
  const Problem p = MakeProblem(state);
  for (auto _ : state) {
    EpipolarCorrelation correlation(p.source, p.levels, p.samples);
    benchmark::DoNotOptimize(correlation.level(p.levels - 1).data_ptr());
  }
  SetCounters(state, p);
}

void BM_Lookup(benchmark::State& state) {
  torch::NoGradGuard no_grad;
  const Problem p = MakeProblem(state);
  const EpipolarCorrelation correlation(p.source, p.levels, p.samples);
  for (auto _ : state) {
    const auto out = correlation.Lookup(p.reference, p.base_xy, p.dir, p.eflow);
    benchmark::DoNotOptimize(out.cost.data_ptr());
  }
  SetCounters(state, p);
}

// The sampling grids of every level, as Lookup() builds them (level-l pixel
// coordinates converted to grid_sample's align_corners=false range).
std::vector<torch::Tensor> SamplingGrids(const Problem& p, const EpipolarCorrelation& correlation) {
  const torch::Tensor match = p.base_xy + p.dir * p.eflow;
  const torch::Tensor offsets =
      (torch::arange(p.samples, torch::kFloat) - 0.5 * static_cast<double>(p.samples - 1))
          .view({1, p.samples, 1, 1});
  std::vector<torch::Tensor> grids;
  for (int64_t l = 0; l < p.levels; ++l) {
    const torch::Tensor& level = correlation.level(l);
    const double scale = static_cast<double>(int64_t{1} << l);
    const torch::Tensor centre = (match + 0.5) / scale - 0.5;
    const torch::Tensor px = centre.narrow(1, 0, 1) + offsets * p.dir.narrow(1, 0, 1);
    const torch::Tensor py = centre.narrow(1, 1, 1) + offsets * p.dir.narrow(1, 1, 1);
    grids.push_back(torch::stack({(2.0 * px + 1.0) / static_cast<double>(level.size(3)) - 1.0,
                                  (2.0 * py + 1.0) / static_cast<double>(level.size(2)) - 1.0},
                                 -1)
                        .view({kSources, p.samples * p.height, p.width, 2}));
  }
  return grids;
}

torch::Tensor Sample(const torch::Tensor& level, const torch::Tensor& grid) {
  return F::grid_sample(level, grid,
                        F::GridSampleFuncOptions()
                            .mode(torch::kBilinear)
                            .padding_mode(torch::kZeros)
                            .align_corners(false));
}

// Half 1: bilinear sampling of C-channel features at every sample point.
void BM_LookupSamplingOnly(benchmark::State& state) {
  torch::NoGradGuard no_grad;
  const Problem p = MakeProblem(state);
  const EpipolarCorrelation correlation(p.source, p.levels, p.samples);
  const std::vector<torch::Tensor> grids = SamplingGrids(p, correlation);
  for (auto _ : state) {
    for (int64_t l = 0; l < p.levels; ++l) {
      const torch::Tensor sampled = Sample(correlation.level(l), grids[static_cast<size_t>(l)]);
      benchmark::DoNotOptimize(sampled.data_ptr());
    }
  }
  SetCounters(state, p);
}

// Half 2: the channel dot products of already sampled features with the
// reference features (as Lookup computes them: product, then channel sum).
void BM_LookupDotOnly(benchmark::State& state) {
  torch::NoGradGuard no_grad;
  const Problem p = MakeProblem(state);
  const EpipolarCorrelation correlation(p.source, p.levels, p.samples);
  const std::vector<torch::Tensor> grids = SamplingGrids(p, correlation);
  std::vector<torch::Tensor> sampled;
  for (int64_t l = 0; l < p.levels; ++l) {
    sampled.push_back(Sample(correlation.level(l), grids[static_cast<size_t>(l)])
                          .view({kSources, p.channels, p.samples, p.height, p.width}));
  }
  const torch::Tensor ref = p.reference.unsqueeze(2);
  for (auto _ : state) {
    for (const torch::Tensor& s : sampled) {
      const torch::Tensor cost = (s * ref).sum(1) / static_cast<double>(p.channels);
      benchmark::DoNotOptimize(cost.data_ptr());
    }
  }
  SetCounters(state, p);
}

// 640x512 and 1600x1152, coarse and fine, small and paper, 1 and 2 threads.
void ForwardPassShapes(benchmark::internal::Benchmark* b) {
  b->ArgNames({"W", "H", "fine", "paper", "threads"});
  for (const auto& size : std::vector<std::pair<int64_t, int64_t>>{{640, 512}, {1600, 1152}}) {
    for (int64_t fine = 0; fine <= 1; ++fine) {
      for (int64_t paper = 0; paper <= 1; ++paper) {
        for (int64_t threads = 1; threads <= 2; ++threads) {
          b->Args({size.first, size.second, fine, paper, threads});
        }
      }
    }
  }
  b->Unit(benchmark::kMillisecond)->UseRealTime();
}

// --- Training: forward and backward, the fused node against the ATen ops ---
//
// A training step's correlations at the shipped model's training size
// (640x480, batch 2 x 5 sources = 10 pairs): the fine stage builds its
// pyramid once and looks it up at each of its 2 iterations; the coarse stage
// builds its segment volume once. Each iteration here runs that forward
// with the features requiring a gradient, then the backward of a weighted
// sum. Matches lie near their own pixel (+- 8 px), as between neighbouring
// views, so the memory access has the locality of a real step. The C
// allocator keeps every freed block, as dispmvs_train sets it (the setting
// then stays for the rest of the process: hence --benchmark_filter).
// Arguments: implementation (0 ATen ops, 1 fused), intra-op threads.
constexpr int64_t kTrainPairs = 10, kTrainWidth = 640, kTrainHeight = 480;

struct TrainingProblem {
  torch::Tensor source, reference, base_xy, dir, eflow, weights;
};

TrainingProblem MakeTrainingProblem(int64_t stride, int64_t channels, int64_t outputs_per_pixel) {
  const int64_t h = kTrainHeight / stride, w = kTrainWidth / stride;
  torch::manual_seed(0);
  TrainingProblem p;
  p.source = torch::randn({kTrainPairs, channels, h, w});
  p.reference = torch::randn({kTrainPairs, channels, h, w});
  const torch::Tensor x =
      torch::arange(w, torch::kFloat).view({1, 1, w}).expand({kTrainPairs, h, w});
  const torch::Tensor y =
      torch::arange(h, torch::kFloat).view({1, h, 1}).expand({kTrainPairs, h, w});
  const double spread = 8.0 / static_cast<double>(stride / 4);
  p.base_xy = torch::stack({x + torch::randn({kTrainPairs, h, w}) * spread,
                            y + torch::randn({kTrainPairs, h, w}) * spread},
                           1);
  const torch::Tensor angle = torch::rand({kTrainPairs, 1, h, w}) * 6.2832;
  p.dir = torch::cat({torch::cos(angle), torch::sin(angle)}, 1);
  p.eflow = torch::randn({kTrainPairs, 1, h, w});
  if (outputs_per_pixel > 0) p.weights = torch::randn({kTrainPairs, outputs_per_pixel, h, w});
  return p;
}

dispmvs::model::CorrelationImpl ImplArgument(const benchmark::State& state) {
  return state.range(0) == 1 ? dispmvs::model::CorrelationImpl::kAuto
                             : dispmvs::model::CorrelationImpl::kAtenOps;
}

void BM_FineStageTraining(benchmark::State& state) {
  dispmvs::model::KeepAllFreedTensorMemory();
  torch::set_num_threads(static_cast<int>(state.range(1)));
  const ModelConfig config = ModelConfig::Small();
  const int64_t levels = config.fine_levels, samples = config.fine_samples, iterations = 2;
  const TrainingProblem p = MakeTrainingProblem(4, config.match_fine_channels, levels * samples);
  for (auto _ : state) {
    const torch::Tensor source = p.source.clone().requires_grad_(true);
    const torch::Tensor reference = p.reference.clone().requires_grad_(true);
    const EpipolarCorrelation correlation(source, levels, samples, ImplArgument(state));
    torch::Tensor loss = torch::zeros({});
    for (int64_t t = 0; t < iterations; ++t) {
      const torch::Tensor eflow = p.eflow + static_cast<double>(t);
      loss = loss + (correlation.Lookup(reference, p.base_xy, p.dir, eflow).cost * p.weights).sum();
    }
    loss.backward();
    benchmark::DoNotOptimize(source.grad().data_ptr());
  }
  state.SetLabel(ImplArgument(state) == dispmvs::model::CorrelationImpl::kAuto ? "fused"
                                                                                : "ATen ops");
}

void BM_SegmentVolumeTraining(benchmark::State& state) {
  dispmvs::model::KeepAllFreedTensorMemory();
  torch::set_num_threads(static_cast<int>(state.range(1)));
  const ModelConfig config = ModelConfig::Small();
  const TrainingProblem p = MakeTrainingProblem(16, config.match_coarse_channels, 0);
  // Segments as long as the coarse map's width: the length of a typical
  // segment across the 40x30 map.
  dispmvs::model::EpipolarSegment segment;
  segment.base_xy = p.base_xy;
  segment.dir = p.dir;
  segment.start = torch::full_like(p.eflow, -20.0);
  segment.end = torch::full_like(p.eflow, 20.0);
  segment.valid = torch::ones_like(p.eflow, torch::kBool);
  for (auto _ : state) {
    const torch::Tensor source = p.source.clone().requires_grad_(true);
    const torch::Tensor reference = p.reference.clone().requires_grad_(true);
    const dispmvs::model::SegmentCorrelation volume(reference, source, segment,
                                                   config.coarse_levels, config.coarse_samples,
                                                   ImplArgument(state));
    volume.volume().sum().backward();
    benchmark::DoNotOptimize(source.grad().data_ptr());
  }
  state.SetLabel(ImplArgument(state) == dispmvs::model::CorrelationImpl::kAuto ? "fused"
                                                                                : "ATen ops");
}

void TrainingShapes(benchmark::internal::Benchmark* b) {
  b->ArgNames({"fused", "threads"});
  for (int64_t threads = 1; threads <= 2; ++threads) {
    for (int64_t fused = 0; fused <= 1; ++fused) b->Args({fused, threads});
  }
  b->Unit(benchmark::kMillisecond)->UseRealTime();
}

BENCHMARK(BM_FineStageTraining)->Apply(TrainingShapes);
BENCHMARK(BM_SegmentVolumeTraining)->Apply(TrainingShapes);

BENCHMARK(BM_Pyramid)->Apply(ForwardPassShapes);
BENCHMARK(BM_Lookup)->Apply(ForwardPassShapes);
BENCHMARK(BM_LookupSamplingOnly)->Apply(ForwardPassShapes);
BENCHMARK(BM_LookupDotOnly)->Apply(ForwardPassShapes);

}  // namespace

BENCHMARK_MAIN();
