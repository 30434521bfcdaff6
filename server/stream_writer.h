#pragma once
// Serialises writes on a gRPC callback stream: one write in flight, a mailbox
// of one for droppable messages (a newer frame replaces a waiting one), a
// queue for those that must arrive (a keyframe a later frame needs; they go
// first), and a Finish that waits for the write in flight — the callback API
// allows neither two outstanding writes nor Finish during a write. Messages
// are held by shared pointer, so one frame can be written to every
// subscriber uncopied.

#include <algorithm>
#include <deque>
#include <functional>
#include <memory>
#include <mutex>
#include <optional>

#include <grpcpp/grpcpp.h>

namespace filigree::server {

// What goes on the wire for a queued message: the message itself, unless an
// overload for its type (found by argument-dependent lookup) says otherwise.
template <class Message>
const Message& wire(const Message& m) {
  return m;
}

template <class Reactor, class Message>
class StreamWriter {
 public:
  explicit StreamWriter(Reactor* reactor) : reactor_(reactor) {}

  // Queues a message. A droppable one replaces a waiting droppable one; a
  // non-droppable one is queued, written before any droppable one, and
  // drops the droppable one waiting before it (it is older). `supersede`: it
  // also replaces the non-droppable ones not started yet (a newer keyframe
  // makes an older one useless), so a stalled client's queue stays short.
  void send(std::shared_ptr<const Message> message, bool droppable, bool supersede = false) {
    std::lock_guard<std::recursive_mutex> lock(mutex_);
    if (closing_ || finished_) return;
    if (droppable) {
      waiting_ = std::move(message);
    } else {
      waiting_.reset();
      if (supersede) must_send_.clear();
      must_send_.push_back(std::move(message));
    }
    pump();
  }

  // At most `n` messages written and not yet released (release()), unless
  // the stream is finishing; 0 (the default): no bound. For a client that
  // acknowledges what it read (Follow): the HTTP/2 window then holds at most
  // `n` frames, and a slow reader gets the newest.
  void set_window(std::size_t n) {
    std::lock_guard<std::recursive_mutex> lock(mutex_);
    window_ = n;
    pump();
  }
  // `n` written messages were read by the client: as many more may be written.
  void release(std::size_t n) {
    std::lock_guard<std::recursive_mutex> lock(mutex_);
    in_flight_ -= std::min(n, in_flight_);
    pump();
  }

  // Called (under the writer's lock) with each message as its write starts.
  void on_start_write(std::function<void(const Message&)> observer) {
    std::lock_guard<std::recursive_mutex> lock(mutex_);
    observer_ = std::move(observer);
  }

  // Finishes the stream once the write in flight (and a waiting
  // non-droppable message) is done; later calls are ignored. `flush`: the
  // waiting droppable message is written first too (a stream's last frame).
  void finish(grpc::Status status, bool flush = false) {
    std::lock_guard<std::recursive_mutex> lock(mutex_);
    if (closing_ || finished_) return;
    closing_ = std::move(status);
    if (!flush) waiting_.reset();
    pump();
  }

  void on_write_done(bool ok) {
    std::lock_guard<std::recursive_mutex> lock(mutex_);
    writing_ = false;
    if (!ok) {  // the client is gone: nothing more can be written
      waiting_.reset();
      must_send_.clear();
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
    const bool window_full = window_ != 0 && in_flight_ >= window_ && !closing_;
    if (window_full) return;  // release() pumps again
    if (!must_send_.empty() || waiting_) {
      if (!must_send_.empty()) {
        out_ = std::move(must_send_.front());
        must_send_.pop_front();
      } else {
        out_ = std::move(waiting_);
      }
      writing_ = true;
      ++in_flight_;
      if (observer_) observer_(*out_);
      reactor_->StartWrite(&wire(*out_));
    } else if (closing_) {
      finished_ = true;
      reactor_->Finish(*closing_);
    }
  }

  // Recursive: gRPC may run OnWriteDone inline from StartWrite.
  std::recursive_mutex mutex_;
  Reactor* reactor_;
  std::shared_ptr<const Message> out_;  // kept alive until OnWriteDone
  std::shared_ptr<const Message> waiting_;        // droppable: the newest only
  std::deque<std::shared_ptr<const Message>> must_send_;
  std::function<void(const Message&)> observer_;
  bool writing_ = false;
  bool finished_ = false;
  std::size_t window_ = 0, in_flight_ = 0;
  std::optional<grpc::Status> closing_;
};

}  // namespace filigree::server
