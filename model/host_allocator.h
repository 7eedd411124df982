#pragma once
// How the process's C allocator treats the network's CPU tensors.
//
// A forward pass allocates and frees hundreds of maps of 1-30 MiB. glibc
// serves blocks above its (dynamic) mmap threshold with fresh mappings and
// returns them to the system on free, so every such map is page-faulted in
// again, zero-filled by the kernel, on every use: at 640x480 that cost a
// sixth of the pass (docs/benchmarks.md). KeepFreedTensorMemory() makes
// glibc serve blocks up to 32 MiB from its heap and keep what is freed for
// the next allocation. The price: the resident set stays at its peak between
// passes (+6 % at 1600x1152, N = 5) instead of shrinking after each.

namespace dispmvs::model {

// Sets glibc's M_MMAP_THRESHOLD to 32 MiB (its maximum on 64-bit systems)
// and M_TRIM_THRESHOLD to 2 GiB (the largest it takes). Returns false, changing nothing, where the C
// library is not glibc or refuses. For programs that run the network on the
// CPU; call once, before the first pass.
bool KeepFreedTensorMemory();

}  // namespace dispmvs::model
