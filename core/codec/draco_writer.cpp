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
#include <bit>
#include <cmath>
#include <cstring>
#include <limits>
#include <numeric>
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
  std::uint64_t reciprocal = 0;  // ⌈2^64 / prob⌉ for prob ≥ 2; 0 for prob 1
  std::uint64_t identity = 0;    // all ones for prob 1 (x / 1 = x), else 0
  std::uint32_t bound = 0;       // renormalise while state ≥ this
  std::uint32_t cum = 0;
  std::uint32_t spare = 0;       // precision − prob
};

struct Scratch {
  std::vector<std::int32_t> quantized;
  std::vector<std::uint32_t> symbols;
  std::vector<std::uint8_t> bit_lengths;  // per point
  std::vector<std::uint32_t> histogram;
  std::vector<std::uint32_t> probabilities;
  std::vector<int> order;
  std::vector<RansSymbol> table;
  std::vector<std::uint8_t> coded;  // rANS bytes, then the tagged scheme's value bits
};

// Draco's ComputeShannonEntropy over a histogram: the same sum in the same
// (ascending) order, so the same double and the same truncation.
std::int64_t entropy_bits(const std::uint32_t* histogram, std::size_t size, int total, int& unique) {
  unique = 0;
  double bits = 0.0;
  const double n = total;
  for (std::size_t i = 0; i < size; ++i) {
    if (histogram[i] == 0) continue;
    ++unique;
    bits += static_cast<int>(histogram[i]) * std::log2(static_cast<double>(histogram[i]) / n);
  }
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
bool rans_probabilities(const std::uint32_t* frequencies, int num_symbols, int precision_bits, Scratch& s) {
  std::uint64_t total = 0;
  int max_valid = 0;
  for (int i = 0; i < num_symbols; ++i) {
    total += frequencies[i];
    if (frequencies[i] > 0) max_valid = i;
  }
  num_symbols = max_valid + 1;
  std::vector<std::uint32_t>& prob = s.probabilities;
  prob.resize(static_cast<std::size_t>(num_symbols));
  const int precision = 1 << precision_bits;
  const double total_d = static_cast<double>(total), precision_d = precision;
  int total_prob = 0;
  for (int i = 0; i < num_symbols; ++i) {
    const double p = static_cast<double>(frequencies[i]) / total_d;
    auto r = static_cast<std::uint32_t>(p * precision_d + 0.5f);
    if (r == 0 && frequencies[i] > 0) r = 1;
    prob[static_cast<std::size_t>(i)] = r;
    total_prob += static_cast<int>(r);
  }
  if (total_prob != precision) {
    std::vector<int>& order = s.order;
    order.resize(static_cast<std::size_t>(num_symbols));
    std::iota(order.begin(), order.end(), 0);
    std::stable_sort(order.begin(), order.end(), [&](int a, int b) { return prob[a] < prob[b]; });
    if (total_prob < precision) {
      prob[static_cast<std::size_t>(order.back())] += static_cast<std::uint32_t>(precision - total_prob);
    } else {
      std::int32_t error = total_prob - precision;
      while (error > 0) {
        const std::int32_t error_before = error;
        const double scale = precision_d / static_cast<double>(total_prob);
        for (int j = num_symbols - 1; j > 0; --j) {
          std::uint32_t& p = prob[static_cast<std::size_t>(order[static_cast<std::size_t>(j)])];
          if (p <= 1) {
            if (j == num_symbols - 1) return false;
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
  }
  std::uint32_t cum = 0;
  s.table.resize(prob.size());
  for (std::size_t i = 0; i < prob.size(); ++i) {
    RansSymbol& t = s.table[i];
    t.cum = cum;
    cum += prob[i];
    // RAnsEncoder::rans_write renormalises while state ≥ l_base / precision ·
    // IO_BASE · prob = 4 · 256 · prob.
    t.bound = 1024u * prob[i];
    t.spare = static_cast<std::uint32_t>(precision) - prob[i];
    t.reciprocal = prob[i] >= 2 ? ~std::uint64_t{0} / prob[i] + 1 : 0;  // ⌊(2^64 − 1)/p⌋ + 1 = ⌈2^64/p⌉
    t.identity = prob[i] == 1 ? ~std::uint64_t{0} : 0;
  }
  return cum == static_cast<std::uint32_t>(precision);
}

// RAnsSymbolEncoder::EncodeTable: the symbol count, then each probability as
// a 1–3 byte varint whose low two bits count the extra bytes, runs of zero
// probabilities as one byte (offset << 2 | 3).
void write_table(Writer& w, const std::vector<std::uint32_t>& prob) {
  w.varint(prob.size());
  for (std::size_t i = 0; i < prob.size(); ++i) {
    const std::uint32_t p = prob[i];
    if (p == 0) {
      std::uint32_t offset = 0;
      for (; offset < (1u << 6) - 1; ++offset) {
        if (prob[i + offset + 1] > 0) break;  // the last symbol is never 0
      }
      w.u8((offset << 2) | 3u);
      i += offset;
      continue;
    }
    const int extra = p >= (1u << 14) ? 2 : p >= (1u << 6) ? 1 : 0;
    w.u8((p << 2) | static_cast<std::uint32_t>(extra));
    for (int b = 0; b < extra; ++b) w.u8(p >> (8 * (b + 1) - 2));
  }
}

// RAnsEncoder::rans_write over symbols[count − 1 … 0] (rANS encodes in
// reverse), then write_end and RAnsSymbolEncoder::EndEncoding: the byte
// count as a varint, then the bytes. One symbol is a chain of dependent
// steps, so each is cut short (a branch-free renormalisation, three
// comparisons and one 4-byte store, measured 35% slower: it lengthens the
// chain more than the mispredictions it saves):
// - ⌊x/p⌋ is the high half of x·m with m = ⌈2^64/p⌉ = (2^64 + r)/p, 0 ≤ r < p:
//   x·m/2^64 = x/p + x·r/(p·2^64), and x·r < 2^30 · 2^20 < 2^64 (x < 1024 · p
//   after renormalisation, p ≤ 2^20), so the floor is exact (p = 1: x itself);
// - (x/p)·precision + x mod p + cum is x + ⌊x/p⌋·(precision − p) + cum.
template <typename SymbolAt>
void rans_encode(Writer& w, std::size_t count, int precision_bits, const std::vector<RansSymbol>& table,
                 SymbolAt symbol_at, std::vector<std::uint8_t>& bytes) {
  const std::uint32_t l_base = 4u << precision_bits;
  // The state before renormalisation is < 1024 · precision ≤ 2^30 and a bound
  // is ≥ 1024: ≤ 3 bytes per symbol, then the state.
  bytes.resize(3 * count + 8);
  std::uint8_t* out = bytes.data();
  std::uint32_t state = l_base;
  const RansSymbol* t = table.data();
  for (std::size_t i = count; i-- > 0;) {
    const RansSymbol& s = t[symbol_at(i)];
    while (state >= s.bound) {
      *out++ = static_cast<std::uint8_t>(state);
      state >>= 8;
    }
    const std::uint64_t r = state;
    const auto q = static_cast<std::uint64_t>((static_cast<unsigned __int128>(r) * s.reciprocal) >> 64) + (r & s.identity);
    state = static_cast<std::uint32_t>(r + q * s.spare + s.cum);
  }
  state -= l_base;
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

// EncodeTaggedSymbols: each point's bit length rANS-coded (precision 12),
// then every value in that many bits, least significant bit first.
void write_tagged(Writer& w, const std::uint32_t* symbols, std::size_t points, const std::uint32_t* tag_histogram,
                  Scratch& s) {
  // EncodeTaggedSymbols' RAnsSymbolEncoder<5>:
  // ComputeRAnsPrecisionFromUniqueSymbolsBitLength(5).
  constexpr int kPrecision = 12;
  if (!rans_probabilities(tag_histogram, kMaxTag, kPrecision, s))
    throw DeltaCodecError("Draco's tag coder cannot encode these deltas");
  write_table(w, s.probabilities);
  const std::uint8_t* lengths = s.bit_lengths.data();
  rans_encode(w, points, kPrecision, s.table, [lengths](std::size_t i) { return lengths[i]; }, s.coded);

  std::vector<std::uint8_t>& bits = s.coded;
  bits.resize(3 * points * 4 + 8);  // every byte up to `out` is written below
  std::uint8_t* out = bits.data();
  std::uint64_t acc = 0;
  int filled = 0;
  for (std::size_t p = 0; p < points; ++p) {
    const int n = lengths[p];
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

// EncodeRawSymbols: the unique-symbol count's bit length, moved by the
// compression level, picks the rANS precision; symbols coded directly.
// Returns false where Draco's would fail (2^18 or more distinct symbols).
bool write_raw(Writer& w, const std::uint32_t* symbols, std::size_t count, std::uint32_t max_value, int unique,
               int compression_level, Scratch& s) {
  int length = most_significant_bit(static_cast<std::uint32_t>(unique)) + 1;
  if (length > kMaxRawBitLength) return false;
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
  const int precision = std::clamp(3 * length / 2, 12, 20);
  if (!rans_probabilities(s.histogram.data(), static_cast<int>(max_value) + 1, precision, s))
    throw DeltaCodecError("Draco's symbol coder cannot encode these deltas");
  w.u8(kRaw);
  w.u8(static_cast<std::uint32_t>(length));
  write_table(w, s.probabilities);
  rans_encode(w, count, precision, s.table, [symbols](std::size_t i) { return symbols[i]; }, s.coded);
  return true;
}

}  // namespace

void encode_draco_into(std::span<const float> values, const DeltaQuantization& q, int speed, std::string& out) {
  out.clear();
  if (!is_encoding_speed(speed)) throw DeltaCodecError("Draco encoding speed must be 0…10, got " + std::to_string(speed));
  if (values.empty()) return;
  // Draco counts values in int.
  if (values.size() % 3 != 0 || values.size() > static_cast<std::size_t>(std::numeric_limits<std::int32_t>::max()))
    throw DeltaCodecError("cannot write " + std::to_string(values.size()) + " values as one Draco buffer of points");
  const std::size_t points = values.size() / 3, count = 3 * points;
  thread_local Scratch s;

  // SequentialQuantizationAttributeEncoder: AttributeQuantizationTransform's
  // floor((v − min) · inverse_delta + 0.5) in float; v ≥ min, so the floor
  // is the truncating conversion (and the loop vectorises).
  const float inverse_delta = q.inverse_step(), min = q.min;
  s.quantized.resize(count);
  std::int32_t* qv = s.quantized.data();
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
    s.bit_lengths[p] = static_cast<std::uint8_t>(length);
    ++tag_lanes[p % kLanes][length];
    max_value = std::max(max_value, m);
  }
  std::uint32_t tag_histogram[kMaxTag + 1] = {};
  std::uint64_t total_length = 0;
  for (int length = 0; length <= kMaxTag; ++length) {
    for (const auto& lane : tag_lanes) tag_histogram[length] += lane[length];
    total_length += std::uint64_t{tag_histogram[length]} * static_cast<std::uint64_t>(length);
  }
  int tag_unique = 0;
  const std::int64_t tagged_bits = entropy_bits(tag_histogram, kMaxTag + 1, static_cast<int>(points), tag_unique) +
                                   table_bits(tag_unique, tag_unique) + static_cast<std::int64_t>(total_length * 3);
  const bool raw_possible = most_significant_bit(std::max(1u, max_value)) + 1 <= kMaxRawBitLength;
  int unique = 0;
  bool raw = false;
  if (raw_possible) {
    // Lanes 1…3 cover the small symbols only, where nearly every value
    // falls: the largest symbol is often the first point's correction, far
    // above the rest, and lanes up to it would each have to be cleared and
    // summed.
    const std::size_t size = static_cast<std::size_t>(max_value) + 1;
    constexpr std::size_t kLaneSymbols = 1024;
    const std::size_t lane_size = std::min(size, kLaneSymbols);
    s.histogram.assign(size + (kLanes - 1) * lane_size, 0);
    std::uint32_t* h = s.histogram.data();  // lane 0, every symbol
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
    const std::int64_t raw_bits = entropy_bits(h, size, static_cast<int>(count), unique) +
                                  table_bits(static_cast<std::int32_t>(max_value), unique);
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

  const int level = 10 - speed;  // Draco's symbol coding compression level
  const std::size_t symbols_at = out.size();
  // With 2^18 distinct symbols Draco's raw coder gives up; the tagged one
  // still encodes them (only a chunk of over 87381 points can get there).
  if (!raw || !write_raw(w, sym, count, max_value, unique, level, s)) {
    out.resize(symbols_at);
    w.u8(kTagged);
    write_tagged(w, sym, points, tag_histogram, s);
  }
  w.u32(static_cast<std::uint32_t>(lo));
  w.u32(static_cast<std::uint32_t>(hi));
  for (int c = 0; c < 3; ++c) w.f32(q.min);
  w.f32(q.range);
  w.u8(q.bits);
}

std::string encode_draco(std::span<const float> values, const DeltaQuantization& q, int speed) {
  std::string out;
  encode_draco_into(values, q, speed, out);
  return out;
}

}  // namespace filigree
