#include "server/session_record.h"

#include <stdexcept>

#include "filigree/internal/session_record.pb.h"

namespace filigree::server {

bool is_session_id(const std::string& id) {
  return id.size() == kSessionIdLength && id.find_first_not_of("0123456789abcdef") == std::string::npos;
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
  return p.SerializeAsString();
}

SessionRecord decode_session_record(const std::string& bytes) {
  internal::SessionRecord p;
  if (!p.ParseFromString(bytes)) throw std::runtime_error("not a session record (unparseable)");
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
  r.version = p.version();
  r.uploaded_ids.assign(p.uploaded_ids().begin(), p.uploaded_ids().end());
  r.rig = p.rig();
  r.owner = p.owner();
  return r;
}

std::string encode_session_progress(const SessionProgress& progress) {
  internal::SessionRecord p;
  p.set_format_version(1);
  *p.mutable_options() = progress.options;
  p.mutable_pose()->Add(progress.pose.begin(), progress.pose.end());
  p.set_version(progress.version);
  return p.SerializeAsString();
}

void apply_session_progress(const std::string& bytes, SessionRecord& r) {
  internal::SessionRecord p;
  if (!p.ParseFromString(bytes) || p.format_version() != 1) throw std::runtime_error("unreadable session progress");
  r.options = p.options();
  r.pose.assign(p.pose().begin(), p.pose().end());
  r.version = p.version();
}

}  // namespace filigree::server
