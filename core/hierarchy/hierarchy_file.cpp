#include "hierarchy/hierarchy_file.h"

#include <fcntl.h>
#include <sys/mman.h>
#include <sys/stat.h>
#include <unistd.h>

#include <bit>
#include <cmath>
#include <cerrno>
#include <cstring>
#include <fstream>
#include <functional>
#include <memory>
#include <optional>
#include <vector>

#include "geometry/ring_frame.h"
#include "hierarchy/hierarchy.h"
#include "util/content_hash.h"

namespace filigree {
namespace {

static_assert(std::endian::native == std::endian::little, "the hierarchy file format is little-endian");

constexpr char kMagic[8] = {'F', 'L', 'G', 'H', 'I', 'E', 'R', '\0'};

struct Header {
  char magic[8];
  std::uint32_t version;
  std::uint32_t header_size;
  std::uint64_t mesh_hash;
  std::uint64_t payload_size;
  std::uint64_t payload_hash;
  std::uint32_t vertex_count, face_count, original_face_count, node_count;
  std::uint32_t section_count;
  std::uint32_t reserved;
};
static_assert(sizeof(Header) == 64);

struct BuildRecord {
  std::uint64_t requested_base_vertices;
  double build_seconds;
  std::uint32_t threads;
  std::uint32_t reserved;
};
static_assert(sizeof(BuildRecord) == 24);

// The sections in file order. `fn(tag, span&)` is called for each array of
// the stored hierarchy, const or not, so writer and reader cannot disagree.
template <class S, class Fn>
void for_each_section(S& s, Fn&& fn) {
  fn(1, s.rest_positions);
  fn(2, s.original_faces);
  fn(3, s.created_corners);
  fn(4, s.node_vertex);
  fn(5, s.node_closed);
  fn(6, s.ring_offsets);
  fn(7, s.ring_vertices);
  fn(8, s.ring_weights);
  fn(9, s.node_offset);
  fn(10, s.maps_face);
  fn(11, s.maps_bary);
}
constexpr std::uint32_t kBuildTag = 12;
constexpr std::uint32_t kSectionCount = 12;

// Version 2, still read (sessions persisted by an older server name their
// hierarchy by key, with no mesh to rebuild it from): sections 1–7 and 9 as
// in version 3, float32 weights (8) and barycentrics (14), and the faces
// each removal deleted and the child lists (10–12), which version 3 derives.
constexpr std::uint32_t kOldestReadableVersion = 2;
constexpr std::uint32_t kV2BuildTag = 15;
constexpr std::uint32_t kV2SectionCount = 15;

using Sink = std::function<void(const void*, std::size_t)>;

void write_section(const Sink& sink, std::uint32_t tag, std::uint32_t elem, std::uint64_t count, const void* data) {
  const std::uint32_t head[2] = {tag, elem};
  sink(head, sizeof head);
  sink(&count, sizeof count);
  sink(data, elem * count);
  static constexpr char zeros[8] = {};
  const std::size_t pad = (8 - (elem * count) % 8) % 8;
  sink(zeros, pad);
}

void write_payload(const Hierarchy& h, const StoredHierarchy& s, const Sink& sink) {
  for_each_section(s, [&](std::uint32_t tag, const auto& v) {
    using T = typename std::decay_t<decltype(v)>::value_type;
    write_section(sink, tag, sizeof(T), v.size(), v.data());
  });
  // Not the time or the threads: the same mesh and options give the same bytes (BuildInfo).
  const BuildRecord b{h.build.requested_base_vertices, 0.0, 0, 0};
  write_section(sink, kBuildTag, sizeof b, 1, &b);
}

Header make_header(const Hierarchy& h, const StoredHierarchy& s) {
  Header hd{};
  std::memcpy(hd.magic, kMagic, sizeof kMagic);
  hd.version = kHierarchyFormatVersion;
  hd.header_size = sizeof(Header);
  hd.mesh_hash = h.mesh_hash;
  ContentHasher hasher;
  std::uint64_t size = 0;
  write_payload(h, s, [&](const void* p, std::size_t n) {
    hasher.update(p, n);
    size += n;
  });
  hd.payload_size = size;
  hd.payload_hash = hasher.digest();
  hd.vertex_count = static_cast<std::uint32_t>(h.rest_positions.size());
  hd.face_count = static_cast<std::uint32_t>(h.face_count());
  hd.original_face_count = static_cast<std::uint32_t>(h.original_face_count());
  hd.node_count = static_cast<std::uint32_t>(h.node_vertex.size());
  hd.section_count = kSectionCount;
  return hd;
}

[[noreturn]] void fail(const std::string& name, const std::string& what) { throw HierarchyFileError(name + ": " + what); }

Header parse_header(std::span<const char> bytes, const std::string& name) {
  if (bytes.size() < sizeof(Header)) {
    if (bytes.size() >= 8 && std::memcmp(bytes.data(), kMagic, 8) != 0) fail(name, "not a Filigree hierarchy file (bad magic)");
    fail(name, "truncated: " + std::to_string(bytes.size()) + " bytes, shorter than the " + std::to_string(sizeof(Header)) + "-byte header");
  }
  Header hd;
  std::memcpy(&hd, bytes.data(), sizeof hd);
  if (std::memcmp(hd.magic, kMagic, sizeof kMagic) != 0) fail(name, "not a Filigree hierarchy file (bad magic)");
  if (hd.version < kOldestReadableVersion)
    fail(name, "unsupported format version " + std::to_string(hd.version) + ", older than this build's version " +
                   std::to_string(kHierarchyFormatVersion) +
                   ": rebuild it from its mesh with `filigree preprocess` (the server rebuilds its cached hierarchies automatically)");
  if (hd.version > kHierarchyFormatVersion)
    fail(name, "unsupported format version " + std::to_string(hd.version) + " (this build reads versions " +
                   std::to_string(kOldestReadableVersion) + "–" + std::to_string(kHierarchyFormatVersion) + ")");
  if (hd.header_size != sizeof(Header)) fail(name, "corrupt header (header size " + std::to_string(hd.header_size) + ")");
  return hd;
}

// Reads sections from the payload with every length checked.
class SectionReader {
 public:
  SectionReader(std::span<const char> payload, const std::string& name) : p_(payload), name_(name) {}

