#include "c_api/frame_stream.h"

#include <algorithm>
#include <cstring>
#include <exception>
#include <utility>

#include "c_api/internal.h"
#include "filigree/client_error.h"

namespace filigree::c_api {
namespace {

// Several frames' changes of one client add up: the newest pose, every vertex.
void merge_changes(const std::vector<v1::Change>& changes, std::map<std::string, v1::Change>& into) {
  for (const v1::Change& c : changes) {
    v1::Change& merged = into[c.client_name()];
    merged.set_client_name(c.client_name());
    merged.set_pose_id(std::max(merged.pose_id(), c.pose_id()));
    merged.set_vertex_count(merged.vertex_count() + c.vertex_count());
  }
}

}  // namespace

FrameStream::FrameStream(Hooks hooks, std::vector<float> rest_positions, unsigned decode_threads,
                         filigree_frame_callback callback, void* user, bool at_level)
    : hooks_(std::move(hooks)),
      decoder_(std::move(rest_positions), decode_threads),
      float_count_(decoder_.rest_positions().size()),
      callback_(callback),
      user_(user),
      frame_floats_(at_level ? 0 : float_count_) {
  // Poll mode keeps a buffer of the frame size: the decoded frames are
  // swapped into it, so the steady state allocates only inside decode().
  if (!callback_) latest_.resize(float_count_);
  thread_ = std::thread([this] { run(); });
}

FrameStream::~FrameStream() {
  stop();
  join();
}

void FrameStream::run() noexcept {
  thread_id_ = std::this_thread::get_id();
  std::optional<End> failure;  // a frame that did not decode: it wins over the CANCELLED that follows
  try {
    while (auto frame = hooks_.read()) {
      if (failure) continue;  // draining the cancelled call (gRPC wants reads until the end)
      try {
        if (frame->has_level()) {
          // A level starts (the stream's first message, and after each
          // set_detail): the frames after it are its.
          decoder_.set_level(frame->level());
          std::lock_guard lock(mutex_);
          ++levels_received_;
          changed_cv_.notify_all();
          continue;
        }
        DecodedFrame decoded = decoder_.decode(*frame);
        deliver(decoded);
      } catch (const ClientError& e) {
        // The decoder's state no longer matches the server's: every later
        // frame would be wrong. Stop, as the C++ examples do.
        failure = End{status_of(e.code()), e.what()};
        hooks_.cancel();
      } catch (const std::bad_alloc&) {
        failure = End{FILIGREE_ERROR_OUT_OF_MEMORY, "out of memory decoding a frame"};
        hooks_.cancel();
      }
    }
  } catch (const std::exception& e) {
    if (!failure) failure = End{FILIGREE_UNKNOWN, e.what()};
    hooks_.cancel();
  } catch (...) {
    if (!failure) failure = End{FILIGREE_UNKNOWN, "unknown exception reading the stream"};
    hooks_.cancel();
  }

  End end;
  try {
    const grpc::Status status = hooks_.finish();
    bool stopped;
    {
      std::lock_guard lock(mutex_);
      stopped = stopped_;
    }
    if (failure) end = std::move(*failure);
    else if (status.ok() || (stopped && status.error_code() == grpc::StatusCode::CANCELLED)) end = End{};
    else end = End{status_of(status.error_code()),
                   std::string(status_code_name(status.error_code())) + ": " + status.error_message()};
  } catch (...) {
    end = failure ? std::move(*failure) : End{FILIGREE_UNKNOWN, "the stream did not finish cleanly"};
  }
  ended(std::move(end));
}

void FrameStream::deliver(DecodedFrame& frame) {
  filigree_frame_info info{};
  info.version = frame.version;
  info.pose_id = frame.pose_id;
  info.encoded_bytes = frame.encoded_bytes;
  info.max_error = frame.max_error;
  info.keyframe = frame.keyframe ? 1 : 0;
  if (callback_) {
    {
      std::lock_guard lock(mutex_);
      info.frames_received = ++frames_received_;
      polled_info_ = info;  // set first, so that the callback may ask for it
      polled_clip_seconds_ = frame.clip_seconds;
      polled_level_ = frame.level;
      polled_vertex_count_ = frame.vertex_count();
      polled_changes_.clear();
      merge_changes(frame.changes, polled_changes_);
    }
    callback_(frame.positions.data(), frame.positions.size(), frame.version, user_);
    return;
  }
  std::lock_guard lock(mutex_);
  latest_.swap(frame.positions);
  frame_floats_ = latest_.size();
  info.frames_received = ++frames_received_;
  latest_info_ = info;
  latest_clip_seconds_ = frame.clip_seconds;
  latest_level_ = std::move(frame.level);
  merge_changes(frame.changes, pending_changes_);
  fresh_ = true;
  changed_cv_.notify_all();
}

int FrameStream::report_end(ErrorSlot& slot, const char* function, const End& end) {
  if (end.status == FILIGREE_OK)
    return fail(&slot, FILIGREE_ERROR_STREAM_ENDED, std::string(function) + ": the stream has ended");
  return fail(&slot, end.status, std::string(function) + ": the stream ended: " + end.message);
}

void FrameStream::ended(End end) {
  std::lock_guard lock(mutex_);
  end_ = std::move(end);
  ended_ = true;
  changed_cv_.notify_all();
}

int FrameStream::poll(ErrorSlot& slot, const char* function, float* positions, std::size_t capacity,
                      std::uint64_t* version, std::uint64_t* pose_id, int* updated) {
  if (callback_)
    return fail(&slot, FILIGREE_FAILED_PRECONDITION,
                std::string(function) + ": this watcher hands its frames to its callback; there is nothing to poll");
  if (!positions) return null_argument(&slot, function, "positions");
  std::unique_lock lock(mutex_);
  // At full detail always 3·n; at a level, the newest frame's (its level's).
  if (capacity < frame_floats_) {
    const std::size_t needed = frame_floats_;
    lock.unlock();
    return fail(&slot, FILIGREE_ERROR_BUFFER_TOO_SMALL,
                std::string(function) + ": the buffer holds " + std::to_string(capacity) + " floats, a frame needs " +
                    std::to_string(needed) + " (3 per vertex" + (needed < float_count_ ? " of its level" : "") + ")");
  }
  const bool fresh = fresh_;
  if (fresh) {
    // The one copy of a frame: into the caller's buffer (a mapped or staging
    // buffer avoids any other).
    std::copy(latest_.begin(), latest_.end(), positions);
    fresh_ = false;
    polled_info_ = latest_info_;
    polled_clip_seconds_ = latest_clip_seconds_;
    polled_level_ = latest_level_;
    polled_vertex_count_ = latest_.size() / 3;
    polled_changes_.swap(pending_changes_);
    pending_changes_.clear();
  }
  if (version) *version = polled_info_.version;
  if (pose_id) *pose_id = polled_info_.pose_id;
  if (updated) *updated = fresh ? 1 : 0;
  if (fresh || !ended_) return FILIGREE_OK;
  const End end = end_;
  lock.unlock();
  return report_end(slot, function, end);
}

filigree_frame_info FrameStream::info() const {
  std::lock_guard lock(mutex_);
  filigree_frame_info out = polled_info_;
  out.frames_received = frames_received_;
  return out;
}

double FrameStream::clip_seconds() const {
  std::lock_guard lock(mutex_);
  return polled_clip_seconds_;
}

std::size_t FrameStream::level_vertex_count() const {
  std::lock_guard lock(mutex_);
  return polled_vertex_count_;
}

std::shared_ptr<const DecodedLevel> FrameStream::level() const {
  std::lock_guard lock(mutex_);
  return polled_level_;
}

int FrameStream::wait_level(ErrorSlot& slot, const char* function, std::chrono::milliseconds timeout) const {
  std::unique_lock lock(mutex_);
  if (!changed_cv_.wait_for(lock, timeout, [this] { return levels_received_ > 0 || ended_; }))
    return fail(&slot, FILIGREE_DEADLINE_EXCEEDED, std::string(function) + ": the stream's level has not arrived");
  if (levels_received_ > 0) return FILIGREE_OK;
  const End end = end_;
  lock.unlock();
  return report_end(slot, function, end);
}

int FrameStream::wait_frame(ErrorSlot& slot, const char* function,
                            std::optional<std::chrono::milliseconds> timeout) const {
  if (callback_)
    return fail(&slot, FILIGREE_FAILED_PRECONDITION,
                std::string(function) + ": this watcher hands its frames to its callback; there is nothing to wait for");
  std::unique_lock lock(mutex_);
  const auto ready = [this] { return fresh_ || ended_; };
  if (!timeout) changed_cv_.wait(lock, ready);
  else if (!changed_cv_.wait_for(lock, *timeout, ready))
    return fail(&slot, FILIGREE_DEADLINE_EXCEEDED, std::string(function) + ": no new frame yet");
  if (fresh_) return FILIGREE_OK;
  const End end = end_;
  lock.unlock();
  return report_end(slot, function, end);
}

int FrameStream::wait_for_pose(ErrorSlot& slot, const char* function, std::uint64_t pose_id,
                               std::optional<std::chrono::milliseconds> timeout) const {
  std::unique_lock lock(mutex_);
  const auto included = [&] { return polled_info_.pose_id >= pose_id || (fresh_ && latest_info_.pose_id >= pose_id); };
  const auto ready = [&] { return included() || ended_; };
  if (!timeout) changed_cv_.wait(lock, ready);
  else if (!changed_cv_.wait_for(lock, *timeout, ready))
    return fail(&slot, FILIGREE_DEADLINE_EXCEEDED,
                std::string(function) + ": no frame includes pose " + std::to_string(pose_id) + " yet");
  if (included()) return FILIGREE_OK;
  const End end = end_;
  lock.unlock();
  return report_end(slot, function, end);
}

std::string FrameStream::changes() const {
  std::lock_guard lock(mutex_);
  std::string out;
  for (const auto& [name, c] : polled_changes_) {
    std::string clean = name;
    std::replace_if(clean.begin(), clean.end(), [](char ch) { return ch == '\t' || ch == '\n' || ch == '\r'; }, ' ');
    out += clean + '\t' + std::to_string(c.pose_id()) + '\t' + std::to_string(c.vertex_count()) + '\n';
  }
  return out;
}

void FrameStream::stop() {
  {
    std::lock_guard lock(mutex_);
    if (ended_) return;
    stopped_ = true;
  }
  hooks_.cancel();
}

bool FrameStream::wait(std::optional<std::chrono::milliseconds> timeout) const {
  std::unique_lock lock(mutex_);
  if (!timeout) {
    changed_cv_.wait(lock, [this] { return ended_; });
    return true;
  }
  return changed_cv_.wait_for(lock, *timeout, [this] { return ended_; });
}

void FrameStream::join() {
  std::lock_guard lock(join_mutex_);
  if (thread_.joinable()) thread_.join();
}

FrameStream::End FrameStream::end() const {
  std::lock_guard lock(mutex_);
  return end_;
}

}  // namespace filigree::c_api
