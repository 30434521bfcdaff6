// OBJ, OFF and PLY reading and writing; glTF/GLB is delegated to gltf_io.cpp.
//
// The text and PLY parsers are our own rather than OpenMesh's readers, because
// OpenMesh 9 (a) passes every position through float, so doubles do not round
// trip; (b) silently drops OBJ faces with a repeated index; (c) reports success
// for garbage OBJ input and for truncated OFF files, the latter with
// uninitialised face indices. Here every malformed file is a MeshIoError and
// every face reaches validate_mesh() as stored.

#include "mesh/mesh_io.h"

#include <algorithm>
#include <bit>
#include <cctype>
#include <cerrno>
#include <charconv>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstring>
#include <fstream>
#include <iterator>
#include <limits>
#include <new>
#include <optional>
#include <string_view>

#include "mesh/gltf_io.h"

namespace filigree {
namespace {

constexpr std::int64_t kMaxIndex = std::numeric_limits<Index>::max();

[[noreturn]] void fail(const std::string& name, const std::string& reason) {
  throw MeshIoError(name + ": " + reason);
}

[[noreturn]] void fail_unsupported(const std::string& name, const std::string& format, const char* supported) {
  fail(name, (format.empty() ? std::string("no file extension") : "unsupported format '." + format + "'") +
                 " (supported: " + supported + ")");
}

constexpr const char* kReadable = ".obj, .ply, .off, .gltf, .glb";
constexpr const char* kWritable = ".obj, .ply, .glb";

// Quotes a token from the file for an error message, defusing binary garbage.
std::string quoted(std::string_view token) {
  constexpr std::size_t kMaxShown = 32;
  std::string out = "'";
  for (const char c : token.substr(0, kMaxShown)) {
    const auto byte = static_cast<unsigned char>(c);
    if (byte >= 0x20 && byte < 0x7f) {
      out += c;
    } else {
      char hex[8];
      std::snprintf(hex, sizeof hex, "\\x%02x", byte);
      out += hex;
    }
  }
  if (token.size() > kMaxShown) out += "...";
  return out + "'";
}

std::string normalized_format(std::string format) {
  if (!format.empty() && format.front() == '.') format.erase(0, 1);
  std::transform(format.begin(), format.end(), format.begin(),
                 [](unsigned char c) { return static_cast<char>(std::tolower(c)); });
  return format;
}

// from_chars rejects a leading '+', which OBJ/OFF/PLY writers do emit.
std::string_view without_plus(std::string_view s) {
  if (s.size() > 1 && s.front() == '+' && s[1] != '-') s.remove_prefix(1);
  return s;
}

bool parse_double(std::string_view s, double& out) {
  s = without_plus(s);
  const auto [end, error] = std::from_chars(s.data(), s.data() + s.size(), out);
  return error == std::errc() && end == s.data() + s.size();
}

bool parse_int(std::string_view s, std::int64_t& out) {
  s = without_plus(s);
  const auto [end, error] = std::from_chars(s.data(), s.data() + s.size(), out);
  return error == std::errc() && end == s.data() + s.size();
}

// Some Windows tools start text files with a UTF-8 byte order mark.
std::string_view without_bom(std::string_view text) {
  if (text.starts_with("\xEF\xBB\xBF")) text.remove_prefix(3);
  return text;
}

bool is_space(char c) { return c == ' ' || c == '\t' || c == '\r' || c == '\v' || c == '\f'; }

// Splits text into lines and lines into whitespace-separated tokens; `comment`
// (if not '\0') starts a comment running to the end of the line.
class LineReader {
 public:
  LineReader(std::string_view text, char comment) : text_(text), comment_(comment) {}

