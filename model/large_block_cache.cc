#include "model/large_block_cache.h"

#include <sys/mman.h>

#include <algorithm>
#include <atomic>
#include <list>
#include <mutex>
#include <stdexcept>
#include <string>
#include <unordered_map>

#include <c10/core/Allocator.h>
#include <c10/core/CPUAllocator.h>
#include <c10/util/Exception.h>

namespace dispmvs::model {
namespace {

// Blocks are whole transparent huge pages.
constexpr std::size_t kHugePage = std::size_t{2} << 20;

std::size_t RoundUpToHugePages(std::size_t bytes) {
  return (bytes + kHugePage - 1) / kHugePage * kHugePage;
}

class LargeBlockCache final : public c10::Allocator {
 public:
  explicit LargeBlockCache(c10::Allocator* smaller_blocks) : smaller_blocks_(smaller_blocks) {}

  void Configure(const LargeBlockCacheOptions& options) {
    const std::lock_guard<std::mutex> lock(mutex_);
    min_block_bytes_.store(options.min_block_bytes);
    max_cached_bytes_ = options.max_cached_bytes;
    EvictUntilCachedAtMost(max_cached_bytes_);
  }

  c10::DataPtr allocate(std::size_t bytes) const override {
    if (bytes < min_block_bytes_.load()) return smaller_blocks_->allocate(bytes);
    const std::size_t size = RoundUpToHugePages(bytes);
    void* block = TakeCached(size);
    if (block == nullptr) block = MapNew(size);
    return {block, block, &LargeBlockCache::Free, c10::Device(c10::DeviceType::CPU)};
  }

  // What raw_deallocate() calls (some LibTorch kernels allocate their
  // scratch buffers raw): Free, which hands blocks it does not know to the
  // smaller blocks' allocator.
  c10::DeleterFnPtr raw_deleter() const override { return &LargeBlockCache::Free; }

  LargeBlockCacheStats stats() const {
    const std::lock_guard<std::mutex> lock(mutex_);
    return stats_;
  }

  std::size_t ReleaseCached() {
    const std::lock_guard<std::mutex> lock(mutex_);
    const std::size_t released = stats_.cached_bytes;
    EvictUntilCachedAtMost(0);
    return released;
  }

  void ResetPeak() {
    const std::lock_guard<std::mutex> lock(mutex_);
    stats_.peak_live_bytes = stats_.live_bytes;
  }

  static LargeBlockCache* instance;

 private:
  struct Block {
    void* data = nullptr;
    std::size_t size = 0;
  };

  static void Free(void* data) { instance->Return(data); }

  // A kept block of exactly `size` bytes, the most recently freed first; null
  // if none.
  void* TakeCached(std::size_t size) const {
    const std::lock_guard<std::mutex> lock(mutex_);
    const auto found = std::find_if(cached_.begin(), cached_.end(),
                                    [&](const Block& block) { return block.size == size; });
    if (found == cached_.end()) return nullptr;
    void* data = found->data;
    cached_.erase(found);
    stats_.cached_bytes -= size;
    ++stats_.hits;
    MarkLive(data, size);
    return data;
  }

  void* MapNew(std::size_t size) const {
    {
      // Kept blocks of other sizes give way to the new one: the memory
      // mapped in all (live + kept) then grows only when nothing is kept,
      // i.e. it never exceeds the largest live total of the process, and
      // the cache adds nothing to the peak resident set.
      const std::lock_guard<std::mutex> lock(mutex_);
      EvictUntilCachedAtMost(stats_.cached_bytes > size ? stats_.cached_bytes - size : 0);
    }
    void* data = mmap(nullptr, size, PROT_READ | PROT_WRITE, MAP_PRIVATE | MAP_ANONYMOUS, -1, 0);
    if (data == MAP_FAILED) {
      // Kept blocks of other sizes may be what stands in the way.
      {
        const std::lock_guard<std::mutex> lock(mutex_);
        EvictUntilCachedAtMost(0);
      }
      data = mmap(nullptr, size, PROT_READ | PROT_WRITE, MAP_PRIVATE | MAP_ANONYMOUS, -1, 0);
    }
    TORCH_CHECK(data != MAP_FAILED, "out of memory: cannot map ", size >> 20,
                " MiB for a tensor");
    // Fewer, larger page faults where the system allows transparent huge
    // pages on request; without it the block still works with small pages.
    madvise(data, size, MADV_HUGEPAGE);
    const std::lock_guard<std::mutex> lock(mutex_);
    ++stats_.misses;
    MarkLive(data, size);
    return data;
  }

