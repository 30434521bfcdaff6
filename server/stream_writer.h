#pragma once
// Serialises writes on a gRPC callback stream: one write in flight, a mailbox
// of one for droppable messages (a newer frame replaces a waiting one), and a
// Finish that waits for the write in flight — the callback API allows neither
// two outstanding writes nor Finish during a write. Messages are held by
// shared pointer, so one frame can be written to every subscriber uncopied.

#include <memory>
#include <mutex>
#include <optional>

#include <grpcpp/grpcpp.h>

namespace filigree::server {

template <class Reactor, class Message>
class StreamWriter {
 public:
  explicit StreamWriter(Reactor* reactor) : reactor_(reactor) {}

  // Queues a message. A droppable one replaces a waiting droppable one; a
  // waiting non-droppable message is never replaced.
  void send(std::shared_ptr<const Message> message, bool droppable) {
    std::lock_guard<std::recursive_mutex> lock(mutex_);
    if (closing_ || finished_) return;
    if (waiting_ && !waiting_droppable_ && droppable) return;
    waiting_ = std::move(message);
    waiting_droppable_ = droppable;
    pump();
  }

  // Finishes the stream once the write in flight (and a waiting
  // non-droppable message) is done; later calls are ignored.
  void finish(grpc::Status status) {
    std::lock_guard<std::recursive_mutex> lock(mutex_);
    if (closing_ || finished_) return;
    closing_ = std::move(status);
    if (waiting_ && waiting_droppable_) waiting_.reset();
    pump();
  }

  void on_write_done(bool ok) {
    std::lock_guard<std::recursive_mutex> lock(mutex_);
    writing_ = false;
    if (!ok) {  // the client is gone: nothing more can be written
      waiting_.reset();
      if (!closing_) closing_ = grpc::Status(grpc::StatusCode::CANCELLED, "the client went away");
    }
    pump();
  }

  // The reactor is being deleted (OnDone): never touch it again.
  void detach() {
    std::lock_guard<std::recursive_mutex> lock(mutex_);
    finished_ = true;
  }

 private:
  void pump() {
    if (finished_ || writing_) return;
    if (waiting_) {
      out_ = std::move(waiting_);
      writing_ = true;
      reactor_->StartWrite(out_.get());
    } else if (closing_) {
      finished_ = true;
      reactor_->Finish(*closing_);
    }
  }

  // Recursive: gRPC may run OnWriteDone inline from StartWrite.
  std::recursive_mutex mutex_;
  Reactor* reactor_;
  std::shared_ptr<const Message> out_;  // kept alive until OnWriteDone
  std::shared_ptr<const Message> waiting_;
  bool waiting_droppable_ = true;
  bool writing_ = false;
  bool finished_ = false;
  std::optional<grpc::Status> closing_;
};

}  // namespace filigree::server