  // Points `out` at the section's elements, in place: the payload starts
  // 8-byte aligned and every section is padded to 8 bytes.
  template <class T>
  void read(std::uint32_t tag, std::span<const T>& out) {
    static_assert(alignof(T) <= 8);
    std::uint64_t count = 0;
    const char* data = next(tag, sizeof(T), count);
    out = {reinterpret_cast<const T*>(data), static_cast<std::size_t>(count)};
  }
  const char* next(std::uint32_t tag, std::uint32_t elem, std::uint64_t& count) {
    if (p_.size() - pos_ < 16) fail(name_, "corrupt: section " + std::to_string(tag) + " is missing");
    std::uint32_t head[2];
    std::memcpy(head, p_.data() + pos_, sizeof head);
    std::memcpy(&count, p_.data() + pos_ + 8, sizeof count);
    pos_ += 16;
    if (head[0] != tag) fail(name_, "corrupt: expected section " + std::to_string(tag) + ", found " + std::to_string(head[0]));
    if (head[1] != elem) fail(name_, "corrupt: section " + std::to_string(tag) + " has element size " + std::to_string(head[1]));
    const std::uint64_t left = p_.size() - pos_;
    if (count > left / elem) fail(name_, "corrupt: section " + std::to_string(tag) + " claims " + std::to_string(count) + " elements, more than the file holds");
    const char* data = p_.data() + pos_;
    const std::uint64_t bytes = count * elem;
    pos_ += bytes + (8 - bytes % 8) % 8;
    if (pos_ > p_.size()) fail(name_, "corrupt: section " + std::to_string(tag) + " padding runs past the end");
    return data;
  }
  bool at_end() const { return pos_ == p_.size(); }

