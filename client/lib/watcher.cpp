#include "filigree/watcher.h"

#include <algorithm>

#include "detail_switch.h"
#include "filigree/call_metadata.h"

namespace filigree {

Watcher::Watcher(v1::Filigree::Stub& stub, const std::string& session_id, const std::string& token,
                 const WatchOptions& options, Routing routing, Reconnect reconnect,
                 std::chrono::milliseconds call_timeout)
    : stub_(stub), token_(token), routing_(routing), call_timeout_(call_timeout), session_id_(session_id),
      last_version_(options.after_version), reconnect_(std::move(reconnect)),
      detail_(std::make_unique<DetailSwitch>(options.max_vertices)) {
  open();
}

Watcher::Watcher(v1::Filigree::Stub& stub, const v1::PlayClipRequest& request, const std::string& token,
                 Routing routing, std::chrono::milliseconds call_timeout)
    : stub_(stub), token_(token), routing_(routing), call_timeout_(call_timeout), clip_(request),
      session_id_(request.session_id()), detail_(std::make_unique<DetailSwitch>(0)) {
  reconnect_.disable();  // a clip that started over would play twice
  open();
}

void Watcher::open() {
  auto context = std::make_unique<grpc::ClientContext>();
  set_session_metadata(*context, session_id_, token_, routing_);
  std::unique_ptr<grpc::ClientReader<v1::Frame>> clip_stream;
  std::unique_ptr<grpc::ClientReaderWriter<v1::FollowRequest, v1::Frame>> follow;
  if (clip_) {
    clip_stream = stub_.PlayClip(context.get(), *clip_);
  } else {
    // Follow, not Watch: each frame read is acknowledged, so the frames on
    // the wire stay few and a slow reader gets the newest.
    follow = stub_.Follow(context.get());
    v1::FollowRequest first;
    first.mutable_watch()->set_session_id(session_id_);
    first.mutable_watch()->set_after_version(last_version_);
    first.mutable_watch()->set_frame_format(v1::FRAME_FORMAT_CHUNKED);
    first.mutable_watch()->set_max_vertices(detail_->max_vertices());
    first.set_max_in_flight(kFramesInFlight);
    follow->Write(first);  // a failed write shows as the stream's end in read()
  }
  detail_->opened();
  std::lock_guard lock(mutex_);
  clip_stream_.reset(), follow_.reset();  // the old stream goes before its context
  context_ = std::move(context);
  clip_stream_ = std::move(clip_stream);
  follow_ = std::move(follow);
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
    if (follow_ ? follow_->Read(&frame) : clip_stream_->Read(&frame)) {
      last_version_ = std::max(last_version_, frame.version());
      detail_->observe(frame);
      if (follow_) {
        v1::FollowRequest read;
        read.set_read_version(frame.version());
        follow_->Write(read);  // a failed write shows as the stream's end at the next read
      }
      reconnect_.reset();
      return frame;
    }
    // gRPC's rule: Finish once Read failed.
    const grpc::Status status = follow_ ? follow_->Finish() : clip_stream_->Finish();
    if (auto ended = reconnect_.wait_to_reconnect(status, mutex_, cancelled_cv_, cancelled_)) {
      status_ = std::move(*ended);
    } else {
      open();
    }
  }
  return std::nullopt;
}

std::uint32_t Watcher::set_detail(std::uint32_t max_vertices) {
  return detail_->set(stub_, session_id_, token_, routing_, call_timeout_, max_vertices);
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
