#pragma once
// The matching encoder's features of workspace images, kept across stereo
// problems: an image is the source of several references (and a reference
// itself), and its features depend on the image and its size alone, so the
// photometric pass encodes it once instead of once per problem. Least
// recently used images go first when the budget is full. Internal to
// DepthEstimator (LibTorch behind dense/depth_estimator.h).

#include <cstddef>
#include <cstdint>
#include <functional>
#include <list>
#include <map>
#include <tuple>

#include "model/encoder.h"

namespace dispmvs::dense {

class FeatureCache {
 public:
  struct Key {
    int64_t image_id = -1;
    int width = 0, height = 0;  // the size the image was brought to
    bool operator<(const Key& other) const {
      return std::tie(image_id, width, height) <
             std::tie(other.image_id, other.width, other.height);
    }
  };
  struct Stats {
    int64_t hits = 0, misses = 0, evictions = 0;
    std::size_t bytes = 0, peak_bytes = 0;
  };

  // budget_bytes = 0: nothing is kept (every Get encodes).
  explicit FeatureCache(std::size_t budget_bytes) : budget_bytes_(budget_bytes) {}

  // The features of `key`, from the cache or from `encode` (then kept, if
  // they fit in the budget, after dropping least recently used entries).
  model::FeaturePyramid Get(const Key& key, const std::function<model::FeaturePyramid()>& encode);

  const Stats& stats() const { return stats_; }

 private:
  struct Entry {
    Key key;
    model::FeaturePyramid features;
    std::size_t bytes = 0;
  };
  std::size_t budget_bytes_;
  std::list<Entry> entries_;  // most recently used first
  std::map<Key, std::list<Entry>::iterator> index_;
  Stats stats_;
};

}  // namespace dispmvs::dense