 private:
  std::span<const char> p_;
  std::size_t pos_ = 0;
  const std::string& name_;
};

}  // namespace

std::string serialize_hierarchy(const Hierarchy& h) {
  const StoredHierarchy s = stored_view(h);
  const Header hd = make_header(h, s);
  std::string out;
  out.reserve(sizeof hd + hd.payload_size);
  out.append(reinterpret_cast<const char*>(&hd), sizeof hd);
  write_payload(h, s, [&](const void* p, std::size_t n) { out.append(static_cast<const char*>(p), n); });
  return out;
}

void save_hierarchy(const Hierarchy& h, const std::filesystem::path& path) {
  const StoredHierarchy s = stored_view(h);
  const Header hd = make_header(h, s);
  // Write to a temporary name, then rename: a crash never leaves half a file
  // under the real name, and a loader never maps a file being written.
  const std::filesystem::path tmp = path.string() + ".partial";
  {
    std::ofstream out(tmp, std::ios::binary | std::ios::trunc);
    if (!out) throw HierarchyFileError(path.string() + ": cannot open for writing");
    out.write(reinterpret_cast<const char*>(&hd), sizeof hd);
    write_payload(h, s, [&](const void* p, std::size_t n) { out.write(static_cast<const char*>(p), static_cast<std::streamsize>(n)); });
    if (!out.flush()) throw HierarchyFileError(path.string() + ": write failed");
  }
  std::filesystem::rename(tmp, path);
}

namespace {

// deserialize_hierarchy(), the arrays read in place from `bytes` if
// `storage` (which keeps them alive) is given and the format allows it.
Hierarchy deserialize(std::span<const char> bytes, const std::string& name, const std::shared_ptr<const void>& storage) {
  if (reinterpret_cast<std::uintptr_t>(bytes.data()) % 8 != 0) {
    // Sections are read in place, which needs the 8-byte alignment every
    // allocation and mapping has; a caller's odd slice gets an aligned copy.
    std::vector<std::uint64_t> aligned((bytes.size() + 7) / 8);
    std::memcpy(aligned.data(), bytes.data(), bytes.size());
    return deserialize({reinterpret_cast<const char*>(aligned.data()), bytes.size()}, name, {});
  }
  const Header hd = parse_header(bytes, name);
  const std::span<const char> payload = bytes.subspan(sizeof(Header));
  if (payload.size() < hd.payload_size)
    fail(name, "truncated: " + std::to_string(bytes.size()) + " bytes, header promises " + std::to_string(sizeof(Header) + hd.payload_size));
  if (payload.size() > hd.payload_size) fail(name, "corrupt: " + std::to_string(payload.size() - hd.payload_size) + " unexpected bytes after the payload");

  // The checksum is computed alongside the checks (they are safe on any
  // bytes: a forged file with a right checksum must be caught by them too),
  // and wins: a damaged file is reported as a checksum mismatch, whatever
  // the checks found first.
  std::optional<std::uint64_t> hash;
  const auto compute_hash = [&] { hash = hash_bytes(payload.data(), payload.size()); };
  const auto verify_hash = [&] {
    if (!hash) compute_hash();
    if (*hash != hd.payload_hash) fail(name, "corrupt: payload checksum mismatch");
  };
  Hierarchy h;
  try {
    const bool v2 = hd.version == 2;
    const std::uint32_t sections = v2 ? kV2SectionCount : kSectionCount;
    if (hd.section_count != sections) fail(name, "corrupt: " + std::to_string(hd.section_count) + " sections, expected " + std::to_string(sections));
    StoredHierarchy s;
    SectionReader reader(payload, name);
    // A version 2 file's float weights and barycentrics, in version 3's form.
    std::vector<std::uint16_t> weights;
    std::vector<Barycentric16> bary;
    if (v2) {
      std::span<const float> weights_f;
      std::span<const Vec3f> bary_f;
      std::span<const Index> unused;  // deleted faces, child offsets, children: derived since
      reader.read(1, s.rest_positions), reader.read(2, s.original_faces), reader.read(3, s.created_corners);
      reader.read(4, s.node_vertex), reader.read(5, s.node_closed), reader.read(6, s.ring_offsets);
      reader.read(7, s.ring_vertices), reader.read(8, weights_f), reader.read(9, s.node_offset);
      reader.read(10, unused), reader.read(11, unused), reader.read(12, unused);
      reader.read(13, s.maps_face), reader.read(14, bary_f);
      weights.resize(weights_f.size());
      for (std::size_t j = 0; j < weights.size(); ++j) {
        if (!(weights_f[j] > 0.0f) || !std::isfinite(weights_f[j])) fail(name, "corrupt: invalid hierarchy: a non-positive or non-finite ring weight");
        weights[j] = quantize_ring_weight(weights_f[j]);
      }
      bary.resize(bary_f.size());
      for (std::size_t v = 0; v < bary.size(); ++v) {
        const Vec3 b = bary_f[v].cast<double>();
        if (!b.allFinite()) fail(name, "corrupt: invalid hierarchy: vertex " + std::to_string(v) + " has invalid barycentric coordinates");
        bary[v] = quantize_barycentric(b);
      }
      s.ring_weights = weights, s.maps_bary = bary;
    } else {
      for_each_section(s, [&](std::uint32_t tag, auto& v) { reader.read(tag, v); });
    }
    std::span<const BuildRecord> build;
    reader.read(v2 ? kV2BuildTag : kBuildTag, build);
    if (build.size() != 1 || !reader.at_end()) fail(name, "corrupt: unexpected section layout");
    if (s.rest_positions.size() != hd.vertex_count || s.original_faces.size() != hd.original_face_count ||
        s.original_faces.size() + s.created_corners.size() != hd.face_count || s.node_vertex.size() != hd.node_count)
      fail(name, "corrupt: section sizes disagree with the header");
    // A version 2 file's converted arrays live here, not in `bytes`: copied.
    h = hierarchy_from(s, v2 ? nullptr : storage, compute_hash);
    h.build = {build[0].requested_base_vertices, build[0].build_seconds, build[0].threads};
    if (v2) {
      // Its offsets are in the frames of its float weights: redo them in the
      // frames of the 16-bit ones, as preprocessing now does, so that the
      // pair puts every vertex back where it was (validated indices by now).
      const std::span<Vec3f> offsets = h.node_offset.edit();
      for (NodeId k = 0; k < h.node_count(); ++k)
        offsets[k] = ring_frame(h.ring(k), h.weights(k), h.rest_positions, h.node_closed[k] != 0)
                               .to_local(h.rest_positions[h.node_vertex[k]])
                               .cast<float>();
    }
  } catch (const HierarchyError& e) {
    verify_hash();
    fail(name, std::string("corrupt: ") + e.what());
  } catch (const HierarchyFileError&) {
    verify_hash();
    throw;
  }
  verify_hash();
  h.mesh_hash = hd.mesh_hash;
  return h;
}

// A file mapped read-only; a loaded hierarchy's arrays are views of it, so
// it lives as long as they do. Its pages are mapped in one go
// (MAP_POPULATE) rather than faulted in one by one: the checksum reads
// every byte anyway (1.25M vertices: loads 3–15% faster here, where a page
// fault is costly).
class MappedFile {
 public:
  explicit MappedFile(const std::filesystem::path& path) {
    const int fd = ::open(path.c_str(), O_RDONLY | O_CLOEXEC);
    if (fd < 0) throw HierarchyFileError(path.string() + ": cannot open (" + std::strerror(errno) + ")");
    struct stat st {};
    if (::fstat(fd, &st) != 0 || !S_ISREG(st.st_mode)) {
      ::close(fd);
      throw HierarchyFileError(path.string() + ": not a regular file");
    }
    size_ = static_cast<std::size_t>(st.st_size);
    if (size_ > 0) {
      void* p = ::mmap(nullptr, size_, PROT_READ, MAP_PRIVATE | MAP_POPULATE, fd, 0);
      const int err = errno;
      ::close(fd);
      if (p == MAP_FAILED) throw HierarchyFileError(path.string() + ": cannot map (" + std::strerror(err) + ")");
      data_ = static_cast<const char*>(p);
    } else {
      ::close(fd);
    }
  }
  ~MappedFile() {
    if (data_) ::munmap(const_cast<char*>(data_), size_);
  }
  MappedFile(const MappedFile&) = delete;
  MappedFile& operator=(const MappedFile&) = delete;
  std::span<const char> bytes() const { return {data_, size_}; }

 private:
  const char* data_ = nullptr;
  std::size_t size_ = 0;
};

}  // namespace

Hierarchy deserialize_hierarchy(std::span<const char> bytes, const std::string& name) { return deserialize(bytes, name, {}); }

Hierarchy load_hierarchy(const std::filesystem::path& path) {
  const auto file = std::make_shared<const MappedFile>(path);
  return deserialize(file->bytes(), path.string(), file);
}

HierarchyFileInfo read_hierarchy_file_info(const std::filesystem::path& path) {
  std::ifstream in(path, std::ios::binary);
  if (!in) throw HierarchyFileError(path.string() + ": cannot open");
  std::vector<char> head(sizeof(Header));
  in.read(head.data(), static_cast<std::streamsize>(head.size()));
  head.resize(static_cast<std::size_t>(in.gcount()));
  const Header hd = parse_header(head, path.string());
  return {hd.version, hd.mesh_hash, std::filesystem::file_size(path), hd.vertex_count, hd.face_count, hd.original_face_count, hd.node_count};
}

}  // namespace filigree
