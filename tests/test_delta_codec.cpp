// Frame deltas on the wire (DESIGN §3): Draco point cloud, sequential order,
// explicit quantization over the deltas' own range.

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <exception>
#include <limits>
#include <numbers>
#include <numeric>
#include <random>
#include <string>
#include <thread>
#include <vector>

#include <gtest/gtest.h>

#include "codec/delta_codec.h"
#include "codec/draco_library_encoder.h"
#include "codec/draco_writer.h"
#include "support/test_meshes.h"

namespace filigree {
namespace {

// A smooth deformation of the mesh: 0.05·diag·(sin, cos, sin) of the
// position, one period over the bounding-box diagonal.
std::vector<Vec3> smooth_field(const TriMesh& mesh) {
  const double diag = bounding_box_diagonal(mesh.positions);
  const double k = 2.0 * std::numbers::pi / diag;
  std::vector<Vec3> d;
  d.reserve(mesh.positions.size());
  for (const Vec3& p : mesh.positions) {
    d.emplace_back(0.05 * diag * std::sin(k * p.x()), 0.05 * diag * std::cos(k * p.y()),
                   0.05 * diag * std::sin(k * p.z()));
  }
  return d;
}

double max_abs_error(const std::vector<Vec3>& a, const std::vector<Vec3>& b) {
  double e = 0.0;
  for (std::size_t i = 0; i < a.size(); ++i) e = std::max(e, (a[i] - b[i]).cwiseAbs().maxCoeff());
  return e;
}

// The theoretical bound: half a quantization step, plus float32 rounding.
// Draco converts to float, subtracts the origin, multiplies by the inverse
// step, rounds, and on decode multiplies by the step and adds the origin, all
// in float: each contributes at most about one unit roundoff (2^-24) of the
// range or of the largest magnitude. 8 of each is a safe allowance, still
// below half a step for 8 and 14 bits by orders of magnitude.
double theoretical_bound(const EncodedDeltas& e) {
  const double range = e.range;
  const double step = range / (std::ldexp(1.0, static_cast<int>(e.bits)) - 1.0);
  const double magnitude = std::max(std::abs(double{e.min}), std::abs(double{e.min} + range));
  const double u = std::ldexp(1.0, -24);
  return step / 2.0 + 8.0 * u * (range + magnitude);
}

void expect_round_trip(const std::vector<Vec3>& deltas, std::uint32_t bits, const std::string& what) {
  SCOPED_TRACE(what + ", bits " + std::to_string(bits));
  const EncodedDeltas e = encode_deltas(deltas, bits);
  ASSERT_EQ(e.count, deltas.size());
  ASSERT_EQ(e.bits, bits);
  ASSERT_FALSE(e.bytes.empty());
  const std::vector<Vec3> decoded = decode_deltas(e);
  ASSERT_EQ(decoded.size(), deltas.size());

  // The quantization box covers every component.
  double lo = std::numeric_limits<double>::infinity(), hi = -lo;
  for (const Vec3& d : deltas) {
    lo = std::min(lo, static_cast<double>(static_cast<float>(d.minCoeff())));
    hi = std::max(hi, static_cast<double>(static_cast<float>(d.maxCoeff())));
  }
  // Origin and range are what survives Draco's six-decimal option strings:
  // at most a few millionths below the smallest value and above the span.
  EXPECT_LE(double{e.min}, lo);
  EXPECT_GT(double{e.min}, lo - 3e-6);
  EXPECT_GE(double{e.min} + double{e.range}, hi);
  EXPECT_LE(double{e.range}, (hi - e.min) * (1.0 + 1e-6) + 3e-6);

  const double actual = max_abs_error(decoded, deltas);
  EXPECT_LE(actual, double{e.max_error});  // reported ≥ actual
  EXPECT_LE(double{e.max_error}, actual * (1.0 + 1e-6) + 1e-30) << "max_error is not tight";
  EXPECT_LE(double{e.max_error}, theoretical_bound(e))
      << "range " << e.range << " step " << e.range / (std::ldexp(1.0, static_cast<int>(bits)) - 1.0);
  for (std::size_t i = 0; i < deltas.size(); ++i) {
    ASSERT_LE((decoded[i] - deltas[i]).cwiseAbs().maxCoeff(), double{e.max_error}) << "point " << i;
  }
}

TEST(DeltaCodec, RoundTripWithinMaxErrorAndTheoreticalBound) {
  const TriMesh sphere = test::icosphere(3);
  const TriMesh bunny = test::shipped_mesh("bunny_small.obj");
  for (std::uint32_t bits : {8u, 14u, 20u}) {
    expect_round_trip(smooth_field(sphere), bits, "icosphere(3)");
    expect_round_trip(smooth_field(bunny), bits, "bunny_small");
  }
}

TEST(DeltaCodec, MaxErrorCoversActualErrorForAnyScaleAndBits) {
  std::mt19937 rng(7);
  // Ranges far from and near zero, tiny and large, including an offset field
  // (every delta around 100) where float rounding of the values dominates.
  struct Case {
    double centre, spread;
  };
  for (const Case c : {Case{0.0, 1e-6}, Case{0.0, 1.0}, Case{0.0, 1e3}, Case{100.0, 1.0}, Case{-3.0, 1e-2}}) {
    std::uniform_real_distribution<double> u(c.centre - c.spread, c.centre + c.spread);
    std::vector<Vec3> d(500);
    for (Vec3& v : d) v = Vec3(u(rng), u(rng), u(rng));
    for (std::uint32_t bits = 8; bits <= 24; ++bits) {
      SCOPED_TRACE("centre " + std::to_string(c.centre) + " spread " + std::to_string(c.spread) + " bits " +
                   std::to_string(bits));
      const EncodedDeltas e = encode_deltas(d, bits);
      const std::vector<Vec3> decoded = decode_deltas(e);
      ASSERT_EQ(decoded.size(), d.size());
      const double actual = max_abs_error(decoded, d);
      EXPECT_LE(actual, double{e.max_error});
      EXPECT_LE(double{e.max_error}, actual * (1.0 + 1e-6) + 1e-30) << "max_error is not tight";
      EXPECT_LE(double{e.max_error}, theoretical_bound(e));
    }
  }
}

// The decoded values we compute (without decoding) are bit for bit what
// Draco's decoder gives, in every compiled copy this CPU runs, for random
// values at many scales and bit depths, a constant field and values
// straddling zero by less than the options' 1e-6; 401 points (the vector
// loop's last values go through its scalar tail), and 1 and 3 values (no
// vector iteration, and a range found without its vector loop).
TEST(DeltaCodec, ComputedDecodeEqualsDracoBitForBit) {
  std::mt19937 rng(11);
  struct Case {
    double centre, spread;
    std::uint32_t points;
  };
  for (const Case c : {Case{0.0, 3e-7, 401}, Case{1e-6, 1e-5, 401}, Case{0.0, 1.0, 401}, Case{-250.0, 40.0, 401}, Case{7.0, 0.0, 401},
                       Case{0.0, 1e6, 401}, Case{0.5, 0.5, 1}}) {
    std::uniform_real_distribution<float> u(static_cast<float>(c.centre - c.spread), static_cast<float>(c.centre + c.spread));
    std::vector<float> values(3 * c.points);
    for (float& v : values) v = c.spread > 0.0 ? u(rng) : static_cast<float>(c.centre);
    for (std::uint32_t bits : {8u, 11u, 16u, 24u}) {
      SCOPED_TRACE("centre " + std::to_string(c.centre) + " spread " + std::to_string(c.spread) + " bits " +
                   std::to_string(bits));
      const DeltaQuantization q = quantization_over(values, bits);
      ASSERT_LE(q.min, *std::min_element(values.begin(), values.end()));
      ASSERT_GE(double{q.min} + q.range, *std::max_element(values.begin(), values.end()));
      const std::string bytes = encode_draco(values, q);
      std::vector<float> decoded(values.size());
      decode_deltas_into(bytes, c.points, decoded);
      ASSERT_FALSE(decode_kernels().empty());
      for (const DecodeKernel& k : decode_kernels()) {
        SCOPED_TRACE(k.name);
        std::vector<float> computed(values.size()), measured(values.size());
        k.decode(q, values, computed);
        // The measuring copy decodes the same, and its largest difference
        // is the largest float |decoded − value|.
        const float worst = k.decode_measured(q, values, measured);
        float want_worst = 0.0f;
        for (std::size_t i = 0; i < values.size(); ++i) {
          ASSERT_EQ(computed[i], decoded[i]) << "value " << i << " = " << values[i];
          ASSERT_EQ(measured[i], decoded[i]) << "value " << i << " = " << values[i];
          ASSERT_LE(std::abs(double{decoded[i]} - values[i]), q.bound()) << "value " << i;
          want_worst = std::max(want_worst, std::abs(decoded[i] - values[i]));
        }
        EXPECT_EQ(worst, want_worst);
      }
    }
  }
}

// encode_draco writes Draco's own bytes: for every speed, bit depth and kind
// of values (noise, smooth walks as real deltas are, a few repeated levels,
// walks with rare jumps, one to five points, a real mesh's smooth field),
// what Draco 1.5's encoder writes for the same input. Both of Draco's symbol
// coders are reached (the method byte follows the fixed 26-byte prefix of
// this stream).
TEST(DeltaCodec, EncodeDracoWritesDracosOwnBytes) {
  constexpr std::size_t kSymbolMethodOffset = 26;
  std::mt19937 rng(5);
  int tagged = 0, raw = 0, cases = 0;
  const auto check = [&](const std::vector<float>& values, std::uint32_t bits, const std::string& what) {
    const DeltaQuantization q = quantization_over(values, bits);
    for (int speed : {0, 3, 5, 8, 10}) {
      SCOPED_TRACE(what + ", " + std::to_string(values.size() / 3) + " points, bits " + std::to_string(bits) +
                   ", speed " + std::to_string(speed));
      const std::string ours = encode_draco(values, q, speed);
      const std::string dracos = encode_with_draco_library(values, q, speed);
      ASSERT_EQ(ours.size(), dracos.size());
      ASSERT_TRUE(ours == dracos) << "first difference at byte "
                                  << std::mismatch(ours.begin(), ours.end(), dracos.begin()).first - ours.begin();
      ASSERT_GT(ours.size(), kSymbolMethodOffset);
      (ours[kSymbolMethodOffset] == 0 ? tagged : raw) += 1;
      ++cases;
    }
  };
  for (int trial = 0; trial < 80; ++trial) {
    const int points = trial % 10 == 0 ? 1 + trial / 10 % 5 : std::uniform_int_distribution<int>(6, 2500)(rng);
    const double scale = std::pow(10.0, std::uniform_real_distribution<double>(-5.0, 2.0)(rng));
    std::vector<float> values(3 * static_cast<std::size_t>(points));
    float walk = 0.0f;
    for (float& v : values) {
      switch (trial % 5) {
        case 0: v = std::normal_distribution<float>(0.0f, static_cast<float>(scale))(rng); break;
        case 1: walk += std::normal_distribution<float>(0.0f, static_cast<float>(scale * 0.01))(rng); v = walk; break;
        case 2: v = static_cast<float>(static_cast<double>(rng() % 3) * scale); break;
        case 3: v = std::uniform_real_distribution<float>(static_cast<float>(-scale), static_cast<float>(scale))(rng); break;
        default:  // a slow walk with rare jumps anywhere, as a sparse chunk's present vertices
          walk += std::normal_distribution<float>(0.0f, static_cast<float>(scale * 0.001))(rng);
          if (rng() % 50 == 0) walk = std::uniform_real_distribution<float>(static_cast<float>(-scale), static_cast<float>(scale))(rng);
          v = walk;
      }
    }
    check(values, 8 + static_cast<std::uint32_t>(rng() % 17), "trial " + std::to_string(trial));
  }
  std::vector<float> field;
  for (const Vec3& d : smooth_field(test::shipped_mesh("bunny_small.obj")))
    for (int k = 0; k < 3; ++k) field.push_back(static_cast<float>(d[k]));
  for (std::uint32_t bits : {12u, 16u, 20u, 24u}) check(field, bits, "bunny field");
  EXPECT_GT(tagged, 0);
  EXPECT_GT(raw, 0);
  // Draco reads speeds outside 0…10 in ways of its own (−1 is its default
  // 5): they are refused.
  const DeltaQuantization q = quantization_over(field, 14);
  for (int speed : {-1, 11}) EXPECT_THROW(encode_draco(field, q, speed), DeltaCodecError) << speed;
  EXPECT_EQ(cases, 5 * (80 + 4));
}

TEST(DeltaCodec, PreservesPointOrder) {
  // Distinct deltas per point, 1e-3 apart per axis: any reordering would put
  // a value off by ≥ 1e-3, far beyond the 20-bit error (~1e-5 here).
  const std::uint32_t n = 5000;
  std::vector<Vec3> d(n);
  for (std::uint32_t i = 0; i < n; ++i) d[i] = 1e-3 * Vec3(i, -2.0 * i + 1.0, 0.5 * (n - i));
  // Also in a shuffled order: the order is what we sent, not sorted.
  std::vector<Vec3> shuffled = d;
  std::shuffle(shuffled.begin(), shuffled.end(), std::mt19937(3));
  for (const auto* input : {&d, &shuffled}) {
    const EncodedDeltas e = encode_deltas(*input, 20);
    const std::vector<Vec3> decoded = decode_deltas(e);
    ASSERT_EQ(decoded.size(), n);
    for (std::uint32_t i = 0; i < n; ++i) {
      ASSERT_LT((decoded[i] - (*input)[i]).cwiseAbs().maxCoeff(), 0.25e-3) << "point " << i;
    }
  }
}

TEST(DeltaCodec, AllZeroIsEmptyAndDecodesToZeros) {
  std::vector<Vec3> d(1234, Vec3::Zero());
  d[17] = Vec3(-0.0, 0.0, -0.0);  // negative zero is zero too
  const EncodedDeltas e = encode_deltas(d, 14);
  EXPECT_TRUE(e.bytes.empty());
  EXPECT_EQ(e.count, 1234u);
  EXPECT_EQ(e.bits, 14u);
  EXPECT_EQ(e.min, 0.0f);
  EXPECT_EQ(e.range, 0.0f);
  EXPECT_EQ(e.max_error, 0.0f);
  const std::vector<Vec3> decoded = decode_deltas(e);
  ASSERT_EQ(decoded.size(), 1234u);
  for (const Vec3& v : decoded) EXPECT_EQ(v, Vec3::Zero());

  // No deltas at all: the same, with count 0.
  const EncodedDeltas none = encode_deltas({}, 14);
  EXPECT_TRUE(none.bytes.empty());
  EXPECT_EQ(none.count, 0u);
  EXPECT_TRUE(decode_deltas(none).empty());
}

TEST(DeltaCodec, ConstantAndSparseFields) {
  // Every component equal: range would be 0; the guard keeps it positive and
  // the value comes back exactly (as float).
  const std::vector<Vec3> constant(300, Vec3(0.25, 0.25, 0.25));
  const EncodedDeltas c = encode_deltas(constant, 14);
  EXPECT_FALSE(c.bytes.empty());
  EXPECT_GT(c.range, 0.0f);
  EXPECT_EQ(c.max_error, 0.0f);
  for (const Vec3& v : decode_deltas(c)) EXPECT_EQ(v, Vec3(0.25, 0.25, 0.25));

  // A rigid translation: the same delta everywhere, different per axis.
  expect_round_trip(std::vector<Vec3>(300, Vec3(0.1, -0.2, 0.3)), 14, "translation");
  // One moved vertex among many still.
  std::vector<Vec3> sparse(1000, Vec3::Zero());
  sparse[500] = Vec3(0.0, 1e-3, 0.0);
  expect_round_trip(sparse, 14, "one vertex");
  // A subnormal difference must not break Draco's quantizer.
  std::vector<Vec3> tiny(10, Vec3::Zero());
  tiny[3] = Vec3(1e-40, 0.0, 0.0);
  const EncodedDeltas t = encode_deltas(tiny, 14);
  EXPECT_EQ(decode_deltas(t).size(), 10u);
  EXPECT_LE(max_abs_error(decode_deltas(t), tiny), double{t.max_error});
}

TEST(DeltaCodec, RejectsBadBits) {
  const std::vector<Vec3> d = smooth_field(test::icosphere(1));
  for (std::uint32_t bits : {0u, 1u, 7u, 25u, 31u, 32u, 1000u}) {
    EXPECT_THROW(encode_deltas(d, bits), DeltaCodecError) << bits;
  }
  EXPECT_NO_THROW(encode_deltas(d, 8));
  EXPECT_NO_THROW(encode_deltas(d, 24));
}

TEST(DeltaCodec, RejectsNonFiniteDeltas) {
  const double bad[] = {std::numeric_limits<double>::quiet_NaN(), std::numeric_limits<double>::infinity(),
                        -std::numeric_limits<double>::infinity(), 1e31};
  for (double b : bad) {
    for (int c = 0; c < 3; ++c) {
      std::vector<Vec3> d(50, Vec3(0.1, 0.2, 0.3));
      d[42][c] = b;
      EXPECT_THROW(encode_deltas(d, 14), DeltaCodecError) << b << " in component " << c;
    }
  }
  // Non-finite even when everything else is zero (not the empty shortcut).
  std::vector<Vec3> d(5, Vec3::Zero());
  d[0].x() = std::numeric_limits<double>::quiet_NaN();
  EXPECT_THROW(encode_deltas(d, 14), DeltaCodecError);
}

TEST(DeltaCodec, RejectsCountMismatch) {
  const std::vector<Vec3> d = smooth_field(test::icosphere(2));
  EncodedDeltas e = encode_deltas(d, 14);
  for (std::uint32_t count : {0u, e.count - 1, e.count + 1, 2 * e.count, 0xffffffffu}) {
    EncodedDeltas wrong = e;
    wrong.count = count;
    EXPECT_THROW(decode_deltas(wrong), DeltaCodecError) << count;
  }
}

// Whatever the bytes, decode_deltas gives `count` values or a DeltaCodecError.
// (Run under AddressSanitizer too: no out-of-bounds read either.)
TEST(DeltaCodec, CorruptBuffersAreErrorsNeverCrashes) {
  const TriMesh bunny = test::shipped_mesh("bunny_small.obj");
  std::vector<EncodedDeltas> originals;
  for (std::uint32_t bits : {8u, 14u, 24u}) originals.push_back(encode_deltas(smooth_field(bunny), bits));
  {
    std::vector<Vec3> small(40);
    for (std::size_t i = 0; i < small.size(); ++i) small[i] = Vec3(0.01 * i, -0.02 * i, 0.5);
    originals.push_back(encode_deltas(small, 14));
  }

  std::mt19937 rng(12345);
  auto uniform = [&](std::size_t n) { return std::uniform_int_distribution<std::size_t>(0, n - 1)(rng); };
  const std::size_t header = 15;  // Draco header + point count: checked before Draco runs
  int errors = 0, decoded_ok = 0;
  const int trials = 4000;
  for (int trial = 0; trial < trials; ++trial) {
    EncodedDeltas e = originals[uniform(originals.size())];
    std::string& b = e.bytes;
    const int kind = trial % 6;
    if (kind == 0) {  // flip 1–4 bits anywhere
      for (std::size_t k = 1 + uniform(4); k > 0; --k) b[uniform(b.size())] ^= static_cast<char>(1 << uniform(8));
    } else if (kind == 1) {  // flip 1–4 bits past the header, so Draco itself parses the damage
      for (std::size_t k = 1 + uniform(4); k > 0; --k) {
        b[header + uniform(b.size() - header)] ^= static_cast<char>(1 << uniform(8));
      }
    } else if (kind == 2) {  // overwrite 1–16 bytes past the header with random values
      for (std::size_t k = 1 + uniform(16); k > 0; --k) b[header + uniform(b.size() - header)] = static_cast<char>(rng());
    } else if (kind == 3) {  // truncate
      b.resize(uniform(b.size()));
    } else if (kind == 4) {  // keep the header, replace the rest with garbage of random length
      b.resize(header + uniform(2 * b.size()));
      for (std::size_t i = header; i < b.size(); ++i) b[i] = static_cast<char>(rng());
    } else {  // pure garbage, sometimes with a DRACO magic
      b.assign(uniform(64), '\0');
      for (char& ch : b) ch = static_cast<char>(rng());
      if (b.size() >= 5 && (trial & 1)) b.replace(0, 5, "DRACO");
    }
    try {
      const std::vector<Vec3> out = decode_deltas(e);
      ASSERT_EQ(out.size(), e.count) << "trial " << trial;
      // An empty buffer (a truncation to 0 bytes) means "all zero" by contract.
      ++decoded_ok;
    } catch (const DeltaCodecError&) {
      ++errors;
    } catch (const std::exception& ex) {
      ADD_FAILURE() << "trial " << trial << " (kind " << kind << ") threw a non-codec error: " << ex.what();
    }
  }
  std::printf("[ corrupt  ] %d trials: %d DeltaCodecError, %d decoded to count values\n", trials, errors,
              decoded_ok);
  EXPECT_GT(errors, trials / 2);  // most damage is detected
}

// Several chunks' coders interleaved in one loop write what each writes
// alone: groups of 1 to 9 chunks (more than one loop's worth) of 1–40000
// points, so coders of different lengths drop out at different steps;
// empty chunks among them; both symbol schemes; every speed's precision.
TEST(DeltaCodec, InterleavedChunksWriteTheSameBytes) {
  constexpr std::size_t kSymbolMethodOffset = 26;
  std::mt19937 rng(11);
  int tagged = 0, raw = 0;
  for (int trial = 0; trial < 40; ++trial) {
    const std::size_t n = 1 + static_cast<std::size_t>(trial) % 9;
    std::vector<std::vector<float>> values(n);
    std::vector<DeltaQuantization> q(n);
    for (std::size_t c = 0; c < n; ++c) {
      if (rng() % 7 == 0) continue;  // an empty chunk: no buffer
      // Every tenth trial, one chunk of 40000 points at 16 bits and speed 0,
      // a slow walk with one value in 20 anywhere: over 2^12 distinct
      // symbols raise the raw coder's precision to 2^20, where a rare
      // symbol's probability is < 16 and one step can write 3 bytes.
      const bool large = trial % 10 == 9 && c == 0;
      int points = 40000;
      if (!large)
        points = rng() % 4 == 0 ? 1 + static_cast<int>(rng() % 5) : std::uniform_int_distribution<int>(6, 6000)(rng);
      const double scale = std::pow(10.0, std::uniform_real_distribution<double>(-4.0, 1.0)(rng));
      float walk = 0.0f;
      for (int i = 0; i < 3 * points; ++i) {
        // Noise codes tagged at high bit depths; a smooth walk codes raw.
        walk += std::normal_distribution<float>(0.0f, static_cast<float>(scale * (large ? 1e-4 : 0.01)))(rng);
        if (large && i % 20 == 0) {  // rare values anywhere in the range: many distinct, rare symbols
          const auto bound = static_cast<float>(scale);
          values[c].push_back(std::uniform_real_distribution<float>(-bound, bound)(rng));
          continue;
        }
        values[c].push_back(c % 2 || large ? walk : std::normal_distribution<float>(0.0f, static_cast<float>(scale))(rng));
      }
      q[c] = quantization_over(values[c], large ? 16 : 8 + static_cast<std::uint32_t>(rng() % 17));
    }
    const int speed = trial % 10 == 9 ? 0 : static_cast<int>(rng() % 11);
    std::vector<std::string> alone(n), together(n, "stale");
    std::vector<DracoChunk> chunks;
    for (std::size_t c = 0; c < n; ++c) {
      alone[c] = encode_draco(values[c], q[c], speed);
      chunks.push_back({values[c], q[c], &together[c]});
    }
    encode_draco_many(chunks, speed);
    for (std::size_t c = 0; c < n; ++c) {
      SCOPED_TRACE("trial " + std::to_string(trial) + ", chunk " + std::to_string(c) + " of " + std::to_string(n));
      ASSERT_EQ(together[c], alone[c]);
      if (alone[c].size() > kSymbolMethodOffset) (alone[c][kSymbolMethodOffset] == 0 ? tagged : raw) += 1;
    }
  }
  EXPECT_GT(tagged, 0);
  EXPECT_GT(raw, 0);
}

// Every one of the 2^18 symbols an 18-bit chunk can have, in one chunk: the
// raw scheme Draco's size estimate prefers cannot code 2^18 distinct symbols
// (its precision would need 19 bits), so Draco's own encoder fails here,
// while ours falls back to the tagged scheme, which Draco decodes. The
// values are whole numbers over [0, 2^18 − 1], so 18 bits carry them
// exactly; x steps through every correction once, y supplies the extremes.
TEST(DeltaCodec, EveryEighteenBitSymbolFallsBackToTheTaggedScheme) {
  constexpr std::size_t kSymbolMethodOffset = 26;
  constexpr std::int64_t kLevels = 1 << 18;
  std::vector<std::int64_t> corrections(kLevels);
  std::iota(corrections.begin(), corrections.end(), -kLevels / 2);
  std::shuffle(corrections.begin(), corrections.end(), std::mt19937(3));
  std::vector<float> values;
  std::int64_t x = 0;
  for (std::size_t p = 0; p <= corrections.size(); ++p) {
    if (p > 0) x = ((x + corrections[p - 1]) % kLevels + kLevels) % kLevels;
    const float y = p == 1 ? static_cast<float>(kLevels - 1) : 0.0f;
    values.insert(values.end(), {static_cast<float>(x), y, 0.0f});
  }
  const DeltaQuantization q = quantization_over(values, 18);
  ASSERT_EQ(q.min, 0.0f);
  ASSERT_EQ(q.range, static_cast<float>(kLevels - 1));
  EXPECT_THROW(encode_with_draco_library(values, q, kDefaultEncodingSpeed), DeltaCodecError);
  const std::string ours = encode_draco(values, q, kDefaultEncodingSpeed);
  ASSERT_GT(ours.size(), kSymbolMethodOffset);
  EXPECT_EQ(ours[kSymbolMethodOffset], 0) << "not the tagged scheme";
  std::vector<float> decoded(values.size());
  decode_deltas_into(ours, static_cast<std::uint32_t>(values.size() / 3), decoded);
  EXPECT_EQ(decoded, values);
}

TEST(DeltaCodec, SameBytesFromConcurrentEncoders) {
  const std::vector<Vec3> d = smooth_field(test::icosphere(4));
  const EncodedDeltas reference = encode_deltas(d, 14);
  std::vector<std::string> bytes(4);
  std::vector<std::thread> threads;
  for (std::size_t t = 0; t < bytes.size(); ++t) {
    threads.emplace_back([&, t] {
      for (int k = 0; k < 5; ++k) bytes[t] = encode_deltas(d, 14).bytes;
    });
  }
  for (std::thread& th : threads) th.join();
  for (const std::string& b : bytes) EXPECT_EQ(b, reference.bytes);
}

// Measured, printed, not asserted: the size depends on how coherent the
// vertex order is (Draco's sequential point cloud predicts each point from
// the previous one).
TEST(DeltaCodec, BytesPerVertexOnShippedBunny) {
  const TriMesh bunny = test::shipped_mesh("bunny_small.obj");
  const std::vector<Vec3> d = smooth_field(bunny);
  std::vector<std::size_t> perm(d.size());
  std::iota(perm.begin(), perm.end(), std::size_t{0});
  std::shuffle(perm.begin(), perm.end(), std::mt19937(42));
  std::vector<Vec3> shuffled(d.size());
  for (std::size_t i = 0; i < d.size(); ++i) shuffled[i] = d[perm[i]];

  for (std::uint32_t bits : {8u, 14u, 20u}) {
    const EncodedDeltas original = encode_deltas(d, bits);
    const EncodedDeltas mixed = encode_deltas(shuffled, bits);
    const double n = static_cast<double>(d.size());
    std::printf("[ size     ] bunny_small %zu vertices, %2u bits: original order %6zu B = %.2f B/vertex, "
                "shuffled %6zu B = %.2f B/vertex (raw float32 12 B/vertex); max_error %.3g of diag %.3g\n",
                d.size(), bits, original.bytes.size(), original.bytes.size() / n, mixed.bytes.size(),
                mixed.bytes.size() / n, original.max_error, bounding_box_diagonal(bunny.positions));
    if (bits == 14) {
      RecordProperty("bytes_per_vertex_14_original", std::to_string(original.bytes.size() / n));
      RecordProperty("bytes_per_vertex_14_shuffled", std::to_string(mixed.bytes.size() / n));
    }
  }
}

}  // namespace
}  // namespace filigree
