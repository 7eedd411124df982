#include "model/large_block_cache.h"

#include <cstddef>
#include <cstdint>
#include <stdexcept>

#include <c10/core/CPUAllocator.h>
#include <gtest/gtest.h>
#include <torch/torch.h>

// The cache replaces LibTorch's CPU allocator for the whole process: this
// test binary holds these tests alone. ctest runs each in a process of its
// own; run together, they run in this order, and each starts from what the
// ones before left (hence the counters read relative to "before").
namespace dispmvs::model {
namespace {

constexpr std::size_t kMiB = std::size_t{1} << 20;

LargeBlockCacheOptions Budget(std::size_t max_cached_mib) {
  LargeBlockCacheOptions options;
  options.max_cached_bytes = max_cached_mib * kMiB;
  return options;
}

torch::Tensor Bytes(std::size_t bytes) {
  return torch::empty({static_cast<int64_t>(bytes)}, torch::kUInt8);
}

TEST(LargeBlockCacheTest, NothingBeforeInstallation) {
  EXPECT_FALSE(LargeBlockCacheInstalled());
  const LargeBlockCacheStats stats = LargeBlockCacheCounters();
  EXPECT_EQ(stats.hits + stats.misses, 0);
  EXPECT_EQ(ReleaseCachedBlocks(), 0u);
  LargeBlockCacheOptions bad;
  bad.min_block_bytes = 0;
  EXPECT_THROW(InstallLargeBlockCache(bad), std::invalid_argument);
  EXPECT_FALSE(LargeBlockCacheInstalled());
}

TEST(LargeBlockCacheTest, FreedBlockServesTheNextRequestOfItsSize) {
  InstallLargeBlockCache(Budget(256));
  ASSERT_TRUE(LargeBlockCacheInstalled());
  const LargeBlockCacheStats before = LargeBlockCacheCounters();
  void* first = nullptr;
  {
    torch::Tensor t = Bytes(40 * kMiB);
    first = t.data_ptr();
    t.fill_(7);  // the block is writable over its whole size
    const uint8_t* bytes = t.data_ptr<uint8_t>();
    EXPECT_EQ(bytes[0], 7);
    EXPECT_EQ(bytes[40 * kMiB - 1], 7);
    const LargeBlockCacheStats held = LargeBlockCacheCounters();
    EXPECT_EQ(held.misses, before.misses + 1);
    EXPECT_EQ(held.live_bytes, before.live_bytes + 40 * kMiB);
  }
  EXPECT_EQ(LargeBlockCacheCounters().cached_bytes, before.cached_bytes + 40 * kMiB);
  {
    // A request that rounds to the same whole 2 MiB pages gets the same block.
    const torch::Tensor again = Bytes(40 * kMiB - 5);
    EXPECT_EQ(again.data_ptr(), first);
    const LargeBlockCacheStats held = LargeBlockCacheCounters();
    EXPECT_EQ(held.hits, before.hits + 1);
    EXPECT_EQ(held.misses, before.misses + 1);
  }
  EXPECT_EQ(ReleaseCachedBlocks(), before.cached_bytes + 40 * kMiB);
  EXPECT_EQ(LargeBlockCacheCounters().cached_bytes, 0u);
}

TEST(LargeBlockCacheTest, SizesRoundUpToWholeHugePages) {
  InstallLargeBlockCache(Budget(256));
  const std::size_t live = LargeBlockCacheCounters().live_bytes;
  const torch::Tensor t = Bytes(33 * kMiB + 1);
  EXPECT_EQ(LargeBlockCacheCounters().live_bytes, live + 34 * kMiB);
}

TEST(LargeBlockCacheTest, SmallBlocksGoToTheOtherAllocator) {
  InstallLargeBlockCache(Budget(256));
  const LargeBlockCacheStats before = LargeBlockCacheCounters();
  {
    const torch::Tensor small = Bytes(31 * kMiB);
    EXPECT_EQ(LargeBlockCacheCounters().live_bytes, before.live_bytes);
  }
  const LargeBlockCacheStats after = LargeBlockCacheCounters();
  EXPECT_EQ(after.hits + after.misses, before.hits + before.misses);
  EXPECT_EQ(after.cached_bytes, before.cached_bytes);
}

TEST(LargeBlockCacheTest, KeepsTheNewestBlocksWithinTheBudget) {
  InstallLargeBlockCache(Budget(100));
  ReleaseCachedBlocks();
  void* newest = nullptr;
  {
    torch::Tensor a = Bytes(40 * kMiB), b = Bytes(40 * kMiB), c = Bytes(40 * kMiB);
    newest = c.data_ptr();
    a.reset();
    b.reset();
    EXPECT_EQ(LargeBlockCacheCounters().cached_bytes, 80 * kMiB);
    c.reset();  // 120 MiB would exceed 100: the oldest (a's) goes
    EXPECT_EQ(LargeBlockCacheCounters().cached_bytes, 80 * kMiB);
  }
  const torch::Tensor again = Bytes(40 * kMiB);
  EXPECT_EQ(again.data_ptr(), newest);
  {
    // A block larger than the whole budget is never kept.
    torch::Tensor huge = Bytes(128 * kMiB);
    const std::size_t cached = LargeBlockCacheCounters().cached_bytes;
    huge.reset();
    EXPECT_EQ(LargeBlockCacheCounters().cached_bytes, cached);
  }
  // A smaller budget gives back what exceeds it at once.
  InstallLargeBlockCache(Budget(0));
  EXPECT_EQ(LargeBlockCacheCounters().cached_bytes, 0u);
}

TEST(LargeBlockCacheTest, KeptBlocksGiveWayToARequestNoneFits) {
  InstallLargeBlockCache(Budget(256));
  ReleaseCachedBlocks();
  const LargeBlockCacheStats before = LargeBlockCacheCounters();
  {
    torch::Tensor a = Bytes(40 * kMiB), b = Bytes(50 * kMiB);
    a.reset();  // kept: 40
    b.reset();  // kept: 90, b's the newest
  }
  EXPECT_EQ(LargeBlockCacheCounters().cached_bytes, 90 * kMiB);
  {
    // 44 MiB fits neither: the oldest kept block (40) is not enough to make
    // room, so b's goes too, and live + kept stays at the 90 MiB that was
    // mapped before.
    const torch::Tensor c = Bytes(44 * kMiB);
    const LargeBlockCacheStats held = LargeBlockCacheCounters();
    EXPECT_EQ(held.cached_bytes, 0u);
    EXPECT_EQ(held.misses, before.misses + 3);
    EXPECT_LE(held.live_bytes - before.live_bytes + held.cached_bytes, 90 * kMiB);
  }
  {
    // c's 44 is kept; a 40 MiB request does not fit it and takes its place.
    torch::Tensor a = Bytes(40 * kMiB);
    EXPECT_EQ(LargeBlockCacheCounters().cached_bytes, 0u);
    torch::Tensor b = Bytes(40 * kMiB);
    a.reset();
    b.reset();
  }
  EXPECT_EQ(LargeBlockCacheCounters().cached_bytes, 80 * kMiB);
  {
    // 36 MiB fits neither 40: the oldest alone makes room.
    const torch::Tensor d = Bytes(36 * kMiB);
    EXPECT_EQ(LargeBlockCacheCounters().cached_bytes, 40 * kMiB);
    // A same-size request still takes the other.
    const int64_t hits = LargeBlockCacheCounters().hits;
    const torch::Tensor e = Bytes(40 * kMiB);
    EXPECT_EQ(LargeBlockCacheCounters().cached_bytes, 0u);
    EXPECT_EQ(LargeBlockCacheCounters().hits, hits + 1);
  }
}

TEST(LargeBlockCacheTest, RawAllocationsOfEitherSizeAreFreed) {
  InstallLargeBlockCache(Budget(256));
  ReleaseCachedBlocks();
  c10::Allocator* allocator = c10::GetCPUAllocator();
  const std::size_t live = LargeBlockCacheCounters().live_bytes;
  void* large = allocator->raw_allocate(36 * kMiB);
  void* small = allocator->raw_allocate(kMiB);
  EXPECT_EQ(LargeBlockCacheCounters().live_bytes, live + 36 * kMiB);
  allocator->raw_deallocate(large);
  allocator->raw_deallocate(small);  // handed to the allocator that made it
  EXPECT_EQ(LargeBlockCacheCounters().live_bytes, live);
  EXPECT_EQ(LargeBlockCacheCounters().cached_bytes, 36 * kMiB);
}

TEST(LargeBlockCacheTest, PeakLiveBytesFollowsTheLargestMomentAndResets) {
  InstallLargeBlockCache(Budget(256));
  ResetPeakLiveBytes();
  const std::size_t base = LargeBlockCacheCounters().live_bytes;
  {
    const torch::Tensor a = Bytes(64 * kMiB);
    const torch::Tensor b = Bytes(32 * kMiB);
  }
  { const torch::Tensor c = Bytes(64 * kMiB); }
  EXPECT_EQ(LargeBlockCacheCounters().peak_live_bytes, base + 96 * kMiB);
  ResetPeakLiveBytes();
  EXPECT_EQ(LargeBlockCacheCounters().peak_live_bytes, base);
}

}  // namespace
}  // namespace dispmvs::model
