#pragma once
// A frame stream's start while its session loads, and how it ends.

#include <memory>
#include <mutex>

#include <grpcpp/grpcpp.h>

#include "server/filigree_service.h"
#include "server/session.h"

namespace filigree::server {

// A stream's start while its session loads (FiligreeService::with_session,
// maybe on a job thread, which gRPC does not know of): until the start
// ends, nothing but the start may end the stream, since the reactor is
// deleted once it ends and the start still runs on it. A cancel that
// arrives meanwhile is held, and end_start() answers it. Shared, so that
// the start can end it after the reactor may be gone.
class StreamStart {
 public:
  void begin() {
    std::lock_guard lock(mutex_);
    starting_ = true;
  }
  bool cancelled() {
    std::lock_guard lock(mutex_);
    return cancelled_;
  }
  // The start is over: whether a cancel came while it ran.
  bool end() {
    std::lock_guard lock(mutex_);
    starting_ = false;
    return cancelled_;
  }
  // OnCancel: whether the caller may end the stream now (false while it starts).
  bool cancel() {
    std::lock_guard lock(mutex_);
    cancelled_ = true;
    return !starting_;
  }

 private:
  std::mutex mutex_;
  bool starting_ = false, cancelled_ = false;
};

// A stream's status once its session is there: CANCELLED if a cancel came
// meanwhile, else authorize()'s answer, else the session's stream limits
// (open_stream; *slot then holds the stream's place).
inline grpc::Status admit_stream(StreamStart& start, FiligreeService& service, const grpc::Status& authorized,
                          const std::shared_ptr<Session>& s, std::shared_ptr<void>* slot) {
  if (start.cancelled()) return grpc::Status::CANCELLED;
  if (!authorized.ok()) return authorized;
  return service.open_stream(*s, slot);
}

// A stream's start's last step: the stream ends with `status` if it is not
// OK, or as cancelled if a cancel came while it started. Touches only what it
// is given (the reactor may be gone once `start` ends; a finished writer
// ignores a second finish).
template <class Stream>
void end_start(const std::shared_ptr<StreamStart>& start, const std::shared_ptr<Stream>& stream, const grpc::Status& status) {
  const bool cancelled = start->end();
  if (!status.ok()) {
    stream->writer().finish(status);
  } else if (cancelled) {
    stream->writer().finish(grpc::Status::CANCELLED);
  }
}

}  // namespace filigree::server
