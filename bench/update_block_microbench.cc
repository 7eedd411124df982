// Microbenchmarks (Google Benchmark) of the GRU update block
// (model/update_block.h), more than half of the network's time: one call of
// the block on every (reference, source) pair of a stage, as the inference
// driver makes it, and the alternatives measured against it.
//
//   update_block_microbench [--benchmark_filter=Fine] [--benchmark_repetitions=3]
//
// Shapes: the small configuration (hidden 48, context 48, correlation
// 2 levels x 5 samples at the fine stage, 4 x 9 at the coarse one) with
// N = 5 sources, at 640x512 (fine 160x128, coarse 40x32). Arguments: stage
// (0 coarse, 1 fine), intra-op threads.
//
//  * BM_Block:           block->forward() on all 5 pairs at once, NCHW
//                        (what the network did before UpdateInChunks).
//  * BM_BlockInChunks:   UpdateInChunks with the driver's budget of 2^16
//                        pixels per call (fine: 3 + 2 pairs; coarse: one call).
//  * BM_BlockInChunksBf16: the same with the block's convolutions in bf16
//                        (--precision bf16; needs native bf16 to be fast).
//  * BM_BlockChannelsLast: weights and inputs in channels-last layout, which
//                        lets oneDNN skip its layout conversions; slower
//                        with LibTorch 1.13 on this CPU (docs/benchmarks.md).
//  * BM_ContextTerms:    the context's share of the GRU gates, which the
//                        block variants above take precomputed: the network
//                        computes it once per reference and stage, so a
//                        stage of T iterations adds 1/T of this per call.

#include <cstdint>
#include <string>

#include <benchmark/benchmark.h>
#include <torch/torch.h>

#include "model/config.h"
#include "model/host_allocator.h"
#include "model/precision.h"
#include "model/update_block.h"

namespace {

using dispmvs::model::ModelConfig;
using dispmvs::model::UpdateBlock;
using dispmvs::model::UpdateBlockOutput;

constexpr int64_t kSources = 5;

struct Problem {
  UpdateBlock block{nullptr};
  torch::Tensor hidden, context, context_terms, cost, eflow;
};

Problem MakeProblem(const benchmark::State& state) {
  const bool fine = state.range(0) == 1;
  torch::set_num_threads(static_cast<int>(state.range(1)));
  dispmvs::model::KeepFreedTensorMemory();  // as the programs run the block
  const ModelConfig config = ModelConfig::SmallV2();
  const int64_t hidden = fine ? config.hidden_fine : config.hidden_coarse;
  const int64_t context = fine ? config.context_input_fine : config.context_input_coarse;
  const int64_t correlation = fine ? config.fine_levels * config.fine_samples
                                   : config.coarse_levels * config.coarse_samples;
  const int64_t h = fine ? 128 : 32, w = fine ? 160 : 40;  // 640x512 at 1/4 and 1/16
  torch::manual_seed(0);
  Problem p;
  p.block = UpdateBlock(correlation, hidden, context, 4);
  p.block->eval();
  p.hidden = torch::randn({kSources, hidden, h, w}).tanh();
  p.context = torch::randn({1, context, h, w}).relu();  // one reference
  p.context_terms = p.block->ContextTerms(p.context);
  p.cost = torch::randn({kSources, correlation, h, w});
  p.eflow = torch::randn({kSources, 1, h, w});
  return p;
}

void Label(benchmark::State& state) {
  state.SetLabel(std::string(state.range(0) == 1 ? "fine 160x128" : "coarse 40x32") + ", N=5, " +
                 std::to_string(state.range(1)) + " thread(s)");
}

void BM_Block(benchmark::State& state) {
  torch::NoGradGuard no_grad;
  Problem p = MakeProblem(state);
  for (auto _ : state) {
    const UpdateBlockOutput out = p.block->forward(p.hidden, p.context_terms, p.cost, p.eflow);
    benchmark::DoNotOptimize(out.hidden.data_ptr());
  }
  Label(state);
}

// The timing loop of the UpdateInChunks variants.
void TimeInChunks(benchmark::State& state, Problem& p) {
  for (auto _ : state) {
    const UpdateBlockOutput out = dispmvs::model::UpdateInChunks(
        p.block, p.hidden, p.context_terms, p.cost, p.eflow,
        dispmvs::model::kInferenceUpdatePixelsPerCall);
    benchmark::DoNotOptimize(out.hidden.data_ptr());
  }
  Label(state);
}

void BM_BlockInChunks(benchmark::State& state) {
  torch::NoGradGuard no_grad;
  Problem p = MakeProblem(state);
  TimeInChunks(state, p);
}

// What inference runs with --precision bf16: UpdateInChunks with every
// convolution of the block in bf16 (model/precision.h), the state in fp32.
// Needs native bf16 (CpuHasNativeBf16) to be fast; skipped without it.
void BM_BlockInChunksBf16(benchmark::State& state) {
  if (!dispmvs::model::CpuHasNativeBf16()) {
    state.SkipWithError("this CPU has no native bf16 (AVX-512 BF16 or AMX)");
    return;
  }
  torch::NoGradGuard no_grad;
  Problem p = MakeProblem(state);
  p.block->set_precision(dispmvs::model::Precision::kBFloat16);
  p.context_terms = p.block->ContextTerms(p.context);
  TimeInChunks(state, p);
}

void BM_BlockChannelsLast(benchmark::State& state) {
  torch::NoGradGuard no_grad;
  Problem p = MakeProblem(state);
  const auto layout = torch::MemoryFormat::ChannelsLast;
  for (auto& parameter : p.block->parameters()) {
    if (parameter.dim() == 4) parameter.set_data(parameter.contiguous(layout));
  }
  const torch::Tensor hidden = p.hidden.contiguous(layout),
                      terms = p.context_terms.contiguous(layout), cost = p.cost.contiguous(layout),
                      eflow = p.eflow.contiguous(layout);
  for (auto _ : state) {
    const UpdateBlockOutput out = p.block->forward(hidden, terms, cost, eflow);
    benchmark::DoNotOptimize(out.hidden.data_ptr());
  }
  Label(state);
}

void BM_ContextTerms(benchmark::State& state) {
  torch::NoGradGuard no_grad;
  Problem p = MakeProblem(state);
  for (auto _ : state) {
    const torch::Tensor terms = p.block->ContextTerms(p.context);
    benchmark::DoNotOptimize(terms.data_ptr());
  }
  Label(state);
}

void Shapes(benchmark::internal::Benchmark* b) {
  for (const int64_t stage : {0, 1}) b->Args({stage, 2});
  b->Unit(benchmark::kMillisecond)->UseRealTime();
}

BENCHMARK(BM_Block)->Apply(Shapes);
BENCHMARK(BM_BlockInChunks)->Apply(Shapes);
BENCHMARK(BM_BlockInChunksBf16)->Apply(Shapes);
BENCHMARK(BM_BlockChannelsLast)->Apply(Shapes);
BENCHMARK(BM_ContextTerms)->Apply(Shapes);

}  // namespace

BENCHMARK_MAIN();