  bool next(std::vector<std::string_view>& tokens) {
    tokens.clear();
    if (pos_ >= text_.size()) return false;
    const std::size_t newline = text_.find('\n', pos_);
    const std::size_t end = newline == std::string_view::npos ? text_.size() : newline;
    std::string_view line = text_.substr(pos_, end - pos_);
    pos_ = end == text_.size() ? end : end + 1;
    ++line_;
    if (comment_ != '\0') line = line.substr(0, line.find(comment_));
    std::size_t i = 0;
    while (i < line.size()) {
      while (i < line.size() && is_space(line[i])) ++i;
      const std::size_t start = i;
      while (i < line.size() && !is_space(line[i])) ++i;
      if (i > start) tokens.push_back(line.substr(start, i - start));
    }
    return true;
  }

  // Skips lines without tokens.
  bool next_nonempty(std::vector<std::string_view>& tokens) {
    while (next(tokens)) {
      if (!tokens.empty()) return true;
    }
    return false;
  }

  std::string where() const { return "line " + std::to_string(line_) + ": "; }
  std::size_t offset() const { return pos_; }
  std::size_t remaining() const { return text_.size() - pos_; }

 private:
  std::string_view text_;
  char comment_;
  std::size_t pos_ = 0;
  std::size_t line_ = 0;
};

// Reserving the count a header claims would let a garbage header allocate
// gigabytes; no element can take less than `min_bytes` of the input.
std::size_t plausible_count(std::uint64_t claimed, std::size_t remaining_bytes, std::size_t min_bytes) {
  return static_cast<std::size_t>(std::min<std::uint64_t>(claimed, remaining_bytes / min_bytes + 1));
}

// Polygons are fan-triangulated around their first corner.
void add_polygon(TriMesh& mesh, const std::vector<Index>& corners) {
  for (std::size_t i = 1; i + 1 < corners.size(); ++i) {
    mesh.faces.push_back({corners[0], corners[i], corners[i + 1]});
  }
}

// ---------------------------------------------------------------------------
// OBJ

TriMesh parse_obj(std::string_view text, const std::string& name) {
  // Statements that carry nothing we keep. Anything else is an error, which is
  // how a binary or unrelated file gets rejected instead of read as empty.
  static constexpr std::string_view kIgnored[] = {
      "vt", "vn", "vp", "o", "g", "s", "mg", "usemtl", "mtllib", "l", "p", "cstype", "deg", "bmat",
      "step", "curv", "curv2", "surf", "parm", "trim", "hole", "scrv", "sp", "end", "con", "call",
      "csh", "shadow_obj", "trace_obj", "ctech", "stech", "bevel", "c_interp", "d_interp", "lod",
      "maplib", "usemap"};

  TriMesh mesh;
  LineReader lines(without_bom(text), '#');
  std::vector<std::string_view> tokens;
  std::vector<Index> corners;
  while (lines.next(tokens)) {
    if (tokens.empty()) continue;
    const std::string_view keyword = tokens[0];
    if (keyword == "v") {
      if (tokens.size() < 4) fail(name, lines.where() + "vertex needs 3 coordinates");
      Vec3 p;
      for (int k = 0; k < 3; ++k) {
        if (!parse_double(tokens[k + 1], p[k])) {
          fail(name, lines.where() + "invalid coordinate " + quoted(tokens[k + 1]));
        }
      }
      mesh.positions.push_back(p);
    } else if (keyword == "f") {
      if (tokens.size() < 4) fail(name, lines.where() + "face needs at least 3 vertices");
      corners.clear();
      for (std::size_t i = 1; i < tokens.size(); ++i) {
        // "v", "v/vt", "v//vn" or "v/vt/vn": only the position index matters.
        const std::string_view ref = tokens[i].substr(0, tokens[i].find('/'));
        std::int64_t value = 0;
        if (!parse_int(ref, value)) fail(name, lines.where() + "invalid vertex reference " + quoted(tokens[i]));
        if (value == 0) fail(name, lines.where() + "vertex reference 0 is invalid (OBJ counts from 1)");
        // Negative references count back from the latest vertex.
        const std::int64_t index =
            value > 0 ? value - 1 : static_cast<std::int64_t>(mesh.positions.size()) + value;
        if (index < 0) {
          fail(name, lines.where() + "relative vertex reference " + std::to_string(value) +
                         " points before the first vertex");
        }
        if (index > kMaxIndex) fail(name, lines.where() + "vertex reference " + std::to_string(value) + " is too large");
        corners.push_back(static_cast<Index>(index));
      }
      add_polygon(mesh, corners);
    } else if (std::find(std::begin(kIgnored), std::end(kIgnored), keyword) == std::end(kIgnored)) {
      fail(name, lines.where() + "unknown OBJ statement " + quoted(keyword));
    }
  }
  return mesh;
}

// ---------------------------------------------------------------------------
// OFF (Geomview): "[ST][C][N][4]OFF", counts, one vertex per line (trailing
// normal/colour/texture values ignored), faces as "n i0 ... i(n-1) [colour]".

TriMesh parse_off(std::string_view text, const std::string& name) {
  LineReader lines(without_bom(text), '#');
  std::vector<std::string_view> tokens;
  if (!lines.next_nonempty(tokens)) fail(name, "empty file");

  const std::string_view header = tokens[0];
  if (!header.ends_with("OFF")) fail(name, "missing OFF header (file starts with " + quoted(header) + ")");
  std::string_view prefix = header.substr(0, header.size() - 3);
  for (const std::string_view flag : {"ST", "C", "N"}) {
    if (prefix.starts_with(flag)) prefix.remove_prefix(flag.size());
  }
  const bool homogeneous = prefix.starts_with("4");
  if (homogeneous) prefix.remove_prefix(1);
  if (prefix == "n") fail(name, "nOFF (arbitrary dimension) is not supported");
  if (!prefix.empty()) fail(name, "unknown OFF header " + quoted(header));

  // Counts may follow the keyword on the same line.
  tokens.erase(tokens.begin());
  if (!tokens.empty() && tokens[0] == "BINARY") fail(name, "binary OFF is not supported");
  if (tokens.empty() && !lines.next_nonempty(tokens)) fail(name, "missing vertex and face counts");
  std::int64_t vertex_count = 0, face_count = 0;
  if (tokens.size() < 2 || !parse_int(tokens[0], vertex_count) || !parse_int(tokens[1], face_count) ||
      vertex_count < 0 || face_count < 0) {
    fail(name, lines.where() + "invalid vertex and face counts");
  }
  if (vertex_count > kMaxIndex) fail(name, "too many vertices (" + std::to_string(vertex_count) + ")");

  TriMesh mesh;
  mesh.positions.reserve(plausible_count(vertex_count, lines.remaining(), 6));
  mesh.faces.reserve(plausible_count(face_count, lines.remaining(), 8));
  const int dimensions = homogeneous ? 4 : 3;
  for (std::int64_t v = 0; v < vertex_count; ++v) {
    if (!lines.next_nonempty(tokens)) {
      fail(name, "file ends after " + std::to_string(v) + " of " + std::to_string(vertex_count) + " vertices");
    }
    if (tokens.size() < static_cast<std::size_t>(dimensions)) {
      fail(name, lines.where() + "vertex needs " + std::to_string(dimensions) + " coordinates");
    }
    double coords[4] = {0.0, 0.0, 0.0, 1.0};
    for (int k = 0; k < dimensions; ++k) {
      if (!parse_double(tokens[k], coords[k])) fail(name, lines.where() + "invalid coordinate " + quoted(tokens[k]));
    }
    mesh.positions.emplace_back(coords[0] / coords[3], coords[1] / coords[3], coords[2] / coords[3]);
  }

  std::vector<Index> corners;
  for (std::int64_t f = 0; f < face_count; ++f) {
    if (!lines.next_nonempty(tokens)) {
      fail(name, "file ends after " + std::to_string(f) + " of " + std::to_string(face_count) + " faces");
    }
    std::int64_t size = 0;
    if (!parse_int(tokens[0], size) || size < 3) {
      fail(name, lines.where() + "invalid face size " + quoted(tokens[0]) + " (need at least 3)");
    }
    if (tokens.size() - 1 < static_cast<std::uint64_t>(size)) {
      fail(name, lines.where() + "face lists fewer than " + std::to_string(size) + " vertex indices");
    }
    corners.clear();
    for (std::int64_t i = 1; i <= size; ++i) {
      std::int64_t index = 0;
      if (!parse_int(tokens[i], index) || index < 0 || index > kMaxIndex) {
        fail(name, lines.where() + "invalid vertex index " + quoted(tokens[i]));
      }
      corners.push_back(static_cast<Index>(index));
    }
    add_polygon(mesh, corners);
  }
  return mesh;
}

// ---------------------------------------------------------------------------
// PLY: ascii, binary_little_endian and binary_big_endian; any scalar types.
// Elements other than "vertex" and "face" are read and discarded.

enum class PlyType { Int8, UInt8, Int16, UInt16, Int32, UInt32, Float32, Float64 };

std::optional<PlyType> ply_type(std::string_view s) {
  if (s == "char" || s == "int8") return PlyType::Int8;
  if (s == "uchar" || s == "uint8") return PlyType::UInt8;
  if (s == "short" || s == "int16") return PlyType::Int16;
  if (s == "ushort" || s == "uint16") return PlyType::UInt16;
  if (s == "int" || s == "int32") return PlyType::Int32;
  if (s == "uint" || s == "uint32") return PlyType::UInt32;
  if (s == "float" || s == "float32") return PlyType::Float32;
  if (s == "double" || s == "float64") return PlyType::Float64;
  return std::nullopt;
}

std::size_t ply_size(PlyType type) {
  switch (type) {
    case PlyType::Int8:
    case PlyType::UInt8: return 1;
    case PlyType::Int16:
    case PlyType::UInt16: return 2;
    case PlyType::Int32:
    case PlyType::UInt32:
    case PlyType::Float32: return 4;
    case PlyType::Float64: return 8;
  }
  return 0;
}

struct PlyProperty {
  std::string name;
  PlyType type = PlyType::Float32;
  bool is_list = false;
  PlyType count_type = PlyType::UInt8;
};

struct PlyElement {
  std::string name;
  std::uint64_t count = 0;
  std::vector<PlyProperty> properties;
};

enum class PlyFormat { Ascii, BinaryLittleEndian, BinaryBigEndian };

// Yields the values of the PLY body one at a time, as doubles (exact for
// every PLY type), checking for the end of the data.
class PlyValues {
 public:
  PlyValues(std::string_view body, PlyFormat format, const std::string& name)
      : body_(body), format_(format), name_(name) {}

