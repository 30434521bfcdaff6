#pragma once
// A subscriber's frame stream: the session's FrameSink over a gRPC stream
// writer (Drive, Watch, Follow and PlayClip streams alike).

#include <atomic>
#include <cstdint>
#include <deque>
#include <exception>
#include <functional>
#include <memory>
#include <mutex>
#include <optional>
#include <random>
#include <string>
#include <utility>

#include <grpcpp/grpcpp.h>
#include <spdlog/spdlog.h>

#include "server/clip_times.h"
#include "server/session.h"
#include "server/stream_writer.h"

namespace filigree::server {

// A frame as one stream writes it: the frame's shared wire bytes (with the
// stream's pose id), and the version it has if it is a chunked keyframe.
struct OutgoingFrame {
  grpc::ByteBuffer bytes;
  std::uint64_t version = 0;
  std::optional<std::uint64_t> keyframe;
  std::uint64_t level_message = 0;  // a DetailLevel message: its number on this stream
};
inline const grpc::ByteBuffer& wire(const OutgoingFrame& f) { return f.bytes; }

// A stream of frames with a mailbox of one: offer() replaces what is waiting,
// so a slow client skips frames, and never blocks the session. In the chunked
// format, a frame whose keyframe this stream has not written goes after it:
// the keyframe is queued to be sent first (Frame.keyframe_version).
template <class Reactor>
class FrameStream : public FrameSink {
 public:
  FrameStream(Reactor* reactor, std::uint64_t driver) : writer_(reactor), driver_(driver) {
    writer_.on_start_write([this](const OutgoingFrame& f) {
      if (f.keyframe) written_keyframe_ = *f.keyframe;
      if (f.level_message) written_level_message_ = f.level_message;
      // Only a stream that acknowledges keeps what it wrote: on Drive and
      // Watch nothing would ever take it off again.
      if (!acknowledged_) return;
      std::lock_guard lock(unread_mutex_);
      unread_.push_back(f.version);
    });
  }

  // Set once, before the stream subscribes (Follow): at most `window`
  // frames written and not acknowledged.
  void acknowledged_within(std::size_t window) {
    acknowledged_ = true;
    writer_.set_window(window);
  }

  // The client read every frame up to `version` (Follow): the frames written
  // at or below it leave the writer's window.
  void acknowledge(std::uint64_t version) {
    std::size_t read = 0;
    {
      std::lock_guard lock(unread_mutex_);
      // Written in version order, but a keyframe may go before an older
      // frame's place: count every written version at or below this one.
      for (auto it = unread_.begin(); it != unread_.end();)
        if (*it <= version) {
          it = unread_.erase(it);
          ++read;
        } else {
          ++it;
        }
    }
    if (read) writer_.release(read);
  }

  // Set once, before the stream subscribes.
  void set_format(v1::FrameFormat format) { format_ = format; }
  // Set once, before the stream subscribes (with the chunked format): the
  // stream is served at level `level` (Session::level_for) and can switch
  // (SetDetail) by `id`, which must not be 0.
  void serve_levels(std::uint64_t id, std::uint32_t level) {
    stream_id_ = id;
    level_ = level;
  }
  std::uint64_t stream_id() const override { return stream_id_; }
  std::uint32_t level() const override { return level_; }
  void switch_level(std::uint32_t level) override { level_ = level; }
  // Set once, before the stream subscribes (PlayClip): the clip time of
  // this stream's poses, written with the pose id into its frames.
  void set_clip_times(std::shared_ptr<const ClipTimes> times) { clip_times_ = std::move(times); }
  // Called after every offer (with the frame) and on close (with null);
  // set once, before the stream subscribes. Must not block.
  void on_event(std::function<void(const PublishedFrame*)> observer) { observer_ = std::move(observer); }
  v1::FrameFormat format() const override { return format_; }
  std::uint64_t driver() const override { return driver_; }

  void offer(std::shared_ptr<const PublishedFrame> frame) override {
    // The session offers from its workers and, once, from subscribe(): one at
    // a time, and never an older frame after a newer one (but after a level
    // switch, the frame already written at the old level).
    std::lock_guard lock(offer_mutex_);
    const std::uint32_t level = level_;
    const bool switching = stream_id_ != 0 && level != level_sent_;
    if (!switching && offered_any_ && frame->frame.version() <= offered_version_) return;
    // A stream at a level of detail writes the level's frame; a frame computed
    // before anyone wanted the level has none, and the next one will.
    const PublishedFrame* at = stream_id_ != 0 ? frame->at_level(level) : frame.get();
    if (at == nullptr) return;
    if (switching) {
      level_sent_ = level;
      level_pending_ = true;  // write() sends the DetailLevel first
      written_keyframe_ = kNone;
      queued_keyframe_ = kNone;
    }
    offered_any_ = true;
    offered_version_ = std::max(offered_version_, frame->frame.version());
    write(*at);
    if (observer_) observer_(frame.get());
  }
  void close(bool session_closed, const std::string& why) override {
    writer_.finish(session_closed ? grpc::Status::OK : grpc::Status(grpc::StatusCode::UNAVAILABLE, why));
    if (observer_) observer_(nullptr);
  }
  StreamWriter<Reactor, OutgoingFrame>& writer() { return writer_; }

