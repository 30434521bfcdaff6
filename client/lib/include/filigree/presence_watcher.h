#pragma once
// Who is in a session and what they touch: a WatchPresence stream of
// v1::Presence snapshots (Client::watch_presence).

#include <condition_variable>
#include <cstdint>
#include <memory>
#include <mutex>
#include <optional>
#include <string>

#include <grpcpp/grpcpp.h>

#include "filigree/call_metadata.h"
#include "filigree/reconnect.h"
#include "filigree/v1/filigree.grpc.pb.h"

namespace filigree {

// Each read() is the whole presence (every participant, by client_name):
// the current one first, then a new one whenever it changes (at most every
// 100 ms). This client's name is listed while the stream is open. It
// reconnects by itself after UNAVAILABLE (a restart, a failover), as
// `reconnect` says. cancel() may be called from any thread, e.g. to wake a
// thread blocked in read(); finish() once no other thread is inside read().
class PresenceWatcher {
 public:
  PresenceWatcher(const PresenceWatcher&) = delete;
  PresenceWatcher& operator=(const PresenceWatcher&) = delete;
  // Cancels the stream if finish() was not called.
  ~PresenceWatcher();

  // Blocks for the next snapshot; nullopt once the stream has ended
  // (session closed, cancelled, error: finish() says which).
  std::optional<v1::Presence> read();

  // Ends the stream at once, a reconnection wait too (thread-safe, any time).
  void cancel();

  // Discards unread snapshots until the stream ends and returns its status:
  // OK when the session was closed, CANCELLED after cancel(). On a live
  // stream it blocks until the session closes: cancel() first.
  grpc::Status finish();

 private:
  friend class Client;
  PresenceWatcher(v1::Filigree::Stub& stub, v1::WatchPresenceRequest request, std::string token, Routing routing,
                  Reconnect reconnect);
  void open();

  v1::Filigree::Stub& stub_;
  const v1::WatchPresenceRequest request_;
  const std::string token_;
  const Routing routing_;
  ReconnectSchedule reconnect_;

  std::mutex mutex_;  // guards context_ (cancel() from other threads) and cancelled_
  std::condition_variable cancelled_cv_;
  bool cancelled_ = false;
  std::unique_ptr<grpc::ClientContext> context_;  // one per stream; outlives it
  std::unique_ptr<grpc::ClientReader<v1::Presence>> stream_;
  std::optional<grpc::Status> status_;  // set once the stream has ended for good
};

}  // namespace filigree
