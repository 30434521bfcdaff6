#include "codec/delta_quantization.h"

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <cstring>
#include <utility>
#include <vector>
#include <string>
#include <limits>

#include <draco/core/quantization_utils.h>

#include "util/cpu_features.h"

namespace filigree {
namespace {

// Draco's quantizer multiplies by (2^bits − 1) / range in float: a range
// below ~1e-31 makes that infinite. Every value then quantizes to 0 and
// decodes to `min`.
constexpr float kMinRange = 1e-20f;

std::int32_t max_level(std::uint32_t bits) { return static_cast<std::int32_t>((1u << bits) - 1u); }

}  // namespace

float float_at_least(double x) {
  float f = static_cast<float>(x);
  if (static_cast<double>(f) < x) f = std::nextafter(f, std::numeric_limits<float>::infinity());
  return f;
}

namespace {

// What a Draco decoder gives for each value (DecodeKernel's contract):
// compiled for AVX2 too (no FMA: a fused multiply-add would round
// differently from Draco's own code).
// With `measure`, also the largest |decoded − value|, each difference
// computed in float.
template <bool measure>
[[gnu::always_inline]] inline float decode_values(const DeltaQuantization& q, std::span<const float> values, std::span<float> out) {
  const std::size_t n = std::min(values.size(), out.size());
  const float min = q.min, range = q.range;
  const std::int32_t levels = max_level(q.bits);
  // The same objects and arithmetic as AttributeQuantizationTransform's
  // GeneratePortableAttribute and InverseTransformAttribute.
  draco::Quantizer quantizer;
  quantizer.Init(range, levels);
  draco::Dequantizer dequantizer;
  dequantizer.Init(range, levels);
  // Eight at a time, the same float operations written out (GCC left the
  // plain loop, now the tail, scalar: 4.6% of encoding a frame): Draco's Init computes
  // inverse_delta = float(levels) / range and delta = range / float(levels)
  // (draco/core/quantization_utils.cc); DequantizeFloat(1) is delta itself.
  // Values are ≥ min, so floor(t) for t ≥ 0.5 is the truncating conversion.
  // The tests compare every decoded value with Draco's own decoder.
  using F8 [[gnu::vector_size(32)]] = float;
  using I8 [[gnu::vector_size(32)]] = std::int32_t;
  const float inverse_delta = q.inverse_step(), delta = dequantizer.DequantizeFloat(1);
  F8 worst = {};
  std::size_t i = 0;
  for (; i + 8 <= n; i += 8) {
    F8 v;
    std::memcpy(&v, values.data() + i, sizeof v);
    const F8 t = (v - min) * inverse_delta + 0.5f;
    const F8 decoded = __builtin_convertvector(__builtin_convertvector(t, I8), F8) * delta + min;
    std::memcpy(out.data() + i, &decoded, sizeof decoded);
    if constexpr (measure) {
      F8 e = decoded - v;
      e = e < 0.0f ? -e : e;
      worst = e > worst ? e : worst;
    }
  }
  float out_worst = 0.0f;
  if constexpr (measure)
    for (int k = 0; k < 8; ++k) out_worst = std::max(out_worst, worst[k]);
  for (; i < n; ++i) {
    const float v = values[i];
    out[i] = dequantizer.DequantizeFloat(quantizer.QuantizeFloat(v - min)) + min;
    if constexpr (measure) out_worst = std::max(out_worst, std::abs(out[i] - v));
  }
  return out_worst;
}
void decode_values_baseline(const DeltaQuantization& q, std::span<const float> values, std::span<float> out) {
  decode_values<false>(q, values, out);
}
float decode_measured_baseline(const DeltaQuantization& q, std::span<const float> values, std::span<float> out) {
  return decode_values<true>(q, values, out);
}
#if FILIGREE_X86_TARGETS
[[gnu::target("avx2")]] void decode_values_avx2(const DeltaQuantization& q, std::span<const float> values, std::span<float> out) {
  decode_values<false>(q, values, out);
}
[[gnu::target("avx2")]] float decode_measured_avx2(const DeltaQuantization& q, std::span<const float> values, std::span<float> out) {
  return decode_values<true>(q, values, out);
}
#endif

std::vector<DecodeKernel> runnable_decode_kernels() {
  std::vector<DecodeKernel> out = {{"baseline", decode_values_baseline, decode_measured_baseline}};
#if FILIGREE_X86_TARGETS
  if (cpu_has_avx2()) out.push_back({"avx2", decode_values_avx2, decode_measured_avx2});
#endif
  return out;
}

// The smallest and largest of n > 0 finite values. Lanes of four hold every
// fourth value (min and max are exact in any order), SSE registers in the
// baseline build; std::minmax_element stays scalar (4.7% of encoding a frame).
std::pair<float, float> value_range(const float* v, std::size_t n) {
  using F4 [[gnu::vector_size(16)]] = float;
  std::size_t j = 0;
  float lo = v[0], hi = v[0];
  if (n >= 4) {
    F4 l, h;
    std::memcpy(&l, v, sizeof l);
    h = l;
    for (j = 4; j + 4 <= n; j += 4) {
      F4 x;
      std::memcpy(&x, v + j, sizeof x);
      l = x < l ? x : l;
      h = x > h ? x : h;
    }
    for (std::size_t k = 0; k < 4; ++k) lo = std::min(lo, l[k]), hi = std::max(hi, h[k]);
  }
  for (; j < n; ++j) lo = std::min(lo, v[j]), hi = std::max(hi, v[j]);
  return {lo, hi};
}

}  // namespace

std::span<const DecodeKernel> decode_kernels() {
  // Found on first use, so that no static initialiser can see it unset.
  static const std::vector<DecodeKernel> runnable = runnable_decode_kernels();
  return runnable;
}

void DeltaQuantization::decode(std::span<const float> values, std::span<float> out) const {
  decode_kernels().back().decode(*this, values, out);
}

double DeltaQuantization::decode_measured(std::span<const float> values, std::span<float> out) const {
  // A float difference rounds once, to within 2^-24 of itself: 2^-22 more
  // covers that and the rounding of this product.
  return double{decode_kernels().back().decode_measured(*this, values, out)} * (1.0 + 0x1p-22);
}

float DeltaQuantization::inverse_step() const { return static_cast<float>(max_level(bits)) / range; }

double DeltaQuantization::half_step() const { return double{range} / max_level(bits) / 2.0; }

double DeltaQuantization::bound() const {
  const double u = std::ldexp(1.0, -24);
  const double r = range, m = std::abs(double{min});
  return half_step() + 4.0 * u * r + u * m + u * (m + r);
}

// Draco keeps encoder options as strings (draco/compression/config/
// draco_options.h: std::to_string, "%f", six decimals; read back with atof):
// the origin and range it quantizes with are these, not the floats we pass.
float as_draco_option(float x) { return static_cast<float>(std::atof(std::to_string(x).c_str())); }

DeltaQuantization quantization_over(std::span<const float> values, std::uint32_t bits) {
  DeltaQuantization q;
  q.bits = bits;
  if (values.empty()) return q;
  const auto [lo, hi] = value_range(values.data(), values.size());
  return quantization_over_range(lo, hi, bits);
}

DeltaQuantization quantization_over_range(float lo, float hi, std::uint32_t bits) {
  DeltaQuantization q;
  q.bits = bits;
  // An origin at or below the smallest value that survives the option
  // strings, then a range that still reaches the largest value on Draco's
  // grid (its quantizer must not go past 2^bits − 1).
  const double grain = 1e-6;  // the options' last decimal
  q.min = as_draco_option(lo);
  for (int i = 0; q.min > lo && i < 4; ++i) q.min = as_draco_option(static_cast<float>(double{q.min} - grain));
  if (q.min > lo) q.min = as_draco_option(std::nextafter(lo, -std::numeric_limits<float>::infinity()));
  const double span = static_cast<double>(hi) - static_cast<double>(q.min);
  q.range = as_draco_option(std::max(float_at_least(span), kMinRange));
  draco::Quantizer quantizer;
  for (int i = 0; i < 64; ++i) {
    if (q.range >= kMinRange) {
      quantizer.Init(q.range, max_level(bits));
      if (quantizer.QuantizeFloat(hi - q.min) <= max_level(bits) && double{q.range} >= span) break;
    }
    q.range = as_draco_option(static_cast<float>(std::max(double{q.range}, double{kMinRange}) + grain * (1 << std::min(i, 20))));
  }
  return q;
}

std::uint32_t bits_for_error(double range, double error) {
  const double steps = range / (2.0 * std::max(error, 1e-300));
  std::uint32_t bits = 8;
  while (bits < 24 && static_cast<double>(max_level(bits)) < steps) ++bits;
  return bits;
}

}  // namespace filigree