 private:
  void write(const PublishedFrame& frame) {
    try {
      if (format_ == v1::FRAME_FORMAT_SINGLE) {
        if (frame.single) writer_.send(outgoing(frame, *frame.single, frame.single_bytes()), /*droppable=*/true);
        return;
      }
      // A DetailLevel not written yet goes again before a newer keyframe (which
      // supersedes what is queued); sent first, it supersedes the old level's
      // queued keyframes itself.
      const bool level_unwritten = stream_id_ != 0 && (level_pending_ || written_level_message_ != level_messages_);
      const PublishedFrame* key = frame.keyframe.get();
      if (key != nullptr) {
        const std::uint64_t version = key->frame.version();
        if (written_keyframe_ != version && queued_keyframe_ != version) {
          queued_keyframe_ = version;
          if (level_unwritten) send_level(frame);
          writer_.send(outgoing(*key, key->frame, key->frame_bytes()), /*droppable=*/false, /*supersede=*/!level_unwritten);
        }
      }
      if (level_pending_) send_level(frame);
      writer_.send(outgoing(frame, frame.frame, frame.frame_bytes()), /*droppable=*/true);
    } catch (const std::exception& e) {  // the frame could not be serialized: this stream cannot go on
      spdlog::error("event=frame_serialization_failed version={} error=\"{}\"", frame.frame.version(), e.what());
      writer_.finish({grpc::StatusCode::INTERNAL, std::string("a frame could not be serialized: ") + e.what()});
    }
  }

  // Queues the DetailLevel of `frame`'s level (offer_mutex_ held), ahead of
  // anything of an older level still queued.
  void send_level(const PublishedFrame& frame) {
    v1::Frame message;
    v1::DetailLevel& level = *message.mutable_level();
    level.set_vertex_count(frame.frame.vertex_count());
    if (frame.geometry) {
      level.set_face_count(frame.geometry->face_count);
      level.set_mesh(frame.geometry->mesh);
    }
    level.set_stream_id(stream_id_);
    auto out = std::make_shared<OutgoingFrame>();
    out->bytes = SerializedFrame(message, frame.wire_pool).for_stream(0);
    out->level_message = ++level_messages_;
    level_pending_ = false;
    writer_.send(std::move(out), /*droppable=*/false, /*supersede=*/true);
  }

  // Every stream writes the frame's one serialized copy; a driver's also
  // names the newest of its poses the frame includes.
  std::shared_ptr<const OutgoingFrame> outgoing(const PublishedFrame& published, const v1::Frame& message,
                                                const SerializedFrame& bytes) const {
    std::uint64_t pose_id = 0;
    if (driver_)
      if (const auto it = published.pose_of_driver.find(driver_); it != published.pose_of_driver.end()) pose_id = it->second;
    auto out = std::make_shared<OutgoingFrame>();
    out->bytes = bytes.for_stream(pose_id, clip_times_ && pose_id ? clip_times_->of(pose_id) : 0.0);
    out->version = message.version();
    if (!message.chunks().empty() && message.keyframe_version() == message.version()) out->keyframe = message.version();
    return out;
  }

  StreamWriter<Reactor, OutgoingFrame> writer_;
  std::function<void(const PublishedFrame*)> observer_;
  std::shared_ptr<const ClipTimes> clip_times_;
  const std::uint64_t driver_;
  v1::FrameFormat format_ = v1::FRAME_FORMAT_SINGLE;
  // Versions of the keyframes written and queued; none yet (a keyframe may be version 0).
  static constexpr std::uint64_t kNone = ~std::uint64_t{0};
  std::atomic<std::uint64_t> written_keyframe_{kNone};
  std::mutex offer_mutex_;
  std::uint64_t queued_keyframe_ = kNone;  // offer_mutex_
  bool offered_any_ = false;               // offer_mutex_
  std::uint64_t offered_version_ = 0;
  // Levels of detail: the stream's id (0: none asked), the level it wants,
  // the level of the frames it writes (offer_mutex_), whether that level's
  // DetailLevel must go out with the next write, and the numbers of the
  // DetailLevel messages queued (offer_mutex_) and written.
  std::uint64_t stream_id_ = 0;
  std::atomic<std::uint32_t> level_{0};
  std::uint32_t level_sent_ = 0;
  bool level_pending_ = false;
  std::uint64_t level_messages_ = 0;
  std::atomic<std::uint64_t> written_level_message_{0};
  std::atomic<bool> acknowledged_{false};  // a Follow stream
  std::mutex unread_mutex_;
  std::deque<std::uint64_t> unread_;  // versions written and not acknowledged (Follow)
};

// Serves `stream` at the level of detail for `max_vertices` (proto
// WatchRequest.max_vertices; 0: full detail, no levels), under a fresh
// random stream id. Call before the stream subscribes. INVALID_ARGUMENT for
// a level in the single-buffer format.
template <class Reactor>
grpc::Status serve_detail(FrameStream<Reactor>& stream, const Session& session, v1::FrameFormat format,
                          std::uint32_t max_vertices) {
  if (max_vertices == 0) return grpc::Status::OK;
  if (format != v1::FRAME_FORMAT_CHUNKED)
    return {grpc::StatusCode::INVALID_ARGUMENT, "max_vertices needs frame_format FRAME_FORMAT_CHUNKED"};
  std::random_device random;
  std::uint64_t id = 0;
  while (id == 0) id = (std::uint64_t{random()} << 32) ^ random();
  stream.serve_levels(id, session.level_for(max_vertices));
  return grpc::Status::OK;
}

// A frame stream's end (OnDone): it no longer subscribes or drives (a
// watcher's driver 0 drives nothing), and its writer never touches the
// reactor again.
template <class Reactor>
void leave(const std::shared_ptr<Session>& session, FrameStream<Reactor>& stream, std::uint64_t driver) {
  if (session) {
    session->unsubscribe(&stream);
    session->driver_left(driver);
  }
  stream.writer().detach();
}

}  // namespace filigree::server
