#include "filigree/watcher.h"

#include "filigree/call_metadata.h"

namespace filigree {

Watcher::Watcher(v1::Filigree::Stub& stub, const std::string& session_id, const std::string& token,
                 std::uint64_t after_version, Routing routing) {
  set_session_metadata(context_, session_id, token, routing);
  v1::WatchRequest request;
  request.set_session_id(session_id);
  request.set_after_version(after_version);
  request.set_frame_format(v1::FRAME_FORMAT_CHUNKED);
  stream_ = stub.Watch(&context_, request);
}

Watcher::Watcher(v1::Filigree::Stub& stub, const v1::PlayClipRequest& request, const std::string& token,
                 Routing routing) {
  set_session_metadata(context_, request.session_id(), token, routing);
  stream_ = stub.PlayClip(&context_, request);
}

Watcher::~Watcher() {
  if (status_) return;
  context_.TryCancel();  // so the drain in finish() cannot wait for the session
  finish();
}

std::optional<v1::Frame> Watcher::read() {
  if (reads_ended_) return std::nullopt;
  v1::Frame frame;
  if (stream_->Read(&frame)) return frame;
  reads_ended_ = true;
  return std::nullopt;
}

void Watcher::cancel() { context_.TryCancel(); }

grpc::Status Watcher::finish() {
  if (status_) return *status_;
  // gRPC's rule: read until Read() fails, then Finish().
  while (read()) {
  }
  status_ = stream_->Finish();
  return *status_;
}

}  // namespace filigree
