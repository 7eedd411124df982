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
//
// A training step holds larger maps still (autograd keeps every iteration's
// intermediates; at 640x480, batch 2, 5 sources many are 40-100 MiB), and
// 32 MiB is the largest mmap threshold glibc takes: with it alone, a third
// of a step's CPU time went to the kernel's page faults and unmappings.
// KeepAllFreedTensorMemory() serves every block from the heap (docs/benchmarks.md,
// "Training steps and the C allocator").

namespace dispmvs::model {

// Sets glibc's M_MMAP_THRESHOLD to 32 MiB (its maximum on 64-bit systems),
// M_MMAP_MAX back to glibc's default (blocks above the threshold are mapped)
// and M_TRIM_THRESHOLD to 2 GiB (the largest it takes). Returns false where
// the C library is not glibc (changing nothing) or refuses a setting. For
// programs that run the network on the CPU; call once, before the first pass.
bool KeepFreedTensorMemory();

// The same, but no block is mapped (M_MMAP_MAX = 0): freed blocks of any
// size stay in the heap for the next step. For CPU training; the resident
// set grows by what the heap cannot reuse exactly (5.2 -> 7.6 GB at 640x480,
// batch 2, 5 sources, for half the step time).
bool KeepAllFreedTensorMemory();

}  // namespace dispmvs::model