  double next(PlyType type, const std::string& context) {
    return format_ == PlyFormat::Ascii ? next_ascii(context) : next_binary(type, context);
  }

  std::size_t remaining() const { return body_.size() - pos_; }

 private:
  double next_ascii(const std::string& context) {
    while (pos_ < body_.size() && (is_space(body_[pos_]) || body_[pos_] == '\n')) ++pos_;
    const std::size_t start = pos_;
    while (pos_ < body_.size() && !is_space(body_[pos_]) && body_[pos_] != '\n') ++pos_;
    if (pos_ == start) fail(name_, "data ends inside " + context);
    const std::string_view token = body_.substr(start, pos_ - start);
    double value = 0.0;
    if (!parse_double(token, value)) fail(name_, "invalid number " + quoted(token) + " in " + context);
    return value;
  }

  double next_binary(PlyType type, const std::string& context) {
    const std::size_t size = ply_size(type);
    if (remaining() < size) fail(name_, "data ends inside " + context);
    unsigned char bytes[8];
    std::memcpy(bytes, body_.data() + pos_, size);
    pos_ += size;
    const bool file_big = format_ == PlyFormat::BinaryBigEndian;
    if (file_big != (std::endian::native == std::endian::big)) std::reverse(bytes, bytes + size);
    switch (type) {
      case PlyType::Int8: return load<std::int8_t>(bytes);
      case PlyType::UInt8: return load<std::uint8_t>(bytes);
      case PlyType::Int16: return load<std::int16_t>(bytes);
      case PlyType::UInt16: return load<std::uint16_t>(bytes);
      case PlyType::Int32: return load<std::int32_t>(bytes);
      case PlyType::UInt32: return load<std::uint32_t>(bytes);
      case PlyType::Float32: return load<float>(bytes);
      case PlyType::Float64: return load<double>(bytes);
    }
    return 0.0;
  }

