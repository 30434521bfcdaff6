// The encoder's vectorised passes against plain loops, every compiled copy
// this CPU runs (baseline, AVX2) and the dispatched functions: every length
// (the vector bodies and their scalar tails), values at the tolerance exactly,
// and an implausible delta in every position.
#include "codec/delta_staging.h"

#include <gtest/gtest.h>

#include <cmath>
#include <limits>
#include <random>
#include <vector>

#include "codec/delta_quantization.h"
#include "util/cpu_features.h"

namespace filigree {
namespace {

struct Values {
  std::vector<double> pos, rest;
  std::vector<float> key, last;
};

Values random_values(std::size_t n, std::mt19937& rng) {
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  Values v;
  for (std::size_t j = 0; j < n; ++j) {
    v.rest.push_back(u(rng));
    v.pos.push_back(v.rest.back() + 1e-3 * u(rng));
    const double d = v.pos.back() - v.rest.back();
    v.key.push_back(static_cast<float>(d + 1e-3 * u(rng)));
    v.last.push_back(static_cast<float>(d + 1e-3 * u(rng)));
  }
  return v;
}

// The dispatched functions, as a copy of their own.
const StagingKernels kDispatched{"dispatched", stage_deltas, stage_and_compare_deltas, max_delta_error};

std::vector<StagingKernels> every_copy() {
  std::vector<StagingKernels> out(staging_kernels().begin(), staging_kernels().end());
  out.push_back(kDispatched);
  return out;
}

TEST(DeltaStaging, EveryCopyThisCpuCanRunIsThere) {
  ASSERT_GE(staging_kernels().size(), 1u);
  EXPECT_STREQ(staging_kernels().front().name, "baseline");
  // On an AVX2 machine the tests below run the AVX2 copy too.
  if (cpu_has_avx2()) {
    ASSERT_EQ(staging_kernels().size(), 2u);
    EXPECT_STREQ(staging_kernels().back().name, "avx2");
  }
}

// Each compiled copy, and the dispatched functions.
class EachCopy : public ::testing::TestWithParam<StagingKernels> {};
INSTANTIATE_TEST_SUITE_P(DeltaStaging, EachCopy, ::testing::ValuesIn(every_copy()),
                         [](const ::testing::TestParamInfo<StagingKernels>& info) { return std::string(info.param.name); });

TEST_P(EachCopy, MatchesPlainLoopsAtEveryLength) {
  const StagingKernels& k = GetParam();
  std::mt19937 rng(7);
  const double tolerance = 0x1p-11;  // ≈ 4.9e-4, and exact sums below
  for (std::size_t n = 0; n < 70; ++n) {
    Values v = random_values(n, rng);
    // A delta exactly at the tolerance from its key is not "moved".
    if (n > 3) v.rest[3] = 0.0, v.key[3] = 0.25f, v.pos[3] = 0.25 + tolerance;
    std::vector<float> staged(n, -1.0f), staged_only(n, -1.0f);
    std::vector<std::uint8_t> from_key(n, 9), from_last(n, 9);
    ASSERT_TRUE(k.stage_compare(v.pos.data(), v.rest.data(), v.key.data(), v.last.data(), tolerance, n, staged.data(),
                                from_key.data(), from_last.data()));
    ASSERT_TRUE(k.stage(v.pos.data(), v.rest.data(), n, staged_only.data()));
    double max_error = 0.0;
    for (std::size_t j = 0; j < n; ++j) {
      const double d = v.pos[j] - v.rest[j];
      ASSERT_EQ(staged[j], static_cast<float>(d)) << n << " " << j;
      ASSERT_EQ(staged_only[j], static_cast<float>(d)) << n << " " << j;
      ASSERT_EQ(from_key[j], std::abs(d - double{v.key[j]}) > tolerance ? 1 : 0) << n << " " << j;
      ASSERT_EQ(from_last[j], std::abs(d - double{v.last[j]}) > tolerance ? 1 : 0) << n << " " << j;
      max_error = std::max(max_error, std::abs(double{v.key[j]} - d));
    }
    if (n > 3) {
      EXPECT_EQ(from_key[3], 0) << n;
    }
    // The error of decoding to `key`, the largest anywhere in the range.
    EXPECT_EQ(k.max_error(v.key.data(), v.pos.data(), v.rest.data(), n), max_error) << n;
  }
}

TEST_P(EachCopy, LargestErrorIsFoundInEveryPosition) {
  const StagingKernels& k = GetParam();
  std::mt19937 rng(8);
  for (std::size_t n : {1u, 4u, 5u, 11u, 64u}) {
    for (std::size_t at = 0; at < n; ++at) {
      Values v = random_values(n, rng);
      std::vector<float> decoded(n);
      for (std::size_t j = 0; j < n; ++j) decoded[j] = static_cast<float>(v.pos[j] - v.rest[j]);
      decoded[at] += 0.5f;  // far above any rounding
      const double expected = std::abs(double{decoded[at]} - (v.pos[at] - v.rest[at]));
      EXPECT_EQ(k.max_error(decoded.data(), v.pos.data(), v.rest.data(), n), expected) << n << " " << at;
    }
  }
}

TEST_P(EachCopy, ImplausibleDeltasAreReportedWherever) {
  const StagingKernels& k = GetParam();
  std::mt19937 rng(9);
  const double bad[] = {std::numeric_limits<double>::quiet_NaN(), std::numeric_limits<double>::infinity(), 2 * kMaxDeltaMagnitude};
  for (std::size_t n : {1u, 3u, 8u, 13u}) {
    for (std::size_t at = 0; at < n; ++at) {
      for (double b : bad) {
        Values v = random_values(n, rng);
        v.pos[at] = b;
        std::vector<float> staged(n);
        std::vector<std::uint8_t> from_key(n), from_last(n);
        EXPECT_FALSE(k.stage(v.pos.data(), v.rest.data(), n, staged.data())) << n << " " << at << " " << b;
        EXPECT_FALSE(k.stage_compare(v.pos.data(), v.rest.data(), v.key.data(), v.last.data(), 1e-3, n, staged.data(),
                                     from_key.data(), from_last.data()))
            << n << " " << at << " " << b;
      }
    }
  }
}

}  // namespace
}  // namespace filigree
