#include "model/host_allocator.h"

#include <cstddef>
#include <cstdint>

#include <gtest/gtest.h>
#include <torch/torch.h>

#if defined(__GLIBC__)
#include <malloc.h>
#endif

namespace dispmvs::model {
namespace {

#if defined(__GLIBC__) && (__GLIBC__ > 2 || __GLIBC_MINOR__ >= 33)  // mallinfo2

constexpr int64_t kMiB = 1024 * 1024;

// How many blocks glibc has mapped (mmap) while a tensor of `bytes` lives.
size_t MappedBlocksWhileHolding(int64_t bytes) {
  const torch::Tensor held = torch::empty({bytes}, torch::kUInt8);
  return mallinfo2().hblks;
}

// A block size above 32 MiB that no free chunk of the heap can serve, so
// that glibc has to choose between mapping it and growing the heap (it maps
// only then: a free chunk that fits is used whatever the settings).
int64_t LargerThanAnyFreeChunk() {
  return 64 * kMiB + static_cast<int64_t>(mallinfo2().fordblks);
}

TEST(HostAllocatorTest, InferenceSettingMapsOnlyBlocksAbove32MiB) {
  ASSERT_TRUE(KeepFreedTensorMemory());
  const size_t mapped = mallinfo2().hblks;
  EXPECT_EQ(MappedBlocksWhileHolding(16 * kMiB), mapped);
  EXPECT_EQ(MappedBlocksWhileHolding(LargerThanAnyFreeChunk()), mapped + 1);
  EXPECT_EQ(mallinfo2().hblks, mapped);  // unmapped again on free
}

TEST(HostAllocatorTest, TrainingSettingMapsNoBlockAndKeepsWhatIsFreed) {
  ASSERT_TRUE(KeepAllFreedTensorMemory());
  const size_t mapped = mallinfo2().hblks;
  const int64_t bytes = LargerThanAnyFreeChunk();
  EXPECT_EQ(MappedBlocksWhileHolding(bytes), mapped);
  // The heap grew to hold the block and, once it is freed, keeps it for
  // later allocations instead of returning it to the system.
  EXPECT_GE(mallinfo2().fordblks, static_cast<size_t>(bytes));
}

TEST(HostAllocatorTest, InferenceSettingUndoesTheTrainingOne) {
  ASSERT_TRUE(KeepAllFreedTensorMemory());
  ASSERT_TRUE(KeepFreedTensorMemory());
  const size_t mapped = mallinfo2().hblks;
  EXPECT_EQ(MappedBlocksWhileHolding(LargerThanAnyFreeChunk()), mapped + 1);
}

#else

TEST(HostAllocatorTest, OtherCLibrariesAreLeftAlone) {
  EXPECT_FALSE(KeepFreedTensorMemory());
  EXPECT_FALSE(KeepAllFreedTensorMemory());
}

#endif

}  // namespace
}  // namespace dispmvs::model
