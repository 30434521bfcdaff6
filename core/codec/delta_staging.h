#pragma once
// The frame encoder's passes over every value of a chunk (codec/frame_encoder.h):
// staging the deltas as float32 while finding what moved, and the exact
// error of the decoded deltas. Flat over coordinates (x y z x y z …), so that
// they vectorise; compiled for AVX2 too and picked by the CPU at first use.
// Results do not depend on which copy runs.

#include <cstddef>
#include <cstdint>
#include <span>

namespace filigree {

// For j < values: d = pos[j] − rest[j]; staged[j] = float(d). Returns false
// if some d is NaN, ±∞ or beyond kMaxDeltaMagnitude (delta_quantization.h),
// with no branch per value: the caller names the culprit on a slow path.
bool stage_deltas(const double* pos, const double* rest, std::size_t values, float* staged);

// The same, and per value whether d is more than `tolerance` from what
// clients hold: from_key[j] = |d − key[j]| > tolerance, from_last[j] the
// same against last[j] (1 or 0).
bool stage_and_compare_deltas(const double* pos, const double* rest, const float* key, const float* last, double tolerance,
                              std::size_t values, float* staged, std::uint8_t* from_key, std::uint8_t* from_last);

// max over j < values of |decoded[j] − (pos[j] − rest[j])|, exact (in
// double), 0 for no values. Every input must be finite.
double max_delta_error(const float* decoded, const double* pos, const double* rest, std::size_t values);

// One compiled copy of the three passes above, with the same contracts.
struct StagingKernels {
  const char* name;  // "baseline", "avx2"
  bool (*stage)(const double* pos, const double* rest, std::size_t values, float* staged);
  bool (*stage_compare)(const double* pos, const double* rest, const float* key, const float* last, double tolerance,
                        std::size_t values, float* staged, std::uint8_t* from_key, std::uint8_t* from_last);
  double (*max_error)(const float* decoded, const double* pos, const double* rest, std::size_t values);
};

// Every copy this CPU can run, the one the functions above use last (tests
// compare them all).
std::span<const StagingKernels> staging_kernels();

}  // namespace filigree
