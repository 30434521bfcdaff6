#pragma once
// The quantization of frame deltas as a Draco decoder will undo it (DESIGN §3).
//
// Draco's explicit quantization maps a float v to q = floor((v − min) ·
// inverse_step + 0.5) and a decoder gives back q · step + min, all in float32
// (draco/core/quantization_utils.h, attribute_quantization_transform.cc). We
// compute the decoded value with Draco's own Quantizer and Dequantizer, so the
// stated error of a frame is exact, not estimated, and no frame has to be
// decoded to measure it. Draco passes the origin and range through decimal
// option strings (six decimals), so quantization_over picks values that
// survive that unchanged: what we compute is what Draco encodes.
//
// Why the error stays near half a step: with u = 2^-24, fl(v − min) is within
// u·|v − min| ≤ u·range of v − min; multiplying by inverse_step and adding 0.5
// move the rounding point by less than 2u·(2^bits) steps, so q is the nearest
// level or, at a tie, its neighbour: |q·step − (v − min)| ≤ step/2 + 2u·range.
// Dequantizing adds fl(q·step) (u·range) and fl(· + min) (u·(|min| + range)).
// In all: |decoded − v| ≤ step/2 + 4u·range + u·|min| + u·(|min| + range), the
// bound `bound()` returns and the tests check against real decodes.

#include <cstdint>
#include <span>

namespace filigree {

// Largest |delta| a frame carries: far beyond any mesh, and small enough
// that min, max, range and min + range all stay finite in float32.
constexpr double kMaxDeltaMagnitude = 1e30;

// The smallest float ≥ x (x finite, within float range): errors are stated
// rounded up.
float float_at_least(double x);

struct DeltaQuantization {
  std::uint32_t bits = 14;  // 8…24
  float min = 0.0f;         // origin on every axis
  float range = 0.0f;       // [min, min + range] holds every value

  // out[i] = what a Draco decoder gives for values[i] (each in [min, min +
  // range]); out may be values. Sizes must match.
  void decode(std::span<const float> values, std::span<float> out) const;
  // The same, and returns an upper bound on max |out[i] − values[i]| (0 for
  // no values), tight to a few float roundings.
  double decode_measured(std::span<const float> values, std::span<float> out) const;
  // |decoded(v) − v| for every v in the range is at most this (see above).
  double bound() const;
  // Draco's inverse step, float(2^bits − 1) / range in float (Quantizer::Init):
  // a value v in range quantizes to ⌊(v − min) · inverse_step() + 0.5⌋, each
  // operation rounded to float.
  float inverse_step() const;
  // Half the distance between two levels.
  double half_step() const;
};

// One compiled copy of DeltaQuantization::decode, with its contract.
struct DecodeKernel {
  const char* name;  // "baseline", "avx2"
  void (*decode)(const DeltaQuantization& q, std::span<const float> values, std::span<float> out);
  // decode, returning max |out[i] − values[i]| computed in float (each
  // difference rounded once).
  float (*decode_measured)(const DeltaQuantization& q, std::span<const float> values, std::span<float> out);
};

// Every copy this CPU can run, the one decode() uses last (tests compare
// them all with Draco's decoder).
std::span<const DecodeKernel> decode_kernels();

// The quantization over `values`' own range with `bits` (8…24): one origin for
// all components at or below the smallest value, a range that reaches the
// largest, both exactly as Draco will read them back (multiples of 1e-6, so
// the range is at least 1e-6). Values must be finite and |v| ≤ 1e30.
DeltaQuantization quantization_over(std::span<const float> values, std::uint32_t bits);
// The same for values whose smallest is `lo` and largest `hi` (lo ≤ hi).
DeltaQuantization quantization_over_range(float lo, float hi, std::uint32_t bits);

// The fewest bits (8…24) whose half step over `range` is at most `error`
// (24 when none is).
std::uint32_t bits_for_error(double range, double error);

}  // namespace filigree
