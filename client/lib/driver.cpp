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
  request_.mutable_positions()->Assign(positions.begin(), positions.end());
  return write();
}

bool Driver::send_partial(std::uint64_t pose_id, std::span<const std::uint32_t> indices,
                          std::span<const float> positions) {
  if (positions.size() != 3 * indices.size())
    throw std::invalid_argument("send_partial: " + std::to_string(positions.size()) + " coordinates for " +
                                std::to_string(indices.size()) + " indices (3 per index expected)");
  request_.set_pose_id(pose_id);
  request_.mutable_indices()->Assign(indices.begin(), indices.end());
  request_.mutable_positions()->Assign(positions.begin(), positions.end());
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
