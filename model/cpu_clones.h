#pragma once
// DISPMVS_CPU_CLONES: build a function also for AVX2 and AVX-512 and pick
// the variant at load time by the processor (GCC's target_clones; the
// library itself targets baseline x86-64, as Debian builds it). Elsewhere
// (other compilers or architectures) the function is built once. For the
// inner loops of the fused CPU passes (correlation_cpu, gru_gates_cpu).
#if defined(__GNUC__) && !defined(__clang__) && defined(__x86_64__)
#define DISPMVS_CPU_CLONES __attribute__((target_clones("default", "avx2", "avx512f")))
#else
#define DISPMVS_CPU_CLONES
#endif