  template <class T>
  static double load(const unsigned char* bytes) {
    T value;
    std::memcpy(&value, bytes, sizeof value);
    return static_cast<double>(value);
  }

  std::string_view body_;
  PlyFormat format_;
  const std::string& name_;
  std::size_t pos_ = 0;
};

TriMesh parse_ply(std::string_view text, const std::string& name) {
  LineReader lines(text, '\0');
  std::vector<std::string_view> tokens;
  if (!lines.next(tokens) || tokens.size() != 1 || tokens[0] != "ply") fail(name, "missing 'ply' header");

  std::optional<PlyFormat> format;
  std::vector<PlyElement> elements;
  bool header_ended = false;
  while (!header_ended && lines.next(tokens)) {
    if (tokens.empty() || tokens[0] == "comment" || tokens[0] == "obj_info") continue;
    if (tokens[0] == "format" && tokens.size() == 3) {
      if (tokens[1] == "ascii") format = PlyFormat::Ascii;
      else if (tokens[1] == "binary_little_endian") format = PlyFormat::BinaryLittleEndian;
      else if (tokens[1] == "binary_big_endian") format = PlyFormat::BinaryBigEndian;
      else fail(name, lines.where() + "unknown PLY format " + quoted(tokens[1]));
    } else if (tokens[0] == "element" && tokens.size() == 3) {
      std::int64_t count = 0;
      if (!parse_int(tokens[2], count) || count < 0) fail(name, lines.where() + "invalid element count " + quoted(tokens[2]));
      elements.push_back({std::string(tokens[1]), static_cast<std::uint64_t>(count), {}});
    } else if (tokens[0] == "property" && !elements.empty() && (tokens.size() == 3 || tokens.size() == 5)) {
      PlyProperty property;
      const bool is_list = tokens.size() == 5;
      if (is_list && tokens[1] != "list") fail(name, lines.where() + "malformed property line");
      const std::optional<PlyType> type = ply_type(tokens[is_list ? 3 : 1]);
      const std::optional<PlyType> count_type = is_list ? ply_type(tokens[2]) : PlyType::UInt8;
      if (!type || !count_type) fail(name, lines.where() + "unknown property type");
      elements.back().properties.push_back({std::string(tokens.back()), *type, is_list, *count_type});
    } else if (tokens[0] == "end_header" && tokens.size() == 1) {
      header_ended = true;
    } else {
      fail(name, lines.where() + "malformed PLY header line starting with " + quoted(tokens[0]));
    }
  }
  if (!header_ended) fail(name, "PLY header has no end_header");
  if (!format) fail(name, "PLY header has no format line");

  TriMesh mesh;
  PlyValues values(text.substr(lines.offset()), *format, name);
  // The smallest an entry of either element can be in this format.
  const std::size_t min_entry_bytes = *format == PlyFormat::Ascii ? 2 : 1;
  std::vector<Index> corners;
  for (const PlyElement& element : elements) {
    const bool is_vertex = element.name == "vertex";
    const bool is_face = element.name == "face";
    int xyz[3] = {-1, -1, -1};
    int face_indices = -1;
    for (std::size_t p = 0; p < element.properties.size(); ++p) {
      const PlyProperty& property = element.properties[p];
      if (is_vertex && !property.is_list) {
        if (property.name == "x") xyz[0] = static_cast<int>(p);
        if (property.name == "y") xyz[1] = static_cast<int>(p);
        if (property.name == "z") xyz[2] = static_cast<int>(p);
      }
      if (is_face && property.is_list && (property.name == "vertex_indices" || property.name == "vertex_index")) {
        face_indices = static_cast<int>(p);
      }
    }
    if (is_vertex && (xyz[0] < 0 || xyz[1] < 0 || xyz[2] < 0)) fail(name, "vertex element lacks x, y or z");
    if (is_face && face_indices < 0) fail(name, "face element lacks a vertex_indices list");
    if (is_vertex) {
      if (element.count > static_cast<std::uint64_t>(kMaxIndex)) fail(name, "too many vertices");
      mesh.positions.reserve(plausible_count(element.count, values.remaining(), 3 * min_entry_bytes));
    }
    if (is_face) mesh.faces.reserve(plausible_count(element.count, values.remaining(), 4 * min_entry_bytes));

    // An element without properties has nothing in the body, whatever its
    // count (found by fuzzing: a count of 10^11 spun here for minutes).
    if (element.properties.empty()) continue;
    const std::string context = "element '" + element.name + "'";
    for (std::uint64_t entry = 0; entry < element.count; ++entry) {
      Vec3 p = Vec3::Zero();
      for (std::size_t k = 0; k < element.properties.size(); ++k) {
        const PlyProperty& property = element.properties[k];
        if (!property.is_list) {
          const double value = values.next(property.type, context);
          for (int c = 0; c < 3; ++c) {
            if (xyz[c] == static_cast<int>(k)) p[c] = value;
          }
          continue;
        }
        const double size = values.next(property.count_type, context);
        // Each list item takes at least one byte: a larger count is garbage.
        if (!(size >= 0.0) || size != std::floor(size) || size > static_cast<double>(values.remaining())) {
          fail(name, "invalid list length in " + context + " #" + std::to_string(entry));
        }
        const bool keep = static_cast<int>(k) == face_indices;
        if (keep && size < 3) {
          fail(name, "face " + std::to_string(entry) + " has fewer than 3 vertices");
        }
        corners.clear();
        for (std::size_t i = 0; i < static_cast<std::size_t>(size); ++i) {
          const double value = values.next(property.type, context);
          if (!keep) continue;
          if (!(value >= 0.0) || value != std::floor(value) || value > static_cast<double>(kMaxIndex)) {
            fail(name, "invalid vertex index " + std::to_string(value) + " in face " + std::to_string(entry));
          }
          corners.push_back(static_cast<Index>(value));
        }
        if (keep) add_polygon(mesh, corners);
      }
      if (is_vertex) mesh.positions.push_back(p);
    }
  }
  return mesh;
}

// ---------------------------------------------------------------------------
// Writing

// Buffers output and reports any I/O failure as a MeshIoError.
class FileWriter {
 public:
  explicit FileWriter(const std::filesystem::path& path) : name_(path.string()), out_(path, std::ios::binary) {
    if (!out_) fail(name_, std::string("cannot open for writing: ") + std::strerror(errno));
  }

