#include "c_api/presence_feed.h"

#include "c_api/internal.h"

namespace filigree::c_api {

PresenceFeed::PresenceFeed(std::unique_ptr<PresenceWatcher> watcher)
    : watcher_(std::move(watcher)), polled_(std::make_shared<const v1::Presence>()), thread_([this] { run(); }) {}

PresenceFeed::~PresenceFeed() {
  stop();
  join();
}

void PresenceFeed::run() noexcept {
  End end;
  try {
    while (auto presence = watcher_->read()) {
      auto shared = std::make_shared<const v1::Presence>(std::move(*presence));
      std::lock_guard lock(mutex_);
      latest_ = std::move(shared);
      fresh_ = true;
      changed_cv_.notify_all();
    }
    const grpc::Status status = watcher_->finish();
    bool stopped;
    {
      std::lock_guard lock(mutex_);
      stopped = stopped_;
    }
    if (!status.ok() && !(stopped && status.error_code() == grpc::StatusCode::CANCELLED))
      end = End{status_of(status.error_code()),
                std::string(status_code_name(status.error_code())) + ": " + status.error_message()};
  } catch (const std::exception& e) {
    watcher_->cancel();
    end = End{FILIGREE_UNKNOWN, e.what()};
  } catch (...) {
    watcher_->cancel();
    end = End{FILIGREE_UNKNOWN, "unknown exception reading the presence stream"};
  }
  std::lock_guard lock(mutex_);
  end_ = std::move(end);
  ended_ = true;
  changed_cv_.notify_all();
}

int PresenceFeed::poll(ErrorSlot& slot, const char* function, std::uint64_t* version, int* updated) {
  std::unique_lock lock(mutex_);
  if (fresh_) {
    polled_ = latest_;
    fresh_ = false;
    if (version) *version = polled_->version();
    if (updated) *updated = 1;
    return FILIGREE_OK;
  }
  if (version) *version = polled_->version();
  if (updated) *updated = 0;
  if (!ended_) return FILIGREE_OK;
  const End end = end_;
  lock.unlock();
  return FrameStream::report_end(slot, function, end);
}

int PresenceFeed::wait(ErrorSlot& slot, const char* function, std::optional<std::chrono::milliseconds> timeout) const {
  std::unique_lock lock(mutex_);
  const auto ready = [this] { return fresh_ || ended_; };
  if (!timeout) changed_cv_.wait(lock, ready);
  else if (!changed_cv_.wait_for(lock, *timeout, ready))
    return fail(&slot, FILIGREE_DEADLINE_EXCEEDED, std::string(function) + ": no new presence yet");
  if (fresh_) return FILIGREE_OK;
  const End end = end_;
  lock.unlock();
  return FrameStream::report_end(slot, function, end);
}

std::shared_ptr<const v1::Presence> PresenceFeed::polled() const {
  std::lock_guard lock(mutex_);
  return polled_;
}

void PresenceFeed::stop() {
  {
    std::lock_guard lock(mutex_);
    if (ended_) return;
    stopped_ = true;
  }
  watcher_->cancel();
}

void PresenceFeed::join() {
  std::lock_guard lock(join_mutex_);
  if (thread_.joinable()) thread_.join();
}

PresenceFeed::End PresenceFeed::end() const {
  std::lock_guard lock(mutex_);
  return end_;
}

}  // namespace filigree::c_api
