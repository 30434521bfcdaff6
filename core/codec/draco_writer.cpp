// The Draco bitstream of one frame chunk (draco_writer.h). Each step names
// the Draco 1.5 source whose output it reproduces; where Draco makes a choice
// from floating-point estimates, the same arithmetic in the same order is
// used, so the choice (and so every byte) is the same.
//
// Layout, in order:
//   header        "DRACO", 2, 3, point cloud (0), sequential (0), flags u16 0
//   geometry      i32 number of points
//   attributes    u8 1 encoder; varint 1 attribute; u8 GENERIC (4),
//                 FLOAT32 (9), 3 components, not normalized; varint id 0;
//                 u8 quantization encoder (2)
//   values        i8 difference prediction (0), i8 wrap transform (1),
//                 u8 1 (compressed), the symbols (EncodeSymbols), i32 min
//                 and max of the quantized values (wrap transform data)
//   quantization  3 × f32 origin, f32 range, u8 bits

#include "codec/draco_writer.h"

#include <algorithm>
#include <array>
#include <bit>
#include <cmath>
#include <cstring>
#include <limits>
#include <vector>

#include "codec/delta_codec.h"

namespace filigree {
namespace {

constexpr std::uint8_t kVersionMajor = 2, kVersionMinor = 3;  // kDracoPointCloudBitstreamVersion
constexpr std::uint8_t kPointCloud = 0, kSequentialEncoding = 0;
constexpr std::uint8_t kGenericAttribute = 4, kFloat32 = 9;
constexpr std::uint8_t kQuantizationEncoder = 2;  // SEQUENTIAL_ATTRIBUTE_ENCODER_QUANTIZATION
constexpr std::uint8_t kPredictionDifference = 0, kTransformWrap = 1;
constexpr std::uint8_t kTagged = 0, kRaw = 1;  // SymbolCodingMethod
constexpr int kMaxRawBitLength = 18;           // symbol_encoding.cc
constexpr int kMaxTag = 32;

// Little-endian fields appended to a string (EncoderBuffer::Encode).
class Writer {
 public:
  explicit Writer(std::string& s) : s_(s) {}
  void u8(std::uint32_t v) { s_.push_back(static_cast<char>(v & 0xffu)); }
  void u32(std::uint32_t v) {
    for (int i = 0; i < 4; ++i) u8(v >> (8 * i));
  }
  void f32(float f) { u32(std::bit_cast<std::uint32_t>(f)); }
  void varint(std::uint64_t v) {  // EncodeVarint, unsigned
    for (; v >= 0x80; v >>= 7) u8(static_cast<std::uint32_t>(v & 0x7f) | 0x80u);
    u8(static_cast<std::uint32_t>(v));
  }
  void bytes(const std::uint8_t* p, std::size_t n) { s_.append(reinterpret_cast<const char*>(p), n); }

