#include "model/host_allocator.h"

#include <limits>

#if defined(__GLIBC__)
#include <malloc.h>
#endif

namespace dispmvs::model {
namespace {

// Blocks above 32 MiB are mapped while fewer than `mmap_max` are (0: none
// is); freed heap memory is kept. false where the C library is not glibc.
bool KeepFreedBlocks(int mmap_max) {
#if defined(__GLIBC__)
  // mallopt returns 1 on success. Setting either threshold also turns off
  // glibc's dynamic adjustment of the mmap threshold.
  const bool mmap_ok = mallopt(M_MMAP_THRESHOLD, 32 * 1024 * 1024) == 1;
  const bool count_ok = mallopt(M_MMAP_MAX, mmap_max) == 1;
  // The largest value mallopt takes (2 GiB): more than a pass ever frees.
  const bool trim_ok = mallopt(M_TRIM_THRESHOLD, std::numeric_limits<int>::max()) == 1;
  return mmap_ok && count_ok && trim_ok;
#else
  (void)mmap_max;
  return false;
#endif
}

// glibc's default M_MMAP_MAX (malloc/malloc.c, DEFAULT_MMAP_MAX).
constexpr int kGlibcDefaultMmapMax = 65536;

}  // namespace

bool KeepFreedTensorMemory() { return KeepFreedBlocks(kGlibcDefaultMmapMax); }

bool KeepAllFreedTensorMemory() { return KeepFreedBlocks(0); }

}  // namespace dispmvs::model
