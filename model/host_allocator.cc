#include "model/host_allocator.h"

#include <limits>

#if defined(__GLIBC__)
#include <malloc.h>
#endif

namespace dispmvs::model {
namespace {

#if defined(__GLIBC__)
// glibc's default M_MMAP_MAX (malloc/malloc.c, DEFAULT_MMAP_MAX).
constexpr int kGlibcDefaultMmapMax = 65536;

// mallopt returns 1 on success. Setting either threshold also turns off
// glibc's dynamic adjustment of the mmap threshold.
bool KeepFreedBlocks(int mmap_max) {
  const bool mmap_ok = mallopt(M_MMAP_THRESHOLD, 32 * 1024 * 1024) == 1;
  const bool count_ok = mallopt(M_MMAP_MAX, mmap_max) == 1;
  // The largest value mallopt takes (2 GiB): more than a pass ever frees.
  const bool trim_ok = mallopt(M_TRIM_THRESHOLD, std::numeric_limits<int>::max()) == 1;
  return mmap_ok && count_ok && trim_ok;
}
#endif

}  // namespace

bool KeepFreedTensorMemory() {
#if defined(__GLIBC__)
  return KeepFreedBlocks(kGlibcDefaultMmapMax);
#else
  return false;
#endif
}

bool KeepAllFreedTensorMemory() {
#if defined(__GLIBC__)
  return KeepFreedBlocks(0);
#else
  return false;
#endif
}

}  // namespace dispmvs::model
