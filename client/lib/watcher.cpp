#include "filigree/watcher.h"

#include <algorithm>

#include "filigree/call_metadata.h"

namespace filigree {

Watcher::Watcher(v1::Filigree::Stub& stub, const std::string& session_id, const std::string& token,
                 std::uint64_t after_version, Routing routing, Reconnect reconnect)
    : stub_(stub), token_(token), routing_(routing), session_id_(session_id), last_version_(after_version),
      reconnect_(std::move(reconnect)) {
  open();
}

Watcher::Watcher(v1::Filigree::Stub& stub, const v1::PlayClipRequest& request, const std::string& token,
                 Routing routing)
    : stub_(stub), token_(token), routing_(routing), clip_(request), session_id_(request.session_id()) {
  reconnect_.disable();  // a clip that started over would play twice
  open();
}

void Watcher::open() {
  auto context = std::make_unique<grpc::ClientContext>();
  set_session_metadata(*context, session_id_, token_, routing_);
  std::unique_ptr<grpc::ClientReader<v1::Frame>> stream;
  if (clip_) {
    stream = stub_.PlayClip(context.get(), *clip_);
  } else {
    v1::WatchRequest request;
    request.set_session_id(session_id_);
    request.set_after_version(last_version_);
    request.set_frame_format(v1::FRAME_FORMAT_CHUNKED);
    stream = stub_.Watch(context.get(), request);
  }
  std::lock_guard lock(mutex_);
  stream_.reset();  // the old stream goes before its context
  context_ = std::move(context);
  stream_ = std::move(stream);
  if (cancelled_) context_->TryCancel();  // cancel() came while this opened
}

Watcher::~Watcher() {
  if (status_) return;
  cancel();  // so the drain in finish() cannot wait for the session
  finish();
}

std::optional<v1::Frame> Watcher::read() {
  while (!status_) {  // set once the stream has ended for good
    v1::Frame frame;
    if (stream_->Read(&frame)) {
      last_version_ = std::max(last_version_, frame.version());
      reconnect_.reset();
      return frame;
    }
    const grpc::Status status = stream_->Finish();  // gRPC's rule: Finish once Read failed
    if (auto ended = reconnect_.wait_to_reconnect(status, mutex_, cancelled_cv_, cancelled_)) {
      status_ = std::move(*ended);
    } else {
      open();
    }
  }
  return std::nullopt;
}

void Watcher::cancel() {
  std::lock_guard lock(mutex_);
  cancelled_ = true;
  if (context_) context_->TryCancel();
  cancelled_cv_.notify_all();
}

grpc::Status Watcher::finish() {
  while (read()) {  // read until the stream has ended
  }
  return *status_;
}

}  // namespace filigree
