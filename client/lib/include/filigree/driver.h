#pragma once
// One Drive stream: numbered poses out, frames in.

#include <cstdint>
#include <memory>
#include <optional>
#include <span>
#include <string>

#include <grpcpp/grpcpp.h>

#include "filigree/call_metadata.h"
#include "filigree/v1/filigree.grpc.pb.h"

namespace filigree {

// Made by Client::drive(). Threading: one thread may send() while another
// read()s (the usual engine split); cancel() may be called from any thread;
// finish() once no other thread is inside read() or send().
class Driver {
 public:
  Driver(const Driver&) = delete;
  Driver& operator=(const Driver&) = delete;
  // Cancels the stream if finish() was not called (then drains and finishes it).
  ~Driver();

  // Sends a full pose: 3·m floats (x y z per base vertex, base order).
  // `pose_id` must increase within the stream; frames echo it. Blocks only
  // while the transport is flow-controlled. Returns false when the stream
  // has ended (the server refused a pose, the session closed, the call was
  // cancelled): finish() then says why.
  bool send(std::uint64_t pose_id, std::span<const float> positions);

  // Sends a partial pose: the base vertices `indices` move to `positions`
  // (3 floats per index). Throws std::invalid_argument if the sizes disagree.
  bool send_partial(std::uint64_t pose_id, std::span<const std::uint32_t> indices, std::span<const float> positions);
  // Sends a skeletal pose (sessions with a skeleton, SessionMesh::skeleton):
  // `values` holds 10 floats per joint for kLocalTrs (translation xyz,
  // rotation quaternion xyzw, scale xyz) or 16 for kModelMatrix (column-major);
  // `joints` names which joints (empty: all, in skeleton order). The server
  // skins the base mesh. Throws std::invalid_argument if the sizes disagree.
  bool send_joints(std::uint64_t pose_id, v1::JointPose::Space space, std::span<const std::uint32_t> joints,
                   std::span<const float> values);

  // Blocks for the next frame; nullopt once the stream has ended.
  std::optional<v1::Frame> read();

  // Tells the server no more poses come (it then ends the stream). Idempotent.
  bool writes_done();

  // Ends the stream at once (thread-safe, any time); reads then return nullopt.
  void cancel();

  // writes_done() if needed, discards unread frames, and returns the call's
  // status (OK when the stream ended normally). Later calls return the same.
  grpc::Status finish();

 private:
  friend class Client;
  Driver(v1::Filigree::Stub& stub, const std::string& session_id, const std::string& token, std::string client_name,
         Routing routing);
  bool write();

  grpc::ClientContext context_;  // declared before stream_: must outlive it
  std::unique_ptr<grpc::ClientReaderWriter<v1::DriveRequest, v1::Frame>> stream_;
  std::string session_id_, client_name_;
  v1::DriveRequest request_;  // reused by send(): no allocation per pose once warm
  bool writes_done_ = false;
  bool reads_ended_ = false;
  std::optional<grpc::Status> status_;
};

}  // namespace filigree
