#pragma once
// The level of detail of one stream (Watcher, Driver): the vertex budget it
// is opened (and reopened) with, the server's id of the stream, which the
// stream's level message names (DetailLevel.stream_id), and the SetDetail
// call that moves the stream to another level.

#include <chrono>
#include <cstdint>
#include <mutex>
#include <string>

#include "filigree/call_metadata.h"
#include "filigree/v1/filigree.grpc.pb.h"

namespace filigree {

// Thread-safe: the reading thread opens streams and observes their
// messages while any thread may change the level.
class DetailSwitch {
 public:
  // `max_vertices`: the budget streams are opened with; 0: full detail, no level.
  explicit DetailSwitch(std::uint32_t max_vertices) : max_vertices_(max_vertices) {}

  // The budget to open a stream with: the first one's, or the latest
  // set() accepted, so that a reconnected stream keeps its level.
  std::uint32_t max_vertices() const;
  // A new stream was opened: its id is unknown until its level arrives.
  void opened();
  // A message read from the stream: a level names the stream.
  void observe(const v1::Frame& message);

  // Asks the server (SetDetail) to serve the stream at a budget of
  // `max_vertices` and returns the level's vertex count. Throws ClientError:
  // INVALID_ARGUMENT for a budget of 0; FAILED_PRECONDITION for a stream
  // opened at full detail, or whose level has not been read yet; the
  // server's status otherwise (NOT_FOUND: the stream has ended).
  std::uint32_t set(v1::Filigree::Stub& stub, const std::string& session_id, const std::string& token,
                    Routing routing, std::chrono::milliseconds timeout, std::uint32_t max_vertices);

 private:
  mutable std::mutex mutex_;
  std::uint32_t max_vertices_;
  std::uint64_t stream_id_ = 0;
  bool stream_known_ = false;  // the current stream's level was read: stream_id_ is its
};

}  // namespace filigree
