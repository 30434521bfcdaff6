#pragma once
// What is kept of a session beyond one process: enough to restart it, on this
// replica after a restart or on another after a failover (DESIGN §4).

#include <array>
#include <cstddef>
#include <cstdint>
#include <string>
#include <vector>

#include "filigree/v1/filigree.pb.h"
#include "mesh/tri_mesh.h"
#include "runtime/cut_snapshot.h"

namespace filigree::server {

// A handle as kept: the vertex, the client that set it and its target (floats
// as SetHandles carries them, so nothing is lost).
struct SessionHandle {
  Index vertex = 0;
  std::string client;
  std::array<float, 3> target{};
  bool operator==(const SessionHandle&) const = default;
};

struct SessionRecord {
  std::string id;
  std::string hierarchy_key;
  v1::SessionOptions options;
  std::string editor_token, viewer_token;
  std::vector<float> pose;  // 3·m, base order
  // The version of the frame that shows `pose`: the current frame's version,
  // or the next frame's while a change is journaled but not yet published.
  std::uint64_t version = 0;
  std::vector<Index> uploaded_ids;  // repair's vertex map, empty if none
  std::string rig;  // serialize_rig() of the base mesh's rig; empty: no skeleton
  std::string owner;  // the API key that created it (its name); empty without --api-keys
  // Every client's handles, oldest first (per vertex the last listed wins).
  std::vector<SessionHandle> handles;
  bool handles_pending = false;  // not solved into `pose` yet
  // The adaptive cut of the frame showing `pose` (empty: none, or not taken).
  CutSnapshot cut;
  // The edit history as EditHistory::serialize() wrote it (kept beside the
  // record by the stores; empty: none).
  std::string history;
};

// Session ids are 20 lowercase hex digits (80 random bits): safe as file
// names and Redis keys, and what a client may propose for a new session.
inline constexpr std::size_t kSessionIdLength = 20;
bool is_session_id(const std::string& id);
// The largest version a stored session may have (decode_* refuse larger).
inline constexpr std::uint64_t kMaxSessionVersion = std::uint64_t{1} << 62;
// `id` for a message: itself if it is a session id, else a bounded
// description (a client's 1 MB "id" is not echoed back).
std::string printable_session_id(const std::string& id);

// What changes while a session runs, journaled on every accepted change when
// replicas share state (the rest of the record is written once).
struct SessionProgress {
  v1::SessionOptions options;
  std::vector<float> pose;
  std::uint64_t version = 0;
  std::vector<SessionHandle> handles;
  bool handles_pending = false;
  // Empty in journaled changes (O(nodes), too large to write per change);
  // set when a whole record is saved as progress (progress_of).
  CutSnapshot cut;
};

// The part of `r` that progress carries, and progress applied onto a record.
// Progress without a cut (a journaled change) keeps the record's: a cut a few
// frames old is a valid cut, closer to the adapted one than a full cut. (With
// Redis a journaled change replaces the stored progress whole, cut included:
// see SessionRecord.cut in session_record.proto.)
SessionProgress progress_of(const SessionRecord& r);
void apply_progress(const SessionProgress& p, SessionRecord& r);

// The record as bytes (filigree.internal.SessionRecord) and back. decode
// throws std::runtime_error for bytes that are not a record of this format.
std::string encode_session_record(const SessionRecord& r);
SessionRecord decode_session_record(const std::string& bytes);
// Progress as bytes (a record with only options, pose, version, handles and
// the cut), and applied onto a record; throws std::runtime_error for
// unreadable bytes.
std::string encode_session_progress(const SessionProgress& p);
SessionProgress decode_session_progress(const std::string& bytes);
void apply_session_progress(const std::string& bytes, SessionRecord& r);

}  // namespace filigree::server
