#include "filigree/presence_watcher.h"

namespace filigree {

PresenceWatcher::PresenceWatcher(v1::Filigree::Stub& stub, v1::WatchPresenceRequest request, std::string token,
                                 Routing routing, Reconnect reconnect)
    : stub_(stub), request_(std::move(request)), token_(std::move(token)), routing_(routing),
      reconnect_(std::move(reconnect)) {
  open();
}

PresenceWatcher::~PresenceWatcher() {
  if (status_) return;
  cancel();  // so the drain in finish() cannot wait for the session
  finish();
}

void PresenceWatcher::open() {
  auto context = std::make_unique<grpc::ClientContext>();
  set_session_metadata(*context, request_.session_id(), token_, routing_);
  auto stream = stub_.WatchPresence(context.get(), request_);
  std::lock_guard lock(mutex_);
  stream_.reset();  // the old stream goes before its context
  context_ = std::move(context);
  stream_ = std::move(stream);
  if (cancelled_) context_->TryCancel();  // cancel() came while this opened
}

std::optional<v1::Presence> PresenceWatcher::read() {
  while (!status_) {
    v1::Presence presence;
    if (stream_->Read(&presence)) {
      reconnect_.reset();
      return presence;
    }
    const grpc::Status status = stream_->Finish();  // gRPC's rule: Finish once Read failed
    if (auto ended = reconnect_.wait_to_reconnect(status, mutex_, cancelled_cv_, cancelled_))
      status_ = std::move(*ended);
    else
      open();  // a new stream starts with the current presence
  }
  return std::nullopt;
}

void PresenceWatcher::cancel() {
  std::lock_guard lock(mutex_);
  cancelled_ = true;
  if (context_) context_->TryCancel();
  cancelled_cv_.notify_all();
}

grpc::Status PresenceWatcher::finish() {
  while (read()) {
  }
  return *status_;
}

}  // namespace filigree
