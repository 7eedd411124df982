// The fusion view cache: a memory budget kept by dropping the least recently
// used views that are not in use, unusable views remembered; and fusion from
// the cache under a tight budget gives exactly the points of fusion from
// views all held at once, with each view loaded a bounded number of times.

#include "fusion/view_cache.h"

#include <gtest/gtest.h>

#include <memory>
#include <stdexcept>
#include <vector>

#include "fusion/point_fusion.h"
#include "fusion/test_scene.h"

namespace dispmvs::fusion {
namespace {

using testing::Camera;
using testing::MakeDepthView;
using testing::Scene;

// A view whose maps take `pixels` x 4 floats x 4 bytes.
FusionView ViewOfSize(int pixels) {
  FusionView view;
  view.geometry.depth = colmap_io::DenseArray(pixels, 1, 1, 1.0f);
  view.geometry.confidence = colmap_io::DenseArray(pixels, 1, 1, 1.0f);
  view.normals = colmap_io::DenseArray(pixels, 1, 2, 0.0f);
  return view;
}

TEST(FusionViewCacheTest, KeepsTheBudgetByDroppingTheLeastRecentlyUsed) {
  std::vector<int> loaded;
  FusionViewCache cache(
      [&loaded](int index) {
        loaded.push_back(index);
        return std::make_shared<const FusionView>(ViewOfSize(10));  // 160 bytes
      },
      /*max_bytes=*/3 * 160);
  EXPECT_EQ(FusionViewCache::BytesOf(ViewOfSize(10)), 160u);
  for (int index : {0, 1, 2}) ASSERT_NE(cache.Get(index), nullptr);
  cache.Get(0);  // now 1 is the least recently used
  cache.Get(3);  // drops 1
  EXPECT_EQ(cache.held_bytes(), 3u * 160u);
  cache.Get(0);
  cache.Get(2);
  EXPECT_EQ(loaded, (std::vector<int>{0, 1, 2, 3}));  // 0 and 2 were still held
  cache.Get(1);
  EXPECT_EQ(loaded.back(), 1);  // loaded again
  EXPECT_EQ(cache.loads(), 5u);
  EXPECT_EQ(cache.peak_bytes(), 3u * 160u);
}

TEST(FusionViewCacheTest, NeverDropsAViewInUse) {
  FusionViewCache cache([](int) { return std::make_shared<const FusionView>(ViewOfSize(10)); },
                        /*max_bytes=*/160);
  const std::shared_ptr<const FusionView> in_use = cache.Get(0);
  const std::shared_ptr<const FusionView> also = cache.Get(1);  // over budget: 0 is in use
  EXPECT_EQ(cache.held_bytes(), 320u);
  EXPECT_EQ(cache.Get(0), in_use);  // the same object, not reloaded
  EXPECT_EQ(cache.loads(), 2u);
}

TEST(FusionViewCacheTest, RemembersUnusableViews) {
  int calls = 0;
  FusionViewCache cache(
      [&calls](int) {
        ++calls;
        return std::shared_ptr<const FusionView>();
      },
      1000);
  EXPECT_EQ(cache.Get(4), nullptr);
  EXPECT_EQ(cache.Get(4), nullptr);
  EXPECT_EQ(calls, 1);
}

// A row of 8 cameras over the two-plane scene, each with its two neighbours
// on either side as sources, fused from views all held and from a cache
// holding about 5 views' maps.
TEST(FusionViewCacheTest, FusionFromATightCacheGivesTheSamePoints) {
  const Scene scene = Scene::TwoPlanes();
  std::vector<Camera> cameras;
  for (int i = 0; i < 8; ++i) {
    const Eigen::Vector3d centre(-1.4 + 0.4 * i, 0.05 * (i % 3), 0.1 * (i % 2));
    cameras.push_back(testing::LookAt(centre, Eigen::Vector3d(0.2, 0.1, 10), 80, 60, 62.0, 58.0,
                                      40.7, 28.3));
  }
  std::vector<FusionView> views;
  for (std::size_t i = 0; i < cameras.size(); ++i) {
    FusionView view;
    view.geometry = MakeDepthView(cameras[i], scene.RenderDepth(cameras[i]));
    view.normals = scene.RenderNormals(cameras[i]);
    view.image = scene.RenderImage(cameras[i], CV_8UC3);
    view.vis_index = static_cast<uint32_t>(i);
    for (int j = static_cast<int>(i) - 2; j <= static_cast<int>(i) + 2; ++j) {
      if (j >= 0 && j < 8 && j != static_cast<int>(i)) view.source_views.push_back(j);
    }
    views.push_back(std::move(view));
  }
  const GeometricFilterOptions options;
  FusionStats all_stats, cached_stats;
  const std::vector<FusedPoint> all = FusePoints(views, options, &all_stats);
  ASSERT_GT(all.size(), 1000u);

  const std::size_t view_bytes = FusionViewCache::BytesOf(views[0]);
  std::vector<int> loads(views.size(), 0);
  FusionViewCache cache(
      [&](int index) {
        ++loads[static_cast<std::size_t>(index)];
        return std::make_shared<const FusionView>(views[static_cast<std::size_t>(index)]);
      },
      5 * view_bytes);
  const std::vector<FusedPoint> cached =
      FusePoints(static_cast<int>(views.size()), &cache, options, &cached_stats);
  ASSERT_EQ(cached.size(), all.size());
  for (std::size_t i = 0; i < all.size(); ++i) {
    ASSERT_EQ(cached[i].xyz, all[i].xyz) << i;
    ASSERT_EQ(cached[i].normal, all[i].normal) << i;
    ASSERT_EQ(cached[i].rgb, all[i].rgb) << i;
    ASSERT_EQ(cached[i].visibility, all[i].visibility) << i;
  }
  EXPECT_EQ(cached_stats.points_per_view, all_stats.points_per_view);
  // Freeing each view's consumed mask after its last use changes nothing;
  // announcing a last use too early is caught.
  std::vector<std::vector<int>> sources;
  for (const FusionView& view : views) sources.push_back(view.source_views);
  const std::vector<int> last_use = LastUses(sources);
  EXPECT_EQ(last_use, (std::vector<int>{2, 3, 4, 5, 6, 7, 7, 7}));
  FusionViewCache freeing_cache(
      [&](int index) {
        return std::make_shared<const FusionView>(views[static_cast<std::size_t>(index)]);
      },
      5 * FusionViewCache::BytesOf(views[0]));
  std::vector<FusedPoint> freed;
  FusePoints(static_cast<int>(views.size()), &freeing_cache, options,
             [&freed](FusedPoint&& point) { freed.push_back(std::move(point)); }, nullptr,
             last_use);
  ASSERT_EQ(freed.size(), all.size());
  for (std::size_t i = 0; i < all.size(); ++i) ASSERT_EQ(freed[i].xyz, all[i].xyz) << i;
  std::vector<int> too_early = last_use;
  too_early[3] = 2;  // view 3 is still a source of references 4 and 5
  FusionViewCache again(
      [&](int index) {
        return std::make_shared<const FusionView>(views[static_cast<std::size_t>(index)]);
      },
      5 * FusionViewCache::BytesOf(views[0]));
  EXPECT_THROW(FusePoints(static_cast<int>(views.size()), &again, options,
                          [](FusedPoint&&) {}, nullptr, too_early),
               std::logic_error);
  EXPECT_EQ(cached_stats.consumed_pixels_per_view, all_stats.consumed_pixels_per_view);
  EXPECT_LE(cache.peak_bytes(), 5 * view_bytes);
  // References in order, sources their neighbours: each view is loaded once.
  for (std::size_t i = 0; i < loads.size(); ++i) EXPECT_EQ(loads[i], 1) << i;

  // A view that cannot be loaded is left out, as in the vector form without it.
  FusionViewCache without_3(
      [&](int index) {
        return index == 3 ? nullptr
                          : std::make_shared<const FusionView>(views[static_cast<std::size_t>(index)]);
      },
      5 * view_bytes);
  std::vector<FusionView> reduced;
  for (std::size_t i = 0; i < views.size(); ++i) {
    if (i == 3) continue;
    FusionView view = views[i];
    view.source_views.clear();
    for (int source : views[i].source_views) {
      if (source != 3) view.source_views.push_back(source < 3 ? source : source - 1);
    }
    reduced.push_back(std::move(view));
  }
  const std::vector<FusedPoint> left_out = FusePoints(8, &without_3, options);
  const std::vector<FusedPoint> expected = FusePoints(reduced, options);
  ASSERT_EQ(left_out.size(), expected.size());
  for (std::size_t i = 0; i < expected.size(); ++i) {
    ASSERT_EQ(left_out[i].xyz, expected[i].xyz) << i;
    ASSERT_EQ(left_out[i].visibility, expected[i].visibility) << i;
  }
}

}  // namespace
}  // namespace dispmvs::fusion
