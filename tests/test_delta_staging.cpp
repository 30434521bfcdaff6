// The encoder's staging pass and compaction against plain loops, every
// compiled copy this CPU runs (baseline, AVX2, AVX-512) and the dispatched
// functions: every length (the vector bodies, their tails, 64-bit word and
// block boundaries), deltas exactly at the tolerance, signed zeros, and an
// implausible delta in every position.
#include "codec/delta_staging.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <random>
#include <vector>

#include "codec/delta_quantization.h"
#include "util/cpu_features.h"

namespace filigree {
namespace {

constexpr double kTolerance = 0x1p-11;  // ≈ 4.9e-4; sums below are exact

struct Values {
  std::vector<double> pos, rest;
  std::vector<float> key, last;
};

// Vertices of which about half stay within the tolerance of their key on
// every axis, some deltas are exactly zero or round to a negative zero.
Values random_values(std::size_t vertices, std::mt19937& rng) {
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  Values v;
  for (std::size_t i = 0; i < vertices; ++i) {
    const bool stays = rng() % 2 == 0;
    for (int k = 0; k < 3; ++k) {
      const unsigned kind = rng() % 8;
      v.rest.push_back(kind == 1 ? 0.0 : u(rng));  // so that −1e-50 survives the sum
      const double d = kind == 0 ? 0.0 : kind == 1 ? -1e-50 : 1e-2 * u(rng);
      v.pos.push_back(v.rest.back() + d);
      const double exact = v.pos.back() - v.rest.back();
      v.key.push_back(static_cast<float>(exact + (stays ? 0.9 * kTolerance : 4 * kTolerance) * u(rng)));
      v.last.push_back(static_cast<float>(exact + 4 * kTolerance * u(rng)));
    }
  }
  return v;
}

// The contract of stage_vertices, written as plainly as it reads.
struct Expected {
  std::vector<float> staged;
  std::vector<bool> moved;
  StagingSummary summary;
};

Expected plain_staging(const Values& v, std::size_t n, bool with_key) {
  Expected e;
  StagingSummary& s = e.summary;
  float lo = std::numeric_limits<float>::infinity(), hi = -lo, mlo = lo, mhi = -lo;
  for (std::size_t i = 0; i < n; ++i) {
    bool moved = !with_key, since = !with_key;
    double unmoved = 0.0;
    for (std::size_t j = 3 * i; j < 3 * i + 3; ++j) {
      const double d = v.pos[j] - v.rest[j];
      e.staged.push_back(static_cast<float>(d));
      s.rounding = std::max(s.rounding, std::abs(double{e.staged.back()} - d));
      if (with_key) {
        moved |= std::abs(d - double{v.key[j]}) > kTolerance;
        since |= std::abs(d - double{v.last[j]}) > kTolerance;
        unmoved = std::max(unmoved, std::abs(d - double{v.key[j]}));
      }
    }
    e.moved.push_back(moved);
    s.moved += moved, s.moved_since_last += since;
    for (std::size_t j = 3 * i; j < 3 * i + 3; ++j) {
      lo = std::min(lo, e.staged[j]), hi = std::max(hi, e.staged[j]);
      if (moved) mlo = std::min(mlo, e.staged[j]), mhi = std::max(mhi, e.staged[j]);
    }
    if (!moved) s.unmoved_error = std::max(s.unmoved_error, unmoved);
  }
  // Zeros come out positive whatever their sign.
  if (n) s.lo = lo == 0.0f ? 0.0f : lo, s.hi = hi == 0.0f ? 0.0f : hi;
  if (s.moved) s.moved_lo = mlo == 0.0f ? 0.0f : mlo, s.moved_hi = mhi == 0.0f ? 0.0f : mhi;
  return e;
}

std::size_t words(std::size_t n) { return (n + 63) / 64; }

// The dispatched functions, as a copy of their own.
const StagingKernels kDispatched{"dispatched", stage_vertices, compact_moved};

std::vector<StagingKernels> every_copy() {
  std::vector<StagingKernels> out(staging_kernels().begin(), staging_kernels().end());
  out.push_back(kDispatched);
  return out;
}

TEST(DeltaStaging, EveryCopyThisCpuCanRunIsThere) {
  ASSERT_GE(staging_kernels().size(), 1u);
  EXPECT_STREQ(staging_kernels().front().name, "baseline");
  std::vector<std::string> names;
  for (const StagingKernels& k : staging_kernels()) names.push_back(k.name);
  // On an AVX2 or AVX-512 machine the tests below run those copies too.
  EXPECT_EQ(std::count(names.begin(), names.end(), "avx2"), cpu_has_avx2() ? 1 : 0);
  EXPECT_EQ(std::count(names.begin(), names.end(), "avx512"), cpu_has_avx512() && cpu_has_bmi2() ? 1 : 0);
}

// Each compiled copy, and the dispatched functions.
class EachCopy : public ::testing::TestWithParam<StagingKernels> {};
INSTANTIATE_TEST_SUITE_P(DeltaStaging, EachCopy, ::testing::ValuesIn(every_copy()),
                         [](const ::testing::TestParamInfo<StagingKernels>& info) { return std::string(info.param.name); });

void expect_summary_eq(const StagingSummary& got, const StagingSummary& want, const std::string& where) {
  EXPECT_TRUE(got.plausible) << where;
  EXPECT_EQ(got.moved, want.moved) << where;
  EXPECT_EQ(got.moved_since_last, want.moved_since_last) << where;
  // Bit for bit: a −0 where +0 is expected would change a frame's bytes.
  EXPECT_EQ(std::signbit(got.lo), std::signbit(want.lo)) << where;
  EXPECT_EQ(got.lo, want.lo) << where;
  EXPECT_EQ(got.hi, want.hi) << where;
  EXPECT_EQ(std::signbit(got.moved_lo), std::signbit(want.moved_lo)) << where;
  EXPECT_EQ(got.moved_lo, want.moved_lo) << where;
  EXPECT_EQ(got.moved_hi, want.moved_hi) << where;
  EXPECT_EQ(got.rounding, want.rounding) << where;
  EXPECT_EQ(got.unmoved_error, want.unmoved_error) << where;
}

std::vector<std::size_t> lengths() {
  std::vector<std::size_t> out;
  for (std::size_t n = 0; n <= 140; ++n) out.push_back(n);
  for (std::size_t n : {255u, 256u, 257u, 511u, 600u, 1000u}) out.push_back(n);
  return out;
}

TEST_P(EachCopy, MatchesPlainLoopsAtEveryLength) {
  const StagingKernels& k = GetParam();
  std::mt19937 rng(7);
  for (std::size_t n : lengths()) {
    Values v = random_values(n, rng);
    // A delta exactly at the tolerance from its key is not "moved".
    if (n > 3) {
      for (std::size_t j = 9; j < 12; ++j) v.rest[j] = 0.0, v.key[j] = 0.25f, v.pos[j] = 0.25 + kTolerance;
    }
    for (bool with_key : {true, false}) {
      const Expected want = plain_staging(v, n, with_key);
      std::vector<float> staged(3 * n, -1.0f);
      std::vector<std::uint64_t> moved(words(n), ~std::uint64_t{0});  // bits past the end must come out cleared
      const StagingSummary got = k.stage(v.pos.data(), v.rest.data(), with_key ? v.key.data() : nullptr,
                                         with_key ? v.last.data() : nullptr, kTolerance, n, staged.data(), moved.data());
      const std::string where = "n=" + std::to_string(n) + (with_key ? " with key" : " without key");
      expect_summary_eq(got, want.summary, where);
      for (std::size_t j = 0; j < 3 * n; ++j) ASSERT_EQ(staged[j], want.staged[j]) << where << " value " << j;
      for (std::size_t i = 0; i < 64 * words(n); ++i)
        ASSERT_EQ((moved[i / 64] >> (i % 64)) & 1, i < n && want.moved[i] ? 1u : 0u) << where << " vertex " << i;
      if (n > 3 && with_key) {
        EXPECT_FALSE(want.moved[3]) << "the case at the tolerance is not what it should be";
      }
    }
  }
}

TEST_P(EachCopy, CompactsTheMovedVerticesInOrder) {
  const StagingKernels& k = GetParam();
  std::mt19937 rng(11);
  for (std::size_t n : lengths()) {
    for (int pattern = 0; pattern < 4; ++pattern) {
      std::vector<std::uint64_t> moved(words(n), 0);
      std::vector<float> values(3 * n), want;
      for (std::size_t i = 0; i < n; ++i) {
        // Random, all, none, and long runs (the AVX-512 copy's fast path).
        const bool m = pattern == 0 ? rng() % 3 != 0 : pattern == 1 ? true : pattern == 2 ? false : (i / 37) % 2 == 0;
        if (m) moved[i / 64] |= std::uint64_t{1} << (i % 64);
        for (int c = 0; c < 3; ++c) {
          values[3 * i + c] = static_cast<float>(3 * i + c);
          if (m) want.push_back(values[3 * i + c]);
        }
      }
      const std::size_t kept = k.compact(values.data(), moved.data(), n);
      ASSERT_EQ(3 * kept, want.size()) << n << " pattern " << pattern;
      for (std::size_t j = 0; j < want.size(); ++j) ASSERT_EQ(values[j], want[j]) << n << " pattern " << pattern << " value " << j;
    }
  }
}

TEST_P(EachCopy, ImplausibleDeltasAreReportedWherever) {
  const StagingKernels& k = GetParam();
  std::mt19937 rng(9);
  const double bad[] = {std::numeric_limits<double>::quiet_NaN(), std::numeric_limits<double>::infinity(), 2 * kMaxDeltaMagnitude};
  for (std::size_t n : {1u, 3u, 8u, 13u, 17u, 70u}) {
    for (std::size_t at = 0; at < 3 * n; ++at) {
      for (double b : bad) {
        Values v = random_values(n, rng);
        v.pos[at] = b;
        std::vector<float> staged(3 * n);
        std::vector<std::uint64_t> moved(words(n));
        for (bool with_key : {true, false}) {
          EXPECT_FALSE(k.stage(v.pos.data(), v.rest.data(), with_key ? v.key.data() : nullptr, with_key ? v.last.data() : nullptr,
                               kTolerance, n, staged.data(), moved.data())
                           .plausible)
              << n << " " << at << " " << b;
        }
      }
    }
  }
}

}  // namespace
}  // namespace filigree