  void MarkLive(void* data, std::size_t size) const {
    live_[data] = size;
    stats_.live_bytes += size;
    stats_.peak_live_bytes = std::max(stats_.peak_live_bytes, stats_.live_bytes);
  }

  void Return(void* data) {
    std::unique_lock<std::mutex> lock(mutex_);
    const auto found = live_.find(data);
    if (found == live_.end()) {
      // A smaller block from raw_allocate(): the other allocator's.
      lock.unlock();
      const c10::DeleterFnPtr smaller = smaller_blocks_->raw_deleter();
      TORCH_CHECK(smaller != nullptr, "LargeBlockCache: cannot free a raw block of the CPU allocator");
      smaller(data);
      return;
    }
    const std::size_t size = found->second;
    live_.erase(found);
    stats_.live_bytes -= size;
    if (size > max_cached_bytes_) {
      munmap(data, size);
      return;
    }
    // The oldest kept blocks make room: the newest are the likeliest to be
    // asked for again (the next iteration repeats this one's shapes).
    EvictUntilCachedAtMost(max_cached_bytes_ - size);
    cached_.push_front({data, size});
    stats_.cached_bytes += size;
  }

  void EvictUntilCachedAtMost(std::size_t bytes) const {
    while (stats_.cached_bytes > bytes && !cached_.empty()) {
      const Block oldest = cached_.back();
      cached_.pop_back();
      munmap(oldest.data, oldest.size);
      stats_.cached_bytes -= oldest.size;
    }
  }

  c10::Allocator* smaller_blocks_;
  std::atomic<std::size_t> min_block_bytes_{std::size_t{32} << 20};
  std::size_t max_cached_bytes_ = 0;
  // allocate() is const in c10::Allocator's interface.
  mutable std::mutex mutex_;
  mutable std::list<Block> cached_;  // most recently freed first
  mutable std::unordered_map<void*, std::size_t> live_;
  mutable LargeBlockCacheStats stats_;
};

LargeBlockCache* LargeBlockCache::instance = nullptr;
std::mutex install_mutex;

}  // namespace

void InstallLargeBlockCache(const LargeBlockCacheOptions& options) {
  if (options.min_block_bytes == 0) {
    throw std::invalid_argument("LargeBlockCache: min_block_bytes must be positive");
  }
  const std::lock_guard<std::mutex> lock(install_mutex);
  if (LargeBlockCache::instance == nullptr) {
    // Never deleted: tensors allocated by it may live until the process ends.
    LargeBlockCache::instance = new LargeBlockCache(c10::GetCPUAllocator());
    LargeBlockCache::instance->Configure(options);
    c10::SetCPUAllocator(LargeBlockCache::instance, /*priority=*/1);
    if (c10::GetCPUAllocator() != LargeBlockCache::instance) {
      throw std::runtime_error("LargeBlockCache: LibTorch kept another CPU allocator");
    }
    return;
  }
  LargeBlockCache::instance->Configure(options);
}

bool LargeBlockCacheInstalled() {
  const std::lock_guard<std::mutex> lock(install_mutex);
  return LargeBlockCache::instance != nullptr;
}

LargeBlockCacheStats LargeBlockCacheCounters() {
  const std::lock_guard<std::mutex> lock(install_mutex);
  return LargeBlockCache::instance ? LargeBlockCache::instance->stats() : LargeBlockCacheStats{};
}

std::size_t ReleaseCachedBlocks() {
  const std::lock_guard<std::mutex> lock(install_mutex);
  return LargeBlockCache::instance ? LargeBlockCache::instance->ReleaseCached() : 0;
}

void ResetPeakLiveBytes() {
  const std::lock_guard<std::mutex> lock(install_mutex);
  if (LargeBlockCache::instance) LargeBlockCache::instance->ResetPeak();
}

}  // namespace dispmvs::model
