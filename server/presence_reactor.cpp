#include "server/presence_reactor.h"

#include <memory>
#include <string>

#include "server/call_arguments.h"
#include "server/filigree_service.h"
#include "server/pose_request.h"
#include "server/session.h"
#include "server/stream_start.h"
#include "server/stream_writer.h"

namespace filigree::server {
namespace {

class PresenceReactor;

// The session's side of the stream: a mailbox of one (a slow reader gets the
// newest presence), written by the reactor's writer.
class PresenceStream final : public PresenceSink {
 public:
  explicit PresenceStream(PresenceReactor* reactor) : writer_(reactor) {}
  void offer(std::shared_ptr<const v1::Presence> presence) override { writer_.send(std::move(presence), /*droppable=*/true); }
  void close(bool session_closed, const std::string& why) override {
    writer_.finish(session_closed ? grpc::Status::OK : grpc::Status(grpc::StatusCode::UNAVAILABLE, why));
  }
  StreamWriter<PresenceReactor, v1::Presence>& writer() { return writer_; }

 private:
  StreamWriter<PresenceReactor, v1::Presence> writer_;
};

class PresenceReactor final : public grpc::ServerWriteReactor<v1::Presence> {
 public:
  PresenceReactor(FiligreeService& service, grpc::CallbackServerContext* context, const v1::WatchPresenceRequest& request)
      : service_(service), name_(request.client_name()), stream_(std::make_shared<PresenceStream>(this)) {
    if (name_.size() > kMaxClientName) {
      stream_->writer().finish({grpc::StatusCode::INVALID_ARGUMENT, "client_name has " + std::to_string(name_.size()) +
                                                                      " bytes; at most " + std::to_string(kMaxClientName)});
      return;
    }
    const std::string token = metadata(*context, "x-filigree-token");
    start_->begin();
    service_.with_session(*context, request.session_id(), Role::kViewer,
                          [this, token](grpc::Status status, std::shared_ptr<Session> s) {
                            const auto started = start_;
                            const auto stream = stream_;  // this reactor may end once the start does
                            status = admit_stream(*started, service_, status, s, &slot_);
                            if (status.ok()) {
                              session_ = std::move(s);
                              session_->join_presence(stream, name_, session_->authorize(token));
                            }
                            end_start(started, stream, status);
                          });
  }

  void OnWriteDone(bool ok) override { stream_->writer().on_write_done(ok); }
  void OnCancel() override {
    if (start_->cancel()) stream_->writer().finish(grpc::Status::CANCELLED);
  }
  void OnDone() override {
    if (session_) session_->leave_presence(stream_.get(), name_);
    stream_->writer().detach();
    delete this;
  }

 private:
  FiligreeService& service_;
  const std::string name_;
  const std::shared_ptr<StreamStart> start_ = std::make_shared<StreamStart>();
  std::shared_ptr<PresenceStream> stream_;
  std::shared_ptr<void> slot_;  // the stream's place in the session's stream limits
  std::shared_ptr<Session> session_;
};

}  // namespace

grpc::ServerWriteReactor<v1::Presence>* new_presence_reactor(FiligreeService& service, grpc::CallbackServerContext* context,
                                                             const v1::WatchPresenceRequest& request) {
  return new PresenceReactor(service, context, request);
}

}  // namespace filigree::server