  void put(std::string_view bytes) {
    buffer_.append(bytes);
    if (buffer_.size() >= (1u << 20)) flush();
  }

  void put_number(double value) {
    char digits[32];
    // Shortest representation that parses back to the same double.
    const auto result = std::to_chars(digits, digits + sizeof digits, value);
    buffer_.append(digits, result.ptr);
  }

  void put_number(std::uint64_t value) {
    char digits[24];
    const auto result = std::to_chars(digits, digits + sizeof digits, value);
    buffer_.append(digits, result.ptr);
  }

  // PLY binary output is little-endian whatever the host.
  template <class T>
  void put_little_endian(T value) {
    unsigned char bytes[sizeof(T)];
    std::memcpy(bytes, &value, sizeof(T));
    if constexpr (std::endian::native == std::endian::big) std::reverse(bytes, bytes + sizeof(T));
    buffer_.append(reinterpret_cast<const char*>(bytes), sizeof(T));
    if (buffer_.size() >= (1u << 20)) flush();
  }

  void finish() {
    flush();
    out_.close();
    if (!out_) fail(name_, "write failed");
  }

 private:
  void flush() {
    out_.write(buffer_.data(), static_cast<std::streamsize>(buffer_.size()));
    if (!out_) fail(name_, std::string("write failed: ") + std::strerror(errno));
    buffer_.clear();
  }

