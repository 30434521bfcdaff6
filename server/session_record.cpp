#include "server/session_record.h"

#include <cstring>
#include <limits>
#include <stdexcept>

#include "filigree/internal/session_record.pb.h"
#include "util/content_hash.h"

namespace filigree::server {
namespace {

// Stored records and progress: "FGSR", the XXH3 hash of the rest (8 bytes,
// little-endian), then the protobuf. A flipped byte is found on load, not
// read as another pose or token. Bytes without the magic are records from
// before it (a protobuf starts with a field tag, never 'F'), read unchecked.
constexpr char kMagic[4] = {'F', 'G', 'S', 'R'};
constexpr std::size_t kHeader = sizeof kMagic + sizeof(std::uint64_t);

// Versions only grow, one a frame: no session reaches 2^62 (a century at a
// billion frames a second). A larger stored one is forged or corrupt, and
// would wrap to 0 and reuse versions clients have seen.
std::uint64_t checked_version(std::uint64_t version) {
  if (version > kMaxSessionVersion) throw std::runtime_error("version " + std::to_string(version) + " is past the largest a session reaches");
  return version;
}

std::string sealed(const std::string& body) {
  const std::uint64_t hash = hash_bytes(body.data(), body.size());
  std::string out(kMagic, sizeof kMagic);
  out.append(reinterpret_cast<const char*>(&hash), sizeof hash);
  return out + body;
}

// The protobuf of stored bytes; throws std::runtime_error if a sealed one
// does not match its hash.
std::string_view unsealed(const std::string& bytes) {
  if (bytes.size() < sizeof kMagic || std::memcmp(bytes.data(), kMagic, sizeof kMagic) != 0) return bytes;
  if (bytes.size() < kHeader) throw std::runtime_error("truncated (" + std::to_string(bytes.size()) + " bytes)");
  std::uint64_t stored = 0;
  std::memcpy(&stored, bytes.data() + sizeof kMagic, sizeof stored);
  const std::string_view body = std::string_view(bytes).substr(kHeader);
  if (body.size() > static_cast<std::size_t>(std::numeric_limits<int>::max())) throw std::runtime_error("over 2 GiB");
  if (hash_bytes(body.data(), body.size()) != stored) throw std::runtime_error("corrupt (its checksum does not match)");
  return body;
}

void put_handles(const std::vector<SessionHandle>& handles, bool pending, internal::SessionRecord& p) {
  for (const SessionHandle& h : handles) {
    internal::SessionHandle& out = *p.add_handles();
    out.set_vertex(h.vertex);
    out.set_client(h.client);
    out.set_x(h.target[0]);
    out.set_y(h.target[1]);
    out.set_z(h.target[2]);
  }
  p.set_handles_pending(pending);
}

std::vector<SessionHandle> handles_of(const internal::SessionRecord& p) {
  std::vector<SessionHandle> out;
  out.reserve(static_cast<std::size_t>(p.handles_size()));
  for (const internal::SessionHandle& h : p.handles()) out.push_back({h.vertex(), h.client(), {h.x(), h.y(), h.z()}});
  return out;
}

void put_cut(const CutSnapshot& cut, internal::SessionRecord& p) {
  if (cut.empty()) return;  // absent: no adaptive cut to restore
  internal::CutSnapshot& out = *p.mutable_cut();
  out.mutable_unrecovered()->Add(cut.unrecovered.begin(), cut.unrecovered.end());
  out.mutable_scores()->Add(cut.scores.begin(), cut.scores.end());
  out.set_next_block(cut.next_block);
}

CutSnapshot cut_of(const internal::SessionRecord& p) {
  CutSnapshot out;
  if (!p.has_cut()) return out;
  out.unrecovered.assign(p.cut().unrecovered().begin(), p.cut().unrecovered().end());
  out.scores.assign(p.cut().scores().begin(), p.cut().scores().end());
  out.next_block = p.cut().next_block();
  return out;
}

}  // namespace

bool is_session_id(const std::string& id) {
  return id.size() == kSessionIdLength && id.find_first_not_of("0123456789abcdef") == std::string::npos;
}

std::string printable_session_id(const std::string& id) {
  if (is_session_id(id)) return "'" + id + "'";
  return "(a malformed id of " + std::to_string(id.size()) + " bytes; ids are " + std::to_string(kSessionIdLength) +
         " lowercase hex digits)";
}

SessionProgress progress_of(const SessionRecord& r) {
  return {r.options, r.pose, r.version, r.handles, r.handles_pending, r.cut};
}

void apply_progress(const SessionProgress& p, SessionRecord& r) {
  r.options = p.options;
  r.pose = p.pose;
  r.version = p.version;
  r.handles = p.handles;
  r.handles_pending = p.handles_pending;
  if (!p.cut.empty()) r.cut = p.cut;
}

std::string encode_session_record(const SessionRecord& r) {
  internal::SessionRecord p;
  p.set_format_version(1);
  p.set_session_id(r.id);
  p.set_hierarchy_key(r.hierarchy_key);
  *p.mutable_options() = r.options;
  p.set_editor_token(r.editor_token);
  p.set_viewer_token(r.viewer_token);
  p.mutable_pose()->Add(r.pose.begin(), r.pose.end());
  p.set_version(r.version);
  p.mutable_uploaded_ids()->Add(r.uploaded_ids.begin(), r.uploaded_ids.end());
  p.set_rig(r.rig);
  p.set_owner(r.owner);
  put_handles(r.handles, r.handles_pending, p);
  put_cut(r.cut, p);
  return sealed(p.SerializeAsString());
}

SessionRecord decode_session_record(const std::string& bytes) {
  internal::SessionRecord p;
  const std::string_view body = unsealed(bytes);
  if (!p.ParseFromArray(body.data(), static_cast<int>(body.size())))
    throw std::runtime_error("not a session record (unparseable)");
  if (p.format_version() != 1)
    throw std::runtime_error("session record format " + std::to_string(p.format_version()) + " is not supported (1 is)");
  if (p.session_id().empty() || p.hierarchy_key().empty()) throw std::runtime_error("session record without id or hierarchy");
  SessionRecord r;
  r.id = p.session_id();
  r.hierarchy_key = p.hierarchy_key();
  r.options = p.options();
  r.editor_token = p.editor_token();
  r.viewer_token = p.viewer_token();
  r.pose.assign(p.pose().begin(), p.pose().end());
  r.version = checked_version(p.version());
  r.uploaded_ids.assign(p.uploaded_ids().begin(), p.uploaded_ids().end());
  r.rig = p.rig();
  r.owner = p.owner();
  r.handles = handles_of(p);
  r.handles_pending = p.handles_pending();
  r.cut = cut_of(p);
  return r;
}

std::string encode_session_progress(const SessionProgress& progress) {
  internal::SessionRecord p;
  p.set_format_version(1);
  *p.mutable_options() = progress.options;
  p.mutable_pose()->Add(progress.pose.begin(), progress.pose.end());
  p.set_version(progress.version);
  put_handles(progress.handles, progress.handles_pending, p);
  put_cut(progress.cut, p);
  return sealed(p.SerializeAsString());
}

SessionProgress decode_session_progress(const std::string& bytes) {
  internal::SessionRecord p;
  const std::string_view body = unsealed(bytes);
  if (!p.ParseFromArray(body.data(), static_cast<int>(body.size())) || p.format_version() != 1)
    throw std::runtime_error("unreadable session progress");
  // Progress written before handles were kept has none: the same as the
  // writer had (it dropped them on a restart too).
  return {p.options(), {p.pose().begin(), p.pose().end()}, checked_version(p.version()), handles_of(p), p.handles_pending(),
          cut_of(p)};
}

void apply_session_progress(const std::string& bytes, SessionRecord& r) { apply_progress(decode_session_progress(bytes), r); }

}  // namespace filigree::server
