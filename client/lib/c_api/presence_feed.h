#pragma once
// The background half of a C presence handle: one thread that reads a
// PresenceWatcher and keeps the newest Presence for poll(). The caller's
// threads never wait for the network to get one.

#include <chrono>
#include <condition_variable>
#include <cstdint>
#include <memory>
#include <mutex>
#include <optional>
#include <thread>

#include "c_api/frame_stream.h"
#include "filigree/presence_watcher.h"

namespace filigree::c_api {

class ErrorSlot;

class PresenceFeed {
 public:
  using End = FrameStream::End;

  // Starts the thread over `watcher`.
  explicit PresenceFeed(std::unique_ptr<PresenceWatcher> watcher);
  // stop() and join() unless done.
  ~PresenceFeed();
  PresenceFeed(const PresenceFeed&) = delete;
  PresenceFeed& operator=(const PresenceFeed&) = delete;

  // filigree_presence_poll, after the handle check.
  int poll(ErrorSlot& slot, const char* function, std::uint64_t* version, int* updated);
  // filigree_presence_wait: until poll() has a newer presence (FILIGREE_OK),
  // the stream ended (why) or `timeout` passed (nullopt: no limit).
  int wait(ErrorSlot& slot, const char* function, std::optional<std::chrono::milliseconds> timeout) const;
  // The presence polled last (empty before the first poll).
  std::shared_ptr<const v1::Presence> polled() const;

  // Cancels the stream; it then ends normally unless it had failed already.
  void stop();
  // Waits for the end and joins the thread (idempotent, thread-safe).
  void join();
  End end() const;

 private:
  void run() noexcept;

  std::unique_ptr<PresenceWatcher> watcher_;
  mutable std::mutex mutex_;  // guards everything below but the thread
  mutable std::condition_variable changed_cv_;  // a presence arrived or the stream ended
  std::shared_ptr<const v1::Presence> latest_, polled_;
  bool fresh_ = false;    // latest_ was not polled yet
  bool stopped_ = false;  // stop() was called: CANCELLED is a normal end
  bool ended_ = false;
  End end_;
  std::mutex join_mutex_;
  std::thread thread_;  // last: starts once everything above exists
};

}  // namespace filigree::c_api
