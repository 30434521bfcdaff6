#include "server/watch_reactors.h"

#include <cstdint>
#include <memory>
#include <optional>
#include <string>

#include "server/call_arguments.h"
#include "server/frame_stream_reactor.h"

namespace filigree::server {
namespace {

// A watching stream's start (Watch, Follow) once its session is admitted:
// subscribes it as `request` says and ends the start.
template <class Reactor>
void start_watching(FiligreeService& service, const grpc::Status& status, const std::shared_ptr<Session>& session,
                    const v1::WatchRequest& request, const std::shared_ptr<StreamStart>& started,
                    const std::shared_ptr<FrameStream<Reactor>>& stream) {
  if (!status.ok()) return end_start(started, stream, status);
  stream->set_format(request.frame_format());
  if (const grpc::Status detail = serve_detail(*stream, *session, request.frame_format(), request.max_vertices());
      !detail.ok())
    return end_start(started, stream, detail);
  // 0: the client has seen nothing yet and gets the current frame, even the rest frame.
  const std::optional<std::uint64_t> after =
      request.after_version() == 0 ? std::nullopt : std::optional<std::uint64_t>(request.after_version());
  if (session->needs_single(request.frame_format())) {
    // subscribe() transcodes the current frame into one buffer first: on a
    // job thread, not one of the callback threads. The start holds the
    // reactor until it ends.
    return service.run_job(
        [session, stream, started, after] {
          session->subscribe(stream, after);
          end_start(started, stream, grpc::Status::OK);
        },
        [started, stream](const grpc::Status& why) { end_start(started, stream, why); });
  }
  session->subscribe(stream, after);
  end_start(started, stream, grpc::Status::OK);
}

class WatchReactor final : public FrameStreamReactor<WatchReactor, grpc::ServerWriteReactor<grpc::ByteBuffer>> {
 public:
  WatchReactor(FiligreeService& service, grpc::CallbackServerContext* context, const grpc::ByteBuffer& request_bytes)
      : FrameStreamReactor(service, 0, this) {
    if (const grpc::Status parsed = parse_request(request_bytes, request_); !parsed.ok()) {
      stream_->writer().finish(parsed);
    } else {
      open(*context, request_.session_id(), Role::kViewer);
    }
  }

 private:
  void start(const grpc::Status& status, const std::shared_ptr<StreamStart>& started,
             const std::shared_ptr<FrameStream<WatchReactor>>& stream) override {
    start_watching(service_, status, session_, request_, started, stream);
  }

  v1::WatchRequest request_;
};

// Watch with acknowledgements: the stream's writer keeps at most
// max_in_flight frames unacknowledged (StreamWriter::set_window), so what
// waits in the HTTP/2 window is bounded in frames, not only in bytes.
class FollowReactor final : public FrameStreamReactor<FollowReactor, grpc::ServerBidiReactor<grpc::ByteBuffer, grpc::ByteBuffer>> {
 public:
  static constexpr std::uint32_t kDefaultInFlight = 2, kMostInFlight = 8;

  FollowReactor(FiligreeService& service, grpc::CallbackServerContext* context)
      : FrameStreamReactor(service, 0, this), context_(context) {
    StartRead(&request_bytes_);
  }

  void OnReadDone(bool ok) override {
    if (!ok) return stream_->writer().finish(grpc::Status::OK);  // the client is done reading
    if (const grpc::Status parsed = parse_request(request_bytes_, request_); !parsed.ok())
      return stream_->writer().finish(parsed);
    if (!watch_) {
      // The first message says what to follow: no read until the session is there.
      if (request_.max_in_flight() > kMostInFlight)
        return stream_->writer().finish({grpc::StatusCode::INVALID_ARGUMENT,
                                         "max_in_flight is at most " + std::to_string(kMostInFlight) + ", not " +
                                             std::to_string(request_.max_in_flight())});
      stream_->acknowledged_within(request_.max_in_flight() == 0 ? kDefaultInFlight : request_.max_in_flight());
      watch_ = request_.watch();
      return open(*context_, watch_->session_id(), Role::kViewer);
    }
    stream_->acknowledge(request_.read_version());
    StartRead(&request_bytes_);
  }

 private:
  void start(const grpc::Status& status, const std::shared_ptr<StreamStart>& started,
             const std::shared_ptr<FrameStream<FollowReactor>>& stream) override {
    if (status.ok()) StartRead(&request_bytes_);  // acknowledgements from now on
    start_watching(service_, status, session_, *watch_, started, stream);
  }

  grpc::CallbackServerContext* context_;
  grpc::ByteBuffer request_bytes_;
  v1::FollowRequest request_;
  std::optional<v1::WatchRequest> watch_;
};

}  // namespace

grpc::ServerWriteReactor<grpc::ByteBuffer>* new_watch_reactor(FiligreeService& service, grpc::CallbackServerContext* context,
                                                              const grpc::ByteBuffer& request) {
  return new WatchReactor(service, context, request);
}

grpc::ServerBidiReactor<grpc::ByteBuffer, grpc::ByteBuffer>* new_follow_reactor(FiligreeService& service,
                                                                             grpc::CallbackServerContext* context) {
  return new FollowReactor(service, context);
}

}  // namespace filigree::server