 private:
  std::string& s_;
};

int most_significant_bit(std::uint32_t n) { return 31 ^ std::countl_zero(n); }  // n > 0

// One symbol of a rANS alphabet, with what encoding it needs precomputed.
struct RansSymbol {
  std::uint64_t reciprocal = 0;  // ⌈2^64 / prob⌉ for prob ≥ 2; 2^64 − 1 for prob 1 (see rans_put)
  std::uint32_t bound = 0;       // renormalise while state ≥ this
  std::uint32_t cum = 0;         // cumulative probability; for prob 1, plus `spare` (see rans_put)
  std::uint32_t spare = 0;       // precision − prob
};

// ⌈2^64/p⌉ = ⌊(2^64 − 1)/p⌋ + 1 (p ≥ 2), for the probabilities below 2^12
// that most symbols of a chunk have: a 64-bit division per symbol and chunk
// was most of building a table (a chunk of 2443 points has some 300 symbols).
constexpr std::size_t kTabledReciprocals = 1 << 12;
constexpr std::array<std::uint64_t, kTabledReciprocals> kReciprocals = [] {
  std::array<std::uint64_t, kTabledReciprocals> r{};
  for (std::size_t p = 2; p < r.size(); ++p) r[p] = ~std::uint64_t{0} / p + 1;
  return r;
}();
std::uint64_t reciprocal_of(std::uint32_t p) {
  if (p == 1) return ~std::uint64_t{0};
  return p < kTabledReciprocals ? kReciprocals[p] : ~std::uint64_t{0} / p + 1;
}

// What one chunk keeps from its preparation until its coder has run.
struct ChunkScratch {
  std::vector<std::uint32_t> symbols;
  std::vector<std::uint32_t> bit_lengths;  // per point (the tagged scheme's rANS symbols)
  std::vector<RansSymbol> table;
  std::vector<std::uint8_t> coded;  // rANS bytes, then the tagged scheme's value bits
};

// What preparing a chunk needs only while it runs: one per thread, shared by
// the chunks of a group (their scratch together stays near one core's L2).
struct PrepareScratch {
  std::vector<std::int32_t> quantized;
  std::vector<std::uint32_t> histogram;
  std::vector<std::uint32_t> present;  // the symbols that occur, ascending
  std::vector<std::uint32_t> probabilities;
  std::vector<std::uint64_t> order;  // (probability, symbol) of the symbols of probability ≥ 2
};

// The symbols of histogram[0, size) that occur, ascending, written to `out`
// (room for `size`). The loops after it run over these only: a chunk's few
// hundred symbols are scattered over thousands of entries, and branching on
// each entry mispredicted often.
std::span<const std::uint32_t> occurring_symbols(const std::uint32_t* histogram, std::size_t size, std::uint32_t* out) {
  std::size_t n = 0;
  for (std::size_t i = 0; i < size; ++i) {
    out[n] = static_cast<std::uint32_t>(i);
    n += histogram[i] != 0;
  }
  return {out, n};
}

// Draco's ComputeShannonEntropy over a histogram: the same sum in the same
// (ascending) order, so the same double and the same truncation.
std::int64_t entropy_bits(const std::uint32_t* histogram, std::span<const std::uint32_t> present, int total) {
  double bits = 0.0;
  const double n = total;
  for (const std::uint32_t i : present) bits += static_cast<int>(histogram[i]) * std::log2(static_cast<double>(histogram[i]) / n);
  return static_cast<std::int64_t>(-bits);
}

// ApproximateRAnsFrequencyTableBits (rans_symbol_coding.h).
std::int64_t table_bits(std::int32_t max_value, int unique) {
  const std::int64_t zero_bits = 8 * (unique + (max_value - unique) / 64);
  return 8 * unique + zero_bits;
}

// RAnsSymbolEncoder::Create: frequencies → probabilities that sum to
// 2^precision_bits, with Draco's rounding and its rescaling of the
// over-allocated case. False where Draco's Create fails (or would never
// finish).
bool rans_probabilities(const std::uint32_t* frequencies, std::span<const std::uint32_t> present, int precision_bits,
                        PrepareScratch& s, std::vector<RansSymbol>& table) {
  std::uint64_t total = 0;
  for (const std::uint32_t i : present) total += frequencies[i];
  const int num_symbols = static_cast<int>(present.back()) + 1;
  // Entries of symbols that never occur are 0 in Draco's; none is read here.
  std::vector<std::uint32_t>& prob = s.probabilities;
  prob.resize(static_cast<std::size_t>(num_symbols));
  const int precision = 1 << precision_bits;
  const double total_d = static_cast<double>(total), precision_d = precision;
  int total_prob = 0;
  for (const std::uint32_t i : present) {
    const double p = static_cast<double>(frequencies[i]) / total_d;
    auto r = static_cast<std::uint32_t>(p * precision_d + 0.5f);
    if (r == 0) r = 1;
    prob[i] = r;
    total_prob += static_cast<int>(r);
  }
  if (total_prob < precision) {
    // Draco sorts every symbol by probability, stably, and gives the
    // difference to the last: the most probable, the last of equals.
    std::uint32_t top = present.front();
    for (const std::uint32_t i : present)
      if (prob[i] >= prob[top]) top = i;
    prob[top] += static_cast<std::uint32_t>(precision - total_prob);
  } else if (total_prob > precision) {
    // Draco's correction walks its stable ascending order down from the
    // most probable and stops at the first p ≤ 1. Those of probability 0,
    // then those of 1 (every other symbol that occurs), come first in that
    // order, so only the symbols of p ≥ 2 are sorted, by (p, index): the
    // stable order. `small` counts the ones of p = 1 before them and
    // `zeros` says whether any of p = 0 come before those.
    std::vector<std::uint64_t>& order = s.order;
    order.clear();
    for (const std::uint32_t i : present)
      if (prob[i] >= 2) order.push_back(std::uint64_t{prob[i]} << 32 | i);
    std::sort(order.begin(), order.end());
    const int occurring = static_cast<int>(present.size());
    const int small = occurring - static_cast<int>(order.size());
    const bool zeros = occurring < num_symbols;
    std::uint32_t one = 1;  // what the walk reads for a symbol of probability 1
    std::int32_t error = total_prob - precision;
    while (error > 0) {
      const std::int32_t error_before = error;
      const double scale = precision_d / static_cast<double>(total_prob);
      // Draco's loop runs down to its order's second entry; here that is
      // the first when symbols of probability 0 were left out before it.
      for (int j = occurring - 1; j >= (zeros ? 0 : 1); --j) {
        std::uint32_t& p =
            j < small ? one : prob[static_cast<std::size_t>(order[static_cast<std::size_t>(j - small)] & 0xffffffffu)];
        if (p <= 1) {
          if (j == occurring - 1) return false;
          break;
        }
        const auto reduced = static_cast<std::int32_t>(std::floor(scale * static_cast<double>(p)));
        auto fix = static_cast<std::int32_t>(p - static_cast<std::uint32_t>(reduced));
        if (fix == 0) fix = 1;
        if (fix >= static_cast<std::int32_t>(p)) fix = static_cast<std::int32_t>(p) - 1;
        if (fix > error) fix = error;
        p -= static_cast<std::uint32_t>(fix);
        total_prob -= fix;
        error -= fix;
        if (total_prob == precision) break;
      }
      if (error == error_before) return false;  // Draco would loop for ever here
    }
  }
  // Entries of symbols that never occur are never read by the coder: they
  // keep whatever an earlier chunk left there.
  std::uint32_t cum = 0;
  table.resize(prob.size());
  for (const std::uint32_t i : present) {
    RansSymbol& t = table[i];
    t.cum = cum;
    cum += prob[i];
    // RAnsEncoder::rans_write renormalises while state ≥ l_base / precision ·
    // IO_BASE · prob = 4 · 256 · prob.
    t.bound = 1024u * prob[i];
    t.spare = static_cast<std::uint32_t>(precision) - prob[i];
    t.reciprocal = reciprocal_of(prob[i]);
    if (prob[i] == 1) t.cum += t.spare;
  }
  return cum == static_cast<std::uint32_t>(precision);
}

// RAnsSymbolEncoder::EncodeTable: the symbol count, then each probability as
// a 1–3 byte varint whose low two bits count the extra bytes, runs of up to
// 64 zero probabilities as one byte ((run − 1) << 2 | 3).
void write_table(Writer& w, const std::vector<std::uint32_t>& prob, std::span<const std::uint32_t> present) {
  w.varint(present.back() + 1);
  std::uint32_t next = 0;  // the first symbol not yet written
  for (const std::uint32_t i : present) {
    for (std::uint32_t zeros = i - next; zeros > 0;) {
      const std::uint32_t run = std::min(zeros, 64u);
      w.u8(((run - 1) << 2) | 3u);
      zeros -= run;
    }
    next = i + 1;
    const std::uint32_t p = prob[i];
    const int extra = p >= (1u << 14) ? 2 : p >= (1u << 6) ? 1 : 0;
    w.u8((p << 2) | static_cast<std::uint32_t>(extra));
    for (int b = 0; b < extra; ++b) w.u8(p >> (8 * (b + 1) - 2));
  }
}

// One rANS coder (RAnsEncoder::rans_write) over symbols[count − 1 … 0]
// (rANS encodes in reverse), writing forward into its chunk's scratch.
struct RansStream {
  const std::uint32_t* next = nullptr;  // one past the next symbol to encode
  std::size_t left = 0;
  const RansSymbol* table = nullptr;
  std::uint8_t* out = nullptr;
  std::uint32_t state = 0;
};

// One symbol is a chain of dependent steps, each cut short:
// - ⌊x/p⌋ is the high half of x·m with m = ⌈2^64/p⌉ = (2^64 + r)/p, 0 ≤ r < p:
//   x·m/2^64 = x/p + x·r/(p·2^64), and x·r < 2^30 · 2^20 < 2^64 (x < 1024 · p
//   after renormalisation, p ≤ 2^20), so the floor is exact;
// - (x/p)·precision + x mod p + cum is x + ⌊x/p⌋·(precision − p) + cum.
// For p = 1, m = 2^64 − 1 gives ⌊x − x/2^64⌋ = x − 1 (x ≥ 1), one short,
// which the table's cum + spare makes up (no select in the chain).
inline std::uint32_t rans_put(std::uint32_t x, const RansSymbol& s) {
  const std::uint64_t r = x;
  const auto q = static_cast<std::uint64_t>((static_cast<unsigned __int128>(r) * s.reciprocal) >> 64);
  return static_cast<std::uint32_t>(r + q * s.spare + s.cum);
}

// Renormalisation as Draco's loop: emit the low byte while x ≥ bound.
// Alone, the fastest: a branch-free step lengthens the one chain more than
// the mispredictions cost (measured 35% slower).
inline void rans_step_loop(std::uint32_t& x, std::uint8_t*& out, const RansSymbol& s) {
  while (x >= s.bound) {
    *out++ = static_cast<std::uint8_t>(x);
    x >>= 8;
  }
  x = rans_put(x, s);
}

// The same, branch-free: the loop runs n = [x ≥ b] + [x/2^8 ≥ b] + [x/2^16
// ≥ b] times (x < 2^30 and b ≥ 2^10, so never a fourth), writing the low n
// bytes of x in order, which one little-endian 4-byte store does (the bytes
// beyond n are overwritten or past the end). With several coders in one loop
// the longer chain is hidden and no misprediction stalls all of them.
static_assert(std::endian::native == std::endian::little, "the branch-free renormalisation stores x little-endian");
inline void rans_step_flat(std::uint32_t& x, std::uint8_t*& out, const RansSymbol& s) {
  const std::uint32_t n = static_cast<std::uint32_t>(x >= s.bound) + static_cast<std::uint32_t>((x >> 8) >= s.bound) +
                          static_cast<std::uint32_t>((x >> 16) >= s.bound);
  std::memcpy(out, &x, sizeof x);
  out += n;
  x >>= 8 * n;
  x = rans_put(x, s);
}

// K coders, each with symbols left, in one loop until the first runs out.
template <int K>
void rans_run(RansStream* const* streams) {
  std::uint32_t x[K];
  const std::uint32_t* next[K];
  const RansSymbol* table[K];
  std::uint8_t* out[K];
  std::size_t steps = streams[0]->left;
  for (int k = 0; k < K; ++k) {
    const RansStream& r = *streams[k];
    x[k] = r.state, next[k] = r.next, table[k] = r.table, out[k] = r.out;
    steps = std::min(steps, r.left);
  }
  for (std::size_t j = 0; j < steps; ++j) {
    if constexpr (K == 1) {
      rans_step_loop(x[0], out[0], table[0][*--next[0]]);
    } else {
#pragma GCC unroll 4
      for (int k = 0; k < K; ++k) rans_step_flat(x[k], out[k], table[k][*--next[k]]);
    }
  }
  for (int k = 0; k < K; ++k) {
    RansStream& r = *streams[k];
    r.state = x[k], r.next = next[k], r.out = out[k], r.left -= steps;
  }
}

// Runs up to kDracoInterleave coders to their ends, as many at once as still
// have symbols.
void rans_run_all(std::span<RansStream*> streams) {
  static_assert(kDracoInterleave == 4, "rans_run_all runs up to four coders");
  while (true) {
    std::size_t n = 0;
    for (RansStream* r : streams)
      if (r->left > 0) streams[n++] = r;
    streams = streams.first(n);
    switch (n) {
      case 0: return;
      case 1: rans_run<1>(streams.data()); break;
      case 2: rans_run<2>(streams.data()); break;
      case 3: rans_run<3>(streams.data()); break;
      default: rans_run<4>(streams.data()); break;
    }
  }
}

// Where a coder starts: its symbols, its table, room for its bytes (a
// symbol writes ≤ 3 bytes, as the state before renormalisation is
// < 1024 · precision ≤ 2^30 and a bound is ≥ 1024; then the final state, and
// the branch-free step's 4-byte store).
RansStream rans_start(const std::uint32_t* symbols, std::size_t count, int precision_bits, const std::vector<RansSymbol>& table,
                      std::vector<std::uint8_t>& bytes) {
  bytes.resize(3 * count + 8);
  return {symbols + count, count, table.data(), bytes.data(), 4u << precision_bits};
}

// RAnsEncoder::write_end and RAnsSymbolEncoder::EndEncoding: the final
// state, then the byte count as a varint and the bytes.
void rans_finish(Writer& w, RansStream& r, int precision_bits, const std::vector<std::uint8_t>& bytes) {
  std::uint8_t* out = r.out;
  const std::uint32_t state = r.state - (4u << precision_bits);
  if (state < (1u << 6)) {
    *out++ = static_cast<std::uint8_t>(state);
  } else if (state < (1u << 14)) {
    const std::uint32_t v = (1u << 14) + state;
    for (int b = 0; b < 2; ++b) *out++ = static_cast<std::uint8_t>(v >> (8 * b));
  } else if (state < (1u << 22)) {
    const std::uint32_t v = (2u << 22) + state;
    for (int b = 0; b < 3; ++b) *out++ = static_cast<std::uint8_t>(v >> (8 * b));
  } else {
    const std::uint32_t v = (3u << 30) + state;  // state < 2^30 always
    for (int b = 0; b < 4; ++b) *out++ = static_cast<std::uint8_t>(v >> (8 * b));
  }
  const auto written = static_cast<std::size_t>(out - bytes.data());
  w.varint(written);
  w.bytes(bytes.data(), written);
}

// EncodeTaggedSymbols' values after its rANS-coded bit lengths: every value
// in its point's bit length, least significant bit first.
void write_tagged_values(Writer& w, const std::uint32_t* symbols, const std::uint32_t* lengths, std::size_t points,
                         std::vector<std::uint8_t>& bits) {
  bits.resize(3 * points * 4 + 8);  // every byte up to `out` is written below
  std::uint8_t* out = bits.data();
  std::uint64_t acc = 0;
  int filled = 0;
  for (std::size_t p = 0; p < points; ++p) {
    const auto n = static_cast<int>(lengths[p]);
    for (int c = 0; c < 3; ++c) {
      const std::uint64_t v = n == 32 ? symbols[3 * p + c] : symbols[3 * p + c] & ((std::uint64_t{1} << n) - 1);
      acc |= v << filled;
      filled += n;
      while (filled >= 8) {
        *out++ = static_cast<std::uint8_t>(acc);
        acc >>= 8;
        filled -= 8;
      }
    }
  }
  if (filled > 0) *out++ = static_cast<std::uint8_t>(acc);
  w.bytes(bits.data(), static_cast<std::size_t>(out - bits.data()));
}

// The raw scheme's precision (EncodeRawSymbols): the unique-symbol count's
// bit length, moved by the compression level. 0 where Draco's would fail
// (2^18 or more distinct symbols).
int raw_precision_bits(int unique, int compression_level, int& length) {
  length = most_significant_bit(static_cast<std::uint32_t>(unique)) + 1;
  if (length > kMaxRawBitLength) return 0;
  if (compression_level < 4) {
    length -= 2;
  } else if (compression_level < 6) {
    length -= 1;
  } else if (compression_level > 9) {
    length += 2;
  } else if (compression_level > 7) {
    length += 1;
  }
  length = std::clamp(length, 1, kMaxRawBitLength);
  return std::clamp(3 * length / 2, 12, 20);
}

// One chunk between its symbols' preparation and its entropy coding.
struct PendingChunk {
  ChunkScratch* s = nullptr;
  std::string* out = nullptr;
  bool tagged = false;
  std::size_t points = 0;
  int precision_bits = 0;
  RansStream rans;
  std::int32_t lo = 0, hi = 0;
  DeltaQuantization q;
};

// Everything before the rANS bytes: the quantized symbols, the choice of
// scheme, and `out` up to the frequency table. False for no values (`out`
// stays empty).
bool prepare_chunk(std::span<const float> values, const DeltaQuantization& q, int speed, PrepareScratch& prep,
                   ChunkScratch& s, std::string& out, PendingChunk& pending) {
  out.clear();
  if (values.empty()) return false;
  // Draco counts values in int.
  if (values.size() % 3 != 0 || values.size() > static_cast<std::size_t>(std::numeric_limits<std::int32_t>::max()))
    throw DeltaCodecError("cannot write " + std::to_string(values.size()) + " values as one Draco buffer of points");
  const std::size_t points = values.size() / 3, count = 3 * points;

  // SequentialQuantizationAttributeEncoder: AttributeQuantizationTransform's
  // floor((v − min) · inverse_delta + 0.5) in float; v ≥ min, so the floor
  // is the truncating conversion (and the loop vectorises).
  const float inverse_delta = q.inverse_step(), min = q.min;
  prep.quantized.resize(count);
  std::int32_t* qv = prep.quantized.data();
  const float* v = values.data();
  const auto quantize = [&](float x) { return static_cast<std::int32_t>((x - min) * inverse_delta + 0.5f); };
  // Four at a time (GCC keeps a float min/max reduction scalar, since it
  // cannot reorder it without -ffinite-math-only), with the extremes: each
  // rounded float operation is monotonic, so the quantized extremes are
  // those of the extreme values.
  using F4 [[gnu::vector_size(16)]] = float;
  using I4 [[gnu::vector_size(16)]] = std::int32_t;
  F4 lo4 = {v[0], v[0], v[0], v[0]}, hi4 = lo4;
  std::size_t i = 0;
  for (; i + 4 <= count; i += 4) {
    F4 x;
    std::memcpy(&x, v + i, sizeof x);
    lo4 = x < lo4 ? x : lo4;
    hi4 = x > hi4 ? x : hi4;
    const I4 qi = __builtin_convertvector((x - min) * inverse_delta + 0.5f, I4);
    std::memcpy(qv + i, &qi, sizeof qi);
  }
  float v_lo = std::min({lo4[0], lo4[1], lo4[2], lo4[3]}), v_hi = std::max({hi4[0], hi4[1], hi4[2], hi4[3]});
  for (; i < count; ++i) {
    qv[i] = quantize(v[i]);
    v_lo = std::min(v_lo, v[i]), v_hi = std::max(v_hi, v[i]);
  }
  const std::int32_t lo = quantize(v_lo), hi = quantize(v_hi);

  // PredictionSchemeDeltaEncoder with PredictionSchemeWrapEncodingTransform:
  // each value minus the one a point before (the first point minus the
  // zero vector clamped into [lo, hi], i.e. lo), wrapped into the
  // correction range; then ConvertSignedIntsToSymbols (zigzag).
  const std::int32_t max_dif = hi - lo + 1;
  std::int32_t max_correction = max_dif / 2;
  const std::int32_t min_correction = -max_correction;
  if ((max_dif & 1) == 0) max_correction -= 1;
  s.symbols.resize(count);
  std::uint32_t* sym = s.symbols.data();
  const auto symbol_of = [&](std::int32_t corr) {
    corr += corr < min_correction ? max_dif : 0;
    corr -= corr > max_correction ? max_dif : 0;
    return static_cast<std::uint32_t>(corr << 1) ^ static_cast<std::uint32_t>(corr >> 31);
  };
  for (std::size_t k = 0; k < 3; ++k) sym[k] = symbol_of(qv[k] - lo);
  for (std::size_t k = 3; k < count; ++k) sym[k] = symbol_of(qv[k] - qv[k - 3]);

  // EncodeSymbols: per point the bit length of its largest symbol; the
  // tagged scheme's size estimate from those, the raw scheme's from the
  // symbols' histogram; the smaller wins (raw only below 2^18).
  // Histograms are counted in kLanes copies, summed after: neighbouring
  // values are often equal, and one copy would make each increment wait for
  // the last.
  constexpr std::size_t kLanes = 4;
  s.bit_lengths.resize(points);
  std::uint32_t tag_lanes[kLanes][kMaxTag + 1] = {};
  std::uint32_t max_value = 0;
  for (std::size_t p = 0; p < points; ++p) {
    const std::uint32_t m = std::max({sym[3 * p], sym[3 * p + 1], sym[3 * p + 2]});
    const int length = most_significant_bit(m | 1u) + 1;
    s.bit_lengths[p] = static_cast<std::uint32_t>(length);
    ++tag_lanes[p % kLanes][length];
    max_value = std::max(max_value, m);
  }
  std::uint32_t tag_histogram[kMaxTag + 1] = {};
  std::uint64_t total_length = 0;
  for (int length = 0; length <= kMaxTag; ++length) {
    for (const auto& lane : tag_lanes) tag_histogram[length] += lane[length];
    total_length += std::uint64_t{tag_histogram[length]} * static_cast<std::uint64_t>(length);
  }
  std::uint32_t tag_present_symbols[kMaxTag + 1];
  std::span<const std::uint32_t> tag_present = occurring_symbols(tag_histogram, kMaxTag + 1, tag_present_symbols);
  const auto tag_unique = static_cast<int>(tag_present.size());
  const std::int64_t tagged_bits = entropy_bits(tag_histogram, tag_present, static_cast<int>(points)) +
                                   table_bits(tag_unique, tag_unique) + static_cast<std::int64_t>(total_length * 3);
  const bool raw_possible = most_significant_bit(std::max(1u, max_value)) + 1 <= kMaxRawBitLength;
  std::span<const std::uint32_t> present;
  bool raw = false;
  if (raw_possible) {
    // Lanes 1…3 cover the small symbols only, where nearly every value
    // falls: the largest symbol is often the first point's correction, far
    // above the rest, and lanes up to it would each have to be cleared and
    // summed.
    const std::size_t size = static_cast<std::size_t>(max_value) + 1;
    constexpr std::size_t kLaneSymbols = 1024;
    const std::size_t lane_size = std::min(size, kLaneSymbols);
    prep.histogram.assign(size + (kLanes - 1) * lane_size, 0);
    std::uint32_t* h = prep.histogram.data();  // lane 0, every symbol
    std::uint32_t* extra = h + size;          // lane l ≥ 1 at extra + (l − 1) · lane_size
    std::size_t k = 0;
    for (; k + kLanes <= count; k += kLanes) {
      ++h[sym[k]];
      for (std::size_t l = 1; l < kLanes; ++l) {
        const std::uint32_t symbol = sym[k + l];
        ++(symbol < lane_size ? extra[(l - 1) * lane_size + symbol] : h[symbol]);
      }
    }
    for (; k < count; ++k) ++h[sym[k]];
    for (std::size_t l = 1; l < kLanes; ++l)
      for (std::size_t j = 0; j < lane_size; ++j) h[j] += extra[(l - 1) * lane_size + j];
    if (prep.present.size() < size) prep.present.resize(size);
    present = occurring_symbols(h, size, prep.present.data());
    const std::int64_t raw_bits = entropy_bits(h, present, static_cast<int>(count)) +
                                  table_bits(static_cast<std::int32_t>(max_value), static_cast<int>(present.size()));
    raw = !(tagged_bits < raw_bits);
  }

  Writer w(out);
  out.reserve(64 + count);
  w.bytes(reinterpret_cast<const std::uint8_t*>("DRACO"), 5);
  w.u8(kVersionMajor), w.u8(kVersionMinor), w.u8(kPointCloud), w.u8(kSequentialEncoding);
  w.u8(0), w.u8(0);  // flags: no metadata
  w.u32(static_cast<std::uint32_t>(points));
  w.u8(1);  // attribute encoders
  w.varint(1);  // attributes
  w.u8(kGenericAttribute), w.u8(kFloat32), w.u8(3), w.u8(0);
  w.varint(0);  // unique id
  w.u8(kQuantizationEncoder);
  w.u8(kPredictionDifference), w.u8(kTransformWrap), w.u8(1);

  pending = {&s, &out, false, points, 0, {}, lo, hi, q};
  // With 2^18 distinct symbols Draco's raw coder gives up; the tagged one
  // still encodes them (only a chunk of over 87381 points can get there).
  int length = 0;
  const int raw_bits = raw ? raw_precision_bits(static_cast<int>(present.size()), 10 - speed, length) : 0;  // 10 − speed: Draco's compression level
  if (raw_bits != 0) {
    if (!rans_probabilities(prep.histogram.data(), present, raw_bits, prep, s.table))
      throw DeltaCodecError("Draco's symbol coder cannot encode these deltas");
    w.u8(kRaw);
    w.u8(static_cast<std::uint32_t>(length));
    write_table(w, prep.probabilities, present);
    pending.precision_bits = raw_bits;
    pending.rans = rans_start(sym, count, raw_bits, s.table, s.coded);
  } else {
    // EncodeTaggedSymbols' RAnsSymbolEncoder<5>:
    // ComputeRAnsPrecisionFromUniqueSymbolsBitLength(5).
    constexpr int kTagPrecision = 12;
    // Draco's tag coder has kMaxTag symbols (lengths 0…31; no symbol here
    // is 2^31 or more, so none is left out).
    if (!tag_present.empty() && tag_present.back() == kMaxTag) tag_present = tag_present.first(tag_present.size() - 1);
    if (tag_present.empty() || !rans_probabilities(tag_histogram, tag_present, kTagPrecision, prep, s.table))
      throw DeltaCodecError("Draco's tag coder cannot encode these deltas");
    w.u8(kTagged);
    write_table(w, prep.probabilities, tag_present);
    pending.tagged = true;
    pending.precision_bits = kTagPrecision;
    pending.rans = rans_start(s.bit_lengths.data(), points, kTagPrecision, s.table, s.coded);
  }
  return true;
}

// Everything after the rANS coder ran: its bytes, the tagged scheme's
// values, the wrap transform's range and the quantization.
void finish_chunk(PendingChunk& p) {
  Writer w(*p.out);
  ChunkScratch& s = *p.s;
  rans_finish(w, p.rans, p.precision_bits, s.coded);
  if (p.tagged) write_tagged_values(w, s.symbols.data(), s.bit_lengths.data(), p.points, s.coded);
  w.u32(static_cast<std::uint32_t>(p.lo));
  w.u32(static_cast<std::uint32_t>(p.hi));
  for (int c = 0; c < 3; ++c) w.f32(p.q.min);
  w.f32(p.q.range);
  w.u8(p.q.bits);
}

}  // namespace

void encode_draco_many(std::span<const DracoChunk> chunks, int speed) {
  if (!is_encoding_speed(speed)) throw DeltaCodecError("Draco encoding speed must be 0…10, got " + std::to_string(speed));
  thread_local PrepareScratch prep;
  thread_local std::array<ChunkScratch, kDracoInterleave> scratch;
  for (std::size_t first = 0; first < chunks.size(); first += kDracoInterleave) {
    const std::size_t n = std::min(kDracoInterleave, chunks.size() - first);
    std::array<PendingChunk, kDracoInterleave> pending;
    std::array<RansStream*, kDracoInterleave> streams;
    std::size_t active = 0;
    for (std::size_t k = 0; k < n; ++k) {
      const DracoChunk& c = chunks[first + k];
      if (prepare_chunk(c.values, c.quantization, speed, prep, scratch[active], *c.out, pending[active])) ++active;
    }
    for (std::size_t k = 0; k < active; ++k) streams[k] = &pending[k].rans;
    rans_run_all(std::span(streams.data(), active));
    for (std::size_t k = 0; k < active; ++k) finish_chunk(pending[k]);
  }
}

void encode_draco_into(std::span<const float> values, const DeltaQuantization& q, int speed, std::string& out) {
  const DracoChunk chunk{values, q, &out};
  encode_draco_many(std::span(&chunk, 1), speed);
}

std::string encode_draco(std::span<const float> values, const DeltaQuantization& q, int speed) {
  std::string out;
  encode_draco_into(values, q, speed, out);
  return out;
}

}  // namespace filigree
