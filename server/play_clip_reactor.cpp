#include "server/play_clip_reactor.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <condition_variable>
#include <cstdint>
#include <memory>
#include <mutex>
#include <string>
#include <system_error>
#include <thread>

#include "server/call_arguments.h"
#include "server/clip_times.h"
#include "server/frame_stream_reactor.h"
#include "skinning/animation_clip.h"

namespace filigree::server {
namespace {

// Plays a clip of the session's rig: a thread samples it at the stream's
// clock and submits each sample as a skeletal pose of this stream, waiting
// for the frame that includes one before sampling the next (so a slow
// session lowers the sample rate instead of queueing poses).
class PlayClipReactor final : public FrameStreamReactor<PlayClipReactor, grpc::ServerWriteReactor<grpc::ByteBuffer>> {
 public:
  PlayClipReactor(FiligreeService& service, grpc::CallbackServerContext* context, const grpc::ByteBuffer& request_bytes)
      : FrameStreamReactor(service, service.next_driver_id(), this) {
    if (const grpc::Status parsed = parse_request(request_bytes, request_); !parsed.ok()) {
      stream_->writer().finish(parsed);
    } else {
      open(*context, request_.session_id(), Role::kEditor);
    }
  }
  void OnCancel() override {
    state_->end();
    FrameStreamReactor::OnCancel();
  }
  void OnDone() override {
    state_->end();
    if (player_.joinable()) player_.get_id() == std::this_thread::get_id() ? player_.detach() : player_.join();
    FrameStreamReactor::OnDone();  // deletes this
  }

 private:
  void start(const grpc::Status& admitted, const std::shared_ptr<StreamStart>& started,
             const std::shared_ptr<FrameStream<PlayClipReactor>>& stream) override {
    grpc::Status status = admitted.ok() ? check() : admitted;
    if (status.ok() && !service_.begin_job()) status = {grpc::StatusCode::UNAVAILABLE, "the server is shutting down"};
    if (!status.ok()) {
      session_.reset();
      return end_start(started, stream, status);
    }
    stream_->set_format(request_.frame_format());
    stream_->set_clip_times(clip_times_);
    // The session may offer after this reactor is gone: the observer owns what it touches.
    stream_->on_event([state = state_, driver = driver_](const PublishedFrame* frame) {
      std::lock_guard lock(state->mutex);
      if (!frame) {
        state->ended = true;  // the session closed or left: the stream is finished already
      } else if (const auto it = frame->pose_of_driver.find(driver); it != frame->pose_of_driver.end()) {
        state->shown = std::max(state->shown, it->second);
      }
      state->changed.notify_all();
    });
    session_->subscribe(stream_, session_->version());
    try {
      player_ = std::thread([this] {
        {  // not before player_ is set: the stream may end with it, and OnDone joins player_
          std::unique_lock lock(state_->mutex);
          state_->changed.wait(lock, [&] { return state_->playing; });
        }
        const grpc::Status status = play();
        service_.end_job();
        stream_->writer().finish(status, /*flush=*/true);
      });
      std::lock_guard lock(state_->mutex);
      state_->playing = true;
      state_->changed.notify_all();
    } catch (const std::system_error& e) {
      service_.end_job();
      status = {grpc::StatusCode::RESOURCE_EXHAUSTED, std::string("the server could not start a thread: ") + e.what()};
    }
    end_start(started, stream, status);
  }

  static constexpr double kMostSamplesPerSecond = 60.0;

  grpc::Status check() {
    if (!session_->has_skeleton())
      return {grpc::StatusCode::FAILED_PRECONDITION, "session " + session_->id() + " has no skeleton (its upload was not a skinned glTF)"};
    clip_ = session_->clip(request_.clip());
    if (!clip_) return {grpc::StatusCode::NOT_FOUND, "session " + session_->id() + " has no clip '" + request_.clip() + "'"};
    if (!std::isfinite(request_.speed()) || request_.speed() < 0.0 || !std::isfinite(request_.start_seconds()) ||
        !std::isfinite(request_.max_rate()) || request_.max_rate() < 0.0)
      return {grpc::StatusCode::INVALID_ARGUMENT, "speed, start_seconds and max_rate must be finite, speed and max_rate ≥ 0"};
    return grpc::Status::OK;
  }

  grpc::Status play() {
    using Clock = std::chrono::steady_clock;
    const double duration = clip_->duration();
    const double speed = request_.speed() > 0.0 ? request_.speed() : 1.0;
    // max_rate counts samples per second of clip time: at speed s that is s
    // times as many per second of the stream's clock, which is capped.
    const double rate = request_.max_rate() > 0.0 ? std::min(request_.max_rate() * speed, kMostSamplesPerSecond)
                                                  : kMostSamplesPerSecond;
    const auto interval = std::chrono::duration_cast<Clock::duration>(std::chrono::duration<double>(1.0 / rate));
    const auto start = Clock::now();
    const std::string name = request_.client_name().empty() ? "clip " + request_.clip() : request_.client_name();
    for (std::uint64_t id = 1;; ++id) {
      const auto tick = Clock::now();
      double t = request_.start_seconds() + speed * std::chrono::duration<double>(tick - start).count();
      const bool last = !request_.loop() && t >= duration;
      if (last) t = duration;
      if (request_.loop() && duration > 0.0) t = std::fmod(t, duration);
      clip_times_->record(id, t);  // before the frame that shows it can be offered
      try {
        session_->submit_clip_sample({driver_, name, id}, *clip_, t);
      } catch (const PoseError& e) {
        return {grpc::StatusCode::INVALID_ARGUMENT, e.what()};
      } catch (const StoreUnavailable& e) {
        return {grpc::StatusCode::UNAVAILABLE, e.what()};
      }
      PlayState& s = *state_;
      std::unique_lock lock(s.mutex);
      // The next sample once this one is shown, and not before the rate allows.
      s.changed.wait(lock, [&] { return s.ended || s.shown >= id; });
      if (s.ended) return grpc::Status::CANCELLED;
      if (last) return grpc::Status::OK;
      s.changed.wait_until(lock, tick + interval, [&] { return s.ended; });
      if (s.ended) return grpc::Status::CANCELLED;
    }
  }

  v1::PlayClipRequest request_;  // set once, in the constructor
  const AnimationClip* clip_ = nullptr;  // owned by the session's rig
  struct PlayState {
    std::mutex mutex;
    std::condition_variable changed;
    bool ended = false;       // cancelled, done, or the session's streams closed
    bool playing = false;     // player_ is set
    std::uint64_t shown = 0;  // the newest sample a frame includes
    void end() {
      std::lock_guard lock(mutex);
      ended = true;
      changed.notify_all();
    }
  };
  const std::shared_ptr<PlayState> state_ = std::make_shared<PlayState>();
  const std::shared_ptr<ClipTimes> clip_times_ = std::make_shared<ClipTimes>();
  std::thread player_;
};

}  // namespace

grpc::ServerWriteReactor<grpc::ByteBuffer>* new_play_clip_reactor(FiligreeService& service,
                                                                  grpc::CallbackServerContext* context,
                                                                  const grpc::ByteBuffer& request) {
  return new PlayClipReactor(service, context, request);
}

}  // namespace filigree::server
