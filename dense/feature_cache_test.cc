#include "dense/feature_cache.h"

#include <gtest/gtest.h>

namespace dispmvs::dense {
namespace {

// Features of `floats` floats in all, marked with `mark`.
model::FeaturePyramid Features(int64_t floats, float mark) {
  return {torch::full({1, floats / 2}, mark), torch::full({1, floats - floats / 2}, mark)};
}

TEST(FeatureCacheTest, KeepsWhatFitsAndDropsTheLeastRecentlyUsed) {
  FeatureCache cache(3 * 100 * sizeof(float));  // three entries of 100 floats
  int encoded = 0;
  auto get = [&](int64_t id, int width = 8) {
    return cache.Get({id, width, 6}, [&] {
      ++encoded;
      return Features(100, static_cast<float>(id));
    });
  };
  get(1);
  get(2);
  get(3);
  EXPECT_EQ(encoded, 3);
  EXPECT_EQ(get(1).coarse[0][0].item<float>(), 1.0f);  // hit: 1 is now the most recent
  EXPECT_EQ(encoded, 3);
  get(4);  // evicts 2, the least recently used
  EXPECT_EQ(cache.stats().evictions, 1);
  get(1);
  get(3);
  EXPECT_EQ(encoded, 4);
  get(2);  // was evicted: encoded again (evicting 4)
  EXPECT_EQ(encoded, 5);
  get(2, 16);  // the same image at another size is another entry
  EXPECT_EQ(encoded, 6);
  EXPECT_EQ(cache.stats().hits, 3);
  EXPECT_EQ(cache.stats().misses, 6);
  EXPECT_EQ(cache.stats().bytes, 3 * 100 * sizeof(float));
  EXPECT_EQ(cache.stats().peak_bytes, 3 * 100 * sizeof(float));
}

TEST(FeatureCacheTest, ZeroBudgetOrOversizedFeaturesAreNeverKept) {
  FeatureCache none(0);
  int encoded = 0;
  for (int i = 0; i < 3; ++i) {
    const model::FeaturePyramid f = none.Get({7, 8, 6}, [&] {
      ++encoded;
      return Features(10, 7.0f);
    });
    EXPECT_EQ(f.fine.numel(), 5);
  }
  EXPECT_EQ(encoded, 3);
  EXPECT_EQ(none.stats().bytes, 0u);

  FeatureCache small(40 * sizeof(float));
  small.Get({1, 8, 6}, [] { return Features(30, 1.0f); });
  small.Get({2, 8, 6}, [] { return Features(50, 2.0f); });  // larger than the budget
  EXPECT_EQ(small.stats().evictions, 0);  // nothing dropped for it
  EXPECT_EQ(small.stats().bytes, 30 * sizeof(float));
}

}  // namespace
}  // namespace dispmvs::dense
