#pragma once
// Wall time spent in each stage of a DispMvsNet forward pass, for
// dispmvs_bench's breakdown. The network times its stages only while a timer
// is attached (DispMvsNetImpl::set_stage_timer); otherwise a section costs one
// null-pointer test.
//
// Stages (what each covers in dispmvs_net.cc):
//   encoders     the matching and context feature encoders (both stages' maps)
//   correlation  the source feature pyramids and every epipolar lookup
//   update       the GRU update blocks and their upsampling-mask heads
//   upsampling   convex and bilinear upsampling of depth and confidence
//   geometry     epipolar lines, projection, E-flow <-> pixel, triangulation,
//                fusion of the per-source inverse depths, the random start
// What is left of the total (padding, per-source repeats, bookkeeping) is
// "other": the caller measures the whole pass and subtracts.
//
// Sections do not nest: each stage boundary is a section of its own. On a GPU
// kernels run asynchronously, so the caller passes a `synchronize` callback
// (e.g. torch::cuda::synchronize) that runs at every section boundary; the
// times then attribute kernels to the stage that launched them, at the cost
// of a slower pass. On the CPU no callback is needed.

#include <array>
#include <chrono>
#include <cstddef>
#include <functional>
#include <string>

namespace dispmvs::model {

enum class NetStage : std::size_t { kEncoders = 0, kCorrelation, kUpdate, kUpsampling, kGeometry };
constexpr std::size_t kNumNetStages = 5;

// "encoders", "correlation", "update", "upsampling", "geometry".
const char* NetStageName(NetStage stage);

class StageTimer {
 public:
  explicit StageTimer(std::function<void()> synchronize = {});

  // Adds the time between construction and destruction to one stage.
  class Section {
   public:
    Section(StageTimer* timer, NetStage stage);  // timer may be null: no-op
    ~Section();
    Section(const Section&) = delete;
    Section& operator=(const Section&) = delete;

   private:
    StageTimer* timer_;
    NetStage stage_;
    std::chrono::steady_clock::time_point start_;
  };

  double seconds(NetStage stage) const { return seconds_[static_cast<std::size_t>(stage)]; }
  // Number of sections timed for `stage` since the last Reset().
  long count(NetStage stage) const { return counts_[static_cast<std::size_t>(stage)]; }
  double total_seconds() const;  // sum over the stages
  void Reset();

 private:
  void Synchronize() const;

  std::function<void()> synchronize_;
  std::array<double, kNumNetStages> seconds_{};
  std::array<long, kNumNetStages> counts_{};
};

}  // namespace dispmvs::model
