#include "dense/feature_cache.h"

#include <algorithm>

namespace dispmvs::dense {

namespace {

std::size_t BytesOf(const model::FeaturePyramid& features) {
  std::size_t bytes = 0;
  for (const torch::Tensor* t : {&features.coarse, &features.fine}) {
    if (t->defined()) bytes += static_cast<std::size_t>(t->numel()) * t->element_size();
  }
  return bytes;
}

}  // namespace

model::FeaturePyramid FeatureCache::Get(const Key& key,
                                        const std::function<model::FeaturePyramid()>& encode) {
  if (const auto found = index_.find(key); found != index_.end()) {
    ++stats_.hits;
    entries_.splice(entries_.begin(), entries_, found->second);  // now most recent
    return found->second->features;
  }
  ++stats_.misses;
  model::FeaturePyramid features = encode();
  const std::size_t bytes = BytesOf(features);
  if (bytes > budget_bytes_) return features;  // would never fit
  while (stats_.bytes + bytes > budget_bytes_) {
    const Entry& oldest = entries_.back();
    stats_.bytes -= oldest.bytes;
    index_.erase(oldest.key);
    entries_.pop_back();
    ++stats_.evictions;
  }
  entries_.push_front(Entry{key, features, bytes});
  index_[key] = entries_.begin();
  stats_.bytes += bytes;
  stats_.peak_bytes = std::max(stats_.peak_bytes, stats_.bytes);
  return features;
}

}  // namespace dispmvs::dense
