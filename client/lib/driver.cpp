#include "filigree/driver.h"

#include <stdexcept>

#include "filigree/call_metadata.h"

namespace filigree {

Driver::Driver(v1::Filigree::Stub& stub, const std::string& session_id, const std::string& token,
               std::string client_name, Routing routing)
    : session_id_(session_id), client_name_(std::move(client_name)) {
  set_session_metadata(context_, session_id, token, routing);
  stream_ = stub.Drive(&context_);
}

Driver::~Driver() {
  if (status_) return;
  // Unfinished: cancel so the drain below cannot wait on the server.
  context_.TryCancel();
  finish();
}

bool Driver::write() {
  // Every request names the session and the client: the first one opens the
  // driver on the server, and the name is reported with each change.
  request_.set_session_id(session_id_);
  request_.set_client_name(client_name_);
  request_.set_frame_format(v1::FRAME_FORMAT_CHUNKED);
  return !writes_done_ && stream_->Write(request_);
}

bool Driver::send(std::uint64_t pose_id, std::span<const float> positions) {
  request_.set_pose_id(pose_id);
  request_.clear_indices();
  request_.clear_joints();
  request_.mutable_positions()->Assign(positions.begin(), positions.end());
  return write();
}

bool Driver::send_partial(std::uint64_t pose_id, std::span<const std::uint32_t> indices,
                          std::span<const float> positions) {
  if (positions.size() != 3 * indices.size())
    throw std::invalid_argument("send_partial: " + std::to_string(positions.size()) + " coordinates for " +
                                std::to_string(indices.size()) + " indices (3 per index expected)");
  request_.set_pose_id(pose_id);
  request_.clear_joints();
  request_.mutable_indices()->Assign(indices.begin(), indices.end());
  request_.mutable_positions()->Assign(positions.begin(), positions.end());
  return write();
}

bool Driver::send_joints(std::uint64_t pose_id, v1::JointPose::Space space, std::span<const std::uint32_t> joints,
                         std::span<const float> values) {
  const std::size_t per_joint = space == v1::JointPose::SPACE_MODEL_MATRIX ? 16 : 10;
  if (!joints.empty() && values.size() != per_joint * joints.size())
    throw std::invalid_argument("send_joints: " + std::to_string(values.size()) + " values for " +
                                std::to_string(joints.size()) + " joints (" + std::to_string(per_joint) +
                                " per joint expected)");
  if (joints.empty() && values.size() % per_joint != 0)
    throw std::invalid_argument("send_joints: " + std::to_string(values.size()) + " values is not a multiple of " +
                                std::to_string(per_joint));
  request_.set_pose_id(pose_id);
  request_.clear_indices();
  request_.clear_positions();
  v1::JointPose& pose = *request_.mutable_joints();
  pose.set_space(space);
  pose.mutable_joint_indices()->Assign(joints.begin(), joints.end());
  pose.mutable_values()->Assign(values.begin(), values.end());
  return write();
}

std::optional<v1::Frame> Driver::read() {
  if (reads_ended_) return std::nullopt;
  v1::Frame frame;
  if (stream_->Read(&frame)) return frame;
  reads_ended_ = true;
  return std::nullopt;
}

bool Driver::writes_done() {
  if (writes_done_) return true;
  writes_done_ = true;
  return stream_->WritesDone();
}

void Driver::cancel() { context_.TryCancel(); }

grpc::Status Driver::finish() {
  if (status_) return *status_;
  writes_done();
  // gRPC's rule: read until Read() fails, then Finish().
  while (read()) {
  }
  status_ = stream_->Finish();
  return *status_;
}

}  // namespace filigree
