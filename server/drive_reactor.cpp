#include "server/drive_reactor.h"

#include <algorithm>
#include <cstdint>
#include <memory>
#include <mutex>
#include <string>
#include <utility>

#include "server/call_arguments.h"
#include "server/frame_stream_reactor.h"
#include "server/pose_request.h"

namespace filigree::server {
namespace {

class DriveReactor final : public FrameStreamReactor<DriveReactor, grpc::ServerBidiReactor<grpc::ByteBuffer, grpc::ByteBuffer>> {
 public:
  DriveReactor(FiligreeService& service, grpc::CallbackServerContext* context)
      : FrameStreamReactor(service, service.next_driver_id(), this), context_(context) {
    // A driver that half-closes still gets the frame of its last pose: the
    // stream finishes once a frame includes it. The observer lives in the
    // stream (so `stream` is alive whenever it runs) and may outlive this.
    stream_->on_event([state = ending_, stream = stream_.get(), driver = driver_](const PublishedFrame* frame) {
      std::lock_guard lock(state->mutex);
      if (!frame) return;  // the session closed: the stream is finished already
      if (const auto it = frame->pose_of_driver.find(driver); it != frame->pose_of_driver.end())
        state->answered = std::max(state->answered, it->second);
      if (state->half_closed && state->answered >= state->submitted) stream->writer().finish(grpc::Status::OK, /*flush=*/true);
    });
    StartRead(&request_bytes_);
  }

  void OnReadDone(bool ok) override {
    if (!ok) {  // the client is done driving: finish after the frame of its last pose
      stream_slot_.reset();  // a half-closed stream no longer counts (before the client can see the end)
      std::lock_guard lock(ending_->mutex);
      ending_->half_closed = true;
      if (!session_ || ending_->answered >= ending_->submitted) stream_->writer().finish(grpc::Status::OK, /*flush=*/true);
      return;
    }
    if (const grpc::Status parsed = parse_request(request_bytes_, request_); !parsed.ok()) return stream_->writer().finish(parsed);
    // The first request names the session: no read until it is there.
    if (!session_) return open(*context_, request_.session_id(), Role::kEditor);
    take_request();
  }

 private:
  void start(const grpc::Status& status, const std::shared_ptr<StreamStart>& started,
             const std::shared_ptr<FrameStream<DriveReactor>>& stream) override {
    if (!status.ok()) return end_start(started, stream, status);
    stream_->set_format(request_.frame_format());
    if (const grpc::Status detail = serve_detail(*stream_, *session_, request_.frame_format(), request_.max_vertices());
        !detail.ok())
      return end_start(started, stream, detail);
    session_->subscribe(stream_, session_->version());
    take_request();  // may end the stream: `this` is not touched after it
    end_start(started, stream, status);
  }

  // Submits the request just read and reads the next.
  void take_request() {
    try {
      submit_pose(*session_, driver_, request_);
      const bool pose = !request_.positions().empty() || request_.has_joints();  // not a keyframe request alone
      std::lock_guard lock(ending_->mutex);
      if (pose) ending_->submitted = std::max(ending_->submitted, request_.pose_id());
    } catch (const PoseError& e) {
      // That pose is refused, not the stream: the client hears which and
      // why, the session is unchanged, and the next good pose is answered.
      refuse(request_.pose_id(), e.what());
    } catch (const StoreUnavailable& e) {  // not journaled, so not acknowledged: the client resends
      return stream_->writer().finish({grpc::StatusCode::UNAVAILABLE, e.what()});
    }
    StartRead(&request_bytes_);
  }

  // A message answering pose `pose_id` as refused (Frame.refused), queued
  // like a keyframe: it is never dropped for a newer frame.
  void refuse(std::uint64_t pose_id, const std::string& why) {
    v1::Frame answer;
    answer.set_pose_id(pose_id);
    answer.mutable_refused()->set_code(static_cast<std::uint32_t>(grpc::StatusCode::INVALID_ARGUMENT));
    answer.mutable_refused()->set_message(why);
    auto out = std::make_shared<OutgoingFrame>();
    grpc::Slice bytes(answer.SerializeAsString());
    out->bytes = grpc::ByteBuffer(&bytes, 1);
    stream_->writer().send(std::move(out), /*droppable=*/false);
  }

  // The newest pose id submitted and the newest a frame has answered.
  struct Ending {
    std::mutex mutex;
    std::uint64_t submitted = 0, answered = 0;
    bool half_closed = false;
  };

  grpc::CallbackServerContext* context_;
  std::shared_ptr<Ending> ending_ = std::make_shared<Ending>();
  grpc::ByteBuffer request_bytes_;
  v1::DriveRequest request_;
};

}  // namespace

grpc::ServerBidiReactor<grpc::ByteBuffer, grpc::ByteBuffer>* new_drive_reactor(FiligreeService& service,
                                                                            grpc::CallbackServerContext* context) {
  return new DriveReactor(service, context);
}

}  // namespace filigree::server
