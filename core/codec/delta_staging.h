#pragma once
// The frame encoder's one pass over every value of a chunk
// (codec/frame_encoder.h): the deltas staged as float32, which vertices moved
// away from what clients hold, and what the frame's error statement needs, so
// that nothing reads the positions a second time. Compiled three times (plain,
// AVX2, AVX-512) and picked by the CPU at first use; every copy gives the same
// results, bit for bit.

#include <cstddef>
#include <cstdint>
#include <span>

namespace filigree {

// What stage_vertices found over its vertices (d = pos − rest, s = float(d)).
// Every field is an exact function of the inputs (a min, max or count), so
// it does not depend on the order the values were visited in.
struct StagingSummary {
  bool plausible = true;              // no d is NaN, ±∞ or beyond kMaxDeltaMagnitude
  std::size_t moved = 0;              // vertices with some |d − key| > tolerance
  std::size_t moved_since_last = 0;   // vertices with some |d − last| > tolerance
  float lo = 0, hi = 0;               // the smallest and largest s (0, 0 for no vertices)
  float moved_lo = 0, moved_hi = 0;   // the same over the moved vertices' values
  double rounding = 0;                // max |s − d|: what staging in float32 lost
  double unmoved_error = 0;           // max |key − d| over the vertices not moved
};

// For vertices i < `vertices`, coordinates k (values j = 3i + k, flat x y z):
// staged[j] = float(pos[j] − rest[j]). With `key` and `last` (both or
// neither), vertex i is moved when some |d − key[j]| > tolerance and bit i of
// `moved` (64-bit words, least significant bit first; ⌈vertices/64⌉ words,
// bits past the end cleared) says so; without them every vertex is moved and
// moved_since_last counts them all. No branch depends on a value: a bad delta
// is reported in `plausible`, and the caller names it on a slow path.
StagingSummary stage_vertices(const double* pos, const double* rest, const float* key, const float* last, double tolerance,
                              std::size_t vertices, float* staged, std::uint64_t* moved);

// In place: the values (x y z) of the vertices whose bit in `moved` is set,
// moved to the front in order. Returns how many vertices that is.
std::size_t compact_moved(float* values, const std::uint64_t* moved, std::size_t vertices);

// One compiled copy of the two functions above, with the same contracts.
struct StagingKernels {
  const char* name;  // "baseline", "avx2", "avx512"
  StagingSummary (*stage)(const double* pos, const double* rest, const float* key, const float* last, double tolerance,
                          std::size_t vertices, float* staged, std::uint64_t* moved);
  std::size_t (*compact)(float* values, const std::uint64_t* moved, std::size_t vertices);
};

// Every copy this CPU can run, the one the functions above use last (tests
// compare them all).
std::span<const StagingKernels> staging_kernels();

}  // namespace filigree
