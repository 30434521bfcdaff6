#include "codec/delta_quantization.h"

#include <algorithm>
#include <cmath>
#include <cstdlib>
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

// Draco's quantizer rounds with floor(float): without SSE4.1 that is a libm
// call per value (2.5% of a busy server's time at 1.25M vertices), with it
// one instruction. Both compile the same Draco code, so results are equal.
struct DecodeArgs {
  const float* values;
  float* out;
  std::size_t n;
  float min, range;
  std::int32_t levels;
};
[[gnu::always_inline]] inline void decode_values(const DecodeArgs& a) {
  // The same objects and arithmetic as AttributeQuantizationTransform's
  // GeneratePortableAttribute and InverseTransformAttribute.
  draco::Quantizer quantizer;
  quantizer.Init(a.range, a.levels);
  draco::Dequantizer dequantizer;
  dequantizer.Init(a.range, a.levels);
  for (std::size_t i = 0; i < a.n; ++i) a.out[i] = dequantizer.DequantizeFloat(quantizer.QuantizeFloat(a.values[i] - a.min)) + a.min;
}
#if FILIGREE_X86_TARGETS
[[gnu::target("sse4.1")]] void decode_values_sse41(const DecodeArgs& a) { decode_values(a); }
void decode_values_baseline(const DecodeArgs& a) { decode_values(a); }
using DecodeFn = void (*)(const DecodeArgs&);
// Chosen on first use, so that no static initialiser can see it unset.
void dispatch_decode(const DecodeArgs& a) {
  static const DecodeFn chosen = cpu_has_sse41() ? decode_values_sse41 : decode_values_baseline;
  chosen(a);
}
#else
void dispatch_decode(const DecodeArgs& a) { decode_values(a); }
#endif

}  // namespace

void DeltaQuantization::decode(std::span<const float> values, std::span<float> out) const {
  dispatch_decode({values.data(), out.data(), std::min(values.size(), out.size()), min, range, max_level(bits)});
}

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
  const auto [lo, hi] = std::minmax_element(values.begin(), values.end());
  // An origin at or below the smallest value that survives the option
  // strings, then a range that still reaches the largest value on Draco's
  // grid (its quantizer must not go past 2^bits − 1).
  const double grain = 1e-6;  // the options' last decimal
  q.min = as_draco_option(*lo);
  for (int i = 0; q.min > *lo && i < 4; ++i) q.min = as_draco_option(static_cast<float>(double{q.min} - grain));
  if (q.min > *lo) q.min = as_draco_option(std::nextafter(*lo, -std::numeric_limits<float>::infinity()));
  const double span = static_cast<double>(*hi) - static_cast<double>(q.min);
  q.range = as_draco_option(std::max(float_at_least(span), kMinRange));
  draco::Quantizer quantizer;
  for (int i = 0; i < 64; ++i) {
    if (q.range >= kMinRange) {
      quantizer.Init(q.range, max_level(bits));
      if (quantizer.QuantizeFloat(*hi - q.min) <= max_level(bits) && double{q.range} >= span) break;
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
