#include "skinning/rig_file.h"

#include <algorithm>
#include <bit>
#include <cerrno>
#include <cstring>
#include <fstream>
#include <iterator>
#include <limits>
#include <system_error>
#include <type_traits>
#include <vector>

namespace filigree {
namespace {

static_assert(std::endian::native == std::endian::little, "the rig file format is little-endian");

constexpr char kMagic[8] = {'F', 'L', 'G', 'R', 'I', 'G', '\0', '\0'};

// The fewest bytes one element of each counted array takes in a valid file:
// a count times this must fit in the bytes left, or the count is a lie (and
// must not be allocated for).
constexpr std::size_t kMinJointBytes = 4 + 4 + 8 * (3 + 4 + 3 + 16);
constexpr std::size_t kMinBindingBytes = 4 + 8 * 16;
constexpr std::size_t kMinVertexBytes = 4 + 8 * 3;  // an offset and a bind position
constexpr std::size_t kMinInfluenceBytes = 4 + 4;
constexpr std::size_t kMinClipBytes = 4 + 4;
constexpr std::size_t kMinChannelBytes = 4 + 1 + 1 + 4 + 4;

class Writer {
 public:
  template <class T>
  void put(T v) {
    static_assert(std::is_arithmetic_v<T>);
    out_.append(reinterpret_cast<const char*>(&v), sizeof v);
  }
  template <class T>
  void put_array(const std::vector<T>& v) {
    static_assert(std::is_arithmetic_v<T>);
    out_.append(reinterpret_cast<const char*>(v.data()), v.size() * sizeof(T));
  }
  // A count as u32; larger arrays cannot be stored (nor would a session hold them).
  void put_count(std::size_t n, const char* what) {
    if (n > std::numeric_limits<std::uint32_t>::max()) throw RigError(std::string("serialize_rig: too many ") + what + " (" + std::to_string(n) + ")");
    put(static_cast<std::uint32_t>(n));
  }
  void put_string(const std::string& s, const char* what) {
    put_count(s.size(), what);
    out_.append(s);
  }
  void put_vec3(const Vec3& v) {
    for (int i = 0; i < 3; ++i) put(v[i]);
  }
  void put_mat4(const Mat4& m) {
    for (int c = 0; c < 4; ++c)
      for (int r = 0; r < 4; ++r) put(m(r, c));
  }
  std::string take() { return std::move(out_); }

 private:
  std::string out_;
};

// Reads the format with every length checked against the bytes left.
class Reader {
 public:
  Reader(std::string_view bytes, const std::string& name) : b_(bytes), name_(name) {}

  [[noreturn]] void fail(const std::string& what) const { throw RigError(name_ + ": " + what); }
  std::size_t left() const { return b_.size() - pos_; }
  std::size_t position() const { return pos_; }

  void need(std::size_t n, const std::string& what) const {
    if (n > left())
      fail("truncated: " + what + " needs " + std::to_string(n) + " bytes at offset " + std::to_string(pos_) + ", only " + std::to_string(left()) + " left");
  }
  template <class T>
  T get(const std::string& what) {
    static_assert(std::is_arithmetic_v<T>);
    need(sizeof(T), what);
    T v;
    std::memcpy(&v, b_.data() + pos_, sizeof v);
    pos_ += sizeof v;
    return v;
  }
  // A u32 count of elements that take at least `min_bytes` each.
  std::uint32_t count(const std::string& what, std::size_t min_bytes) {
    const std::uint32_t n = get<std::uint32_t>(what + " count");
    if (static_cast<std::uint64_t>(n) * min_bytes > left())
      fail("count too large: " + std::to_string(n) + " " + what + " take at least " + std::to_string(static_cast<std::uint64_t>(n) * min_bytes) +
           " bytes, only " + std::to_string(left()) + " left at offset " + std::to_string(pos_) + " (truncated or corrupt)");
    return n;
  }
  template <class T>
  void get_array(std::vector<T>& v, std::uint64_t n, const std::string& what) {
    static_assert(std::is_arithmetic_v<T>);
    // Divided, not multiplied: n may come from a forged count.
    if (n > left() / sizeof(T))
      fail("truncated: " + what + " needs " + std::to_string(n) + " x " + std::to_string(sizeof(T)) + " bytes at offset " + std::to_string(pos_) +
           ", only " + std::to_string(left()) + " left");
    v.resize(static_cast<std::size_t>(n));
    // memcpy from or to an empty vector's null data() is undefined even for 0 bytes (found by fuzz_rig_file).
    if (n > 0) std::memcpy(v.data(), b_.data() + pos_, static_cast<std::size_t>(n) * sizeof(T));
    pos_ += static_cast<std::size_t>(n) * sizeof(T);
  }
  std::string get_string(const std::string& what) {
    const std::uint32_t n = count(what + " bytes", 1);
    std::string s(b_.substr(pos_, n));
    pos_ += n;
    return s;
  }
  Vec3 get_vec3(const std::string& what) {
    Vec3 v;
    for (int i = 0; i < 3; ++i) v[i] = get<double>(what);
    return v;
  }
  Mat4 get_mat4(const std::string& what) {
    Mat4 m;
    for (int c = 0; c < 4; ++c)
      for (int r = 0; r < 4; ++r) m(r, c) = get<double>(what);
    return m;
  }

