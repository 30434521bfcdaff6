#include "codec/delta_staging.h"

#include <algorithm>
#include <bit>
#include <cmath>
#include <cstring>
#include <limits>
#include <vector>

#if defined(__x86_64__) && defined(__GNUC__)
#include <immintrin.h>
#endif

#include "codec/delta_quantization.h"
#include "util/cpu_features.h"

namespace filigree {
namespace {

constexpr float kInf = std::numeric_limits<float>::infinity();

// The summary while it is gathered: extremes start empty.
struct Running {
  bool plausible = true;
  std::size_t moved = 0, moved_since_last = 0;
  float lo = kInf, hi = -kInf, moved_lo = kInf, moved_hi = -kInf;
  double rounding = 0, unmoved_error = 0;

  StagingSummary finish() const {
    // + 0.0f makes −0 +0: which of two equal zeros a min keeps depends on
    // the order of the visit, and the copies visit in different orders.
    const bool any = lo <= hi, any_moved = moved_lo <= moved_hi;
    return {plausible,
            moved,
            moved_since_last,
            any ? lo + 0.0f : 0.0f,
            any ? hi + 0.0f : 0.0f,
            any_moved ? moved_lo + 0.0f : 0.0f,
            any_moved ? moved_hi + 0.0f : 0.0f,
            rounding,
            unmoved_error};
  }
};

// The plain and AVX2 copies (and the AVX-512 copy's last vertices): blocks of
// vertices whose per-value work is one flat loop over x y z (GCC vectorises
// it with AVX: a double comparison made a byte needs it), then a scalar loop
// per vertex combining its three values. The block's scratch stays in L1.
// Adds to `r`; `moved` starts at the first vertex's word.
constexpr std::size_t kBlock = 256;

// One value: s = float(d) for d = p − q, what float32 lost, and whether d is
// implausible (no branch). Returns d.
[[gnu::always_inline]] inline double stage_value(double p, double q, float& s, double& lost, unsigned& bad) {
  const double d = p - q;
  bad |= !(std::abs(d) <= kMaxDeltaMagnitude);  // true for NaN too
  s = static_cast<float>(d);
  lost = std::abs(double{s} - d);
  return d;
}

[[gnu::always_inline]] inline void stage_blocks(const double* __restrict pos, const double* __restrict rest,
                                                const float* __restrict key, const float* __restrict last, double tolerance,
                                                std::size_t vertices, float* __restrict staged, std::uint64_t* moved, Running& r) {
  std::fill_n(moved, (vertices + 63) / 64, std::uint64_t{0});
  double lost[3 * kBlock], from_key[3 * kBlock];
  std::uint8_t beyond_key[3 * kBlock], beyond_last[3 * kBlock];
  for (std::size_t b = 0; b < vertices; b += kBlock) {
    const std::size_t n = std::min(kBlock, vertices - b), values = 3 * n;
    const double* p = pos + 3 * b;
    const double* q = rest + 3 * b;
    float* s = staged + 3 * b;
    unsigned bad = 0;
    if (key) {
      const float* k = key + 3 * b;
      const float* l = last + 3 * b;
      for (std::size_t j = 0; j < values; ++j) {
        const double d = stage_value(p[j], q[j], s[j], lost[j], bad);
        from_key[j] = std::abs(d - double{k[j]});
        beyond_key[j] = from_key[j] > tolerance;
        beyond_last[j] = std::abs(d - double{l[j]}) > tolerance;
      }
    } else {
      for (std::size_t j = 0; j < values; ++j) {
        stage_value(p[j], q[j], s[j], lost[j], bad);
        beyond_key[j] = beyond_last[j] = 1;
        from_key[j] = 0.0;
      }
    }
    r.plausible &= bad == 0;
    for (std::size_t i = 0; i < n; ++i) {
      const std::size_t j = 3 * i, v = b + i;
      const bool m = beyond_key[j] | beyond_key[j + 1] | beyond_key[j + 2];
      r.moved += m;
      r.moved_since_last += beyond_last[j] | beyond_last[j + 1] | beyond_last[j + 2];
      moved[v / 64] |= std::uint64_t{m} << (v % 64);
      r.rounding = std::max({r.rounding, lost[j], lost[j + 1], lost[j + 2]});
      const float lo = std::min({s[j], s[j + 1], s[j + 2]}), hi = std::max({s[j], s[j + 1], s[j + 2]});
      r.lo = std::min(r.lo, lo), r.hi = std::max(r.hi, hi);
      r.moved_lo = std::min(r.moved_lo, m ? lo : kInf), r.moved_hi = std::max(r.moved_hi, m ? hi : -kInf);
      r.unmoved_error = std::max(r.unmoved_error, m ? 0.0 : std::max({from_key[j], from_key[j + 1], from_key[j + 2]}));
    }
  }
}

// Branch-free: every vertex is copied down, j advances past moved ones.
[[gnu::always_inline]] inline std::size_t compact_plain(float* v, const std::uint64_t* moved, std::size_t first, std::size_t vertices,
                                                        std::size_t j) {
  for (std::size_t i = first; i < vertices; ++i) {
    const float x = v[3 * i], y = v[3 * i + 1], z = v[3 * i + 2];
    v[3 * j] = x, v[3 * j + 1] = y, v[3 * j + 2] = z;
    j += (moved[i / 64] >> (i % 64)) & 1;
  }
  return j;
}

[[gnu::always_inline]] inline StagingSummary stage_plain(const double* p, const double* r, const float* k, const float* l, double t,
                                                        std::size_t n, float* s, std::uint64_t* m) {
  Running run;
  stage_blocks(p, r, k, l, t, n, s, m, run);
  return run.finish();
}

StagingSummary stage_baseline(const double* p, const double* r, const float* k, const float* l, double t, std::size_t n, float* s,
                              std::uint64_t* m) {
  return stage_plain(p, r, k, l, t, n, s, m);
}
std::size_t compact_baseline(float* v, const std::uint64_t* m, std::size_t n) { return compact_plain(v, m, 0, n, 0); }

#if FILIGREE_X86_TARGETS
[[gnu::target("avx2")]] StagingSummary stage_avx2(const double* p, const double* r, const float* k, const float* l, double t, std::size_t n,
                                                  float* s, std::uint64_t* m) {
  return stage_plain(p, r, k, l, t, n, s, m);
}
[[gnu::target("avx2")]] std::size_t compact_avx2(float* v, const std::uint64_t* m, std::size_t n) { return compact_plain(v, m, 0, n, 0); }

// The AVX-512 copy: eight vertices (24 values, three registers of doubles) at
// a time, up to the last whole word of bits (the rest as the plain copy
// does). A vertex's three comparison bits are folded into one with shifts
// and picked out with pext, and spread back over its values with pdep, so
// the per-vertex work stays in mask registers; reductions are lane-wise
// (min, max: exact in any order) and folded at the end.
// GCC 12's AVX-512 intrinsics start from _mm512_undefined_*(), which its
// own uninitialised-use warnings flag once inlined (GCC bug 105593; clang
// has neither the warning nor the bug).
#if !defined(__clang__)
#pragma GCC diagnostic push
#pragma GCC diagnostic ignored "-Wuninitialized"
#pragma GCC diagnostic ignored "-Wmaybe-uninitialized"
#endif
#define FILIGREE_AVX512 gnu::target("avx512f,avx512vl,avx512dq,avx512bw,bmi2")

[[FILIGREE_AVX512]] StagingSummary stage_avx512(const double* pos, const double* rest, const float* key, const float* last,
                                               double tolerance, std::size_t vertices, float* staged, std::uint64_t* moved) {
  const std::size_t whole = vertices / 64 * 64;
  std::fill_n(moved, whole / 64, std::uint64_t{0});
  const __m512d limit = _mm512_set1_pd(kMaxDeltaMagnitude), tol = _mm512_set1_pd(tolerance);
  __m512d rounding = _mm512_setzero_pd(), unmoved = _mm512_setzero_pd();
  __m256 lo = _mm256_set1_ps(kInf), hi = _mm256_set1_ps(-kInf), mlo = lo, mhi = hi;
  __mmask8 ok = 0xFF;
  std::size_t count = 0, since = 0;
  std::size_t i = 0;
  for (; i < whole; i += 8) {
    const std::size_t o = 3 * i;
    __m512d d[3];
    __m256 s[3];
    for (int k = 0; k < 3; ++k) {
      d[k] = _mm512_sub_pd(_mm512_loadu_pd(pos + o + 8 * k), _mm512_loadu_pd(rest + o + 8 * k));
      ok &= _mm512_cmp_pd_mask(_mm512_abs_pd(d[k]), limit, _CMP_LE_OQ);  // false for NaN too
      s[k] = _mm512_cvtpd_ps(d[k]);
      _mm256_storeu_ps(staged + o + 8 * k, s[k]);
      rounding = _mm512_max_pd(rounding, _mm512_abs_pd(_mm512_sub_pd(_mm512_cvtps_pd(s[k]), d[k])));
      lo = _mm256_min_ps(lo, s[k]), hi = _mm256_max_ps(hi, s[k]);
    }
    std::uint32_t vertex_moved = 0xFF;
    if (key) {
      __m512d e[3];
      std::uint32_t beyond_key = 0, beyond_last = 0;
      for (int k = 0; k < 3; ++k) {
        e[k] = _mm512_abs_pd(_mm512_sub_pd(d[k], _mm512_cvtps_pd(_mm256_loadu_ps(key + o + 8 * k))));
        beyond_key |= std::uint32_t{_mm512_cmp_pd_mask(e[k], tol, _CMP_GT_OQ)} << (8 * k);
        const __m512d f = _mm512_abs_pd(_mm512_sub_pd(d[k], _mm512_cvtps_pd(_mm256_loadu_ps(last + o + 8 * k))));
        beyond_last |= std::uint32_t{_mm512_cmp_pd_mask(f, tol, _CMP_GT_OQ)} << (8 * k);
      }
      // Value bits 3v, 3v+1, 3v+2 belong to vertex v.
      constexpr std::uint32_t kFirstOfVertex = 0x249249;
      vertex_moved = _pext_u32(beyond_key | beyond_key >> 1 | beyond_key >> 2, kFirstOfVertex);
      since += std::popcount(_pext_u32(beyond_last | beyond_last >> 1 | beyond_last >> 2, kFirstOfVertex));
      std::uint32_t values_moved = _pdep_u32(vertex_moved, kFirstOfVertex);
      values_moved |= values_moved << 1 | values_moved << 2;
      for (int k = 0; k < 3; ++k) {
        const __mmask8 m = static_cast<__mmask8>(values_moved >> (8 * k));
        unmoved = _mm512_mask_max_pd(unmoved, static_cast<__mmask8>(~m), unmoved, e[k]);
        mlo = _mm256_mask_min_ps(mlo, m, mlo, s[k]), mhi = _mm256_mask_max_ps(mhi, m, mhi, s[k]);
      }
    } else {
      since += 8;
      for (int k = 0; k < 3; ++k) mlo = _mm256_min_ps(mlo, s[k]), mhi = _mm256_max_ps(mhi, s[k]);
    }
    count += std::popcount(vertex_moved);
    moved[i / 64] |= std::uint64_t{vertex_moved} << (i % 64);
  }
  Running r;
  r.plausible = ok == 0xFF;
  r.moved = count, r.moved_since_last = since;
  r.rounding = _mm512_reduce_max_pd(rounding), r.unmoved_error = _mm512_reduce_max_pd(unmoved);
  alignas(32) float lanes[4][8];
  _mm256_store_ps(lanes[0], lo), _mm256_store_ps(lanes[1], hi), _mm256_store_ps(lanes[2], mlo), _mm256_store_ps(lanes[3], mhi);
  r.lo = *std::min_element(lanes[0], lanes[0] + 8), r.hi = *std::max_element(lanes[1], lanes[1] + 8);
  r.moved_lo = *std::min_element(lanes[2], lanes[2] + 8), r.moved_hi = *std::max_element(lanes[3], lanes[3] + 8);
  stage_blocks(pos + 3 * whole, rest + 3 * whole, key ? key + 3 * whole : nullptr, last ? last + 3 * whole : nullptr, tolerance,
               vertices - whole, staged + 3 * whole, moved + whole / 64, r);
  return r.finish();
}

// Sixteen vertices (48 values, three registers) at a time: each register's
// moved values compressed to its front and stored whole (the store may run
// past the moved values into ones already read; a compressing store to
// memory is microcode on some processors).
[[FILIGREE_AVX512]] std::size_t compact_avx512(float* v, const std::uint64_t* moved, std::size_t vertices) {
  std::size_t i = 0, j = 0;  // j: values kept so far
  for (; i + 16 <= vertices; i += 16) {
    const std::uint64_t m16 = (moved[i / 64] >> (i % 64)) & 0xFFFF;
    if (m16 == 0xFFFF && j == 3 * i) {
      j += 48;  // nothing moved down yet, and all of these stay
      continue;
    }
    std::uint64_t bits = _pdep_u64(m16, 0x249249249249ull);
    bits |= bits << 1 | bits << 2;
    const __m512 a = _mm512_loadu_ps(v + 3 * i), b = _mm512_loadu_ps(v + 3 * i + 16), c = _mm512_loadu_ps(v + 3 * i + 32);
    const __m512 parts[3] = {a, b, c};
    for (int k = 0; k < 3; ++k) {
      const __mmask16 m = static_cast<__mmask16>(bits >> (16 * k));
      _mm512_storeu_ps(v + j, _mm512_maskz_compress_ps(m, parts[k]));
      j += std::popcount(static_cast<unsigned>(m));
    }
  }
  return compact_plain(v, moved, i, vertices, j / 3);
}
#undef FILIGREE_AVX512
#if !defined(__clang__)
#pragma GCC diagnostic pop
#endif
#endif

std::vector<StagingKernels> runnable_kernels() {
  std::vector<StagingKernels> out = {{"baseline", stage_baseline, compact_baseline}};
#if FILIGREE_X86_TARGETS
  if (cpu_has_avx2()) out.push_back({"avx2", stage_avx2, compact_avx2});
  if (cpu_has_avx512() && cpu_has_bmi2()) out.push_back({"avx512", stage_avx512, compact_avx512});
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

StagingSummary stage_vertices(const double* pos, const double* rest, const float* key, const float* last, double tolerance,
                              std::size_t vertices, float* staged, std::uint64_t* moved) {
  return kernels().stage(pos, rest, key, last, tolerance, vertices, staged, moved);
}

std::size_t compact_moved(float* values, const std::uint64_t* moved, std::size_t vertices) {
  return kernels().compact(values, moved, vertices);
}

}  // namespace filigree
