#include "codec/delta_staging.h"

#include <algorithm>
#include <cmath>
#include <cstring>
#include <vector>

#include "codec/delta_quantization.h"
#include "util/cpu_features.h"

namespace filigree {
namespace {

// The kernels, inlined into one baseline and one AVX2 copy each. GCC
// vectorises the staging loops only with AVX (a double comparison made a
// byte needs it), and a floating-point max reduction never (it may not
// reorder it): max_error uses explicit vectors of four, whose lanes hold
// every fourth value (max is exact in any order).
// Outputs never alias inputs (__restrict): without it GCC gives up
// versioning the loops for every pair of pointers.
[[gnu::always_inline]] inline bool stage_kernel(const double* __restrict pos, const double* __restrict rest, std::size_t values,
                                                float* __restrict staged) {
  unsigned bad = 0;
  for (std::size_t j = 0; j < values; ++j) {
    const double d = pos[j] - rest[j];
    bad |= !(std::abs(d) <= kMaxDeltaMagnitude);  // true for NaN too
    staged[j] = static_cast<float>(d);
  }
  return bad == 0;
}

[[gnu::always_inline]] inline bool stage_compare_kernel(const double* __restrict pos, const double* __restrict rest,
                                                        const float* __restrict key, const float* __restrict last, double tolerance,
                                                        std::size_t values, float* __restrict staged,
                                                        std::uint8_t* __restrict from_key, std::uint8_t* __restrict from_last) {
  unsigned bad = 0;
  for (std::size_t j = 0; j < values; ++j) {
    const double d = pos[j] - rest[j];
    bad |= !(std::abs(d) <= kMaxDeltaMagnitude);
    staged[j] = static_cast<float>(d);
    from_key[j] = std::abs(d - double{key[j]}) > tolerance;
    from_last[j] = std::abs(d - double{last[j]}) > tolerance;
  }
  return bad == 0;
}

[[gnu::always_inline]] inline double max_error_kernel(const float* decoded, const double* pos, const double* rest, std::size_t values) {
  using Doubles = double __attribute__((vector_size(32)));
  using Floats = float __attribute__((vector_size(16)));
  Doubles e = {0.0, 0.0, 0.0, 0.0};
  std::size_t j = 0;
  for (; j + 4 <= values; j += 4) {
    Floats f;
    Doubles p, r;
    std::memcpy(&f, decoded + j, sizeof f);
    std::memcpy(&p, pos + j, sizeof p);
    std::memcpy(&r, rest + j, sizeof r);
    Doubles x = __builtin_convertvector(f, Doubles) - (p - r);
    x = x < 0.0 ? -x : x;
    e = x > e ? x : e;
  }
  double out = std::max({e[0], e[1], e[2], e[3]});
  for (; j < values; ++j) out = std::max(out, std::abs(double{decoded[j]} - (pos[j] - rest[j])));
  return out;
}

#define FILIGREE_STAGING_KERNELS(attributes, suffix)                                                                      \
  attributes bool stage_##suffix(const double* p, const double* r, std::size_t n, float* s) { return stage_kernel(p, r, n, s); } \
  attributes bool stage_compare_##suffix(const double* p, const double* r, const float* k, const float* l, double t,           \
                                         std::size_t n, float* s, std::uint8_t* fk, std::uint8_t* fl) {                       \
    return stage_compare_kernel(p, r, k, l, t, n, s, fk, fl);                                                                  \
  }                                                                                                                            \
  attributes double max_error_##suffix(const float* d, const double* p, const double* r, std::size_t n) {                     \
    return max_error_kernel(d, p, r, n);                                                                                       \
  }

FILIGREE_STAGING_KERNELS(, baseline)
#if FILIGREE_X86_TARGETS
FILIGREE_STAGING_KERNELS([[gnu::target("avx2")]], avx2)
#endif
#undef FILIGREE_STAGING_KERNELS

std::vector<StagingKernels> runnable_kernels() {
  std::vector<StagingKernels> out = {{"baseline", stage_baseline, stage_compare_baseline, max_error_baseline}};
#if FILIGREE_X86_TARGETS
  if (cpu_has_avx2()) out.push_back({"avx2", stage_avx2, stage_compare_avx2, max_error_avx2});
#endif
  return out;
}

const StagingKernels& kernels() { return staging_kernels().back(); }

}  // namespace

std::span<const StagingKernels> staging_kernels() {
  // Found on first use, so that no static initialiser can see it unset.
  static const std::vector<StagingKernels> runnable = runnable_kernels();
  return runnable;
}

bool stage_deltas(const double* pos, const double* rest, std::size_t values, float* staged) {
  return kernels().stage(pos, rest, values, staged);
}

bool stage_and_compare_deltas(const double* pos, const double* rest, const float* key, const float* last, double tolerance,
                              std::size_t values, float* staged, std::uint8_t* from_key, std::uint8_t* from_last) {
  return kernels().stage_compare(pos, rest, key, last, tolerance, values, staged, from_key, from_last);
}

double max_delta_error(const float* decoded, const double* pos, const double* rest, std::size_t values) {
  return kernels().max_error(decoded, pos, rest, values);
}

}  // namespace filigree
