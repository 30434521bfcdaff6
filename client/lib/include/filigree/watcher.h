#pragma once
// One stream of a session's frames as they are computed (Follow: each frame
// read is acknowledged), or of a clip's (PlayClip).

#include <chrono>
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

class DetailSwitch;

// What Client::watch() asks of the stream (WatchRequest's fields).
struct WatchOptions {
  // The last version this client saw: frames up to it are not sent (after a
  // reconnect of your own); 0: the current frame first.
  std::uint64_t after_version = 0;
  // A level of detail: at most this many vertices (0: full detail). Budgets
  // round down to a power of two; below the base's vertex count they get the
  // base, at or above the mesh's the full mesh. The stream's first message
  // is then the level (v1::Frame::has_level(): FrameDecoder::set_level),
  // and its frames carry the level's vertices only. Watcher::set_detail
  // changes it.
  std::uint32_t max_vertices = 0;
};

// Made by Client::watch() (or Client::play_clip(), whose stream carries the
// frames of the clip it plays, each with the clip time it shows in
// Frame.clip_seconds, and ends after the clip's last one). A slow
// reader skips frames and is at most two frames behind the newest; it never
// slows the session. cancel() may be called from any
// thread, e.g. to wake a thread blocked in read(); finish() once no other
// thread is inside read().
class Watcher {
 public:
  Watcher(const Watcher&) = delete;
  Watcher& operator=(const Watcher&) = delete;
  // Cancels the stream if finish() was not called.
  ~Watcher();

  // Blocks for the next frame; nullopt once the stream has ended (session
  // closed, cancelled, error: finish() says which). With Reconnect, an
  // UNAVAILABLE end is not the end: read() reconnects (waiting the backoff)
  // and goes on, until give_up_after passes without success.
  std::optional<v1::Frame> read();

  // Ends the stream at once, a reconnection wait too (thread-safe, any time).
  void cancel();

  // Moves a stream opened with a vertex budget (WatchOptions::max_vertices)
  // to the level of `max_vertices` (SetDetail): the stream then sends that
  // level (a message with v1::Frame::has_level()) and its keyframe, and
  // frames of that level after. Returns the level's vertex count. A
  // reconnected stream keeps the level. Thread-safe (one thread may read
  // while another calls this). Throws ClientError: INVALID_ARGUMENT for 0;
  // FAILED_PRECONDITION for a stream opened at full detail or a clip's, or
  // before the stream's level was read (its first message, and again after
  // a reconnection); NOT_FOUND once the stream has ended.
  std::uint32_t set_detail(std::uint32_t max_vertices);

  // Discards unread frames until the stream ends and returns the call's
  // status: OK when the session was closed, CANCELLED after cancel(). On a
  // live stream it blocks until the session closes: cancel() first to stop
  // watching now. Later calls return the same.
  grpc::Status finish();

 private:
  friend class Client;
  Watcher(v1::Filigree::Stub& stub, const std::string& session_id, const std::string& token,
          const WatchOptions& options, Routing routing, Reconnect reconnect, std::chrono::milliseconds call_timeout);
  Watcher(v1::Filigree::Stub& stub, const v1::PlayClipRequest& request, const std::string& token, Routing routing,
          std::chrono::milliseconds call_timeout);
  // Opens the stream (again) from last_version_ (a Watch) or the request (a clip).
  void open();

  v1::Filigree::Stub& stub_;
  const std::string token_;
  const Routing routing_;
  const std::chrono::milliseconds call_timeout_;  // of set_detail's SetDetail
  std::optional<v1::PlayClipRequest> clip_;  // set for a clip: not reconnected
  std::string session_id_;
  std::uint64_t last_version_ = 0;
  ReconnectSchedule reconnect_;
  std::unique_ptr<DetailSwitch> detail_;  // the budget, and the stream id the level names

  std::mutex mutex_;  // guards context_ (cancel() from other threads) and cancelled_
  std::condition_variable cancelled_cv_;
  bool cancelled_ = false;
  std::unique_ptr<grpc::ClientContext> context_;  // one per stream; outlives it
  // Frames on the wire beyond the newest one read (FollowRequest.max_in_flight).
  static constexpr std::uint32_t kFramesInFlight = 2;
  // One of the two: a clip's stream, or a Follow stream of the session.
  std::unique_ptr<grpc::ClientReader<v1::Frame>> clip_stream_;
  std::unique_ptr<grpc::ClientReaderWriter<v1::FollowRequest, v1::Frame>> follow_;
  std::optional<grpc::Status> status_;
};

}  // namespace filigree