 private:
  std::string_view b_;
  std::size_t pos_ = 0;
  const std::string& name_;
};

void read_header(Reader& in, std::string_view bytes) {
  // Only the bytes present are compared: a short file that does not even
  // start like a rig is reported as not a rig, not as a truncated one.
  const std::size_t head = std::min(bytes.size(), sizeof kMagic);
  if (head > 0 && std::memcmp(bytes.data(), kMagic, head) != 0) in.fail("not a Filigree rig file (bad magic)");
  in.get<std::uint64_t>("the magic");
  const std::uint32_t version = in.get<std::uint32_t>("the format version");
  if (version != kRigFormatVersion)
    in.fail("unknown format version " + std::to_string(version) + " (this build reads version " + std::to_string(kRigFormatVersion) + ")");
}

Joint read_joint(Reader& in, std::size_t j) {
  const std::string where = "joint " + std::to_string(j);
  Joint joint;
  joint.name = in.get_string(where + " name");
  joint.parent = in.get<std::int32_t>(where + " parent");
  joint.rest.translation = in.get_vec3(where + " translation");
  double q[4];
  for (double& c : q) c = in.get<double>(where + " rotation");
  joint.rest.rotation = Eigen::Quaterniond(q[3], q[0], q[1], q[2]);  // stored x y z w
  joint.rest.scale = in.get_vec3(where + " scale");
  joint.root_parent = in.get_mat4(where + " root parent");
  return joint;
}

ClipChannel read_channel(Reader& in, const std::string& where) {
  ClipChannel ch;
  ch.joint = in.get<std::uint32_t>(where + " joint");
  const std::uint8_t path = in.get<std::uint8_t>(where + " path");
  if (path > static_cast<std::uint8_t>(ClipChannel::Path::kScale)) in.fail("corrupt: " + where + " has unknown path " + std::to_string(path));
  ch.path = static_cast<ClipChannel::Path>(path);
  const std::uint8_t interpolation = in.get<std::uint8_t>(where + " interpolation");
  if (interpolation > static_cast<std::uint8_t>(ClipChannel::Interpolation::kCubicSpline))
    in.fail("corrupt: " + where + " has unknown interpolation " + std::to_string(interpolation));
  ch.interpolation = static_cast<ClipChannel::Interpolation>(interpolation);
  const std::uint32_t keys = in.count(where + " keys", 4);
  in.get_array(ch.times, keys, where + " times");
  const std::uint32_t values = in.count(where + " values", 4);
  in.get_array(ch.values, values, where + " values");
  return ch;
}

}  // namespace

std::string serialize_rig(const Rig& rig) {
  try {
    validate_rig(rig);
  } catch (const RigError& e) {
    throw RigError(std::string("serialize_rig: invalid rig: ") + e.what());
  }
  Writer out;
  for (char c : kMagic) out.put(c);
  out.put(kRigFormatVersion);

  out.put_count(rig.joints.size(), "joints");
  for (const Joint& joint : rig.joints) {
    out.put_string(joint.name, "bytes in a joint name");
    out.put(joint.parent);
    out.put_vec3(joint.rest.translation);
    const Eigen::Quaterniond& q = joint.rest.rotation;
    for (double c : {q.x(), q.y(), q.z(), q.w()}) out.put(c);
    out.put_vec3(joint.rest.scale);
    out.put_mat4(joint.root_parent);
  }

  out.put_count(rig.bindings.size(), "bindings");
  for (const Binding& binding : rig.bindings) {
    out.put(binding.joint);
    out.put_mat4(binding.inverse_bind);
  }

  out.put_count(rig.weights.vertex_count(), "vertices");
  out.put_array(rig.weights.offsets);
  out.put_count(rig.weights.binding.size(), "influences");
  out.put_array(rig.weights.binding);
  out.put_array(rig.weights.weight);
  for (const Vec3& p : rig.bind_positions) out.put_vec3(p);

  out.put_count(rig.clips.size(), "clips");
  for (const AnimationClip& clip : rig.clips) {
    out.put_string(clip.name, "bytes in a clip name");
    out.put_count(clip.channels.size(), "channels in a clip");
    for (const ClipChannel& ch : clip.channels) {
      out.put(ch.joint);
      out.put(static_cast<std::uint8_t>(ch.path));
      out.put(static_cast<std::uint8_t>(ch.interpolation));
      out.put_count(ch.times.size(), "keys in a channel");
      out.put_array(ch.times);
      out.put_count(ch.values.size(), "values in a channel");
      out.put_array(ch.values);
    }
  }
  return out.take();
}

Rig deserialize_rig(std::string_view bytes, const std::string& name) {
  Reader in(bytes, name);
  read_header(in, bytes);
  Rig rig;

  const std::uint32_t joints = in.count("joints", kMinJointBytes);
  rig.joints.reserve(joints);
  for (std::uint32_t j = 0; j < joints; ++j) rig.joints.push_back(read_joint(in, j));

  const std::uint32_t bindings = in.count("bindings", kMinBindingBytes);
  rig.bindings.reserve(bindings);
  for (std::uint32_t b = 0; b < bindings; ++b) {
    const std::string where = "binding " + std::to_string(b);
    Binding binding;
    binding.joint = in.get<std::uint32_t>(where + " joint");
    binding.inverse_bind = in.get_mat4(where + " inverse bind matrix");
    rig.bindings.push_back(binding);
  }

  const std::uint32_t vertices = in.count("vertices", kMinVertexBytes);
  in.get_array(rig.weights.offsets, std::uint64_t{vertices} + 1, "weight offsets");
  const std::uint32_t influences = in.count("influences", kMinInfluenceBytes);
  in.get_array(rig.weights.binding, influences, "influence bindings");
  in.get_array(rig.weights.weight, influences, "influence weights");
  std::vector<double> positions;
  in.get_array(positions, std::uint64_t{vertices} * 3, "bind positions");
  rig.bind_positions.resize(vertices);
  for (std::size_t v = 0; v < vertices; ++v) rig.bind_positions[v] = Vec3(positions[3 * v], positions[3 * v + 1], positions[3 * v + 2]);

  const std::uint32_t clips = in.count("clips", kMinClipBytes);
  rig.clips.resize(clips);
  for (std::uint32_t c = 0; c < clips; ++c) {
    AnimationClip& clip = rig.clips[c];
    const std::string where = "clip " + std::to_string(c);
    clip.name = in.get_string(where + " name");
    const std::uint32_t channels = in.count(where + " channels", kMinChannelBytes);
    clip.channels.reserve(channels);
    for (std::uint32_t k = 0; k < channels; ++k) clip.channels.push_back(read_channel(in, where + " channel " + std::to_string(k)));
  }

  if (in.left() != 0) in.fail("corrupt: " + std::to_string(in.left()) + " unexpected bytes after the rig (at offset " + std::to_string(in.position()) + ")");
  try {
    validate_rig(rig);
  } catch (const RigError& e) {
    in.fail(std::string("invalid rig: ") + e.what());
  }
  return rig;
}

void save_rig(const Rig& rig, const std::filesystem::path& path) {
  std::string bytes;
  try {
    bytes = serialize_rig(rig);
  } catch (const RigError& e) {
    throw RigError(path.string() + ": " + e.what());
  }
  // Write to a temporary name, then rename: a crash never leaves half a file
  // under the real name.
  const std::filesystem::path tmp = path.string() + ".partial";
  {
    std::ofstream out(tmp, std::ios::binary | std::ios::trunc);
    if (!out) throw RigError(path.string() + ": cannot open " + tmp.string() + " for writing (" + std::strerror(errno) + ")");
    out.write(bytes.data(), static_cast<std::streamsize>(bytes.size()));
    if (!out.flush()) {
      out.close();
      std::error_code ignored;
      std::filesystem::remove(tmp, ignored);
      throw RigError(path.string() + ": write failed");
    }
  }
  std::error_code ec;
  std::filesystem::rename(tmp, path, ec);
  if (ec) {
    std::error_code ignored;
    std::filesystem::remove(tmp, ignored);
    throw RigError(path.string() + ": cannot rename " + tmp.string() + " into place (" + ec.message() + ")");
  }
}

Rig load_rig(const std::filesystem::path& path) {
  std::error_code ec;
  if (!std::filesystem::is_regular_file(path, ec)) throw RigError(path.string() + ": cannot open (no such regular file)");
  std::ifstream in(path, std::ios::binary);
  if (!in) throw RigError(path.string() + ": cannot open (" + std::strerror(errno) + ")");
  const std::string bytes((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  if (in.bad()) throw RigError(path.string() + ": read failed");
  return deserialize_rig(bytes, path.string());
}

}  // namespace filigree
