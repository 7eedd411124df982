#include "model/stage_timer.h"

#include <numeric>
#include <utility>

namespace dispmvs::model {

const char* NetStageName(NetStage stage) {
  switch (stage) {
    case NetStage::kEncoders: return "encoders";
    case NetStage::kCorrelation: return "correlation";
    case NetStage::kUpdate: return "update";
    case NetStage::kUpsampling: return "upsampling";
    case NetStage::kGeometry: return "geometry";
  }
  return "unknown";
}

StageTimer::StageTimer(std::function<void()> synchronize)
    : synchronize_(std::move(synchronize)) {}

void StageTimer::Synchronize() const {
  if (synchronize_) synchronize_();
}

double StageTimer::total_seconds() const {
  return std::accumulate(seconds_.begin(), seconds_.end(), 0.0);
}

void StageTimer::Reset() {
  seconds_.fill(0.0);
  counts_.fill(0);
}

StageTimer::Section::Section(StageTimer* timer, NetStage stage) : timer_(timer), stage_(stage) {
  if (timer_ == nullptr) return;
  // Work queued before the section belongs to whatever queued it.
  timer_->Synchronize();
  start_ = std::chrono::steady_clock::now();
}

StageTimer::Section::~Section() {
  if (timer_ == nullptr) return;
  timer_->Synchronize();
  const std::chrono::duration<double> elapsed = std::chrono::steady_clock::now() - start_;
  const auto index = static_cast<std::size_t>(stage_);
  timer_->seconds_[index] += elapsed.count();
  timer_->counts_[index] += 1;
}

}  // namespace dispmvs::model
