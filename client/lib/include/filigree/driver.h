#pragma once
// One Drive stream: numbered poses out, frames in.

#include <atomic>
#include <chrono>
#include <condition_variable>
#include <cstdint>
#include <deque>
#include <memory>
#include <mutex>
#include <optional>
#include <span>
#include <string>
#include <vector>

#include <grpcpp/grpcpp.h>

#include "filigree/call_metadata.h"
#include "filigree/reconnect.h"
#include "filigree/v1/filigree.grpc.pb.h"

namespace filigree {

class DetailSwitch;

// What Client::drive() asks of the stream.
struct DriveOptions {
  // A level of detail for the frames that answer the poses, as
  // WatchOptions::max_vertices (0: full detail): the stream's first message
  // after the first pose is the level (v1::Frame::has_level():
  // FrameDecoder::set_level). Driver::set_detail changes it.
  std::uint32_t max_vertices = 0;
};

// Made by Client::drive(). Threading: one thread may send() while another
// read()s (the usual engine split); cancel() may be called from any thread;
// finish() once no other thread is inside read() or send().
//
// Reconnection (Reconnect, on by default): when the server goes away
// (UNAVAILABLE: a restart, a failover to another replica), read() opens a
// new Drive stream after a backoff and re-sends, in order, every pose no
// frame has acknowledged yet (a frame acknowledges the poses up to its
// pose_id), then a pending writes_done(). Meanwhile send() keeps accepting
// poses (they wait for the new stream) and read() blocks. So reconnection
// needs a thread in read() (or finish()), as every Drive does to get frames.
class Driver {
 public:
  Driver(const Driver&) = delete;
  Driver& operator=(const Driver&) = delete;
  // Cancels the stream if finish() was not called (then drains and finishes it).
  ~Driver();

  // Sends a full pose: 3·m floats (x y z per base vertex, base order).
  // `pose_id` must increase within the Driver; frames echo it. Blocks only
  // while the transport is flow-controlled. Returns false when the stream
  // has ended for good (the server refused a pose, the session closed, the
  // call was cancelled, reconnection gave up): finish() then says why.
  // Throws std::invalid_argument, sending nothing, for a coordinate that is
  // not finite (naming the base vertex): the stream goes on.
  bool send(std::uint64_t pose_id, std::span<const float> positions);

  // Sends a partial pose: the base vertices `indices` move to `positions`
  // (3 floats per index). Throws std::invalid_argument if the sizes disagree
  // or a coordinate is not finite.
  bool send_partial(std::uint64_t pose_id, std::span<const std::uint32_t> indices, std::span<const float> positions);
  // Sends a skeletal pose (sessions with a skeleton, SessionMesh::skeleton):
  // `values` holds 10 floats per joint for kLocalTrs (translation xyz,
  // rotation quaternion xyzw, scale xyz) or 16 for kModelMatrix (column-major);
  // `joints` names which joints (empty: all, in skeleton order). The server
  // skins the base mesh. Throws std::invalid_argument if the sizes disagree,
  // a value is not finite, a rotation quaternion is zero or a model matrix
  // is not affine, naming the joint (its index in the skeleton).
  bool send_joints(std::uint64_t pose_id, v1::JointPose::Space space, std::span<const std::uint32_t> joints,
                   std::span<const float> values);

  // Blocks for the next frame; nullopt once the stream has ended for good
  // (with Reconnect, UNAVAILABLE is not the end: read() reconnects). A pose
  // the server refused (Frame.refused: beyond the mesh's reach, a joint the
  // skeleton lacks…) is no frame: read() goes on past it, and
  // last_refusal() tells which pose and why. The stream goes on.
  std::optional<v1::Frame> read();

  struct Refusal {
    std::uint64_t pose_id = 0;
    std::string message;
  };
  // The newest pose the server refused, if any (thread-safe).
  std::optional<Refusal> last_refusal() const {
    std::lock_guard lock(mutex_);
    return last_refusal_;
  }

  // The gesture the poses sent from now on belong to (a drag, a slider's
  // travel): poses of one nonzero id are one history entry, undone as one
  // (Client::undo). Use a new id for each gesture (a counter will do: only
  // this client's latest entry can continue); 0 (the default) ends the
  // gesture: the server then joins poses less than 0.5 s apart. Thread-safe;
  // a pose takes the id set when it is sent, a re-sent one (after a
  // reconnection) keeps it.
  void set_gesture(std::uint64_t gesture_id) { gesture_.store(gesture_id); }
  std::uint64_t gesture() const { return gesture_.load(); }

  // Tells the server no more poses come (it then ends the stream). Idempotent.
  bool writes_done();

  // Moves a stream opened with a vertex budget (DriveOptions::max_vertices)
  // to the level of `max_vertices`, as Watcher::set_detail: returns the
  // level's vertex count; the stream then sends the level and frames of it.
  // Needs the stream's level read (it follows the first pose). Thread-safe.
  std::uint32_t set_detail(std::uint32_t max_vertices);

  // Ends the stream at once, a reconnection wait too (thread-safe, any
  // time); reads then return nullopt.
  void cancel();

  // Poses sent that no frame has acknowledged yet (they would be re-sent
  // after a reconnection). A full pose makes the poses before it moot.
  std::size_t unacknowledged() const;
  // At most this many are kept, for a driver whose frames nobody reads
  // (nothing acknowledges them): past it the oldest go, and a reconnection
  // could not re-send them.
  static constexpr std::size_t kMaxUnacknowledged = 4096;

  // writes_done() if needed, discards unread frames, and returns the call's
  // status (OK when the stream ended normally). Later calls return the same.
  grpc::Status finish();

 private:
  friend class Client;
  Driver(v1::Filigree::Stub& stub, const std::string& session_id, const std::string& token, std::string client_name,
         const DriveOptions& options, Routing routing, Reconnect reconnect, std::chrono::milliseconds call_timeout);
  // Opens a stream (again) and re-sends the unacknowledged poses; mutex_ held.
  void open(std::unique_lock<std::mutex>& lock);
  // Remembers request_ as unacknowledged and writes it.
  bool write();

  v1::Filigree::Stub& stub_;
  const std::string session_id_, token_, client_name_;
  const Routing routing_;
  const std::chrono::milliseconds call_timeout_;  // of set_detail's SetDetail
  ReconnectSchedule reconnect_;  // the reading thread's
  std::unique_ptr<DetailSwitch> detail_;  // the budget, and the stream id the level names
  std::atomic<std::uint64_t> gesture_{0};  // set_gesture's, for the poses sent from then on
  v1::DriveRequest request_;  // filled by send(); recycled (spare_), so no allocation per pose once warm

  // Held while writing, which may block on flow control, so cancel() has
  // its own mutex. Order: mutex_, then cancel_mutex_.
  mutable std::mutex mutex_;  // guards the stream's use and the state below it
  std::mutex cancel_mutex_;   // guards context_ and cancelled_
  std::condition_variable cancelled_cv_;
  std::unique_ptr<grpc::ClientContext> context_;  // one per stream; outlives it
  bool cancelled_ = false;
  std::unique_ptr<grpc::ClientReaderWriter<v1::DriveRequest, v1::Frame>> stream_;
  std::deque<v1::DriveRequest> unacknowledged_;  // in pose_id order
  std::optional<Refusal> last_refusal_;
  std::vector<v1::DriveRequest> spare_;           // acknowledged, for request_ to reuse
  bool broken_ = false;       // the current stream failed; poses wait for the next one
  bool writes_done_ = false;  // asked by the caller; repeated on every new stream
  std::optional<grpc::Status> status_;  // set once the stream has ended for good
};

}  // namespace filigree