  std::string name_;
  std::ofstream out_;
  std::string buffer_;
};

void write_obj(const TriMesh& mesh, const std::filesystem::path& path) {
  FileWriter out(path);
  for (const Vec3& p : mesh.positions) {
    out.put("v ");
    out.put_number(p.x());
    out.put(" ");
    out.put_number(p.y());
    out.put(" ");
    out.put_number(p.z());
    out.put("\n");
  }
  for (const Triangle& f : mesh.faces) {
    out.put("f");
    for (const Index i : f) {
      out.put(" ");
      out.put_number(std::uint64_t{i} + 1);
    }
    out.put("\n");
  }
  out.finish();
}

void write_ply(const TriMesh& mesh, const std::filesystem::path& path) {
  FileWriter out(path);
  out.put("ply\nformat binary_little_endian 1.0\ncomment written by filigree\nelement vertex ");
  out.put_number(std::uint64_t{mesh.vertex_count()});
  out.put("\nproperty double x\nproperty double y\nproperty double z\nelement face ");
  out.put_number(std::uint64_t{mesh.face_count()});
  out.put("\nproperty list uchar uint vertex_indices\nend_header\n");
  for (const Vec3& p : mesh.positions) {
    for (int k = 0; k < 3; ++k) out.put_little_endian(p[k]);
  }
  for (const Triangle& f : mesh.faces) {
    out.put_little_endian(std::uint8_t{3});
    for (const Index i : f) out.put_little_endian(i);
  }
  out.finish();
}

RiggedMesh parse(const std::string& bytes, const std::string& format, const std::string& name,
                 const std::filesystem::path& base_dir) {
  try {
    if (format == "obj") return {parse_obj(bytes, name), std::nullopt};
    if (format == "off") return {parse_off(bytes, name), std::nullopt};
    if (format == "ply") return {parse_ply(bytes, name), std::nullopt};
    // Accept a binary container under either extension: the magic decides.
    if (format == "gltf" || format == "glb") return read_gltf_rigged(bytes, bytes.starts_with("glTF"), name, base_dir);
  } catch (const std::bad_alloc&) {
    fail(name, "out of memory while reading");
  }
  fail_unsupported(name, format, kReadable);
}

bool is_readable(const std::string& format) {
  return format == "obj" || format == "off" || format == "ply" || format == "gltf" || format == "glb";
}

}  // namespace

TriMesh read_mesh(const std::filesystem::path& path) { return read_rigged_mesh(path).mesh; }

TriMesh read_mesh_from_memory(const std::string& bytes, const std::string& format) {
  return read_rigged_mesh_from_memory(bytes, format).mesh;
}

RiggedMesh read_rigged_mesh(const std::filesystem::path& path) {
  const std::string name = path.string();
  const std::string format = normalized_format(path.extension().string());
  if (!is_readable(format)) fail_unsupported(name, format, kReadable);
  std::ifstream in(path, std::ios::binary);
  if (!in) fail(name, std::string("cannot open: ") + std::strerror(errno));
  // A directory opens fine on Linux and then reads as empty.
  if (std::filesystem::is_directory(path)) fail(name, "is a directory");
  std::string bytes((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  if (in.bad()) fail(name, "read failed");
  return parse(bytes, format, name, path.parent_path().empty() ? std::filesystem::path(".") : path.parent_path());
}

RiggedMesh read_rigged_mesh_from_memory(const std::string& bytes, const std::string& format) {
  const std::string normalized = normalized_format(format);
  return parse(bytes, normalized, "<memory>." + normalized, {});
}

void write_mesh(const TriMesh& mesh, const std::filesystem::path& path) {
  const std::string format = normalized_format(path.extension().string());
  if (format == "obj") return write_obj(mesh, path);
  if (format == "ply") return write_ply(mesh, path);
  if (format == "glb") return write_glb(mesh, path);
  fail_unsupported(path.string(), format, kWritable);
}

}  // namespace filigree
