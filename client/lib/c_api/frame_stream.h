#pragma once
// The background half of a C driver or watcher: one thread that reads a
// stream of v1::Frames, decodes them with a FrameDecoder, and either hands
// each to a callback or keeps the newest for poll(). The caller's threads
// never wait for the network to get a frame.

#include <chrono>
#include <atomic>
#include <condition_variable>
#include <cstddef>
#include <cstdint>
#include <functional>
#include <map>
#include <memory>
#include <mutex>
#include <optional>
#include <string>
#include <thread>
#include <vector>

#include <grpcpp/support/status.h>

#include "filigree/filigree.h"
#include "filigree/frame_decoder.h"
#include "filigree/v1/filigree.pb.h"

namespace filigree::c_api {

class ErrorSlot;

class FrameStream {
 public:
  // How to use the stream: a Driver's or a Watcher's calls.
  struct Hooks {
    std::function<std::optional<v1::Frame>()> read;  // blocks; nullopt once the stream has ended
    std::function<grpc::Status()> finish;            // after the last read: the call's status
    std::function<void()> cancel;                    // any thread, any time
  };
  // Why a stream ended: FILIGREE_OK for a normal end (the server's OK, or
  // CANCELLED after stop()).
  struct End {
    int status = FILIGREE_OK;
    std::string message;
  };

  // Starts the thread. `callback` may be null (then frames wait for poll()).
  // `at_level`: the stream was opened with a vertex budget, so its frames'
  // size is known only once they come.
  FrameStream(Hooks hooks, std::vector<float> rest_positions, unsigned decode_threads,
              filigree_frame_callback callback, void* user, bool at_level = false);
  // stop() and join() unless done.
  ~FrameStream();
  FrameStream(const FrameStream&) = delete;
  FrameStream& operator=(const FrameStream&) = delete;

  // filigree_driver_poll / filigree_watcher_poll, after the handle check.
  int poll(ErrorSlot& slot, const char* function, float* positions, std::size_t capacity, std::uint64_t* version,
           std::uint64_t* pose_id, int* updated);
  // The latest frame polled or handed to the callback.
  filigree_frame_info info() const;
  // That frame's DecodedFrame::clip_seconds (not in filigree_frame_info,
  // whose size existing binaries rely on).
  double clip_seconds() const;
  // That frame's vertex count (the level's; 0 before the first frame) and
  // level (null at full detail).
  std::size_t level_vertex_count() const;
  std::shared_ptr<const DecodedLevel> level() const;
  // filigree_*_set_detail's wait: until the stream has received a level
  // (FILIGREE_OK), ended (why), or `timeout` passed (FILIGREE_DEADLINE_EXCEEDED).
  int wait_level(ErrorSlot& slot, const char* function, std::chrono::milliseconds timeout) const;
  // filigree_*_wait_frame: waits until poll() has a frame newer than the last
  // polled one (FILIGREE_OK), the stream ended without one (why it ended) or
  // `timeout` passed (FILIGREE_DEADLINE_EXCEEDED; nullopt: no limit).
  int wait_frame(ErrorSlot& slot, const char* function, std::optional<std::chrono::milliseconds> timeout) const;
  // filigree_driver_wait_for_pose: as wait_frame, for a frame (waiting or
  // polled already) whose pose_id is at least `pose_id`.
  int wait_for_pose(ErrorSlot& slot, const char* function, std::uint64_t pose_id,
                    std::optional<std::chrono::milliseconds> timeout) const;
  // filigree_*_changes: who changed what in the frames up to the latest one
  // polled (since the poll before) or handed to the callback, one line per
  // client: "name\tpose_id\tvertex_count\n" (tabs and newlines in names become
  // spaces), by name.
  std::string changes() const;

  // Cancels the call; it then ends normally unless it had failed already.
  void stop();
  // Waits for the end, up to `timeout` (nullopt: without limit); true once ended.
  bool wait(std::optional<std::chrono::milliseconds> timeout) const;
  // Waits for the end and joins the thread (idempotent, thread-safe). Not
  // from the stream's own thread.
  void join();
  bool on_own_thread() const { return std::this_thread::get_id() == thread_id_; }
  // Why the stream ended; call after wait() returned true.
  End end() const;
  // The status a call gives for a stream that ended (FILIGREE_ERROR_STREAM_ENDED
  // for a normal end), recorded in `slot`.
  static int report_end(ErrorSlot& slot, const char* function, const End& end);

 private:
  void run() noexcept;
  void deliver(DecodedFrame& frame);
  void ended(End end);

  Hooks hooks_;
  FrameDecoder decoder_;  // used by the thread only
  const std::size_t float_count_;  // of a frame at full detail
  const filigree_frame_callback callback_;
  void* const user_;

  mutable std::mutex mutex_;  // guards everything below but the thread
  mutable std::condition_variable changed_cv_;  // a frame arrived or the stream ended
  std::vector<float> latest_;  // the newest frame not polled yet, when fresh_
  filigree_frame_info latest_info_{}, polled_info_{};
  double latest_clip_seconds_ = 0.0, polled_clip_seconds_ = 0.0;  // as the infos
  std::shared_ptr<const DecodedLevel> latest_level_, polled_level_;  // as the infos
  std::size_t polled_vertex_count_ = 0;  // 3 floats each in the polled frame
  std::size_t frame_floats_;  // poll()'s buffer needs: the newest frame's size
  std::uint64_t levels_received_ = 0;
  // Frames' changes merged by client: since the last poll, and up to it.
  std::map<std::string, v1::Change> pending_changes_, polled_changes_;
  std::uint64_t frames_received_ = 0;
  bool fresh_ = false;
  bool stopped_ = false;  // stop() was called: CANCELLED is a normal end
  bool ended_ = false;
  End end_;

  std::mutex join_mutex_;  // std::thread::join() must not race with itself
  std::thread thread_;     // last: starts once everything above exists
  std::atomic<std::thread::id> thread_id_{};  // set by the thread itself, before any callback
};

}  // namespace filigree::c_api
