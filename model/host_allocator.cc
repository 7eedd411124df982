#include "model/host_allocator.h"

#include <limits>

#if defined(__GLIBC__)
#include <malloc.h>
#endif

namespace dispmvs::model {

bool KeepFreedTensorMemory() {
#if defined(__GLIBC__)
  // mallopt returns 1 on success. Setting either threshold also turns off
  // glibc's dynamic adjustment of the mmap threshold.
  const bool mmap_ok = mallopt(M_MMAP_THRESHOLD, 32 * 1024 * 1024) == 1;
  // The largest value mallopt takes (2 GiB): more than a pass ever frees.
  const bool trim_ok = mallopt(M_TRIM_THRESHOLD, std::numeric_limits<int>::max()) == 1;
  return mmap_ok && trim_ok;
#else
  return false;
#endif
}

}  // namespace dispmvs::model
