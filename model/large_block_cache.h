#pragma once
// A cache of LibTorch's large CPU buffers, so that a forward pass reuses the
// memory of the maps it freed instead of asking the kernel for fresh pages.
//
// Why: glibc serves blocks above its mmap threshold with fresh mappings and
// returns them on free, and 32 MiB is the largest threshold it accepts
// (model/host_allocator.h). Every map above it is page-faulted in and
// zero-filled by the kernel on every use. Below about 2 megapixels the
// network's maps stay under 32 MiB (at 1600x1200 the fine stage's hidden
// state of one source is 23 MiB, the encoder's half-resolution maps 29 MiB);
// above, they cross it, and the time per megapixel tripled between 1600x1200
// and 2000x1500 (docs/benchmarks.md, "Image size"). Keeping every block in
// the heap instead (M_MMAP_MAX = 0) removes the faults but nearly doubles
// the resident set through fragmentation; jemalloc's default purging faults
// even more.
//
// The cache: blocks of at least `min_block_bytes` (default 32 MiB, what glibc
// would map) are rounded up to whole 2 MiB pages and mapped on their own,
// with transparent huge pages requested (MADV_HUGEPAGE: a 2 MiB page is one
// fault where 4 KiB pages are 512). A freed block is kept in a free list,
// by size, and served again to the next request of the same rounded size;
// passes repeat their shapes, so nearly every large map after the first
// iteration reuses one. A request that no kept block fits first unmaps kept
// blocks (the oldest first) of at least its size: memory is mapped anew only
// when nothing is kept, so live + kept never exceeds the largest live total
// so far, and the cache does not raise the peak resident set. Kept blocks are
// also unmapped once they would exceed `max_cached_bytes` (what stays
// resident between passes); ReleaseCachedBlocks() unmaps them all. No block
// is shared or split, so there is no fragmentation inside the cache.
//
// Install once per process, before the first pass: the cache becomes
// LibTorch's CPU allocator (c10::SetCPUAllocator) and smaller blocks go to the
// allocator it replaced. It is never uninstalled (tensors may outlive any
// scope); installing again changes the budget.

#include <cstddef>
#include <cstdint>

namespace dispmvs::model {

struct LargeBlockCacheOptions {
  std::size_t min_block_bytes = std::size_t{32} << 20;
  std::size_t max_cached_bytes = std::size_t{512} << 20;
};

struct LargeBlockCacheStats {
  int64_t hits = 0;              // requests served by a kept block
  int64_t misses = 0;            // requests that mapped a new block
  std::size_t live_bytes = 0;    // in blocks held by tensors now
  std::size_t cached_bytes = 0;  // in blocks kept for reuse now
  std::size_t peak_live_bytes = 0;
};

// Installs the cache as LibTorch's CPU allocator (or changes its budget).
// Throws std::invalid_argument when min_block_bytes is 0.
void InstallLargeBlockCache(const LargeBlockCacheOptions& options = {});

// Whether InstallLargeBlockCache has run in this process.
bool LargeBlockCacheInstalled();

// Counters since the installation (all zero before it).
LargeBlockCacheStats LargeBlockCacheCounters();

// Unmaps every kept block (live ones stay); returns the bytes given back.
std::size_t ReleaseCachedBlocks();

// Starts peak_live_bytes again from the live bytes now.
void ResetPeakLiveBytes();

}  // namespace dispmvs::model
