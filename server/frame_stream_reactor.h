#pragma once
// The base of the frame streams' reactors (Drive, Watch, Follow, PlayClip).

#include <cstdint>
#include <memory>
#include <string>
#include <utility>

#include <grpcpp/grpcpp.h>

#include "server/filigree_service.h"
#include "server/frame_stream.h"
#include "server/session.h"
#include "server/stream_start.h"

namespace filigree::server {

// What the frame streams (Drive, Watch, Follow, PlayClip) share: the stream
// with its mailbox, its start while the session loads, its place in the
// session's stream limits, and the session once admitted. open() loads and
// authorizes the session (FiligreeService::with_session), admits the stream
// (admit_stream) and hands the reactor's start() the result: OK with
// session_ set, or why not. start() must end with end_start(started, stream, …),
// now or later; until then the reactor is not deleted.
template <class Reactor, class Base>
class FrameStreamReactor : public Base {
 public:
  void OnWriteDone(bool ok) override { stream_->writer().on_write_done(ok); }
  void OnCancel() override {
    if (start_->cancel()) stream_->writer().finish(grpc::Status::CANCELLED);
  }
  // The stream no longer subscribes or drives (leave()), and the reactor is
  // deleted: the last thing it does.
  void OnDone() override {
    leave(session_, *stream_, driver_);
    delete static_cast<Reactor*>(this);
  }

 protected:
  // `self`: the reactor being made (the stream's writer calls it later).
  FrameStreamReactor(FiligreeService& service, std::uint64_t driver, Reactor* self)
      : service_(service), driver_(driver), stream_(std::make_shared<FrameStream<Reactor>>(self, driver)) {}

  void open(grpc::CallbackServerContext& context, const std::string& session_id, Role role) {
    start_->begin();
    service_.with_session(context, session_id, role, [this](grpc::Status status, std::shared_ptr<Session> s) {
      const auto started = start_;
      const auto stream = stream_;  // this reactor may end once the start does
      status = admit_stream(*started, service_, status, s, &stream_slot_);
      if (status.ok()) session_ = std::move(s);
      start(status, started, stream);
    });
  }
  virtual void start(const grpc::Status& admitted, const std::shared_ptr<StreamStart>& started,
                     const std::shared_ptr<FrameStream<Reactor>>& stream) = 0;

  FiligreeService& service_;
  const std::uint64_t driver_;  // 0: a stream that does not drive (Watch)
  const std::shared_ptr<StreamStart> start_ = std::make_shared<StreamStart>();
  std::shared_ptr<void> stream_slot_;  // of the session owner's stream quota
  std::shared_ptr<FrameStream<Reactor>> stream_;
  std::shared_ptr<Session> session_;
};

}  // namespace filigree::server
