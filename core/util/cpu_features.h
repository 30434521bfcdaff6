#pragma once
// What the processor can do, for kernels compiled once more for a newer
// instruction set ([[gnu::target]]) and picked at run time, so that one binary
// runs on every x86-64. FILIGREE_X86_TARGETS says whether such copies can be
// compiled here (GCC or clang on x86-64); elsewhere only the baseline copy
// exists and every check says false.

#if defined(__x86_64__) && defined(__GNUC__)
#define FILIGREE_X86_TARGETS 1
#else
#define FILIGREE_X86_TARGETS 0
#endif

namespace filigree {

inline bool cpu_has_avx2() {
#if FILIGREE_X86_TARGETS
  __builtin_cpu_init();
  return __builtin_cpu_supports("avx2");
#else
  return false;
#endif
}

inline bool cpu_has_bmi2() {
#if FILIGREE_X86_TARGETS
  __builtin_cpu_init();
  return __builtin_cpu_supports("bmi2");
#else
  return false;
#endif
}

// AVX-512 as the kernels use it: the foundation with 256-bit forms (VL),
// double/quad-word and byte/word instructions, and FMA.
inline bool cpu_has_avx512() {
#if FILIGREE_X86_TARGETS
  __builtin_cpu_init();
  return __builtin_cpu_supports("avx512f") && __builtin_cpu_supports("avx512vl") && __builtin_cpu_supports("avx512dq") &&
         __builtin_cpu_supports("avx512bw") && __builtin_cpu_supports("fma");
#else
  return false;
#endif
}

}  // namespace filigree
